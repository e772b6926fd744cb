"""Road-limited capacity: queue discharge at an active bottleneck, and entrance checks.

Pure numpy; the data come from :class:`cosim.sim.recording.CapacityRecorder` (SI units:
times s, positions m, flows veh/h).

**Method** (Cassidy & Bertini, "Some traffic features at freeway bottlenecks",
Transportation Research Part B 33(1), 1999, 25-42): a bottleneck is *active* while
traffic is queued upstream of it and unqueued downstream; its capacity is the
*queue-discharge flow* measured downstream while it is active, as the slope of the
cumulative vehicle count ``N(x, t)`` (the N-curve: vehicles whose front passed ``x`` by
time ``t``) at cross-sections downstream of it. Here:

* **Bottleneck** (:func:`find_bottleneck`): a stopped obstacle, else the first width drop
  of the road (the first position where the width is :data:`MIN_WIDTH_DROP_M` below the
  widest upstream: a taper counts as one drop, from its first narrower piece to the start
  of its last, where the road stops narrowing), else an on-ramp merge.
* **Zones** (:func:`layout_for`): an *entrance* zone (the first :data:`ENTRANCE_ZONE_M`
  of the road), an *upstream* zone ending :data:`UPSTREAM_GAP_M` before the bottleneck
  and a *downstream* zone starting :data:`DOWNSTREAM_GAP_M` after it, each at most
  :data:`ZONE_LENGTH_M` long; :data:`N_SECTIONS` count cross-sections spread over the
  downstream zone.
* **Queued / unqueued**: per bin of :data:`BIN_S`, a zone's *speed ratio*
  ``r = TTD / TDD``: distance travelled over the distance the same vehicles would have
  travelled at their desired speeds (Edie's sums over the zone and bin; 1 = everybody at
  the desired speed). Queued: ``r <= QUEUE_SPEED_RATIO``; free: ``r >=
  FREE_SPEED_RATIO``; an empty zone is neither.
* **Active bins**: upstream queued and downstream unqueued (``r > QUEUE_SPEED_RATIO``:
  Cassidy & Bertini's unqueued, no queue reaching back from further downstream). Not
  "free": SUMO's human drivers dawdle (Krauss, ``sigma = 0.5``) and cannot pass each
  other in a neck, so past a bottleneck they queued at they drive at 0.79-0.95 of their
  desired speeds bin by bin (the headline's width drop and lane closure, 10 s bins): a
  free-flow test would call a third of their uncongested bins not free, and their
  discharge unmeasurable. The *discharge window* is the
  measured period (after the warm-up) without its leading and trailing inactive bins
  (the queue still forming); the bottleneck counts as active when that window is at
  least :data:`MIN_WINDOW_S` and :data:`MIN_WINDOW_SHARE` of the measured period long
  and at least :data:`ACTIVE_SHARE` of its bins are active.
* **Discharge flow**: ``(N(x, t1) - N(x, t0)) / (t1 - t0)`` over the window, averaged
  over the downstream cross-sections (the mean slope of the N-curves: with no ramp in
  between they count the same vehicles, so the average only removes the end effects of
  single sections).
* **Drift** (:func:`relative_drift`): the relative difference of the mean flow of the
  second and the first half of the measured period (the window for the discharge):
  ``(q2 - q1) / ((q1 + q2) / 2)``. It uses every interval (less noisy than the first
  against the last interval), equals a linear trend's change over half the period, and
  reads as what a reviewer would check: did the flow still change? A point is
  *stationary* when ``|drift| <`` :data:`STATIONARY_DRIFT` (2 %).

**Entrance checks** (:func:`entrance_check`), on the measured bins:

* *waiting*: vehicles were waiting to be inserted in a bin: the world had pending
  insertions (``world.pending() > 0``), or the *backlog* (the demand's expected arrivals,
  ``demand_vph x t``, minus the vehicles inserted by the end of the bin) exceeded
  :func:`backlog_tolerance` (three Poisson standard deviations of the arrivals plus
  :data:`BACKLOG_MIN`): slot insertion delays departures in the plan itself, where the
  world cannot see them waiting;
* *starved*: vehicles were waiting while the entrance zone flowed freely (unqueued): the
  road could have taken them, the entrance could not deliver them (its service rate set
  the flow). Bins between queued and free (stop-and-go of a queue that reached the
  entrance) are not starved;
* *queue at the entrance*: the entrance zone was queued.

A run is **entrance-limited** when it has no active bottleneck and it was starved, or its
entrance was queued (the entrance's own disturbance), in at least
:data:`ENTRANCE_SHARE` of its measured bins: then the entrance, not the road, set its
flow. A run whose bottleneck is active is never entrance-limited: a queue upstream of the
bottleneck means that the entrance delivered at least what the bottleneck discharges, and
the discharge is measured downstream of the bottleneck while that queue lasts (Cassidy &
Bertini), even when the queue spilled back to the entrance (reported as
``queue_at_entrance``, with the starved share).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

#: Bin of the zone sums, the pending counts and the activity test, s.
BIN_S = 10.0
#: A zone is queued when its speed ratio (actual / desired distance) is at most this.
QUEUE_SPEED_RATIO = 0.7
#: A zone flows freely when its speed ratio is at least this (the entrance checks).
FREE_SPEED_RATIO = 0.85
#: Share of the discharge window's bins that must be active.
ACTIVE_SHARE = 0.8
#: Shortest discharge window, s, and as a share of the measured period.
MIN_WINDOW_S = 120.0
MIN_WINDOW_SHARE = 0.5
#: Share of the measured bins starved (or queued at the entrance) that flags a run.
ENTRANCE_SHARE = 0.25
#: A point is stationary when its flow drift is below this (relative).
STATIONARY_DRIFT = 0.02
#: A width drop of at least this much makes a bottleneck, m.
MIN_WIDTH_DROP_M = 0.1
#: Zone geometry, m (see the module docstring).
ENTRANCE_ZONE_M = 200.0
UPSTREAM_GAP_M = 50.0
DOWNSTREAM_GAP_M = 100.0
ZONE_LENGTH_M = 250.0
#: A zone shorter than this is not measured, m.
MIN_ZONE_M = 50.0
#: Count cross-sections in the downstream zone.
N_SECTIONS = 3
#: Backlog (vehicles) always tolerated on top of the arrivals' Poisson spread.
BACKLOG_MIN = 5.0


@dataclass(frozen=True)
class Bottleneck:
    """Where the road's capacity drops.

    Attributes:
        kind: "obstacle", "width_drop" or "merge".
        s_m: where it starts along the road, m (an obstacle's rear, the first position of
            the narrower road, the merge point).
        end_m: where the constriction ends (an obstacle's front; a taper's narrowest piece;
            else ``s_m``), m.
        detail: one line for the reader, e.g. "width 10.2 -> 6.8 m".
    """

    kind: str
    s_m: float
    end_m: float
    detail: str = ""


@dataclass(frozen=True)
class Layout:
    """Zones (start, end) m and count cross-sections (m) of a run; ``note`` says why a
    part cannot be measured ("" when all can)."""

    length_m: float
    periodic: bool
    bottleneck: Bottleneck | None = None
    entrance_zone_m: tuple[float, float] | None = None
    upstream_zone_m: tuple[float, float] | None = None
    downstream_zone_m: tuple[float, float] | None = None
    sections_m: tuple[float, ...] = ()
    note: str = ""

    @property
    def zones(self) -> dict[str, tuple[float, float]]:
        """The zones that exist, by name ("entrance", "upstream", "downstream")."""
        out = {}
        for name in ("entrance", "upstream", "downstream"):
            z = getattr(self, f"{name}_zone_m")
            if z is not None:
                out[name] = z
        return out

    @property
    def measures_discharge(self) -> bool:
        return (self.bottleneck is not None and self.upstream_zone_m is not None
                and self.downstream_zone_m is not None and len(self.sections_m) > 0)


def find_bottleneck(widths_s0: Sequence[float] | np.ndarray | None = None,
                    widths_m: Sequence[float] | np.ndarray | None = None,
                    obstacle: tuple[float, float] | None = None,
                    merge_s_m: float | None = None) -> Bottleneck | None:
    """The road's bottleneck, or None.

    Args:
        widths_s0: (K,) start of each piece of the width profile, m (increasing).
        widths_m: (K,) road width on each piece, m.
        obstacle: (centre s, length) of a stopped obstacle, m.
        merge_s_m: an on-ramp's merge point, m.

    Order: an obstacle, else the first width drop of at least :data:`MIN_WIDTH_DROP_M`,
    else a merge.
    """
    if obstacle is not None:
        s, length = float(obstacle[0]), float(obstacle[1])
        return Bottleneck("obstacle", s - 0.5 * length, s + 0.5 * length,
                          f"stopped obstacle {length:g} m long at {s:g} m")
    if widths_s0 is not None and widths_m is not None and len(widths_m) > 1:
        w = np.asarray(widths_m, dtype=float)
        s0 = np.asarray(widths_s0, dtype=float)
        widest = np.maximum.accumulate(w)  # a taper (SUMO's junction) counts as a whole
        drops = np.flatnonzero(w < widest - MIN_WIDTH_DROP_M)
        if len(drops):
            k = int(drops[0])
            narrow = float(w[k:].min())
            j = k  # a taper: the pieces that keep narrowing after the first drop
            while j + 1 < len(w) and w[j + 1] < w[j] - MIN_WIDTH_DROP_M:
                j += 1
            return Bottleneck("width_drop", float(s0[k]), float(s0[j]),
                              f"width {widest[k]:.3g} -> {narrow:.3g} m at {s0[k]:.4g} m")
    if merge_s_m is not None and math.isfinite(merge_s_m):
        return Bottleneck("merge", float(merge_s_m), float(merge_s_m),
                          f"on-ramp merge at {merge_s_m:g} m")
    return None


def layout_for(length_m: float, periodic: bool, bottleneck: Bottleneck | None) -> Layout:
    """Zones and count cross-sections for a road of ``length_m`` (m) and its bottleneck."""
    if periodic:
        return Layout(length_m, True, bottleneck, note="ring: no entrance and no discharge "
                      "measurement (the density is set)")
    entrance = (0.0, min(ENTRANCE_ZONE_M, length_m))
    if bottleneck is None:
        return Layout(length_m, False, None, entrance, note="no bottleneck in the network")
    b, end = bottleneck.s_m, bottleneck.end_m
    up1 = b - UPSTREAM_GAP_M
    up0 = max(up1 - ZONE_LENGTH_M, entrance[1])
    down0 = end + DOWNSTREAM_GAP_M
    down1 = min(down0 + ZONE_LENGTH_M, length_m - 10.0)
    notes = []
    upstream = (up0, up1) if up1 - up0 >= MIN_ZONE_M else None
    if upstream is None:
        notes.append(f"bottleneck at {b:g} m leaves no upstream zone of {MIN_ZONE_M:g} m "
                     f"beyond the entrance zone")
    downstream = (down0, down1) if down1 - down0 >= MIN_ZONE_M else None
    if downstream is None:
        notes.append(f"the road ends {length_m - end:g} m after the bottleneck: no "
                     f"downstream zone of {MIN_ZONE_M:g} m starting {DOWNSTREAM_GAP_M:g} m "
                     "after it")
        sections: tuple[float, ...] = ()
    else:
        sections = tuple(float(x) for x in np.linspace(down0, down1, N_SECTIONS))
    return Layout(length_m, False, bottleneck, entrance, upstream, downstream, sections,
                  "; ".join(notes))


# --------------------------------------------------------------------------------------
# N-curves
# --------------------------------------------------------------------------------------


def cumulative_counts(crossing_times_s: np.ndarray, t_s: np.ndarray | float) -> np.ndarray:
    """N(t): crossings at or before each ``t`` (s), from sorted crossing times (s)."""
    times = np.sort(np.asarray(crossing_times_s, dtype=float))
    return np.searchsorted(times, np.asarray(t_s, dtype=float), side="right")


def n_curve_flow(crossing_times_s: np.ndarray, t0_s: float, t1_s: float) -> float:
    """Mean slope of the N-curve over ``[t0, t1]``: ``(N(t1) - N(t0)) / (t1 - t0)``, veh/h."""
    if not t1_s > t0_s:
        return math.nan
    n0, n1 = cumulative_counts(crossing_times_s, np.array([t0_s, t1_s]))
    return float(n1 - n0) / (t1_s - t0_s) * 3600.0


def discharge_flow(crossings: Sequence[np.ndarray], t0_s: float, t1_s: float) -> float:
    """Mean over cross-sections of :func:`n_curve_flow` over ``[t0, t1]``, veh/h."""
    flows = [n_curve_flow(c, t0_s, t1_s) for c in crossings]
    flows = [f for f in flows if math.isfinite(f)]
    return float(np.mean(flows)) if flows else math.nan


def relative_drift(first: float, second: float) -> float:
    """``(second - first) / mean(first, second)``; NaN when undefined."""
    mean = 0.5 * (first + second)
    if not (math.isfinite(first) and math.isfinite(second)) or mean <= 0:
        return math.nan
    return (second - first) / mean


def interval_drift(flows: Sequence[float]) -> float:
    """Drift of a run's interval flows (veh/h): :func:`relative_drift` of the means of
    the first and second half of the intervals (the middle one left out when their
    number is odd); NaN for fewer than 2 intervals."""
    q = np.asarray([f for f in flows if f is not None and math.isfinite(f)], dtype=float)
    if len(q) < 2:
        return math.nan
    h = len(q) // 2
    return relative_drift(float(q[:h].mean()), float(q[-h:].mean()))


def is_stationary(drift: float, limit: float = STATIONARY_DRIFT) -> bool:
    """``|drift| < limit``; False when the drift is unknown (NaN)."""
    return bool(math.isfinite(drift) and abs(drift) < limit)


# --------------------------------------------------------------------------------------
# Zones: speed ratios, activity, discharge window
# --------------------------------------------------------------------------------------


def speed_ratio(ttd_m: np.ndarray, tdd_m: np.ndarray) -> np.ndarray:
    """Per bin ``TTD / TDD`` (distance travelled / distance at the desired speeds); NaN
    where the zone was empty."""
    ttd = np.asarray(ttd_m, dtype=float)
    tdd = np.asarray(tdd_m, dtype=float)
    out = np.full(ttd.shape, np.nan)
    ok = tdd > 0
    out[ok] = ttd[ok] / tdd[ok]
    return out


def queued(ratio: np.ndarray) -> np.ndarray:
    """Bins whose zone was queued (NaN: empty zone: not queued)."""
    r = np.asarray(ratio, dtype=float)
    return np.isfinite(r) & (r <= QUEUE_SPEED_RATIO)


def unqueued(ratio: np.ndarray) -> np.ndarray:
    """Bins whose zone was not queued (NaN: empty zone: not unqueued)."""
    r = np.asarray(ratio, dtype=float)
    return np.isfinite(r) & (r > QUEUE_SPEED_RATIO)


def free(ratio: np.ndarray) -> np.ndarray:
    """Bins whose zone flowed freely (NaN: empty zone: not free)."""
    r = np.asarray(ratio, dtype=float)
    return np.isfinite(r) & (r >= FREE_SPEED_RATIO)


def discharge_window(active: np.ndarray, bin_starts_s: np.ndarray, bin_s: float
                     ) -> tuple[float, float, float] | None:
    """(t0, t1, active share) of the measured bins without leading and trailing inactive
    bins; None when no bin is active.

    Args:
        active: (B,) bool per measured bin. bin_starts_s: (B,) s. bin_s: bin length, s.
    """
    a = np.asarray(active, dtype=bool)
    idx = np.flatnonzero(a)
    if len(idx) == 0:
        return None
    i0, i1 = int(idx[0]), int(idx[-1])
    share = float(a[i0:i1 + 1].mean())
    return float(bin_starts_s[i0]), float(bin_starts_s[i1] + bin_s), share


@dataclass
class CapacityData:
    """What :class:`~cosim.sim.recording.CapacityRecorder` measured (SI units).

    Attributes:
        bin_s: bin length, s. warmup_s: start of the measured period, s. t_end_s: end, s.
        zone_ttd_m, zone_tdd_m: per zone name, (B,) distance travelled and distance at
            the desired speeds in each bin (bin b covers ``[b bin_s, (b+1) bin_s)``), m.
        zone_tts_s: per zone name, (B,) time spent, s.
        pending: (B,) most vehicles waiting to be inserted in each bin.
        inserted: (B,) vehicles inserted by the end of each bin (cumulative).
        demand_vph: the demand's mean arrival rate (main road and ramp), veh/h (0: none).
        crossings: per downstream cross-section, the sorted crossing times, s.
    """

    bin_s: float
    warmup_s: float
    t_end_s: float
    zone_ttd_m: dict[str, np.ndarray] = field(default_factory=dict)
    zone_tdd_m: dict[str, np.ndarray] = field(default_factory=dict)
    zone_tts_s: dict[str, np.ndarray] = field(default_factory=dict)
    pending: np.ndarray = field(default_factory=lambda: np.zeros(0))
    inserted: np.ndarray = field(default_factory=lambda: np.zeros(0))
    demand_vph: float = 0.0
    crossings: list[np.ndarray] = field(default_factory=list)

    def waiting(self) -> np.ndarray:
        """(B_measured,) bool: vehicles were waiting to be inserted in the measured bins
        (pending insertions, or a backlog beyond :func:`backlog_tolerance`)."""
        bins = self.measured_bins()
        out = _take(self.pending, bins) > 0
        if self.demand_vph > 0 and len(self.inserted):
            t_end = (bins + 1) * self.bin_s
            expected = self.demand_vph * t_end / 3600.0
            inserted = _take(_carry(self.inserted), bins)
            out |= expected - inserted > backlog_tolerance(expected)
        return out

    def measured_bins(self) -> np.ndarray:
        """Indices of the bins wholly inside ``[warmup_s, t_end_s]``."""
        n = int(math.floor(self.t_end_s / self.bin_s + 1e-9))
        first = int(math.ceil(self.warmup_s / self.bin_s - 1e-9))
        return np.arange(first, max(first, n))

    def ratio(self, zone: str) -> np.ndarray:
        """(B_measured,) speed ratio of ``zone`` in the measured bins (NaN if empty)."""
        bins = self.measured_bins()
        ttd = _take(self.zone_ttd_m.get(zone), bins)
        tdd = _take(self.zone_tdd_m.get(zone), bins)
        return speed_ratio(ttd, tdd)


def backlog_tolerance(expected: np.ndarray) -> np.ndarray:
    """Backlog (vehicles) within the arrivals' randomness: ``3 sqrt(expected) + 5``."""
    return 3.0 * np.sqrt(np.maximum(np.asarray(expected, dtype=float), 0.0)) + BACKLOG_MIN


