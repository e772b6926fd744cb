"""The record phase's recorders give exactly what they gave before issue 15's speed-up.

``cosim/metrics/jams.py`` (JamRecorder), ``cosim/sim/recording.py`` (step_state,
_flock_sample, CapacityRecorder) and ``cosim/metrics/flock.py`` (flock_metrics and the
proximity net) were vectorised: no Python loop per vehicle, no dictionaries rebuilt every
step, the proximity net and nearest-neighbour distances computed once per sample. Below
are verbatim copies of the code before that change (``Old*`` / ``old_*``; only the names
changed, and the old jam recorder accepts and ignores the ``prev_rows`` its caller now
passes) and the new code must agree with them bit for bit: on synthetic step sequences
(vehicles entering and leaving, standstills, obstacles, straight road and ring) and on
whole SUMO-free road-world runs (``scenario.world = "road"``), whose summary, intervals,
flock, collisions and meta tables must be identical with the old recorders patched in.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from controllers import protocol
from controllers.neighbours import neighbour_pairs, tree_points
from controllers.observation import Circles, Walls
from cosim.metrics import capacity as cap
from cosim.metrics import flock as new_flock
from cosim.metrics.jams import UPSTREAM_M, JamRecorder, align
from cosim.metrics.traffic import StepState
from cosim.sim import recording, runner
from cosim.sim.loop import StepData
from cosim.sim.recording import (
    HARSH_ACCEL_MPS2,
    PENDING_SAMPLE_S,
    CapacityRecorder,
    Recorders,
)

# ======================================================================================
# The code before the change, verbatim (only the names carry an old_ / Old prefix)
# ======================================================================================


class OldJamRecorder:
    """Accumulate jam figures step by step (see the module docstring).

    Args:
        dt: step, s. warmup_s: start of the windows, s. cross_sections: (K,) m.
        period: ring length, m, or None. v_stop: standstill speed, m/s.
        long_s: long-standstill threshold and window length, s.
    """

    def __init__(self, dt: float, warmup_s: float, cross_sections, period: float | None,
                 v_stop: float = 0.5, long_s: float = 30.0) -> None:
        self.dt = dt
        self.warmup_s = warmup_s
        self.xs = np.asarray(cross_sections, dtype=float)
        self.period = period
        self.v_stop = v_stop
        self.long_s = long_s
        self._since: dict = {}  # id -> time the standstill began, s
        self.max_standstill_s = 0.0
        self._long_ids: set = set()
        self._prev_front: dict = {}
        self._win_start: float | None = None
        self._win_crossed = np.zeros(len(self.xs), dtype=bool)
        self._win_waiting = np.ones(len(self.xs), dtype=bool)
        self.blocked_windows = 0
        self.blocked_log: list[dict] = []

    def record(self, t: float, ids: list, s_front: np.ndarray, v: np.ndarray,
               is_static: np.ndarray, prev_rows=None,
               is_cav=None) -> None:  # prev_rows, is_cav: ignored (no split by kind)
        """One step: ids (M,), front positions (M,) m, speeds (M,) m/s, obstacle mask (M,)."""
        moving_ids = set()
        stopped = (v < self.v_stop) & ~is_static
        for vid, stop in zip(ids, stopped, strict=True):
            if stop:
                t0 = self._since.setdefault(vid, t)
                dur = t - t0
                if dur > self.max_standstill_s:
                    self.max_standstill_s = dur
                if dur > self.long_s:
                    self._long_ids.add(vid)
            else:
                moving_ids.add(vid)
        for vid in moving_ids:
            self._since.pop(vid, None)
        present = set(ids)
        for vid in [k for k in self._since if k not in present]:
            del self._since[vid]
        self._windows(t, ids, s_front, stopped, is_static)

    def _windows(self, t, ids, s_front, stopped, is_static) -> None:
        if not len(self.xs) or t <= self.warmup_s + 1e-9:
            self._prev_front = dict(zip(ids, s_front, strict=True))
            return
        if self._win_start is None:
            self._win_start = self.warmup_s
        # crossings since the last step
        prev = np.array([self._prev_front.get(k, np.nan) for k in ids])
        ok = np.isfinite(prev) & ~is_static
        cur, prv = s_front[ok], prev[ok]
        if self.period is not None:
            cur = np.where(cur < prv - 0.5 * self.period, cur + self.period, cur)
        for k, x in enumerate(self.xs):
            hit = (prv < x) & (cur >= x)
            if self.period is not None:
                hit |= (prv < x + self.period) & (cur >= x + self.period)
            if hit.any():
                self._win_crossed[k] = True
            up = x - s_front
            if self.period is not None:
                up = np.mod(up, self.period)
            waiting = stopped & (up >= 0) & (up <= UPSTREAM_M)
            if not waiting.any():
                self._win_waiting[k] = False
        self._prev_front = dict(zip(ids, s_front, strict=True))
        if t >= self._win_start + self.long_s - 1e-9:
            blocked = ~self._win_crossed & self._win_waiting
            for k in np.flatnonzero(blocked):
                self.blocked_log.append({"t_start_s": self._win_start, "t_end_s": t,
                                         "cross_section_m": float(self.xs[k])})
            self.blocked_windows += int(np.count_nonzero(blocked))
            self._win_start = t
            self._win_crossed[:] = False
            self._win_waiting[:] = True

    def summary(self) -> dict:
        """The run's jam figures (units in the names)."""
        return {
            "max_standstill_s": float(self.max_standstill_s),
            "vehicles_stopped_long": len(self._long_ids),
            "long_standstill_s": float(self.long_s),
            "blocked_windows": int(self.blocked_windows),
            "gridlock": bool(self.blocked_windows > 0),
        }


