"""Per-vehicle gamma references on a road: desired speed bounded by a time-gap policy.

A flock that tracks a constant reference speed keeps that speed at any density
and so flattens the fundamental diagram. Real automated vehicles keep a time
gap: the reference speed of CAV ``i`` is

    v_ref_i = clip((g_i - s0) / T, 0, v_des_i)

with ``g_i`` the bumper-to-bumper gap to the nearest vehicle ahead that
overlaps laterally (m), ``s0`` the standstill gap (m) and ``T`` the time gap
(s) (constant time-gap policy; e.g. Ploeg et al., IEEE T-ITS 2014). In
equilibrium ``g = s0 + T v``, which gives a triangular fundamental diagram
per row of vehicles: ``q = v / (s0 + L + T v)``.
"""

from __future__ import annotations

import numpy as np

from .neighbours import cross_pairs


def leader_gaps(
    s: np.ndarray,
    d: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    rows: np.ndarray,
    reach_m: float,
    period: float | None = None,
    lateral_margin_m: float = 0.0,
) -> np.ndarray:
    """Gap (m) from each vehicle in ``rows`` to its nearest laterally overlapping leader.

    ``s``, ``d``, ``length``, ``width`` (M,) describe all vehicles (centres, m);
    ``rows`` (N,) selects the vehicles asked about. Returns (N,) gaps, inf where
    no leader is within ``reach_m``.
    """
    n = len(rows)
    gap = np.full(n, np.inf)
    if n == 0:
        return gap
    xy = np.column_stack([s, d])
    pairs = cross_pairs(xy[rows], xy, reach_m, period)
    pairs = pairs[rows[pairs[:, 0]] != pairs[:, 1]]
    if len(pairs) == 0:
        return gap
    i, j = pairs[:, 0], pairs[:, 1]
    me = rows[i]
    ds = s[j] - s[me]
    if period is not None:
        ds = (ds + 0.5 * period) % period - 0.5 * period
    overlap = np.abs(d[j] - d[me]) < 0.5 * (width[me] + width[j]) + lateral_margin_m
    ahead = (ds > 0) & overlap
    np.minimum.at(gap, i[ahead], ds[ahead] - 0.5 * (length[me[ahead]] + length[j[ahead]]))
    return gap


def time_gap_speed(
    v_des: np.ndarray, gap: np.ndarray, time_gap_s: float, standstill_gap_m: float
) -> np.ndarray:
    """Reference speed (m/s): ``clip((gap - s0) / T, 0, v_des)``; ``v_des`` if T = 0."""
    if time_gap_s <= 0:
        return np.asarray(v_des, dtype=float)
    return np.clip((gap - standstill_gap_m) / time_gap_s, 0.0, v_des)
