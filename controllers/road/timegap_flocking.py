"""``flocking_timegap``: Olfati-Saber's Algorithm 3 tracking a time-gap reference.

The road law of the first rounds, kept selectable for comparison with the lane-free
law (``controller.kind = "flocking_timegap"``). Each step:

1. reference: the desired speed of CAV i bounded by a constant time-gap policy and a
   closing-speed bound to its leader, the nearest vehicle ahead that overlaps it
   laterally (``controllers.road.reference``):
   ``v_ref = min(v_des, (g - s0) / T, sqrt(v_l^2 + 2 b (g - s0)))``;
2. ``u = u_alpha + u_beta + u_gamma`` with ``p_gamma = (v_ref, 0)``
   (``controllers.plane.olfati_saber``);
3. the actuator box (and jerk limit) of the run;
4. lateral damping ``u_lat -= c_d v_lat``, clipped to the lateral limit.

Measured (README): it drives in invisible lanes (no lateral purpose) and is string
unstable with the default ``c2_gamma``; see ``controllers/road/lanefree/``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.errors import ParameterError
from controllers.layers.constraints import AccelerationBox, ConstrainedController, JerkLimit
from controllers.observation import Observation
from controllers.plane.olfati_saber import OlfatiSaberController
from controllers.plane.params import FlockingParams
from controllers.road.reference import time_gap_reference


@dataclass(frozen=True)
class TimeGapFlockingParams(FlockingParams):
    """FlockingParams plus the time-gap reference and lateral damping (SI units).

    Attributes (beyond :class:`~controllers.plane.params.FlockingParams`):
        time_gap_s: time gap T of the reference ``min(v_des, (g - s0)/T)``, s; 0 tracks
            the desired speed only.
        standstill_gap_m: standstill gap s0, m.
        reference_decel_mps2: deceleration b of the closing-speed bound, m/s^2; 0: off.
        lateral_margin_m: extra lateral width within which a vehicle ahead counts as
            the leader, m.
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


def road_flocking_defaults() -> dict:
    """Gains for cars on a 10.2 m road (rows of 3 across, long headways along).

    Spacing is anisotropic: ``d_lat`` = 3.4 m (a lane's width), ``d_long`` = 35 m
    (about 1.2 s at 30 m/s); gains are scaled to car accelerations (a few m/s^2)
    instead of seed 000's point-robot gains.
    """
    return dict(
        d=3.4, r=1.2 * 3.4, d_long=35.0, d_lat=3.4, epsilon=0.1, a=5.0, b=5.0,
        h_alpha=0.2, h_beta=0.9, d_beta=5.0, r_beta=6.0, d_vehicle=2.0, r_vehicle=4.0,
        d_wall=0.6, r_wall=1.5, c1_alpha=0.3, c2_alpha=0.3, c1_beta=1.0, c2_beta=0.5,
        c1_wall=2.0, c2_wall=1.0, c1_gamma=(0.0, 0.0), c2_gamma=(0.5, 0.0),
    )


class TimeGapFlocking:
    """The time-gap flocking law on the road (see the module docstring).

    Args:
        params: the law's parameters.
        box: the run's actuator limits as an :class:`AccelerationBox`.
        jerk_max_mps3: jerk limit, m/s^3 (0: none).
        wrap: optional function wrapping the inner Olfati-Saber law (the communication
            layer of seed 001 acts on the law, not on the reference).
    """

    name = "flocking_timegap"

    def __init__(self, params: TimeGapFlockingParams, box: AccelerationBox,
                 jerk_max_mps3: float = 0.0, wrap=None) -> None:
        self.params = params
        inner = OlfatiSaberController(params)
        if wrap is not None:
            inner = wrap(inner)
        layers = [box]
        if jerk_max_mps3 > 0:
            layers.append(JerkLimit(jerk_max_mps3))
        self.lat_max_mps2 = box.lat_max
        self.law = ConstrainedController(inner, layers)

    @property
    def lattice_m(self) -> tuple[float, float]:
        """Longitudinal spacing and range of the alpha lattice, m (for the flock metrics)."""
        p = self.params
        d = p.d_long or p.d
        return d, p.r * d / p.d

    def reset(self) -> None:
        for layer in self.law.layers:
            if hasattr(layer, "_prev"):
                layer._prev = {}
        fn = getattr(self.law.law, "reset", None)
        if callable(fn):
            fn()

    def clip_stats(self) -> dict[str, float]:
        return self.law.clip_stats()

    def reference_speed(self, obs: Observation) -> np.ndarray:
        """Reference speeds (N,) m/s: desired speed bounded by the time-gap policy."""
        p = self.params
        return time_gap_reference(obs, p.time_gap_s, p.standstill_gap_m,
                                  p.reference_decel_mps2, p.lateral_margin_m)

    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations (N, 2), m/s^2."""
        leader_p = np.zeros_like(obs.p)
        leader_p[:, 0] = self.reference_speed(obs)
        inner_obs = Observation(
            q=obs.q, p=obs.p, t=obs.t, dt=obs.dt, ids=obs.ids, length=obs.length,
            width=obs.width, others_q=obs.others_q, others_p=obs.others_p,
            others_length=obs.others_length, others_width=obs.others_width,
            road_edges=obs.road_edges, leader_p=leader_p, period_s=obs.period_s,
        )
        u = self.law.compute(inner_obs)
        if self.params.lateral_damping > 0:
            u[:, 1] -= self.params.lateral_damping * obs.p[:, 1]
            u[:, 1] = np.clip(u[:, 1], -self.lat_max_mps2, self.lat_max_mps2)
        return u

