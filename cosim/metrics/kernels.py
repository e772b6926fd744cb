"""Compiled per-step arithmetic of the recorders (numba), bit for bit what numpy gave.

The recorders of :mod:`cosim.metrics.traffic`, :mod:`cosim.metrics.jams` and
:mod:`cosim.sim.recording` run every step; as numpy they were dozens of small array
operations on (M,) masks each step, each paying numpy's per-call overhead (1-2 us) for a
few hundred vehicles. These kernels do the same arithmetic in one pass each.

Exactness: a masked sum such as ``np.sum(v[mask])`` is numpy's pairwise summation over
the gathered values (:func:`np_sum` repeats its blocking: 8 accumulators up to 128
values, halves beyond), so the kernels gather first and sum with :func:`np_sum`; the
results equal numpy's to the last bit (tests/test_recorder_exactness.py). Comparisons
keep numpy's NaN rules (a NaN compares false; a maximum or minimum with a NaN is NaN).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _block(a, lo, n):
    """numpy's pairwise sum of ``a[lo:lo + n]`` for ``n <= 128`` (one block: in order below
    8 values, else 8 accumulators)."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    m = n - n % 8
    i = 8
    while i < m:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def np_sum(a, n):
    """``np.sum(a[:n])`` of a contiguous float64 array, the same bits: numpy's
    ``pairwise_sum_DOUBLE``, which halves a range of more than 128 values (the first half
    a multiple of 8 long) and adds the halves' sums. Walked with an explicit stack (numba
    cannot load a recursive function from its cache)."""
    if n <= 128:
        return _block(a, 0, n)
    lo_s = np.empty(64, np.int64)
    n_s = np.empty(64, np.int64)
    right = np.zeros(64, np.bool_)  # the frame's left half is done, in left_s
    left_s = np.empty(64)
    sp = 0
    lo_s[0] = 0
    n_s[0] = n
    ret = 0.0
    have = False  # ret holds the sum of the frame just popped
    while True:
        if have:
            if sp < 0:
                return ret
            if not right[sp]:  # the left half is done: do the right one
                left_s[sp] = ret
                right[sp] = True
                have = False
                m = n_s[sp]
                n2 = m // 2
                n2 -= n2 % 8
                sp += 1
                lo_s[sp] = lo_s[sp - 1] + n2
                n_s[sp] = m - n2
                right[sp] = False
            else:
                ret = left_s[sp] + ret
                sp -= 1
            continue
        m = n_s[sp]
        if m <= 128:
            ret = _block(a, lo_s[sp], m)
            have = True
            sp -= 1
            continue
        n2 = m // 2
        n2 -= n2 % 8
        sp += 1
        lo_s[sp] = lo_s[sp - 1]
        n_s[sp] = n2
        right[sp] = False


