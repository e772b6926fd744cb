"""``flocking``: lane-free flocking for roads: car following, lateral purpose, cooperation.

The law keeps the seeds' form ``u_i = u_alpha + u_beta + u_gamma`` (Olfati-Saber 2006,
Algorithm 3; seed 000): interaction terms with the other CAVs (alpha-agents, connected:
they share their state, their applied acceleration and their lateral intention), with
the non-cooperating road users, the road edges and a stopped obstacle (beta-agents), and a
navigation term towards each CAV's own reference (gamma-agent: its desired speed along the
road and a lateral position it chooses). The axes are composed as road vehicles need:

**Longitudinal** (``u_s``): the navigation term and one interaction term per leader, of
which the smallest acts (the interaction terms are one-sided: they only ever slow a CAV,
as a repulsive potential ahead would)::

    u_s = min( k_v (v_des - v),                                   gamma: desired speed
               min_j  k_p (g_j - s0 - T_j v) + k_d (v_j - v) + k_ff,j a_j,   alpha/beta
               min_j  k_a (v_safe(g_j, v_j) - v) )                 approach bound

over the leaders ``j``: vehicles ahead that overlap the CAV laterally now or within
``anticipation_s`` (their lateral motion and its own), and CAVs that announced a move into
its band from ahead (*virtual leaders*, cooperation). ``g_j`` is the bumper-to-bumper gap,
``T_j`` the time gap (``time_gap_s`` behind a CAV, ``time_gap_hdv_s`` behind others),
``a_j`` the leader's applied acceleration (CAVs share it: ``k_ff = ff_gain``; others:
``k_ff = 0``). ``v_safe = -b tau + sqrt((b tau)^2 + v_j^2 + 2 b (g - s0))`` with the
comfortable deceleration ``b`` bounds the speed when closing in on a slow or stopped
vehicle from far (e.g. an obstacle), which the linear term alone does not. The spacing
error is clipped below at ``spacing_error_min_m`` so a cut-in at a safe gap does not cause
harsh braking, and the linear term acts only within ``spacing_error_max_m`` of the
desired gap (beyond it the approach bound alone brings the CAV in).

*String stability* (one step of actuation delay, ``dt`` = 0.1 s): for the linearised
CAV-behind-CAV law the low-frequency condition is ``k_p T^2 + 2 k_d T >= 2 (1 - k_ff)``
(here 0.6 x 0.55^2 + 2 x 0.95 x 0.55 = 1.23 >= 0.8, margin 0.43) and ``|G(e^{j w dt})| <= 1``
at all frequencies holds for ``k_p = 0.6, k_d = 0.95, k_ff = 0.6`` from T = 0.4 to 1.2 s with
one or two steps of delay (checked numerically; ``tests/test_lanefree_law.py`` checks a
20-CAV platoon's speed dip shrinking along the string). Behind human drivers
(no shared acceleration) the ACC gains ``k_p = 0.55, k_d = 1.6`` with T = 0.9 s keep
the condition (0.45 + 2.88 >= 2).

**Lateral** (``u_d``): each CAV chooses a lateral target ``d*`` every ``replan_s`` (staggered)
by scoring candidate positions across the road ahead (``candidate_step_m`` apart, inside the
narrowest edges over the next ``lookahead_s`` of travel)::

    J(y) = v_offer(y) - c_move |y - d| + c_clear min(clearance(y), c) - c_nudge n(y)
           - c_order |y - y_pref(v_des)|

``v_offer(y)``: the speed the band at ``y`` offers (the slowest vehicle ahead in it, by the
same approach bound and time gap; ``v_des`` if free): CAVs overtake slower vehicles
through free lateral space and leave a blocked band (obstacle, narrowing) early.
``clearance(y)``: the lateral clearance at ``y`` to the vehicles alongside: as density
rises and every band offers the same speed, CAVs spread into the gaps, so rows form from
the vehicles' widths, not from slots. ``n(y)``: the desired-speed excess of CAVs close
behind in the band over this CAV's own desired speed, when this CAV drives at its desired
speed (nudging: a slower CAV that is the bottleneck makes room; in congestion nobody is
nudged). ``y_pref``: a weak
order by desired speed, slower to the right (a tie-breaker that keeps bands free for
overtaking at low density; 8 m of road weigh 0.8 m/s). The target changes only when the gain exceeds
``hysteresis_mps``. Then a PD navigation term with barrier repulsion::

    u_d = k_y (d* - d) - c_y v_d + sum_j repulsion(clearance_ij)

bounded (boundary control, as TrafficFluid's boundary controllers) so that the CAV can stop
laterally, at ``a_lat_bound``, before coming closer than ``lateral_clearance_m`` to a vehicle
alongside (longitudinally overlapping, with a closing-speed buffer, or one it could not be
followed by or follow safely) or ``edge_margin_m`` to the road edge ahead.

The tie-breakers (clearance, order) weigh only for a CAV near its desired speed (their
weight falls from 1 at 95 % to 0 at 75 % of it): in dense traffic a lateral move must pay
in speed.

**Cooperation** (CAVs are connected): a CAV whose move pays in speed
(``urgent_gain_mps``) or leaves a blocked band, and is still more than half its width from
its target, announces
its target band; a CAV behind it in that band treats it as a virtual leader projected into
its own lane-free position, with time gap ``coop_time_gap_s``, braking at most at
``yield_decel_mps2`` (politeness); a CAV ahead of it does nothing, so the mover slots in
behind: it treats the vehicles in its target band that are ahead of it as leaders at the
same time gap, braking at most at the comfortable deceleration. A CAV behind the mover that
would have to brake harder than ``yield_decel_mps2`` to let it in, or is already closer
behind it than the gap the mover needs beside it, goes on instead, and the mover, which
computes the same test, falls in behind it (zipper order: the one further ahead goes first
unless the other cannot let it in; nothing waits for a vehicle that waits for it). Human
drivers are not cooperative: a slow or stopped human driver whose own band is blocked
ahead is given the same yield by the CAVs behind it in the neighbouring bands, so it can
merge out (nobody traps it).

All terms are vectorised over the CAVs with a fixed window of neighbours in road order
(no N x N array); memory across steps (targets, last accelerations, speeds of others) is
keyed by vehicle id.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from controllers.observation import Observation
from controllers.params import ParameterError
from controllers.road_reference import leader_gaps


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
        window: neighbours in road order looked at on each side of a CAV.
        entry_reach_m: a vehicle outside the road within this distance of its edge (about
            to merge from an on-ramp) counts as on the road at its nearest inside
            position, m.
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
    yield_decel_mps2: float = 2.0
    window: int = 16
    entry_reach_m: float = 6.0
    lateral_mode: str = "free"

    def __post_init__(self) -> None:
        if self.lateral_mode not in ("free", "fixed"):
            raise ParameterError(f"lateral_mode must be 'free' or 'fixed', got "
                                 f"{self.lateral_mode!r}")
        for name, value in self.__dict__.items():
            if name == "lateral_mode":
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
                     "approach_gain", "spacing_error_max_m", "anticipation_s",
                     "follow_margin_m", "lat_gain", "lat_damping", "lateral_clearance_m",
                     "edge_margin_m", "side_buffer_m", "side_buffer_s", "repulsion_gain",
                     "side_buffer_speed_s", "zipper_slack_m",
                     "lookahead_min_m", "edge_lookahead_min_m",
                     "edge_lookahead_s", "scan_margin_m", "move_cost", "clear_gain",
                     "clear_cap_m", "nudge_gain", "hysteresis_mps", "order_gain",
                     "bias_speed_low_mps", "urgent_gain_mps", "bias_speed_high_mps",
                     "queue_speed_mps", "queue_hysteresis", "entry_reach_m",
                     "cut_in_gap_m", "cut_in_speed_margin_mps"):
            if getattr(self, name) < 0:
                raise ParameterError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if self.spacing_error_min_m > 0:
            raise ParameterError("spacing_error_min_m must be <= 0")
        if self.ff_gain > 1:
            raise ParameterError(f"ff_gain must be in [0, 1], got {self.ff_gain!r}")

    def string_stability_margin(self) -> float:
        """``k_p T^2 + 2 k_d T - 2 (1 - k_ff)`` (>= 0: the low-frequency condition holds)."""
        T = self.time_gap_s
        return self.kp * T * T + 2 * self.kd * T - 2 * (1 - self.ff_gain)


def _stable_hash(vid) -> int:
    """A hash of a vehicle id that is the same in every process (Python's is salted)."""
    return zlib.crc32(str(vid).encode())


@dataclass
class _Scene:
    """All vehicles of a step in one array set: CAVs first (rows 0..N-1), then the others."""

    s: np.ndarray
    d: np.ndarray
    v: np.ndarray
    v_lat: np.ndarray
    length: np.ndarray
    width: np.ndarray
    accel: np.ndarray
    is_cav: np.ndarray
    static: np.ndarray  # a non-CAV never seen moving (a stopped obstacle)
    n: int


class LaneFreeFlocking:
    """The lane-free flocking law (see the module docstring).

    Args:
        params: the law's parameters.
        ctx: the run's context (step, actuator limits; :class:`controllers.registry.RoadContext`).
    """

    name = "flocking"

    def __init__(self, params: LaneFreeParams, ctx=None) -> None:
        self.params = params
        limits = getattr(ctx, "limits", None)
        self.long_min = getattr(limits, "long_min_mps2", -4.5)
        self.long_max = getattr(limits, "long_max_mps2", 2.6)
        self.lat_max = getattr(limits, "lat_max_mps2", 1.5)
        self.lat_speed_max = getattr(limits, "lat_speed_max_mps", 1.5)
        self.emergency_decel = getattr(limits, "emergency_decel_mps2", 9.0)
        self.reset()

    # ------------------------------------------------------------------ protocol
    def reset(self) -> None:
        self._u_prev: dict = {}  # CAV id -> last longitudinal command, m/s^2
        self._v_prev: dict = {}  # other id -> last speed, m/s
        self._moved: set = set()  # others seen moving (a stopped obstacle never is)
        self._yield_since: dict = {}  # (CAV id, vehicle id) -> time the yield began, s
        self._target: dict = {}  # CAV id -> lateral target d*, m
        self._urgent: dict = {}  # CAV id -> its move pays in speed (announced: others yield)
        self._urgent_now = np.zeros(0, bool)
        self._phase: dict = {}  # CAV id -> replanning slot
        self._k = 0
        self.stats = {"steps": 0, "cav_steps": 0, "target_changes": 0, "yields": 0}

    @property
    def lattice_m(self) -> tuple[float, float]:
        """Nominal spacing along the road at 25 m/s and twice it as range, m (flock metrics)."""
        p = self.params
        d = p.standstill_gap_m + 4.5 + p.time_gap_s * 25.0
        return d, 2.0 * d

    def extra_metrics(self) -> dict[str, float]:
        """Lateral target changes per CAV-step and yields per CAV-step (cooperation)."""
        n = max(self.stats["cav_steps"], 1)
        return {"target_change_rate": self.stats["target_changes"] / n,
                "yield_rate": self.stats["yields"] / n}

    # ------------------------------------------------------------------ the law
    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations (N, 2), m/s^2."""
        obs.check_finite()
        n = obs.n
        self._k += 1
        self.stats["steps"] += 1
        self.stats["cav_steps"] += n
        if n == 0:
            return np.zeros((0, 2))
        sc = self._scene(obs)
        ids = obs.ids.tolist()
        win = self._window(sc, obs.period_s)
        targets = self._targets(obs, sc, win, ids)
        u = np.empty((n, 2))
        side = self._side(obs, sc, win)
        u[:, 0] = self._longitudinal(obs, sc, win, targets, side)
        u[:, 1] = self._lateral(obs, sc, win, targets, side)
        u[:, 0] = np.clip(u[:, 0], self.long_min, self.long_max)
        u[:, 1] = np.clip(u[:, 1], -self.lat_max, self.lat_max)
        self._remember(obs, sc, ids, u)
        return u

    # ------------------------------------------------------------------ inputs
    def _scene(self, obs: Observation) -> _Scene:
        n = obs.n
        has_others = obs.others_q is not None and len(obs.others_q) > 0
        oq = obs.others_q if has_others else np.zeros((0, 2))
        op = obs.others_p if has_others else np.zeros((0, 2))
        ol = obs.others_length if has_others else np.zeros(0)
        ow = obs.others_width if has_others else np.zeros(0)
        oids = obs.others_ids.tolist() if (has_others and obs.others_ids is not None) else \
            [None] * len(oq)
        self._moved.update(i for i, v in zip(oids, op[:, 0], strict=True)
                           if i is not None and v > 0.5)
        u_prev = np.array([self._u_prev.get(i, 0.0) for i in obs.ids.tolist()])
        v_prev = np.array([self._v_prev.get(i, np.nan) if i is not None else np.nan
                           for i in oids])
        a_other = np.where(np.isfinite(v_prev), (op[:, 0] - v_prev) / obs.dt, 0.0)
        length = obs.length if obs.length is not None else np.full(n, 4.5)
        width = obs.width if obs.width is not None else np.full(n, 1.8)
        od = self._entering(obs, oq, ow) if len(oq) else oq[:, 1]
        return _Scene(
            s=np.concatenate([obs.q[:, 0], oq[:, 0]]),
            d=np.concatenate([obs.q[:, 1], od]),
            v=np.concatenate([obs.p[:, 0], op[:, 0]]),
            v_lat=np.concatenate([obs.p[:, 1], op[:, 1]]),
            length=np.concatenate([length, ol]),
            width=np.concatenate([width, ow]),
            accel=np.concatenate([u_prev, a_other]),
            is_cav=np.concatenate([np.ones(n, bool), np.zeros(len(oq), bool)]),
            static=np.concatenate([np.zeros(n, bool),
                                   np.array([i is not None and i not in self._moved
                                             and abs(v) < 0.5 for i, v in
                                             zip(oids, op[:, 0], strict=True)], dtype=bool)]),
            n=n,
        )

    def _entering(self, obs: Observation, oq: np.ndarray, ow: np.ndarray) -> np.ndarray:
        """Lateral positions (M,) m of the sensed vehicles as the law uses them: a vehicle
        still outside the road but within ``entry_reach_m`` of its edge (on an on-ramp
        about to merge) is taken to be on the road already, at its nearest inside
        position: CAVs behind it there keep their gap to it, CAVs beside it make room."""
        p = self.params
        d = oq[:, 1].copy()
        if obs.road is None:
            return d
        edges = obs.road.edges(oq[:, 0])
        lo = edges[:, 0] + 0.5 * ow + 0.1
        hi = edges[:, 1] - 0.5 * ow - 0.1
        out = np.maximum(lo - d, d - hi)  # > 0: outside by this much
        merging = (out > 0) & (out < p.entry_reach_m)
        d[merging] = np.clip(d[merging], lo[merging], np.maximum(lo, hi)[merging])
        return d

    def _window(self, sc: _Scene, period: float | None) -> dict:
        """Neighbours of each CAV in road order: index ``j`` (N, K), ``ds`` (N, K) m (wrapped
        on a ring; inf where there is none), ``dd`` (N, K) m."""
        n, m = sc.n, len(sc.s)
        order = np.argsort(sc.s, kind="stable")
        rank = np.empty(m, dtype=np.intp)
        rank[order] = np.arange(m)
        k_side = min(self.params.window, max((m - 1) // 2, 1)) if period is not None else \
            self.params.window
        offs = np.concatenate([np.arange(-k_side, 0), np.arange(1, k_side + 1)])
        pos = rank[:n, None] + offs[None, :]
        if period is None:
            valid = (pos >= 0) & (pos < m)
            j = order[np.clip(pos, 0, m - 1)]
        else:
            valid = np.ones(pos.shape, bool)
            if 2 * k_side >= m:  # few vehicles: each neighbour once
                valid &= (offs[None, :] > 0) | (offs[None, :] >= -(m - 1 - k_side))
                valid &= np.abs(offs)[None, :] <= m - 1
            j = order[np.mod(pos, m)]
        valid &= j != np.arange(n)[:, None]
        ds = sc.s[j] - sc.s[:n, None]
        if period is not None:
            ds = (ds + 0.5 * period) % period - 0.5 * period
        ds = np.where(valid, ds, np.inf)
        dd = sc.d[j] - sc.d[:n, None]
        return {"j": j, "ds": ds, "dd": dd, "valid": valid}

    # ------------------------------------------------------------------ lateral target
    def _targets(self, obs: Observation, sc: _Scene, win: dict, ids: list) -> np.ndarray:
        """Lateral targets d* (N,) m: kept, or re-chosen for the CAVs whose turn it is."""
        p = self.params
        n = sc.n
        every = max(1, int(round(p.replan_s / obs.dt)))
        target = np.array([self._target.get(i, np.nan) for i in ids])
        urgent = np.array([self._urgent.get(i, False) for i in ids])
        slot = np.array([self._phase.setdefault(i, _stable_hash(i) % every) for i in ids])
        due = np.isnan(target) | (slot == self._k % every)
        lo, hi = self._band_limits(obs, sc)
        if p.lateral_mode == "fixed":  # rows (or lanes) fixed where each CAV entered
            target = np.where(np.isnan(target), sc.d[:n], target)
            due[:] = False
        if due.any():
            rows = np.flatnonzero(due)
            best, gain, need = self._plan(obs, sc, win, rows, target[rows], lo[rows], hi[rows])
            # in a slow queue lateral moves do not pay: the bar rises as the speed falls
            bar = p.hysteresis_mps + p.queue_hysteresis * np.maximum(
                p.queue_speed_mps - sc.v[rows], 0.0)
            changed = np.isnan(target[rows]) | (gain > bar) | need
            self.stats["target_changes"] += int(np.count_nonzero(
                changed & ~np.isnan(target[rows])))
            target[rows] = np.where(changed, best, target[rows])
            urgent[rows] = np.where(changed, need, urgent[rows] & (need | ~changed))
        # a target outside the road ahead (narrowing) is pulled inside at once
        target = np.clip(target, lo, np.maximum(lo, hi))
        arrived = (np.abs(target - sc.d[:n]) < 0.5 * sc.width[:n]) & (sc.d[:n] >= lo - 0.05) & (
            sc.d[:n] <= hi + 0.05)  # and inside the road ahead
        urgent &= ~arrived
        for i, t, u in zip(ids, target, urgent, strict=True):
            self._target[i] = float(t)
            self._urgent[i] = bool(u)
        self._urgent_now = urgent
        return target

    def _band_limits(self, obs: Observation, sc: _Scene) -> tuple[np.ndarray, np.ndarray]:
        """Lowest and highest lateral centre (N,) m inside the road ahead (look-ahead)."""
        p = self.params
        n = sc.n
        w = sc.width[:n]
        if obs.road is not None:
            ahead = np.maximum(p.edge_lookahead_min_m, sc.v[:n] * p.edge_lookahead_s)
            edges = obs.road.narrowest(sc.s[:n], ahead)
        elif obs.road_edges is not None:
            edges = obs.road_edges
        else:
            edges = np.column_stack([np.full(n, -np.inf), np.full(n, np.inf)])
        if obs.road_edges is not None:  # never wider than what the loop enforces
            edges = np.column_stack([np.maximum(edges[:, 0], obs.road_edges[:, 0]),
                                     np.minimum(edges[:, 1], obs.road_edges[:, 1])])
        self._edges_plan = edges
        lo = edges[:, 0] + 0.5 * w + p.edge_margin_m
        hi = edges[:, 1] - 0.5 * w - p.edge_margin_m
        return lo, hi

    def _plan(self, obs, sc, win, rows, current, lo, hi):
        """Best candidate (R,) m and its score gain over the current target (R,) m/s."""
        p = self.params
        n_c = max(2, int(np.ceil((np.max(hi - lo) if len(hi) else 0.0) / p.candidate_step_m)) + 1)
        frac = np.linspace(0.0, 1.0, n_c)
        cand = lo[:, None] + (np.maximum(hi - lo, 0.0))[:, None] * frac[None, :]  # (R, C)
        j = win["j"][rows]
        ds = win["ds"][rows]
        w_i = sc.width[rows]
        l_i = sc.length[rows]
        v_i = sc.v[rows]
        v_des = np.asarray(obs.desired_speed, dtype=float)[rows] if obs.desired_speed \
            is not None else np.full(len(rows), 30.0)
        d_i = sc.d[rows]
        # --- offered speed of each band (the slowest vehicle ahead in it)
        gap = ds - 0.5 * (l_i[:, None] + sc.length[j])  # (R, K)
        ahead = (ds > 0) & np.isfinite(ds)
        v_j = sc.v[j]
        g0 = np.maximum(gap - p.standstill_gap_m, 0.0)
        b = p.scan_decel_mps2  # gentler than the approach bound: decide before braking
        v_pass = np.minimum(v_j + g0 / p.scan_time_gap_s, np.sqrt(v_j * v_j + 2 * b * g0))
        v_pass = np.where(ahead, v_pass, np.inf)
        reach = 0.5 * (w_i[:, None] + sc.width[j]) + p.scan_margin_m  # (R, K)
        lat = np.abs(sc.d[j][:, None, :] - cand[:, :, None])  # (R, C, K)
        in_band = lat < reach[:, None, :]
        offer = np.min(np.where(in_band, v_pass[:, None, :], np.inf), axis=2)
        offer = np.minimum(offer, v_des[:, None])
        # a band that ends at a stopped obstacle (a vehicle never seen moving) within the
        # look-ahead offers nothing in the long run, however far the obstacle still is
        # (obstacles are few: every one is looked at, not only those in the window)
        look = np.maximum(p.lookahead_min_m, v_i * p.lookahead_s)
        blocked = np.zeros(cand.shape, bool)
        for k in np.flatnonzero(sc.static):
            ds_k = sc.s[k] - sc.s[rows]
            if obs.period_s is not None:
                ds_k = np.mod(ds_k, obs.period_s)
            g_k = ds_k - 0.5 * (l_i + sc.length[k])
            near = (ds_k > 0) & (g_k < look)
            reach_k = 0.5 * (w_i + sc.width[k]) + p.scan_margin_m
            blocked |= near[:, None] & (np.abs(sc.d[k] - cand) < reach_k[:, None])
        offer = np.where(blocked, 0.0, offer)
        # --- clearance to the vehicles alongside at each candidate
        along = np.abs(ds) < 0.5 * (l_i[:, None] + sc.length[j]) + p.side_buffer_m
        side_gap = lat - 0.5 * (w_i[:, None, None] + sc.width[j][:, None, :])
        clear = np.min(np.where(along[:, None, :], side_gap, np.inf), axis=2)
        clear = np.clip(clear, -1.0, p.clear_cap_m)
        # --- nudging: a CAV close behind that wants to go faster than this one wants to
        # (this CAV, free of its own leader, is the bottleneck) asks it to make room
        behind = (ds < 0) & np.isfinite(ds) & sc.is_cav[j]
        v_des_all = self._desired_all(obs, sc)
        free = v_i > v_des - 1.0  # not held up itself
        eager = np.where(free[:, None], np.maximum(v_des_all[j] - v_des[:, None] - 1.0, 0.0),
                         0.0)
        close = behind & (-gap < 2.0 * np.maximum(sc.v[j], 5.0))  # within 2 s behind
        nudge = np.sum(np.where(in_band & (close & (eager > 0))[:, None, :],
                                eager[:, None, :], 0.0), axis=2)
        # weak order by desired speed (slower to the right), a tie-breaker that keeps
        # bands free for overtaking at low density (TUM's potential lines, much weaker)
        rank = np.clip((v_des - p.bias_speed_low_mps)
                       / max(p.bias_speed_high_mps - p.bias_speed_low_mps, 1e-9), 0.0, 1.0)
        y_pref = lo + (hi - lo) * rank
        # tie-breakers (clearance, order) only for a CAV that drives near its desired
        # speed: in dense traffic a lateral move must pay in speed, or it only disturbs
        free_w = np.clip((v_i / np.maximum(v_des, 1.0) - 0.75) / 0.2, 0.0, 1.0)[:, None]
        score = (offer - p.move_cost * np.abs(cand - d_i[:, None])
                 + free_w * (p.clear_gain * clear
                             - p.order_gain * np.abs(cand - y_pref[:, None]))
                 - p.nudge_gain * nudge)
        k_best = np.argmax(score, axis=1)
        r = np.arange(len(rows))
        best = cand[r, k_best]
        # score of the current target: the nearest candidate
        cur = np.where(np.isnan(current), d_i, current)
        k_cur = np.argmin(np.abs(cand - cur[:, None]), axis=1)
        gain = score[r, k_best] - score[r, k_cur]
        # the move is announced (others yield) only when it pays in speed or the band
        # here is blocked (a stopped obstacle ahead)
        k_here = np.argmin(np.abs(cand - d_i[:, None]), axis=1)
        offer_here = offer[r, k_here]
        # outside the road ahead (a narrowing): leaving is urgent too
        outside = (d_i < lo - 0.05) | (d_i > hi + 0.05)
        need = (blocked[r, k_here] | outside) & (gain > 0) & ~blocked[r, k_best]
        need |= (offer[r, k_best] - offer_here > np.maximum(p.urgent_gain_mps, 0.3 * v_i)) & (
            v_i > p.queue_speed_mps) & (gain > 0)
        return best, gain, need

    def _desired_all(self, obs, sc) -> np.ndarray:
        """Desired speeds of all vehicles, m/s (others: their current speed + 0)."""
        v_des = np.asarray(obs.desired_speed, dtype=float) if obs.desired_speed is not None \
            else np.full(sc.n, 30.0)
        return np.concatenate([v_des, sc.v[sc.n:]])

    # ------------------------------------------------------------------ longitudinal
    def _longitudinal(self, obs, sc, win, targets, side) -> np.ndarray:
        p = self.params
        n = sc.n
        v = sc.v[:n]
        v_des = np.asarray(obs.desired_speed, dtype=float) if obs.desired_speed is not None \
            else np.full(n, 30.0)
        u = p.speed_gain * (v_des - v)
        # primary leader in the current band, searched as far as braking needs
        reach = float(np.max(v)) ** 2 / (2 * p.comfort_decel_mps2) + 30.0 if n else 30.0
        gap, v_l = leader_gaps(sc.s, sc.d, sc.length, sc.width, np.arange(n), reach_m=reach,
                               period=obs.period_s, lateral_margin_m=p.follow_margin_m, v=sc.v)
        has = np.isfinite(gap)
        u = np.minimum(u, np.where(has, self._approach(gap, v_l, v), np.inf))
        # a narrowing ahead that this CAV's body does not fit into where it is: its start
        # is a stopped wall for the approach bound (the CAV merges or waits before it)
        if obs.road is not None and not obs.road.is_constant:
            u = np.minimum(u, self._narrowing(obs, sc, side))
        # window leaders: overlapping now or within the anticipation horizon
        j, ds = win["j"], win["ds"]
        g = ds - 0.5 * (sc.length[:n, None] + sc.length[j])
        ahead = (ds > 0) & np.isfinite(ds)
        half = 0.5 * (sc.width[:n, None] + sc.width[j])
        lat_gap = np.abs(win["dd"]) - half
        # relative lateral motion over the horizon (both vehicles), and this CAV's own
        # move towards its target
        rel_vlat = sc.v_lat[j] - sc.v_lat[:n, None]
        closing = np.where(win["dd"] > 0, -rel_vlat, rel_vlat)
        lat_future = lat_gap - np.maximum(closing, 0.0) * p.anticipation_s
        leader = ahead & (np.minimum(lat_gap, lat_future) < p.follow_margin_m)
        u_f = self._follow(g, sc.v[j], sc.accel[j], sc.is_cav[j], v[:, None], p.time_gap_s,
                           p.time_gap_hdv_s)
        u_f = np.minimum(u_f, self._approach(g, sc.v[j], v[:, None]))
        u = np.minimum(u, np.min(np.where(leader, u_f, np.inf), axis=1))
        # cooperation: yield to movers announced into this CAV's band from ahead, and to
        # held-up human drivers next to it
        u_y = self._yield(obs, sc, win, targets, g, ahead)
        u = np.minimum(u, u_y)
        # zipper: an announced mover slots in behind every vehicle in its target band that
        # is ahead of it, or behind it but unable to let it in (it would have to brake
        # harder than yield_decel_mps2 to fall back behind the mover)
        mover = self._urgent_now
        if mover.any():
            in_target = np.abs(sc.d[j] - targets[:, None]) < half + p.follow_margin_m
            # what a vehicle behind would need to let this mover in, m/s^2
            g_back = -ds - 0.5 * (sc.length[:n, None] + sc.length[j])
            u_let = self._follow(g_back, v[:, None], sc.accel[:n, None], np.ones_like(g, bool),
                                 sc.v[j], p.coop_time_gap_s, p.coop_time_gap_s)
            u_let = np.where(np.isfinite(u_let), u_let, 0.0)
            # ... or already too close behind to open the gap the mover needs beside it
            passes = (ds <= 0) & ((u_let < -p.yield_decel_mps2)
                                  | (g_back < p.side_buffer_m + p.zipper_slack_m))
            z = mover[:, None] & in_target & ((ds > 0) | passes) & np.isfinite(ds) & ~leader
            u_z = self._follow(g, sc.v[j], sc.accel[j], sc.is_cav[j], v[:, None],
                               p.coop_time_gap_s, p.coop_time_gap_s)
            u_z = np.maximum(u_z, -p.comfort_decel_mps2)
            u = np.minimum(u, np.min(np.where(z, u_z, np.inf), axis=1))
        return u

    def _narrowing(self, obs, sc, side) -> np.ndarray:
        """Approach bound (N,) m/s^2 to the start of the first road piece ahead (within the
        look-ahead) whose edges exclude the CAV's body at its lateral position by more than
        it can still move sideways before it gets there; inf if none."""
        p = self.params
        n = sc.n
        road = obs.road
        s, d = sc.s[:n], sc.d[:n]
        half_w = 0.5 * sc.width[:n] + 0.1
        ds = road.s0[None, :] - s[:, None]  # (N, K)
        if road.periodic:
            ds = np.mod(ds, road.length_m)
        look = np.maximum(p.edge_lookahead_min_m, sc.v[:n] * p.lookahead_s)
        # lateral shift the body needs to fit the piece, and what it can still do before
        # reaching it (half the lateral speed limit and half the bound deceleration)
        need = np.maximum(road.right[None, :] - (d[:, None] - half_w[:, None]),
                          (d[:, None] + half_w[:, None]) - road.left[None, :])
        t_avail = np.maximum(ds, 0.0) / np.maximum(sc.v[:n], 1.0)[:, None]
        can = np.minimum(0.5 * self.lat_speed_max * t_avail,
                         0.25 * p.a_lat_bound_mps2 * t_avail**2)
        # a vehicle alongside on the side the CAV must move to blocks it now
        to_left = road.right[None, :] > d[:, None] - half_w[:, None]
        room = np.where(to_left, side["hi"][:, None] - d[:, None],
                        d[:, None] - side["lo"][:, None])
        can = np.minimum(can, np.maximum(room, 0.0) + 0.1)
        wall = (ds > 0) & (ds < look[:, None]) & (need > can)
        if not wall.any():
            return np.full(n, np.inf)
        g = np.min(np.where(wall, ds, np.inf), axis=1) - 0.5 * sc.length[:n]
        return np.where(np.isfinite(g), self._approach(g, np.zeros(n), sc.v[:n]), np.inf)

    def _follow(self, g, v_j, a_j, j_cav, v, t_cav, t_hdv) -> np.ndarray:
        """CACC (CAV leaders) or ACC (others) command, m/s^2, element-wise; inf for a leader
        beyond the linear law's range (spacing error above ``spacing_error_max_m``), where
        the approach bound alone acts."""
        p = self.params
        T = np.where(j_cav, t_cav, t_hdv)
        raw = g - p.standstill_gap_m - T * v
        err = np.maximum(raw, p.spacing_error_min_m)
        kp = np.where(j_cav, p.kp, p.kp_hdv)
        kd = np.where(j_cav, p.kd, p.kd_hdv)
        kff = np.where(j_cav, p.ff_gain, 0.0)
        u = kp * err + kd * (v_j - v) + kff * np.clip(a_j, self.long_min, self.long_max)
        return np.where(raw <= p.spacing_error_max_m, u, np.inf)

    def _approach(self, g, v_j, v) -> np.ndarray:
        """Approach bound ``k_a (v_safe - v)``: come down to the leader's speed at the
        comfortable deceleration before the gap falls to s0, m/s^2."""
        p = self.params
        b = p.comfort_decel_mps2
        tau = 0.5
        g0 = g - p.standstill_gap_m
        vj = np.maximum(v_j, 0.0)
        root = np.sqrt(np.maximum((b * tau) ** 2 + vj * vj + 2 * b * g0, 0.0))
        v_safe = np.where(g0 > 0, -b * tau + root, 0.0)
        v_safe = np.maximum(v_safe, np.minimum(vj, np.maximum(g0, 0.0)))  # never below 0
        return p.approach_gain * (v_safe - v)

    def _yield(self, obs, sc, win, targets, g, ahead) -> np.ndarray:
        """Cooperative gap opening (N,) m/s^2 (inf where nobody asks)."""
        p = self.params
        n = sc.n
        j = win["j"]
        j_cav = sc.is_cav[j]
        # announced target of each neighbour CAV (its own position if none or not a CAV)
        tgt_all = sc.d.copy()
        tgt_all[:n] = targets
        moving = np.zeros(len(sc.s), bool)
        moving[:n] = self._urgent_now
        # a mover ahead whose target band overlaps this CAV (now) asks it to open a gap
        half = 0.5 * (sc.width[:n, None] + sc.width[j])
        into = np.abs(tgt_all[j] - sc.d[:n, None]) < half + p.follow_margin_m
        not_yet = np.abs(win["dd"]) >= half  # not already a leader in this band
        mover = j_cav & moving[j] & into & not_yet & ahead
        # a held-up human driver next to this CAV (slow, blocked ahead in its own band)
        held = self._held(obs, sc)
        near_side = np.abs(win["dd"]) < half + 2.5
        human = (~j_cav) & held[j] & near_side & ahead & (np.abs(win["dd"]) >= half)
        ask = mover | human
        if not ask.any():
            return np.full(n, np.inf)
        v = sc.v[:n, None]
        u_c = self._follow(g, sc.v[j], sc.accel[j], j_cav, v, p.coop_time_gap_s,
                           p.coop_time_gap_s)
        # polite, never harsh: a CAV that would have to brake harder to let a mover in goes
        # on, and the mover falls in behind it (the zipper rule, computed alike by both)
        ask &= ~(j_cav & ((u_c < -p.yield_decel_mps2)
                          | (g < p.side_buffer_m + p.zipper_slack_m)))
        # nothing waits forever: a CAV lets the same vehicle in for at most
        # yield_timeout_s, then goes on for yield_cooldown_s (a human driver who does not
        # take the gap, or a mover that cannot move, must not stop the band behind it)
        ask &= self._patience(obs, sc, j, ask)
        u_c = np.maximum(u_c, -p.yield_decel_mps2)
        u_c = np.where(ask, u_c, np.inf)
        out = np.min(u_c, axis=1)
        self.stats["yields"] += int(np.count_nonzero(np.isfinite(out) & (out < 0)))
        return out

    def _patience(self, obs, sc, j, ask) -> np.ndarray:
        """``ask`` (N, K) without the pairs a CAV has yielded to too long (memory by ids)."""
        p = self.params
        t = float(obs.t)
        ids_all = list(obs.ids.tolist()) + (list(obs.others_ids.tolist())
                                            if obs.others_ids is not None else
                                            [None] * (len(sc.s) - sc.n))
        keep = ask.copy()
        seen = set()
        rows, cols = np.nonzero(ask)
        for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
            key = (obs.ids[r], ids_all[j[r, c]])
            seen.add(key)
            start = self._yield_since.setdefault(key, t)
            waited = t - start
            if waited > p.yield_timeout_s:
                keep[r, c] = False
                if waited > p.yield_timeout_s + p.yield_cooldown_s:
                    self._yield_since[key] = t  # patience again
        for key in [k for k, t0 in self._yield_since.items()
                    if k not in seen and t - t0 <= p.yield_timeout_s]:
            del self._yield_since[key]  # the pair ended before the timeout
        return keep

    def _held(self, obs, sc) -> np.ndarray:
        """Non-CAVs (M,) that have moved, are now slower than 3 m/s and have a vehicle ahead
        in their band within 15 m: they want to merge out and must not be trapped (a
        stopped obstacle, which never moved, is not held up)."""
        n = sc.n
        m = len(sc.s)
        out = np.zeros(m, bool)
        if m == n or obs.others_ids is None:
            return out
        rows = np.arange(n, m)
        moved = np.array([i in self._moved for i in obs.others_ids.tolist()], dtype=bool)
        slow = rows[(sc.v[rows] < 3.0) & moved]
        if not len(slow):
            return out
        gap, _ = leader_gaps(sc.s, sc.d, sc.length, sc.width, slow, reach_m=40.0,
                             period=obs.period_s, v=sc.v)
        out[slow] = gap < 15.0
        return out

    # ------------------------------------------------------------------ lateral
    def _side(self, obs, sc, win) -> dict:
        """Vehicles alongside each CAV (N, K) and the lateral bounds (N,) m they set: the
        CAV may not come closer to them than ``lateral_clearance_m`` (plus their step)."""
        p = self.params
        n = sc.n
        j, ds = win["j"], win["ds"]
        half_l = 0.5 * (sc.length[:n, None] + sc.length[j])
        half_w = 0.5 * (sc.width[:n, None] + sc.width[j])
        closing_long = np.where(ds > 0, sc.v[:n, None] - sc.v[j], sc.v[j] - sc.v[:n, None])
        v_rear = np.where(ds > 0, sc.v[:n, None], sc.v[j])
        buf = (p.side_buffer_m + p.side_buffer_speed_s * v_rear
               + p.side_buffer_s * np.maximum(closing_long, 0.0))
        along = (np.abs(ds) < half_l + buf) & np.isfinite(ds)
        # a vehicle that could not follow (or be followed) at this distance within its
        # emergency braking (Krauss's safe speed, one step of reaction, both braking at
        # the emergency deceleration) is alongside too: no unsafe cut-ins
        g_pair = np.abs(ds) - half_l - p.cut_in_gap_m
        v_follow = np.where(ds > 0, sc.v[:n, None], sc.v[j])
        v_lead = np.where(ds > 0, sc.v[j], sc.v[:n, None])
        b, tau = self.emergency_decel, obs.dt
        root = np.sqrt(np.maximum((b * tau) ** 2 + v_lead**2 + 2 * b * g_pair, 0.0))
        v_ok = np.where(g_pair < 0, 0.0, -b * tau + root)
        along |= np.isfinite(ds) & (v_follow > v_ok - p.cut_in_speed_margin_mps) & (
            v_follow > 0.01)  # at a standstill nobody cuts in
        shift = np.where(sc.is_cav[j], self.lat_speed_max * obs.dt, np.abs(sc.v_lat[j]) * obs.dt)
        need = half_w + p.lateral_clearance_m + shift
        hi_n = np.min(np.where(along & (win["dd"] >= 0), sc.d[j] - need, np.inf), axis=1)
        lo_n = np.max(np.where(along & (win["dd"] < 0), sc.d[j] + need, -np.inf), axis=1)
        return {"along": along, "half_w": half_w, "hi": hi_n, "lo": lo_n}

    def _lateral(self, obs, sc, win, targets, side) -> np.ndarray:
        p = self.params
        n = sc.n
        d, vl = sc.d[:n], sc.v_lat[:n]
        u = p.lat_gain * (targets - d) - p.lat_damping * vl
        # barrier repulsion from vehicles alongside
        along, half_w = side["along"], side["half_w"]
        side_gap = np.abs(win["dd"]) - half_w
        push = np.where(along & (side_gap < 2.0 * p.lateral_clearance_m),
                        p.repulsion_gain * (2.0 * p.lateral_clearance_m - side_gap)
                        / (2.0 * p.lateral_clearance_m), 0.0)
        u -= np.sum(np.sign(win["dd"]) * push, axis=1)
        # boundary bounds: stop laterally before the clearance and the road edges
        hi_n, lo_n = side["hi"], side["lo"]
        a = p.a_lat_bound_mps2
        vmax = self.lat_speed_max
        # neighbours: never move closer than the clearance (no push back: theirs to keep)
        v_hi_n = np.minimum(np.where(hi_n > d, np.sqrt(2 * a * np.maximum(hi_n - d, 0.0)), 0.0),
                            vmax)
        v_lo_n = np.maximum(np.where(lo_n < d, -np.sqrt(2 * a * np.maximum(d - lo_n, 0.0)), 0.0),
                            -vmax)
        # road edges (narrowest over the target's look-ahead, longer than the safety
        # layer's): stop before them, and steer back in when outside already (the road
        # ahead narrows), early enough to be inside before the safety layer looks
        v_hi_e = np.full(n, vmax)
        v_lo_e = np.full(n, -vmax)
        edges = getattr(self, "_edges_plan", None)  # the target's look-ahead (longer)
        if edges is not None and len(edges) == n:
            w = sc.width[:n]
            hi_e = edges[:, 1] - 0.5 * w - p.edge_margin_m
            lo_e = edges[:, 0] + 0.5 * w + p.edge_margin_m
            v_hi_e = np.clip(np.sign(hi_e - d) * np.sqrt(2 * a * np.abs(hi_e - d)), -vmax, vmax)
            v_lo_e = np.clip(-np.sign(d - lo_e) * np.sqrt(2 * a * np.abs(d - lo_e)), -vmax, vmax)
            v_lo_e = np.minimum(v_lo_e, v_hi_e)  # a road narrower than the body: its centre
        want = vl + u * obs.dt
        v_next = np.clip(np.clip(want, v_lo_e, v_hi_e), v_lo_n, v_hi_n)  # neighbours first
        # squeezed between neighbours: hold still (their moves are bounded by their laws)
        v_next = np.where(v_lo_n > v_hi_n, 0.0, v_next)
        return (v_next - vl) / obs.dt

    # ------------------------------------------------------------------ memory
    def _remember(self, obs, sc, ids, u) -> None:
        present = set(ids)
        self._u_prev = {i: float(a) for i, a in zip(ids, u[:, 0], strict=True)}
        for gone in [k for k in self._target if k not in present]:
            del self._target[gone]
            self._phase.pop(gone, None)
            self._urgent.pop(gone, None)
        if obs.others_ids is not None and sc.n < len(sc.s):
            oids = obs.others_ids.tolist()
            self._v_prev = {i: float(v) for i, v in zip(oids, sc.v[sc.n:], strict=True)}
            self._moved.intersection_update(oids)
        else:
            self._v_prev = {}
