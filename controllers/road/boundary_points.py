"""``boundary_points``: seed 003's boundary-point law driving CAVs on the road.

The plane-world law (:mod:`controllers.plane.boundary_points`) sees obstacles as boundary
points. On the road, the sensed vehicles (human drivers, a stopped vehicle) are
sampled as boundary points on their perimeters every ``BP_SPACING_M``, moving with
them; the gamma-agent is placed ``BP_GOAL_AHEAD_M`` ahead of each CAV in its own
lateral position and moves at the time-gap reference speed
(:func:`controllers.road.reference.time_gap_reference`). Then the run's actuator
box and jerk limit, and a lateral damping ``u_lat -= c_d v_lat`` (clipped).

A stopped car is a local minimum of seed 003's potential field on a road: the gamma-agent
straight ahead pulls a CAV into the car, the car's boundary points push it back, and the
CAV stays behind it (measured: 35-70 s in the built-in ``obstacle_seed003`` scenario). The
adapter adds a road navigation term for that case only: a CAV with a stopped vehicle
(slower than ``STOPPED_MPS``) ahead in its band within ``BP_GOAL_AHEAD_M`` gets
``u_lat += k_nav (d_goal - d) - c_nav v_lat`` towards the nearest side of that vehicle that
fits inside the road (:func:`lateral_goal`); the law is unchanged everywhere else.

Road edges are not boundary points: every car is always within seed 003's
early-warning distance of both edges of a 10.2 m road, so edge points jam the flock
(measured: 0.5 m/s mean speed with them); the edges are the safety layer's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.errors import ParameterError
from controllers.layers.constraints import ConstrainedController
from controllers.observation import Observation
from controllers.plane.boundary_points import BoundaryPointController, BoundaryPointParams
from controllers.road.reference import time_gap_reference

BP_GOAL_AHEAD_M = 50.0  # m: seed 003's gamma-agent placed this far ahead of each CAV
BP_SPACING_M = 1.0  # m: spacing of boundary points on vehicle perimeters
STOPPED_MPS = 1.0  # m/s: a sensed vehicle slower than this is a stopped one to pass
K_NAV = 0.6  # 1/s^2: lateral navigation gain around a stopped vehicle
C_NAV = 1.2  # 1/s: its damping


@dataclass(frozen=True)
class RoadBoundaryPointParams(BoundaryPointParams):
    """Seed 003 parameters plus the road reference (SI units).

    Attributes (beyond :class:`~controllers.plane.boundary_points.BoundaryPointParams`;
    ``dt`` is the run's step):
        time_gap_s, standstill_gap_m, reference_decel_mps2, lateral_margin_m: the
            time-gap reference speed of the gamma-agent (see
            :func:`controllers.road.reference.time_gap_speed`), s, m, m/s^2, m.
        lateral_damping: gain pulling the lateral speed to zero, 1/s.
    """

    time_gap_s: float = 0.8
    standstill_gap_m: float = 2.0
    reference_decel_mps2: float = 3.0
    lateral_margin_m: float = 0.3
    lateral_damping: float = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("time_gap_s", "standstill_gap_m", "reference_decel_mps2",
                     "lateral_margin_m", "lateral_damping"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ParameterError(f"{name} must be finite and >= 0, got {v!r}")


# Seed 003's law scaled to cars (table 3 is for point robots at 5 m/s): sensing radius
# 15 m, spacing 6 m; p_max = 10 m/s is the largest *relative* speed between neighbours
# on a road (so d_e = d_min + 2 p_max dt = 3 m); separation weight tau_s = 10 instead of
# 1e4 because cars side by side sit inside d_e; bounded (sigma_1) pull to the goal.
ROAD_DEFAULTS = {
    "r": 15.0, "d": 6.0, "epsilon": 0.1, "a": 2.0, "b": 20.0, "c1_alpha": 0.05,
    "c2_alpha": 0.3, "c1_beta": 0.05, "c2_beta": 0.3, "c1_gamma": 0.5, "c2_gamma": 0.5,
    "tau_a": 0.1, "tau_e": 1.0, "tau_s": 10.0, "p_max": 10.0, "d_min": 1.0,
    "gamma_position": "sigma1", "beta_potential": "repulsive",
}


def perimeter_points(q: np.ndarray, p: np.ndarray, length: np.ndarray, width: np.ndarray,
                     spacing_m: float = BP_SPACING_M) -> tuple[np.ndarray, np.ndarray]:
    """Boundary points (K, 2) m on the perimeters of rectangles centred at ``q`` (M, 2) m,
    sized ``length`` x ``width`` (M,) m, with their velocities ``p`` (K, 2) m/s."""
    pts, vel = [], []
    for r in range(len(q)):
        hl, hw = 0.5 * length[r], 0.5 * width[r]
        xs = np.arange(-hl, hl + 1e-9, spacing_m)
        ys = np.arange(-hw, hw + 1e-9, spacing_m)
        ring = np.vstack([
            np.column_stack([xs, np.full_like(xs, -hw)]),
            np.column_stack([xs, np.full_like(xs, hw)]),
            np.column_stack([np.full_like(ys, -hl), ys]),
            np.column_stack([np.full_like(ys, hl), ys]),
        ])
        pts.append(ring + q[r])
        vel.append(np.tile(p[r], (len(ring), 1)))
    if not pts:
        return np.empty((0, 2)), np.empty((0, 2))
    return np.vstack(pts), np.vstack(vel)


def lateral_goal(obs: Observation, reach_m: float, margin_m: float) -> tuple[np.ndarray,
                                                                              np.ndarray]:
    """Lateral goal (N,) m of each CAV blocked by a stopped vehicle, and the mask (N,) of
    the blocked ones: the nearest stopped vehicle ahead in the CAV's band (lateral gap
    below ``margin_m``) within ``reach_m`` (m, bumper to bumper); the goal is beside it, on
    the side nearer to the CAV that keeps the body ``margin_m`` (m) from it and inside the
    road edges (``obs.road_edges``); a CAV for which neither side fits is not blocked.

    Cost: one pass over the stopped vehicles (few) with (N,) arrays each.
    """
    d = obs.q[:, 1].astype(float)
    n = len(d)
    goal = d.copy()
    blocked = np.zeros(n, bool)
    if obs.others_q is None or not len(obs.others_q):
        return goal, blocked
    stopped = np.flatnonzero(np.abs(obs.others_p[:, 0]) < STOPPED_MPS)
    if not len(stopped):
        return goal, blocked
    w = obs.width if obs.width is not None else np.zeros(n)
    length = obs.length if obs.length is not None else np.zeros(n)
    if obs.road_edges is not None:
        right, left = obs.road_edges[:, 0], obs.road_edges[:, 1]
    else:
        right, left = np.full(n, -np.inf), np.full(n, np.inf)
    nearest = np.full(n, np.inf)
    for k in stopped.tolist():
        ds = obs.others_q[k, 0] - obs.q[:, 0]
        if obs.period_s is not None:
            ds = np.mod(ds, obs.period_s)
        gap = ds - 0.5 * (length + obs.others_length[k])
        half = 0.5 * (w + obs.others_width[k]) + margin_m
        dk = obs.others_q[k, 1]
        to_left, to_right = dk + half, dk - half
        fits_left = to_left + 0.5 * w + margin_m <= left
        fits_right = to_right - 0.5 * w - margin_m >= right
        hit = ((ds > 0) & (gap < reach_m) & (np.abs(d - dk) < half) & (gap < nearest)
               & (fits_left | fits_right))
        if not hit.any():
            continue
        prefer_left = np.abs(to_left - d) <= np.abs(to_right - d)
        side = np.where(fits_left & (prefer_left | ~fits_right), to_left, to_right)
        goal[hit] = side[hit]
        blocked[hit] = True
        nearest[hit] = gap[hit]
    return goal, blocked


class RoadBoundaryPoints:
    """Seed 003's law on the road (see the module docstring)."""

    name = "boundary_points"

    def __init__(self, params: RoadBoundaryPointParams, ctx, wrap=None) -> None:
        self.params = params
        inner = BoundaryPointController(params)
        if wrap is not None:
            inner = wrap(inner)
        self.lat_max_mps2 = ctx.limits.lat_max_mps2
        self.law = ConstrainedController(inner, ctx.limits.layers())

    @property
    def lattice_m(self) -> tuple[float, float]:
        """Spacing and sensing range of the law, m (for the flock metrics)."""
        return self.params.d, self.params.r

    def reset(self) -> None:
        fn = getattr(self.law.law, "reset", None)
        if callable(fn):
            fn()

    def clip_stats(self) -> dict[str, float]:
        return self.law.clip_stats()

    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations (N, 2), m/s^2."""
        p = self.params
        leader_p = np.zeros_like(obs.p)
        leader_p[:, 0] = time_gap_reference(obs, p.time_gap_s, p.standstill_gap_m,
                                            p.reference_decel_mps2, p.lateral_margin_m)
        extras = {}
        if obs.others_q is not None and len(obs.others_q):
            pts, vel = perimeter_points(obs.others_q, obs.others_p, obs.others_length,
                                        obs.others_width)
            if obs.period_s is not None:
                pts[:, 0] = np.mod(pts[:, 0], obs.period_s)
            extras = {"boundary_points": pts, "boundary_point_velocities": vel}
        inner = Observation(
            q=obs.q, p=obs.p, t=obs.t, dt=obs.dt, ids=obs.ids, length=obs.length,
            width=obs.width, others_q=obs.others_q, others_p=obs.others_p,
            others_length=obs.others_length, others_width=obs.others_width,
            road_edges=obs.road_edges, leader_p=leader_p,
            leader_q=obs.q + np.array([BP_GOAL_AHEAD_M, 0.0]), period_s=obs.period_s,
            extras=extras,
        )
        u = self.law.compute(inner)
        if p.lateral_damping > 0:
            u[:, 1] -= p.lateral_damping * obs.p[:, 1]
        goal, blocked = lateral_goal(obs, BP_GOAL_AHEAD_M, p.lateral_margin_m)
        if blocked.any():
            u[blocked, 1] = (K_NAV * (goal[blocked] - obs.q[blocked, 1])
                             - C_NAV * obs.p[blocked, 1])
        u[:, 1] = np.clip(u[:, 1], -self.lat_max_mps2, self.lat_max_mps2)
        return u
