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
   could not stop behind it, nor behind one it could not stop behind. A vehicle in the
   CAV's band (lateral gap below ``lateral_clearance``) ahead of it, or behind it and able
   to stop behind it, without longitudinal overlap, is a leader or follower, not a side
   neighbour: rule 3 holds the CAV off a leader, and the CAV may move sideways out of the
   band (e.g. from behind a stopped car).
3. **Safe speed** (longitudinal, Krauss 1998 / SUMO's default model): with
   ``g`` the bumper-to-bumper gap minus ``min_gap`` to the nearest vehicle
   ahead that overlaps laterally anywhere along the lateral move, the next speed
   is at most ``v_safe = -b tau + sqrt((b tau)^2 + v_l^2 b / b_l + 2 b g)``,
   which lets the CAV stop behind a leader braking at ``b_l`` after one
   reaction delay ``tau``, braking itself at ``b`` (the emergency deceleration).
   A vehicle alongside (the bodies overlap along the road, its centre ahead) that is
   clear sideways along the move is no leader unless its lateral speed closes the gap
   within ``ALONGSIDE_S`` (1 s): stopping dead cannot avoid a vehicle beside, and the
   driver behind may not stop in time (rule 2 keeps the side clearance).

Every activation is counted per rule.

The rules run in one compiled loop per CAV (numba,
:func:`controllers.layers.safety_kernels.apply_kernel`) over the vehicles within reach, found in
a window of the vehicles sorted along the road (no pair arrays); it computes what the
vectorised numpy form of the layer computed (``tests/test_exactness.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from controllers.errors import ParameterError


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
        (:class:`~controllers.layers.constraints.ActuatorLimits`)."""
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
        n = len(cav_index)
        u = np.array(u, dtype=float, copy=True)
        self.counts.seen += n
        if n == 0:
            return u, np.zeros(0)
        cav_index = np.asarray(cav_index, dtype=np.int64)
        v = road.v[cav_index]
        # neighbours within a longitudinal reach
        length = _f64(road.length)
        v_max = float(v.max())
        reach = v_max * c.tau + v_max ** 2 / (2 * c.own_decel_mps2)
        reach += float(length.max()) + c.min_gap_m + 10.0
        m = len(road.s)
        periodic = period is not None
        key = np.mod(road.s, period) if periodic else road.s
        order = np.argsort(key, kind="stable")
        key = key[order]
        if periodic:  # copies one period below and above close the ring
            key = np.concatenate([key - period, key, key + period])
        is_cav = np.zeros(m, bool)
        is_cav[cav_index] = True
        has_wall = wall_gap is not None
        v_lat_next, counts = _apply_kernel()(
            u, cav_index, _f64(v_lat), _f64(road.s), _f64(road.d), _f64(road.v),
            length, _f64(road.width),
            np.zeros(m) if road.v_lat is None else _f64(road.v_lat), is_cav, _f64(edges),
            periodic, float(period) if periodic else 0.0, order, key,
            _f64(wall_gap) if has_wall else np.zeros(0), has_wall, reach, self._scalars_of(c))
        self.counts.edge += int(counts[0])
        self.counts.side += int(counts[1])
        self.counts.speed += int(counts[2])
        return u, v_lat_next

    def _scalars_of(self, c: SafetyConfig) -> np.ndarray:
        """:func:`_scalars` of ``c``, kept while the layer's config is the same object."""
        cached = self.__dict__.get("_scalars_cache")
        if cached is None or cached[0] is not c:
            cached = (c, _scalars(c))
            self.__dict__["_scalars_cache"] = cached
        return cached[1]


def _f64(x) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=float)


def _apply_kernel():
    """:func:`controllers.layers.safety_kernels.apply_kernel` (numba: imported when first used)."""
    global _APPLY_KERNEL
    if _APPLY_KERNEL is None:
        from controllers.layers.safety_kernels import apply_kernel

        _APPLY_KERNEL = apply_kernel
    return _APPLY_KERNEL


_APPLY_KERNEL = None


def _scalars(c: SafetyConfig) -> np.ndarray:
    """The layer's scalars for :func:`~controllers.layers.safety_kernels.apply_kernel`, folded as
    the numpy rules folded them."""
    b = c.own_decel_mps2
    return np.array([
        c.dt, c.min_gap_m, c.lateral_clearance_m, c.edge_margin_m, b, c.leader_decel_mps2,
        c.lat_speed_max_mps, c.cut_in_time_s, (b * c.tau) ** 2, -b * c.tau, 2.0 * b,
        2.0 * c.lat_accel_mps2, c.lat_accel_mps2 * c.dt, c.lat_speed_max_mps * c.dt,
    ])