@njit(cache=True)
def traffic_tallies(s, s_front, d, v, width, is_cav, static, desired, has_desired,
                    edge_right, edge_left, z0, z1, measuring, count_crossings, prev_front,
                    prev_row, same_rows, xs, periodic, period, crossings):
    """One step of :class:`~cosim.metrics.traffic.TrafficRecorder` but gaps and collisions.

    Args: the step's (M,) arrays (m, m/s; ``static``: stopped obstacles; ``desired``
    (M,) m/s, read only if ``has_desired``); the zone ``[z0, z1)`` m; ``measuring``: after
    the warm-up (the zone sums are wanted); ``count_crossings``: count the fronts that
    passed the cross-sections ``xs`` (K,) m since the previous step, whose fronts are
    ``prev_front`` (m; NaN: unknown) at rows ``prev_row`` (M,) of each vehicle (-1: absent;
    :func:`cosim.metrics.jams.align`), or at the same rows if ``same_rows``; ``crossings``
    (K,) int64 is incremented in place.

    Returns ``(n_traffic, n_zone, ttd_sum, sf_cav, n_sf_cav, sf_hdv, n_sf_hdv, out,
    n_out, n_out_cav, max_excursion)``: vehicles that are traffic; those in the zone, the
    sum of their speeds (m/s) and the shortfall sums ``desired - v`` (m/s) and counts of
    CAVs and human drivers with a known desired speed there (zeros unless measuring);
    the mask (M,) of traffic with a body more than 1e-6 m outside the edges, their number,
    of them CAVs, and the largest excursion (m) of any vehicle (NaN if any is NaN).
    """
    n = s.shape[0]
    buf_v = np.empty(n)
    buf_c = np.empty(n)
    buf_h = np.empty(n)
    n_traffic = 0
    n_zone = 0
    n_c = 0
    n_h = 0
    out = np.zeros(n, np.bool_)
    n_out = 0
    n_out_cav = 0
    exc_max = -np.inf
    exc_nan = False
    for i in range(n):
        traffic = not static[i]
        if traffic:
            n_traffic += 1
        if measuring and traffic and s[i] >= z0 and s[i] < z1:
            buf_v[n_zone] = v[i]
            n_zone += 1
            if has_desired and np.isfinite(desired[i]):
                if is_cav[i]:
                    buf_c[n_c] = desired[i] - v[i]
                    n_c += 1
                else:
                    buf_h[n_h] = desired[i] - v[i]
                    n_h += 1
        a = edge_right[i] - (d[i] - 0.5 * width[i])
        b = (d[i] + 0.5 * width[i]) - edge_left[i]
        if a != a or b != b:
            exc_nan = True
        else:
            e = a if a >= b else b
            if e > exc_max:
                exc_max = e
            if e > 1e-6 and traffic:
                out[i] = True
                n_out += 1
                if is_cav[i]:
                    n_out_cav += 1
    if count_crossings:
        for i in range(n):
            if same_rows:
                prv = prev_front[i]
            else:
                j = prev_row[i]
                if j < 0:
                    continue
                prv = prev_front[j]
            if prv != prv:
                continue
            cur = s_front[i]
            if periodic and cur < prv - 0.5 * period:
                cur = cur + period
            for k in range(xs.shape[0]):
                x = xs[k]
                if prv < x and cur >= x:
                    crossings[k] += 1
                if periodic and prv < x + period and cur >= x + period:
                    crossings[k] += 1
    ttd = np_sum(buf_v, n_zone)
    sf_c = np_sum(buf_c, n_c)
    sf_h = np_sum(buf_h, n_h)
    if exc_nan:
        exc_max = np.nan
    return (n_traffic, n_zone, ttd, sf_c, n_c, sf_h, n_h, out, n_out, n_out_cav, exc_max)


@njit(cache=True)
def gap_tallies(g_long, g_side, leader, v, is_cav, static, ttc_threshold_s):
    """A measured step's gap, headway and time-to-collision figures
    (:class:`~cosim.metrics.traffic.TrafficRecorder`), obstacles following nobody.

    Args: gaps to the leaders and side clearances (M,) m, leader rows (M,) (-1: none),
    speeds (M,) m/s, CAV and obstacle masks (M,), ``TTC*`` s.

    Returns ``(n_traffic, ttc_min, n_cav, ttc_cav_min, n_exposed, tit_sum, gap_min,
    cav_gap_min, n_finite, n_cav_finite, headways, side_min, n_side)``: the TTC minimum
    over all vehicles and over CAVs (NaN if any TTC is NaN; ``n_cav`` CAVs), the vehicles
    with ``TTC <= TTC*`` and the sum of ``TTC* - TTC`` over them (s), the smallest finite
    gap (m) of all and of CAVs and their numbers, the time headways ``gap / v`` (s) of the
    vehicles with a finite gap moving faster than 1 m/s (in row order), the smallest finite
    side clearance (m) and the number of finite ones.
    """
    n = v.shape[0]
    n_traffic = 0
    ttc_min = np.inf
    ttc_nan = False
    cav_min = np.inf
    cav_nan = False
    n_cav = 0
    buf = np.empty(n)
    n_exp = 0
    hw = np.empty(n)
    n_hw = 0
    gap_min = np.inf
    cav_gap_min = np.inf
    n_fin = 0
    n_cav_fin = 0
    side_min = np.inf
    n_side = 0
    for i in range(n):
        traffic = not static[i]
        if traffic:
            n_traffic += 1
        g = g_long[i] if traffic else np.inf
        gs = g_side[i] if traffic else np.inf
        ttc = np.inf
        j = leader[i]
        if j >= 0:
            closing = v[i] - v[j]
            if closing > 0:
                ttc = (g if g >= 0.0 else 0.0) / closing
                if g != g:
                    ttc = np.nan
        if ttc != ttc:
            ttc_nan = True
        elif ttc < ttc_min:
            ttc_min = ttc
        if is_cav[i]:
            n_cav += 1
            if ttc != ttc:
                cav_nan = True
            elif ttc < cav_min:
                cav_min = ttc
        if ttc <= ttc_threshold_s:
            buf[n_exp] = ttc_threshold_s - ttc
            n_exp += 1
        if np.isfinite(g):
            n_fin += 1
            if g < gap_min:
                gap_min = g
            if is_cav[i]:
                n_cav_fin += 1
                if g < cav_gap_min:
                    cav_gap_min = g
            if v[i] > 1.0:
                hw[n_hw] = g / v[i]
                n_hw += 1
        if np.isfinite(gs):
            n_side += 1
            if gs < side_min:
                side_min = gs
    if ttc_nan:
        ttc_min = np.nan
    if cav_nan:
        cav_min = np.nan
    tit = np_sum(buf, n_exp)
    return (n_traffic, ttc_min, n_cav, cav_min, n_exp, tit, gap_min, cav_gap_min, n_fin,
            n_cav_fin, hw[:n_hw].copy(), side_min, n_side)


