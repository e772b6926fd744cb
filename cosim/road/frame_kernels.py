"""Compiled fast paths of the road frame (:mod:`cosim.road.frame`) for lanes that run
parallel to the reference line: every lane of the networks cosim builds, a user's straight
lanes. The SUMO world maps every vehicle through them every step; as numpy each call was a
dozen small array operations. Each kernel returns ``ok = False`` as soon as a vehicle is on
a lane it does not handle, and the caller then takes the numpy path, which projects onto
the line. Where a kernel answers, it does the numpy path's arithmetic element by element:
the same bits (tests/test_exactness.py, tests/test_road_frame.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit


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
        pp = pos[i]
        for _ in range(3):
            if pp > lane_len[kk] and next_lane[kk] >= 0:
                pp = pp - lane_len[kk]
                kk = next_lane[kk]
            else:
                break
        if not par[kk]:
            return lat, False
        lat[i] = d[i] - par_d0[kk]
    return lat, True
