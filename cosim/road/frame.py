"""The road frame on a SUMO network: ``s`` along the main route, ``d`` across it.

:func:`load_road_network` reads a ``.net.xml`` with sumolib and builds the frame of the
main route (and an optional ramp route) from the lanes' real geometry, as SUMO lays
them out: :class:`RoadNetwork`.

The reference line (:func:`_reference_line`): the centre line of the main route's lanes,
edge after edge, joined through the junction lanes SUMO drives on (an edge whose lanes sit
elsewhere relative to the edge as drawn than the first edge's is moved sideways onto the
first edge's course and joined by a smooth curve). It serves the parts of the network
that are not on the main route (an on-ramp before it joins) and the measure: ``s`` (m)
runs as SUMO measures the main route (lane lengths plus junction lanes:
:class:`_Measure`), across junctions and the ring's seam. ``d`` (m) is positive to the
left. On the networks :mod:`cosim.road.build` generates (every edge
``spreadType="center"``) ``d`` is SUMO's lateral lane position. An on-ramp's lanes lie
right of the main road until they merge: a ramp vehicle's ``d`` is beyond the main road's
right edge, and its ``s`` advances by ``v dt cos(angle)`` (the main road's direction).

Mapping a vehicle (:meth:`RoadNetwork.lane_frame`): SUMO's lane coordinates on the main
route (:mod:`cosim.road.lane_coordinates`). SUMO moves a vehicle from a lane onto the
junction lane and the next lane keeping its lateral lane position (``MSLink``'s lateral
shift applies only where lane shapes do not meet, never on netconvert's networks), and
its collision check and drivers compare those positions. So every main-route lane maps as
``s = s0 + pos``, ``d = d0 + lat``: ``s0`` sums SUMO's lane lengths along the route,
``d0`` carries the lateral position across every connection from the first edge
(centred on its middle lane, or the border between its two middle lanes); an edge's other
lanes lie beside its route lane as the edge lays them out, and a junction lane beside the
route's (where the lane count changes) carries the lateral position of the lane it
leaves, as SUMO does. Where a narrower edge built with netconvert's defaults hangs from
the wider one's left border, SUMO draws a vehicle that keeps its lateral position jumping
sideways along the short junction lane; in its coordinates, and so in ours, the vehicle
drives straight, and the neck lies centred (what the law keeps apart SUMO keeps apart:
tests/test_user_roads.py). :meth:`RoadNetwork.xy_of` maps ``(s, d)`` back to SUMO's x, y
(SUMO's point ``P(pos) + lat n(pos)`` on the route lane at ``s``: ``geometryPositionAt
Offset``). An on-ramp's lanes, until they join the route, are projected onto the line (the
segment found from a per-lane table of ``s``, sampled every :data:`SAMPLE_M`, then walked
to the segment that holds the foot). The inverse (:meth:`RoadNetwork.lateral_lane_position`)
gives the ``lat`` that puts a vehicle at a road-frame ``d`` where it will be after the
step. Both are vectorised over vehicles; lanes are looked up in a dict (no per-vehicle
geometry in Python).

The road's edges along ``s`` (:meth:`RoadNetwork.profile`): the outer borders of the
main route's lanes (right border of the rightmost, left border of the leftmost), in the
frame, sampled every :data:`SAMPLE_M`; across a junction they are the junction lanes' own
borders, so a width change is a step at the junction lane's start, as SUMO sees it
(where an edge adds a lane beside the road, e.g. an on-ramp's acceleration lane, the
added lane's border holds from the junction's start). Right and left edges
are independent (asymmetric roads are fine). The
profile is piecewise constant: flat stretches are one piece each, and where an edge
moves the pieces are short enough that it moves by at most :data:`PROFILE_TOL_M` within
one; each piece takes the narrower value (the road is never wider than SUMO's).

What the frame refuses (one :class:`~cosim.errors.NetworkError` line): route edges that
do not connect or repeat, an edge without lanes, a lane that runs backwards along the
route or meets it at more than :data:`MAX_LANE_ANGLE_DEG`, lanes of one edge that cross,
a route that turns back on itself, and geometry sumolib cannot read.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from controllers.observation import RoadProfile
from cosim.errors import ConfigError, NetworkError
from cosim.road.lane_coordinates import lane_coordinates, use_lane_coordinates
from cosim.road.sumo_net import (
    connections,
    lanes_of,
    read_sumo_net,
    reference_lane,
    via_chain,
)

#: Spacing (m) of the per-lane tables of ``s`` and of the road-edge samples.
SAMPLE_M = 1.0
#: Largest change (m) of a road edge within one piece of the profile.
PROFILE_TOL_M = 0.02
#: Largest angle (degrees) between a route lane and the reference line.
MAX_LANE_ANGLE_DEG = 80.0
#: Key spacing between lanes in the global segment tables (longer than any lane), m.
_LANE_KEY = float(2**24)
#: Most segments a projection walks from its first guess.
_MAX_WALK = 64
#: Slack (m) when deciding whether a projection's foot lies inside a segment.
_FOOT_EPS = 1e-6
#: Up to this many segments :meth:`_Line.nearest` measures every point against all.
_NEAREST_ALL_MAX = 64


# --------------------------------------------------------------------------------------
# Geometry: the reference line and the lanes' tables (plain numpy)
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Line:
    """A polyline: points (M+1, 2), cumulative length (M+1,), unit tangents and left
    normals (M, 2), segment lengths (M,); ``periodic``: the last point is the first."""

    pts: np.ndarray
    cum: np.ndarray
    tan: np.ndarray
    nrm: np.ndarray
    seg: np.ndarray
    periodic: bool

    @classmethod
    def of(cls, pts: np.ndarray, periodic: bool) -> _Line:
        pts = np.asarray(pts, dtype=float)
        d = np.diff(pts, axis=0)
        seg = np.hypot(d[:, 0], d[:, 1])
        tan = d / seg[:, None]
        nrm = np.column_stack([-tan[:, 1], tan[:, 0]])
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        return cls(pts, cum, tan, nrm, seg, periodic)

    @property
    def length(self) -> float:
        return float(self.cum[-1])

    @property
    def n_seg(self) -> int:
        return len(self.seg)

    def segment_of(self, s: np.ndarray) -> np.ndarray:
        """Index of the segment that holds each ``s`` (m; clamped at the ends)."""
        if self.periodic:
            s = np.mod(s, self.length)
        j = np.searchsorted(self.cum, s, side="right") - 1
        return np.clip(j, 0, self.n_seg - 1)

    def project_on(self, xy: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(along, d): foot of each point on the infinite line of segment ``j`` (m from the
        segment's start) and the signed distance (m, left positive)."""
        v = xy - self.pts[j]
        t = self.tan[j]
        along = v[:, 0] * t[:, 0] + v[:, 1] * t[:, 1]
        d = t[:, 0] * v[:, 1] - t[:, 1] * v[:, 0]
        return along, d

    def holding(self, xy: np.ndarray, j: np.ndarray) -> np.ndarray:
        """The segment on which each point's foot lies, walking from ``j`` (a guess)
        segment by segment; where no segment holds it (the outside of a bend) the last
        one the walk reached."""
        j = j.copy()
        n = self.n_seg
        last = np.zeros(len(j), dtype=int)
        active = np.ones(len(j), dtype=bool)
        for _ in range(_MAX_WALK):
            a, _ = self.project_on(xy, j)
            step = np.where(a > self.seg[j] + _FOOT_EPS, 1, np.where(a < -_FOOT_EPS, -1, 0))
            if not self.periodic:  # an open line is extended beyond its ends
                step[(j == 0) & (step < 0)] = 0
                step[(j == n - 1) & (step > 0)] = 0
            step[~active | (step == -last)] = 0  # a reversal: the outside of a bend
            if not step.any():
                break
            active &= step != 0
            j = np.mod(j + step, n) if self.periodic else j + step
            last = np.where(step != 0, step, last)
        return j

    def project(self, xy: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(s, d)`` of points ``xy`` (K, 2), m: the foot on segment ``j`` (a guess) or on a
        neighbour that holds it (:meth:`holding`); an open line is extended beyond its ends."""
        j = self.holding(xy, j)
        a, d = self.project_on(xy, j)
        s = self.cum[j] + a
        if self.periodic:
            s = np.mod(s, self.length)
        return s, d

    def _inside(self, along: np.ndarray, j: np.ndarray) -> np.ndarray:
        lo = along >= -_FOOT_EPS
        hi = along <= self.seg[j] + _FOOT_EPS
        if not self.periodic:
            lo |= j == 0
            hi |= j == self.n_seg - 1
        return lo & hi

    def nearest(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(s, d, j)`` (K,) each of the nearest point of the line to each point ``xy``
        (K, 2) m (open lines are extended beyond their ends). Build-time only.

        Each point is measured against the segments that can hold its nearest point
        (:meth:`_candidates`: O(K log M) with a tree of the segments' middles, not K x M);
        :meth:`_nearest_among` measures them as the full search would, so the answer is
        the same to the bit (tests/test_road_frame.py)."""
        if self.n_seg <= _NEAREST_ALL_MAX or len(xy) == 0:
            return self._nearest_among(xy, None)
        return self._nearest_among(xy, self._candidates(xy))

    @cached_property
    def _middles(self):
        """A tree of the segments' middles and the longest half segment, m."""
        from scipy.spatial import cKDTree  # scipy: imported when first used

        return cKDTree(0.5 * (self.pts[:-1] + self.pts[1:])), 0.5 * float(self.seg.max())

    def _candidates(self, xy: np.ndarray) -> np.ndarray:
        """Segment indices (K, C), ascending in each row (a row's last repeated as padding),
        that include every segment nearest to each point.

        A segment's distance is at most that of its middle and at least the middle's less
        half its length, so the nearest lie within (distance to the nearest middle) + (the
        longest half segment) of their middles; an open line's end segments, extended
        without end, are always candidates."""
        tree, half_max = self._middles
        r0, _ = tree.query(xy)
        reach = r0 + half_max + 1e-6 + 1e-9 * r0  # rounding's slack
        lists = tree.query_ball_point(xy, reach)
        if not self.periodic:
            ends = [0, self.n_seg - 1]
            lists = [lst + ends for lst in lists]
        size = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
        cand = np.full((len(lists), int(size.max())), self.n_seg, dtype=np.int64)
        rows = np.repeat(np.arange(len(lists)), size)
        cols = np.arange(len(rows)) - np.repeat(np.cumsum(size) - size, size)
        cand[rows, cols] = np.concatenate([np.asarray(lst, dtype=np.int64) for lst in lists])
        cand.sort(axis=1)
        last = cand[np.arange(len(cand)), size - 1]
        return np.where(cand == self.n_seg, last[:, None], cand)

    def _nearest_among(self, xy: np.ndarray, cand: np.ndarray | None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`nearest` over the segments ``cand`` (K, C) of each point (ascending; a
        repeat only after its first place), or over all of them (None), in chunks."""
        k = len(xy)
        s_out, d_out, j_out = np.empty(k), np.empty(k), np.empty(k, dtype=int)
        width = self.n_seg if cand is None else cand.shape[1]
        chunk = max(1, 2_000_000 // max(width, 1))
        lo_all = np.zeros(self.n_seg)
        hi_all = self.seg.copy()
        if not self.periodic:
            lo_all[0], hi_all[-1] = -np.inf, np.inf
        for a in range(0, k, chunk):
            p = xy[a:a + chunk]
            r = np.arange(len(p))
            c = (np.broadcast_to(np.arange(self.n_seg), (len(p), self.n_seg)) if cand is None
                 else cand[a:a + chunk])
            start, tan = self.pts[c], self.tan[c]  # (k, C, 2)
            v = p[:, None, :] - start
            along = v[:, :, 0] * tan[:, :, 0] + v[:, :, 1] * tan[:, :, 1]
            t = np.clip(along, lo_all[c], hi_all[c])
            foot = start + t[:, :, None] * tan
            dist = np.hypot(p[:, None, 0] - foot[:, :, 0], p[:, None, 1] - foot[:, :, 1])
            col = np.argmin(dist, axis=1)
            j = c[r, col]
            s_out[a:a + chunk] = self.cum[j] + t[r, col]
            vv = v[r, col]
            tt = self.tan[j]
            d_out[a:a + chunk] = tt[:, 0] * vv[:, 1] - tt[:, 1] * vv[:, 0]
            j_out[a:a + chunk] = j
        if self.periodic:
            s_out = np.mod(s_out, self.length)
        return s_out, d_out, j_out

    def point(self, s: np.ndarray, d: np.ndarray) -> np.ndarray:
        """``(x, y)`` (K, 2) of road-frame positions: the point at ``s`` plus ``d`` times
        the left normal of the segment that holds ``s`` (the inverse of :meth:`project`)."""
        s = np.asarray(s, dtype=float)
        j = self.segment_of(s)
        if self.periodic:
            s = np.mod(s, self.length)
        a = s - self.cum[j]
        return self.pts[j] + a[:, None] * self.tan[j] + np.asarray(d, float)[:, None] * self.nrm[j]


def _dedupe(pts: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Drop consecutive repeated points."""
    if len(pts) < 2:
        return pts
    keep = np.concatenate([[True], np.hypot(*np.diff(pts, axis=0).T) > eps])
    return pts[keep]


def _offset_polyline(pts: np.ndarray, c: float, periodic: bool) -> np.ndarray:
    """``pts`` moved sideways by ``c`` (m, left positive), vertices on the mitre (as SUMO's
    ``PositionVector::move2side`` builds lane shapes from an edge's line)."""
    if c == 0.0:
        return pts.copy()
    d = np.diff(pts, axis=0)
    t = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    n = np.column_stack([-t[:, 1], t[:, 0]])
    out = np.empty_like(pts)
    m = len(t)
    for i in range(len(pts)):
        if periodic:
            a, b = n[(i - 1) % m], n[i % m]
        elif i == 0:
            a = b = n[0]
        elif i == len(pts) - 1:
            a = b = n[-1]
        else:
            a, b = n[i - 1], n[i]
        cos = float(a @ b)
        if cos < -0.9:
            raise NetworkError("the main route turns back on itself (a turn of more than "
                               "150 degrees between two edges): the road frame cannot follow it")
        out[i] = pts[i] + c * (a + b) / (1.0 + cos)
    if periodic:
        out[-1] = out[0]
    return out


@dataclass(frozen=True)
class _Measure:
    """``s`` as SUMO measures the main route: a monotone map from the reference line's
    arc length ``g`` (m) to lane metres ``s`` (m) through knots ``(g_k, s_k)``.

    The knots are the main route's middle lanes and the junction lanes between them,
    each point at ``s = offset + lane position`` (offsets summing SUMO's lane lengths),
    so a vehicle on those lanes has exactly ``s = offset + pos`` and advances by exactly
    ``v dt`` per step. Open roads extend the map with slope 1 beyond its ends; on the ring
    ``g`` and ``s`` wrap (at ``g_period`` and ``s_period``).
    """

    g: np.ndarray
    s: np.ndarray
    periodic: bool
    g_period: float
    s_period: float

    def to_s(self, g: np.ndarray) -> np.ndarray:
        g = np.asarray(g, dtype=float)
        if self.periodic:
            x = self.g[0] + np.mod(g - self.g[0], self.g_period)
            return np.mod(np.interp(x, self.g, self.s), self.s_period)
        return _interp_ext(g, self.g, self.s)

    def to_g(self, s: np.ndarray) -> np.ndarray:
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


@dataclass
class _LaneGeo:
    """Build-time data of one lane on a route."""

    lane_id: str
    edge_id: str
    width: float
    length: float
    shape: np.ndarray  # (V, 2)
    internal: bool
    main: bool  # on the main route (else the ramp)
    successors: tuple[str, ...] = ()  # lanes a vehicle may drive onto at the end


@dataclass(frozen=True)
class _Tables:
    """Run-time tables of every route lane (global arrays, keyed by lane index).

    Segment tables: ``seg_key`` = lane index x :data:`_LANE_KEY` + lane position (m)
    where the segment starts; start point, unit tangent and left normal; ``seg_scale`` =
    geometric length per unit of lane position. ``s`` tables: ``tab_key`` as above and
    ``tab_g`` the (unwrapped) arc length of the reference line where the lane's centre
    projects there; ``measure`` turns arc length into ``s``.
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
    line: _Line
    measure: _Measure | None = None
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
                c(d0, float), float(_LANE_KEY), int(_MAX_WALK), float(_FOOT_EPS),
            )
            object.__setattr__(self, "_kernel_args", args)
        return self._kernel_args


def _lane_points(tb: _Tables, k: np.ndarray, pos: np.ndarray):
    """Centre point (K, 2) and left normal (K, 2) of lanes ``k`` at lane positions ``pos``,
    as SUMO computes them; also the table key of each."""
    p = np.clip(pos, 0.0, tb.lane_len[k])
    key = k * _LANE_KEY + p
    i = np.searchsorted(tb.seg_key, key, side="right") - 1
    along = (p - tb.seg_p0[i]) * tb.seg_scale[i]
    pt = tb.seg_a[i] + along[:, None] * tb.seg_t[i]
    return pt, tb.seg_n[i], key


def _frame_of(tb: _Tables, k: np.ndarray, pos: np.ndarray, lat: np.ndarray):
    """``(s, d)`` of SUMO positions on known lanes ``k`` (the core of lane_frame); a
    position beyond a lane's ends continues along ``s`` from the end.

    A lane parallel to the reference line at a constant offset (every lane of the
    networks cosim builds, a user's straight lanes) maps exactly as ``s = s0 + pos``,
    ``d = d0 + lat``; the others are projected (:func:`_frame_geo`).
    """
    if tb.par is None:
        return _frame_geo(tb, k, pos, lat)
    par = tb.par[k]
    if par.all():
        s, d = tb.par_s0[k] + pos, tb.par_d0[k] + lat
    else:
        s, d = _frame_geo(tb, k, pos, lat)
        s = np.where(par, tb.par_s0[k] + pos, s)
        d = np.where(par, tb.par_d0[k] + lat, d)
    if tb.measure.periodic:
        s = np.mod(s, tb.measure.s_period)
    return s, d


def _frame_geo(tb: _Tables, k: np.ndarray, pos: np.ndarray, lat: np.ndarray):
    """``(s, d)`` by projecting SUMO's point onto the reference line."""
    pt, nrm, key = _lane_points(tb, k, pos)
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


def _lane_frame_numpy(tb: _Tables, k: np.ndarray, pos: np.ndarray, lat: np.ndarray):
    """``RoadNetwork.lane_frame`` in numpy (the reference of ``frame_kernels.geo_frame``;
    also the path of tables without a measure)."""
    s = np.full(len(k), np.nan)
    d = lat.astype(float, copy=True)
    ok = k >= 0
    if ok.all():
        return _frame_of(tb, k, pos, lat)
    if ok.any():
        s[ok], d[ok] = _frame_of(tb, k[ok], pos[ok], lat[ok])
    return s, d


def _lateral_numpy(tb: _Tables, k: np.ndarray, pos: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``RoadNetwork.lateral_lane_position`` in numpy (the reference of
    ``frame_kernels.geo_lateral``)."""
    lat = d.astype(float, copy=True)
    ok = k >= 0
    if not ok.any():
        return lat
    kk, dd = k[ok], d[ok]
    pp = pos[ok]
    if tb.par[kk].all() and (pp <= tb.lane_len[kk]).all():
        lat[ok] = dd - tb.par_d0[kk]
        return lat
    for _ in range(3):  # a position past the lane's end lies on the lane after it
        past = (pp > tb.lane_len[kk]) & (tb.next_lane[kk] >= 0)
        if not past.any():
            break
        pp = np.where(past, pp - tb.lane_len[kk], pp)
        kk = np.where(past, tb.next_lane[kk], kk)
    par = tb.par[kk]
    if par.all():
        lat[ok] = dd - tb.par_d0[kk]
        return lat
    pt, nrm, key = _lane_points(tb, kk, pp)
    line = tb.line
    j = line.segment_of(np.interp(key, tb.tab_key, tb.tab_g))
    for _ in range(4):  # the segment of the line depends a little on where it goes
        _, d0 = line.project_on(pt, j)
        t = line.tan[j]
        cos = t[:, 0] * nrm[:, 1] - t[:, 1] * nrm[:, 0]  # d per metre of lat
        guess = (dd - d0) / cos
        j_new = line.holding(pt + guess[:, None] * nrm, j)
        if np.array_equal(j_new, j):
            break
        j = j_new
    lat[ok] = np.where(par, dd - tb.par_d0[kk], guess)
    return lat


# --------------------------------------------------------------------------------------
# RoadNetwork
# --------------------------------------------------------------------------------------


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
    tables: _Tables | None = field(default=None, repr=False, compare=False)
    #: lanes (junction lanes included) and edges of the main route: a vehicle on one of
    #: them is on the main road; a ramp's lanes and its junction lanes are not
    main_lanes: frozenset = field(default=frozenset(), repr=False, compare=False)

    @property
    def lane_based(self) -> bool:
        """True for the lane-based baseline (``three_lane``: SUMO's LC2013 drivers keep
        lanes). Every other road, a user's multi-lane network included, is lane-free:
        SUMO's sublane model, the lanes only carry the geometry."""
        return self.kind == "three_lane"

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
        (:mod:`cosim.road.frame_kernels`; the same bits as :func:`_lane_frame_numpy`,
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
        return _lane_frame_numpy(tb, k, pos, lat)

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
        :func:`_lateral_numpy`, tests/test_frame_kernels.py)."""
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
        return _lateral_numpy(tb, k, pos, d)

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
        pt, nrm, _ = _lane_points(tb, k, pos)
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
        lo = np.searchsorted(tb.tab_key, k * _LANE_KEY, side="left")
        hi = np.searchsorted(tb.tab_key, (k + 1) * _LANE_KEY, side="left")
        ss = tb.measure.to_s(tb.tab_g[lo:hi])
        pp = tb.tab_key[lo:hi] - k * _LANE_KEY
        if self.periodic:  # unwrap the lane's s and bring s next to it
            ss = ss[0] + np.concatenate([[0.0], np.cumsum(_wrap(np.diff(ss), self.length_m))])
            s = ss[0] + np.mod(s - ss[0], self.length_m)
        pos = float(np.interp(s, ss, pp))
        # one Newton step on the exact mapping (the table is linear between samples)
        s_at, _ = _frame_of(tb, np.array([k]), np.array([pos]), np.zeros(1))
        err = float(s_at[0]) - (s % self.length_m if self.periodic else s)
        if self.periodic:
            err = (err + 0.5 * self.length_m) % self.length_m - 0.5 * self.length_m
        return float(np.clip(pos - err, 0.0, tb.lane_len[k]))


def _geo(lane: Any, main: bool) -> _LaneGeo:
    shape = _dedupe(np.asarray(lane.getShape(), dtype=float)[:, :2])
    if len(shape) == 0:
        raise NetworkError(f"lane {lane.getID()!r} has no shape")
    if len(shape) == 1:  # a junction lane of no extent (SUMO gives it 0.1 m): a point,
        shape = np.vstack([shape, shape + 1e-3 * _direction_near(lane)])  # 1 mm long
    edge = lane.getEdge()
    succ = tuple(c.getViaLaneID() or c.getToLane().getID() for c in lane.getOutgoing())
    return _LaneGeo(lane.getID(), edge.getID(), float(lane.getWidth()), float(lane.getLength()),
                    shape, edge.getFunction() == "internal", main, succ)


def _direction_near(lane: Any) -> np.ndarray:
    """Unit direction of the lanes before or after ``lane`` where they touch it."""
    for conn in lane.getOutgoing():
        nxt = _dedupe(np.asarray(conn.getToLane().getShape(), dtype=float)[:, :2])
        if len(nxt) >= 2:
            v = nxt[1] - nxt[0]
            return v / np.hypot(*v)
    for prev in lane.getIncoming():
        sh = _dedupe(np.asarray(prev.getShape(), dtype=float)[:, :2])
        if len(sh) >= 2:
            v = sh[-1] - sh[-2]
            return v / np.hypot(*v)
    return np.array([1.0, 0.0])


def _route_lanes(net: Any, route: Sequence[str], periodic: bool, main: bool,
                 what: str) -> list[_LaneGeo]:
    """Every lane of the route's edges and of the junction lanes between them."""
    out: list[_LaneGeo] = []
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


def _centre_shape(edge: Any, lanes: Sequence[Any] | None = None) -> np.ndarray:
    """Centre line of an edge's lanes as SUMO lays them out: the middle lane's centre (an
    even count: the border between the two middle lanes), (V, 2) m. ``lanes``: only
    these (adjacent) lanes of the edge, e.g. the ones the road continues on."""
    lanes = list(lanes) if lanes else lanes_of(edge)
    mid = lanes[len(lanes) // 2]
    shape = _dedupe(np.asarray(mid.getShape(), dtype=float)[:, :2])
    if len(lanes) % 2 == 0:  # the right border of the left middle lane
        shape = _offset_polyline(shape, -0.5 * float(mid.getWidth()), False)
    return shape


def _continuing_lanes(prev: Any, edge: Any) -> list[Any] | None:
    """The lanes of ``edge`` that the lanes of ``prev`` lead onto, right to left, when
    they are not all of them (a lane added beside the road, e.g. an acceleration lane);
    else None."""
    reached = {c.getToLane().getID() for c in connections(prev, edge.getID())}
    lanes = [ln for ln in lanes_of(edge) if ln.getID() in reached]
    return lanes if lanes and len(lanes) < len(lanes_of(edge)) else None


def _reference_line(net: Any, route: Sequence[str], periodic: bool) -> _Line:
    """The reference line (see the module docstring), as a polyline.

    Each route edge contributes its lanes' centre line (:func:`_centre_shape`; of the
    lanes the previous edge's lanes lead onto, when a lane is added beside them), moved
    sideways by ``shift = delta_0 - delta_k`` where ``delta_k`` is how far that centre
    lies from the edge as drawn (its raw shape) and ``delta_0`` the same for the first
    edge. Between two unshifted edges the line runs along the junction lanes SUMO drives
    through; elsewhere (the lanes changed their place, e.g. after a width change built
    with netconvert's defaults) it bridges the junction with a smooth cubic curve tangent
    to both sides (points every BRIDGE_STEP_M). So on generated
    networks, and wherever lanes keep their place, the line is exactly the lanes' centre
    line, junction lanes included (vehicles there have ``d = lat``).
    """
    edges = [net.getEdge(e) for e in route]
    centres, shifts = [], []
    delta0 = None
    for k, edge in enumerate(edges):
        centre = _centre_shape(edge, _continuing_lanes(edges[k - 1], edge) if k else None)
        raw = _raw_shape(edge, centre)
        if len(raw) < 2 or len(centre) < 2:
            raise NetworkError(f"route edge {edge.getID()!r} has no length")
        _, d, _ = _Line.of(raw, False).nearest(_point_at(centre, 0.5)[None, :])
        delta = float(d[0])
        delta0 = delta if delta0 is None else delta0
        shift = delta0 - delta
        shift = 0.0 if abs(shift) < SHIFT_TOL_M else shift
        centres.append(centre if shift == 0.0 else _offset_polyline(centre, shift, False))
        shifts.append(shift)
    n = len(edges)
    chain = centres[0]
    for k in range(n if periodic else n - 1):
        nk = (k + 1) % n
        nxt = centres[nk] if nk else centres[0][:1]
        bridge = None
        if shifts[k] == 0.0 and shifts[nk] == 0.0:  # the lanes are the line: keep them
            bridge = _junction_lanes(net, edges[k], edges[nk])
            if bridge is not None and (np.hypot(*(bridge[0] - chain[-1])) > SHIFT_TOL_M
                                       or np.hypot(*(bridge[-1] - centres[nk][0])) > SHIFT_TOL_M):
                bridge = None  # the junction lanes do not join these lanes: bridge smoothly
        if bridge is None and np.hypot(*(centres[nk][0] - chain[-1])) > 1e-6:
            bridge = _hermite(chain[-2:], centres[nk][:2])
        if bridge is not None:
            chain = _join(chain, bridge)
        chain = _join(chain, nxt)
    chain = _dedupe(chain)
    if periodic:
        chain[-1] = chain[0]
    if len(chain) < 2:
        raise NetworkError(f"the main route {list(route)} has no length")
    return _Line.of(chain, periodic)


def _raw_shape(edge: Any, centre: np.ndarray) -> np.ndarray:
    """The edge as drawn (its raw shape), m; the lanes' centre line when the file does not
    tell (sumolib needs the nodes' positions: a file without junctions has none, and SUMO
    refuses it when it starts)."""
    try:
        raw = edge.getRawShape()
        return _dedupe(np.asarray(raw, dtype=float)[:, :2])
    except (TypeError, ValueError, IndexError):
        return centre


def _junction_lanes(net: Any, edge: Any, nxt: Any) -> np.ndarray | None:
    """The junction lanes from ``edge``'s middle lane to ``nxt`` as one polyline, or None
    (no junction lanes)."""
    conns = connections(edge, nxt.getID())
    if not conns:
        return None
    ref = reference_lane(edge)
    conn = next((c for c in conns if c.getFromLane() is ref), conns[0])
    chain = via_chain(net, conn, nxt.getID())
    if not chain:
        return None
    pts = _dedupe(np.concatenate([np.asarray(ln.getShape(), dtype=float)[:, :2]
                                  for ln in chain]))
    return pts if len(pts) >= 2 else None


#: Lanes that move sideways by less than this (m) keep their place (net.xml rounds
#: coordinates to 0.01 m).
SHIFT_TOL_M = 0.02
#: Spacing (m) and least number of the points of a smooth bridge across a junction (a
#: turn of 10 degrees then bends by 0.2 degrees per point: at d = 5 m a point off the
#: line in the outside corner of a bend is represented to 0.02 m).
BRIDGE_STEP_M = 0.1
BRIDGE_POINTS = 48


def _hermite(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """A cubic curve from ``before[-1]`` (leaving along ``before``'s last direction) to
    ``after[0]`` (arriving along ``after``'s first direction), at least BRIDGE_POINTS
    points, at most BRIDGE_STEP_M apart."""
    p0, p1 = before[-1], after[0]
    t0 = before[-1] - before[-2]
    t1 = after[1] - after[0]
    t0, t1 = t0 / np.hypot(*t0), t1 / np.hypot(*t1)
    chord = float(np.hypot(*(p1 - p0)))
    n = max(BRIDGE_POINTS, int(math.ceil(chord / BRIDGE_STEP_M)))
    u = np.linspace(0.0, 1.0, n + 1)[:, None]
    h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
    h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
    return h00 * p0 + h10 * chord * t0 + h01 * p1 + h11 * chord * t1


def _join(chain: np.ndarray, piece: np.ndarray) -> np.ndarray:
    """``chain`` continued by ``piece`` (a straight segment between them); points of the
    piece that lie behind the chain's end (lanes overlapping in a junction) are dropped."""
    end = chain[-1]
    t = chain[-1] - chain[-2]
    t = t / np.hypot(*t)
    ahead = (piece - end) @ t > 1e-6
    if not ahead.any():
        if len(piece) == 1:  # closing a loop onto its start
            return np.vstack([chain, piece])
        raise NetworkError("the main route turns back on itself: the road frame cannot follow it")
    first = int(np.argmax(ahead))
    return np.vstack([chain, piece[first:]])


def _point_at(shape: np.ndarray, frac: float) -> np.ndarray:
    seg = np.hypot(*np.diff(shape, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    g = frac * cum[-1]
    return np.array([np.interp(g, cum, shape[:, 0]), np.interp(g, cum, shape[:, 1])])


def _next_lanes(lanes: list[_LaneGeo], index: dict[str, int]) -> np.ndarray:
    """For each route lane, the index of the route lane a vehicle drives onto at its end
    (-1: none on the routes)."""
    out = np.full(len(lanes), -1, dtype=np.int64)
    for k, g in enumerate(lanes):
        for nxt in g.successors:
            if nxt in index:
                out[k] = index[nxt]
                break
    return out


def _build_tables(lanes: list[_LaneGeo], line: _Line, index: dict[str, int]) -> _Tables:
    """Segment tables and ``s`` tables of every route lane (see :class:`_Tables`)."""
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
        seg_key.append(k * _LANE_KEY + cum[:-1])
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
            s = s[0] + np.concatenate([[0.0], np.cumsum(_wrap(np.diff(s), line.length))])
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
        tab_key.append(k * _LANE_KEY + p)
        tab_g.append(s)
    return _Tables(
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


def _wrap(x: np.ndarray, period: float) -> np.ndarray:
    """Differences ``x`` brought into [-period/2, period/2)."""
    return x - period * np.round(x / period)


def _measure(tb: _Tables, net: Any, route: Sequence[str],
             periodic: bool) -> tuple[_Measure, dict[int, float]]:
    """The knots of :class:`_Measure` along the main route's middle lanes and junction
    lanes, and the offset (m, SUMO's lane lengths summed) of each of those lanes."""
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
            lo = np.searchsorted(tb.tab_key, i * _LANE_KEY, side="left")
            hi = np.searchsorted(tb.tab_key, (i + 1) * _LANE_KEY, side="left")
            gs.append(tb.tab_g[lo:hi])
            ss.append(off + tb.tab_key[lo:hi] - i * _LANE_KEY)
            chain_off.setdefault(i, off)
            off += float(tb.lane_len[i])
    g = np.concatenate(gs)
    s = np.concatenate(ss)
    if periodic:
        g = g[0] + np.concatenate([[0.0], np.cumsum(_wrap(np.diff(g), tb.line.length))])
    # one knot per g (junction lanes may touch the same g twice), increasing
    g = np.maximum.accumulate(g)
    keep = np.concatenate([[True], np.diff(g) > 1e-9])
    g, s = g[keep], s[keep]
    if periodic:  # close the loop: one full turn of g is one full turn of s
        g = np.concatenate([g, [g[0] + tb.line.length]])
        s = np.concatenate([s, [off]])
        keep = np.concatenate([np.diff(g) > 1e-9, [True]])
        g, s = g[keep], s[keep]
    return _Measure(g, s, periodic, tb.line.length, off), chain_off


#: A lane counts as parallel to the line when its centre's d varies and its s runs from
#: lane metres by less than this, m.
PARALLEL_TOL_M = 1e-6


def _find_parallel(tb: _Tables, chain_off: dict[int, float]) -> None:
    """Mark the lanes that run parallel to the line at a constant offset (their ``s`` is
    the lane position plus a constant, ``d`` the lateral position plus a constant) and
    store those constants; a lane of the measure's chain keeps SUMO's offset exactly."""
    n = len(tb.lane_len)
    par = np.zeros(n, dtype=bool)
    s0 = np.zeros(n)
    d0 = np.zeros(n)
    period = tb.measure.s_period if tb.measure.periodic else None
    starts = np.searchsorted(tb.tab_key, np.arange(n + 1) * _LANE_KEY, side="left")
    for k in range(n):
        p = tb.tab_key[starts[k]:starts[k + 1]] - k * _LANE_KEY
        s, d = _frame_geo(tb, np.full(len(p), k), p, np.zeros(len(p)))
        if period is not None:
            s = s[0] + np.concatenate([[0.0], np.cumsum(_wrap(np.diff(s), period))])
        lag = s - p
        if np.ptp(d) < PARALLEL_TOL_M and np.ptp(lag) < PARALLEL_TOL_M:
            par[k] = True
            s0[k] = chain_off.get(k, float(lag[0]))
            d0[k] = round(float(d[0]), 9)
    object.__setattr__(tb, "par", par)
    object.__setattr__(tb, "par_s0", s0)
    object.__setattr__(tb, "par_d0", d0)


def _lane_cos(tb: _Tables, k: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """d per metre of lateral lane position (the cosine of the lane's angle to the line)."""
    pt, nrm, key = _lane_points(tb, k, pos)
    line = tb.line
    j = line.holding(pt, line.segment_of(np.interp(key, tb.tab_key, tb.tab_g)))
    t = line.tan[j]
    return t[:, 0] * nrm[:, 1] - t[:, 1] * nrm[:, 0]


def _edge_borders(tb: _Tables, lanes: list[_LaneGeo], edge_lanes: list[int], edge: str,
                  periodic: bool, length: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(s, right, left)`` samples (m) of one main-route edge's outer lane borders; lanes of
    the edge must not cross (their centres keep the order of their indices)."""
    grids, rights, lefts, centres = [], [], [], []
    for k in edge_lanes:
        g = lanes[k]
        n = max(2, int(math.ceil(g.length / SAMPLE_M)) + 1)
        p = np.linspace(0.0, tb.lane_len[k], n)
        kk = np.full(n, k)
        s, dc = _frame_of(tb, kk, p, np.zeros(n))
        # the borders half a width either side, across the lane (cos: the lane's angle to
        # the line), so that a lane on the line has its borders at exactly +-w/2
        half = 0.5 * g.width * (1.0 if tb.par[k] else _lane_cos(tb, kk, p))
        dr, dl = dc - half, dc + half
        if periodic:
            s = s[0] + np.concatenate([[0.0], np.cumsum(_wrap(np.diff(s), length))])
        grids.append(s)
        rights.append(dr)
        lefts.append(dl)
        centres.append(dc)
    grid = np.unique(np.concatenate(grids))
    # keep the grid on the span every lane covers (lanes of one edge start and end together
    # up to the junction cuts)
    right = np.min([np.interp(grid, s, r) for s, r in zip(grids, rights, strict=True)], axis=0)
    left = np.max([np.interp(grid, s, v) for s, v in zip(grids, lefts, strict=True)], axis=0)
    if len(edge_lanes) > 1:
        # the lanes as drawn must not cross (SUMO's lane coordinates would not tell)
        centres = [_frame_geo(tb, np.full(len(s), k), np.linspace(0.0, tb.lane_len[k], len(s)),
                              np.zeros(len(s)))[1] for s, k in zip(grids, edge_lanes, strict=True)]
        cs = np.array([np.interp(grid, s, c) for s, c in zip(grids, centres, strict=True)])
        gaps = np.diff(cs, axis=0)
        if gaps.min() <= 0.0:
            i, j = np.unravel_index(int(np.argmin(gaps)), gaps.shape)
            raise NetworkError(
                f"lanes {lanes[edge_lanes[i]].lane_id!r} and {lanes[edge_lanes[i + 1]].lane_id!r} "
                f"of edge {edge!r} cross near s = {grid[j]:.1f} m: the road frame cannot "
                "represent crossing lanes"
            )
    if np.any(left <= right):
        raise NetworkError(f"edge {edge!r} has no width in the road frame")
    return grid, right, left


def _junction_borders(tb: _Tables, lanes: list[_LaneGeo], net: Any, edge: str, nxt: str,
                      periodic: bool, length: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``(s, right, left)`` samples (m) of the main route's junction lanes from ``edge`` to
    ``nxt``: at each ``s`` the outermost borders of the junction lanes there; None when the
    edges join without junction lanes."""
    keys = []
    for conn in connections(net.getEdge(edge), nxt):
        keys += [tb.index[ln.getID()] for ln in via_chain(net, conn, nxt)
                 if ln.getID() in tb.index and lanes[tb.index[ln.getID()]].main]
    keys = sorted(set(keys))
    if not keys:
        return None
    grids, rights, lefts = [], [], []
    for k in keys:
        n = max(2, int(math.ceil(tb.lane_len[k] / SAMPLE_M)) + 1)
        p = np.linspace(0.0, tb.lane_len[k], n)
        s, dc = _frame_of(tb, np.full(n, k), p, np.zeros(n))
        if periodic:
            s = s[0] + np.concatenate([[0.0], np.cumsum(_wrap(np.diff(s), length))])
        half = 0.5 * lanes[k].width * (1.0 if tb.par[k] else _lane_cos(tb, np.full(n, k), p))
        grids.append(s)
        rights.append(dc - half)
        lefts.append(dc + half)
    grid = np.unique(np.concatenate(grids))
    inside = [(grid >= s[0] - 1e-9) & (grid <= s[-1] + 1e-9) for s in grids]
    right = np.min([np.where(m, np.interp(grid, s, r), np.inf)
                    for s, r, m in zip(grids, rights, inside, strict=True)], axis=0)
    left = np.max([np.where(m, np.interp(grid, s, v), -np.inf)
                   for s, v, m in zip(grids, lefts, inside, strict=True)], axis=0)
    ok = np.isfinite(right) & np.isfinite(left)
    return grid[ok], right[ok], left[ok]


def _pieces(s: np.ndarray, right: np.ndarray, left: np.ndarray, length: float,
            periodic: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Piecewise-linear edges -> piecewise-constant pieces (start s, right, left), m: a new
    piece whenever an edge would move by more than PROFILE_TOL_M; each piece the narrower."""
    # refine every interval so that linear changes are resolved to the tolerance
    ds = np.maximum(np.abs(np.diff(right)), np.abs(np.diff(left)))
    n_sub = np.maximum(1, np.ceil(ds / (0.5 * PROFILE_TOL_M)).astype(int))
    if n_sub.max() > 1:
        fine = np.concatenate([np.linspace(s[i], s[i + 1], n_sub[i], endpoint=False)
                               for i in range(len(s) - 1)] + [s[-1:]])
        right = np.interp(fine, s, right)
        left = np.interp(fine, s, left)
        s = fine
    # flat stretches are pieces of their own (their exact value), changes are cut finely
    flat = np.concatenate([(np.abs(np.diff(right)) < 1e-9) & (np.abs(np.diff(left)) < 1e-9),
                           [True]])
    s0, r_out, l_out = [], [], []
    i, n = 0, len(s)
    while i < n:
        lo_r = hi_r = right[i]
        lo_l = hi_l = left[i]
        j = i + 1
        while j < n and flat[j - 1] == flat[i]:
            lo_r2, hi_r2 = min(lo_r, right[j]), max(hi_r, right[j])
            lo_l2, hi_l2 = min(lo_l, left[j]), max(hi_l, left[j])
            if hi_r2 - lo_r2 > PROFILE_TOL_M or hi_l2 - lo_l2 > PROFILE_TOL_M:
                break
            lo_r, hi_r, lo_l, hi_l = lo_r2, hi_r2, lo_l2, hi_l2
            j += 1
        s0.append(s[i])
        r_out.append(hi_r)  # narrower: the rightmost right edge, the leftmost left edge
        l_out.append(lo_l)
        i = j
    s0_a = np.array(s0)
    s0_a[0] = min(s0_a[0], 0.0)
    keep = np.concatenate([[True], np.diff(s0_a) > 1e-9])
    return s0_a[keep], np.array(r_out)[keep], np.array(l_out)[keep]


def _profile(tb: _Tables, lanes: list[_LaneGeo], net: Any, route: Sequence[str],
             periodic: bool, length: float):
    """The road's edges along ``s``: pieces (s0, right, left) and the edges' spans."""
    s_all, r_all, l_all, spans = [], [], [], []
    for k, eid in enumerate(route):
        ks = [tb.index[ln.getID()] for ln in lanes_of(net.getEdge(eid))]
        s, r, left = _edge_borders(tb, lanes, ks, eid, periodic, length)
        if k and s_all and _continuing_lanes(net.getEdge(route[k - 1]), net.getEdge(eid)):
            # a lane added beside the road (an on-ramp's acceleration lane) is paved from
            # the junction's start: the ramp's junction lane leads onto it there
            s = np.concatenate([[s_all[-1][-1] + 1e-3], s])
            r = np.concatenate([[min(r[0], r_all[-1][-1])], r])
            left = np.concatenate([[max(left[0], l_all[-1][-1])], left])
        elif k or periodic:
            # the junction before this edge: as wide as SUMO's junction lanes (each as wide
            # as the lane it leads onto), not a linear change between the edges
            junction = _junction_borders(tb, lanes, net, route[k - 1], eid, periodic, length)
            if junction is not None:
                s_all.append(junction[0])
                r_all.append(junction[1])
                l_all.append(junction[2])
        ref = tb.index[eid]
        s_ref, _ = _frame_of(tb, np.array([ref, ref]), np.array([0.0, tb.lane_len[ref]]),
                             np.zeros(2))
        s0 = float(s_ref[0])
        s1 = s0 + float(np.mod(s_ref[1] - s_ref[0], length)) if periodic else float(s_ref[1])
        spans.append((eid, s0, s1))
        s_all.append(s)
        r_all.append(r)
        l_all.append(left)
    s = np.concatenate(s_all)
    r = np.concatenate(r_all)
    left = np.concatenate(l_all)
    if periodic:
        s = np.mod(s, length)
        order = np.argsort(s, kind="stable")
        s, r, left = s[order], r[order], left[order]
        # across the seam: the junction between the last and the first edge
        s = np.concatenate([s[-1:] - length, s, s[:1] + length])
        r = np.concatenate([r[-1:], r, r[:1]])
        left = np.concatenate([left[-1:], left, left[:1]])
        r0, l0 = np.interp(0.0, s, r), np.interp(0.0, s, left)
        inside = (s > 0.0) & (s < length)
        s = np.concatenate([[0.0], s[inside], [length]])
        r = np.concatenate([[r0], r[inside], [r0]])
        left = np.concatenate([[l0], left[inside], [l0]])
    else:
        order = np.argsort(s, kind="stable")
        s, r, left = s[order], r[order], left[order]
        if np.any(np.diff(np.array([sp[1] for sp in spans])) <= 0):
            raise NetworkError("the main route's edges do not follow each other along the route")
    s0, right, left_p = _pieces(s, r, left, length, periodic)
    if periodic:
        keep = s0 < length
        s0, right, left_p = s0[keep], right[keep], left_p[keep]
    return s0, right, left_p, spans


def load_road_network(
    net_file: Path | str,
    *,
    kind: str,
    main_route: Sequence[str],
    ramp_route: Sequence[str] | None = None,
    periodic: bool = False,
    speed_limit_mps: float | None = None,
) -> RoadNetwork:
    """Read a ``.net.xml`` with sumolib and compute the road frame of ``main_route``.

    Raises:
        NetworkError: an unreadable file, a route edge missing or without lanes, route
            edges that do not connect, or geometry the frame cannot represent.
    """
    path = Path(net_file)
    net = read_sumo_net(path)
    try:
        return _road_network(path, net, kind, main_route, ramp_route, periodic,
                             speed_limit_mps)
    except (TypeError, ValueError, IndexError, KeyError, ZeroDivisionError) as exc:
        # geometry sumolib or the frame cannot handle (missing shapes, positions...)
        msg = str(exc).splitlines()[0] if str(exc) else ""
        raise NetworkError(f"network {path.name}: cannot build the road frame of route "
                           f"{list(main_route)}: {type(exc).__name__}: {msg}") from None


def _road_network(path: Path, net: Any, kind: str, main_route: Sequence[str],
                  ramp_route: Sequence[str] | None, periodic: bool,
                  speed_limit_mps: float | None) -> RoadNetwork:
    """The body of :func:`load_road_network` (errors of unexpected geometry wrapped there)."""
    for eid in (*main_route, *(ramp_route or ())):
        if not net.hasEdge(eid):
            raise NetworkError(f"edge {eid!r} of the route is not in network {path.name}")
        if net.getEdge(eid).getFunction() == "internal":
            raise NetworkError(f"route edge {eid!r} is a junction lane, not an edge")
    if len(set(main_route)) != len(main_route):
        raise NetworkError(f"the main route lists an edge twice: {list(main_route)}")
    lanes = _route_lanes(net, main_route, periodic, True, "route")
    if ramp_route:
        if ramp_route[-1] not in main_route:
            raise NetworkError(
                f"ramp route must end on a main-route edge (ends on {ramp_route[-1]!r})"
            )
        known = {g.lane_id for g in lanes}
        lanes += [g for g in _route_lanes(net, ramp_route, False, False, "ramp")
                  if g.lane_id not in known]
    line = _reference_line(net, main_route, periodic)
    index = {g.lane_id: k for k, g in enumerate(lanes)}
    for eid in (*main_route, *(ramp_route or ())):
        index.setdefault(eid, index[reference_lane(net.getEdge(eid)).getID()])
    tb = _build_tables(lanes, line, index)
    measure, chain_off = _measure(tb, net, main_route, periodic)
    object.__setattr__(tb, "measure", measure)
    _find_parallel(tb, chain_off)
    use_lane_coordinates(tb, lane_coordinates(net, tb, main_route, periodic, chain_off),
                          chain_off)
    length = measure.s_period if periodic else float(
        measure.to_s(np.array([line.length]))[0])
    s0, right, left, spans = _profile(tb, lanes, net, main_route, periodic, length)

    route_lanes = {g.lane_id for g in lanes}
    all_ids = [g.lane_id for g in lanes] + [e for e in index if e not in route_lanes]
    ks = np.array([index[x] for x in all_ids])
    s_start, _ = _frame_of(tb, ks, np.zeros(len(ks)), np.zeros(len(ks)))
    _, d_mid = _frame_of(tb, ks, 0.5 * tb.lane_len[ks], np.zeros(len(ks)))
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
