"""The road frame on a SUMO network: ``s`` along the main route, ``d`` across it.

:func:`load_road_network` reads a ``.net.xml`` with sumolib and builds the frame of the
main route (with its on-ramps and off-ramps, :mod:`cosim.road.ramps`) from the lanes' real
geometry, as SUMO lays them out: :class:`RoadNetwork`. ``s`` (m) runs as SUMO measures the
main route (its lanes' lengths plus the junction lanes between them), across junctions and
the ring's seam;
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

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from controllers.observation import RoadProfile
from cosim.errors import ConfigError, NetworkError
from cosim.road import ramps as R
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
from cosim.road.ramps import OffRamp, OnRamp
from cosim.road.reference_line import reference_line
from cosim.road.sumo_net import (
    lanes_of,
    read_sumo_net,
    reference_lane,
)


@dataclass(frozen=True)
class RoadNetwork:
    """A built SUMO network and its road frame (see the module docstring).

    Attributes:
        net_file: the ``.net.xml``.
        kind: the spec's kind.
        main_route: edge ids of the main route in driving order; ``s`` is
            continuous along them (and across the junction lanes between them).
        length_m: length of the main route as SUMO measures it (its lanes plus the
            junction lanes between them), m; on the ring the circumference (``s`` wraps
            there).
        width_m: widest width of the main road (right to left edge), m.
        periodic: True on the ring: ``s`` wraps at ``length_m``.
        speed_limit_mps: speed limit on the main route.
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
        ramps, offramps: the on-ramps (:class:`~cosim.road.ramps.OnRamp`: route, merge
            point, entry strip) and off-ramps (:class:`~cosim.road.ramps.OffRamp`: route,
            diverge edge, exit strip), in the order given; ``ramp_route``,
            ``merge_s_m``, ``ramp_length_m`` and ``ramp_width_m`` are the first on-ramp's.

    The ring keeps vehicles circling through routes with a ``repeat``
    attribute: :meth:`ring_route_edges` gives the loop starting on a given
    edge and :mod:`cosim.demand` writes ``<route edges=... repeat=N>`` with N
    large enough for the run (SUMO then repeats the edge list N more times).
    """

    net_file: Path
    kind: str
    main_route: tuple[str, ...]
    length_m: float
    width_m: float
    periodic: bool
    speed_limit_mps: float
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
    #: the on-ramps and off-ramps (:mod:`cosim.road.ramps`), in the order given
    ramps: tuple[OnRamp, ...] = ()
    offramps: tuple[OffRamp, ...] = ()
    #: kind ``file``: the user's file, when ``net_file`` is a copy of it without the forks
    #: at the main route's joints (:mod:`cosim.road.forks`), and the connections taken out
    #: ``(from edge, to edge, from lane, to lane)``
    source_file: Path | None = None
    forks_removed: tuple[tuple[str, str, int, int], ...] = ()

    # ---- the first on-ramp (the onramp and corridor kinds have one) --------------------

    @property
    def ramp_route(self) -> tuple[str, ...] | None:
        """The first on-ramp's route, or None."""
        return self.ramps[0].route if self.ramps else None

    @property
    def merge_s_m(self) -> float | None:
        """The first on-ramp's :attr:`OnRamp.merge_s_m` (m), or None."""
        return self.ramps[0].merge_s_m if self.ramps else None

    @property
    def ramp_length_m(self) -> float | None:
        """The first on-ramp's :attr:`OnRamp.length_m` (m), or None."""
        return self.ramps[0].length_m if self.ramps else None

    @property
    def ramp_width_m(self) -> float | None:
        """The first on-ramp's width (m), or None."""
        return self.ramps[0].width_m if self.ramps else None

    @property
    def exit_strips(self) -> np.ndarray | None:
        """(K, 4) the off-ramps' exit strips ``(s_start, s_gore, d_right, d_left)`` (m), in
        the order of :attr:`offramps`; None without one."""
        return (np.array([o.exit_strip for o in self.offramps], dtype=float)
                if self.offramps else None)

    @property
    def entry_strips(self) -> np.ndarray | None:
        """(J, 4) the on-ramps' acceleration strips ``(s_start, s_end, d_right, d_left)``
        (m); None when no on-ramp joins beside the road."""
        rows = [r.entry_strip for r in self.ramps if r.entry_strip is not None]
        return np.array(rows, dtype=float) if rows else None

    @property
    def lane_based(self) -> bool:
        """True for the lane-based baseline (``three_lane``: SUMO's LC2013 drivers keep
        lanes). Every other road, a user's multi-lane network included, is lane-free:
        SUMO's sublane model, the lanes only carry the geometry."""
        return self.kind == "three_lane" or (self.kind == "corridor" and self.n_lanes > 1)

    # ---- origins, destinations and their routes -----------------------------------------

    @property
    def origins(self) -> tuple[str, ...]:
        """Where traffic enters an open road: ``"main"`` (the main route's start) and its
        on-ramps (``"ramp"``, ``"ramp2"``, ...)."""
        if self.periodic:
            return ()
        return ("main", *(r.name for r in self.ramps))

    @property
    def destinations(self) -> tuple[str, ...]:
        """Where traffic leaves: ``"main"`` (the main route's end) and its off-ramps'
        ends (``"off"``, ``"off2"``, ...)."""
        if self.periodic:
            return ()
        return ("main", *(o.name for o in self.offramps))

    def exit_number(self, destination: str) -> int:
        """0 for ``"main"`` (the road's end), k >= 1 for the k-th off-ramp's name (the
        observation's ``exit_index``)."""
        if destination == "main":
            return 0
        return 1 + [o.name for o in self.offramps].index(destination)

    def od_route(self, origin: str, destination: str) -> tuple[str, ...]:
        """SUMO's edges from ``origin`` to ``destination`` (:attr:`origins`,
        :attr:`destinations`): an on-ramp's edges join the main route where its route
        ends; an off-ramp's leave it at its diverge edge. Raises ConfigError for a pair the
        network does not connect (an off-ramp before the on-ramp)."""
        if origin not in self.origins or destination not in self.destinations:
            raise ConfigError(f"no route from {origin!r} to {destination!r} on this network "
                              f"(origins {', '.join(self.origins)}; destinations "
                              f"{', '.join(self.destinations)})")
        main = self.main_route
        edges: list[str] = []
        first = 0
        if origin != "main":
            ramp = self.ramps[self.origins.index(origin) - 1]
            i = ramp.join_index
            edges, first = list(ramp.route[:i]), main.index(ramp.route[i])
        if destination != "main":
            off = self.offramps[self.exit_number(destination) - 1]
            leave = main.index(off.diverge_edge)
            if leave < first:
                raise ConfigError(f"no route from {origin!r} to {destination!r}: the "
                                  f"off-ramp leaves the road before the on-ramp joins it")
            return (*edges, *main[first:leave + 1], *off.route)
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
    ramp_routes: Sequence[Sequence[str]] = (),
    periodic: bool = False,
    speed_limit_mps: float | None = None,
    offramp_routes: Sequence[Sequence[str]] = (),
) -> RoadNetwork:
    """Read a ``.net.xml`` with sumolib and compute the road frame of ``main_route``, with
    its on-ramps ``ramp_routes`` (each ramp edge(s) then the main-route edge it joins) and
    off-ramps ``offramp_routes`` (each leaves a main-route edge with its first edge).

    Raises:
        NetworkError: an unreadable file, a route edge missing or without lanes, route
            edges that do not connect, or geometry the frame cannot represent.
    """
    path = Path(net_file)
    net = read_sumo_net(path)
    try:
        return _road_network(path, net, kind, main_route, [tuple(r) for r in ramp_routes],
                             periodic, speed_limit_mps, [tuple(r) for r in offramp_routes])
    except (TypeError, ValueError, IndexError, KeyError, ZeroDivisionError) as exc:
        # geometry sumolib or the frame cannot handle (missing shapes, positions...)
        msg = str(exc).splitlines()[0] if str(exc) else ""
        raise NetworkError(f"network {path.name}: cannot build the road frame of route "
                           f"{list(main_route)}: {type(exc).__name__}: {msg}") from None