# ------------------------------------------------------------------ pairs along the road
@njit(cache=True)
def all_finite(s, d, length, width):
    """True if the four (M,) arrays hold no NaN or inf."""
    return _finite(s) and _finite(d) and _finite(length) and _finite(width)


@njit(cache=True, inline="always")
def _finite(a):
    for x in a:
        if not np.isfinite(x):
            return False
    return True


@njit(cache=True, inline="always")
def tree_within(xi, yi, xj, yj, r2, periodic, period, box_y):
    """cKDTree's test of ``query_pairs`` for points (xi, yi), (xj, yj): squared distance
    (wrapped per axis on a ring, as its ``boxsize`` wraps) ``<= r^2``."""
    dx = xi - xj
    dy = yi - yj
    if periodic:
        hb = 0.5 * period
        if dx < -hb:
            dx = period + dx
        elif dx > hb:
            dx = dx - period
        hby = 0.5 * box_y
        if dy < -hby:
            dy = box_y + dy
        elif dy > hby:
            dy = dy - box_y
    return dx * dx + dy * dy <= r2


@njit(cache=True)
def pairs_within(px, py, reach, periodic, period, box_y):
    """The pairs (i < j) cKDTree's ``query_pairs(reach)`` returns for the points
    (``px``, ``py``) (M,) m, as a set: (P, 2) int64, in sweep order (not the tree's).

    A sweep along ``px`` sorted, each point against the next ones within a window a
    little wider than the reach (then the tree's own test); on a ring (``periodic``,
    ``px`` in [0, period)) also across the seam, each pair once. Two passes: count, fill."""
    order = np.argsort(px)
    xs = px[order]
    ys = py[order]
    out = np.empty((0, 2), np.int64)
    cnt = _sweep(xs, ys, order, reach, periodic, period, box_y, out, False)
    out = np.empty((cnt, 2), np.int64)
    _sweep(xs, ys, order, reach, periodic, period, box_y, out, True)
    return out


@njit(cache=True)
def _sweep(xs, ys, order, reach, periodic, period, box_y, out, fill):
    """:func:`pairs_within` over points sorted by ``xs``: the number of pairs, written to
    ``out`` (P, 2) if ``fill``."""
    n = xs.shape[0]
    r2 = reach * reach
    win = reach * (1.0 + 1e-9) + 1e-6
    cnt = 0
    for p in range(n):
        xp, yp = xs[p], ys[p]
        for q in range(p + 1, n):
            if xs[q] - xp > win:
                break
            if tree_within(xp, yp, xs[q], ys[q], r2, periodic, period, box_y):
                if fill:
                    out[cnt, 0] = min(order[p], order[q])
                    out[cnt, 1] = max(order[p], order[q])
                cnt += 1
        if periodic:
            for q in range(p):  # ahead across the seam
                if (xs[q] - xp) + period > win:
                    break
                if xp - xs[q] <= win:  # q's own sweep found this pair
                    continue
                if tree_within(xp, yp, xs[q], ys[q], r2, periodic, period, box_y):
                    if fill:
                        out[cnt, 0] = min(order[p], order[q])
                        out[cnt, 1] = max(order[p], order[q])
                    cnt += 1
    return cnt


