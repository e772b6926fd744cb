"""Compiled passes of the constraint layers (:mod:`controllers.layers.constraints`).

:class:`~controllers.layers.constraints.AccelerationBox` on the road's (N, 2) commands was five
small numpy calls per step (clip, compare, or, count, length), each paying numpy's
per-call cost for a few hundred values; :func:`box_clip` is one pass with the same
comparisons: ``np.clip`` of a finite value is the bound it passes or the value itself, a
NaN stays NaN (and counts as changed, as ``out != u`` counts it). The results are
identical (tests/test_constraints.py)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def box_clip(u, lo0, hi0, lo1, hi1):
    """``np.clip(u, [lo0, lo1], [hi0, hi1])`` of (N, 2) commands (m/s^2, ``lo < hi`` per
    axis) and the number of rows it changed: ``(out (N, 2), n_changed)``."""
    n = u.shape[0]
    out = np.empty((n, 2))
    changed = 0
    for i in range(n):
        a = u[i, 0]
        b = u[i, 1]
        x = a
        if x < lo0:
            x = lo0
        elif x > hi0:
            x = hi0
        y = b
        if y < lo1:
            y = lo1
        elif y > hi1:
            y = hi1
        out[i, 0] = x
        out[i, 1] = y
        if x != a or y != b:
            changed += 1
    return out, changed
