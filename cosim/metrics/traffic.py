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
from scipy.spatial import cKDTree

from controllers.neighbours import tree_points
from cosim.metrics import kernels as K
from cosim.metrics.capacity import interval_drift, is_stationary
from cosim.metrics.jams import UNALIGNED, align


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
    #: each vehicle's row in the previous step (:func:`cosim.metrics.jams.align` of its ids
    #: and these; None: the same vehicles at the same rows), when the caller that feeds
    #: every step to every recorder computed it once for all; else UNALIGNED
    prev_rows: object = UNALIGNED


GAP_REACH_M = 150.0  # reach of the leader and side search, m (distance in (s, d))
_NO_VALUES = np.zeros(0)  # placeholders for the kernels' unused arguments
_NO_ROWS = np.zeros(0, dtype=np.int64)
_NO_COUNTS = np.zeros(0, dtype=np.int64)


def overlapping_pairs(st: StepState, period: float | None) -> np.ndarray:
    """Pairs (i < j) of vehicles whose rectangles overlap (strictly), (P, 2).

    A sweep along ``s`` (:func:`~cosim.metrics.kernels.pair_sweep`) finds every such
    pair; with two or more the pairs come from scipy's cKDTree
    (:func:`_overlapping_pairs_tree`), in its order, which the collision log keeps."""
    return overlaps_and_gaps(st, period, with_gaps=False)[0]


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

    The pairs within the reach are those scipy's cKDTree finds (the sweep of
    :func:`~cosim.metrics.kernels.pair_sweep` applies its test). Of two leaders at the
    same gap, one with a higher index than the follower wins; which of several such (or,
    without one, of several lower ones) depends on the tree's order: then the tree decides
    (:func:`_gaps_and_leaders_tree`)."""
    return overlaps_and_gaps(st, period, True, lateral_overlap_margin_m)[1]


def overlaps_and_gaps(st: StepState, period: float | None, with_gaps: bool = True,
                      lateral_overlap_margin_m: float = 0.0):
    """:func:`overlapping_pairs` and, if ``with_gaps``, :func:`gaps_and_leaders` (else
    None), from one sort and one sweep along the road (what the recorder needs each step).
    Non-finite or non-float64 inputs take the tree paths."""
    n = len(st.s)
    margin = float(lateral_overlap_margin_m)
    if n < 2 or not _fast_ok(st):
        pairs = _overlapping_pairs_tree(st, period)
        gaps_ = _gaps_and_leaders_tree(st, period, margin) if with_gaps else None
        return pairs, gaps_
    if period is None:
        px, py, box_y = st.s, st.d, 0.0
    else:  # the tree's coordinates (_points), compiled
        px, py, box_y = K.tree_points_2d(st.s, st.d, GAP_REACH_M, float(period))
    pairs, n_pairs, g_long, g_side, leader, tied = K.pair_sweep(
        px, py, st.s, st.d, st.length, st.width, period is not None, _period(period), box_y,
        bool(with_gaps), GAP_REACH_M, margin)
    if n_pairs >= 2:
        pairs = _overlapping_pairs_tree(st, period)
    if not with_gaps:
        return pairs, None
    if tied:
        return pairs, _gaps_and_leaders_tree(st, period, margin)
    return pairs, (g_long, g_side, leader)


def _fast_ok(st: StepState) -> bool:
    """True when the compiled path applies: float64 arrays of finite values (otherwise
    the tree path keeps numpy's NaN and dtype rules)."""
    arrs = (st.s, st.d, st.length, st.width)
    return all(
        isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == 1 for a in arrs
    ) and K.all_finite(st.s, st.d, st.length, st.width)


def _period(period: float | None) -> float:
    return 0.0 if period is None else float(period)


def _points(st: StepState, reach: float, period: float | None):
    """The tree's coordinates (:func:`controllers.neighbours.tree_points`): ``px``, ``py``
    (M,) m, contiguous, and the box along ``d`` (m; 0 off a ring)."""
    if period is None:
        return np.ascontiguousarray(st.s), np.ascontiguousarray(st.d), 0.0
    pts, box = tree_points(np.column_stack([st.s, st.d]), reach, period)
    return np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), float(box[1])


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
        """Add one step (state after the step at time ``st.t``).

        The per-vehicle arithmetic runs in two compiled passes
        (:func:`~cosim.metrics.kernels.traffic_tallies`,
        :func:`~cosim.metrics.kernels.gap_tallies`); what they return is accumulated here
        as the numpy version accumulated it (the same bits)."""
        t = st.t
        measuring = t > self.warmup_s + 1e-9
        if measuring and (self._acc is None or t > self._acc.t0 + self.interval_s + 1e-9):
            self._close_interval()
            start = self.warmup_s if self._acc is None else self._acc.t0 + self.interval_s
            self._acc = IntervalAccumulator(t0=start, crossings=np.zeros(len(self.xs), int))
        acc = self._acc if measuring else None
        n = len(st.s)
        static = np.zeros(n, dtype=bool) if st.is_static is None else st.is_static
        ids = list(st.ids)  # a copy: kept for the next step
        # cross-section counts (a front passes x between steps) are added in place
        count = acc is not None and len(self.xs) > 0
        idx = None
        if count:
            idx = align(self._prev_ids, ids) if st.prev_rows is UNALIGNED else st.prev_rows
        (n_traffic, n_zone, ttd, sf_cav, n_sf_cav, sf_hdv, n_sf_hdv, out, n_out, n_out_cav,
         exc_max) = K.traffic_tallies(
            st.s, st.s_front, st.d, st.v, st.width, st.is_cav, static,
            _NO_VALUES if st.desired is None else st.desired, st.desired is not None,
            st.edge_right, st.edge_left, float(self.zone[0]), float(self.zone[1]),
            acc is not None, count, self._prev_front, _NO_ROWS if idx is None else idx,
            idx is None, self.xs, self.period is not None, _period(self.period),
            acc.crossings if count else _NO_COUNTS)
        self.vehicle_steps += int(n_traffic)
        self._prev_ids = ids
        self._prev_front = np.asarray(st.s_front, dtype=float)

        # Edie sums in the zone (each vehicle spends dt in this step).
        if acc is not None:
            acc.tts_s += self.dt * int(n_zone)
            acc.ttd_m += self.dt * float(ttd)
            if st.desired is not None:
                self._shortfall["cav"][0] += float(sf_cav)
                self._shortfall["cav"][1] += int(n_sf_cav)
                self._shortfall["hdv"][0] += float(sf_hdv)
                self._shortfall["hdv"][1] += int(n_sf_hdv)

        # Boundary violations (body outside the edges).
        if n_out:
            self.boundary_vehicle_steps += int(n_out)
            self.boundary_vehicle_steps_cav += int(n_out_cav)
            self._boundary_ids.update(np.asarray(st.ids, dtype=object)[out].tolist())
            self.worst_excursion_m = max(self.worst_excursion_m, float(exc_max))
            if acc is not None:
                acc.boundary_vehicle_steps += int(n_out)

        # Collisions: geometric new overlaps and SUMO's list.
        pairs, gaps_ = overlaps_and_gaps(st, self.period, with_gaps=measuring)
        if len(pairs) or self._prev_overlaps:
            self._new_overlaps(st, pairs, acc)
        if sumo_collisions or self._prev_sumo:
            self._new_sumo_collisions(st, sumo_collisions, acc)

        # Gaps, headways, TTC (Minderhoud & Bovy's TET/TIT); an obstacle follows nobody.
        if measuring:
            g_long, g_side, leader = gaps_
            (n_traffic, ttc_min, n_cav, ttc_cav_min, n_exposed, tit, gap_min, cav_gap_min,
             n_finite, n_cav_finite, hw, side_min, n_side) = K.gap_tallies(
                g_long, g_side, leader, np.asarray(st.v, dtype=float), st.is_cav, static,
                float(self.ttc_threshold_s))
            self.measured_vehicle_s += self.dt * int(n_traffic)
            if n:
                self.min_ttc_s = min(self.min_ttc_s, float(ttc_min))
                if n_cav:
                    self.min_cav_ttc_s = min(self.min_cav_ttc_s, float(ttc_cav_min))
                if n_exposed:
                    self.tet_veh_s += self.dt * int(n_exposed)
                    self.tit_veh_s2 += self.dt * float(tit)
            if n_finite:
                self.min_gap_m = min(self.min_gap_m, float(gap_min))
                if n_cav_finite:
                    self.min_cav_gap_m = min(self.min_cav_gap_m, float(cav_gap_min))
                if acc is not None:
                    acc.min_gap_m = min(acc.min_gap_m, float(gap_min))
                    acc.headways_s.append(hw)
            if n_side:
                self.min_side_clearance_m = min(self.min_side_clearance_m, float(side_min))
                if acc is not None:
                    acc.min_side_clearance_m = min(acc.min_side_clearance_m, float(side_min))

    def _new_overlaps(self, st: StepState, pairs: np.ndarray,
                      acc: IntervalAccumulator | None) -> None:
        """Count and log the overlapping pairs (P, 2) that did not overlap in the last step."""
        now = set()
        for a, b in pairs:
            key = tuple(sorted((st.ids[a], st.ids[b])))
            now.add(key)
            if key not in self._prev_overlaps:
                kind = "cav" if (st.is_cav[a] or st.is_cav[b]) else "hdv_only"
                self.collisions_geom[kind] += 1
                self.collision_log.append(
                    {"t_s": st.t, "source": "geometric", "a": key[0], "b": key[1],
                     "kind": kind})
                if acc is not None:
                    acc.collisions_geom += 1
        self._prev_overlaps = now

    def _new_sumo_collisions(self, st: StepState, sumo_collisions: list[tuple[str, str]],
                             acc: IntervalAccumulator | None) -> None:
        """Count and log SUMO's pairs that start to collide (SUMO lists a pair in every step
        it overlaps)."""
        sumo_now = {tuple(sorted(pair)) for pair in sumo_collisions}
        new_sumo = sorted(sumo_now - self._prev_sumo)
        self._prev_sumo = sumo_now
        if new_sumo:
            cav_set = {k for k, c in zip(st.ids, st.is_cav, strict=True) if c}
        for a, b in new_sumo:
            kind = "cav" if (a in cav_set or b in cav_set) else "hdv_only"
            self.collisions_sumo[kind] += 1
            self.collision_log.append(
                {"t_s": st.t, "source": "sumo", "a": a, "b": b, "kind": kind})
            if acc is not None:
                acc.collisions_sumo += 1

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