def _carry(cum: np.ndarray) -> np.ndarray:
    """A cumulative count carried past its end (a bin nothing was recorded in keeps it)."""
    return np.maximum.accumulate(np.asarray(cum, dtype=float)) if len(cum) else cum


def _take(arr: np.ndarray | None, bins: np.ndarray) -> np.ndarray:
    """``arr[bins]`` with zeros beyond its end (bins nothing was recorded in)."""
    out = np.zeros(len(bins))
    if arr is None:
        return out
    ok = bins < len(arr)
    out[ok] = np.asarray(arr)[bins[ok]]
    return out


def entrance_check(entrance_ratio: np.ndarray, waiting: np.ndarray,
                   bottleneck_active: bool) -> dict:
    """Entrance figures over the measured bins (see the module docstring).

    Args:
        entrance_ratio: (B,) speed ratio of the entrance zone. waiting: (B,) bool (or
            counts > 0): vehicles waited to be inserted in the bin.
        bottleneck_active: an active bottleneck downstream.
    Returns: ``entrance_starved_share``, ``entrance_queued_share`` (shares of the bins),
    ``queue_at_entrance`` and ``entrance_limited`` (bool).
    """
    r = np.asarray(entrance_ratio, dtype=float)
    p = np.asarray(waiting, dtype=float)
    if len(r) == 0:
        return {"entrance_starved_share": math.nan, "entrance_queued_share": math.nan,
                "queue_at_entrance": False, "entrance_limited": False}
    q = queued(r)
    starved = (p > 0) & free(r)
    starved_share = float(starved.mean())
    queued_share = float(q.mean())
    at_entrance = queued_share >= ENTRANCE_SHARE
    limited = not bottleneck_active and (starved_share >= ENTRANCE_SHARE or at_entrance)
    return {"entrance_starved_share": starved_share, "entrance_queued_share": queued_share,
            "queue_at_entrance": bool(at_entrance), "entrance_limited": bool(limited)}


