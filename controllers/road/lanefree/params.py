"""The lane-free flocking law's parameters (:class:`LaneFreeParams`); the law itself is
described in :mod:`controllers.road.lanefree`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.errors import ParameterError


@dataclass(frozen=True)
class LaneFreeParams:
    """Parameters of the lane-free flocking law (SI units; see the module docstring).

    Longitudinal:
        time_gap_s: time gap T behind a CAV, s.
        time_gap_hdv_s: time gap behind a human driver or obstacle, s.
        standstill_gap_m: standstill gap s0, m.
        kp: spacing gain k_p, 1/s^2. kd: relative-speed gain k_d, 1/s.
        ff_gain: feed-forward of a CAV leader's acceleration k_ff (0..1).
        kp_hdv, kd_hdv: gains behind non-CAVs (no acceleration shared), 1/s^2, 1/s.
        speed_gain: desired-speed gain k_v, 1/s.
        approach_gain: gain k_a of the approach bound, 1/s.
        comfort_decel_mps2: deceleration b of the approach bound, m/s^2.
        spacing_error_min_m: lower clip of ``g - s0 - T v``, m.
        spacing_error_max_m: range of the linear term beyond the desired gap, m.
        anticipation_s: horizon over which lateral motion makes a vehicle a leader, s.
        follow_margin_m: lateral gap below which a vehicle ahead is a leader, m.
    Lateral:
        lat_gain: k_y, 1/s^2. lat_damping: c_y, 1/s.
        a_lat_bound_mps2: lateral deceleration the boundary bounds assume, m/s^2.
        lateral_clearance_m: side clearance kept to vehicles alongside, m.
        edge_margin_m: distance kept between the body and the road edge, m.
        side_buffer_m, side_buffer_speed_s, side_buffer_s: a vehicle counts as alongside
            within a bumper gap of ``m + s_v v_rear + s * closing speed`` (the rear vehicle's
            speed and the closing speed of the two), m, s and s.
        cut_in_gap_m, cut_in_speed_margin_mps: a vehicle also counts as alongside when the
            follower of the two would be faster than its safe speed (Krauss, emergency
            braking, one step of reaction) at the bumper gap minus ``cut_in_gap_m``, less
            ``cut_in_speed_margin_mps`` (stricter than the safety layer's rule), m and m/s.
        repulsion_gain: barrier repulsion strength, m/s^2.
        replan_s: period of the lateral target choice, s.
        candidate_step_m: spacing of candidate lateral positions, m.
        lookahead_s, lookahead_min_m: stopped obstacles ahead considered for the target (at
            least ``lookahead_min_m``, or ``lookahead_s`` of travel), s and m.
        edge_lookahead_min_m, edge_lookahead_s: road edges ahead (a narrowing) bounding the
            lateral target and position: at least this far, or this long of travel (longer
            than the loop's 4 s, so a CAV is inside before the safety layer looks), m and s.
        scan_margin_m: lateral gap below which a vehicle ahead blocks a candidate band, m.
        scan_time_gap_s: time gap of the offered-speed estimate, s.
        scan_decel_mps2: deceleration of the offered-speed estimate, m/s^2 (below the
            approach bound's, so a CAV changes band before it has to brake).
        move_cost: c_move, (m/s) per m of lateral distance.
        clear_gain: c_clear, (m/s) per m of lateral clearance (up to ``clear_cap_m``).
        clear_cap_m: clearance beyond which a candidate gains nothing, m.
        nudge_gain: c_nudge, (m/s) per (m/s) of desired-speed excess of held-up followers.
        hysteresis_mps: score gain needed to change target, m/s.
        order_gain: weight of the desired-speed order ``-c_o |y - y_pref|``, (m/s) per m;
            ``y_pref`` runs from the right (``bias_speed_low_mps`` and slower) to the left
            (``bias_speed_high_mps`` and faster) of the road ahead.
        bias_speed_low_mps, bias_speed_high_mps: desired speeds of the two ends, m/s.
        urgent_gain_mps: offered-speed gain (and at least 30 % of the own speed) above which
            a move is announced (others yield), for a CAV faster than ``queue_speed_mps``;
            a move out of a band blocked by a stopped obstacle is always announced, m/s.
        congested_hysteresis_mps: the score gain needed to change target rises by up to this
            as the CAV's speed falls from 95 % to 75 % of its desired speed, m/s: in dense
            traffic every lateral move makes the followers in two bands brake, and moves
            that gain little cost the road more than they give (on TUM's ring at 225 veh/km:
            10 800 veh/h with 0, 16 300 with 2.5).
        row_pull: how far (0..1) a congested CAV's lateral target is pulled to the nearest
            row that fits across the road (rows as many as the widest vehicle present plus
            ``lateral_clearance_m`` fit, spread evenly), scaled by its congestion (0 at 95 %,
            1 at 75 % of its desired speed): rows form from the widths as density rises.
        queue_speed_mps, queue_hysteresis: below this speed (m/s) the score gain needed to
            change target rises by ``queue_hysteresis`` (m/s per m/s): in a slow queue
            lateral moves do not pay.
    Cooperation:
        coop_time_gap_s: time gap to a virtual leader (an announced mover), s.
        yield_decel_mps2: strongest braking to let a mover in, m/s^2.
        yield_timeout_s, yield_cooldown_s: a CAV lets the same vehicle in for at most this
            long, then goes on for the cool-down, s (nothing waits forever).
        zipper_slack_m: a CAV closer behind a mover than ``side_buffer_m`` plus this cannot
            let it in (the mover needs that gap beside it) and goes on instead, m.
        mover_skips_followers: a mover does not wait for a vehicle behind it that already
            follows it (a CAV within ``follow_margin_m``, a human driver within
            ``human_follow_margin_m``). It ends a zipper deadlock of dense files (TUM's
            ring at 400 veh/km with T 0.5 s and a 0.5 m standstill gap crawled at 1.1 m/s
            for good); off by default because with it the law's checks regressed (a CAV
            collision in the width drop at 60 % CAVs and on the corridor at 40 %, a 177 s
            standstill behind a stopped car on a user's road).
        human_in_band_follows: a human driver in a CAV's band, one behind the other (the
            bodies overlap across the road, not along it), is a leader or a follower, not a
            driver at its side: he bounds no lateral move of the CAV (unless he follows it
            too closely to stop if it moved further into his band: then he keeps his
            bound) and is never a driver to evade. It ends the safety layer's hold of a
            CAV pushed from the edge into a CAV beside it by a human driver behind it (TUM's
            ring, 50 % CAVs, 350 veh/km, TUM's margins: 2.2 % of the CAV-steps clipped) and
            a 119 s standstill on a user's width step; off by default because with it the
            corridor's checks pass 64 of 65 (a CAV merging from a stop at 70 % CAVs on
            ``corridor`` waited 30.4 s for a gap; bound 30 s).
        squeezed_moves_to_middle: a CAV squeezed between a human driver inside its
            clearance (he moved towards it) and another vehicle whose bound it is also
            inside moves to the middle of the two bounds instead of holding still (on by
            default: held still, a CAV at a width drop, 60 % CAVs, was touched by a driver
            who overtook it 0.14 m away and drifted on). Off in the margins arm on TUM's
            ring (``tum_protocol_tum_margins``): at TUM's margins (T 0.5 s behind humans,
            TUM's human model) the rule moved CAVs into a driver's follow margin, each then
            followed the other, and the ring stood at 400 veh/km; since the law's standoff
            rule (``STANDOFF_*`` in kernels.py) it no longer stands there, but the safety
            layer acts on 5.1 % of CAV-steps at 50 % CAVs, so the arm keeps it off (with
            TUM's humans at the default margins the standoff, not this rule, stood the ring
            at 50 % CAVs; docs/results.md).
        row_approach_gain: approach gain k_a (1/s) of a congested CAV about in a row
            (within ``ROW_SLACK_M`` of it) whose window holds no CAV between rows; 0: the
            ``approach_gain`` everywhere (the default). At a time gap equal to the
            approach bound's reaction time (0.5 s) the bound is active at equilibrium
            and string-unstable at ``approach_gain`` 1.5 (stop-and-go at 0.82-0.90 of 4
            rows' equilibrium flow on TUM's ring); stable everywhere (2.5-3.5) it freezes
            the random start lattice, as the rows form only through the waves. Stable
            only where the rows have formed: 15 383-15 699 veh/h at 400 veh/km over 4
            seeds (road world, 100 % CAVs, T 0.5 s, 0.5 m; 11 663-12 988 without; 4 rows'
            equilibrium 15 696).
        human_follow_margin_m: a human driver behind a mover within this lateral gap
            follows the mover, so the mover does not wait for it to pass, m. Set by the
            run, not in ``[controller.params]``: SUMO's sublane width (its drivers follow
            whatever shares a sublane with them: 0.8 m on a plain road, 0.2 m where it
            narrows), 0 in the road world (its drivers follow only an overlapping vehicle).
        window: neighbours in road order looked at on each side of a CAV.
        entry_reach_m: a vehicle outside the road within this distance of its edge (about
            to merge from an on-ramp) counts as on the road at its nearest inside
            position, m.
        entry_horizon_s: ... or that reaches the edge within this time at its lateral speed
            towards the road (a ramp vehicle is seen while it can still be given a gap), s.
        squeeze_s, squeeze_min_m: a moving sensed vehicle whose body leaves the road's
            narrowest edges within this time at its speed (at least this distance ahead) is
            seen at its nearest inside position there (a human driver about to be squeezed
            in by a narrowing), s and m.
    Exits (a road with an off-ramp; :mod:`controllers.road.exits`):
        exit_prepare_m: a CAV leaving by an exit is confined, from this distance before the
            gore on, to a band at the road's right edge that narrows towards the exit's
            strip (the road's width here, the strip's width at ``exit_commit_m``), m.
        exit_commit_m: from this distance before the gore on it keeps to the strip; where
            it cannot get in, it waits before this point for a gap rather than pass its
            exit, m.
        exit_keep_clear_m: a CAV that stays on the road, with a human driver near, keeps
            this band beside an exit's strip free, from ``exit_commit_m`` before the
            strip's start to the gore: the room through which vehicles bound for the exit
            reach the strip (a human driver waiting there for a gap would otherwise wait for
            the CAV beside it, and it for him), m.
    Comparison:
        lateral_mode: "free" (the lane-free law) or "fixed": every CAV keeps the lateral
            position it entered with (rows, or lanes on a lane network): the same
            longitudinal law without lateral freedom, to isolate the lane-free gain.
    """

    time_gap_s: float = 0.55
    time_gap_hdv_s: float = 0.9
    standstill_gap_m: float = 2.5
    kp: float = 0.6
    kd: float = 0.95
    ff_gain: float = 0.6
    kp_hdv: float = 0.55
    kd_hdv: float = 1.6
    speed_gain: float = 0.6
    approach_gain: float = 1.5
    comfort_decel_mps2: float = 2.5
    spacing_error_min_m: float = -3.0
    spacing_error_max_m: float = 10.0
    anticipation_s: float = 1.0
    follow_margin_m: float = 0.35
    lat_gain: float = 0.6
    lat_damping: float = 1.6
    a_lat_bound_mps2: float = 1.0
    lateral_clearance_m: float = 0.5
    edge_margin_m: float = 0.2
    side_buffer_m: float = 2.2
    side_buffer_speed_s: float = 0.3
    side_buffer_s: float = 1.5
    cut_in_gap_m: float = 2.2
    cut_in_speed_margin_mps: float = 0.5
    repulsion_gain: float = 0.8
    replan_s: float = 0.5
    candidate_step_m: float = 0.3
    lookahead_s: float = 5.0
    lookahead_min_m: float = 400.0
    edge_lookahead_min_m: float = 100.0
    edge_lookahead_s: float = 8.0
    scan_margin_m: float = 0.35
    scan_time_gap_s: float = 4.0
    scan_decel_mps2: float = 1.0
    move_cost: float = 0.2
    clear_gain: float = 0.3
    clear_cap_m: float = 0.6
    nudge_gain: float = 0.3
    hysteresis_mps: float = 0.5
    congested_hysteresis_mps: float = 2.5
    row_pull: float = 1.0
    order_gain: float = 0.2
    urgent_gain_mps: float = 2.0
    queue_speed_mps: float = 10.0
    queue_hysteresis: float = 0.5
    bias_speed_low_mps: float = 25.0
    bias_speed_high_mps: float = 35.0
    coop_time_gap_s: float = 0.35
    yield_timeout_s: float = 8.0
    yield_cooldown_s: float = 6.0
    zipper_slack_m: float = 0.3
    human_follow_margin_m: float = 0.0
    mover_skips_followers: bool = False
    human_in_band_follows: bool = False
    squeezed_moves_to_middle: bool = True
    row_approach_gain: float = 0.0
    yield_decel_mps2: float = 2.0
    window: int = 16
    entry_reach_m: float = 6.0
    entry_horizon_s: float = 3.0
    squeeze_s: float = 3.0
    squeeze_min_m: float = 20.0
    exit_prepare_m: float = 1000.0
    exit_commit_m: float = 60.0
    exit_keep_clear_m: float = 2.2
    lateral_mode: str = "free"

    def __post_init__(self) -> None:
        if self.lateral_mode not in ("free", "fixed"):
            raise ParameterError(f"lateral_mode must be 'free' or 'fixed', got "
                                 f"{self.lateral_mode!r}")
        for name, value in self.__dict__.items():
            if name == "lateral_mode":
                continue
            if name in ("mover_skips_followers", "human_in_band_follows",
                        "squeezed_moves_to_middle"):
                if not isinstance(value, bool):
                    raise ParameterError(f"{name} must be true or false, got {value!r}")
                continue
            if name == "window":
                if isinstance(value, bool) or not isinstance(value, int) or value < 2:
                    raise ParameterError(f"window must be an integer >= 2, got {value!r}")
                continue
            if isinstance(value, bool) or not isinstance(value, int | float) \
                    or not np.isfinite(value):
                raise ParameterError(f"{name} must be a finite number, got {value!r}")
        positive = ("time_gap_s", "time_gap_hdv_s", "comfort_decel_mps2", "a_lat_bound_mps2",
                    "replan_s", "candidate_step_m", "lookahead_s", "scan_time_gap_s",
                    "coop_time_gap_s", "yield_decel_mps2", "speed_gain", "scan_decel_mps2",
                    "yield_timeout_s", "yield_cooldown_s")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ParameterError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("standstill_gap_m", "kp", "kd", "ff_gain", "kp_hdv", "kd_hdv",
                     "approach_gain", "row_approach_gain", "spacing_error_max_m",
                     "anticipation_s",
                     "follow_margin_m", "lat_gain", "lat_damping", "lateral_clearance_m",
                     "edge_margin_m", "side_buffer_m", "side_buffer_s", "repulsion_gain",
                     "side_buffer_speed_s", "zipper_slack_m",
                     "human_follow_margin_m", "lookahead_min_m", "edge_lookahead_min_m",
                     "edge_lookahead_s", "scan_margin_m", "move_cost", "clear_gain",
                     "clear_cap_m", "nudge_gain", "hysteresis_mps", "order_gain",
                     "bias_speed_low_mps", "urgent_gain_mps", "bias_speed_high_mps",
                     "queue_speed_mps", "queue_hysteresis", "congested_hysteresis_mps",
                     "entry_reach_m", "entry_horizon_s", "squeeze_s", "squeeze_min_m",
                     "cut_in_gap_m", "cut_in_speed_margin_mps", "exit_keep_clear_m"):
            if getattr(self, name) < 0:
                raise ParameterError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if self.spacing_error_min_m > 0:
            raise ParameterError("spacing_error_min_m must be <= 0")
        if self.ff_gain > 1:
            raise ParameterError(f"ff_gain must be in [0, 1], got {self.ff_gain!r}")
        if not 0 < self.exit_commit_m < self.exit_prepare_m:
            raise ParameterError(f"exit_commit_m must be > 0 and < exit_prepare_m, got "
                                 f"{self.exit_commit_m!r} (exit_prepare_m "
                                 f"{self.exit_prepare_m!r})")
        if not 0 <= self.row_pull <= 1:
            raise ParameterError(f"row_pull must be in [0, 1], got {self.row_pull!r}")

    def string_stability_margin(self) -> float:
        """``k_p T^2 + 2 k_d T - 2 (1 - k_ff)`` (>= 0: the low-frequency condition holds)."""
        T = self.time_gap_s
        return self.kp * T * T + 2 * self.kd * T - 2 * (1 - self.ff_gain)

    def string_stability_margin_hdv(self) -> float:
        """The same condition behind a human driver (ACC: no shared acceleration),
        ``k_p,hdv T_hdv^2 + 2 k_d,hdv T_hdv - 2`` (>= 0: it holds). Default 0.45 + 2.88 - 2;
        at ``time_gap_hdv_s`` = 0.5 s ``kd_hdv`` must be at least 1.86 1/s."""
        T = self.time_gap_hdv_s
        return self.kp_hdv * T * T + 2 * self.kd_hdv * T - 2