def _road_network(path: Path, net: Any, kind: str, main_route: Sequence[str],
                  ramp_routes: list[tuple[str, ...]], periodic: bool,
                  speed_limit_mps: float | None,
                  offramp_routes: list[tuple[str, ...]]) -> RoadNetwork:
    """The body of :func:`load_road_network` (errors of unexpected geometry wrapped there)."""
    for eid in main_route:
        if not net.hasEdge(eid):
            raise NetworkError(f"edge {eid!r} of the route is not in network {path.name}")
        if net.getEdge(eid).getFunction() == "internal":
            raise NetworkError(f"route edge {eid!r} is a junction lane, not an edge")
    if len(set(main_route)) != len(main_route):
        raise NetworkError(f"the main route lists an edge twice: {list(main_route)}")
    lanes = route_lanes(net, main_route, periodic, True, "route")
    known = {g.lane_id for g in lanes}
    for ramp in ramp_routes:
        R.check_ramp_edges(net, path, ramp, "ramp")
        R.join_index(ramp, main_route, path)
        lanes += [g for g in route_lanes(net, ramp, False, False, "ramp")
                  if g.lane_id not in known]
        known |= {g.lane_id for g in lanes}
    diverges: set[str] = set()
    for off in offramp_routes:  # its lanes (and the junction lanes onto it) in the frame:
        # a vehicle on them is seen where SUMO draws it, projected onto the reference line
        diverge = R.diverge_edge(net, main_route, off, path)
        if diverge in diverges:
            raise NetworkError(f"two off-ramps leave main-route edge {diverge!r}: give "
                               f"each off-ramp its own diverge edge")
        diverges.add(diverge)
        lanes += [g for g in route_lanes(net, (diverge, *off), False, False, "off-ramp")
                  if g.lane_id not in known]
        known |= {g.lane_id for g in lanes}
    line = reference_line(net, main_route, periodic)
    index = {g.lane_id: k for k, g in enumerate(lanes)}
    for eid in (*main_route, *(e for r in (*ramp_routes, *offramp_routes) for e in r)):
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

    if speed_limit_mps is None:
        speed_limit_mps = float(reference_lane(net.getEdge(main_route[0])).getSpeed())
    if not speed_limit_mps > 0:
        raise NetworkError(
            f"network {path.name}: the speed limit of edge {main_route[0]!r} must be > 0 m/s "
            f"(got {speed_limit_mps})"
        )
    widths = left - right
    road = RoadNetwork(
        net_file=path.resolve(),
        kind=kind,
        main_route=tuple(main_route),
        length_m=float(length),
        width_m=float(widths.max()),
        periodic=periodic,
        speed_limit_mps=float(speed_limit_mps),
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
    lane_width = road.lane_width
    strip_of = functools.partial(R.strip, tb, offsets, lane_d, lane_width)
    return replace(
        road,
        ramps=tuple(R.on_ramp(net, k, r, main_route, path, offsets, strip_of)
                    for k, r in enumerate(ramp_routes)),
        offramps=tuple(R.off_ramp(net, k, r, main_route, path, strip_of)
                       for k, r in enumerate(offramp_routes)))