@njit(cache=True, inline="always")
def wrap_ds(ds, periodic, period):
    """``(ds + period / 2) % period - period / 2`` on a ring (numpy's float ``%``), else
    ``ds``. ``%`` returns its operand unchanged in [0, period): skipped there."""
    if periodic:
        x = ds + 0.5 * period
        if not (0.0 <= x < period):
            x = x % period
        return x - 0.5 * period
    return ds


@njit(cache=True)
def pair_sweep(px, py, s, d, length, width, periodic, period, box_y, gaps, reach_gap,
               margin):
    """Overlapping rectangles and, if ``gaps``, each vehicle's leader gap, side clearance
    and leader, from one sort along the road (:mod:`cosim.metrics.traffic`).

    Points (``px``, ``py``) (M,) m are the tree's coordinates (on a ring ``px`` in
    [0, period) and a box ``box_y`` m along d); rectangles have centres ``s``, ``d`` and
    sizes ``length``, ``width`` (M,) m. From each vehicle ``a`` (follower) the vehicles in
    road order are scanned ahead while one of them could still be its leader (the distance
    along the road minus half of both lengths at most the smallest gap so far, within
    ``reach_gap`` m) or beside it (within half of both lengths), and behind while beside
    it. A vehicle ``b`` counts for ``a``'s gaps only within ``reach_gap`` by cKDTree's test
    (``query_pairs``, the candidates the tree code used), laterally overlapping within
    ``margin`` m: the leader is the one ahead with the smallest bumper gap, the side
    clearance the smallest one beside it. Every pair whose rectangles overlap strictly is
    an overlap (they lie within half of both lengths of each other).

    Returns ``(overlaps (min(P, 2), 2) int64 (i < j), P, g_long (M,) m, g_side (M,) m,
    leader (M,) int64, tied)``: the first two of the P overlapping pairs (with two or more
    the caller asks cKDTree for them in its order); gaps inf and leader -1 where none (all
    of them without ``gaps``); ``tied``: some follower has two leaders at its smallest gap
    on the same side of its index (cKDTree's order decided which: the caller asks it).
    Minima and the tie test do not depend on the order the vehicles are visited in, so the
    results equal those of every pair within the reach (tests/test_metrics_exactness.py).
    """
    n = px.shape[0]
    order = np.argsort(px)
    xs = px[order]
    ys = py[order]
    g_long = np.full(n, np.inf)
    g_side = np.full(n, np.inf)
    leader = np.full(n, -1, np.int64)
    n_hi = np.zeros(n, np.int64)  # leaders at the smallest gap with an index above
    n_lo = np.zeros(n, np.int64)  # ... and below the follower's
    ov = np.empty((2, 2), np.int64)
    n_ov = 0
    r2 = reach_gap * reach_gap
    half_l_max = 0.0
    for i in range(n):
        half_l_max = max(half_l_max, 0.5 * length[i])
    slack = 1e-6  # m: the sorted coordinates and s differ by rounding on a ring
    half_ring = 0.5 * period * (1.0 + 1e-9) + slack
    reach_along = reach_gap * (1.0 + 1e-9) + slack
    for p in range(n):
        a = order[p]
        side = 0.5 * length[a] + half_l_max + slack  # beside a: |ds| below this
        n_fwd = 0
        for way in range(2):  # 0: ahead, 1: behind
            for step in range(1, n):
                q = p + step if way == 0 else p - step
                if not periodic and (q < 0 or q >= n):
                    break
                if way == 1 and step + n_fwd >= n:
                    break  # the scan ahead reached these already
                q = q % n
                along = xs[q] - xs[p] if way == 0 else xs[p] - xs[q]
                if along < 0:
                    along += period
                if periodic and along > half_ring:
                    break
                if way == 0:
                    bound = side
                    if gaps:
                        bound = max(bound, min(g_long[a] + side, reach_along))
                    if along > bound:
                        break
                    n_fwd = step
                elif along > side:
                    break
                b = order[q]
                ds = wrap_ds(s[b] - s[a], periodic, period)
                half_l = 0.5 * (length[a] + length[b])
                half_w = 0.5 * (width[a] + width[b])
                dd = abs(d[b] - d[a])
                if a < b and abs(ds) < half_l and dd < half_w:
                    if n_ov < 2:
                        ov[n_ov, 0] = a
                        ov[n_ov, 1] = b
                    n_ov += 1
                if not gaps or not tree_within(xs[p], ys[p], xs[q], ys[q], r2, periodic,
                                               period, box_y):
                    continue
                lat = dd < half_w + margin
                if ds > 0 and lat:
                    g = ds - half_l
                    if g < g_long[a]:
                        g_long[a] = g
                        leader[a] = b
                        n_hi[a] = 1 if b > a else 0
                        n_lo[a] = 0 if b > a else 1
                    elif g == g_long[a]:
                        if b > a:
                            n_hi[a] += 1
                            leader[a] = b
                        else:  # a leader above, if any, stays first
                            n_lo[a] += 1
                if abs(ds) < half_l and not lat:
                    gs = dd - half_w
                    if gs < g_side[a]:
                        g_side[a] = gs
    tied = False
    for a in range(n):
        if n_hi[a] >= 2 or (n_hi[a] == 0 and n_lo[a] >= 2):
            tied = True
    return ov[:min(n_ov, 2)].copy(), n_ov, g_long, g_side, leader, tied


