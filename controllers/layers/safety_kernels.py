"""The safety layer's compiled pass (:class:`controllers.layers.safety.SafetyLayer`): one loop per
CAV over a window of the vehicles sorted along the road. Its own module so that importing
the layer (a scenario's configuration) does not import numba."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _krauss(g, v_l, bt2, mbt, b, bl, two_b):
    """:func:`krauss_safe_speed` of one pair, m/s (the same operations in the same order)."""
    root = math.sqrt(max(bt2 + v_l * v_l * b / bl + two_b * g, 0.0))
    return 0.0 if g < 0 else mbt + root


#: Rule 3 takes a vehicle alongside (bodies overlapping along the road, its centre ahead)
#: that is clear sideways for a leader only if its lateral speed closes the lateral gap
#: within this time, s. Before, any such vehicle within ``lateral_clearance`` was a leader
#: at a negative gap and the CAV stopped dead: on TUM's ring (10 % CAVs, 400 veh/km) a
#: human driver's centre passed a CAV's 0.23 m beside it, the CAV stopped from 3.3 m/s in
#: 0.5 s and the driver behind it (TUM's model, reaction time 1.5 s) ran into it.
ALONGSIDE_S = 1.0


@njit(cache=True)
def apply_kernel(u, cav_index, v_lat, s_all, d_all, v_all, len_all, wid_all, vlat_all,
                  is_cav, edges, periodic, period, order, key, wall_gap, has_wall, reach, C):
    """The three rules for every CAV (see :meth:`SafetyLayer.apply`), ``u`` (N, 2) changed
    in place; returns (v_lat_next (N,) m/s, counts (3,): edge, side and speed rule
    activations).

    Neighbours: every other vehicle whose centre lies closer than ``reach`` (m; Euclidean
    in the road frame, wrapped on a ring of length ``period``), found in a window of the
    vehicles sorted along the road (``order``; ``key`` their sorted ``s``, modulo the
    period on a ring, there in three copies, one period apart), as
    :func:`controllers.neighbours.strip_cross_pairs` finds them. A ring shorter than twice
    the reach is scanned whole (each vehicle once). All reductions are minima and maxima:
    the order of the pairs does not matter.
    """
    dt, min_gap, lat_clear, edge_margin, b, bl = C[0], C[1], C[2], C[3], C[4], C[5]
    lsm, cut_in, bt2, mbt, two_b = C[6], C[7], C[8], C[9], C[10]
    two_la, la_dt, shift_cav = C[11], C[12], C[13]
    n = cav_index.shape[0]
    m = s_all.shape[0]
    v_lat_next = np.empty(n)
    counts = np.zeros(3, np.int64)
    r2 = reach * reach
    scan_all = periodic and not (period > 2.0 * reach)
    for i in range(n):
        ci = cav_index[i]
        s, d, v = s_all[ci], d_all[ci], v_all[ci]
        L, W = len_all[ci], wid_all[ci]
        u0 = u[i, 0]
        # 1. road edges ----------------------------------------------------------------
        vl = min(max(v_lat[i] + u[i, 1] * dt, -lsm), lsm)
        lo = edges[i, 0] + 0.5 * W + edge_margin
        hi = edges[i, 1] - 0.5 * W - edge_margin
        cap_left = math.sqrt(two_la * max(hi - d, 0.0))
        cap_right = math.sqrt(two_la * max(d - lo, 0.0))
        vl_edge = min(max(vl, -cap_right), cap_left)
        back_in = min(max(v_lat[i] - la_dt, -lsm), 0.0)
        back_out = min(max(v_lat[i] + la_dt, 0.0), lsm)
        if d > hi:
            vl_edge = min(vl_edge, back_in)
        if d < lo:
            vl_edge = max(vl_edge, back_out)
        d_next = d + vl_edge * dt
        d_next = min(max(d_next, min(lo, d)), max(hi, d))
        vl_edge = (d_next - d) / dt
        if abs(vl_edge - vl) > 1e-9:
            counts[0] += 1
        # the window of candidates
        if scan_all:
            e0, e1 = 0, m
        else:
            x = s % period if periodic else s
            e0 = np.searchsorted(key, x - reach, side="right")
            e1 = np.searchsorted(key, x + reach, side="left")
        # 2. side clearance (first pass over the neighbours) -------------------------------
        hi_side = np.inf
        lo_side = -np.inf
        for e in range(e0, e1):
            j = order[e % m]
            if j == ci:
                continue
            ds = s_all[j] - s
            if periodic:
                ds = (ds + 0.5 * period) % period - 0.5 * period
            dd = d_all[j] - d
            if not (ds * ds + dd * dd < r2):
                continue
            half_l = 0.5 * (L + len_all[j])
            v_j = v_all[j]
            if ds >= 0:
                buf = max(v - v_j, 0.0) * cut_in + min_gap
                v_follow, v_lead = v, v_j
            else:
                buf = max(v_j - v, 0.0) * cut_in + min_gap
                v_follow, v_lead = v_j, v
            beside = abs(ds) < half_l + buf
            gap_pair = abs(ds) - half_l - min_gap
            unsafe = v_follow > _krauss(gap_pair, v_lead, bt2, mbt, b, bl, two_b) + 1e-9
            if unsafe:
                beside = True
            half_w = 0.5 * (W + wid_all[j])
            if (beside and abs(dd) < half_w + lat_clear and abs(ds) >= half_l
                    and (ds > 0 or not unsafe)):
                # in one band, one behind the other: a leader (rule 3 holds the CAV off)
                # or a follower that can stop behind it, not a neighbour at one side (its
                # side is undefined; a CAV stopped behind a car must be able to move out
                # from behind it)
                beside = False
            if beside:
                shift = shift_cav if is_cav[j] else abs(vlat_all[j]) * dt
                need = half_w + lat_clear + shift
                if dd >= 0:
                    hi_side = min(hi_side, d_all[j] - need)
                else:
                    lo_side = max(lo_side, d_all[j] + need)
        d_side = min(max(d_next, min(lo_side, d)), max(hi_side, d))
        if abs(d_side - d_next) > 1e-9:
            counts[1] += 1
        d_next = d_side
        vln = (d_next - d) / dt
        v_lat_next[i] = vln
        # 3. safe speed (second pass) -----------------------------------------------------
        d_lo = min(d, d_next)
        d_hi = max(d, d_next)
        v_safe = np.inf
        for e in range(e0, e1):
            j = order[e % m]
            if j == ci:
                continue
            ds = s_all[j] - s
            if periodic:
                ds = (ds + 0.5 * period) % period - 0.5 * period
            dd = d_all[j] - d
            if not (ds * ds + dd * dd < r2) or not ds > 0:
                continue
            lat_gap = max(d_all[j] - d_hi, d_lo - d_all[j]) - 0.5 * (W + wid_all[j])
            if lat_gap < lat_clear:
                if lat_gap >= 0 and ds < 0.5 * (L + len_all[j]):
                    # alongside (bodies overlap along the road), clear sideways and not
                    # closing within ALONGSIDE_S: not a leader (stopping dead cannot
                    # avoid a vehicle beside; rule 2 keeps the side clearance)
                    toward = -vlat_all[j] if dd > 0 else vlat_all[j]
                    if lat_gap - max(toward, 0.0) * ALONGSIDE_S >= 0:
                        continue
                gap = ds - 0.5 * (L + len_all[j]) - min_gap
                v_safe = min(v_safe, _krauss(gap, v_all[j], bt2, mbt, b, bl, two_b))
        if has_wall and np.isfinite(wall_gap[i]):
            v_safe = min(v_safe, _krauss(wall_gap[i] - 0.5, 0.0, bt2, mbt, b, bl, two_b))
        u_long = min(u0, (v_safe - v) / dt)
        u_long = max(u_long, -b)
        u_long = max(u_long, -v / dt)
        if u_long < u0 - 1e-9:
            counts[2] += 1
        u[i, 0] = u_long
        u[i, 1] = (vln - v_lat[i]) / dt
    return v_lat_next, counts
