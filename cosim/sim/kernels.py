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
    operations in the same order as the numpy code of ``Loop._reference``; and whether
    every entry of ``q`` and ``p`` is finite."""
    n = rows.shape[0]
    q = np.empty((n, 2))
    p = np.empty((n, 2))
    des = np.empty(n)
    stop = np.empty(n)
    ln = np.empty(n)
    wd = np.empty(n)
    finite = True
    for k in range(n):
        r = rows[k]
        q[k, 0] = s[r]
        q[k, 1] = d[r]
        vk = v[r]
        p[k, 0] = vk
        p[k, 1] = v_lat[r]
        if not (np.isfinite(s[r]) and np.isfinite(d[r]) and np.isfinite(vk)
                and np.isfinite(v_lat[r])):
            finite = False
        x = desired[r]
        des[k] = x if np.isfinite(x) else speed_limit
        stop[k] = vk * dt + (vk * vk) / two_b + margin
        ln[k] = length[r]
        wd[k] = width[r]
    return q, p, des, stop, ln, wd, finite


@njit(cache=True)
def integrate(q, p, u, v_lat_next, dt, speed_limit):
    """The loop's semi-implicit Euler step of N CAVs: next speed
    ``clip(p[:, 0] + u[:, 0] dt, 0, speed_limit)`` (m/s) and next lateral position
    ``q[:, 1] + v_lat_next dt`` (m), (N,) each; the same operations as the numpy code of
    ``Loop._integrate`` (a NaN stays NaN, as ``np.clip`` keeps it)."""
    n = q.shape[0]
    v_next = np.empty(n)
    d_next = np.empty(n)
    for i in range(n):
        x = p[i, 0] + u[i, 0] * dt
        if x < 0.0:
            x = 0.0
        elif x > speed_limit:
            x = speed_limit
        v_next[i] = x
        d_next[i] = q[i, 1] + v_lat_next[i] * dt
    return v_next, d_next
