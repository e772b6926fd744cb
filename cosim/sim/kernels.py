"""Compiled per-step helper of the loop (:mod:`cosim.sim.loop`): the CAVs' columns of the
observation gathered from the world's snapshot in one pass (as numpy it was a dozen
small array operations per step)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def cav_columns(rows, s, d, v, v_lat, length, width, desired, speed_limit, dt, two_b,
                margin):
    """The CAVs' rows of the snapshot: positions ``q`` and velocities ``p`` (N, 2) (m, m/s),
    lengths and widths (N,) m, desired speeds (N,) m/s (``speed_limit`` where unknown) and
    the reach of the road edges ahead ``v dt + v^2 / two_b + margin`` (N,) m, the same
    operations in the same order as the numpy code of ``Loop._reference``."""
    n = rows.shape[0]
    q = np.empty((n, 2))
    p = np.empty((n, 2))
    des = np.empty(n)
    stop = np.empty(n)
    ln = np.empty(n)
    wd = np.empty(n)
    for k in range(n):
        r = rows[k]
        q[k, 0] = s[r]
        q[k, 1] = d[r]
        vk = v[r]
        p[k, 0] = vk
        p[k, 1] = v_lat[r]
        x = desired[r]
        des[k] = x if np.isfinite(x) else speed_limit
        stop[k] = vk * dt + (vk * vk) / two_b + margin
        ln[k] = length[r]
        wd[k] = width[r]
    return q, p, des, stop, ln, wd
