"""Safety layer for road vehicles: clips a command only when it is unsafe.

Pure numpy, road frame (axis 0 = ``s`` along the road, axis 1 = ``d`` across,
left positive), vehicles are rectangles centred at ``(s, d)``.

Rules, applied in this order to CAV ``i`` with command ``u_i``:

1. **Road edges** (lateral): the next lateral position keeps the body at
   least ``edge_margin`` inside the road, and the lateral speed towards an
   edge never exceeds ``sqrt(2 a_lat g)`` with ``g`` the remaining distance, so
   the vehicle can always stop laterally before the edge. The edges are the
   narrowest within the vehicle's stopping distance (the caller's choice); a
   narrowing further ahead that the body does not fit into is a stopped
   leader for rule 3 (``wall_gap``), so a CAV that cannot move in stops before it.
2. **Side clearance** (lateral): vehicles that overlap longitudinally (with a
   speed-dependent buffer ahead and behind) bound the next lateral position so
   that the side-to-side clearance stays above ``lateral_clearance`` even if
   the neighbour also moves towards it in the same step (a CAV by up to
   ``lat_speed_max dt``, another vehicle by its current lateral speed times
   ``dt``); a vehicle never moves sideways into a gap that is already too small.
   **No unsafe cut-ins**: a neighbour also counts as beside, at any distance
   within reach, when sharing a band with it would leave the follower of the
   two (the CAV behind it, or it behind the CAV) faster than the Krauss safe
   speed of rule 3, so a CAV never moves sideways in front of a vehicle that
   could not stop behind it, nor behind one it could not stop behind.
3. **Safe speed** (longitudinal, Krauss 1998 / SUMO's default model): with
   ``g`` the bumper-to-bumper gap minus ``min_gap`` to the nearest vehicle
   ahead that overlaps laterally anywhere along the lateral move, the next speed
   is at most ``v_safe = -b tau + sqrt((b tau)^2 + v_l^2 b / b_l + 2 b g)``,
   which lets the CAV stop behind a leader braking at ``b_l`` after one
   reaction delay ``tau``, braking itself at ``b`` (the emergency deceleration).

Every activation is counted per rule.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .neighbours import cross_pairs
from .params import ParameterError


@dataclass(frozen=True)
class SafetyParams:
    """The safety layer's own parameters: the ``[safety]`` section of a scenario.

    The step, the emergency deceleration and the lateral limits come from the run
    (``[scenario]`` and ``[limits]``), never from here: see :meth:`SafetyConfig.for_run`.

    Attributes:
        enabled: apply the layer (default) or not (to study a raw law).
        reaction_steps: command delay assumed in the safe-speed rule, steps.
        min_gap_m: bumper-to-bumper standstill gap kept to the vehicle ahead, m.
        lateral_clearance_m: side-to-side clearance kept to vehicles beside, m.
        edge_margin_m: distance kept between the vehicle's side and the road edge, m.
        assumed_leader_decel_mps2: deceleration assumed for the vehicle ahead, m/s^2.
        cut_in_time_s: closing-speed buffer of the side rule: a vehicle closing in at
            ``dv`` counts as beside within ``dv * cut_in_time_s + min_gap_m``, s.
    """

    enabled: bool = True
    reaction_steps: int = 1
    min_gap_m: float = 2.0
    lateral_clearance_m: float = 0.3
    edge_margin_m: float = 0.1
    assumed_leader_decel_mps2: float = 9.0
    cut_in_time_s: float = 1.0

    def __post_init__(self) -> None:
        if isinstance(self.reaction_steps, bool) or not isinstance(self.reaction_steps, int) \
                or self.reaction_steps < 0:
            raise ParameterError(f"reaction_steps must be an integer >= 0, got "
                                 f"{self.reaction_steps!r}")
        for name in ("min_gap_m", "lateral_clearance_m", "edge_margin_m", "cut_in_time_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ParameterError(f"{name} must be finite and >= 0, got {v!r}")
        v = self.assumed_leader_decel_mps2
        if not (np.isfinite(v) and v > 0):
            raise ParameterError(f"assumed_leader_decel_mps2 must be finite and > 0, got {v!r}")


@dataclass
class SafetyConfig:
    """Everything the layer uses (SI); see the module docstring for the rules.

    Built for a run by :meth:`for_run` from :class:`SafetyParams`, the step and the
    actuator limits; the defaults serve unit tests.
    """

    dt: float = 0.1
    reaction_steps: int = 1
    min_gap_m: float = 2.0
    lateral_clearance_m: float = 0.3
    edge_margin_m: float = 0.1
    own_decel_mps2: float = 9.0
    leader_decel_mps2: float = 9.0
    lat_accel_mps2: float = 1.5
    lat_speed_max_mps: float = 1.5
    cut_in_time_s: float = 1.0

    @property
    def tau(self) -> float:
        return self.reaction_steps * self.dt

    @classmethod
    def for_run(cls, params: SafetyParams, dt: float, limits) -> SafetyConfig:
        """The layer's configuration for a run with step ``dt`` (s) and ``limits``
        (:class:`~controllers.constraints.ActuatorLimits`)."""
        return cls(
            dt=dt,
            reaction_steps=params.reaction_steps,
            min_gap_m=params.min_gap_m,
            lateral_clearance_m=params.lateral_clearance_m,
            edge_margin_m=params.edge_margin_m,
            own_decel_mps2=limits.emergency_decel_mps2,
            leader_decel_mps2=params.assumed_leader_decel_mps2,
            lat_accel_mps2=limits.lat_max_mps2,
            lat_speed_max_mps=limits.lat_speed_max_mps,
            cut_in_time_s=params.cut_in_time_s,
        )


def krauss_safe_speed(gap_m: np.ndarray, v_leader_mps: np.ndarray, c: SafetyConfig) -> np.ndarray:
    """Krauss (1998) safe speed, m/s, element-wise over pairs.

    ``gap_m`` is the bumper-to-bumper gap minus ``min_gap`` (m), ``v_leader_mps``
    the leader's speed; the follower reacts after ``tau`` and brakes at
    ``own_decel``, the leader at ``leader_decel``:
    ``v_safe = -b tau + sqrt((b tau)^2 + v_l^2 b / b_l + 2 b g)``, 0 for ``g < 0``.
    """
    b, bl, tau = c.own_decel_mps2, c.leader_decel_mps2, c.tau
    root = np.sqrt(np.maximum((b * tau) ** 2 + v_leader_mps**2 * b / bl + 2.0 * b * gap_m, 0.0))
    return np.where(gap_m < 0, 0.0, -b * tau + root)


@dataclass
class SafetyCounts:
    """Agent-steps in which each rule changed the command."""

    edge: int = 0
    side: int = 0
    speed: int = 0
    seen: int = 0

    def as_dict(self) -> dict[str, int]:
        return {
            "safety_edge_activations": self.edge,
            "safety_side_activations": self.side,
            "safety_speed_activations": self.speed,
            "safety_agent_steps": self.seen,
        }


@dataclass
class RoadState:
    """All vehicles on the road (M of them), SI units.

    ``s``, ``d`` (M,) centre positions, m; ``v`` (M,) longitudinal speed, m/s;
    ``length``, ``width`` (M,) m; ``v_lat`` (M,) lateral speed, m/s (None: 0).
    """

    s: np.ndarray
    d: np.ndarray
    v: np.ndarray
    length: np.ndarray
    width: np.ndarray
    v_lat: np.ndarray | None = None


@dataclass
class SafetyLayer:
    """Clip CAV commands for safety; ``apply`` returns the safe command and next lateral state."""

    config: SafetyConfig = field(default_factory=SafetyConfig)
    counts: SafetyCounts = field(default_factory=SafetyCounts)

    def apply(
        self,
        u: np.ndarray,
        cav_index: np.ndarray,
        v_lat: np.ndarray,
        road: RoadState,
        edges: np.ndarray,
        period: float | None = None,
        wall_gap: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Safe command for the CAVs.

        Args:
            u: (N, 2) commanded accelerations, m/s^2.
            cav_index: (N,) rows of the CAVs in ``road``.
            v_lat: (N,) current lateral speeds of the CAVs, m/s.
            road: all vehicles, CAVs included.
            edges: (N, 2) right and left road edge at each CAV, m.
            period: ring length, m, or None.
            wall_gap: (N,) distance from each CAV's front to the start of a road piece ahead
                that its body does not fit into at its lateral position (a narrowing), m;
                inf where none. The speed rule treats it as a stopped leader.

        Returns:
            (u_safe (N, 2), v_lat_next (N,)): the longitudinal acceleration to
            apply and the lateral speed for the next step (m/s).
        """
        c = self.config
        dt = c.dt
        n = len(cav_index)
        u = np.array(u, dtype=float, copy=True)
        self.counts.seen += n
        if n == 0:
            return u, np.zeros(0)
        s, d, v = road.s[cav_index], road.d[cav_index], road.v[cav_index]
        L, W = road.length[cav_index], road.width[cav_index]

        # 1. road edges ------------------------------------------------------------
        vl = np.clip(v_lat + u[:, 1] * dt, -c.lat_speed_max_mps, c.lat_speed_max_mps)
        lo = edges[:, 0] + 0.5 * W + c.edge_margin_m
        hi = edges[:, 1] - 0.5 * W - c.edge_margin_m
        room_left = np.maximum(hi - d, 0.0)
        room_right = np.maximum(d - lo, 0.0)
        cap_left = np.sqrt(2.0 * c.lat_accel_mps2 * room_left)
        cap_right = np.sqrt(2.0 * c.lat_accel_mps2 * room_right)
        vl_edge = np.clip(vl, -cap_right, cap_left)
        # Outside the allowed band already (e.g. entering a narrowing): steer back in
        # at the lateral acceleration limit.
        back_in = np.clip(v_lat - c.lat_accel_mps2 * dt, -c.lat_speed_max_mps, 0.0)
        back_out = np.clip(v_lat + c.lat_accel_mps2 * dt, 0.0, c.lat_speed_max_mps)
        vl_edge = np.where(d > hi, np.minimum(vl_edge, back_in), vl_edge)
        vl_edge = np.where(d < lo, np.maximum(vl_edge, back_out), vl_edge)
        d_next = d + vl_edge * dt
        d_next = np.clip(d_next, np.minimum(lo, d), np.maximum(hi, d))
        vl_edge = (d_next - d) / dt
        self.counts.edge += int(np.count_nonzero(np.abs(vl_edge - vl) > 1e-9))

        # neighbours within a longitudinal reach ------------------------------------
        reach = float(np.max(v)) * c.tau + float(np.max(v)) ** 2 / (2 * c.own_decel_mps2)
        reach += float(np.max(road.length)) + c.min_gap_m + 10.0
        xy_all = np.column_stack([road.s, road.d])
        pairs = cross_pairs(np.column_stack([s, d]), xy_all, reach, period)
        pairs = pairs[cav_index[pairs[:, 0]] != pairs[:, 1]]
        i, j = pairs[:, 0], pairs[:, 1]
        ds = road.s[j] - s[i]
        if period is not None:
            ds = (ds + 0.5 * period) % period - 0.5 * period
        half_l = 0.5 * (L[i] + road.length[j])
        half_w = 0.5 * (W[i] + road.width[j])

        # 2. side clearance ----------------------------------------------------------
        # Longitudinal overlap with a buffer for closing speed (cut-in protection).
        closing_ahead = np.maximum(v[i] - road.v[j], 0.0)  # i catches j ahead
        closing_behind = np.maximum(road.v[j] - v[i], 0.0)  # j catches i from behind
        buf = np.where(ds >= 0, closing_ahead, closing_behind) * c.cut_in_time_s + c.min_gap_m
        beside = np.abs(ds) < half_l + buf
        # Cut-in: the follower of the pair, were they in one band, must already be
        # within its Krauss safe speed (rule 3) of the other.
        ahead_j = ds >= 0
        v_follow = np.where(ahead_j, v[i], road.v[j])
        v_lead = np.where(ahead_j, road.v[j], v[i])
        gap_pair = np.abs(ds) - half_l - c.min_gap_m
        beside |= v_follow > krauss_safe_speed(gap_pair, v_lead, c) + 1e-9
        dd = road.d[j] - d[i]
        # Worst-case lateral step of the neighbour towards i during this step.
        shift = np.zeros(len(road.s)) if road.v_lat is None else np.abs(road.v_lat) * dt
        shift[cav_index] = c.lat_speed_max_mps * dt
        need = half_w + c.lateral_clearance_m + shift[j]
        hi_side = np.full(n, np.inf)
        lo_side = np.full(n, -np.inf)
        left = beside & (dd >= 0)
        right = beside & (dd < 0)
        np.minimum.at(hi_side, i[left], road.d[j[left]] - need[left])
        np.maximum.at(lo_side, i[right], road.d[j[right]] + need[right])
        d_side = np.clip(d_next, np.minimum(lo_side, d), np.maximum(hi_side, d))
        moved = np.abs(d_side - d_next) > 1e-9
        self.counts.side += int(np.count_nonzero(moved))
        d_next = d_side
        v_lat_next = (d_next - d) / dt

        # 3. safe speed ----------------------------------------------------------------
        d_lo = np.minimum(d, d_next)
        d_hi = np.maximum(d, d_next)
        lat_gap = np.maximum(road.d[j] - d_hi[i], d_lo[i] - road.d[j]) - half_w
        ahead = (ds > 0) & (lat_gap < c.lateral_clearance_m)
        gap = ds - half_l - c.min_gap_m
        v_safe_pair = krauss_safe_speed(gap, road.v[j], c)
        v_safe = np.full(n, np.inf)
        np.minimum.at(v_safe, i[ahead], v_safe_pair[ahead])
        if wall_gap is not None:
            finite = np.isfinite(wall_gap)
            v_wall = krauss_safe_speed(np.where(finite, wall_gap - 0.5, 0.0), np.zeros(n), c)
            v_safe = np.where(finite, np.minimum(v_safe, v_wall), v_safe)
        u_max = (v_safe - v) / dt
        u_long = np.minimum(u[:, 0], u_max)
        u_long = np.maximum(u_long, -c.own_decel_mps2)
        # Never command a negative next speed.
        u_long = np.maximum(u_long, -v / dt)
        self.counts.speed += int(np.count_nonzero(u_long < u[:, 0] - 1e-9))
        u[:, 0] = u_long
        u[:, 1] = (v_lat_next - v_lat) / dt
        return u, v_lat_next
