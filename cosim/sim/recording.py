"""Recorders that attach to the loop's ``record`` phase: traffic, jams, capacity, flock,
trajectories.

Each reads the :class:`~cosim.sim.world.RoadSnapshot` of the step (the state after it)
and keeps what it measures; :func:`attach_recorders` wires them all for a run and
:meth:`Recorders.results` turns them into the run's tables.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from controllers import protocol
from cosim.metrics import capacity as cap
from cosim.metrics import kernels as K
from cosim.metrics.flock import flock_metrics
from cosim.metrics.jams import UNALIGNED, JamRecorder, align
from cosim.metrics.traffic import StepState, TrafficRecorder
from cosim.sim.loop import Loop, StepData

FLOCK_SAMPLE_S = 1.0  # s between flock-metric samples
#: |acceleration| above this is harsh (comfort column), m/s^2.
HARSH_ACCEL_MPS2 = 3.0
#: How often the capacity recorder asks the world for its pending insertions, s.
PENDING_SAMPLE_S = 1.0
_NO_VALUES = np.zeros(0)  # placeholders for the kernels' unused arguments
_NO_ROWS = np.zeros(0, dtype=np.int64)


def step_state(st: StepData, road) -> StepState:
    """The vehicles on the main route as the traffic metrics see them."""
    state = st.state
    if state.on_main.all():  # every vehicle on the main route (the usual case): no copies
        edges = road.edges(state.s) if len(state.s) else np.zeros((0, 2))
        return StepState(
            t=st.t, ids=list(state.ids), s=state.s, s_front=state.s_front, d=state.d,
            v=state.v, v_lat=state.v_lat, length=state.length, width=state.width,
            is_cav=state.is_cav, edge_right=edges[:, 0], edge_left=edges[:, 1],
            is_static=state.is_static, desired=state.desired,
        )
    rows = np.flatnonzero(state.on_main)
    edges = road.edges(state.s[rows]) if len(rows) else np.zeros((0, 2))
    ids = list(map(state.ids.__getitem__, rows.tolist()))
    return StepState(
        t=st.t, ids=ids, s=state.s[rows], s_front=state.s_front[rows],
        d=state.d[rows], v=state.v[rows], v_lat=state.v_lat[rows], length=state.length[rows],
        width=state.width[rows], is_cav=state.is_cav[rows], edge_right=edges[:, 0],
        edge_left=edges[:, 1], is_static=state.is_static[rows], desired=state.desired[rows],
    )


@dataclass
class Recorders:
    """The recorders of one run (see :func:`attach_recorders`)."""

    traffic: TrafficRecorder
    jams: JamRecorder
    capacity: CapacityRecorder | None = None
    flock_rows: list[dict] = field(default_factory=list)
    trajectories: list[pd.DataFrame] = field(default_factory=list)
    departed: set = field(default_factory=set)
    arrived: set = field(default_factory=set)
    max_pending: int = 0
    prev_ids: list = field(default_factory=list)  # the vehicles of the last recorded step

    def flock_table(self) -> pd.DataFrame:
        return pd.DataFrame(self.flock_rows)

    def trajectory_table(self) -> pd.DataFrame | None:
        return pd.concat(self.trajectories, ignore_index=True) if self.trajectories else None


def attach_recorders(loop: Loop, traffic: TrafficRecorder, jams: JamRecorder, *,
                     warmup_s: float, trajectories_every: int = 0,
                     flock_sample_s: float = FLOCK_SAMPLE_S,
                     capacity: CapacityRecorder | None = None) -> Recorders:
    """Hook the recorders into ``loop``'s ``record`` phase; returns them."""
    rec = Recorders(traffic, jams, capacity)
    world = loop.world
    sample_every = max(1, int(round(flock_sample_s / loop.dt)))
    lattice = protocol.lattice(loop.law) if loop.law is not None else None

    def on_record(st: StepData) -> None:
        rec.departed.update(world.departed_now)
        rec.arrived.update(world.arrived_now)
        ss = step_state(st, world.road)
        # every recorder sees every step: their previous vehicles are these, aligned once
        ss.prev_rows = align(rec.prev_ids, ss.ids)
        rec.prev_ids = ss.ids
        traffic.record(ss, world.collisions())
        jams.record(st.t, ss.ids, ss.s_front, ss.v, ss.is_static, prev_rows=ss.prev_rows,
                    is_cav=ss.is_cav)
        if capacity is not None:
            new = [v for v in world.departed_now if v != loop.obstacle_id]
            capacity.record(ss, world.pending, len(new))
        if st.k % sample_every == 0 and st.t > warmup_s:
            _flock_sample(rec, ss, st.t, lattice, loop.law, world.period)
        if trajectories_every and st.k % trajectories_every == 0:
            rec.trajectories.append(pd.DataFrame({
                "t_s": st.t, "id": ss.ids, "s_m": ss.s, "d_m": ss.d, "v_mps": ss.v,
                "v_lat_mps": ss.v_lat, "length_m": ss.length, "width_m": ss.width,
                "is_cav": ss.is_cav,
            }))

    loop.hooks.add("record", on_record)
    return rec


