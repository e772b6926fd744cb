"""The road frame on a SUMO network: ``s`` along the main route, ``d`` across it.

:func:`load_road_network` reads a ``.net.xml`` with sumolib and builds the frame of the
main route (and an optional ramp route) from the lanes' real geometry, as SUMO lays them
out: :class:`RoadNetwork`. ``s`` (m) runs as SUMO measures the main route (its lanes'
lengths plus the junction lanes between them), across junctions and the ring's seam;
``d`` (m) is positive to the left of the reference line, the centre line of the main
route's lanes.

Mapping a vehicle (:meth:`RoadNetwork.lane_frame`): on the main route by SUMO's own lane
coordinates, ``s = s0 + pos``, ``d = d0 + lat`` (SUMO carries a vehicle's lateral lane
position from lane to lane, and its collision check and drivers compare those positions);
off it (an on-ramp's lanes before they join) the point SUMO draws, projected onto the
reference line. :meth:`RoadNetwork.xy_of` maps ``(s, d)`` back to SUMO's x, y;
:meth:`RoadNetwork.lateral_lane_position` gives the ``lat`` that puts a vehicle at a
road-frame ``d`` where it will be after the step. Both are vectorised over vehicles and
compiled; lanes are looked up in a dict (no per-vehicle geometry in Python). The road's
edges along ``s``: :meth:`RoadNetwork.profile`.

The modules of the frame, in the order it is built (details there):

    sumo_net.py          the network as sumolib reads it, and the questions asked of it
    lane_tables.py       the route's lanes, their tables and SUMO's measure of ``s``
    polyline.py          the reference line as a polyline: arc length, projection
    reference_line.py    the reference line built from the main route's lanes
    lane_coordinates.py  SUMO's lane coordinates of every main-route lane
    profile.py           the road's edges along ``s`` (piecewise constant)
    frame_reference.py   the vehicle mapping in plain numpy (the definition)
    frame_kernels.py     the same, compiled (numba; the same bits)

What the frame refuses (one :class:`~cosim.errors.NetworkError` line): route edges that
do not connect or repeat, an edge without lanes, a lane that runs backwards along the
route or meets it at more than :data:`~cosim.road.lane_tables.MAX_LANE_ANGLE_DEG`, lanes
of one edge that cross, a route that turns back on itself, and geometry sumolib cannot
read.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controllers.observation import RoadProfile
from cosim.errors import ConfigError, NetworkError
from cosim.road.frame_reference import lane_frame_reference, lateral_reference
from cosim.road.lane_coordinates import lane_coordinates, use_lane_coordinates
from cosim.road.lane_tables import (
    LANE_KEY,
    Tables,
    build_measure,
    build_tables,
    find_parallel,
    frame_of,
    lane_points,
    route_lanes,
    wrap,
)
from cosim.road.profile import road_profile
from cosim.road.reference_line import reference_line
from cosim.road.sumo_net import (
    connections,
    lanes_of,
    read_sumo_net,
    reference_lane,
    via_chain,
)


@dataclass(frozen=True)
class RoadNetwork:
    """A built SUMO network and its road frame (see the module docstring).

    Attributes:
        net_file: the ``.net.xml``.
        kind: the spec's kind.
        main_route: edge ids of the main route in driving order; ``s`` is
            continuous along them (and across the junction lanes between them).
        ramp_route: edge ids of the on-ramp route (ramp edge(s) then the main
            road's edge after the merge), or None.
        length_m: length of the main route as SUMO measures it (its lanes plus the
            junction lanes between them), m; on the ring the circumference (``s`` wraps
            there).
        width_m: widest width of the main road (right to left edge), m.
        periodic: True on the ring: ``s`` wraps at ``length_m``.
        speed_limit_mps: speed limit on the main route.
        merge_s_m: onramp: ``s`` where the main road's lane leaves the merge
            junction (ramp traffic is on the main lane from here on), else None.
        ramp_length_m: onramp: SUMO's length of the ramp route up to the main road
            (ramp lanes plus their junction lanes; along the ramp, not along ``s``), m.
        ramp_width_m: onramp: width of the ramp's first edge, else None.
        n_lanes: number of lanes on the main route's first edge (1 when lane-free).
        lane_offsets: ``s`` (m) of position 0 of every lane and edge on the main and
            ramp routes, internal junction lanes included (ramp lanes upstream of the
            main route's start get negative values on open roads).
        lane_d: ``d`` (m) of each route lane's centre at its middle (0 for the one
            wide lane of a generated road; +-3.4 m for the outer lanes of three_lane;
            a user's narrow lane after a width change may be off-centre).
        lane_width: width (m) of each route lane.
        segment_s0, segment_width: the profile's pieces: start ``s`` (m) and width (m).
        edge_spans: ``(edge, s_start, s_end)`` of every main-route edge's lanes, m.

    The ring keeps vehicles circling through routes with a ``repeat``
    attribute: :meth:`ring_route_edges` gives the loop starting on a given
    edge and :mod:`cosim.demand` writes ``<route edges=... repeat=N>`` with N
    large enough for the run (SUMO then repeats the edge list N more times).
    """

    net_file: Path
    kind: str
    main_route: tuple[str, ...]
    ramp_route: tuple[str, ...] | None
    length_m: float
    width_m: float
    periodic: bool
    speed_limit_mps: float
    merge_s_m: float | None = None
    ramp_length_m: float | None = None
    ramp_width_m: float | None = None
    n_lanes: int = 1
    lane_offsets: Mapping[str, float] = field(default_factory=dict, repr=False, compare=False)
    lane_d: Mapping[str, float] = field(default_factory=dict, repr=False, compare=False)
    lane_width: Mapping[str, float] = field(default_factory=dict, repr=False, compare=False)
    segment_s0: tuple[float, ...] = field(default=(0.0,), repr=False, compare=False)
    segment_width: tuple[float, ...] = field(default=(10.2,), repr=False, compare=False)
    edge_spans: tuple[tuple[str, float, float], ...] = field(
        default=(), repr=False, compare=False
    )
    profile_right: tuple[float, ...] = field(default=(), repr=False, compare=False)
    profile_left: tuple[float, ...] = field(default=(), repr=False, compare=False)
    tables: Tables | None = field(default=None, repr=False, compare=False)
    #: lanes (junction lanes included) and edges of the main route: a vehicle on one of
    #: them is on the main road; a ramp's lanes and its junction lanes are not
    main_lanes: frozenset = field(default=frozenset(), repr=False, compare=False)
    #: an off-ramp: its edges (the first leaves a main-route edge), or None
    offramp_route: tuple[str, ...] | None = None
    #: the main-route edge the off-ramp leaves, and its lanes that lead onto the off-ramp
    diverge_edge: str | None = None
    exit_lanes: tuple[str, ...] = ()
    #: the exit lanes' extent ``(s_start, s_gore, d_right, d_left)`` (m): ``s`` where they
    #: start and where they end (the gore: the off-ramp leaves there), their right and
    #: left border
    exit_strip: tuple[float, float, float, float] | None = None
    #: the on-ramp's lanes on the main route (an acceleration strip beside the road) and
    #: their extent ``(s_start, s_end, d_right, d_left)`` (m); None when the ramp joins
    #: the road's own lane(s)
    entry_lanes: tuple[str, ...] = ()
    entry_strip: tuple[float, float, float, float] | None = None

    @property
    def lane_based(self) -> bool:
        """True for the lane-based baseline (``three_lane``: SUMO's LC2013 drivers keep
        lanes). Every other road, a user's multi-lane network included, is lane-free:
        SUMO's sublane model, the lanes only carry the geometry."""
        return self.kind == "three_lane" or (self.kind == "corridor" and self.n_lanes > 1)

    # ---- origins, destinations and their routes -----------------------------------------

    @property
    def join_index(self) -> int:
        """Index in :attr:`ramp_route` of its first main-route edge (where it joins)."""
        return next(i for i, e in enumerate(self.ramp_route) if e in self.main_route)

    @property
    def origins(self) -> tuple[str, ...]:
        """Where traffic enters an open road: ``"main"`` (the main route's start) and, with
        an on-ramp, ``"ramp"``."""
        if self.periodic:
            return ()
        return ("main", "ramp") if self.ramp_route else ("main",)

    @property
    def destinations(self) -> tuple[str, ...]:
        """Where traffic leaves: ``"main"`` (the main route's end) and, with an off-ramp,
        ``"off"`` (the off-ramp's end)."""
        if self.periodic:
            return ()
        return ("main", "off") if self.offramp_route else ("main",)

    def od_route(self, origin: str, destination: str) -> tuple[str, ...]:
        """SUMO's edges from ``origin`` to ``destination`` (:attr:`origins`,
        :attr:`destinations`): the ramp's edges join the main route where the ramp route
        ends; the off-ramp's leave it at :attr:`diverge_edge`. Raises ConfigError for a
        pair the network does not connect (an off-ramp before the on-ramp)."""
        if origin not in self.origins or destination not in self.destinations:
            raise ConfigError(f"no route from {origin!r} to {destination!r} on this network "
                              f"(origins {', '.join(self.origins)}; destinations "
                              f"{', '.join(self.destinations)})")
        main = self.main_route
        if origin == "ramp":
            i = self.join_index
            edges, first = list(self.ramp_route[:i]), main.index(self.ramp_route[i])
        else:
            edges, first = [], 0
        if destination == "off":
            leave = main.index(self.diverge_edge)
            if leave < first:
                raise ConfigError(f"no route from {origin!r} to 'off': the off-ramp leaves "
                                  f"the road before the on-ramp joins it")
            return (*edges, *main[first:leave + 1], *self.offramp_route)
        return (*edges, *main[first:])

    # ---- vehicles: SUMO (lane, position, lateral position) <-> road frame (s, d) --------

    def lane_keys(self, lanes: Sequence[str]) -> np.ndarray:
        """Index of each lane (or route edge) id in the frame's tables; -1 if off-route."""
        get = self.tables.index.get
        return np.fromiter((get(x, -1) for x in lanes), dtype=np.int64, count=len(lanes))

    def lane_frame(self, lanes: Sequence[str] | None, pos_m: np.ndarray,
                   lat_m: np.ndarray, keys: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Road-frame ``(s, d)`` (m, each (N,)) of N vehicles from SUMO's lane ids, lane
        positions ``pos_m`` (N,) m and lateral lane positions ``lat_m`` (N,) m.

        ``s`` is the position of the point SUMO reports (the front bumper's centre) along
        the reference line (wrapped on the ring), ``d`` its signed offset. Lanes off the
        routes give ``s = NaN`` and ``d = lat``. Lanes by dict lookup, or ``keys`` (N,) =
        :meth:`lane_keys` of them when the caller has them already. Compiled
        (:mod:`cosim.road.frame_kernels`; the same bits as :func:`lane_frame_reference`,
        tests/test_frame_kernels.py).
        """
        pos = np.asarray(pos_m, dtype=float)
        lat = np.asarray(lat_m, dtype=float)
        k = self.lane_keys(lanes) if keys is None else keys
        tb = self.tables
        if tb.par is not None and tb.measure is not None and len(k):  # parallel lanes
            from cosim.road import frame_kernels as FK  # numba: imported when first used

            s, d, ok = FK.parallel_frame(k, pos, lat, tb.par, tb.par_s0, tb.par_d0,
                                         tb.measure.periodic, float(tb.measure.s_period))
            if ok:
                return s, d
            return FK.geo_frame(np.ascontiguousarray(k, np.int64), np.ascontiguousarray(
                pos, float), np.ascontiguousarray(lat, float), tb.kernel_args())
        return lane_frame_reference(tb, k, pos, lat)

    def lateral_lane_position(self, lanes: Sequence[str] | None, pos_m: np.ndarray,
                              d_m: np.ndarray, keys: np.ndarray | None = None) -> np.ndarray:
        """SUMO lateral lane positions (N,) m that put vehicles now on ``lanes`` at
        road-frame offsets ``d_m`` (N,) m when they are at lane positions ``pos_m`` (N,) m
        (the inverse of :meth:`lane_frame`). Give the position a vehicle will reach in the
        step (SUMO keeps the lateral lane position while it moves, also onto the next
        lane): a position past the lane's end is taken on the route lane after it, whose
        centre may lie elsewhere (a junction lane). Off-route lanes: ``lat = d``. ``keys``:
        :meth:`lane_keys` of ``lanes``, when the caller has them already.

        Compiled (:mod:`cosim.road.frame_kernels`; the same bits as
        :func:`lateral_reference`, tests/test_frame_kernels.py)."""
        pos = np.asarray(pos_m, dtype=float)
        d = np.asarray(d_m, dtype=float)
        k = self.lane_keys(lanes) if keys is None else keys
        tb = self.tables
        if tb.par is not None and tb.measure is not None and len(k):
            from cosim.road import frame_kernels as FK

            lat, ok = FK.parallel_lateral(k, pos, d, tb.lane_len, tb.next_lane, tb.par,
                                          tb.par_d0)
            if ok:
                return lat
            return FK.geo_lateral(np.ascontiguousarray(k, np.int64), np.ascontiguousarray(
                pos, float), np.ascontiguousarray(d, float), tb.kernel_args())
        return lateral_reference(tb, k, pos, d)

    def xy_of(self, s_m: np.ndarray, d_m: np.ndarray) -> np.ndarray:
        """``(x, y)`` (N, 2) in the network's coordinates where SUMO draws a vehicle's
        reference point at road-frame positions (m) on the main route: on the route's chain
        of lanes (the middle lane of each edge and the junction lanes it drives through) at
        lane position ``s - s0`` and lateral lane position ``d - d0`` (SUMO's
        ``geometryPositionAtOffset``; where a lane's centre moves sideways across a
        junction, SUMO's drawing jumps there, see :func:`lane_coordinates`)."""
        tb = self.tables
        s = np.atleast_1d(np.asarray(s_m, dtype=float))
        d = np.broadcast_to(np.atleast_1d(np.asarray(d_m, dtype=float)), s.shape)
        if self.periodic:
            s = np.mod(s, self.length_m)
        i = np.clip(np.searchsorted(tb.chain_s0, s, side="right") - 1, 0, len(tb.chain_s0) - 1)
        k = tb.chain_keys[i]
        pos = s - tb.chain_s0[i]
        pt, nrm, _ = lane_points(tb, k, pos)
        beyond = pos - np.clip(pos, 0.0, tb.lane_len[k])  # past the route's ends: straight on
        tang = np.column_stack([nrm[:, 1], -nrm[:, 0]])
        return pt + (d - tb.par_d0[k])[:, None] * nrm + beyond[:, None] * tang

    def s_of(self, lane_or_edge: str, pos_m: float) -> float:
        """Continuous ``s`` (m) of lane position ``pos_m`` on a lane's centre (an edge: its
        middle lane); NaN if off-route."""
        s, _ = self.lane_frame([lane_or_edge], np.array([float(pos_m)]), np.zeros(1))
        return float(s[0])

    def s_of_many(self, lanes: Sequence[str], pos_m: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`s_of`: ``s`` (m) for each (lane or edge id, lane position)."""
        pos = np.asarray(pos_m, dtype=float)
        return self.lane_frame(lanes, pos, np.zeros(len(pos)))[0]

    def d_of(self, lane_or_edge: str, lateral_lane_pos_m: float) -> float:
        """Road-frame ``d`` (m) of SUMO's lateral position on a lane, at the lane's middle."""
        return self.lane_d.get(lane_or_edge, 0.0) + float(lateral_lane_pos_m)

    # ---- the road's edges ---------------------------------------------------------------

    def profile(self) -> RoadProfile:
        """The main route's lateral edges along ``s`` as a pure-numpy profile (controllers)."""
        s0 = np.asarray(self.segment_s0, dtype=float)
        if self.profile_right:
            right = np.asarray(self.profile_right, dtype=float)
            left = np.asarray(self.profile_left, dtype=float)
        else:
            w = np.asarray(self.segment_width, dtype=float)
            right, left = -0.5 * w, 0.5 * w
        return RoadProfile(s0, right, left, float(self.length_m), self.periodic)

    def width_at(self, s: np.ndarray) -> np.ndarray:
        """Road width (m) at each ``s`` (m); beyond the ends the end pieces' widths."""
        right, left = self.edges_at(s)
        return left - right

    def edges_at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lateral road edges ``(d_right, d_left)`` (m) at each ``s`` (m).

        One wide lane of width w centred on the line gives ``(-w/2, +w/2)``.
        """
        s_arr = np.asarray(s, dtype=float)
        e = self.profile().edges(np.atleast_1d(s_arr))
        return e[:, 0].reshape(s_arr.shape), e[:, 1].reshape(s_arr.shape)

    # ---- routes and positions -----------------------------------------------------------

    def ring_route_edges(self, start_edge: str | None = None) -> tuple[str, ...]:
        """Ring only: the loop's edges starting at ``start_edge`` (default: the first)."""
        if not self.periodic:
            raise NetworkError(f"ring_route_edges: network kind {self.kind!r} is not a ring")
        start = self.main_route[0] if start_edge is None else start_edge
        if start not in self.main_route:
            raise NetworkError(f"ring_route_edges: edge {start!r} is not on the ring")
        k = self.main_route.index(start)
        return self.main_route[k:] + self.main_route[:k]

    def locate(self, s: float) -> tuple[str, float]:
        """The main-route edge (not a junction) and lane position (m) at ``s`` (m).

        A position inside a junction is moved to the start of the next edge (SUMO
        detectors cannot sit on junction lanes); on open roads ``s`` must lie in
        ``[0, length_m]``.
        """
        s = float(s)
        if self.periodic:
            s %= self.length_m
        elif not 0.0 <= s <= self.length_m:
            raise ConfigError(f"position s={s} m is outside the road [0, {self.length_m:.2f}] m")
        for i, (edge, s0, s1) in enumerate(self.edge_spans):
            if s0 <= s <= s1:
                return edge, self._pos_on(edge, s)
            if s < s0:  # inside the junction before this edge
                return edge, 0.0
            if i + 1 == len(self.edge_spans) and self.periodic:
                return self.edge_spans[0][0], 0.0
        edge, s0, s1 = self.edge_spans[-1]
        return edge, self._pos_on(edge, s1)

    def _pos_on(self, edge: str, s: float) -> float:
        """Lane position (m) on the middle lane of main-route ``edge`` whose centre is at ``s``."""
        tb = self.tables
        k = tb.index[edge]
        lo = np.searchsorted(tb.tab_key, k * LANE_KEY, side="left")
        hi = np.searchsorted(tb.tab_key, (k + 1) * LANE_KEY, side="left")
        ss = tb.measure.to_s(tb.tab_g[lo:hi])
        pp = tb.tab_key[lo:hi] - k * LANE_KEY
        if self.periodic:  # unwrap the lane's s and bring s next to it
            ss = ss[0] + np.concatenate([[0.0], np.cumsum(wrap(np.diff(ss), self.length_m))])
            s = ss[0] + np.mod(s - ss[0], self.length_m)
        pos = float(np.interp(s, ss, pp))
        # one Newton step on the exact mapping (the table is linear between samples)
        s_at, _ = frame_of(tb, np.array([k]), np.array([pos]), np.zeros(1))
        err = float(s_at[0]) - (s % self.length_m if self.periodic else s)
        if self.periodic:
            err = (err + 0.5 * self.length_m) % self.length_m - 0.5 * self.length_m
        return float(np.clip(pos - err, 0.0, tb.lane_len[k]))


def load_road_network(
    net_file: Path | str,
    *,
    kind: str,
    main_route: Sequence[str],
    ramp_route: Sequence[str] | None = None,
    periodic: bool = False,
    speed_limit_mps: float | None = None,
    offramp_route: Sequence[str] | None = None,
) -> RoadNetwork:
    """Read a ``.net.xml`` with sumolib and compute the road frame of ``main_route``.

    Raises:
        NetworkError: an unreadable file, a route edge missing or without lanes, route
            edges that do not connect, or geometry the frame cannot represent.
    """
    path = Path(net_file)
    net = read_sumo_net(path)
    try:
        road = _road_network(path, net, kind, main_route, ramp_route, periodic,
                             speed_limit_mps, offramp_route)
        if offramp_route:
            road = _with_offramp(road, net, tuple(offramp_route))
        if ramp_route and road.join_index > 0:
            road = _with_entry_strip(road, net)
        return road
    except (TypeError, ValueError, IndexError, KeyError, ZeroDivisionError) as exc:
        # geometry sumolib or the frame cannot handle (missing shapes, positions...)
        msg = str(exc).splitlines()[0] if str(exc) else ""
        raise NetworkError(f"network {path.name}: cannot build the road frame of route "
                           f"{list(main_route)}: {type(exc).__name__}: {msg}") from None


def _road_network(path: Path, net: Any, kind: str, main_route: Sequence[str],
                  ramp_route: Sequence[str] | None, periodic: bool,
                  speed_limit_mps: float | None,
                  offramp_route: Sequence[str] | None = None) -> RoadNetwork:
    """The body of :func:`load_road_network` (errors of unexpected geometry wrapped there)."""
    for eid in (*main_route, *(ramp_route or ())):
        if not net.hasEdge(eid):
            raise NetworkError(f"edge {eid!r} of the route is not in network {path.name}")
        if net.getEdge(eid).getFunction() == "internal":
            raise NetworkError(f"route edge {eid!r} is a junction lane, not an edge")
    if len(set(main_route)) != len(main_route):
        raise NetworkError(f"the main route lists an edge twice: {list(main_route)}")
    lanes = route_lanes(net, main_route, periodic, True, "route")
    if ramp_route:
        if ramp_route[-1] not in main_route:
            raise NetworkError(
                f"ramp route must end on a main-route edge (ends on {ramp_route[-1]!r})"
            )
        known = {g.lane_id for g in lanes}
        lanes += [g for g in route_lanes(net, ramp_route, False, False, "ramp")
                  if g.lane_id not in known]
    off_edges: tuple[str, ...] = ()
    if offramp_route:  # its lanes (and the junction lanes onto it) in the frame: a
        # vehicle on them is seen where SUMO draws it, projected onto the reference line
        diverge = _diverge_edge(net, main_route, offramp_route, path)
        known = {g.lane_id for g in lanes}
        off_edges = tuple(offramp_route)
        lanes += [g for g in route_lanes(net, (diverge, *offramp_route), False, False,
                                         "off-ramp") if g.lane_id not in known]
    line = reference_line(net, main_route, periodic)
    index = {g.lane_id: k for k, g in enumerate(lanes)}
    for eid in (*main_route, *(ramp_route or ()), *off_edges):
        index.setdefault(eid, index[reference_lane(net.getEdge(eid)).getID()])
    tb = build_tables(lanes, line, index)
    measure, chain_off = build_measure(tb, net, main_route, periodic)
    object.__setattr__(tb, "measure", measure)
    find_parallel(tb, chain_off)
    use_lane_coordinates(tb, lane_coordinates(net, tb, main_route, periodic, chain_off),
                          chain_off)
    length = measure.s_period if periodic else float(
        measure.to_s(np.array([line.length]))[0])
    s0, right, left, spans = road_profile(tb, lanes, net, main_route, periodic, length)

    lane_ids = {g.lane_id for g in lanes}
    all_ids = [g.lane_id for g in lanes] + [e for e in index if e not in lane_ids]
    ks = np.array([index[x] for x in all_ids])
    s_start, _ = frame_of(tb, ks, np.zeros(len(ks)), np.zeros(len(ks)))
    _, d_mid = frame_of(tb, ks, 0.5 * tb.lane_len[ks], np.zeros(len(ks)))
    offsets = {x: float(v) for x, v in zip(all_ids, s_start, strict=True)}
    lane_d = {x: round(float(v), 9) for x, v in zip(all_ids, d_mid, strict=True)
              if x in {g.lane_id for g in lanes}}
    if periodic:  # the first edge starts at s = 0 (its lanes may start a little after)
        offsets = {x: (v if v < length - 1e-9 else 0.0) for x, v in offsets.items()}

    merge_s = ramp_len = ramp_width = None
    if ramp_route:
        merge_s = offsets[ramp_route[-1]]
        ramp_len = 0.0
        for k in range(len(ramp_route) - 1):
            edge = net.getEdge(ramp_route[k])
            conn = connections(edge, ramp_route[k + 1])[0]
            ramp_len += conn.getFromLane().getLength()
            ramp_len += sum(ln.getLength() for ln in via_chain(net, conn, ramp_route[k + 1]))
        ramp_width = float(sum(ln.getWidth() for ln in lanes_of(net.getEdge(ramp_route[0]))))
    if speed_limit_mps is None:
        speed_limit_mps = float(reference_lane(net.getEdge(main_route[0])).getSpeed())
    if not speed_limit_mps > 0:
        raise NetworkError(
            f"network {path.name}: the speed limit of edge {main_route[0]!r} must be > 0 m/s "
            f"(got {speed_limit_mps})"
        )
    widths = left - right
    return RoadNetwork(
        net_file=path.resolve(),
        kind=kind,
        main_route=tuple(main_route),
        ramp_route=tuple(ramp_route) if ramp_route else None,
        length_m=float(length),
        width_m=float(widths.max()),
        periodic=periodic,
        speed_limit_mps=float(speed_limit_mps),
        merge_s_m=merge_s,
        ramp_length_m=ramp_len,
        ramp_width_m=ramp_width,
        n_lanes=len(lanes_of(net.getEdge(main_route[0]))),
        lane_offsets=offsets,
        lane_d=lane_d,
        lane_width={g.lane_id: float(g.width) for g in lanes},
        segment_s0=tuple(float(x) for x in s0),
        segment_width=tuple(float(x) for x in widths),
        edge_spans=tuple(spans),
        profile_right=tuple(float(x) for x in right),
        profile_left=tuple(float(x) for x in left),
        tables=tb,
        main_lanes=frozenset([g.lane_id for g in lanes if g.main] + list(main_route)),
    )


def _strip(road: RoadNetwork, lanes: list[str]) -> tuple[float, float, float, float]:
    """``(s_start, s_end, d_right, d_left)`` (m) of route lanes ``lanes`` side by side."""
    tb = road.tables
    keys = np.array([tb.index[x] for x in lanes])
    s_end, _ = frame_of(tb, keys, tb.lane_len[keys], np.zeros(len(keys)))
    right = min(road.lane_d[x] - 0.5 * road.lane_width[x] for x in lanes)
    left = max(road.lane_d[x] + 0.5 * road.lane_width[x] for x in lanes)
    return (float(min(road.lane_offsets[x] for x in lanes)), float(s_end.max()),
            float(right), float(left))


def _with_entry_strip(road: RoadNetwork, net: Any) -> RoadNetwork:
    """``road`` with its acceleration strip: the lanes of the main-route edge the on-ramp
    joins that are reached from the ramp, when they are not all of that edge's lanes."""
    from dataclasses import replace

    i = road.join_index
    edge = net.getEdge(road.ramp_route[i])
    reached = sorted({c.getToLane().getID() for c in connections(
        net.getEdge(road.ramp_route[i - 1]), edge.getID())})
    if not reached or len(reached) == len(lanes_of(edge)):
        return road
    return replace(road, entry_lanes=tuple(reached), entry_strip=_strip(road, reached))


def _diverge_edge(net: Any, main_route: Sequence[str], offramp: Sequence[str],
                  path: Path) -> str:
    """The main-route edge the off-ramp ``offramp`` leaves (the last one with a lane
    connected to its first edge); NetworkError for an off-ramp the frame cannot use."""
    for eid in offramp:
        if not net.hasEdge(eid):
            raise NetworkError(f"edge {eid!r} of the off-ramp route is not in network "
                               f"{path.name}")
    if offramp[0] in main_route:
        raise NetworkError(f"the off-ramp route's first edge {offramp[0]!r} is on the main "
                           f"route: it must leave it")
    diverge = [e for e in main_route if connections(net.getEdge(e), offramp[0])]
    if not diverge:
        raise NetworkError(f"no main-route edge leads onto the off-ramp's first edge "
                           f"{offramp[0]!r}")
    return diverge[-1]


def _with_offramp(road: RoadNetwork, net: Any, offramp: tuple[str, ...]) -> RoadNetwork:
    """``road`` with its off-ramp: the main-route edge it leaves (the last one with lanes
    connected to the off-ramp's first edge), those lanes and their extent in the frame."""
    from dataclasses import replace

    edge = _diverge_edge(net, road.main_route, offramp, road.net_file)
    lanes = sorted({c.getFromLane().getID() for c in connections(net.getEdge(edge), offramp[0])})
    return replace(road, offramp_route=offramp, diverge_edge=edge, exit_lanes=tuple(lanes),
                   exit_strip=_strip(road, lanes))
