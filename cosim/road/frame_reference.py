"""The road frame's plain-numpy definitions: what the compiled kernels in
:mod:`cosim.road.frame_kernels` (``geo_frame``, ``geo_lateral``) compute, written to be
read, and the numpy path of tables without a measure. The kernels give the same bits
(tests/test_frame_kernels.py).

``tb`` is the frame's :class:`~cosim.road.lane_tables.Tables`; ``k`` (N,) lane indices
(:meth:`cosim.road.frame.RoadNetwork.lane_keys`, -1 off the routes), positions (N,) m.
"""

from __future__ import annotations

import numpy as np

from cosim.road.lane_tables import Tables, frame_of, lane_points


def lane_frame_reference(tb: Tables, k: np.ndarray, pos: np.ndarray, lat: np.ndarray):
    """``(s, d)`` (N,) m each: ``RoadNetwork.lane_frame`` in numpy (the reference of
    ``frame_kernels.geo_frame``; also the path of tables without a measure) of vehicles on
    lanes ``k`` (N,) at lane positions ``pos`` and lateral lane positions ``lat`` (N,) m;
    off the routes (``k < 0``): ``s = NaN``, ``d = lat``."""
    s = np.full(len(k), np.nan)
    d = lat.astype(float, copy=True)
    ok = k >= 0
    if ok.all():
        return frame_of(tb, k, pos, lat)
    if ok.any():
        s[ok], d[ok] = frame_of(tb, k[ok], pos[ok], lat[ok])
    return s, d


def lateral_reference(tb: Tables, k: np.ndarray, pos: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Lateral lane positions (N,) m: ``RoadNetwork.lateral_lane_position`` in numpy (the
    reference of ``frame_kernels.geo_lateral``) that put vehicles on lanes ``k`` (N,) at
    road-frame offsets ``d`` (N,) m once at lane positions ``pos`` (N,) m (past a lane's
    end: on the route lane after it); off the routes (``k < 0``): ``d``."""
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
    pt, nrm, key = lane_points(tb, kk, pp)
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