def assess(data: CapacityData, layout: Layout) -> dict:
    """Every capacity figure of a run (the summary's fields; NaN/False where not
    measurable; ``capacity_note`` says why).

    Returns: ``bottleneck_kind``, ``bottleneck_s_m``, ``bottleneck_active``,
    ``bottleneck_active_share``, ``discharge_flow_vph``, ``discharge_t0_s``,
    ``discharge_t1_s``, ``discharge_drift``, ``discharge_stationary``,
    ``upstream_speed_ratio``, ``downstream_speed_ratio``, ``entrance_speed_ratio``
    (means over the measured bins), the :func:`entrance_check` fields and
    ``capacity_note``.
    """
    out: dict = {
        "bottleneck_kind": layout.bottleneck.kind if layout.bottleneck else "",
        "bottleneck_s_m": layout.bottleneck.s_m if layout.bottleneck else math.nan,
        "bottleneck_active": False,
        "bottleneck_active_share": math.nan,
        "discharge_flow_vph": math.nan,
        "discharge_t0_s": math.nan,
        "discharge_t1_s": math.nan,
        "discharge_drift": math.nan,
        "discharge_stationary": False,
        "upstream_speed_ratio": math.nan,
        "downstream_speed_ratio": math.nan,
        "entrance_speed_ratio": math.nan,
    }
    notes = [layout.note] if layout.note else []
    bins = data.measured_bins()
    if layout.periodic:
        out.update(entrance_check(np.zeros(0), np.zeros(0), False))
        out["capacity_note"] = "; ".join(notes)
        return out
    if len(bins) == 0:
        notes.append("no complete measurement bin after the warm-up")
    starts = bins * data.bin_s
    active_ok = False
    if layout.measures_discharge and len(bins):
        up = data.ratio("upstream")
        down = data.ratio("downstream")
        out["upstream_speed_ratio"] = _nanmean(up)
        out["downstream_speed_ratio"] = _nanmean(down)
        active = queued(up) & unqueued(down)
        win = discharge_window(active, starts, data.bin_s)
        measured_s = len(bins) * data.bin_s
        if win is None:
            notes.append("bottleneck never active (no queue upstream with unqueued flow "
                         "downstream)")
        else:
            t0, t1, share = win
            out["bottleneck_active_share"] = share
            long_enough = (t1 - t0 >= MIN_WINDOW_S - 1e-9
                           and t1 - t0 >= MIN_WINDOW_SHARE * measured_s - 1e-9)
            active_ok = long_enough and share >= ACTIVE_SHARE
            if not long_enough:
                notes.append(f"bottleneck active for only {t1 - t0:g} s of the "
                             f"{measured_s:g} s measured")
            elif share < ACTIVE_SHARE:
                notes.append(f"bottleneck active in only {share:.0%} of its window")
            out.update(discharge_t0_s=t0, discharge_t1_s=t1)
            out["discharge_flow_vph"] = discharge_flow(data.crossings, t0, t1)
            tm = 0.5 * (t0 + t1)
            out["discharge_drift"] = relative_drift(discharge_flow(data.crossings, t0, tm),
                                                    discharge_flow(data.crossings, tm, t1))
            out["discharge_stationary"] = is_stationary(out["discharge_drift"])
    out["bottleneck_active"] = bool(active_ok)
    if len(bins) and layout.entrance_zone_m is not None:
        ent = data.ratio("entrance")
        out["entrance_speed_ratio"] = _nanmean(ent)
        out.update(entrance_check(ent, data.waiting(), active_ok))
    else:
        out.update(entrance_check(np.zeros(0), np.zeros(0), active_ok))
    if out["entrance_limited"]:
        notes.append("entrance-limited: the entrance, not the road, set the flow")
    out["capacity_note"] = "; ".join(n for n in notes if n)
    return out


def _nanmean(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(x.mean()) if len(x) else math.nan
