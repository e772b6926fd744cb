"""Compiled paths of the road frame (:mod:`cosim.road.frame`): SUMO's (lane, position,
lateral position) to the road frame's (s, d) and back, every vehicle, every step.

* ``parallel_frame`` / ``parallel_lateral``: lanes that run parallel to the reference line
  (every lane of the networks cosim builds, a user's straight lanes): ``s = s0 + pos``,
  ``d = d0 + lat``. They return ``ok = False`` as soon as a vehicle is on another lane.
* ``geo_frame`` / ``geo_lateral``: any lanes (a user's kinks and bends, netconvert's
  junction lanes, a ramp): the point SUMO computes on the lane, projected onto the
  reference line (and back), as the numpy reference
  ``frame_reference.lane_frame_reference`` and ``frame_reference.lateral_reference`` do.

Each does the numpy path's arithmetic element by element, in the same order (numpy's
``interp``, ``searchsorted``, ``mod`` and ``clip`` branch for branch): the same bits
(tests/test_frame_kernels.py, tests/test_exactness.py, tests/test_road_frame.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _lane_reached(kk, pp, lane_len, next_lane):
    """Lane and lane position ``(kk, pp)`` where position ``pp`` (m) on lane ``kk`` lies: a
    position past a lane's end is on the route lane after it (at most three lanes on)."""
    for _ in range(3):
        if pp > lane_len[kk] and next_lane[kk] >= 0:
            pp = pp - lane_len[kk]
            kk = next_lane[kk]
        else:
            break
    return kk, pp


@njit(cache=True)
def parallel_frame(k, pos, lat, par, par_s0, par_d0, periodic, s_period):
    """Road-frame ``(s, d, ok)`` of SUMO positions: ``s = s0 + pos``, ``d = d0 + lat``.

    Args: lane table keys ``k`` (N,) (every one >= 0), lane positions ``pos`` and lateral
    lane positions ``lat`` (N,) m; per lane: ``par`` (parallel to the line), ``par_s0``
    (s of its position 0, m), ``par_d0`` (d of its centre, m); on a ring ``s`` is wrapped
    into ``[0, s_period)`` (numpy's ``mod``). ``ok``: every lane was parallel.
    """
    n = k.shape[0]
    s = np.empty(n)
    d = np.empty(n)
    for i in range(n):
        kk = k[i]
        if kk < 0 or not par[kk]:
            return s, d, False
        x = par_s0[kk] + pos[i]
        if periodic:
            x = x % s_period
        s[i] = x
        d[i] = par_d0[kk] + lat[i]
    return s, d, True


@njit(cache=True)
def parallel_lateral(k, pos, d, lane_len, next_lane, par, par_d0):
    """SUMO lateral lane positions ``(lat, ok)`` (N,) m that put vehicles on lanes ``k``
    at road-frame offsets ``d`` (N,) m once at lane positions ``pos`` (N,) m: a position
    past a lane's end lies on the lane after it (at most three lanes on), whose centre
    ``par_d0`` counts (``lat = d - d0``); off-route (``k < 0``): ``lat = d``. ``ok``: every
    lane reached was parallel to the line."""
    n = k.shape[0]
    lat = np.empty(n)
    for i in range(n):
        kk = k[i]
        if kk < 0:
            lat[i] = d[i]
            continue
        kk, pp = _lane_reached(kk, pos[i], lane_len, next_lane)
        if not par[kk]:
            return lat, False
        lat[i] = d[i] - par_d0[kk]
    return lat, True


# ---- lanes that do not run parallel to the line (curves, a user's bends): projection ----
#
# ``tables`` is :meth:`cosim.road.lane_tables.Tables.kernel_args`: one tuple of the run-time
# tables, in the order unpacked below. Each helper does what the numpy function it names
# does to one element.


