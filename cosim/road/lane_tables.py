"""The route's lanes as tables: each lane's geometry as SUMO lays it out, where it lies
along the reference line, and the map from the line's arc length to ``s``.

:func:`route_lanes` reads every lane of a route's edges and of the junction lanes between
them from sumolib (:class:`LaneGeo`); :func:`build_tables` turns them into one set of
global arrays keyed by lane index (:class:`Tables`): per-segment tables of each lane's
shape (SUMO's point ``P(pos) + lat n(pos)`` at lane position ``pos``,
:func:`lane_points`) and a table of the reference line's arc length ``g`` where each lane's
centre projects, sampled at every vertex and at least every :data:`SAMPLE_M`.

``s`` (m) runs as SUMO measures the main route (:class:`Measure`, built by
:func:`build_measure`): lane lengths plus junction lanes, across junctions and the ring's
seam. Lanes that run parallel to the line at a constant offset (:func:`find_parallel`;
every main-route lane once :func:`cosim.road.lane_coordinates.use_lane_coordinates` has
placed it in SUMO's lane coordinates) map as ``s = s0 + pos``, ``d = d0 + lat``; the others
(an on-ramp's lanes until they join the route) are projected onto the line
(:func:`frame_geo`: the segment found from the lane's table of ``g``, then walked to the
segment that holds the foot). :func:`frame_of` is that mapping for lanes on the routes;
:mod:`cosim.road.frame_reference` and the compiled :mod:`cosim.road.frame_kernels` add the
off-route lanes and the inverse.

Lengths and positions in m; a lane's index is its key in :attr:`Tables.index`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cosim.errors import NetworkError
from cosim.road.polyline import FOOT_EPS, MAX_WALK, Line, dedupe
from cosim.road.sumo_net import connections, lanes_of, reference_lane, via_chain

#: Spacing (m) of the per-lane tables of ``s`` and of the road-edge samples
#: (:mod:`cosim.road.profile`).
SAMPLE_M = 1.0
#: Largest angle (degrees) between a route lane and the reference line.
MAX_LANE_ANGLE_DEG = 80.0
#: Key spacing between lanes in the global segment tables (longer than any lane), m: a
#: table key is lane index x LANE_KEY + lane position.
LANE_KEY = float(2**24)
#: A lane counts as parallel to the line when its centre's d varies and its s runs from
#: lane metres by less than this, m.
PARALLEL_TOL_M = 1e-6


@dataclass
class LaneGeo:
    """Build-time data of one lane on a route, as sumolib reads it (:func:`route_lanes`).

    Attributes:
        lane_id, edge_id: SUMO's ids of the lane and its edge.
        width: the lane's width, m.
        length: SUMO's length of the lane (its lane positions run over ``[0, length]``),
            m; may differ from its shape's geometric length.
        shape: the lane's centre line (V, 2), m, V >= 2, no consecutive repeats.
        internal: a junction lane.
        main: on the main route (else on the ramp route only).
        successors: lanes a vehicle may drive onto at its end (junction lanes first).
    """

    lane_id: str
    edge_id: str
    width: float
    length: float
    shape: np.ndarray  # (V, 2)
    internal: bool
    main: bool  # on the main route (else the ramp)
    successors: tuple[str, ...] = ()  # lanes a vehicle may drive onto at the end


def _geo(lane: Any, main: bool) -> LaneGeo:
    """A sumolib lane as :class:`LaneGeo` (a junction lane of no extent: 1 mm long)."""
    shape = dedupe(np.asarray(lane.getShape(), dtype=float)[:, :2])
    if len(shape) == 0:
        raise NetworkError(f"lane {lane.getID()!r} has no shape")
    if len(shape) == 1:  # a junction lane of no extent (SUMO gives it 0.1 m): a point,
        shape = np.vstack([shape, shape + 1e-3 * _direction_near(lane)])  # 1 mm long
    edge = lane.getEdge()
    succ = tuple(c.getViaLaneID() or c.getToLane().getID() for c in lane.getOutgoing())
    return LaneGeo(lane.getID(), edge.getID(), float(lane.getWidth()), float(lane.getLength()),
                   shape, edge.getFunction() == "internal", main, succ)


def _direction_near(lane: Any) -> np.ndarray:
    """Unit direction of the lanes before or after ``lane`` where they touch it."""
    for conn in lane.getOutgoing():
        nxt = dedupe(np.asarray(conn.getToLane().getShape(), dtype=float)[:, :2])
        if len(nxt) >= 2:
            v = nxt[1] - nxt[0]
            return v / np.hypot(*v)
    for prev in lane.getIncoming():
        sh = dedupe(np.asarray(prev.getShape(), dtype=float)[:, :2])
        if len(sh) >= 2:
            v = sh[-1] - sh[-2]
            return v / np.hypot(*v)
    return np.array([1.0, 0.0])


def route_lanes(net: Any, route: Sequence[str], periodic: bool, main: bool,
                what: str) -> list[LaneGeo]:
    """Every lane of the route's edges (sumolib ``net``, edge ids ``route`` in driving
    order; ``periodic``: the last edge leads onto the first) and of the junction lanes
    between them, each once, in route order. ``main``: the route is the main route;
    ``what`` names the route in the error when two edges do not connect."""
    out: list[LaneGeo] = []
    seen: set[str] = set()
    for k, eid in enumerate(route):
        edge = net.getEdge(eid)
        for lane in lanes_of(edge):
            if lane.getID() not in seen:
                out.append(_geo(lane, main))
                seen.add(lane.getID())
        nxt = route[k + 1] if k + 1 < len(route) else (route[0] if periodic else None)
        if nxt is None:
            break
        conns = connections(edge, nxt)
        if not conns:
            raise NetworkError(f"{what} edge {eid!r} is not connected to the next edge {nxt!r}")
        for conn in conns:
            for lane in via_chain(net, conn, nxt):
                if lane.getID() not in seen:
                    out.append(_geo(lane, main))
                    seen.add(lane.getID())
    return out


@dataclass(frozen=True)
class Measure:
    """``s`` as SUMO measures the main route: a monotone map from the reference line's
    arc length ``g`` (m) to lane metres ``s`` (m) through knots ``(g_k, s_k)``.

    The knots are the main route's middle lanes and the junction lanes between them,
    each point at ``s = offset + lane position`` (offsets summing SUMO's lane lengths),
    so a vehicle on those lanes has exactly ``s = offset + pos`` and advances by exactly
    ``v dt`` per step. Open roads extend the map with slope 1 beyond its ends; on the ring
    ``g`` and ``s`` wrap (at ``g_period`` and ``s_period``).

    Attributes:
        g, s: the knots (n,) m, both increasing.
        periodic: the ring.
        g_period: the reference line's length, m.
        s_period: the main route's length as SUMO measures it, m.
    """

    g: np.ndarray
    s: np.ndarray
    periodic: bool
    g_period: float
    s_period: float

    def to_s(self, g: np.ndarray) -> np.ndarray:
        """``s`` (m, same shape) at arc lengths ``g`` (m) of the reference line."""
        g = np.asarray(g, dtype=float)
        if self.periodic:
            x = self.g[0] + np.mod(g - self.g[0], self.g_period)
            return np.mod(np.interp(x, self.g, self.s), self.s_period)
        return _interp_ext(g, self.g, self.s)

    def to_g(self, s: np.ndarray) -> np.ndarray:
        """Arc length ``g`` (m, same shape) of the reference line at ``s`` (m)."""
        s = np.asarray(s, dtype=float)
        if self.periodic:
            x = self.s[0] + np.mod(s - self.s[0], self.s_period)
            return np.mod(np.interp(x, self.s, self.g), self.g_period)
        return _interp_ext(s, self.s, self.g)


def _interp_ext(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """np.interp with slope-1 extension beyond the knots."""
    y = np.interp(x, xp, fp)
    y = np.where(x < xp[0], fp[0] + (x - xp[0]), y)
    return np.where(x > xp[-1], fp[-1] + (x - xp[-1]), y)


@dataclass(frozen=True)
class Tables:
    """Run-time tables of every route lane (global arrays, keyed by lane index).

    Segment tables: ``seg_key`` = lane index x :data:`LANE_KEY` + lane position (m)
    where the segment starts; start point, unit tangent and left normal; ``seg_scale`` =
    geometric length per unit of lane position. ``s`` tables: ``tab_key`` as above and
    ``tab_g`` the (unwrapped) arc length of the reference line where the lane's centre
    projects there; ``measure`` turns arc length into ``s``.

    Attributes (L lanes, G lane segments in all, T samples in all; m unless told):
        index: lane id -> lane index; a route edge's id -> its middle lane's index.
        lane_len: SUMO's length of each lane (L,).
        next_lane: the route lane a vehicle drives onto at each lane's end, -1 none (L,).
        seg_key, seg_p0: key and lane position where each segment starts (G,).
        seg_a, seg_t, seg_n: start point, unit tangent, unit left normal (G, 2).
        seg_scale: geometric metres per lane metre (G,).
        tab_key, tab_g: key and reference-line arc length of each sample (T,).
        line: the reference line (:class:`~cosim.road.polyline.Line`).
        measure: arc length -> ``s`` (:func:`build_measure`; set once built).
        par, par_s0, par_d0: lanes mapped as ``s = s0 + pos``, ``d = d0 + lat`` (L,)
            (:func:`find_parallel`, then SUMO's lane coordinates on the main route).
        chain_keys, chain_s0: the main route's chain of lanes (middle lanes and the
            junction lanes between them) in order of ``s``, and ``s`` where each starts.

    Built by :func:`build_tables`; ``measure`` and the parallel lanes are filled in
    afterwards (:func:`cosim.road.frame.load_road_network`).
    """

    index: dict[str, int]
    lane_len: np.ndarray
    next_lane: np.ndarray
    seg_key: np.ndarray
    seg_p0: np.ndarray
    seg_a: np.ndarray
    seg_t: np.ndarray
    seg_n: np.ndarray
    seg_scale: np.ndarray
    tab_key: np.ndarray
    tab_g: np.ndarray
    line: Line
    measure: Measure | None = None
    par: np.ndarray | None = None  # (lanes,) bool: the lane runs parallel to the line
    par_s0: np.ndarray | None = None  # (lanes,) s of its position 0, m
    par_d0: np.ndarray | None = None  # (lanes,) d of its centre, m
    chain_keys: np.ndarray | None = None  # the main route's chain of lanes, in order of s
    chain_s0: np.ndarray | None = None  # s (m) where each of them starts
    _kernel_args: tuple | None = field(default=None, repr=False, compare=False)

    def kernel_args(self) -> tuple:
        """The tables as one tuple for :func:`cosim.road.frame_kernels.geo_frame` and
        ``geo_lateral`` (built once, after the measure and the parallel lanes are known)."""
        if self._kernel_args is None:
            c = np.ascontiguousarray
            line, m = self.line, self.measure
            n = len(self.lane_len)
            par = np.zeros(n, dtype=bool) if self.par is None else self.par
            s0 = np.zeros(n) if self.par_s0 is None else self.par_s0
            d0 = np.zeros(n) if self.par_d0 is None else self.par_d0
            args = (
                c(self.lane_len, float), c(self.next_lane, np.int64), c(self.seg_key, float),
                c(self.seg_p0, float), c(self.seg_scale, float), c(self.seg_a, float),
                c(self.seg_t, float), c(self.seg_n, float), c(self.tab_key, float),
                c(self.tab_g, float), c(line.pts, float), c(line.cum, float),
                c(line.tan, float), c(line.seg, float), bool(line.periodic),
                c(m.g, float), c(m.s, float), bool(m.periodic), float(m.g_period),
                float(m.s_period), self.par is not None, c(par, bool), c(s0, float),
                c(d0, float), float(LANE_KEY), int(MAX_WALK), float(FOOT_EPS),
            )
            object.__setattr__(self, "_kernel_args", args)
        return self._kernel_args


def _next_lanes(lanes: list[LaneGeo], index: dict[str, int]) -> np.ndarray:
    """For each route lane, the index of the route lane a vehicle drives onto at its end
    (-1: none on the routes)."""
    out = np.full(len(lanes), -1, dtype=np.int64)
    for k, g in enumerate(lanes):
        for nxt in g.successors:
            if nxt in index:
                out[k] = index[nxt]
                break
    return out


def build_tables(lanes: list[LaneGeo], line: Line, index: dict[str, int]) -> Tables:
    """Segment tables and ``s`` tables of every route lane (see :class:`Tables`): lane
    ``k`` is ``lanes[k]``; ``index`` maps ids to lane indices. Raises NetworkError for a
    lane that runs backwards along ``line`` or meets it at more than
    :data:`MAX_LANE_ANGLE_DEG`."""
    seg_key, seg_p0, seg_a, seg_t, seg_n, seg_scale = [], [], [], [], [], []
    tab_key, tab_g = [], []
    lane_len = np.empty(len(lanes))
    max_cos = math.cos(math.radians(MAX_LANE_ANGLE_DEG))
    for k, g in enumerate(lanes):
        d = np.diff(g.shape, axis=0)
        seg = np.hypot(d[:, 0], d[:, 1])
        geo_len = float(seg.sum())
        length = g.length if g.length > 0 else geo_len
        scale = geo_len / length if length > 0 else 1.0  # geometry metres per lane metre
        cum = np.concatenate([[0.0], np.cumsum(seg)]) / scale  # lane positions of vertices
        lane_len[k] = length
        t = d / seg[:, None]
        seg_key.append(k * LANE_KEY + cum[:-1])
        seg_p0.append(cum[:-1])
        seg_a.append(g.shape[:-1])
        seg_t.append(t)
        seg_n.append(np.column_stack([-t[:, 1], t[:, 0]]))
        seg_scale.append(np.full(len(seg), scale))
        # s along the lane, at every vertex and at least every SAMPLE_M
        n_sub = np.maximum(1, np.ceil(seg / SAMPLE_M).astype(int))
        p = np.concatenate([np.linspace(cum[i], cum[i + 1], n_sub[i], endpoint=False)
                            for i in range(len(seg))] + [cum[-1:]])
        xy = np.column_stack([np.interp(p * scale, cum * scale, g.shape[:, 0]),
                              np.interp(p * scale, cum * scale, g.shape[:, 1])])
        s, _, _ = line.nearest(xy)
        if line.periodic:  # unwrap across the ring's seam
            s = s[0] + np.concatenate([[0.0], np.cumsum(wrap(np.diff(s), line.length))])
        back = np.diff(s)
        if len(back) and back.min() < -0.05:
            i = int(np.argmin(back))
            raise NetworkError(
                f"lane {g.lane_id!r} runs backwards along the main route (s falls by "
                f"{-back[i]:.2f} m near lane position {p[i]:.1f} m): the road frame cannot "
                "represent it"
            )
        # angle between each lane segment and the line where its middle projects
        mid = 0.5 * (g.shape[:-1] + g.shape[1:])
        _, _, jm = line.nearest(mid)
        cos = np.abs(np.einsum("ij,ij->i", t, line.tan[jm]))
        if cos.min() < max_cos:
            i = int(np.argmin(cos))
            ang = math.degrees(math.acos(min(1.0, float(cos[i]))))
            raise NetworkError(
                f"lane {g.lane_id!r} meets the main route at {ang:.0f} degrees near lane "
                f"position {cum[i]:.1f} m (more than {MAX_LANE_ANGLE_DEG:g}): the road frame "
                "cannot represent it"
            )
        tab_key.append(k * LANE_KEY + p)
        tab_g.append(s)
    return Tables(
        index=index,
        lane_len=lane_len,
        next_lane=_next_lanes(lanes, index),
        seg_key=np.concatenate(seg_key),
        seg_p0=np.concatenate(seg_p0),
        seg_a=np.concatenate(seg_a),
        seg_t=np.concatenate(seg_t),
        seg_n=np.concatenate(seg_n),
        seg_scale=np.concatenate(seg_scale),
        tab_key=np.concatenate(tab_key),
        tab_g=np.concatenate(tab_g),
        line=line,
    )


def wrap(x: np.ndarray, period: float) -> np.ndarray:
    """Differences ``x`` (m, any shape) brought into [-period/2, period/2] by whole
    periods (``period`` m): ``x - period * round(x / period)``."""
    return x - period * np.round(x / period)


def build_measure(tb: Tables, net: Any, route: Sequence[str],
                  periodic: bool) -> tuple[Measure, dict[int, float]]:
    """The knots of :class:`Measure` along the main route's middle lanes and junction
    lanes (``route``: the main route's edge ids), and the offset (m, SUMO's lane lengths
    summed) of each of those lanes: lane index -> ``s`` of its position 0."""
    gs, ss = [], []
    chain_off: dict[int, float] = {}
    off = 0.0
    for k, eid in enumerate(route):
        edge = net.getEdge(eid)
        ref = reference_lane(edge)
        chain = [ref]
        nxt = route[k + 1] if k + 1 < len(route) else (route[0] if periodic else None)
        if nxt is not None:
            conns = connections(edge, nxt)
            conn = next((c for c in conns if c.getFromLane() is ref), conns[0])
            chain = [conn.getFromLane(), *via_chain(net, conn, nxt)]
        for lane in chain:
            i = tb.index[lane.getID()]
            lo = np.searchsorted(tb.tab_key, i * LANE_KEY, side="left")
            hi = np.searchsorted(tb.tab_key, (i + 1) * LANE_KEY, side="left")
            gs.append(tb.tab_g[lo:hi])
            ss.append(off + tb.tab_key[lo:hi] - i * LANE_KEY)
            chain_off.setdefault(i, off)
            off += float(tb.lane_len[i])
    g = np.concatenate(gs)
    s = np.concatenate(ss)
    if periodic:
        g = g[0] + np.concatenate([[0.0], np.cumsum(wrap(np.diff(g), tb.line.length))])
    # one knot per g (junction lanes may touch the same g twice), increasing
    g = np.maximum.accumulate(g)
    keep = np.concatenate([[True], np.diff(g) > 1e-9])
    g, s = g[keep], s[keep]
    if periodic:  # close the loop: one full turn of g is one full turn of s
        g = np.concatenate([g, [g[0] + tb.line.length]])
        s = np.concatenate([s, [off]])
        keep = np.concatenate([np.diff(g) > 1e-9, [True]])
        g, s = g[keep], s[keep]
    return Measure(g, s, periodic, tb.line.length, off), chain_off


def find_parallel(tb: Tables, chain_off: dict[int, float]) -> None:
    """Mark the lanes that run parallel to the line at a constant offset (their ``s`` is
    the lane position plus a constant, ``d`` the lateral position plus a constant) and
    store those constants (``tb.par``, ``tb.par_s0``, ``tb.par_d0``, each (L,), set in
    place); a lane of the measure's chain keeps SUMO's offset exactly (``chain_off``: lane
    index -> ``s`` of its position 0, m, from :func:`build_measure`)."""
    n = len(tb.lane_len)
    par = np.zeros(n, dtype=bool)
    s0 = np.zeros(n)
    d0 = np.zeros(n)
    period = tb.measure.s_period if tb.measure.periodic else None
    starts = np.searchsorted(tb.tab_key, np.arange(n + 1) * LANE_KEY, side="left")
    for k in range(n):
        p = tb.tab_key[starts[k]:starts[k + 1]] - k * LANE_KEY
        s, d = frame_geo(tb, np.full(len(p), k), p, np.zeros(len(p)))
        if period is not None:
            s = s[0] + np.concatenate([[0.0], np.cumsum(wrap(np.diff(s), period))])
        lag = s - p
        if np.ptp(d) < PARALLEL_TOL_M and np.ptp(lag) < PARALLEL_TOL_M:
            par[k] = True
            s0[k] = chain_off.get(k, float(lag[0]))
            d0[k] = round(float(d[0]), 9)
    object.__setattr__(tb, "par", par)
    object.__setattr__(tb, "par_s0", s0)
    object.__setattr__(tb, "par_d0", d0)


def lane_points(tb: Tables, k: np.ndarray, pos: np.ndarray):
    """``(point, normal, key)``: centre point (K, 2) m and unit left normal (K, 2) of lanes
    ``k`` (K,) at lane positions ``pos`` (K,) m (clamped to the lane), as SUMO computes
    them; also the table key (K,) of each."""
    p = np.clip(pos, 0.0, tb.lane_len[k])
    key = k * LANE_KEY + p
    i = np.searchsorted(tb.seg_key, key, side="right") - 1
    along = (p - tb.seg_p0[i]) * tb.seg_scale[i]
    pt = tb.seg_a[i] + along[:, None] * tb.seg_t[i]
    return pt, tb.seg_n[i], key


def frame_of(tb: Tables, k: np.ndarray, pos: np.ndarray, lat: np.ndarray):
    """``(s, d)`` (K,) m each of SUMO positions on route lanes ``k`` (K,) (every one >= 0)
    at lane positions ``pos`` and lateral lane positions ``lat`` (K,) m (the core of
    ``RoadNetwork.lane_frame``); a position beyond a lane's ends continues along ``s``
    from the end.

    A lane parallel to the reference line at a constant offset (every lane of the
    networks cosim builds, a user's straight lanes) maps exactly as ``s = s0 + pos``,
    ``d = d0 + lat``; the others are projected (:func:`frame_geo`).
    """
    if tb.par is None:
        return frame_geo(tb, k, pos, lat)
    par = tb.par[k]
    if par.all():
        s, d = tb.par_s0[k] + pos, tb.par_d0[k] + lat
    else:
        s, d = frame_geo(tb, k, pos, lat)
        s = np.where(par, tb.par_s0[k] + pos, s)
        d = np.where(par, tb.par_d0[k] + lat, d)
    if tb.measure.periodic:
        s = np.mod(s, tb.measure.s_period)
    return s, d


def frame_geo(tb: Tables, k: np.ndarray, pos: np.ndarray, lat: np.ndarray):
    """``(s, d)`` (K,) m as :func:`frame_of`, every lane by projecting SUMO's point onto the
    reference line (needs ``tb.measure``)."""
    pt, nrm, key = lane_points(tb, k, pos)
    xy = pt + lat[:, None] * nrm
    g_est = np.interp(key, tb.tab_key, tb.tab_g)
    g, d = tb.line.project(xy, tb.line.segment_of(g_est))
    s = tb.measure.to_s(g)
    beyond = pos - np.clip(pos, 0.0, tb.lane_len[k])
    if beyond.any():
        s = s + beyond
        if tb.measure.periodic:
            s = np.mod(s, tb.measure.s_period)
    return s, d


def lane_cos(tb: Tables, k: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """``d`` per metre of lateral lane position (K,) (the cosine of the lane's angle to the
    line) on lanes ``k`` (K,) at lane positions ``pos`` (K,) m."""
    pt, nrm, key = lane_points(tb, k, pos)
    line = tb.line
    j = line.holding(pt, line.segment_of(np.interp(key, tb.tab_key, tb.tab_g)))
    t = line.tan[j]
    return t[:, 0] * nrm[:, 1] - t[:, 1] * nrm[:, 0]
