"""Compiled look-ups of a piecewise-constant road profile
(:class:`controllers.observation.RoadProfile`): the edges at a position and the narrowest
edges over a stretch ahead, for every vehicle in one call. As numpy each was a dozen
small (N,) and (N, K) array operations per call, and the loop, the law and the recorders
call them several times a step on a road whose width changes. The same comparisons and
the same additions as the numpy code (maxima and minima are exact), NaN positions
included: the results are identical (tests/test_observation_profile.py)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _piece(s0, x):
    """``clip(searchsorted(s0, x, 'right') - 1, 0, K - 1)``: the piece holding ``x`` (NaN
    sorts after every value, as in numpy: the last piece)."""
    k_last = s0.shape[0] - 1
    if x != x:
        return k_last
    lo, hi = 0, s0.shape[0]  # first index with s0 > x, by bisection
    while lo < hi:
        mid = (lo + hi) // 2
        if s0[mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return min(max(lo - 1, 0), k_last)


@njit(cache=True)
def edges_at(s, s0, right, left, periodic, length_m):
    """Edges (N, 2) m ``[right, left]`` at positions ``s`` (N,) m of a profile with pieces
    starting at ``s0`` (K,) m (wrapped with numpy's ``mod`` on a ring of ``length_m``)."""
    n = s.shape[0]
    out = np.empty((n, 2))
    for i in range(n):
        x = s[i] % length_m if periodic else s[i]
        k = _piece(s0, x)
        out[i, 0] = right[k]
        out[i, 1] = left[k]
    return out


@njit(cache=True)
def narrowest_over(s, ahead, s0, right, left, periodic, length_m):
    """Narrowest edges (N, 2) m over ``[s, s + ahead]`` (N,) m: the edges at ``s``, then
    the largest right and smallest left edge of every piece the stretch touches (a piece
    ``[s0_k, s0_k+1)`` with ``s0_k+1 > s`` and ``s0_k <= s + ahead``; on a ring also the same
    pieces one lap on, ``+ length_m``)."""
    n = s.shape[0]
    k_n = s0.shape[0]
    out = edges_at(s, s0, right, left, periodic, length_m)
    for i in range(n):
        col = s[i]
        end = col + ahead[i]
        r = -np.inf
        lf = np.inf
        for k in range(k_n):
            start = s0[k]
            stop = s0[k + 1] if k + 1 < k_n else np.inf
            hit = stop > col and start <= end
            if periodic and not hit:
                hit = stop + length_m > col and start + length_m <= end
            if hit:
                r = max(r, right[k])
                lf = min(lf, left[k])
        out[i, 0] = max(out[i, 0], r)
        out[i, 1] = min(out[i, 1], lf)
    return out


@njit(cache=True)
def first_wall_ahead(s, d, width, length, s0, right, left, periodic, length_m, reach_m):
    """Distance (N,) m from each body's front (centres ``s``, ``d``, sizes ``width``,
    ``length`` (N,) m) to the start of the first piece within ``reach_m`` ahead whose edges
    it does not fit into at its lateral position: ``min ds - length / 2`` over those pieces
    (``ds = s0_k - s``, wrapped with numpy's ``mod`` on a ring), inf where none."""
    n = s.shape[0]
    out = np.empty(n)
    for i in range(n):
        half = 0.5 * width[i]
        best = np.inf
        for k in range(s0.shape[0]):
            ds = s0[k] - s[i]
            if periodic:
                ds = ds % length_m
            if ds > 0 and ds < reach_m and (d[i] - half < right[k] or d[i] + half > left[k]):
                best = min(best, ds)
        out[i] = best - 0.5 * length[i]
    return out