def _flock_sample(rec: Recorders, ss: StepState, t: float, lattice, law, period) -> None:
    cav = ss.is_cav & ~ss.is_static
    if cav.sum() < 2:
        return
    q = np.column_stack([ss.s[cav], ss.d[cav]])
    p = np.column_stack([ss.v[cav], ss.v_lat[cav]])
    row = {"t_s": t, "n_cav": int(cav.sum())}
    d, r = lattice if lattice is not None else (np.nan, np.nan)
    metrics = flock_metrics(q, p, d if lattice else 1.0, r if lattice else 1.0, period=period)
    if lattice is None:  # no lattice of its own: lattice metrics do not apply
        metrics["deviation_energy_m2"] = np.nan
        metrics["n_components"] = np.nan
        metrics["largest_component_share"] = np.nan
    row.update(metrics)
    if law is not None:
        row.update(protocol.extra_metrics(law))
    rec.flock_rows.append(row)


class CapacityRecorder:
    """Bins of zone sums, crossing times, pending insertions, harsh accelerations and CAV
    distance: the data of :mod:`cosim.metrics.capacity` and of the comfort columns.

    Per step (state after it, at ``t``; the step covers ``(t - dt, t]`` and counts in the
    bin of its middle):

    * each zone of ``layout`` (entrance, upstream, downstream): time spent (s), distance
      travelled (m) and distance at the desired speeds (m, vehicles with a known desired
      speed) of the traffic in it (obstacles excluded);
    * each count cross-section: the time (linearly interpolated within the step, s) at
      which a vehicle's front passed it;
    * every :data:`PENDING_SAMPLE_S`: ``pending()``, the vehicles waiting to be inserted
      (the bin keeps the most), and in every step the vehicles inserted (the bin keeps
      the running total), for the backlog against ``demand_vph``;
    * after the warm-up, per CAV- and HDV-step: whether ``|dv/dt| > HARSH_ACCEL_MPS2``
      (speed change over the step of a vehicle present in both steps);
    * over the whole run: the distance driven by CAVs (km), the base of the safety layer's
      activations per vehicle-km (the safety layer counts over the whole run too).

    Per-step cost: one compiled pass over the vehicles, and when the vehicles changed one
    C-level dictionary look-up per vehicle (:func:`cosim.metrics.jams.align`, shared by the
    recorders of a run through ``StepState.prev_rows``).

    Args:
        dt: step, s. layout: zones and cross-sections. warmup_s: start of the measured
        period, s. duration_s: length of the run, s. bin_s: bin length, s.
        demand_vph: the demand's mean arrival rate on open roads (main and ramp), veh/h.
        preloaded: vehicles of a standing queue placed at t = 0 (not counted as inserted).
    """

    def __init__(self, dt: float, layout: cap.Layout, warmup_s: float, duration_s: float,
                 bin_s: float = cap.BIN_S, demand_vph: float = 0.0,
                 preloaded: int = 0) -> None:
        self.dt = float(dt)
        self.layout = layout
        self.warmup_s = float(warmup_s)
        self.duration_s = float(duration_s)
        self.bin_s = float(bin_s)
        n_bins = int(np.ceil(duration_s / bin_s)) + 1
        self.zones = layout.zones
        # per zone: tts, ttd, tdd by bin (views of one array the kernel adds to)
        self._sums_all = np.zeros((len(self.zones), 3, n_bins))
        self._sums = {name: self._sums_all[z] for z, name in enumerate(self.zones)}
        self._zone_bounds = np.array([self.zones[name] for name in self.zones],
                                     dtype=float).reshape(len(self.zones), 2)
        self.pending = np.zeros(n_bins)
        self.inserted = np.zeros(n_bins)
        self.demand_vph = float(demand_vph)
        # the arrivals' insertions only: a standing queue placed at t = 0 (``preloaded``
        # vehicles, demand.queue_vpkm) is not demand
        self._n_inserted = -int(preloaded)
        self.xs = np.asarray(layout.sections_m, dtype=float)
        self._crossings: list[list[float]] = [[] for _ in self.xs]
        self._pending_every = max(1, int(round(PENDING_SAMPLE_S / dt)))
        self._k = 0
        self._prev_ids: list = []
        self._prev_front = np.zeros(0)
        self._prev_v = np.zeros(0)
        self.harsh = {"cav": [0, 0], "hdv": [0, 0]}  # harsh steps, steps
        self.cav_distance_m = 0.0
        self.t_end_s = 0.0

    def record(self, ss: StepState, pending=None, n_departed: int = 0) -> None:
        """Add one step; ``pending()`` returns the vehicles waiting to be inserted,
        ``n_departed`` the vehicles inserted in this step. The per-vehicle arithmetic is one
        compiled pass (:func:`cosim.metrics.kernels.capacity_tallies`)."""
        t = ss.t
        self.t_end_s = t
        b = min(int((t - 0.5 * self.dt) // self.bin_s), self.pending.shape[0] - 1)
        self._n_inserted += int(n_departed)
        self.inserted[b] = self._n_inserted
        n = len(ss.s)
        static = np.zeros(n, dtype=bool) if ss.is_static is None else ss.is_static
        ids = list(ss.ids)  # a copy: kept for the next step
        idx = align(self._prev_ids, ids) if ss.prev_rows is UNALIGNED else ss.prev_rows
        (sec, frac, harsh_cav, n_cav, harsh_hdv, n_hdv, cav_speed, any_seen) = \
            K.capacity_tallies(
                ss.s, ss.s_front, ss.v, ss.is_cav, static,
                _NO_VALUES if ss.desired is None else np.asarray(ss.desired, dtype=float),
                ss.desired is not None, self._zone_bounds, self._sums_all, b, self.dt,
                _NO_ROWS if idx is None else idx, idx is None, self._prev_front,
                self._prev_v, self.xs, t > self.warmup_s + 1e-9, HARSH_ACCEL_MPS2)
        if pending is not None and self._k % self._pending_every == 0:
            self.pending[b] = max(self.pending[b], float(pending()))
        self._k += 1
        if len(sec):
            for k in np.unique(sec).tolist():
                self._crossings[k].extend((t - self.dt + frac[sec == k] * self.dt).tolist())
        if any_seen and t > self.warmup_s + 1e-9:
            self.harsh["cav"][0] += int(harsh_cav)
            self.harsh["cav"][1] += int(n_cav)
            self.harsh["hdv"][0] += int(harsh_hdv)
            self.harsh["hdv"][1] += int(n_hdv)
        self.cav_distance_m += self.dt * float(cav_speed)
        self._prev_ids = ids
        self._prev_front = np.asarray(ss.s_front, dtype=float)
        self._prev_v = np.asarray(ss.v, dtype=float)

    def data(self) -> cap.CapacityData:
        """The recorded data for :func:`cosim.metrics.capacity.assess`."""
        return cap.CapacityData(
            bin_s=self.bin_s, warmup_s=self.warmup_s, t_end_s=self.t_end_s,
            zone_tts_s={n: s[0].copy() for n, s in self._sums.items()},
            zone_ttd_m={n: s[1].copy() for n, s in self._sums.items()},
            zone_tdd_m={n: s[2].copy() for n, s in self._sums.items()},
            pending=self.pending.copy(),
            inserted=self.inserted.copy(), demand_vph=self.demand_vph,
            crossings=[np.sort(np.asarray(c, dtype=float)) for c in self._crossings],
        )

    def comfort(self) -> dict:
        """``harsh_accel_share_cav`` / ``_hdv`` (share of CAV- / HDV-steps after the warm-up
        with ``|a| > HARSH_ACCEL_MPS2``; NaN without such steps) and ``cav_vehicle_km``."""
        out = {}
        for kind in ("cav", "hdv"):
            n_harsh, n = self.harsh[kind]
            out[f"harsh_accel_share_{kind}"] = n_harsh / n if n else float("nan")
        out["cav_vehicle_km"] = self.cav_distance_m / 1000.0
        return out

    def series(self) -> dict:
        """Compact per-bin series for meta.json (figures: N-curves, speed ratios)."""
        n = int(np.ceil(self.t_end_s / self.bin_s - 1e-9))
        out: dict = {"bin_s": self.bin_s, "zones_m": {k: list(v) for k, v in self.zones.items()},
                     "sections_m": self.xs.tolist(),
                     "pending": self.pending[:n].astype(int).tolist(),
                     "inserted": self.inserted[:n].astype(int).tolist(),
                     "demand_vph": self.demand_vph}
        for name, sums in self._sums.items():
            ratio = cap.speed_ratio(sums[1, :n], sums[2, :n])
            out[f"{name}_speed_ratio"] = [None if not np.isfinite(r) else round(float(r), 4)
                                          for r in ratio]
        edges = np.arange(n + 1) * self.bin_s
        out["section_counts"] = [np.histogram(c, bins=edges)[0].tolist() if len(edges) > 1
                                 else [] for c in self._crossings]
        return out