@njit(cache=True, inline="always")
def _count_le(a, x):
    """``np.searchsorted(a, x, side="right")``: how many of sorted ``a`` are <= ``x``."""
    lo = 0
    hi = a.shape[0]
    while lo < hi:
        mid = (lo + hi) >> 1
        if x >= a[mid]:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def _interp(x, xp, fp):
    """``np.interp(x, xp, fp)`` for one ``x``, branch for branch as numpy's C code
    (``arr_interp``: the knot below by binary search, the knot's value where ``x`` is on
    it, otherwise the slope form and, if that is NaN, the slope form from the knot above)."""
    n = xp.shape[0]
    if n == 1:
        return fp[0]
    if x > xp[n - 1]:
        return fp[n - 1]
    if x < xp[0]:
        return fp[0]
    j = _count_le(xp, x) - 1
    if j == n - 1:
        return fp[j]
    if xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    y = slope * (x - xp[j]) + fp[j]
    if np.isnan(y):
        y = slope * (x - xp[j + 1]) + fp[j + 1]
        if np.isnan(y) and fp[j] == fp[j + 1]:
            y = fp[j]
    return y


@njit(cache=True)
def _lane_point(kk, pos, tables):
    """``lane_tables.lane_points`` for one vehicle: centre point, left normal and table key."""
    lane_len, seg_key, seg_p0, seg_scale = tables[0], tables[2], tables[3], tables[4]
    seg_a, seg_t, seg_n, lane_key = tables[5], tables[6], tables[7], tables[24]
    hi = lane_len[kk]
    p = pos
    if p < 0.0:
        p = 0.0
    elif p > hi:
        p = hi
    key = float(kk) * lane_key + p
    i = _count_le(seg_key, key) - 1
    along = (p - seg_p0[i]) * seg_scale[i]
    x = seg_a[i, 0] + along * seg_t[i, 0]
    y = seg_a[i, 1] + along * seg_t[i, 1]
    return x, y, seg_n[i, 0], seg_n[i, 1], key


@njit(cache=True)
def _segment_of(g, tables):
    """``polyline.Line.segment_of`` for one arc length ``g`` (m)."""
    cum = tables[11]
    periodic = tables[14]
    n_seg = cum.shape[0] - 1
    if periodic:
        g = g % cum[n_seg]
    j = _count_le(cum, g) - 1
    if j < 0:
        return 0
    if j > n_seg - 1:
        return n_seg - 1
    return j


@njit(cache=True)
def _holding(x, y, j, tables):
    """``polyline.Line.holding`` for one point: walk from segment ``j`` to the one that holds the
    point's foot (at most ``max_walk`` steps; a reversal stops it)."""
    pts, tan, seg = tables[10], tables[12], tables[13]
    periodic = tables[14]
    max_walk, foot_eps = tables[25], tables[26]
    n = seg.shape[0]
    last = 0
    for _ in range(max_walk):
        a = (x - pts[j, 0]) * tan[j, 0] + (y - pts[j, 1]) * tan[j, 1]
        if a > seg[j] + foot_eps:
            step = 1
        elif a < -foot_eps:
            step = -1
        else:
            step = 0
        if not periodic:
            if j == 0 and step < 0:
                step = 0
            if j == n - 1 and step > 0:
                step = 0
        if step == -last:
            step = 0
        if step == 0:
            break
        j = j + step
        if periodic:
            if j < 0:
                j += n
            elif j >= n:
                j -= n
        last = step
    return j


@njit(cache=True)
def _to_s(g, tables):
    """``lane_tables.Measure.to_s`` for one arc length ``g`` (m)."""
    m_g, m_s = tables[15], tables[16]
    m_periodic, g_period, s_period = tables[17], tables[18], tables[19]
    if m_periodic:
        x = m_g[0] + (g - m_g[0]) % g_period
        return _interp(x, m_g, m_s) % s_period
    y = _interp(g, m_g, m_s)
    if g < m_g[0]:
        return m_s[0] + (g - m_g[0])
    if g > m_g[m_g.shape[0] - 1]:
        return m_s[m_s.shape[0] - 1] + (g - m_g[m_g.shape[0] - 1])
    return y


