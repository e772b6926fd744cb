"""``vicsek``: seed 004's velocity alignment driving CAVs on the road.

``u_i = k_align (mean_{j in N_i} p_j - p_i) + k_v (v_des_i - v_i) e_s`` with ``N_i`` the
other CAVs within ``radius_m`` (controllers.plane.vicsek.VicsekAlignmentController) and a
desired-speed term along the road (``k_v = 0`` gives pure alignment, which only keeps
the flock's mean velocity). No spacing and no collision avoidance of its own: the
safety layer keeps it apart and on the road (its interventions are counted).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.errors import ParameterError
from controllers.observation import Observation
from controllers.plane.vicsek import VicsekAlignmentController


@dataclass(frozen=True)
class RoadVicsekParams:
    """Attributes:
    radius_m: alignment neighbourhood radius, m (> 0).
    align_gain_per_s: alignment gain ``k_align``, 1/s (>= 0).
    speed_gain_per_s: desired-speed tracking gain ``k_v``, 1/s (>= 0).
    """

    radius_m: float = 30.0
    align_gain_per_s: float = 0.5
    speed_gain_per_s: float = 0.3

    def __post_init__(self) -> None:
        if not (np.isfinite(self.radius_m) and self.radius_m > 0):
            raise ParameterError(f"radius_m must be finite and > 0, got {self.radius_m!r}")
        for name in ("align_gain_per_s", "speed_gain_per_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ParameterError(f"{name} must be finite and >= 0, got {v!r}")


class RoadVicsek:
    """Alignment plus desired-speed tracking (see the module docstring)."""

    name = "vicsek"

    def __init__(self, params: RoadVicsekParams, ctx=None) -> None:
        self.params = params
        self.align = VicsekAlignmentController(params.radius_m, params.align_gain_per_s)

    @property
    def lattice_m(self) -> tuple[float, float]:
        """No spacing of its own: the alignment radius as range, m."""
        return self.params.radius_m, self.params.radius_m

    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations (N, 2), m/s^2."""
        u = self.align.compute(obs)
        if obs.desired_speed is not None and self.params.speed_gain_per_s > 0:
            u[:, 0] += self.params.speed_gain_per_s * (obs.desired_speed - obs.p[:, 0])
        return u
