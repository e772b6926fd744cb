"""Compiled look-ups of a piecewise-constant road profile
(:class:`controllers.observation.RoadProfile`): the edges at a position and the narrowest
edges over a stretch ahead, for every vehicle in one call. As numpy each was a dozen
small (N,) and (N, K) array operations per call, and the loop, the law and the recorders
call them several times a step on a road whose width changes. The same comparisons and
the same additions as the numpy code (maxima and minima are exact), NaN positions
included: the results are identical (tests/test_observation_profile.py).

Each vehicle looks only at the pieces that can lie in its stretch ahead, found by
bisection of the pieces' starts (:func:`ahead_windows`, :func:`_touching`), and tests
those with the comparisons of the full pass over all K pieces, in the same order: the
cost is O(N log K + the pieces in reach), not O(N K) (on a long road of many pieces, with
N growing with the length, that was quadratic; tests/test_profile_windows.py checks the
results against the numpy references on profiles of up to 600 pieces, and that the
windows hold every piece ahead)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: A stretch's windows are widened by this (m, plus 1e-9 of the magnitudes involved) so
#: that rounding in ``s0 - s`` and in numpy's ``mod`` cannot leave a piece out; the exact
#: test of each piece inside decides.
WINDOW_SLACK_M = 1e-6
#: More windows than this (a ring's pieces spread over many laps): test every piece.
_MAX_WINDOWS = 8


@njit(cache=True, inline="always")
def _first_above(s0, y):
    """First index with ``s0[i] > y`` (K if none), by bisection; ``y`` not NaN."""
    lo, hi = 0, s0.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if s0[mid] <= y:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, inline="always")
def _piece(s0, x):
    """``clip(searchsorted(s0, x, 'right') - 1, 0, K - 1)``: the piece holding ``x`` (NaN
    sorts after every value, as in numpy: the last piece)."""
    k_last = s0.shape[0] - 1
    if x != x:
        return k_last
    return min(max(_first_above(s0, x) - 1, 0), k_last)


@njit(cache=True)
def ahead_windows(s0, x, reach, periodic, length_m, out):
    """Index windows ``[out[w, 0], out[w, 1])`` (ascending, disjoint; their number is
    returned) holding every piece ``k`` whose start lies ahead of ``x`` by ``ds`` with
    ``0 < ds < reach`` (``ds = s0[k] - x``, on a ring ``(s0[k] - x) mod length_m``), and a
    few more; none when ``x`` or ``reach`` is NaN or ``x`` infinite. ``out`` (W, 2) int64,
    W >= ``_MAX_WINDOWS``."""
    k_n = s0.shape[0]
    if x != x or reach != reach or not math.isfinite(x):
        return 0
    m = WINDOW_SLACK_M + 1e-9 * (abs(x) + (length_m if periodic else 0.0)
                                 + (abs(reach) if math.isfinite(reach) else 0.0))
    if not periodic:
        out[0, 0] = max(_first_above(s0, x - m) - 1, 0)
        out[0, 1] = k_n if not math.isfinite(reach) else _first_above(s0, x + reach + m)
        return 1
    if not (reach + 2.0 * m < length_m) or not (math.isfinite(s0[0])
                                                 and math.isfinite(s0[k_n - 1])):
        out[0, 0], out[0, 1] = 0, k_n
        return 1
    xr = x % length_m
    # the starts s0 = xr + j length_m + (0, reach), for the laps j the pieces span
    j_lo = int(math.floor((s0[0] - xr - reach) / length_m)) - 1
    j_hi = int(math.ceil((s0[k_n - 1] - xr) / length_m)) + 1
    if j_hi - j_lo + 1 > _MAX_WINDOWS:
        out[0, 0], out[0, 1] = 0, k_n
        return 1
    w = 0
    prev = 0
    for j in range(j_lo, j_hi + 1):
        base = xr + j * length_m
        lo = max(_first_above(s0, base - m) - 1, prev)
        hi = _first_above(s0, base + reach + m)
        if hi > lo:
            out[w, 0], out[w, 1] = lo, hi
            w += 1
            prev = hi
    return w


@njit(cache=True, inline="always")
def _touching(s0, col, end, shift):
    """``[lo, hi)``: the pieces ``[s0_k, s0_k+1)`` moved by ``shift`` (0 or a lap) that can
    touch ``[col, end]`` (``stop + shift > col`` and ``start + shift <= end``), and a few
    more; ``col``, ``end`` not NaN."""
    m = 0.0 if shift == 0.0 else WINDOW_SLACK_M + 1e-9 * (abs(col) + abs(end) + abs(shift))
    lo = max(_first_above(s0, col - shift - m) - 1, 0)
    hi = _first_above(s0, end - shift + m) if math.isfinite(end) else s0.shape[0]
    return lo, hi


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
        if col == col and end == end:  # NaN touches no piece
            a_lo, a_hi = _touching(s0, col, end, 0.0)
            b_lo, b_hi = _touching(s0, col, end, length_m) if periodic else (0, 0)
            # the two windows in ascending order, each piece once
            if b_hi <= b_lo:
                b_lo, b_hi = 0, 0
            elif a_hi <= a_lo:
                a_lo, a_hi, b_lo, b_hi = b_lo, b_hi, 0, 0
            else:
                if b_lo < a_lo:
                    a_lo, a_hi, b_lo, b_hi = b_lo, b_hi, a_lo, a_hi
                if b_lo < a_hi:  # overlapping: one window
                    a_hi, b_lo, b_hi = max(a_hi, b_hi), 0, 0
            for w in range(2):
                lo, hi = (a_lo, a_hi) if w == 0 else (b_lo, b_hi)
                for k in range(lo, hi):
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
    win = np.empty((_MAX_WINDOWS, 2), dtype=np.int64)
    for i in range(n):
        half = 0.5 * width[i]
        best = np.inf
        for w in range(ahead_windows(s0, s[i], reach_m, periodic, length_m, win)):
            for k in range(win[w, 0], win[w, 1]):
                ds = s0[k] - s[i]
                if periodic:
                    ds = ds % length_m
                if ds > 0 and ds < reach_m and (d[i] - half < right[k]
                                                or d[i] + half > left[k]):
                    best = min(best, ds)
        out[i] = best - 0.5 * length[i]
    return out