def old_step_state(st: StepData, road) -> StepState:
    """The vehicles on the main route as the traffic metrics see them."""
    state = st.state
    rows = np.flatnonzero(state.on_main)
    edges = road.edges(state.s[rows]) if len(rows) else np.zeros((0, 2))
    return StepState(
        t=st.t, ids=[state.ids[r] for r in rows], s=state.s[rows], s_front=state.s_front[rows],
        d=state.d[rows], v=state.v[rows], v_lat=state.v_lat[rows], length=state.length[rows],
        width=state.width[rows], is_cav=state.is_cav[rows], edge_right=edges[:, 0],
        edge_left=edges[:, 1], is_static=state.is_static[rows], desired=state.desired[rows],
    )


def old_flock_sample(rec: Recorders, ss: StepState, t: float, lattice, law, period) -> None:
    cav = ss.is_cav & ~ss.is_static
    if cav.sum() < 2:
        return
    q = np.column_stack([ss.s[cav], ss.d[cav]])
    p = np.column_stack([ss.v[cav], ss.v_lat[cav]])
    row = {"t_s": t, "n_cav": int(cav.sum())}
    d, r = lattice if lattice is not None else (np.nan, np.nan)
    metrics = old_flock_metrics(q, p, d if lattice else 1.0, r if lattice else 1.0, period=period)
    if lattice is None:  # no lattice of its own: lattice metrics do not apply
        metrics["deviation_energy_m2"] = np.nan
        metrics["n_components"] = np.nan
        metrics["largest_component_share"] = np.nan
    row.update(metrics)
    if law is not None:
        row.update(protocol.extra_metrics(law))
    rec.flock_rows.append(row)


def old_nearest_neighbour_distances(q: np.ndarray, period: float | None = None) -> np.ndarray:
    """Distance from each agent to its nearest other agent, (N,) m (inf if N < 2)."""
    if len(q) < 2:
        return np.full(len(q), np.inf)
    q = np.asarray(q, dtype=float)
    # The lateral box must exceed the lateral span so that only axis 0 wraps.
    span = float(np.ptp(q[:, 1:])) if q.shape[1] > 1 else 0.0
    pts, box = tree_points(q, max(1.0, span), period)
    dist, _ = cKDTree(pts, boxsize=box).query(pts, k=2)
    return dist[:, 1]


def old_min_pair_distance(q: np.ndarray, period: float | None = None) -> float:
    """Minimum centre distance between any two agents, m (seed 003 Fig. "minimum distance")."""
    return float(np.min(old_nearest_neighbour_distances(q, period))) if len(q) > 1 else np.inf


