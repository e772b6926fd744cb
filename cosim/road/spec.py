"""The ``[network]`` section: a road from a few parameters, or the user's own ``.net.xml``.

Lengths and widths in m, speeds in m/s. :class:`NetworkSpec` is validated on
construction; :mod:`cosim.road.build` turns it into a SUMO network.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

from cosim.errors import ConfigError

KINDS = ("straight", "ring", "onramp", "varying_width", "three_lane", "corridor", "file")


#: Fewest edges of the ring; each is a circular arc drawn with RING_ARC_POINTS segments.
RING_EDGES = 4


RING_ARC_POINTS = 16


#: Width of one conventional lane in the three-lane baseline, m (3 x 3.4 = 10.2).
CONVENTIONAL_LANE_WIDTH_M = 3.4


#: Shortest main-road edge after an on-ramp's acceleration lane, m.
MIN_EDGE_AFTER_LANE_M = 20.0


#: Freeway corridor (kind ``corridor``) after TUM LaneFreeDrive's highway with an off- and an
#: on-ramp (adapted from TrafficFluid-Sim): 3 m ramp strips, the on-ramp's 482 m long and
#: the off-ramp's 342 m long (m).
CORRIDOR_STRIP_WIDTH_M = 3.0
CORRIDOR_ACCELERATION_LANE_M = 482.0
CORRIDOR_DECELERATION_LANE_M = 342.0


@dataclass(frozen=True)
class NetworkSpec:
    """Parameters of a road network (lengths and widths in m, speeds in m/s).

    Attributes:
        kind: one of ``straight``, ``ring``, ``onramp``, ``varying_width``,
            ``three_lane``, ``corridor``, ``file``. ``corridor``: a freeway stretch of
            ``length_m`` with an on-ramp (its acceleration strip of ``acceleration_lane_m``
            starts at ``merge_position_m``) and, downstream of it, an off-ramp (its
            deceleration strip of ``deceleration_lane_m`` ends at the gore,
            ``diverge_position_m``, where the off-ramp of ``offramp_length_m`` leaves);
            the stretch between them is a weaving section. Ramps and strips are
            ``ramp_width_m`` wide; ``lanes`` = 3 gives the same corridor with three
            conventional lanes (SUMO's LC2013 drivers, the lane-based baseline).
        length_m: road length (straight, three_lane) or main-road length (onramp).
        width_m: width of the single wide lane (three_lane: total width of 3 lanes).
        circumference_m: ring circumference along the road centre line.
        ramp_length_m: straight-line distance from the ramp's start to the merge
            node; SUMO's measured ramp length is reported in
            :attr:`RoadNetwork.ramp_length_m` (the junction takes its share).
        ramp_width_m: width of the ramp's single lane, m (default 3.4, one conventional
            lane); 0: as wide as the main road. With an acceleration lane it is also that
            lane's width. Without one (``acceleration_lane_m = 0``) a ramp narrower than
            the road joins it in its middle (SUMO keeps a vehicle's offset from the lane's
            centre line across a junction): use 0 there, so that ramp traffic, which
            departs at the ramp's right side, joins at the road's right side.
        ramp_angle_deg: angle between ramp and main road at the merge, degrees.
        merge_position_m: distance from the main road's start to the merge node.
        acceleration_lane_m: length (m) of the acceleration lane: from the merge node the
            ramp's lane runs on beside the main road's right edge, as a second lane of
            the same edge (the road is ``width_m + ramp_width_m`` wide there), and ends;
            ramp traffic crosses onto the main road anywhere along it. Default 250.
            0: no acceleration lane; the ramp's lane and the road's lane join in the
            merge junction (SUMO then keeps both streams in one file through the
            junction's lanes, whatever their lateral positions: a bottleneck of the
            set-up, README "On-ramp").
        width_profile: varying_width only: consecutive ``(length_m, width_m)``
            segments, one edge each, in driving order.
        speed_limit_mps: speed limit on every edge.
        max_edge_length_m: straight and ring roads are split into equal edges no
            longer than this (0: one edge per road; the ring has at least 4).
            Vehicles cross the joints unchanged, but SUMO's sublane model works
            per lane, and on one 2 km lane its step costs about 3.8 times as much
            as on 100 m edges (benchmarks/bench_sumo_options.py, 12 000 veh/h).
        net_file: kind ``file``: path to the user's ``.net.xml``.
        route_edges: kind ``file``: edge ids of the main route in driving order.
        ramp_edges: kind ``file`` (optional): the edge ids of an on-ramp route that
            ends on a main-route edge, or a list of such routes (several on-ramps, named
            ``ramp``, ``ramp2``, ... in the demand in this order).
        diverge_position_m: corridor: distance from the main road's start to the gore
            (where the off-ramp leaves the deceleration strip), m.
        deceleration_lane_m: corridor: length of the deceleration strip before the gore, m.
        offramp_length_m: corridor: length of the off-ramp after the gore, m.
        lanes: corridor: 1 (one wide lane, lane-free) or 3 (three conventional lanes of
            ``width_m / 3``).
        offramp_edges: kind ``file`` (optional): the edge ids of an off-ramp route, its
            first edge leaving a main-route edge (from the lanes of that edge that connect
            to it), or a list of such routes (named ``off``, ``off2``, ... in this order).
    """

    kind: str = "straight"
    length_m: float = 2000.0
    width_m: float = 10.2
    circumference_m: float = 1000.0
    ramp_length_m: float = 300.0
    ramp_width_m: float = CONVENTIONAL_LANE_WIDTH_M
    ramp_angle_deg: float = 8.0
    merge_position_m: float = 500.0
    acceleration_lane_m: float = 250.0
    width_profile: tuple[tuple[float, float], ...] = ()
    speed_limit_mps: float = 40.0
    max_edge_length_m: float = 100.0
    net_file: str | None = None
    route_edges: tuple[str, ...] = ()
    ramp_edges: tuple[str, ...] | tuple[tuple[str, ...], ...] = ()
    diverge_position_m: float = 2500.0
    deceleration_lane_m: float = CORRIDOR_DECELERATION_LANE_M
    offramp_length_m: float = 300.0
    lanes: int = 1
    offramp_edges: tuple[str, ...] | tuple[tuple[str, ...], ...] = ()

    def __post_init__(self) -> None:
        # Accept lists from TOML/JSON but store hashable tuples.
        profile = tuple(tuple(float(v) for v in seg) for seg in self.width_profile)
        object.__setattr__(self, "width_profile", profile)
        object.__setattr__(self, "route_edges", tuple(str(e) for e in self.route_edges))
        for name in ("ramp_edges", "offramp_edges"):
            object.__setattr__(self, name, _routes_field(name, getattr(self, name)))
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ConfigError` (naming the field) for impossible values."""
        if self.kind not in KINDS:
            raise ConfigError(
                f"network.kind must be one of {', '.join(KINDS)} (got {self.kind!r})"
            )
        _positive("speed_limit_mps", self.speed_limit_mps)
        m = self.max_edge_length_m
        if isinstance(m, bool) or not isinstance(m, int | float) or not math.isfinite(m) or m < 0:
            raise ConfigError(f"network.max_edge_length_m must be >= 0 (got {m!r})")
        check = {
            "straight": self._validate_straight,
            "three_lane": self._validate_three_lane,
            "ring": self._validate_ring,
            "onramp": self._validate_onramp,
            "varying_width": self._validate_varying,
            "corridor": self._validate_corridor,
            "file": self._validate_file,
        }[self.kind]
        check()

    def _validate_straight(self) -> None:
        _positive("length_m", self.length_m)
        _positive("width_m", self.width_m)

    def _validate_three_lane(self) -> None:
        self._validate_straight()
        if self.width_m / 3 < 2.0:
            raise ConfigError(
                f"network.width_m must be >= 6 m for three_lane (3 lanes; got {self.width_m})"
            )

    def _validate_ring(self) -> None:
        _positive("width_m", self.width_m)
        _positive("circumference_m", self.circumference_m)
        radius = self.circumference_m / (2 * math.pi)
        if radius < 1.5 * self.width_m:
            raise ConfigError(
                f"network.circumference_m={self.circumference_m} is too small for "
                f"width_m={self.width_m} (radius must be >= 1.5 x width)"
            )

    def _validate_onramp(self) -> None:
        self._validate_straight()
        _positive("ramp_length_m", self.ramp_length_m)
        if self.ramp_width_m != 0:
            _positive("ramp_width_m", self.ramp_width_m)
        if not 0.0 < self.ramp_angle_deg < 90.0:
            raise ConfigError(
                f"network.ramp_angle_deg must be in (0, 90) (got {self.ramp_angle_deg})"
            )
        if not 0.0 < self.merge_position_m < self.length_m:
            raise ConfigError(
                f"network.merge_position_m must be in (0, length_m={self.length_m}) "
                f"(got {self.merge_position_m})"
            )
        acc = self.acceleration_lane_m
        if isinstance(acc, bool) or not isinstance(acc, int | float) or not math.isfinite(acc) \
                or acc < 0:
            raise ConfigError(f"network.acceleration_lane_m must be >= 0 (got {acc!r})")
        if acc > 0 and self.merge_position_m + acc + MIN_EDGE_AFTER_LANE_M > self.length_m:
            raise ConfigError(
                f"network.acceleration_lane_m = {acc:g} m does not fit: the lane must end at "
                f"least {MIN_EDGE_AFTER_LANE_M:g} m before the road's end (merge_position_m "
                f"+ acceleration_lane_m <= {self.length_m - MIN_EDGE_AFTER_LANE_M:g} m)"
            )

    def _validate_corridor(self) -> None:
        self._validate_straight()
        for name in ("ramp_length_m", "deceleration_lane_m", "offramp_length_m",
                     "acceleration_lane_m", "diverge_position_m", "merge_position_m"):
            _positive(name, getattr(self, name))
        _positive("ramp_width_m", self.ramp_width_m)
        if not 0.0 < self.ramp_angle_deg < 90.0:
            raise ConfigError(
                f"network.ramp_angle_deg must be in (0, 90) (got {self.ramp_angle_deg})"
            )
        if self.lanes not in (1, 3):
            raise ConfigError(f"network.lanes must be 1 or 3 for corridor (got {self.lanes})")
        acc_end = self.merge_position_m + self.acceleration_lane_m
        dec_start = self.diverge_position_m - self.deceleration_lane_m
        if acc_end + MIN_EDGE_AFTER_LANE_M > dec_start:
            raise ConfigError(
                f"network: the corridor's strips overlap: the acceleration strip ends at "
                f"{acc_end:g} m (merge_position_m + acceleration_lane_m) and the "
                f"deceleration strip starts at {dec_start:g} m (diverge_position_m - "
                f"deceleration_lane_m); leave at least {MIN_EDGE_AFTER_LANE_M:g} m between"
            )
        if self.diverge_position_m + MIN_EDGE_AFTER_LANE_M > self.length_m:
            raise ConfigError(
                f"network.diverge_position_m = {self.diverge_position_m:g} m must be at least "
                f"{MIN_EDGE_AFTER_LANE_M:g} m before the road's end (length_m = "
                f"{self.length_m:g})"
            )

    def _validate_varying(self) -> None:
        if not self.width_profile:
            raise ConfigError("network.width_profile must list (length_m, width_m) segments")
        for i, seg in enumerate(self.width_profile):
            if len(seg) != 2:
                raise ConfigError(
                    f"network.width_profile[{i}] must be (length_m, width_m) (got {seg})"
                )
            _positive(f"width_profile[{i}] length", seg[0])
            _positive(f"width_profile[{i}] width", seg[1])

    def _validate_file(self) -> None:
        if not self.net_file:
            raise ConfigError("network.net_file is required for kind 'file'")
        if not self.route_edges:
            raise ConfigError("network.route_edges must list the main route's edges")

    def ramp_routes(self) -> tuple[tuple[str, ...], ...]:
        """The on-ramp routes of ``ramp_edges`` (one route or a list of them)."""
        return _as_routes(self.ramp_edges)

    def offramp_routes(self) -> tuple[tuple[str, ...], ...]:
        """The off-ramp routes of ``offramp_edges`` (one route or a list of them)."""
        return _as_routes(self.offramp_edges)

    def joints_m(self) -> tuple[float, ...]:
        """Positions along the road (m) where a built straight road or ring joins two
        edges (empty for other kinds; ring joints are approximate: SUMO's junctions)."""
        if self.kind == "straight":
            n, length = _n_edges(self.length_m, self.max_edge_length_m), self.length_m
            return tuple(length * k / n for k in range(1, n))
        if self.kind == "ring":
            n = _n_edges(self.circumference_m, self.max_edge_length_m, minimum=RING_EDGES)
            return tuple(self.circumference_m * k / n for k in range(n))
        return ()

    def cache_params(self) -> dict[str, Any]:
        """The parameters that determine the built network for this kind (for the hash)."""
        keys = {
            "straight": ("length_m", "width_m", "max_edge_length_m"),
            "three_lane": ("length_m", "width_m"),
            "ring": ("circumference_m", "width_m", "max_edge_length_m"),
            "onramp": (
                "length_m", "width_m", "ramp_length_m", "ramp_width_m",
                "ramp_angle_deg", "merge_position_m", "acceleration_lane_m",
            ),
            "varying_width": ("width_profile",),
            "corridor": (
                "length_m", "width_m", "ramp_length_m", "ramp_width_m", "ramp_angle_deg",
                "merge_position_m", "acceleration_lane_m", "diverge_position_m",
                "deceleration_lane_m", "offramp_length_m", "lanes", "max_edge_length_m",
            ),
            "file": ("net_file", "route_edges", "ramp_edges", "offramp_edges"),
        }[self.kind]
        params = {k: getattr(self, k) for k in keys}
        params.update(kind=self.kind, speed_limit_mps=self.speed_limit_mps)
        return json.loads(json.dumps(params))  # tuples -> lists, stable for hashing