@njit(cache=True)
def tree_points_2d(s, d, radius, period):
    """:func:`controllers.neighbours.tree_points` of the points (``s``, ``d``) (M,) m on a
    ring of ``period`` m: ``(px, py, box_y)``, ``px`` wrapped into [0, period) (numpy's
    ``mod``, a value rounded up to the period set to 0), ``py = d - min(d)`` and the box
    along d ``max(py) + 2 radius + 1`` (m)."""
    n = s.shape[0]
    px = np.empty(n)
    py = np.empty(n)
    lo = np.inf
    for i in range(n):
        x = s[i] % period
        px[i] = 0.0 if x >= period else x
        lo = min(lo, d[i])
    hi = -np.inf
    for i in range(n):
        py[i] = d[i] - lo
        hi = max(hi, py[i])
    return px, py, hi + 2.0 * radius + 1.0


# ------------------------------------------------------------------ capacity recorder
@njit(cache=True)
def capacity_tallies(s, s_front, v, is_cav, static, desired, has_desired, zones, sums, b, dt,
                     prev_row, same_rows, prev_front, prev_v, xs, harsh_after, harsh_mps2):
    """One step of :class:`~cosim.sim.recording.CapacityRecorder`.

    Adds to ``sums`` (Z, 3, bins) at bin ``b``, for each zone ``[z0, z1)`` of ``zones``
    (Z, 2) m that holds traffic: the time spent ``dt n`` (s), and over the vehicles in it
    with a known desired speed the distance travelled ``dt sum(v)`` and at the desired
    speeds ``dt sum(desired)`` (m). The vehicles seen in the previous step (``prev_row``
    (M,), -1: new; all at the same rows if ``same_rows``; their fronts ``prev_front`` m and
    speeds ``prev_v`` m/s there) give the crossings of the cross-sections ``xs`` (K,) m and,
    if ``harsh_after``, the harsh accelerations ``|dv / dt| > harsh_mps2``.

    Returns ``(sec, frac, harsh_cav, n_cav, harsh_hdv, n_hdv, cav_speed_sum, any_seen)``:
    per crossing (section order, then row order) its section and the fraction of the
    step at which the front passed; the harsh and moving CAV- and HDV-steps; the sum of
    the CAVs' speeds (m/s; obstacles excluded); whether any vehicle was seen before.
    """
    n = s.shape[0]
    buf_v = np.empty(n)
    buf_d = np.empty(n)
    for z in range(zones.shape[0]):
        z0 = zones[z, 0]
        z1 = zones[z, 1]
        n_in = 0
        m = 0
        for i in range(n):
            if s[i] >= z0 and s[i] < z1 and not static[i]:
                n_in += 1
                if has_desired and np.isfinite(desired[i]):
                    buf_v[m] = v[i]
                    buf_d[m] = desired[i]
                    m += 1
        if n_in:
            sums[z, 0, b] += dt * n_in
            sums[z, 1, b] += dt * np_sum(buf_v, m)
            sums[z, 2, b] += dt * np_sum(buf_d, m)
    # rows of the vehicles seen in both steps, and their rows then
    cur = np.empty(n, np.int64)
    prv = np.empty(n, np.int64)
    n_seen = 0
    for i in range(n):
        j = i if same_rows else prev_row[i]
        if j >= 0:
            cur[n_seen] = i
            prv[n_seen] = j
            n_seen += 1
    n_k = xs.shape[0]
    sec = np.empty(n_seen * n_k, np.int64)
    frac = np.empty(n_seen * n_k)
    n_hit = 0
    if n_seen:
        for k in range(n_k):
            x = xs[k]
            for c in range(n_seen):
                a = prev_front[prv[c]]
                f = s_front[cur[c]]
                if a < x and f >= x:
                    dx = f - a
                    sec[n_hit] = k
                    frac[n_hit] = (x - a) / (dx if dx >= 1e-9 or dx != dx else 1e-9)
                    n_hit += 1
    harsh_cav = 0
    n_cav = 0
    harsh_hdv = 0
    n_hdv = 0
    if harsh_after and n_seen:
        for c in range(n_seen):
            i = cur[c]
            if static[i]:
                continue
            acc = (v[i] - prev_v[prv[c]]) / dt
            harsh = abs(acc) > harsh_mps2
            if is_cav[i]:
                n_cav += 1
                harsh_cav += harsh
            else:
                n_hdv += 1
                harsh_hdv += harsh
    m = 0
    for i in range(n):
        if is_cav[i] and not static[i]:
            buf_v[m] = v[i]
            m += 1
    return (sec[:n_hit].copy(), frac[:n_hit].copy(), harsh_cav, n_cav, harsh_hdv, n_hdv,
            np_sum(buf_v, m), n_seen > 0)


