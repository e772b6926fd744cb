"""Traffic metrics of a road run, accumulated online from per-step vehicle arrays.

Definitions (units in names):

* **Edie's generalised flow, density and speed** (L. C. Edie, "Discussion of
  traffic stream measurements and definitions", 1963) over a space-time
  region of length ``X`` (m) and duration ``T`` (s): with total distance
  travelled ``TTD`` (m) and total time spent ``TTS`` (s) inside it,
  ``q = TTD / (X T)`` (veh/s -> veh/h), ``k = TTS / (X T)`` (veh/m -> veh/km),
  ``v = TTD / TTS`` (space-mean speed, m/s).
* **Cross-section flow**: vehicles whose front passes ``x`` per hour, as an
  induction loop counts them (SUMO E1 counts a vehicle when its front enters).
* **Gaps**: bumper-to-bumper longitudinal gap to the nearest vehicle ahead
  that overlaps laterally; side clearance to the nearest vehicle beside that
  overlaps longitudinally; time headway = gap / own speed.
* **Time to collision** (Hayward, "Near-miss determination through use of a scale of
  danger", Highway Research Record 384, 1972): ``TTC = gap / (v - v_leader)`` to the
  leader above (the laterally overlapping vehicle ahead) while closing in
  (``v > v_leader``), otherwise infinite: the car-following TTC of a same-lane pair,
  with our lateral-overlap leader in place of the lane; the summary keeps its minimum
  over all followers (``min_ttc_s``) and over CAV followers (``min_cav_ttc_s``). Exposure
  to TTC below a
  threshold ``TTC*`` (s) over the measured vehicle-steps, after Minderhoud & Bovy,
  "Extended time-to-collision measures for road traffic safety assessment", Accident
  Analysis & Prevention 33(1), 2001: **TET** (time exposed, vehicle-s: the time spent
  with ``0 <= TTC <= TTC*``) and **TIT** (time integrated, vehicle-s^2: the sum of
  ``(TTC* - TTC) dt`` over those steps). ``TTC* = 1.5 s`` by default, the maximum TTC
  of a conflict in FHWA's Surrogate Safety Assessment Model (Gettman et al.,
  FHWA-HRT-08-051, 2008); ``outputs.ttc_threshold_s`` sets it.
* **Speed shortfall**: the mean of ``v_des - v`` over the vehicle-steps in the zone
  after warm-up, per kind (CAVs, human drivers), m/s: how far traffic falls short of
  what its drivers want (0: everybody at the desired speed).
* **Boundary violations**: vehicle-steps with any part of the body outside
  the road edges, distinct vehicles, worst excursion (m).
* **Flow drift** (``flow_drift``): the relative difference of the mean Edie flow of the
  second and the first half of the measured intervals (the middle one left out when
  their number is odd), ``(q2 - q1) / ((q1 + q2) / 2)``; ``stationary`` when
  ``|flow_drift| < 2 %`` (:mod:`cosim.metrics.capacity` says why this form). NaN and not
  stationary with fewer than two intervals.
* **Collisions**: SUMO's own list (``simulation.getCollisions``) and a
  geometric rectangle-overlap check; a collision event is a pair that starts
  to overlap; split into CAV-involved and HDV-only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from controllers.neighbours import tree_points
from cosim.metrics.capacity import interval_drift, is_stationary
from cosim.metrics.jams import align


@dataclass
class StepState:
    """All vehicles on the main road at one step (M of them), SI units."""

    t: float
    ids: list
    s: np.ndarray  # centre position along the main route, m
    s_front: np.ndarray  # front bumper, m
    d: np.ndarray  # lateral centre offset, m
    v: np.ndarray  # longitudinal speed, m/s
    v_lat: np.ndarray  # lateral speed, m/s
    length: np.ndarray
    width: np.ndarray
    is_cav: np.ndarray  # bool
    edge_right: np.ndarray  # lateral road edges at each vehicle, m
    edge_left: np.ndarray
    is_static: np.ndarray | None = None  # bool: a stopped obstacle (collisions only)
    desired: np.ndarray | None = None  # desired speed, m/s (NaN: unknown)


GAP_REACH_M = 150.0  # reach of the leader and side search, m (distance in (s, d))


def overlapping_pairs(st: StepState, period: float | None) -> np.ndarray:
    """Pairs (i < j) of vehicles whose rectangles overlap (strictly), (P, 2).

    The candidates are the pairs within ``hypot(max length, max width)`` (m) of each
    other, as scipy's cKDTree finds them (:func:`_pairs_within`, a sweep along ``s``).
    With two or more overlaps the pairs come from the tree itself
    (:func:`_overlapping_pairs_tree`), in its order, which the collision log keeps."""
    if len(st.s) < 2:
        return np.empty((0, 2), dtype=np.int64)
    if not _fast_ok(st):
        return _overlapping_pairs_tree(st, period)
    reach = float(np.hypot(st.length.max(), st.width.max()))
    px, py, box_y = _points(st, reach, period)
    cand = _pairs_within(px, py, reach, period is not None, _period(period), box_y)
    pairs = _overlaps(cand, st.s, st.d, st.length, st.width, period is not None,
                      _period(period))
    if len(pairs) >= 2:
        return _overlapping_pairs_tree(st, period)
    return pairs


def gaps(st: StepState, period: float | None, lateral_overlap_margin_m: float = 0.0):
    """Per-vehicle longitudinal gap to the leader, side clearance, (M,) m each (inf if none)."""
    g_long, g_side, _ = gaps_and_leaders(st, period, lateral_overlap_margin_m)
    return g_long, g_side


def gaps_and_leaders(
    st: StepState, period: float | None, lateral_overlap_margin_m: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`gaps` plus each vehicle's leader: (g_long, g_side, leader), (M,) each.

    ``leader[i]`` is the index of the laterally overlapping vehicle ahead with the
    smallest bumper gap (the one ``g_long[i]`` is measured to), -1 if none within
    the 150 m reach.

    The pairs within the reach are those scipy's cKDTree finds (:func:`_pairs_within`).
    Of two leaders at the same gap, one with a higher index than the follower wins; which
    of several such (or, without one, of several lower ones) depends on the tree's order:
    then the tree decides (:func:`_gaps_and_leaders_tree`)."""
    n = len(st.s)
    if n < 2 or not _fast_ok(st):
        return _gaps_and_leaders_tree(st, period, lateral_overlap_margin_m)
    reach = GAP_REACH_M
    px, py, box_y = _points(st, reach, period)
    cand = _pairs_within(px, py, reach, period is not None, _period(period), box_y)
    g_long, g_side, leader, tied = _gaps_kernel(
        cand, st.s, st.d, st.length, st.width, period is not None, _period(period),
        float(lateral_overlap_margin_m),
    )
    if tied:
        return _gaps_and_leaders_tree(st, period, lateral_overlap_margin_m)
    return g_long, g_side, leader