def _routes_field(name: str, value) -> tuple:
    """``value`` as stored: one route (a tuple of edge ids) or a tuple of routes; a
    ConfigError for a mix of both or an empty route in a list."""
    items = tuple(value)
    if all(isinstance(e, str) for e in items):
        return tuple(str(e) for e in items)
    if all(isinstance(e, list | tuple) for e in items):
        routes = tuple(tuple(str(x) for x in r) for r in items)
        if any(not r for r in routes):
            raise ConfigError(f"network.{name}: a route in the list has no edge")
        return routes
    raise ConfigError(f"network.{name} must be a list of edge ids or a list of such lists "
                      f"(got {value!r})")


def _as_routes(value: tuple) -> tuple[tuple[str, ...], ...]:
    if not value:
        return ()
    return (value,) if isinstance(value[0], str) else value


def _positive(name: str, value: float) -> None:
    if not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
        raise ConfigError(f"network.{name} must be a positive number (got {value!r})")


def _n_edges(length_m: float, max_edge_length_m: float, minimum: int = 1) -> int:
    """How many equal edges split a road of ``length_m`` (m) into pieces <= the maximum."""
    if max_edge_length_m <= 0:
        return minimum
    return max(minimum, math.ceil(length_m / max_edge_length_m - 1e-9))
