"""The traffic recorder gives exactly what it gave before its per-step arithmetic was
compiled (issue 15).

``TrafficRecorder.record`` was dozens of numpy operations per step; it now runs two
compiled passes (:mod:`cosim.metrics.kernels`). ``OldTrafficRecorder`` below carries a
verbatim copy of the methods before that change (``record`` and ``_record_ttc``; only
the class name changed, the rest is inherited and unchanged), and the new recorder must
agree with it bit for bit: step by step on synthetic sequences (vehicles entering and
leaving, reordered rows, obstacles, bodies over the edges, overlaps, SUMO's collision
list, a straight road and a ring) and on whole SUMO-free road-world runs.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cosim.metrics import kernels as K
from cosim.metrics.jams import align
from cosim.metrics.traffic import (
    IntervalAccumulator,
    StepState,
    TrafficRecorder,
    gaps_and_leaders,
    overlapping_pairs,
    time_to_collision,
)
from cosim.sim import runner


class OldTrafficRecorder(TrafficRecorder):
    """The recorder with its step methods as they were (verbatim)."""

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



# ======================================================================================
# numpy's pairwise sum
# ======================================================================================


def test_np_sum_is_numpys_sum_bit_for_bit():
    rng = np.random.default_rng(0)
    for n in [*range(0, 140), 255, 256, 257, 1000, 1023, 1024, 1025, 4097]:
        for _ in range(5):
            a = rng.standard_normal(n) * 10.0 ** rng.uniform(-3, 3, n)
            assert K.np_sum(a, n) == np.sum(a), n
            assert K.np_sum(a, n // 2) == np.sum(a[: n // 2]), n


# ======================================================================================
# Synthetic steps
# ======================================================================================

DT = 0.5  # s


def _steps(seed: int, n_steps: int, period: float | None, length: float = 600.0,
           none_fields: bool = False):
    """Steps of vehicles that enter, leave, change rows, drift sideways over the edges,
    overlap now and then; with SUMO collision pairs; yields (StepState, sumo pairs)."""
    rng = np.random.default_rng(seed)
    road = period if period is not None else length
    veh: dict = {}  # id -> [front m, speed m/s, d m, static, desired m/s, cav]
    next_id = 0
    for k in range(n_steps):
        t = (k + 1) * DT
        if rng.random() < 0.4 or len(veh) < 4:
            vid = f"v{next_id}"
            next_id += 1
            static = rng.random() < 0.05
            veh[vid] = [float(rng.uniform(0.0, 0.4 * road)), 0.0,
                        float(rng.uniform(-4.5, 4.5)), static,
                        float(rng.uniform(20, 30)) if rng.random() < 0.8 else np.nan,
                        bool(rng.random() < 0.6)]
        for vid in list(veh):
            f, _, d, static, _, _ = veh[vid]
            v = 0.0 if static else float(rng.choice([0.0, 0.5, 8.0, 12.0, 20.0, 31.0]))
            f = f + v * DT
            d = d if static else float(np.clip(d + rng.normal(0, 0.4), -6.0, 6.0))
            if period is not None:
                f = f % period
            elif f > length or rng.random() < 0.01:
                del veh[vid]
                continue
            veh[vid][:3] = [f, v, d]
        ids = list(veh)
        if rng.random() < 0.3:
            rng.shuffle(ids)
        arr = np.array([veh[i] for i in ids], dtype=float).reshape(-1, 6)
        front = arr[:, 0].copy()
        s = front - 2.25
        if period is not None:
            s = np.mod(s, period)
        d = arr[:, 2].copy()
        n = len(ids)
        z = np.zeros(n)
        pairs = []
        if n >= 2 and rng.random() < 0.15:
            a, b = rng.choice(n, 2, replace=False)
            pairs.append((ids[a], ids[b]))
        yield StepState(
            t=t, ids=ids, s=s, s_front=front, d=d, v=arr[:, 1].copy(),
            v_lat=z, length=z + 4.5, width=z + rng.choice([1.8, 2.5]),
            is_cav=arr[:, 5].astype(bool), edge_right=z - 5.1, edge_left=z + 5.1,
            is_static=None if none_fields else arr[:, 3].astype(bool),
            desired=None if none_fields else arr[:, 4].copy()), pairs


_SCALARS = ("vehicle_steps", "measured_vehicle_s", "min_ttc_s", "min_cav_ttc_s", "tet_veh_s",
            "tit_veh_s2", "min_gap_m", "min_cav_gap_m", "min_side_clearance_m",
            "worst_excursion_m", "boundary_vehicle_steps", "boundary_vehicle_steps_cav")


def _same(a, b) -> bool:
    return a == b or (a != a and b != b)


def _compare(old: TrafficRecorder, new: TrafficRecorder) -> None:
    for name in _SCALARS:
        a, b = getattr(old, name), getattr(new, name)
        assert type(a) is type(b) and _same(a, b), (name, a, b)
    assert old._shortfall == new._shortfall
    assert old._boundary_ids == new._boundary_ids
    assert old.collisions_geom == new.collisions_geom
    assert old.collisions_sumo == new.collisions_sumo
    assert old.collision_log == new.collision_log
    assert old._prev_ids == new._prev_ids
    np.testing.assert_array_equal(new._prev_front, old._prev_front)
    assert len(old.rows) == len(new.rows)
    for ra, rb in zip(old.rows, new.rows, strict=True):
        assert list(ra) == list(rb)
        assert all(_same(ra[k], rb[k]) for k in ra), (ra, rb)
    for acc_a, acc_b in ((old._acc, new._acc),):
        if acc_a is None:
            assert acc_b is None
            continue
        for f in ("t0", "tts_s", "ttd_m", "boundary_vehicle_steps", "collisions_sumo",
                  "collisions_geom", "min_gap_m", "min_side_clearance_m"):
            assert _same(getattr(acc_a, f), getattr(acc_b, f)), f
        np.testing.assert_array_equal(acc_b.crossings, acc_a.crossings)
        assert len(acc_a.headways_s) == len(acc_b.headways_s)
        for ha, hb in zip(acc_a.headways_s, acc_b.headways_s, strict=True):
            np.testing.assert_array_equal(hb, ha)


CASES = [(seed, period, none_fields) for seed in (0, 1, 2) for period in (None, 500.0)
         for none_fields in (False, True)]


@pytest.mark.parametrize(("seed", "period", "none_fields"), CASES)
def test_traffic_recorder_matches_the_old_one_step_by_step(seed, period, none_fields):
    xs = (0.0, 120.0, 250.0, 499.0) if period else (100.0, 300.0, 450.0)
    zone = (0.0, period) if period else (50.0, 550.0)
    args = (DT, zone, xs, 10.0, 15.0, period, 1.5)
    old, new = OldTrafficRecorder(*args), TrafficRecorder(*args)
    for st, pairs in _steps(seed, 400, period, none_fields=none_fields):
        old.record(st, list(pairs))
        new.record(st, list(pairs))
        _compare(old, new)
    old.finish(400 * DT)
    new.finish(400 * DT)
    _compare(old, new)
    a, b = old.summary(), new.summary()
    assert list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    # the sequences exercise what they compare
    assert new.boundary_vehicle_steps > 0 and new.collisions_sumo["cav"] + \
        new.collisions_sumo["hdv_only"] > 0 and new.tet_veh_s > 0
    assert sum(r[f"flow_x{xs[1]:g}_vph"] for r in new.rows) > 0


# ======================================================================================
# Whole road-world runs
# ======================================================================================

RUNS = {
    "straight": ("default", {"scenario.duration_s": 60.0, "scenario.warmup_s": 10.0,
                             "demand.inflow_vph": 7000.0}),
    "obstacle": ("obstacle", {"scenario.duration_s": 90.0, "scenario.warmup_s": 20.0,
                              "demand.inflow_vph": 7000.0}),
    "ring": ("ring", {"scenario.duration_s": 40.0, "scenario.warmup_s": 5.0,
                      "demand.ring_density_vpkm": 200.0, "safety.enabled": False}),
}


def _road_run(name: str, over: dict):
    from cosim.config.scenario import load_scenario

    sc = load_scenario(name, {"scenario.world": "road", "scenario.interval_s": 10.0, **over})
    return runner.run_scenario(sc)


@pytest.mark.parametrize("case", sorted(RUNS))
@pytest.mark.slow(seconds=3)
def test_road_world_run_matches_the_old_traffic_recorder(case, monkeypatch):
    name, over = RUNS[case]
    new = _road_run(name, over)
    with monkeypatch.context() as m:
        m.setattr(runner, "TrafficRecorder", OldTrafficRecorder)
        old = _road_run(name, over)
    drop = ["wall_time_s"]
    pd.testing.assert_frame_equal(new.summary.drop(columns=drop),
                                  old.summary.drop(columns=drop), check_exact=True)
    for table in ("intervals", "collisions"):
        pd.testing.assert_frame_equal(getattr(new, table), getattr(old, table),
                                      check_exact=True)
    assert len(new.intervals) >= 3