def _fast_ok(st: StepState) -> bool:
    """True when the compiled path applies: float64 arrays of finite values (otherwise
    the tree path keeps numpy's NaN and dtype rules)."""
    arrs = (st.s, st.d, st.length, st.width)
    return all(
        isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == 1 for a in arrs
    ) and _all_finite(st.s, st.d, st.length, st.width)


@njit(cache=True)
def _all_finite(s, d, length, width):
    """True if the four (M,) arrays hold no NaN or inf."""
    return _finite(s) and _finite(d) and _finite(length) and _finite(width)


@njit(cache=True, inline="always")
def _finite(a):
    for x in a:
        if not np.isfinite(x):
            return False
    return True


def _period(period: float | None) -> float:
    return 0.0 if period is None else float(period)


def _points(st: StepState, reach: float, period: float | None):
    """The tree's coordinates (:func:`controllers.neighbours.tree_points`): ``px``, ``py``
    (M,) m, contiguous, and the box along ``d`` (m; 0 off a ring)."""
    if period is None:
        return np.ascontiguousarray(st.s), np.ascontiguousarray(st.d), 0.0
    pts, box = tree_points(np.column_stack([st.s, st.d]), reach, period)
    return np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), float(box[1])


@njit(cache=True, inline="always")
def _tree_within(xi, yi, xj, yj, r2, periodic, period, box_y):
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
def _pairs_within(px, py, reach, periodic, period, box_y):
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
    """:func:`_pairs_within` over points sorted by ``xs``: the number of pairs, written to
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
            if _tree_within(xp, yp, xs[q], ys[q], r2, periodic, period, box_y):
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
                if _tree_within(xp, yp, xs[q], ys[q], r2, periodic, period, box_y):
                    if fill:
                        out[cnt, 0] = min(order[p], order[q])
                        out[cnt, 1] = max(order[p], order[q])
                    cnt += 1
    return cnt


@njit(cache=True, inline="always")
def _wrap_ds(ds, periodic, period):
    """``(ds + period / 2) % period - period / 2`` on a ring (numpy's float ``%``), else
    ``ds``. ``%`` returns its operand unchanged in [0, period): skipped there."""
    if periodic:
        x = ds + 0.5 * period
        if not (0.0 <= x < period):
            x = x % period
        return x - 0.5 * period
    return ds


@njit(cache=True)
def _overlaps(cand, s, d, length, width, periodic, period):
    """The candidate pairs (P, 2) whose rectangles overlap strictly, (Q, 2) int64."""
    keep = np.zeros(cand.shape[0], np.bool_)
    for k in range(cand.shape[0]):
        i, j = cand[k, 0], cand[k, 1]
        ds = _wrap_ds(s[j] - s[i], periodic, period)
        keep[k] = (abs(ds) < 0.5 * (length[i] + length[j])) and (
            abs(d[j] - d[i]) < 0.5 * (width[i] + width[j]))
    return cand[keep]


@njit(cache=True)
def _gaps_kernel(cand, s, d, length, width, periodic, period, margin):
    """Gaps, side clearances and leaders over the candidate pairs (P, 2), both ways each:
    (g_long, g_side (M,) m, leader (M,), tied). ``tied``: some follower has two leaders at
    its smallest gap on the same side of its index (the tree's order would decide)."""
    n = s.shape[0]
    g_long = np.full(n, np.inf)
    g_side = np.full(n, np.inf)
    leader = np.full(n, -1, np.int64)
    n_hi = np.zeros(n, np.int64)  # leaders at the smallest gap with an index above
    n_lo = np.zeros(n, np.int64)  # ... and below the follower's
    for k in range(cand.shape[0]):
        for way in range(2):
            if way == 0:
                a, b = cand[k, 0], cand[k, 1]
            else:
                a, b = cand[k, 1], cand[k, 0]
            ds = _wrap_ds(s[b] - s[a], periodic, period)
            half_l = 0.5 * (length[a] + length[b])
            half_w = 0.5 * (width[a] + width[b])
            dd = abs(d[b] - d[a])
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
    return g_long, g_side, leader, tied


# ------------------------------------------------------------------ tree reference
def _overlapping_pairs_tree(st: StepState, period: float | None) -> np.ndarray:
    """:func:`overlapping_pairs` by cKDTree, in the tree's order."""
    if len(st.s) < 2:
        return np.empty((0, 2), dtype=np.int64)
    reach = float(np.hypot(st.length.max(), st.width.max()))
    pts, box = tree_points(np.column_stack([st.s, st.d]), reach, period)
    pairs = cKDTree(pts, boxsize=box).query_pairs(reach, output_type="ndarray")
    if len(pairs) == 0:
        return pairs
    i, j = pairs[:, 0], pairs[:, 1]
    ds = st.s[j] - st.s[i]
    if period is not None:
        ds = (ds + 0.5 * period) % period - 0.5 * period
    ov = (np.abs(ds) < 0.5 * (st.length[i] + st.length[j])) & (
        np.abs(st.d[j] - st.d[i]) < 0.5 * (st.width[i] + st.width[j])
    )
    return pairs[ov]


def _gaps_and_leaders_tree(
    st: StepState, period: float | None, lateral_overlap_margin_m: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`gaps_and_leaders` by cKDTree (ties between leaders in the tree's order)."""
    n = len(st.s)
    g_long = np.full(n, np.inf)
    g_side = np.full(n, np.inf)
    leader = np.full(n, -1, dtype=np.int64)
    if n < 2:
        return g_long, g_side, leader
    reach = GAP_REACH_M
    pts, box = tree_points(np.column_stack([st.s, st.d]), reach, period)
    pairs = cKDTree(pts, boxsize=box).query_pairs(reach, output_type="ndarray")
    if len(pairs) == 0:
        return g_long, g_side, leader
    i = np.concatenate([pairs[:, 0], pairs[:, 1]])
    j = np.concatenate([pairs[:, 1], pairs[:, 0]])
    ds = st.s[j] - st.s[i]
    if period is not None:
        ds = (ds + 0.5 * period) % period - 0.5 * period
    half_l = 0.5 * (st.length[i] + st.length[j])
    half_w = 0.5 * (st.width[i] + st.width[j])
    dd = np.abs(st.d[j] - st.d[i])
    lat_overlap = dd < half_w + lateral_overlap_margin_m
    ahead = (ds > 0) & lat_overlap
    if ahead.any():
        ia, ja, ga = i[ahead], j[ahead], ds[ahead] - half_l[ahead]
        order = np.lexsort((ga, ia))  # by follower, then gap: the first row of each is its leader
        ia, ja, ga = ia[order], ja[order], ga[order]
        first = np.ones(len(ia), dtype=bool)
        first[1:] = ia[1:] != ia[:-1]
        g_long[ia[first]] = ga[first]
        leader[ia[first]] = ja[first]
    beside = (np.abs(ds) < half_l) & ~lat_overlap
    np.minimum.at(g_side, i[beside], dd[beside] - half_w[beside])
    return g_long, g_side, leader


def time_to_collision(g_long: np.ndarray, v: np.ndarray, leader: np.ndarray) -> np.ndarray:
    """TTC (s) of each vehicle to its leader, (M,): ``gap / (v - v_leader)`` while closing
    in, inf when not closing in or without a leader; 0 when already overlapping.

    Args:
        g_long: bumper gaps to the leaders, (M,) m; v: speeds, (M,) m/s;
        leader: leader indices, (M,), -1 for none (from :func:`gaps_and_leaders`).
    """
    ttc = np.full(len(v), np.inf)
    has = leader >= 0
    closing = np.zeros(len(v))
    closing[has] = v[has] - v[leader[has]]
    hit = has & (closing > 0)
    ttc[hit] = np.maximum(g_long[hit], 0.0) / closing[hit]
    return ttc


@dataclass
class IntervalAccumulator:
    """Edie sums and counters for one measurement interval."""

    t0: float
    tts_s: float = 0.0
    ttd_m: float = 0.0
    crossings: np.ndarray | None = None
    boundary_vehicle_steps: int = 0
    collisions_sumo: int = 0
    collisions_geom: int = 0
    min_gap_m: float = np.inf
    min_side_clearance_m: float = np.inf
    headways_s: list = field(default_factory=list)


class TrafficRecorder:
    """Accumulate traffic metrics step by step; produce the interval table and summary.

    Args:
        dt: step, s.
        zone: (start, end) of the Edie measurement zone along the main route, m.
        cross_sections: positions (m) of the flow cross-sections.
        interval_s: interval length, s; warmup_s: start of the measurement, s.
        period: ring length, m, or None.
        ttc_threshold_s: ``TTC*`` of the exposure measures TET and TIT, s.
    """

    def __init__(
        self,
        dt: float,
        zone: tuple[float, float],
        cross_sections: tuple[float, ...],
        interval_s: float,
        warmup_s: float,
        period: float | None = None,
        ttc_threshold_s: float = 1.5,
    ) -> None:
        self.dt = dt
        self.ttc_threshold_s = ttc_threshold_s
        self.zone = zone
        self.xs = np.asarray(cross_sections, dtype=float)
        self.interval_s = interval_s
        self.warmup_s = warmup_s
        self.period = period
        self.rows: list[dict] = []
        self._acc: IntervalAccumulator | None = None
        self._prev_ids: list = []  # the last step's vehicles and their front positions (m)
        self._prev_front = np.zeros(0)
        self._prev_overlaps: set = set()
        self._prev_sumo: set = set()
        self._shortfall = {"cav": [0.0, 0], "hdv": [0.0, 0]}  # sum (m/s), vehicle-steps
        self._boundary_ids: set = set()
        self.worst_excursion_m = 0.0
        self.boundary_vehicle_steps = 0
        self.boundary_vehicle_steps_cav = 0
        self.collisions_sumo = {"cav": 0, "hdv_only": 0}
        self.collisions_geom = {"cav": 0, "hdv_only": 0}
        self.collision_log: list[dict] = []
        self.min_gap_m = np.inf
        self.min_side_clearance_m = np.inf
        self.min_cav_gap_m = np.inf
        self.headway_samples: list[np.ndarray] = []
        self.vehicle_steps = 0
        self.measured_vehicle_s = 0.0
        self.min_ttc_s = np.inf
        self.min_cav_ttc_s = np.inf
        self.tet_veh_s = 0.0
        self.tit_veh_s2 = 0.0

    # --------------------------------------------------------------------------
    def record(self, st: StepState, sumo_collisions: list[tuple[str, str]]) -> None:
        """Add one step (state after the step at time ``st.t``)."""
        t = st.t
        measuring = t > self.warmup_s + 1e-9
        if measuring and (self._acc is None or t > self._acc.t0 + self.interval_s + 1e-9):
            self._close_interval()
            start = self.warmup_s if self._acc is None else self._acc.t0 + self.interval_s
            self._acc = IntervalAccumulator(t0=start, crossings=np.zeros(len(self.xs), int))
        acc = self._acc if measuring else None
        static = np.zeros(len(st.s), dtype=bool) if st.is_static is None else st.is_static
        traffic = ~static
        self.vehicle_steps += int(np.count_nonzero(traffic))

        # Edie sums in the zone (each vehicle spends dt in this step).
        z0, z1 = self.zone
        in_zone = (st.s >= z0) & (st.s < z1) & traffic
        if acc is not None:
            acc.tts_s += self.dt * int(np.count_nonzero(in_zone))
            acc.ttd_m += self.dt * float(np.sum(st.v[in_zone]))
            if st.desired is not None:
                for kind, mask in (("cav", st.is_cav), ("hdv", ~st.is_cav)):
                    sel = in_zone & mask & np.isfinite(st.desired)
                    self._shortfall[kind][0] += float(np.sum(st.desired[sel] - st.v[sel]))
                    self._shortfall[kind][1] += int(np.count_nonzero(sel))

        # Cross-section counts (front bumper passes x between steps).
        ids = list(st.ids)  # a copy: kept for the next step
        if acc is not None and len(self.xs):
            idx = align(self._prev_ids, ids)  # None: the same vehicles in the same rows
            if idx is None:
                prev = self._prev_front
            else:
                prev = np.where(idx >= 0, self._prev_front[np.maximum(idx, 0)], np.nan) \
                    if len(self._prev_front) else np.full(len(ids), np.nan)
            ok = ~np.isnan(prev)
            cur = st.s_front[ok]
            prv = prev[ok]
            if self.period is not None:
                wrapped = cur < prv - 0.5 * self.period
                cur = np.where(wrapped, cur + self.period, cur)
                for k, x in enumerate(self.xs):
                    acc.crossings[k] += int(
                        np.count_nonzero((prv < x) & (cur >= x))
                        + np.count_nonzero((prv < x + self.period) & (cur >= x + self.period))
                    )
            else:
                for k, x in enumerate(self.xs):
                    acc.crossings[k] += int(np.count_nonzero((prv < x) & (cur >= x)))
        self._prev_ids = ids
        self._prev_front = np.asarray(st.s_front, dtype=float)

        # Boundary violations (body outside the edges).
        excursion = np.maximum(
            st.edge_right - (st.d - 0.5 * st.width), (st.d + 0.5 * st.width) - st.edge_left
        )
        out = (excursion > 1e-6) & traffic
        if out.any():
            self.boundary_vehicle_steps += int(np.count_nonzero(out))
            self.boundary_vehicle_steps_cav += int(np.count_nonzero(out & st.is_cav))
            self._boundary_ids.update(np.asarray(st.ids, dtype=object)[out].tolist())
            self.worst_excursion_m = max(self.worst_excursion_m, float(excursion.max()))
            if acc is not None:
                acc.boundary_vehicle_steps += int(np.count_nonzero(out))

        # Collisions: geometric new overlaps and SUMO's list.
        pairs = overlapping_pairs(st, self.period)
        now = set()
        for a, b in pairs:
            key = tuple(sorted((st.ids[a], st.ids[b])))
            now.add(key)
            if key not in self._prev_overlaps:
                kind = "cav" if (st.is_cav[a] or st.is_cav[b]) else "hdv_only"
                self.collisions_geom[kind] += 1
                self.collision_log.append(
                    {"t_s": t, "source": "geometric", "a": key[0], "b": key[1], "kind": kind}
                )
                if acc is not None:
                    acc.collisions_geom += 1
        self._prev_overlaps = now
        # SUMO lists a pair in every step it overlaps: count only pairs that start to.
        sumo_now = {tuple(sorted(pair)) for pair in sumo_collisions}
        new_sumo = sorted(sumo_now - self._prev_sumo)
        self._prev_sumo = sumo_now
        if new_sumo:
            cav_set = {k for k, c in zip(st.ids, st.is_cav, strict=True) if c}
        for a, b in new_sumo:
            kind = "cav" if (a in cav_set or b in cav_set) else "hdv_only"
            self.collisions_sumo[kind] += 1
            self.collision_log.append({"t_s": t, "source": "sumo", "a": a, "b": b, "kind": kind})
            if acc is not None:
                acc.collisions_sumo += 1

        # Gaps and headways.
        if measuring:
            g_long, g_side, leader = gaps_and_leaders(st, self.period)
            g_long = np.where(traffic, g_long, np.inf)  # an obstacle follows nobody
            g_side = np.where(traffic, g_side, np.inf)
            self._record_ttc(g_long, st, leader, traffic)
            finite = np.isfinite(g_long)
            if finite.any():
                self.min_gap_m = min(self.min_gap_m, float(g_long[finite].min()))
                cav_f = finite & st.is_cav
                if cav_f.any():
                    self.min_cav_gap_m = min(self.min_cav_gap_m, float(g_long[cav_f].min()))
                moving = finite & (st.v > 1.0)
                hw = g_long[moving] / st.v[moving]
                if acc is not None:
                    acc.min_gap_m = min(acc.min_gap_m, float(g_long[finite].min()))
                    acc.headways_s.append(hw)
            fs = np.isfinite(g_side)
            if fs.any():
                self.min_side_clearance_m = min(self.min_side_clearance_m, float(g_side[fs].min()))
                if acc is not None:
                    acc.min_side_clearance_m = min(
                        acc.min_side_clearance_m, float(g_side[fs].min())
                    )

    def _record_ttc(self, g_long: np.ndarray, st: StepState, leader: np.ndarray,
                    traffic: np.ndarray) -> None:
        """TTC minimum and Minderhoud & Bovy's TET/TIT over one measured step."""
        self.measured_vehicle_s += self.dt * int(np.count_nonzero(traffic))
        ttc = time_to_collision(g_long, st.v, leader)
        if not len(ttc):
            return
        self.min_ttc_s = min(self.min_ttc_s, float(ttc.min()))
        if st.is_cav.any():
            self.min_cav_ttc_s = min(self.min_cav_ttc_s, float(ttc[st.is_cav].min()))
        exposed = ttc <= self.ttc_threshold_s
        if exposed.any():
            self.tet_veh_s += self.dt * int(np.count_nonzero(exposed))
            self.tit_veh_s2 += self.dt * float(np.sum(self.ttc_threshold_s - ttc[exposed]))

    # --------------------------------------------------------------------------
    def _close_interval(self) -> None:
        acc = self._acc
        if acc is None:
            return
        z0, z1 = self.zone
        x_len = z1 - z0
        hw = np.concatenate(acc.headways_s) if acc.headways_s else np.empty(0)
        if len(hw):
            self.headway_samples.append(hw)
        row = {
            "t_start_s": acc.t0,
            "t_end_s": acc.t0 + self.interval_s,
            "edie_flow_vph": acc.ttd_m / (x_len * self.interval_s) * 3600.0,
            "edie_density_vpkm": acc.tts_s / (x_len * self.interval_s) * 1000.0,
            "space_mean_speed_mps": acc.ttd_m / acc.tts_s if acc.tts_s > 0 else np.nan,
            "boundary_vehicle_steps": acc.boundary_vehicle_steps,
            "collisions_sumo": acc.collisions_sumo,
            "collisions_geometric": acc.collisions_geom,
            "min_gap_m": acc.min_gap_m,
            "min_side_clearance_m": acc.min_side_clearance_m,
            "median_time_headway_s": float(np.median(hw)) if len(hw) else np.nan,
        }
        for k, x in enumerate(self.xs):
            row[f"flow_x{x:g}_vph"] = acc.crossings[k] / self.interval_s * 3600.0
        self.rows.append(row)

    def finish(self, t_end: float) -> None:
        """Close the last interval if it is complete (partial intervals are dropped)."""
        if self._acc is not None and t_end >= self._acc.t0 + self.interval_s - 1e-6:
            self._close_interval()
        self._acc = None

    def summary(self) -> dict:
        """One-row summary over the measurement period (after warm-up)."""
        rows = self.rows
        hw = np.concatenate(self.headway_samples) if self.headway_samples else np.empty(0)

        def mean(key):
            vals = [r[key] for r in rows]
            return float(np.nanmean(vals)) if vals else np.nan

        drift = interval_drift([r["edie_flow_vph"] for r in rows])
        total_k = float(np.nansum([r["edie_density_vpkm"] for r in rows])) if rows else 0.0
        total_q = float(np.nansum([r["edie_flow_vph"] for r in rows])) if rows else 0.0
        out = {
            "edie_flow_vph": mean("edie_flow_vph"),
            "edie_density_vpkm": mean("edie_density_vpkm"),
            # q / k in (veh/h) / (veh/km) = km/h; undefined when nobody was in the zone.
            "space_mean_speed_mps": total_q / total_k / 3.6 if total_k > 0 else np.nan,
            "boundary_vehicle_steps": self.boundary_vehicle_steps,
            "boundary_vehicle_steps_cav": self.boundary_vehicle_steps_cav,
            "boundary_vehicles": len(self._boundary_ids),
            "worst_boundary_excursion_m": self.worst_excursion_m,
            "collisions_sumo_cav": self.collisions_sumo["cav"],
            "collisions_sumo_hdv_only": self.collisions_sumo["hdv_only"],
            "collisions_geometric_cav": self.collisions_geom["cav"],
            "collisions_geometric_hdv_only": self.collisions_geom["hdv_only"],
            "min_gap_m": self.min_gap_m,
            "min_cav_gap_m": self.min_cav_gap_m,
            "min_side_clearance_m": self.min_side_clearance_m,
            "median_time_headway_s": float(np.median(hw)) if len(hw) else np.nan,
            "p05_time_headway_s": float(np.percentile(hw, 5)) if len(hw) else np.nan,
            "min_ttc_s": self.min_ttc_s,
            "min_cav_ttc_s": self.min_cav_ttc_s,
            "ttc_threshold_s": self.ttc_threshold_s,
            "measured_vehicle_s": self.measured_vehicle_s,
            "tet_veh_s": self.tet_veh_s,
            "tit_veh_s2": self.tit_veh_s2,
            # TET as a share of the measured vehicle-time (all vehicles on the road).
            "tet_share": (
                self.tet_veh_s / self.measured_vehicle_s if self.measured_vehicle_s else np.nan
            ),
            "vehicle_steps": self.vehicle_steps,
            # mean (desired - actual) speed in the zone after warm-up, per kind, m/s
            "cav_speed_shortfall_mps": (self._shortfall["cav"][0] / self._shortfall["cav"][1]
                                        if self._shortfall["cav"][1] else np.nan),
            "hdv_speed_shortfall_mps": (self._shortfall["hdv"][0] / self._shortfall["hdv"][1]
                                        if self._shortfall["hdv"][1] else np.nan),
            "n_intervals": len(rows),
            "flow_drift": drift,
            "stationary": is_stationary(drift),
        }
        for x in self.xs:
            out[f"flow_x{x:g}_vph"] = mean(f"flow_x{x:g}_vph")
        return out