# ------------------------------------------------------------------ jam recorder
@njit(cache=True)
def jam_step(t, v, is_static, s_front, prev_row, same_rows, t0_old, long_old, front_old,
             v_stop, long_s):
    """One step of :class:`~cosim.metrics.jams.JamRecorder` but its windows.

    Args: the step's speeds (M,) m/s, obstacle mask and fronts (M,) m; ``prev_row`` (M,):
    each vehicle's row in the previous step (-1: new; the same rows if ``same_rows``);
    the previous step's standstill starts ``t0_old`` (s, NaN: moving), long-standstill
    flags ``long_old`` and fronts ``front_old`` (m), each (M_old + 1,) with a sentinel
    last row (NaN, False, NaN) that new vehicles read; the standstill speed ``v_stop``
    m/s and the long-standstill threshold ``long_s`` s.

    Returns ``(t0, long_now, front_now, stopped, front_prev, longest, new_long)``: the
    standstill starts, long flags and fronts (M + 1,) with the sentinel row (what the next
    step reads), the standstill mask (M,), the fronts a step ago (M,) m, the longest
    standstill now (s; -inf if nobody stands still) and the rows whose standstill became
    long in this step.
    """
    n = v.shape[0]
    t0 = np.full(n + 1, np.nan)
    front_now = np.empty(n + 1)
    front_now[n] = np.nan
    long_now = np.zeros(n + 1, np.bool_)
    stopped = np.zeros(n, np.bool_)
    front_prev = np.empty(n)
    new_long = np.empty(n, np.int64)
    n_new = 0
    longest = -np.inf
    for i in range(n):
        j = i if same_rows else prev_row[i]
        if j < 0:
            j = t0_old.shape[0] - 1  # the sentinel row
        front_prev[i] = front_old[j]
        front_now[i] = s_front[i]
        if v[i] < v_stop and not is_static[i]:
            stopped[i] = True
            began = t0_old[j]
            if began != began:
                began = t
            t0[i] = began
            dur = t - began
            if dur > longest:
                longest = dur
            if dur > long_s:
                long_now[i] = True
                if not long_old[j]:
                    new_long[n_new] = i
                    n_new += 1
            elif long_old[j]:
                long_now[i] = True
    return t0, long_now, front_now, stopped, front_prev, longest, new_long[:n_new].copy()