def old_average_nn_distance(q: np.ndarray, period: float | None = None) -> float:
    """Mean over agents of the nearest-neighbour distance, m (seed 004 avg_neighbor_distance)."""
    return float(np.mean(old_nearest_neighbour_distances(q, period))) if len(q) > 1 else np.nan


def old_min_obstacle_distance(
    q: np.ndarray, circles: Circles | None = None, walls: Walls | None = None
) -> float:
    """Minimum distance from any agent to a circle's surface or a wall, m (negative: inside)."""
    best = np.inf
    if circles is not None and len(circles.radii):
        for y, r in zip(circles.centres, circles.radii, strict=True):
            best = min(best, float(np.min(np.linalg.norm(q - y, axis=1) - r)))
    if walls is not None and len(walls.points):
        for y, a in zip(walls.points, walls.normals, strict=True):
            best = min(best, float(np.min((q - y) @ a)))
    return best


def old_velocity_mismatch(p: np.ndarray, p_ref: np.ndarray | None = None) -> float:
    """Mean squared velocity deviation ``(1/N) sum ||p_i - p_c||^2``, m^2/s^2.

    ``p_c`` is the flock's mean velocity, or ``p_ref`` (the leader's) when given:
    twice the kinetic energy of relative motion per agent (OS06 Sec. VIII).
    """
    if len(p) == 0:
        return np.nan
    c = p.mean(axis=0) if p_ref is None else np.asarray(p_ref)
    return float(np.mean(np.sum((p - c) ** 2, axis=1)))


def old_deviation_energy(q: np.ndarray, d: float, r: float, period: float | None = None) -> float:
    """Lattice deviation energy ``E = 1/(|E|+1) sum_(i,j in E) (||q_j - q_i|| - d)^2``, m^2.

    OS06 eq. 7 with the proximity net of range ``r`` (directed edges, so each
    undirected pair counts twice in the sum and in ``|E|``). Zero for a perfect
    alpha-lattice.
    """
    pairs = neighbour_pairs(q, r, period, "auto")
    if len(pairs) == 0:
        return 0.0
    dq = q[pairs[:, 1]] - q[pairs[:, 0]]
    if period is not None:
        dq[:, 0] = (dq[:, 0] + 0.5 * period) % period - 0.5 * period
    dev = np.linalg.norm(dq, axis=1) - d
    return float(2.0 * np.sum(dev**2) / (2 * len(pairs) + 1))


def old_velocity_alignment(p: np.ndarray) -> float:
    """Order parameter ``||(1/N) sum p_i / ||p_i||||`` in [0, 1] (1: all headings equal)."""
    speed = np.linalg.norm(p, axis=1)
    moving = speed > 1e-12
    if not moving.any():
        return np.nan
    return float(np.linalg.norm(np.mean(p[moving] / speed[moving, None], axis=0)))


def old_dispersion(q: np.ndarray) -> float:
    """Group spatial dispersion ``sqrt(sum_k var(q[:, k]))``, m (seed 004; sample variance)."""
    if len(q) < 2:
        return 0.0
    return float(np.sqrt(np.sum(np.var(q, axis=0, ddof=1))))


def old_connectivity(q: np.ndarray, r: float, period: float | None = None) -> tuple[int, float]:
    """Proximity-graph connectivity: (number of components, largest component share).

    Graph edges join agents closer than ``r`` (m), OS06's proximity net.
    """
    n = len(q)
    if n == 0:
        return 0, np.nan
    pairs = neighbour_pairs(q, r, period, "auto")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    k, labels = connected_components(graph, directed=False)
    return int(k), float(np.bincount(labels).max() / n)


