"""The road's edges along ``s``: the piecewise-constant profile of the main route.

The road's edges along ``s`` (:func:`road_profile`, served by
:meth:`cosim.road.frame.RoadNetwork.profile`): the outer borders of the main route's lanes
(right border of the rightmost, left border of the leftmost), in the frame, sampled every
:data:`~cosim.road.lane_tables.SAMPLE_M`; across a junction they are the junction lanes'
own borders, so a width change is a step at the junction lane's start, as SUMO sees it
(where an edge adds a lane beside the road, e.g. an on-ramp's acceleration lane, the
added lane's border holds from the junction's start). Right and left edges are
independent (asymmetric roads are fine). The profile is piecewise constant: flat
stretches are one piece each, and where an edge moves the pieces are short enough that it
moves by at most :data:`PROFILE_TOL_M` within one; each piece takes the narrower value (the
road is never wider than SUMO's). Lanes of one edge that cross are refused
(:class:`~cosim.errors.NetworkError`). ``s`` and ``d`` in m.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from cosim.errors import NetworkError
from cosim.road.lane_tables import (
    SAMPLE_M,
    LaneGeo,
    Tables,
    frame_geo,
    frame_of,
    lane_cos,
    wrap,
)
from cosim.road.sumo_net import connections, continuing_lanes, lanes_of, via_chain

#: Largest change (m) of a road edge within one piece of the profile.
PROFILE_TOL_M = 0.02


def _edge_borders(tb: Tables, lanes: list[LaneGeo], edge_lanes: list[int], edge: str,
                  periodic: bool, length: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(s, right, left)`` samples (m) of one main-route edge's outer lane borders; lanes of
    the edge must not cross (their centres keep the order of their indices)."""
    grids, rights, lefts, centres = [], [], [], []
    for k in edge_lanes:
        g = lanes[k]
        n = max(2, int(math.ceil(g.length / SAMPLE_M)) + 1)
        p = np.linspace(0.0, tb.lane_len[k], n)
        kk = np.full(n, k)
        s, dc = frame_of(tb, kk, p, np.zeros(n))
        # the borders half a width either side, across the lane (cos: the lane's angle to
        # the line), so that a lane on the line has its borders at exactly +-w/2
        half = 0.5 * g.width * (1.0 if tb.par[k] else lane_cos(tb, kk, p))
        dr, dl = dc - half, dc + half
        if periodic:
            s = s[0] + np.concatenate([[0.0], np.cumsum(wrap(np.diff(s), length))])
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
        centres = [frame_geo(tb, np.full(len(s), k), np.linspace(0.0, tb.lane_len[k], len(s)),
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


def _junction_borders(tb: Tables, lanes: list[LaneGeo], net: Any, edge: str, nxt: str,
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
        s, dc = frame_of(tb, np.full(n, k), p, np.zeros(n))
        if periodic:
            s = s[0] + np.concatenate([[0.0], np.cumsum(wrap(np.diff(s), length))])
        half = 0.5 * lanes[k].width * (1.0 if tb.par[k] else lane_cos(tb, np.full(n, k), p))
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


def road_profile(tb: Tables, lanes: list[LaneGeo], net: Any, route: Sequence[str],
                 periodic: bool, length: float):
    """The road's edges along ``s`` of main route ``route`` (edge ids; ``lanes`` and ``tb``
    the route lanes and their tables, measure and lane coordinates in place; ``length``
    the route's length in ``s``, m): ``(s0, right, left, spans)`` with the pieces' start
    ``s``, right and left edge ``d`` (P,) m each (on the ring ``s0 < length``) and
    ``spans`` ``(edge, s_start, s_end)`` (m) of every route edge's lanes. Raises
    NetworkError when lanes of an edge cross, an edge has no width, or the edges do not
    follow each other along ``s``."""
    s_all, r_all, l_all, spans = [], [], [], []
    for k, eid in enumerate(route):
        ks = [tb.index[ln.getID()] for ln in lanes_of(net.getEdge(eid))]
        s, r, left = _edge_borders(tb, lanes, ks, eid, periodic, length)
        if k and s_all and continuing_lanes(net.getEdge(route[k - 1]), net.getEdge(eid)):
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
        s_ref, _ = frame_of(tb, np.array([ref, ref]), np.array([0.0, tb.lane_len[ref]]),
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