@njit(cache=True)
def jam_windows(s_front, stopped, is_static, front_prev, xs, todo_cross, todo_wait,
                periodic, period, upstream_m, crossed, waiting):
    """The window test of :class:`~cosim.metrics.jams.JamRecorder` for one step: for each
    cross-section ``xs`` (K,) m still in ``todo_cross``, whether a front (not an obstacle's,
    seen a step ago at ``front_prev``) passed it (on a ring also across the seam); for each
    still in ``todo_wait``, whether a vehicle stands still within ``upstream_m`` m upstream
    of it. Written into ``crossed`` and ``waiting`` (K,) in place."""
    n = s_front.shape[0]
    for k in range(xs.shape[0]):
        x = xs[k]
        if todo_cross[k]:
            hit = False
            for i in range(n):
                prv = front_prev[i]
                if not np.isfinite(prv) or is_static[i]:
                    continue
                cur = s_front[i]
                if periodic and cur < prv - 0.5 * period:
                    cur = cur + period
                if (prv < x and cur >= x) or (
                        periodic and prv < x + period and cur >= x + period):
                    hit = True
                    break
            crossed[k] = hit
        if todo_wait[k]:
            w = False
            for i in range(n):
                if not stopped[i]:
                    continue
                up = x - s_front[i]
                if periodic:
                    up = up % period
                if up >= 0 and up <= upstream_m:
                    w = True
                    break
            waiting[k] = w


