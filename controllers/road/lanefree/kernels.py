"""Compiled kernels of the lane-free law (numba, ``cache=True``): one loop per CAV over its
window of neighbours in road order, instead of (N, K) and (R, C, K) numpy temporaries.

Every kernel computes what the vectorised numpy code of the law computed before (commit of
issue 15; ``tests/test_exactness.py``), in the same floating-point order: the same
expressions evaluated left to right, scalars folded the same way (``P`` holds them, made by
:func:`pack`), ``min``/``max``/``argmin``/``argmax`` with numpy's first-index ties, and the
sums over a window in numpy's pairwise order (:func:`pairwise_sum`). Entries of a window
with no neighbour (``ds = inf``) never contribute, as before.

Shapes: N CAVs (rows 0..N-1 of the scene), M vehicles in all (CAVs first), K = 2 x the
law's ``window`` neighbours per CAV; positions m, speeds m/s, accelerations m/s^2.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from controllers.road import profile_kernels as PK

# ------------------------------------------------------------------ scalar parameters
#: Names of the scalars in ``P`` (see :func:`pack`), in order.
NAMES = (
    "time_gap_s", "time_gap_hdv_s", "standstill_gap_m", "kp", "kd", "ff_gain", "kp_hdv",
    "kd_hdv", "speed_gain", "approach_gain", "spacing_error_min_m", "spacing_error_max_m",
    "anticipation_s", "follow_margin_m", "lat_gain", "lat_damping", "lateral_clearance_m",
    "edge_margin_m", "side_buffer_m", "side_buffer_speed_s", "side_buffer_s",
    "cut_in_speed_margin_mps", "cut_in_gap_m", "repulsion_gain", "lookahead_s",
    "lookahead_min_m", "scan_margin_m", "scan_time_gap_s", "move_cost", "clear_gain",
    "clear_cap_m", "nudge_gain", "order_gain", "urgent_gain_mps", "queue_speed_mps",
    "bias_speed_low_mps", "coop_time_gap_s", "yield_decel_mps2", "comfort_decel_mps2",
    "congested_hysteresis_mps", "human_follow_margin_m", "mover_skips_followers",
    "row_approach_gain", "human_in_band_follows", "squeezed_moves_to_middle",
    # derived (folded as the numpy code folded them)
    "bias_span", "app_bt2", "app_mbt", "app_2b", "scan_2b", "lat_2a", "two_lc",
    "zipper_gap", "long_min", "long_max", "lat_speed_max", "em_bt2", "em_mbt", "em_2b",
    "shift_cav", "dt",
)
(TG, TGH, S0, KP, KD, KFF, KPH, KDH, KV, KA, EMIN, EMAX, ANT, FM, KY, CY, LC, EM, SB, SBV,
 SBT, CIM, CIG, RG, LAS, LAM, SCM, SCT, MC, CG, CC, NG, OG, UG, QS, BL, CT, YD, CB, CH, HFM,
 MSF, RAG, HIB, SQM, BSPAN,
 ABT2, AMBT, A2B, SC2B, L2A, TWOLC, ZG, LMIN, LMAX, VMAX, EBT2, EMBT, E2B, SHC, DT) = range(
    len(NAMES))


def pack(p, long_min: float, long_max: float, lat_speed_max: float, emergency_decel: float,
         dt: float) -> np.ndarray:
    """The scalars of the kernels (float64 array, order of :data:`NAMES`) for parameters
    ``p`` (:class:`~controllers.road.lanefree.LaneFreeParams`), the actuator limits and the
    step ``dt`` (s). Derived values are computed exactly as the numpy law wrote them."""
    vals = [float(getattr(p, name)) for name in NAMES[:NAMES.index("bias_span")]]
    b, tau = p.comfort_decel_mps2, 0.5
    e, t = emergency_decel, dt
    vals += [
        max(p.bias_speed_high_mps - p.bias_speed_low_mps, 1e-9),
        (b * tau) ** 2, -b * tau, 2 * b,
        2 * p.scan_decel_mps2,
        2 * p.a_lat_bound_mps2,
        2.0 * p.lateral_clearance_m,
        p.side_buffer_m + p.zipper_slack_m,
        long_min, long_max, lat_speed_max,
        (e * t) ** 2, -e * t, 2 * e,
        lat_speed_max * dt,
        dt,
    ]
    return np.array(vals, dtype=float)


#: A candidate band is free of a stopped obstacle ahead only this much beyond the lateral
#: gap at which the obstacle leads (``scan_margin_m``, as ``follow_margin_m``), m: a CAV
#: that reaches a band just clear of it would still follow it, standing behind the car
#: while it creeps the last centimetres sideways (a user's neck, a stopped car: 31.8 s).
STATIC_CLEAR_M = 0.15

#: A CAV stuck behind a stopped obstacle moves sideways in front of a vehicle behind it
#: slower than ZIPPER_MOVING_MPS with at least this bumper gap, m.
STUCK_GAP_M = 1.0

#: A slow CAV whose body reaches more than this over the edges of the road ahead (a strip
#: that ends, a narrowing) moves sideways in front of a CAV behind it as a stuck mover
#: does (:data:`STUCK_GAP_M`), m: else two CAVs behind it, one on each side and each
#: within the other's side buffer, hold it where it stands, and the one behind it waits
#: for it (a user's freeway with two on-ramps: a merging CAV stood for 200 s).
OUTSIDE_TOL_M = 0.05

#: A vehicle behind a mover in its target band goes first (zipper) only when faster than
#: this, m/s: at a standstill the one ahead goes, or both would wait for each other.
ZIPPER_MOVING_MPS = 1.0

#: A human driver slower than this, and turning slower than this (m/s), who overlaps a CAV
#: along the road but not across it, his centre ahead of the CAV's and his rear behind its
#: rear, is no leader of the CAV once it has stood (slower than this) for STANDOFF_S: a
#: standoff with SUMO's sublane leader rule (see ``interact``). (Not at once: a driver who
#: stops beside a CAV for a moment mostly goes on by himself.)
STANDOFF_MPS = 0.1
STANDOFF_S = 3.0


# ------------------------------------------------------------------ helpers
@njit(cache=True, inline="always")
def pairwise_sum(a, n):
    """``np.sum`` of ``a[:n]`` in numpy's order (pairwise, 8 accumulators; n <= 128)."""
    if n < 8:
        res = -0.0
        for i in range(n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[0], a[1], a[2], a[3]
    r4, r5, r6, r7 = a[4], a[5], a[6], a[7]
    i = 8
    stop = n - (n % 8)
    while i < stop:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[i]
        i += 1
    return res


@njit(cache=True, inline="always")
def _follow(P, g, v_j, a_j, j_cav, v, t_cav, t_hdv):
    """CACC (CAV leader) or ACC command, m/s^2; inf beyond the linear law's range."""
    if j_cav:
        T, kp, kd, kff = t_cav, P[KP], P[KD], P[KFF]
    else:
        T, kp, kd, kff = t_hdv, P[KPH], P[KDH], 0.0
    raw = g - P[S0] - T * v
    err = max(raw, P[EMIN])
    u = kp * err + kd * (v_j - v) + kff * min(max(a_j, P[LMIN]), P[LMAX])
    return u if raw <= P[EMAX] else np.inf


@njit(cache=True, inline="always")
def _approach(P, g, v_j, v, k_a):
    """Approach bound ``k_a (v_safe - v)``, m/s^2 (``k_a`` 1/s)."""
    g0 = g - P[S0]
    vj = max(v_j, 0.0)
    root = math.sqrt(max(P[ABT2] + vj * vj + P[A2B] * g0, 0.0))
    v_safe = P[AMBT] + root if g0 > 0 else 0.0
    v_safe = max(v_safe, min(vj, max(g0, 0.0)))
    return k_a * (v_safe - v)


# ------------------------------------------------------------------ neighbours
@njit(cache=True)
def window(s, d, n, order, rank, k_side, periodic, period):
    """Neighbours of each CAV in road order: ``j`` (N, K) rows, ``ds`` (N, K) m (wrapped on
    a ring; inf where there is none), ``dd`` (N, K) m; K = 2 ``k_side``."""
    m = s.shape[0]
    k2 = 2 * k_side
    j = np.empty((n, k2), np.int64)
    ds = np.empty((n, k2))
    dd = np.empty((n, k2))
    for i in range(n):
        r = rank[i]
        for q in range(k2):
            off = q - k_side if q < k_side else q - k_side + 1
            pos = r + off
            if not periodic:
                valid = 0 <= pos < m
                jj = order[min(max(pos, 0), m - 1)]
            else:
                valid = True
                if 2 * k_side >= m:
                    valid = (off > 0) or (off >= -(m - 1 - k_side))
                    valid = valid and abs(off) <= m - 1
                jj = order[pos % m]
            valid = valid and jj != i
            x = s[jj] - s[i]
            if periodic:
                x = (x + 0.5 * period) % period - 0.5 * period
            j[i, q] = jj
            ds[i, q] = x if valid else np.inf
            dd[i, q] = d[jj] - d[i]
    return j, ds, dd


@njit(cache=True)
def leader_gaps(s, d, length, width, rows, reach_m, periodic, period, lateral_margin_m, v,
                order, rank):
    """:func:`controllers.road.reference.leader_gaps` with ``v``: (gap (R,) m, v_leader (R,)
    m/s; inf / nan where none), visiting the vehicles ahead in the same blocks."""
    n, m = rows.shape[0], s.shape[0]
    gap = np.full(n, np.inf)
    v_leader = np.full(n, np.nan)
    if n == 0 or m < 2:
        return gap, v_leader
    max_ds = reach_m if not periodic else min(reach_m, 0.5 * period)
    half_l_max = 0.5 * np.max(length)
    for a in range(n):
        me = rows[a]
        r = rank[me]
        hl_me = 0.5 * length[me]
        k0, block = 1, 8
        while k0 < m:
            stop = min(k0 + block, m)
            last = np.inf
            for off in range(k0, stop):
                idx = r + off
                if not periodic and idx >= m:
                    x = np.inf
                    jj = order[0]
                else:
                    jj = order[idx % m]
                    x = s[jj] - s[me]
                    if periodic:
                        x = np.mod(x, period)
                last = x
                overlap = abs(d[jj] - d[me]) < 0.5 * (width[me] + width[jj]) + lateral_margin_m
                if x > 0 and x <= max_ds and overlap:
                    g = x - hl_me - 0.5 * length[jj]
                    if g < gap[a]:
                        gap[a] = g
                        v_leader[a] = v[jj]
            lower = last - hl_me - half_l_max
            if not (last <= max_ds and lower < gap[a]):
                break
            k0 += block
            block *= 2
    return gap, v_leader


# ------------------------------------------------------------------ lateral target
@njit(cache=True)
def plan(P, rows, frac, lo, hi, current, j, ds, s, d, v, length, width, is_cav, v_des,
         v_des_all, static_idx, periodic, period):
    """Best candidate (R,) m, its score gain over the current target (R,) m/s and whether
    the move is announced (R,) for the CAVs ``rows`` (see the law's ``_plan``)."""
    n_r = rows.shape[0]
    n_c = frac.shape[0]
    k2 = j.shape[1]
    best = np.empty(n_r)
    gain = np.empty(n_r)
    need = np.zeros(n_r, np.bool_)
    v_pass = np.empty(k2)
    reach = np.empty(k2)
    along = np.zeros(k2, np.bool_)
    half_w = np.empty(k2)
    eager = np.empty(k2)
    nudging = np.zeros(k2, np.bool_)
    keep = np.empty(k2, np.int64)  # the window entries that can change a score
    buf = np.zeros(k2)
    cand = np.empty(n_c)
    score = np.empty(n_c)
    offer = np.empty(n_c)
    blocked = np.zeros(n_c, np.bool_)
    for r in range(n_r):
        i = rows[r]
        w_i, l_i, v_i, d_i, vd = width[i], length[i], v[i], d[i], v_des[r]
        lo_r, hi_r = lo[r], hi[r]
        free = v_i > vd - 1.0
        n_keep = 0
        any_nudge = False
        for k in range(k2):
            x = ds[i, k]
            if not np.isfinite(x):
                continue
            jj = j[i, k]
            gap = x - 0.5 * (l_i + length[jj])
            v_j = v[jj]
            g0 = max(gap - P[S0], 0.0)
            vp = np.inf
            if x > 0:
                vp = min(v_j + g0 / P[SCT], math.sqrt(v_j * v_j + P[SC2B] * g0))
            al = abs(x) < 0.5 * (l_i + length[jj]) + P[SB]
            e = max(v_des_all[jj] - vd - 1.0, 0.0) if free else 0.0
            close = x < 0 and is_cav[jj] and (-gap < 2.0 * max(v_j, 5.0))
            nud = close and e > 0
            # offer = min(min over the band of v_pass, v_des): a v_pass >= v_des cannot
            # lower it; only entries that can change an offer, a clearance or a nudge count
            if not (vp < vd or al or nud):
                continue
            v_pass[k] = vp if vp < vd else np.inf
            reach[k] = 0.5 * (w_i + width[jj]) + P[SCM]
            along[k] = al
            half_w[k] = 0.5 * (w_i + width[jj])
            eager[k] = e
            nudging[k] = nud
            any_nudge = any_nudge or nud
            keep[n_keep] = k
            n_keep += 1
        span = max(hi_r - lo_r, 0.0)
        for c in range(n_c):
            cand[c] = lo_r + span * frac[c]
            blocked[c] = False
        # a band that ends at a stopped obstacle within the look-ahead offers nothing
        look = max(P[LAM], v_i * P[LAS])
        for q in range(static_idx.shape[0]):
            kk = static_idx[q]
            ds_k = s[kk] - s[i]
            if periodic:
                ds_k = np.mod(ds_k, period)
            g_k = ds_k - 0.5 * (l_i + length[kk])
            if ds_k > 0 and g_k < look:
                reach_k = 0.5 * (w_i + width[kk]) + P[SCM] + STATIC_CLEAR_M
                for c in range(n_c):
                    if abs(d[kk] - cand[c]) < reach_k:
                        blocked[c] = True
        rank_v = min(max((vd - P[BL]) / P[BSPAN], 0.0), 1.0)
        y_pref = lo_r + (hi_r - lo_r) * rank_v
        free_w = min(max((v_i / max(vd, 1.0) - 0.75) / 0.2, 0.0), 1.0)
        for c in range(n_c):
            y = cand[c]
            off = np.inf
            clear = np.inf
            for q in range(n_keep):
                k = keep[q]
                lat = abs(d[j[i, k]] - y)
                in_band = lat < reach[k]
                if in_band and v_pass[k] < off:
                    off = v_pass[k]
                if along[k]:
                    sg = lat - half_w[k]
                    if sg < clear:
                        clear = sg
                if any_nudge:
                    buf[k] = eager[k] if (in_band and nudging[k]) else 0.0
            off = min(off, vd)
            if blocked[c]:
                off = 0.0
            offer[c] = off
            clear = min(max(clear, -1.0), P[CC])
            nudge = 0.0
            if any_nudge:  # numpy's sum over the whole window (zeros elsewhere)
                nudge = pairwise_sum(buf, k2)
            score[c] = (off - P[MC] * abs(y - d_i)
                        + free_w * (P[CG] * clear - P[OG] * abs(y - y_pref))
                        - P[NG] * nudge)
        if any_nudge:
            for q in range(n_keep):
                buf[keep[q]] = 0.0
        k_best = 0
        for c in range(1, n_c):
            if score[c] > score[k_best]:
                k_best = c
        cur = d_i if np.isnan(current[r]) else current[r]
        k_cur = 0
        k_here = 0
        for c in range(1, n_c):
            if abs(cand[c] - cur) < abs(cand[k_cur] - cur):
                k_cur = c
            if abs(cand[c] - d_i) < abs(cand[k_here] - d_i):
                k_here = c
        best[r] = cand[k_best]
        gn = score[k_best] - score[k_cur]
        gain[r] = gn
        outside = (d_i < lo_r - 0.05) or (d_i > hi_r + 0.05)
        nd = (blocked[k_here] or outside) and gn > 0 and not blocked[k_best]
        # a move that pays in speed is announced (others yield) only if it pays more in
        # dense traffic, where every announced move makes two bands brake
        jam = min(max((0.95 - v_i / max(vd, 0.1)) / 0.2, 0.0), 1.0)
        nd = nd or ((offer[k_best] - offer[k_here] > max(P[UG], 0.3 * v_i) + P[CH] * jam)
                    and v_i > P[QS] and gn > 0)
        need[r] = nd
    return best, gain, need


# ------------------------------------------------------------------ interactions
@njit(cache=True)
def interact(P, j, ds, dd, s, d, v, v_lat, length, width, accel, is_cav, n, targets,
             urgent, held, stood_s, lead_gap, lead_v, v_des, edges, has_edges, static,
             evade_edges, k_a):
    """Everything of one step that needs the window, per CAV:

    * side bounds ``hi``, ``lo`` (N,) m (the law's ``_side``);
    * longitudinal command (N,) m/s^2 from the desired speed, the primary leader
      (``lead_gap``, ``lead_v``; approach gains ``k_a`` (N,) 1/s), the window leaders and
      the zipper (not the narrowing and not the yield, which the caller adds: ``min`` is
      order-free);
    * the yield requests ``ask`` (N, K) and their commands ``u_yield`` (N, K), already
      bounded below by ``-yield_decel_mps2`` (before the patience rule), and how many
      pairs asked before the zipper rule took some back (``n_asked``: the law applies its
      patience rule whenever one did);
    * lateral command (N,) m/s^2 (the law's ``_lateral``; ``edges`` (N, 2) m, the road
      edges of the target's look-ahead, used when ``has_edges``). The repulsion of the
      vehicles alongside never pushes a CAV towards a stopped obstacle (``static`` (M,)
      bool) ahead of it within :data:`BLOCK_REACH_S` of travel (at least
      :data:`BLOCK_REACH_M`) and less than twice the lateral clearance to the side: a CAV
      behind a stopped car, steering for the gap beside it, would be held against the car
      by the traffic passing on the other side (a user's neck with a stopped car: standing
      for minutes). A human driver alongside that drifts towards the CAV bounds it where it
      will be in :data:`EVADE_S`; a CAV already inside a human driver's clearance moves out
      of it (within ``evade_edges`` (N, 2) m and the other side's bound) instead of holding
      still: the band the law keeps clear beside an exit's strip for a human driver
      leaving is no wall to a CAV a human driver moves onto (a user's freeway: a driver at
      34.7 m/s moved onto a CAV held at that band's border). Squeezed between such a
      driver and another vehicle (both bounds in conflict), it moves to the middle of the
      two bounds instead of holding still. A CAV passing a slower human driver ahead of
      it who turns towards it (or is very close beside it) is at most a few m/s faster than
      him, fewer the closer he is (:data:`PASS_DV_PER_M`): were he to turn in, it could
      still slow down behind him. A CAV that has stood for :data:`STANDOFF_S` (``stood_s``
      (N,) s) does not follow a stopped, longer human driver beside it whose centre is
      ahead of its centre but whose rear is behind its rear (SUMO's driver waits for it).
      An announced mover still behind a stopped obstacle moves sideways in front of a
      vehicle behind it (a slow CAV whose body is outside the road ahead,
      :data:`OUTSIDE_TOL_M`, in front of a CAV behind it) that is slower than
      :data:`ZIPPER_MOVING_MPS` and at least :data:`STUCK_GAP_M` back (in a slow, dense
      file nobody is far enough back to yield, and the mover would wait for ever). A CAV
      slower than :data:`ZIPPER_MOVING_MPS` behind such a slow CAV outside the road ahead,
      with that CAV's target in its band, is asked to hold where it is (``ask``, at any
      gap; it would otherwise creep into the safety layer's buffer behind the mover).
    """
    k2 = j.shape[1]
    u_long = np.empty(n)
    u_lat = np.empty(n)
    hi_n = np.empty(n)
    lo_n = np.empty(n)
    ask = np.zeros((n, k2), np.bool_)
    u_yield = np.full((n, k2), np.inf)
    push = np.zeros(k2)
    n_asked = 0
    dt = P[DT]
    # slow CAVs whose body is outside the road ahead (a strip that ends): they must move
    must_move = np.zeros(n, np.bool_)
    if has_edges:
        for i in range(n):
            must_move[i] = v[i] < ZIPPER_MOVING_MPS and (
                d[i] - 0.5 * width[i] < edges[i, 0] - OUTSIDE_TOL_M
                or d[i] + 0.5 * width[i] > edges[i, 1] + OUTSIDE_TOL_M)
    for i in range(n):
        v_i, d_i, vl_i, l_i, w_i = v[i], d[i], v_lat[i], length[i], width[i]
        # one pass over the window: side bounds and repulsion (the law's _side), leaders,
        # yield requests and the zipper (its _longitudinal)
        hi = np.inf
        lo = -np.inf
        hi_human = False  # the bound on that side is a human driver's
        lo_human = False
        hi_trail = False  # the bound on that side is a vehicle behind it in its band
        lo_trail = False  # that could not stop behind it
        u = P[KV] * (v_des[i] - v_i)
        u_lead = np.inf
        if np.isfinite(lead_gap[i]):
            u_lead = _approach(P, lead_gap[i], lead_v[i], v_i, k_a[i])
        standoff = False  # its nearest leader is a stopped driver in a standoff (below)
        u_win = np.inf
        u_zip = np.inf
        mover_i = urgent[i]
        block_left = False  # a stopped obstacle ahead, close on this side
        block_right = False
        block_reach = max(BLOCK_REACH_M, BLOCK_REACH_S * v_i)
        stuck = False  # a mover still behind a stopped obstacle
        if mover_i:
            for k in range(k2):
                x = ds[i, k]
                if np.isfinite(x) and x > 0 and static[j[i, k]]:
                    jj = j[i, k]
                    if (x - 0.5 * (l_i + length[jj]) < block_reach
                            and abs(dd[i, k]) - 0.5 * (w_i + width[jj]) < P[FM]):
                        stuck = True
        # its body outside the road ahead (a strip that ends): it must move (in front of
        # CAVs behind it only: a human driver behind does not know it waits for him)
        outside = not stuck and must_move[i]
        for k in range(k2):
            x = ds[i, k]
            ddk = dd[i, k]
            if not np.isfinite(x):
                # np.sign(dd) * 0.0: the sign of a zero term, as the numpy sum saw it
                push[k] = np.sign(ddk) * 0.0
                continue
            jj = j[i, k]
            v_j = v[jj]
            j_cav = is_cav[jj]
            half_l = 0.5 * (l_i + length[jj])
            half_w = 0.5 * (w_i + width[jj])
            ahead = x > 0
            # -- side
            if ahead:
                closing_long, v_rear, v_follow, v_lead = v_i - v_j, v_i, v_i, v_j
            else:
                closing_long, v_rear, v_follow, v_lead = v_j - v_i, v_j, v_j, v_i
            buf = P[SB] + P[SBV] * v_rear + P[SBT] * max(closing_long, 0.0)
            al = abs(x) < half_l + buf
            g_pair = abs(x) - half_l - P[CIG]
            root = math.sqrt(max(P[EBT2] + v_lead * v_lead + P[E2B] * g_pair, 0.0))
            v_ok = 0.0 if g_pair < 0 else P[EMBT] + root
            cut = (v_follow > v_ok - P[CIM]) and (v_follow > 0.01)
            al = al or cut
            if ((stuck or (outside and j_cav)) and not ahead and v_j < ZIPPER_MOVING_MPS
                    and -x - half_l > STUCK_GAP_M):
                al = False  # a slow vehicle behind lets a stuck mover in front of it
            in_band = (P[HIB] > 0.0 and not j_cav and abs(ddk) < half_w
                       and abs(x) >= half_l)
            if in_band and (ahead or not cut):
                # (``human_in_band_follows``; off by default, see its doc) a human driver in
                # its band, one behind the other (the bodies overlap
                # across the road, not along it): a leader or a follower that can stop
                # behind it, not a driver at one side (the safety layer's rule 2); one that
                # could not stop keeps his bound (the CAV does not move further into his
                # band) but is no driver to evade. Before, his bound sat on the side of his
                # centre, replaced the bound of a CAV beside on that side and set off the
                # evasion below: on TUM's ring (50 % CAVs, 350 veh/km, TUM's margins) a CAV
                # 0.01 m outside its edge margin, a human driver 1.8 m behind it in its
                # band, was pushed in towards a CAV beside it, and the safety layer held it
                # every step for minutes (2.2 % of the CAV-steps clipped). (For a CAV in
                # its band the rule stays as it was: applied to CAVs too it changed the
                # timing of a weave on a user's freeway into a deadlock of two CAVs side by
                # side, each announced into the other's place, and a collision.)
                al = False
            shift = P[SHC] if j_cav else abs(v_lat[jj]) * dt
            if not j_cav:  # a human driver drifting towards it: where it will be
                toward = -v_lat[jj] if ddk > 0 else v_lat[jj]
                shift = max(shift, toward * EVADE_S)
            need = half_w + P[LC] + shift
            # behind it in its band (the bodies overlap across the road, not along it) and
            # unable to stop behind it: behind it whichever way it moves sideways; the
            # safety layer holds the CAV from moving towards him (rule 2), so the law does
            # not ask it to (below)
            trail = (not ahead and abs(ddk) < half_w and abs(x) >= half_l
                     and (cut or (g_pair < 0 and v_follow > 1e-9)))
            if al:
                if ddk >= 0:
                    if d[jj] - need < hi:
                        hi = d[jj] - need
                        hi_human = not j_cav and not in_band
                        hi_trail = trail
                else:
                    if d[jj] + need > lo:
                        lo = d[jj] + need
                        lo_human = not j_cav and not in_band
                        lo_trail = trail
            side_gap = abs(ddk) - half_w
            if static[jj] and x > 0 and x - half_l < block_reach and side_gap < P[TWOLC]:
                if ddk > 0:
                    block_left = True
                else:
                    block_right = True
            pk = 0.0
            if al and side_gap < P[TWOLC]:
                pk = P[RG] * (P[TWOLC] - side_gap) / P[TWOLC]
            push[k] = np.sign(ddk) * pk
            # -- leaders: overlapping now or within the anticipation horizon
            g = x - half_l
            lat_gap = abs(ddk) - half_w
            rel_vlat = v_lat[jj] - vl_i
            closing = -rel_vlat if ddk > 0 else rel_vlat
            lat_future = lat_gap - max(closing, 0.0) * P[ANT]
            is_leader = ahead and (min(lat_gap, lat_future) < P[FM])
            if (is_leader and not j_cav and g < 0 and lat_gap > 0
                    and stood_s[i] >= STANDOFF_S and v_j < STANDOFF_MPS
                    and abs(v_lat[jj]) < STANDOFF_MPS
                    and x < 0.5 * (length[jj] - l_i)):
                # a stopped human driver beside it, just ahead of its centre but not of its
                # back: SUMO's driver takes the CAV (its back ahead of his, in his sublane)
                # for his leader, at a negative gap, and waits for it; followed here, the
                # CAV would wait for him, both for good (TUM's ring, TUM's humans, 50 %
                # CAVs, 400 veh/km: a CAV 0.3 m beside a driver stood from 15 s to the end).
                # It goes on (the passing cap keeps it slow) and the driver follows it.
                is_leader = False
                if abs(g - lead_gap[i]) < 1e-6:
                    standoff = True
            if is_leader:
                u_f = _follow(P, g, v_j, accel[jj], j_cav, v_i, P[TG], P[TGH])
                u_f = min(u_f, _approach(P, g, v_j, v_i, k_a[i]))
                u_win = min(u_win, u_f)
            # -- passing a slower human driver who turns towards it (PASS_*)
            toward_i = -v_lat[jj] if ddk > 0 else v_lat[jj]
            if ((not j_cav) and ahead and not is_leader and lat_gap < PASS_GAP_M
                    and (toward_i > PASS_DRIFT_MPS or lat_gap < PASS_CLOSE_M)
                    and g < max(PASS_REACH_M, PASS_REACH_S * v_i)):
                v_cap = v_j + PASS_DV_PER_M * max(lat_gap, 0.0)
                if v_i > v_cap:
                    u_win = min(u_win, max((v_cap - v_i) / PASS_T_S, -P[CB]))
            # -- cooperation: a mover announced into this CAV's band from ahead, or a
            # held-up human driver next to it, asks for a gap
            if ahead:
                tgt = targets[jj] if jj < n else d[jj]
                moving = urgent[jj] if jj < n else False
                into = abs(tgt - d_i) < half_w + P[FM]
                not_yet = abs(ddk) >= half_w
                a_k = j_cav and moving and into and not_yet
                # (only from behind it: a CAV alongside that stopped would take the very
                # space the driver waits for; it goes on instead)
                held_k = ((not j_cav) and held[jj] and abs(ddk) < half_w + HELD_REACH_M
                          and not_yet and g > 0)
                a_k = a_k or held_k
                if a_k:
                    n_asked += 1
                    # a held-up human driver moves out only with SUMO's gap behind it
                    g_c = g - HELD_GAP_M if held_k else g
                    u_c = _follow(P, g_c, v_j, accel[jj], j_cav, v_i, P[CT], P[CT])
                    if not (j_cav and ((u_c < -P[YD]) or (g < P[ZG]))):
                        ask[i, k] = True
                        u_yield[i, k] = max(u_c, -P[YD])
                # a slow CAV behind a standing CAV that must move into its band (its body
                # over the road's edge ahead: a strip that ends) holds at any gap ahead of
                # the mover's tail (holding costs it nothing, and the zipper lets the
                # standing mover go first): creeping on into the gap that the mover needs,
                # it would take the safety layer's buffer, which then holds the mover off
                # its band (a user's freeway: both stood 460 s). (Not for every announced
                # mover: on a dense ring that is ``mover_skips_followers``'s question.)
                if (j_cav and jj < n and not ask[i, k] and g > 0 and must_move[jj]
                        and v_i < ZIPPER_MOVING_MPS and into and not_yet):
                    n_asked += 1
                    ask[i, k] = True
                    u_yield[i, k] = max(-v_i / dt, -P[YD])
            # -- zipper: an announced mover slots in behind the vehicles of its target band
            # (not behind a CAV standing that it already overlaps: it cannot get behind
            # that one, which may wait for it to pass, so it passes)
            if mover_i and not is_leader and not (g < 0 and v_j < ZIPPER_MOVING_MPS
                                                  and j_cav):
                in_target = abs(d[jj] - targets[i]) < half_w + P[FM]
                if in_target:
                    g_back = -x - half_l
                    passes = False
                    if x <= 0:
                        u_let = _follow(P, g_back, v_i, accel[i], True, v_j, P[CT], P[CT])
                        if not np.isfinite(u_let):
                            u_let = 0.0
                        # it goes first only if it is moving: a stopped vehicle
                        # behind passes nobody (the mover would wait for it forever);
                        # nor does one that follows the mover already (the mover is in
                        # its band: a CAV within the follow margin, a human driver within
                        # ``human_follow_margin_m``, the run's: SUMO's drivers follow
                        # whatever shares a sublane with them): in a dense file both would
                        # wait for the other and the whole file crawl (a ring at 400 veh/km
                        # with a 0.5 m standstill gap: 1.1 m/s for good, with CAVs alone
                        # and with human drivers)
                        # (``mover_skips_followers``; off by default, see its doc)
                        follows_mover = P[MSF] > 0 and (
                            abs(ddk) - half_w < (P[FM] if j_cav else P[HFM]))
                        passes = ((u_let < -P[YD]) or (g_back < P[ZG])) and (
                            v_j > ZIPPER_MOVING_MPS) and not follows_mover
                    if ahead or passes:
                        u_z = _follow(P, g, v_j, accel[jj], j_cav, v_i, P[CT], P[CT])
                        u_z = max(u_z, -P[CB])
                        u_zip = min(u_zip, u_z)
        hi_n[i] = hi
        lo_n[i] = lo
        if not standoff:
            u = min(u, u_lead)
        u = min(u, u_win)
        u = min(u, u_zip)
        u_long[i] = u
        # ---- lateral
        ul = P[KY] * (targets[i] - d_i) - P[CY] * vl_i
        if block_left or block_right:  # no push towards the stopped obstacle
            for k in range(k2):
                if (block_left and push[k] < 0) or (block_right and push[k] > 0):
                    push[k] = np.sign(push[k]) * 0.0
        ul -= pairwise_sum(push, k2)
        vmax = P[VMAX]
        a2 = P[L2A]
        v_hi_n = min(math.sqrt(a2 * max(hi - d_i, 0.0)) if hi > d_i else 0.0, vmax)
        v_lo_n = max(-math.sqrt(a2 * max(d_i - lo, 0.0)) if lo < d_i else 0.0, -vmax)
        v_hi_e = vmax
        v_lo_e = -vmax
        if has_edges:
            hi_e = edges[i, 1] - 0.5 * w_i - P[EM]
            lo_e = edges[i, 0] + 0.5 * w_i + P[EM]
            v_hi_e = min(max(np.sign(hi_e - d_i) * math.sqrt(a2 * abs(hi_e - d_i)), -vmax),
                         vmax)
            v_lo_e = min(max(-np.sign(d_i - lo_e) * math.sqrt(a2 * abs(d_i - lo_e)), -vmax),
                         vmax)
            v_lo_e = min(v_lo_e, v_hi_e)
        # inside a human driver's clearance (it moved towards the CAV): move out of it,
        # within the edges it may evade in and the other side's bound
        if (hi_human and hi < d_i) or (lo_human and lo > d_i):
            hi_p = evade_edges[i, 1] - 0.5 * w_i - P[EM]
            lo_p = evade_edges[i, 0] + 0.5 * w_i + P[EM]
            v_hi_p = min(max(np.sign(hi_p - d_i) * math.sqrt(a2 * abs(hi_p - d_i)), -vmax),
                         vmax)
            v_lo_p = min(min(max(-np.sign(d_i - lo_p) * math.sqrt(a2 * abs(d_i - lo_p)),
                                 -vmax), vmax), v_hi_p)
            if hi_human and hi < d_i:
                v_hi_n = max(-min(math.sqrt(a2 * (d_i - hi)), vmax), v_lo_p)
                v_lo_e = min(v_lo_e, v_lo_p)
                if hi_trail:
                    # away from a driver behind it in its band who could not stop, never
                    # towards him (TUM's ring, TUM's humans, 10 % CAVs, 400 veh/km: CAVs
                    # at the edge, drivers 0.3 m off their centre 0-1 m behind them; the
                    # edge margin asked them in towards the driver every step and the
                    # safety layer held them, 10 % of the CAV-steps)
                    v_hi_n = min(v_hi_n, 0.0)
            if lo_human and lo > d_i:
                v_lo_n = min(min(math.sqrt(a2 * (lo - d_i)), vmax), v_hi_p)
                v_hi_e = max(v_hi_e, v_hi_p)
                if lo_trail:
                    v_lo_n = max(v_lo_n, 0.0)
        want = vl_i + ul * dt
        v_next = min(max(min(max(want, v_lo_e), v_hi_e), v_lo_n), v_hi_n)
        if v_lo_n > v_hi_n:
            v_next = 0.0
            in_hi = hi_human and hi < d_i
            in_lo = lo_human and lo > d_i
            # (not for a driver behind it in its band: he does not drift onto its side,
            # and the middle would be towards him or deep into the other side's bound)
            if (P[SQM] > 0.0 and in_hi != in_lo and not (in_hi and hi_trail)
                    and not (in_lo and lo_trail)):
                # squeezed between a human driver who came too close and another
                # vehicle: the middle of the two bounds (held still, it was touched by the
                # driver drifting on: a width drop, 60 % CAVs, a CAV between a CAV and a
                # driver overtaking it at 0.14 m; ``squeezed_moves_to_middle``)
                mid = 0.5 * (lo + hi)
                v_next = min(max(np.sign(mid - d_i) * math.sqrt(a2 * abs(mid - d_i)),
                                 v_lo_e), v_hi_e)
        u_lat[i] = (v_next - vl_i) / dt
    return u_long, hi_n, lo_n, u_lat, ask, u_yield, n_asked


@njit(cache=True)
def _behind_static(P, i, s, d, v, length, width, static_idx, periodic, period):
    """Whether CAV ``i`` has a stopped obstacle ahead within :data:`BLOCK_REACH_S` of travel
    (at least :data:`BLOCK_REACH_M`) that it would still follow: lateral gap below
    ``follow_margin_m``. Near its target it has not arrived then: a CAV within half its
    width of a band beside a stopped car, but not yet clear of it, would otherwise drop its
    announced move and wait, unannounced, for a gap in the traffic passing beside the car
    (a user's neck, a stopped car: 32 s)."""
    reach = max(BLOCK_REACH_M, BLOCK_REACH_S * v[i])
    for q in range(static_idx.shape[0]):
        kk = static_idx[q]
        ds_k = s[kk] - s[i]
        if periodic:
            ds_k = np.mod(ds_k, period)
        gap = ds_k - 0.5 * (length[i] + length[kk])
        lat_gap = abs(d[kk] - d[i]) - 0.5 * (width[i] + width[kk])
        if ds_k > 0 and gap < reach and lat_gap < P[FM]:
            return True
    return False


# ------------------------------------------------------------------ one step
@njit(cache=True)
def linspace01(num):
    """``np.linspace(0.0, 1.0, num)``, the same numbers: ``i * (1 / (num - 1))``, last 1."""
    out = np.empty(num)
    step = 1.0 / (num - 1)
    for i in range(num):
        out[i] = i * step
    out[num - 1] = 1.0
    return out


#: A held-up human driver (see the law's ``_held``) is given a gap by the CAVs behind it
#: whose centre is within this of its side (the band it merges into, not the one beyond),
#: m, and the gap they keep behind it is larger by SUMO's ``minGap`` (2.5 m) plus 0.5 m:
#: SUMO's driver changes its lateral position only with that gap to its follower there.
HELD_REACH_M = 1.0
HELD_GAP_M = 3.0

#: A human driver alongside that drifts towards a CAV is given the clearance it will have
#: taken within this time (its lateral speed towards the CAV times it), s.
EVADE_S = 1.0

#: The repulsion does not push a CAV towards a stopped obstacle ahead within this time of
#: travel (s), or this distance (m) when slower (bumper to bumper).
BLOCK_REACH_S = 3.0
BLOCK_REACH_M = 15.0

#: A congested CAV's target within this of a row is not pulled to it, m.
ROW_SLACK_M = 0.5


#: A CAV passing a slower human driver ahead of it, less than PASS_GAP_M beside its body
#: and within PASS_REACH_S of travel (at least PASS_REACH_M) of his rear, while he turns
#: towards it faster than PASS_DRIFT_MPS (or at any drift closer than PASS_CLOSE_M), is
#: at most PASS_DV_PER_M times the lateral gap faster than he is: a driver who turns in at
#: about 1 m/s is in its band after "gap / (1 m/s)" s, and the CAV sheds that excess at
#: 5 m/s^2 in that time (it brakes over PASS_T_S s, at most at ``comfort_decel_mps2``).
#: Without it a CAV closed up at 12 m/s beside a driver at 4 m/s who turned into it at the
#: taper of a width drop (60 % CAVs: CAV collisions on 3 of 15 seeds). Units: m, m/s, m,
#: 1/s, m, s, s.
PASS_GAP_M = 1.0
PASS_DRIFT_MPS = 0.05
PASS_CLOSE_M = 0.3
PASS_DV_PER_M = 5.0
PASS_REACH_M = 10.0
PASS_REACH_S = 1.0
PASS_T_S = 1.0


@njit(cache=True)
def _pull_to_rows(P, target, urgent, s, d, v, v_des, length, width, lo, hi, n, static_idx,
                  periodic, period, row_pull, k_a, between):
    """Rows in dense traffic (in place on ``target`` (N,) m): as a CAV's speed falls from
    95 % to 75 % of its desired speed, its lateral target is pulled, by up to ``row_pull``
    (0..1) of the way, to the nearest of the rows that fit across the road ahead: as many
    as the widest vehicle present plus ``clearance`` (m) fit between the edges, spread
    evenly (the rows come from the vehicles' widths and the road, not from slots). A CAV
    whose move is announced (leaving a blocked band) is not pulled, nor one with a stopped
    obstacle ahead within the look-ahead (the free part of the road is no whole number of
    rows: the planner's offers and the zipper arrange the merge).

    With ``row_approach_gain`` > 0 it also marks, in place, a congested CAV within
    ``ROW_SLACK_M`` of a row with that approach gain in ``k_a`` (N,) 1/s, and one that is
    not in ``between`` (N,) bool (the caller keeps the gain only where no CAV in the window
    is between rows)."""
    if n == 0:
        return
    w_max = 0.0
    for i in range(width.shape[0]):
        w_max = max(w_max, width[i])
    pitch = w_max + P[LC]
    for i in range(n):
        if urgent[i] or np.isnan(target[i]):
            continue
        ratio = v[i] / max(v_des[i], 0.1)
        congested = min(max((0.95 - ratio) / 0.2, 0.0), 1.0)
        if congested <= 0.0:
            continue
        # centres of the widest vehicle that fit inside the road ahead
        half_extra = 0.5 * (w_max - width[i])
        lo_w = lo[i] + half_extra
        hi_w = hi[i] - half_extra
        if hi_w <= lo_w:
            continue
        n_rows = int(math.floor((hi_w - lo_w) / pitch)) + 1
        if n_rows < 2:
            nearest = 0.5 * (lo_w + hi_w)
        else:
            step = (hi_w - lo_w) / (n_rows - 1)
            k = min(max(round((target[i] - lo_w) / step), 0), n_rows - 1)
            nearest = lo_w + k * step
        look = max(P[LAM], v[i] * P[LAS])
        free_row = True
        for q in range(static_idx.shape[0]):
            kk = static_idx[q]
            ds_k = s[kk] - s[i]
            if periodic:
                ds_k = np.mod(ds_k, period)
            if ds_k > 0 and ds_k - 0.5 * (length[i] + length[kk]) < look:
                free_row = False  # merging past an obstacle: no rows (they would
                # hold the free part to whole rows)
        # ``row_approach_gain``: a CAV about in a row follows with that approach gain
        if free_row and P[RAG] > 0:
            k_d = 0
            if n_rows >= 2:
                k_d = min(max(round((d[i] - lo_w) / step), 0), n_rows - 1)
                in_row = abs(lo_w + k_d * step - d[i]) <= ROW_SLACK_M
            else:
                in_row = abs(nearest - d[i]) <= ROW_SLACK_M
            if in_row:
                k_a[i] = P[RAG]
            else:
                between[i] = True
        # a CAV about in a row stays where it is (moving a whole ordered flock by a few
        # decimetres costs more than it gives); one between two rows is pulled
        if free_row and abs(nearest - target[i]) > ROW_SLACK_M:
            target[i] += row_pull * congested * (nearest - target[i])


@njit(cache=True)
def law_step(P, s, d, v, v_lat, length, width, accel, is_cav, n, order, k_side, periodic,
             period, target0, urgent0, due0, fixed, edges_ahead, evade_ahead, loop_edges,
             has_loop_edges,
             v_des, static_idx, held, stood_s, candidate_step_m, hysteresis_mps,
             queue_hysteresis,
             congested_hysteresis, row_pull, lat_max, reach_lead):
    """The law's step after its inputs (see the law's ``compute``): the road edges of the
    target's look-ahead (``edges_ahead``, never wider than ``loop_edges``; ``evade_ahead``
    the same a CAV may evade a human driver within), the neighbour
    window, the lateral targets of the CAVs whose turn it is (``due0``), the primary
    leaders, the window terms and the command clipped to the actuator box.

    Returns (u (N, 2), u_long unclipped (N,), hi_n, lo_n (N,) side bounds, j (N, K),
    ask, u_yield (N, K), n_asked, target (N,), urgent (N,), target changes, the edges used
    (N, 2)).
    """
    # lowest and highest lateral centre inside the road ahead
    edges = np.empty((n, 2))
    evade = np.empty((n, 2))  # the same for evading a human driver (``evade_ahead``)
    lo = np.empty(n)
    hi = np.empty(n)
    for i in range(n):
        e0, e1 = edges_ahead[i, 0], edges_ahead[i, 1]
        f0, f1 = evade_ahead[i, 0], evade_ahead[i, 1]
        if has_loop_edges:
            e0 = max(e0, loop_edges[i, 0])
            e1 = min(e1, loop_edges[i, 1])
            f0 = max(f0, loop_edges[i, 0])
            f1 = min(f1, loop_edges[i, 1])
        edges[i, 0] = e0
        edges[i, 1] = e1
        evade[i, 0] = f0
        evade[i, 1] = f1
        lo[i] = e0 + 0.5 * width[i] + P[EM]
        hi[i] = e1 - 0.5 * width[i] - P[EM]
    m = s.shape[0]
    rank = np.empty(m, np.int64)
    for q in range(m):
        rank[order[q]] = q
    j, ds, dd = window(s, d, n, order, rank, k_side, periodic, period)
    target = target0.copy()
    urgent = urgent0.copy()
    due = due0.copy()
    if fixed:  # rows (or lanes) fixed where each CAV entered
        for i in range(n):
            if np.isnan(target[i]):
                target[i] = d[i]
            due[i] = False
    n_due = 0
    for i in range(n):
        if due[i]:
            n_due += 1
    n_changes = 0
    if n_due:
        rows = np.empty(n_due, np.int64)
        q = 0
        for i in range(n):
            if due[i]:
                rows[q] = i
                q += 1
        lo_r = lo[rows]
        hi_r = hi[rows]
        widest = -np.inf
        for r in range(n_due):
            widest = max(widest, hi_r[r] - lo_r[r])
        n_c = max(2, int(np.ceil(widest / candidate_step_m)) + 1)
        frac = linspace01(n_c)
        v_des_all = np.empty(m)
        v_des_all[:n] = v_des
        v_des_all[n:] = v[n:]
        best, gain, need = plan(P, rows, frac, lo_r, hi_r, target[rows], j, ds, s, d, v,
                                length, width, is_cav, v_des[rows], v_des_all, static_idx,
                                periodic, period)
        for r in range(n_due):
            i = rows[r]
            # in dense traffic lateral moves do not pay (each one makes the followers in
            # both bands brake): the bar rises from hysteresis_mps at 95 % of the desired
            # speed to hysteresis_mps + congested_hysteresis at 75 %, and further in a
            # slow queue
            ratio = v[i] / max(v_des[i], 0.1)
            congested = min(max((0.95 - ratio) / 0.2, 0.0), 1.0)
            bar = (hysteresis_mps + congested_hysteresis * congested
                   + queue_hysteresis * max(P[QS] - v[i], 0.0))
            was_nan = np.isnan(target[i])
            changed = was_nan or gain[r] > bar or need[r]
            if changed:
                if not was_nan:
                    n_changes += 1
                target[i] = best[r]
                urgent[i] = need[r]
    k_a = np.full(n, P[KA])
    if not fixed and row_pull > 0:
        between = np.zeros(n, np.bool_)
        _pull_to_rows(P, target, urgent, s, d, v, v_des, length, width, lo, hi, n,
                      static_idx, periodic, period, row_pull, k_a, between)
        # the stable gain only where the window is in rows: the waves of the others are
        # what lets a CAV between rows find a gap
        for i in range(n):
            if k_a[i] != P[KA]:
                for k in range(j.shape[1]):
                    jj = j[i, k]
                    if np.isfinite(ds[i, k]) and jj < n and between[jj]:
                        k_a[i] = P[KA]
                        break
    for i in range(n):
        # a target outside the road ahead (narrowing) is pulled inside at once
        target[i] = min(max(target[i], lo[i]), max(lo[i], hi[i]))
        arrived = (abs(target[i] - d[i]) < 0.5 * width[i]) and (d[i] >= lo[i] - 0.05) and (
            d[i] <= hi[i] + 0.05)  # and inside the road ahead
        if arrived and urgent[i] and static_idx.shape[0] and _behind_static(
                P, i, s, d, v, length, width, static_idx, periodic, period):
            arrived = False  # still behind the stopped car: the move stays announced
        if arrived:
            urgent[i] = False
    lead_gap, lead_v = leader_gaps(s, d, length, width, np.arange(n), reach_lead, periodic,
                                   period, P[FM], v, order, rank)
    static = np.zeros(m, np.bool_)
    for q in range(static_idx.shape[0]):
        static[static_idx[q]] = True
    u_long, hi_n, lo_n, u_lat, ask, u_yield, n_asked = interact(
        P, j, ds, dd, s, d, v, v_lat, length, width, accel, is_cav, n, target, urgent, held,
        stood_s, lead_gap, lead_v, v_des, edges, True, static, evade, k_a)
    u = np.empty((n, 2))
    for i in range(n):
        u[i, 0] = min(max(u_long[i], P[LMIN]), P[LMAX])
        u[i, 1] = min(max(u_lat[i], -lat_max), lat_max)
    return u, u_long, hi_n, lo_n, j, ask, u_yield, n_asked, target, urgent, n_changes, edges


# ------------------------------------------------------------------ narrowing
@njit(cache=True)
def narrowing_bound(P, s, d, v, width, length, n, s0, right, left, periodic, period, hi_n,
                    lo_n, look_min, look_s, half_lat_speed, quarter_a_lat):
    """The law's ``_narrowing``: approach bound (N,) m/s^2 to the start of the first road
    piece ahead (``s0``, ``right``, ``left`` (K,) m; within ``max(look_min, v look_s)``)
    whose edges exclude the CAV's body at its lateral position by more than it can still
    move sideways before it gets there (``half_lat_speed t`` and ``quarter_a_lat t^2``, and
    the room to its side bounds ``hi_n``, ``lo_n`` (N,) m); inf if none. Also whether any
    CAV has such a piece."""
    out = np.full(n, np.inf)
    any_wall = False
    win = np.empty((PK._MAX_WINDOWS, 2), dtype=np.int64)
    for i in range(n):
        hw = 0.5 * width[i] + 0.1
        look = max(look_min, v[i] * look_s)
        v1 = max(v[i], 1.0)
        best = np.inf
        # only the pieces that can start within (0, look) ahead (the same test on each)
        for w in range(PK.ahead_windows(s0, s[i], look, periodic, period, win)):
            for k in range(win[w, 0], win[w, 1]):
                ds = s0[k] - s[i]
                if periodic:
                    ds = ds % period
                need = max(right[k] - (d[i] - hw), (d[i] + hw) - left[k])
                t = max(ds, 0.0) / v1
                can = min(half_lat_speed * t, quarter_a_lat * (t * t))
                room = hi_n[i] - d[i] if right[k] > d[i] - hw else d[i] - lo_n[i]
                can = min(can, max(room, 0.0) + 0.1)
                if ds > 0 and ds < look and need > can:
                    any_wall = True
                    best = min(best, ds)
        g = best - 0.5 * length[i]
        if np.isfinite(g):
            out[i] = _approach(P, g, 0.0, v[i], P[KA])
    return out, any_wall


# ------------------------------------------------------------------ the law's memory
@njit(cache=True)
def recall(fresh, slots, mem_target, mem_urgent, mem_phase, mem_u, phase_now):
    """What the law remembers of its N CAVs (memory slots ``slots``; ``fresh``: no memory):
    lateral targets (NaN: none), announced moves, whether each re-chooses its target this
    step (no target, or its staggered phase is ``phase_now``) and the last longitudinal
    command (0 m/s^2 when fresh): ``(target, urgent, due, u_prev)`` (N,), as
    ``np.where``/``&``/``isnan``/``==`` gave them."""
    n = slots.shape[0]
    target = np.empty(n)
    urgent = np.empty(n, np.bool_)
    due = np.empty(n, np.bool_)
    u_prev = np.empty(n)
    for i in range(n):
        k = slots[i]
        if fresh[i]:
            target[i] = np.nan
            urgent[i] = False
            u_prev[i] = 0.0
        else:
            target[i] = mem_target[k]
            urgent[i] = mem_urgent[k]
            u_prev[i] = mem_u[k]
        due[i] = np.isnan(target[i]) or mem_phase[k] == phase_now
    return target, urgent, due, u_prev


@njit(cache=True)
def remember(slots, target, urgent, u, calls, mem_target, mem_urgent, mem_u, mem_last):
    """Store the step's lateral targets, announced moves and longitudinal commands
    (``u[:, 0]``) in the CAVs' memory slots, marked with the call ``calls``."""
    for i in range(slots.shape[0]):
        k = slots[i]
        mem_target[k] = target[i]
        mem_urgent[k] = urgent[i]
        mem_u[k] = u[i, 0]
        mem_last[k] = calls