def old_flock_metrics(
    q: np.ndarray,
    p: np.ndarray,
    d: float,
    r: float,
    p_ref: np.ndarray | None = None,
    circles: Circles | None = None,
    walls: Walls | None = None,
    period: float | None = None,
) -> dict[str, float]:
    """All flock metrics of one instant, keyed by column name (units in the name)."""
    n_comp, largest = old_connectivity(q, r, period)
    return {
        "min_agent_distance_m": old_min_pair_distance(q, period),
        "min_obstacle_distance_m": old_min_obstacle_distance(q, circles, walls),
        "velocity_mismatch_m2ps2": old_velocity_mismatch(p),
        "leader_velocity_mismatch_m2ps2": (
            old_velocity_mismatch(p, p_ref) if p_ref is not None else np.nan
        ),
        "deviation_energy_m2": old_deviation_energy(q, d, r, period),
        "avg_nn_distance_m": old_average_nn_distance(q, period),
        "velocity_alignment": old_velocity_alignment(p),
        "dispersion_m": old_dispersion(q),
        "n_components": n_comp,
        "largest_component_share": largest,
    }


class OldCapacityRecorder:
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

    Per-step cost: one dictionary look-up per vehicle and a few vectorised masks.

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
        self._sums = {name: np.zeros((3, n_bins)) for name in self.zones}  # tts, ttd, tdd
        self.pending = np.zeros(n_bins)
        self.inserted = np.zeros(n_bins)
        self.demand_vph = float(demand_vph)
        self._n_inserted = -int(preloaded)
        self.xs = np.asarray(layout.sections_m, dtype=float)
        self._crossings: list[list[float]] = [[] for _ in self.xs]
        self._pending_every = max(1, int(round(PENDING_SAMPLE_S / dt)))
        self._k = 0
        self._prev_index: dict = {}
        self._prev_front = np.zeros(0)
        self._prev_v = np.zeros(0)
        self.harsh = {"cav": [0, 0], "hdv": [0, 0]}  # harsh steps, steps
        self.cav_distance_m = 0.0
        self.t_end_s = 0.0

    def record(self, ss: StepState, pending=None, n_departed: int = 0) -> None:
        """Add one step; ``pending()`` returns the vehicles waiting to be inserted,
        ``n_departed`` the vehicles inserted in this step."""
        t = ss.t
        self.t_end_s = t
        b = min(int((t - 0.5 * self.dt) // self.bin_s), self.pending.shape[0] - 1)
        self._n_inserted += int(n_departed)
        self.inserted[b] = self._n_inserted
        static = np.zeros(len(ss.s), dtype=bool) if ss.is_static is None else ss.is_static
        traffic = ~static
        desired = (np.full(len(ss.s), np.nan) if ss.desired is None
                   else np.asarray(ss.desired, dtype=float))
        known = np.isfinite(desired)
        for name, (z0, z1) in self.zones.items():
            m = traffic & (ss.s >= z0) & (ss.s < z1)
            if m.any():
                sums = self._sums[name]
                mk = m & known
                sums[0, b] += self.dt * int(np.count_nonzero(m))
                sums[1, b] += self.dt * float(np.sum(ss.v[mk]))
                sums[2, b] += self.dt * float(np.sum(desired[mk]))
        if pending is not None and self._k % self._pending_every == 0:
            self.pending[b] = max(self.pending[b], float(pending()))
        self._k += 1

        idx = np.fromiter((self._prev_index.get(i, -1) for i in ss.ids), dtype=np.int64,
                          count=len(ss.ids))
        seen = idx >= 0
        if len(self.xs) and seen.any():
            prv = self._prev_front[idx[seen]]
            cur = ss.s_front[seen]
            for k, x in enumerate(self.xs):
                hit = (prv < x) & (cur >= x)
                if hit.any():
                    frac = (x - prv[hit]) / np.maximum(cur[hit] - prv[hit], 1e-9)
                    self._crossings[k].extend((t - self.dt + frac * self.dt).tolist())
        if t > self.warmup_s + 1e-9 and seen.any():
            acc = (ss.v[seen] - self._prev_v[idx[seen]]) / self.dt
            harsh = np.abs(acc) > HARSH_ACCEL_MPS2
            is_cav = ss.is_cav[seen]
            moving = traffic[seen]
            for kind, mask in (("cav", is_cav & moving), ("hdv", ~is_cav & moving)):
                self.harsh[kind][0] += int(np.count_nonzero(harsh & mask))
                self.harsh[kind][1] += int(np.count_nonzero(mask))
        cav = ss.is_cav & traffic
        self.cav_distance_m += self.dt * float(np.sum(ss.v[cav]))
        self._prev_index = {vid: k for k, vid in enumerate(ss.ids)}
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


# ======================================================================================
# Synthetic step sequences
# ======================================================================================

DT = 0.5  # s


def _traffic(seed: int, n_steps: int, period: float | None, length: float = 600.0):
    """Steps of a few vehicles that enter and leave, stand still in runs (a stopped
    vehicle keeps its place), some obstacles; yields (t, ids, s, s_front, v, static,
    desired, is_cav). Ids are unique within a step and never reused (as in SUMO)."""
    rng = np.random.default_rng(seed)
    road = period if period is not None else length
    veh: dict = {}  # id -> [front position m, speed m/s, stopped, static, desired, cav]
    next_id = 0
    for k in range(n_steps):
        t = (k + 1) * DT
        if rng.random() < 0.35 or len(veh) < 3:  # someone enters
            vid = f"v{next_id}"
            next_id += 1
            static = rng.random() < 0.05
            veh[vid] = [float(rng.uniform(0.0, 0.3 * road)), 0.0, static, static,
                        float(rng.uniform(20, 30)) if rng.random() < 0.8 else np.nan,
                        bool(rng.random() < 0.7)]
        for vid in list(veh):
            f, _, stopped, static, _, _ = veh[vid]
            if not static and rng.random() < (0.04 if stopped else 0.03):
                stopped = not stopped
            v = 0.0 if (stopped or static) else float(rng.choice([0.3, 8.0, 12.0, 20.0]))
            f = f + v * DT
            if period is not None:
                f = f % period
            elif f > length or rng.random() < 0.01:  # leaves at the end or takes an exit
                del veh[vid]
                continue
            veh[vid][:3] = [f, v, stopped]
        ids = list(veh)
        if rng.random() < 0.3:  # the order of the list changes now and then
            rng.shuffle(ids)
        arr = np.array([veh[i] for i in ids], dtype=float).reshape(-1, 6)
        s_front = arr[:, 0]
        yield (t, ids, s_front - 2.25, s_front, arr[:, 1], arr[:, 3].astype(bool), arr[:, 4],
               arr[:, 5].astype(bool))


JAM_CASES = [(seed, period, warmup, xs)
             for seed in (0, 1, 2)
             for period, xs in ((None, (150.0, 300.0, 450.0)), (500.0, (0.0, 120.0, 499.0)),
                                (None, ()))
             for warmup in (0.0, 20.0)]


@pytest.mark.parametrize(("seed", "period", "warmup", "xs"), JAM_CASES)
def test_jam_recorder_matches_the_old_one_step_by_step(seed, period, warmup, xs):
    old = OldJamRecorder(DT, warmup, xs, period, v_stop=0.5, long_s=5.0)
    new = JamRecorder(DT, warmup, xs, period, v_stop=0.5, long_s=5.0)
    for t, ids, _, front, v, static, _, _ in _traffic(seed, 600, period):
        old.record(t, list(ids), front.copy(), v.copy(), static.copy())
        new.record(t, list(ids), front.copy(), v.copy(), static.copy())
        assert new._since == old._since
        assert new.max_standstill_s == old.max_standstill_s
        assert new._long_ids == old._long_ids
        assert new.blocked_log == old.blocked_log
        assert new._win_start == old._win_start
    assert new.summary() == old.summary()


@pytest.mark.slow(seconds=5)
def test_the_jam_cases_exercise_what_they_compare():
    """The synthetic sequences have long standstills and blocked windows (or the step-by-step
    comparison above would compare zeros)."""
    blocked, long_ = 0, 0
    for seed, period, warmup, xs in JAM_CASES:
        rec = JamRecorder(DT, warmup, xs, period, v_stop=0.5, long_s=5.0)
        for t, ids, _, front, v, static, _, _ in _traffic(seed, 600, period):
            rec.record(t, ids, front, v, static)
        blocked += rec.blocked_windows
        long_ += rec.summary()["vehicles_stopped_long"]
    assert blocked >= 5 and long_ >= 20


def test_align_rows_of_the_previous_step():
    assert align(["a", "b"], ["a", "b"]) is None
    assert align(["a", "b", "c"], ["c", "x", "a"]).tolist() == [2, -1, 0]
    assert align([], ["a"]).tolist() == [-1]
    assert align(["a"], []).tolist() == []


def _layout(period: float | None) -> cap.Layout:
    if period is not None:
        return cap.Layout(period, True, None, sections_m=(10.0, 250.0))
    return cap.Layout(600.0, False, None, entrance_zone_m=(0.0, 100.0),
                      upstream_zone_m=(150.0, 300.0), downstream_zone_m=(320.0, 590.0),
                      sections_m=(120.0, 310.0, 450.0))


def _step_states(seed: int, period: float | None, none_fields: bool = False):
    for t, ids, s, front, v, static, desired, is_cav in _traffic(seed, 500, period):
        n = len(ids)
        z = np.zeros(n)
        yield StepState(t=t, ids=ids, s=s, s_front=front, d=z, v=v, v_lat=z, length=z + 4.5,
                        width=z + 1.8, is_cav=is_cav, edge_right=z - 5, edge_left=z + 5,
                        is_static=None if none_fields else static,
                        desired=None if none_fields else desired)


@pytest.mark.parametrize("seed", [0, 3])
@pytest.mark.parametrize("period", [None, 500.0])
@pytest.mark.parametrize("none_fields", [False, True])
def test_capacity_recorder_matches_the_old_one(seed, period, none_fields):
    layout = _layout(period)
    old = OldCapacityRecorder(DT, layout, 30.0, 250.0, bin_s=20.0, demand_vph=3000.0)
    new = CapacityRecorder(DT, layout, 30.0, 250.0, bin_s=20.0, demand_vph=3000.0)
    pending = iter(range(10**6))
    for k, ss in enumerate(_step_states(seed, period, none_fields)):
        p = next(pending) % 7
        old.record(ss, lambda p=p: p, k % 3)
        new.record(ss, lambda p=p: p, k % 3)
    a, b = old.data(), new.data()
    for field in ("bin_s", "warmup_s", "t_end_s", "demand_vph"):
        assert getattr(a, field) == getattr(b, field)
    for field in ("zone_tts_s", "zone_ttd_m", "zone_tdd_m"):
        assert getattr(a, field).keys() == getattr(b, field).keys()
        for key, arr in getattr(a, field).items():
            np.testing.assert_array_equal(getattr(b, field)[key], arr)
    np.testing.assert_array_equal(b.pending, a.pending)
    np.testing.assert_array_equal(b.inserted, a.inserted)
    assert len(a.crossings) == len(b.crossings) == len(layout.sections_m)
    for ca, cb in zip(a.crossings, b.crossings, strict=True):
        np.testing.assert_array_equal(cb, ca)
    assert old._crossings == new._crossings  # the same times in the same order
    assert old.harsh == new.harsh
    assert json.dumps(old.comfort()) == json.dumps(new.comfort())
    assert json.dumps(old.series()) == json.dumps(new.series())
    assert sum(len(c) for c in a.crossings) > 20 and old.harsh["cav"][0] > 0


def _flock_inputs():
    rng = np.random.default_rng(7)
    for n in (0, 1, 2, 3, 40, 64, 65, 300):
        for period in (None, 800.0):
            q = np.column_stack([rng.uniform(0, 800, n), rng.uniform(-4, 4, n)])
            p = np.column_stack([rng.uniform(0, 30, n), rng.normal(0, 0.3, n)])
            yield q, p, period


def _same_dict(a: dict, b: dict) -> bool:
    return list(a) == list(b) and all(
        (type(a[k]) is type(b[k])) and (a[k] == b[k] or (a[k] != a[k] and b[k] != b[k]))
        for k in a)


@pytest.mark.parametrize(("d", "r"), [(29.0, 58.0), (1.0, 1.0), (7.0, 9.5)])
def test_flock_metrics_match_the_old_ones(d, r):
    for q, p, period in _flock_inputs():
        old = old_flock_metrics(q, p, d, r, period=period)
        new = new_flock.flock_metrics(q, p, d, r, period=period)
        assert _same_dict(old, new), (len(q), period, old, new)
        assert new_flock.connectivity(q, r, period) == old_connectivity(q, r, period)
        assert (new_flock.deviation_energy(q, d, r, period)
                == old_deviation_energy(q, d, r, period))


def test_flock_metrics_with_obstacles_and_a_leader_match_the_old_ones():
    q, p, _ = list(_flock_inputs())[-2]
    circles = Circles(centres=np.array([[100.0, 0.0]]), radii=np.array([2.0]))
    walls = Walls(points=np.array([[0.0, -5.0]]), normals=np.array([[0.0, 1.0]]))
    old = old_flock_metrics(q, p, 29.0, 58.0, p_ref=np.array([25.0, 0.0]), circles=circles,
                            walls=walls)
    new = new_flock.flock_metrics(q, p, 29.0, 58.0, p_ref=np.array([25.0, 0.0]),
                                  circles=circles, walls=walls)
    assert _same_dict(old, new)


def test_compiled_flock_sums_match_the_old_ones_on_hard_velocities():
    """The compiled sums (mismatch, alignment, dispersion, deviation energy, nearest
    distances) against the old numpy on velocities that stand still (some or all), carry
    negative zeros or span many orders of magnitude, at N around numpy's pairwise-sum
    blocks (128 values) and nets of hundreds of pairs."""
    rng = np.random.default_rng(19)
    for _ in range(300):
        n = int(rng.choice([2, 7, 8, 9, 127, 128, 129, 257, 400]))
        period = None if rng.random() < 0.5 else 500.0
        q = np.column_stack([rng.uniform(0, 500, n), rng.uniform(-5, 5, n)])
        scale = 10.0 ** rng.uniform(-8, 3, (n, 1))
        p = np.column_stack([rng.uniform(-1, 30, n), rng.normal(0, 0.5, n)]) * scale
        kind = rng.integers(0, 4)
        if kind == 1:
            p[rng.random(n) < 0.5] = 0.0
        elif kind == 2:
            p[:] = 0.0
        elif kind == 3:
            p[rng.random(n) < 0.5] = -0.0
        d, r = float(rng.choice([1.0, 7.0])), float(rng.choice([5.0, 60.0]))
        old = old_flock_metrics(q, p, d, r, period=period)
        new = new_flock.flock_metrics(q, p, d, r, period=period)
        assert _same_dict(old, new), (n, period, kind, old, new)


# ======================================================================================
# Whole road-world runs: new recorders against the old ones patched in
# ======================================================================================

RUNS = {
    "straight": ("default", {"scenario.duration_s": 60.0, "scenario.warmup_s": 10.0,
                             "demand.inflow_vph": 7000.0}),
    "obstacle_jam": ("obstacle", {"scenario.duration_s": 150.0, "scenario.warmup_s": 20.0,
                                  "outputs.long_standstill_s": 5.0,
                                  "demand.inflow_vph": 7000.0}),
    "ring": ("ring", {"scenario.duration_s": 40.0, "scenario.warmup_s": 5.0,
                      "demand.ring_density_vpkm": 200.0, "safety.enabled": False}),
    "varying_width_trajectories": ("varying_width", {
        "scenario.duration_s": 60.0, "scenario.warmup_s": 10.0, "demand.inflow_vph": 7000.0,
        "outputs.trajectories": True}),
    "varying_width_standing_queue": ("varying_width", {
        "scenario.duration_s": 60.0, "scenario.warmup_s": 10.0, "demand.inflow_vph": 4000.0,
        "demand.queue_vpkm": 150.0, "demand.queue_span_m": [50.0, 250.0]}),
}


def _road_run(name: str, over: dict):
    from cosim.config.scenario import load_scenario

    sc = load_scenario(name, {"scenario.world": "road", "scenario.interval_s": 10.0, **over})
    return runner.run_scenario(sc)


def _meta(res) -> str:
    return json.dumps({k: v for k, v in res.meta.items() if k != "wall_time_s"},
                      sort_keys=True, default=str)


@pytest.mark.parametrize("case", sorted(RUNS))
@pytest.mark.slow(seconds=4)
def test_road_world_run_matches_the_old_recorders(case, monkeypatch):
    name, over = RUNS[case]
    new = _road_run(name, over)
    with monkeypatch.context() as m:
        m.setattr(runner, "JamRecorder", OldJamRecorder)
        m.setattr(runner, "CapacityRecorder", OldCapacityRecorder)
        m.setattr(recording, "step_state", old_step_state)
        m.setattr(recording, "_flock_sample", old_flock_sample)
        old = _road_run(name, over)
    # the standstills by kind are new (the old recorder had only the longest of all)
    kinds = ["max_standstill_cav_s", "max_standstill_hdv_s"]
    row = new.summary.iloc[0]
    assert row["max_standstill_s"] == max(row[k] for k in kinds)
    drop = ["wall_time_s"]
    pd.testing.assert_frame_equal(new.summary.drop(columns=drop + kinds),
                                  old.summary.drop(columns=drop), check_exact=True)
    for table in ("intervals", "flock", "collisions", "trajectories"):
        a, b = getattr(old, table), getattr(new, table)
        if a is None:
            assert b is None
            continue
        pd.testing.assert_frame_equal(b, a, check_exact=True)
    assert _meta(new) == _meta(old)
    assert len(new.flock) > 10 and len(new.intervals) >= 3
    if case == "obstacle_jam":  # the jam figures are not all zero
        s = new.summary.iloc[0]
        assert s["max_standstill_s"] > 30.0 and s["vehicles_stopped_long"] > 5


def test_connectivity_with_given_pairs_in_any_order_matches_the_old_one():
    rng = np.random.default_rng(3)
    for q, _, period in _flock_inputs():
        if len(q) < 3:
            continue
        pairs = neighbour_pairs(q, 30.0, period, "auto")
        shuffled = pairs[rng.permutation(len(pairs))]
        want = old_connectivity(q, 30.0, period)
        assert new_flock.connectivity(q, 30.0, period, pairs) == want
        assert new_flock.connectivity(q, 30.0, period, shuffled) == want
        assert (new_flock.deviation_energy(q, 7.0, 30.0, period, pairs)
                == old_deviation_energy(q, 7.0, 30.0, period))


def test_compiled_flock_net_matches_the_old_metrics_on_ties_grids_and_seams():
    """The compiled proximity net, components and nearest distances (m = 2) against the old
    code on states built to break them: positions on grids (equal distances, pairs at
    exactly the radius, duplicates), around the dense/tree switch (64 agents), points on a
    ring's seam."""
    rng = np.random.default_rng(11)
    for _ in range(400):
        n = int(rng.choice([2, 3, 20, 64, 65, 120]))
        period = None if rng.random() < 0.5 else float(rng.choice([100.0, 300.0, 123.4]))
        road = period or float(rng.choice([50.0, 400.0]))
        if rng.random() < 0.5:
            step = float(rng.choice([0.5, 1.0, 2.5, 3.0]))
            s = rng.integers(0, max(int(road / step), 1), n) * step
            d = rng.integers(-4, 5, n) * float(rng.choice([1.0, 0.5, 1.275]))
        else:
            s, d = rng.uniform(0, road, n), rng.uniform(-5, 5, n)
        if period and rng.random() < 0.3:
            k = rng.integers(0, n, max(n // 4, 1))
            s[k] = rng.choice([period - 1e-9, 0.0, -0.0, 1e-12, 0.5 * period], len(k))
        q = np.column_stack([s, d])
        p = np.column_stack([rng.uniform(0, 30, n), rng.normal(0, 0.3, n)])
        d_lat, r = float(rng.choice([1.0, 7.0, 29.0])), float(rng.choice([1.0, 2.5, 3.0, 58.0]))
        assert _same_dict(old_flock_metrics(q, p, d_lat, r, period=period),
                          new_flock.flock_metrics(q, p, d_lat, r, period=period)), (n, period)