# ------------------------------------------------------------------ flock metrics (m = 2)
@njit(cache=True)
def dense_pairs(x0, x1, radius, periodic, period):
    """:func:`controllers.neighbours.neighbour_pairs_dense` in 2-d: the pairs (i < j) with
    ``sqrt(dx^2 + dy^2) < radius`` (``dx = x0[j] - x0[i]`` wrapped as numpy wraps it on a
    ring), (P, 2) int64 in row-major order. For small N (it tests every pair)."""
    n = x0.shape[0]
    out = np.empty((max(n * (n - 1) // 2, 1), 2), np.int64)
    cnt = 0
    for i in range(n):
        for j in range(i + 1, n):
            dx = x0[j] - x0[i]
            if periodic:
                dx = (dx + 0.5 * period) % period - 0.5 * period
            dy = x1[j] - x1[i]
            if math.sqrt(dx * dx + dy * dy) < radius:
                out[cnt, 0] = i
                out[cnt, 1] = j
                cnt += 1
    return out[:cnt].copy()


@njit(cache=True)
def sorted_pairs(pairs, n):
    """``pairs`` (P, 2) (i < j < n) in the order of the key ``i n + j`` (what
    :func:`controllers.neighbours.neighbour_pairs` returns)."""
    key = pairs[:, 0] * n + pairs[:, 1]
    key.sort()
    out = np.empty((key.shape[0], 2), np.int64)
    for k in range(key.shape[0]):
        out[k, 0] = key[k] // n
        out[k, 1] = key[k] % n
    return out


@njit(cache=True)
def components(pairs, n):
    """Connected components of the graph on ``n`` nodes with edges ``pairs`` (P, 2):
    ``(number, size of the largest)`` (union-find; the partition is the graph's, so both
    equal scipy's ``connected_components``)."""
    parent = np.arange(n)
    for k in range(pairs.shape[0]):
        a = pairs[k, 0]
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        b = pairs[k, 1]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a != b:
            parent[max(a, b)] = min(a, b)
    size = np.zeros(n, np.int64)
    n_comp = 0
    for i in range(n):
        a = i
        while parent[a] != a:
            a = parent[a]
        if size[a] == 0:
            n_comp += 1
        size[a] += 1
    largest = 0
    for i in range(n):
        largest = max(largest, size[i])
    return n_comp, largest


@njit(cache=True)
def nearest_distances(px, py, periodic, period, box_y):
    """Distance from each point to its nearest other point, (N,) m, as cKDTree's ``query``
    gives it for the tree's coordinates (``px``, ``py``; on a ring ``px`` in [0, period)
    and both axes wrapped as the tree's box ``period`` x ``box_y`` wraps them):
    ``sqrt(dx^2 + dy^2)``, inf for a single point. A scan outwards along ``px`` sorted,
    each way until the distance along it alone exceeds the best so far (or half the ring)."""
    n = px.shape[0]
    out = np.full(n, np.inf)
    order = np.argsort(px)
    xs = px[order]
    ys = py[order]
    hb = 0.5 * period
    hby = 0.5 * box_y
    for p in range(n):
        best2 = np.inf
        for way in range(2):
            for step in range(1, n):
                q = p + step if way == 0 else p - step
                if not periodic and (q < 0 or q >= n):
                    break
                q = q % n
                # the distance along px, one way round (it only grows)
                along = xs[q] - xs[p] if way == 0 else xs[p] - xs[q]
                if along < 0:
                    along += period
                if periodic and along > hb * (1.0 + 1e-9) + 1e-9:
                    break  # the other way round is shorter: the other scan's
                if along * along > best2 * (1.0 + 1e-9) + 1e-300:
                    break
                dx = xs[p] - xs[q]
                dy = ys[p] - ys[q]
                if periodic:
                    if dx < -hb:
                        dx = period + dx
                    elif dx > hb:
                        dx = dx - period
                    if dy < -hby:
                        dy = box_y + dy
                    elif dy > hby:
                        dy = dy - box_y
                d2 = dx * dx + dy * dy
                if d2 < best2:
                    best2 = d2
        out[order[p]] = math.sqrt(best2)
    return out


@njit(cache=True, inline="always")
def _column_means(a):
    """``a.mean(axis=0)`` of an (N, 2) array, N >= 1: numpy adds row after row."""
    n = a.shape[0]
    m0 = 0.0
    m1 = 0.0
    for i in range(n):
        m0 += a[i, 0]
        m1 += a[i, 1]
    return m0 / n, m1 / n


@njit(cache=True)
def flock_moments(q, p, pairs, d, periodic, period, nn):
    """The flock metrics of :mod:`cosim.metrics.flock` that are sums over agents or pairs,
    in one pass each, the same bits as its numpy functions: positions ``q`` and velocities
    ``p`` (N, 2), N >= 2, of C order; the proximity net ``pairs`` (P, 2); the lattice
    distance ``d`` m; nearest-neighbour distances ``nn`` (N,) m.

    Returns ``(velocity_mismatch m^2/s^2, mean unit velocity x, y, moving agents,
    dispersion m, deviation energy m^2, min nn m, mean nn m)``. numpy's reductions along
    axis 0 of an (N, 2) array add row after row; along a row of two it adds the two; a
    reduction of a 1-d array is :func:`np_sum`. The norm of the mean unit velocity is left
    to numpy (``np.linalg.norm`` of a 2-vector is a BLAS dot product)."""
    n = q.shape[0]
    # velocity_mismatch: mean over agents of ||p_i - mean(p)||^2
    c0, c1 = _column_means(p)
    buf = np.empty(max(n, pairs.shape[0]))
    for i in range(n):
        e0 = p[i, 0] - c0
        e1 = p[i, 1] - c1
        buf[i] = e0 * e0 + e1 * e1
    mismatch = np_sum(buf, n) / n
    # velocity_alignment: the mean of the unit velocities of the moving agents
    u0 = 0.0
    u1 = 0.0
    moving = 0
    for i in range(n):
        speed = math.sqrt(p[i, 0] * p[i, 0] + p[i, 1] * p[i, 1])
        if speed > 1e-12:
            u0 += p[i, 0] / speed
            u1 += p[i, 1] / speed
            moving += 1
    if moving:
        u0 /= moving
        u1 /= moving
    # dispersion: sqrt of the sum of the coordinates' sample variances (ddof 1)
    m0, m1 = _column_means(q)
    v0 = 0.0
    v1 = 0.0
    for i in range(n):
        e0 = q[i, 0] - m0
        e1 = q[i, 1] - m1
        v0 += e0 * e0
        v1 += e1 * e1
    v0 /= n - 1
    v1 /= n - 1
    dispersion = math.sqrt(v0 + v1)
    # deviation_energy: 1 / (|E| + 1) sum over directed edges of (||q_j - q_i|| - d)^2
    n_p = pairs.shape[0]
    energy = 0.0
    if n_p:
        for k in range(n_p):
            dq0 = q[pairs[k, 1], 0] - q[pairs[k, 0], 0]
            if periodic:
                dq0 = (dq0 + 0.5 * period) % period - 0.5 * period
            dq1 = q[pairs[k, 1], 1] - q[pairs[k, 0], 1]
            dev = math.sqrt(dq0 * dq0 + dq1 * dq1) - d
            buf[k] = dev * dev
        energy = 2.0 * np_sum(buf, n_p) / (2 * n_p + 1)
    nn_min = np.inf
    for i in range(n):
        nn_min = min(nn_min, nn[i])
    return mismatch, u0, u1, moving, dispersion, energy, nn_min, np_sum(nn, n) / n
