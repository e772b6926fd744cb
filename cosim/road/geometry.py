"""The road frame without SUMO: a road's length and edges from its :class:`NetworkSpec`.

:func:`road_geometry` gives what the SUMO-free road world (:mod:`cosim.sim.road_world`)
and the demand plan need: the main route's length, whether it is a ring, its width
along ``s`` and its speed limit. It mirrors :class:`~cosim.road.frame.RoadNetwork`'s
interface for straight roads, rings and width profiles (no junction lanes, no ramps).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.observation import RoadProfile
from cosim.errors import ConfigError
from cosim.road.spec import NetworkSpec

#: Network kinds the road world can represent.
ROAD_WORLD_KINDS = ("straight", "ring", "varying_width")


@dataclass(frozen=True)
class RoadGeometry:
    """A lane-free road's frame (lengths m, speeds m/s).

    Attributes:
        kind: the spec's kind. length_m: main route length. periodic: ring.
        speed_limit_mps: speed limit. segment_s0, segment_width: width profile.
    """

    kind: str
    length_m: float
    periodic: bool
    speed_limit_mps: float
    segment_s0: tuple[float, ...]
    segment_width: tuple[float, ...]
    n_lanes: int = 1
    ramp_route: tuple[str, ...] | None = None
    ramp_width_m: float | None = None
    merge_s_m: float | None = None

    @property
    def width_m(self) -> float:
        """Widest width of the road, m."""
        return float(max(self.segment_width))

    def profile(self) -> RoadProfile:
        w = np.asarray(self.segment_width, dtype=float)
        return RoadProfile(np.asarray(self.segment_s0, dtype=float), -0.5 * w, 0.5 * w,
                           self.length_m, self.periodic)

    def width_at(self, s) -> np.ndarray:
        """Road width (m) at each ``s`` (m); a scalar for a scalar ``s``."""
        s_arr = np.asarray(s, dtype=float)
        e = self.profile().edges(np.atleast_1d(s_arr))
        w = e[:, 1] - e[:, 0]
        return w.reshape(s_arr.shape)

    def edges_at(self, s) -> tuple[np.ndarray, np.ndarray]:
        e = self.profile().edges(np.atleast_1d(np.asarray(s, dtype=float)))
        return e[:, 0], e[:, 1]

    def locate(self, s: float) -> tuple[str, float]:
        """("road", s): the road world has one edge."""
        return "road", float(s)


def road_geometry(spec: NetworkSpec) -> RoadGeometry:
    """The frame of a straight road, a ring or a width profile, without netconvert."""
    if spec.kind == "straight":
        return RoadGeometry("straight", spec.length_m, False, spec.speed_limit_mps, (0.0,),
                            (spec.width_m,))
    if spec.kind == "ring":
        return RoadGeometry("ring", spec.circumference_m, True, spec.speed_limit_mps, (0.0,),
                            (spec.width_m,))
    if spec.kind == "varying_width":
        s0 = np.concatenate([[0.0], np.cumsum([seg[0] for seg in spec.width_profile])[:-1]])
        return RoadGeometry("varying_width", float(sum(seg[0] for seg in spec.width_profile)),
                            False, spec.speed_limit_mps, tuple(float(x) for x in s0),
                            tuple(float(seg[1]) for seg in spec.width_profile))
    raise ConfigError(
        f"scenario.world = 'road' supports network kinds {', '.join(ROAD_WORLD_KINDS)}, "
        f"not {spec.kind!r} (use world = 'sumo')"
    )