@njit(cache=True)
def geo_frame(k, pos, lat, tables):
    """Road-frame ``(s, d)`` (N,) m of SUMO positions on any lanes: what
    ``RoadNetwork.lane_frame``'s numpy path returns, bit for bit (``lane_tables.frame_of`` on the
    vehicles on route lanes, ``s = NaN, d = lat`` off them).

    Args: lane table keys ``k`` (N,) (-1 off-route), lane positions ``pos`` and lateral lane
    positions ``lat`` (N,) m, ``tables`` (see above). A vehicle on a lane parallel to the
    line takes ``s0 + pos, d0 + lat``; the others are projected onto the line, and a
    position beyond its lane's ends continues along ``s`` from the end (as numpy: once one
    vehicle is beyond, every projected ``s`` gets its ``beyond`` added, zeros included).
    """
    lane_len, tab_key, tab_g = tables[0], tables[8], tables[9]
    pts, cum, tan = tables[10], tables[11], tables[12]
    line_periodic = tables[14]
    m_periodic, s_period = tables[17], tables[19]
    has_par, par, par_s0, par_d0 = tables[20], tables[21], tables[22], tables[23]
    n = k.shape[0]
    s = np.empty(n)
    d = np.empty(n)
    beyond = np.zeros(n)
    any_beyond = False
    for i in range(n):
        kk = k[i]
        if kk < 0:
            s[i] = np.nan
            d[i] = lat[i]
            continue
        hi = lane_len[kk]
        p = pos[i]
        if p < 0.0:
            b = p - 0.0
        elif p > hi:
            b = p - hi
        else:
            b = p - p
        beyond[i] = b
        if b != 0.0:
            any_beyond = True
        if has_par and par[kk]:
            continue  # set below
        x, y, nx, ny, key = _lane_point(kk, p, tables)
        x = x + lat[i] * nx
        y = y + lat[i] * ny
        j = _holding(x, y, _segment_of(_interp(key, tab_key, tab_g), tables), tables)
        vx = x - pts[j, 0]
        vy = y - pts[j, 1]
        a = vx * tan[j, 0] + vy * tan[j, 1]
        d[i] = tan[j, 0] * vy - tan[j, 1] * vx
        g = cum[j] + a
        if line_periodic:
            g = g % cum[cum.shape[0] - 1]
        s[i] = _to_s(g, tables)
    for i in range(n):
        kk = k[i]
        if kk < 0:
            continue
        if has_par and par[kk]:
            s[i] = par_s0[kk] + pos[i]
            d[i] = par_d0[kk] + lat[i]
        elif any_beyond:
            s[i] = s[i] + beyond[i]
            if m_periodic:
                s[i] = s[i] % s_period
        if has_par and m_periodic:
            s[i] = s[i] % s_period
    return s, d


@njit(cache=True)
def geo_lateral(k, pos, d, tables):
    """SUMO lateral lane positions (N,) m that put vehicles on lanes ``k`` at road-frame
    offsets ``d`` (N,) m once at lane positions ``pos`` (N,) m, on any lanes: what
    ``RoadNetwork.lateral_lane_position``'s numpy path returns, bit for bit. A position
    past a lane's end lies on the lane after it (at most three lanes on); a lane parallel
    to the line takes ``d - d0``, the others the point along the lane's normal whose
    projection onto the line is at ``d`` (at most four rounds of segment and guess)."""
    lane_len, next_lane, tab_key, tab_g = tables[0], tables[1], tables[8], tables[9]
    pts, tan = tables[10], tables[12]
    par, par_d0 = tables[21], tables[23]
    n = k.shape[0]
    lat = np.empty(n)
    for i in range(n):
        kk = k[i]
        if kk < 0:
            lat[i] = d[i]
            continue
        kk, pp = _lane_reached(kk, pos[i], lane_len, next_lane)
        if par[kk]:
            lat[i] = d[i] - par_d0[kk]
            continue
        x, y, nx, ny, key = _lane_point(kk, pp, tables)
        j = _segment_of(_interp(key, tab_key, tab_g), tables)
        guess = 0.0
        for _ in range(4):
            vx = x - pts[j, 0]
            vy = y - pts[j, 1]
            d0 = tan[j, 0] * vy - tan[j, 1] * vx
            cos = tan[j, 0] * ny - tan[j, 1] * nx
            guess = (d[i] - d0) / cos
            j_new = _holding(x + guess * nx, y + guess * ny, j, tables)
            if j_new == j:
                break
            j = j_new
        lat[i] = guess
    return lat
