"""cosim/traffic_metrics.py without SUMO: Edie's flow/density/speed, cross-section
counts, gaps, boundary violations, collisions and interval boundaries on synthetic
StepState sequences with known answers.

Synthetic traffic: an endless platoon at speed v (m/s) with constant spacing h (m)
(centre to centre): density 1/h, flow v/h, space-mean speed v; 4.5 m x 1.8 m cars on
a 10.2 m road.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.metrics.traffic import (
    StepState,
    TrafficRecorder,
    gaps,
    gaps_and_leaders,
    overlapping_pairs,
    time_to_collision,
)

DT = 0.1
L, W = 4.5, 1.8
HALF_ROAD = 5.1


def state(t, s, d=None, v=10.0, length=L, width=W, ids=None, is_cav=True) -> StepState:
    s = np.asarray(s, float)
    n = len(s)
    d = np.zeros(n) if d is None else np.asarray(d, float)
    length = np.broadcast_to(np.asarray(length, float), (n,)).copy()
    return StepState(
        t=t,
        ids=list(ids) if ids is not None else [f"v{i}" for i in range(n)],
        s=s,
        s_front=s + 0.5 * length,
        d=d,
        v=np.broadcast_to(np.asarray(v, float), (n,)).copy(),
        v_lat=np.zeros(n),
        length=length,
        width=np.broadcast_to(np.asarray(width, float), (n,)).copy(),
        is_cav=np.broadcast_to(np.asarray(is_cav, bool), (n,)).copy(),
        edge_right=np.full(n, -HALF_ROAD),
        edge_left=np.full(n, HALF_ROAD),
    )


def platoon(v: float, h: float, n_steps: int, period: float | None = None, n: int = 0):
    """States of a platoon: vehicle i at s = i h - offset + v t (t = k dt, k >= 1)."""
    if period is None:
        n = n or 200
        base = np.arange(n) * h - 0.5 * n * h
    else:
        n = int(round(period / h))
        base = np.arange(n) * h + 0.3 * h
    ids = [f"c{i}" for i in range(n)]
    for k in range(1, n_steps + 1):
        t = round(k * DT, 10)
        s = base + v * k * DT
        if period is not None:
            s = np.mod(s, period)
        yield state(t, s, v=v, ids=ids)


# --------------------------------------------------------------------------------------
# Edie and cross-sections
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(("v", "h"), [(20.0, 25.0), (30.0, 40.0), (8.0, 12.5)])
def test_edie_density_flow_speed_of_a_uniform_platoon(v, h):
    """Zone 0..1000 m, intervals of 20 s after a 10 s warm-up, 70 s: 3 intervals, each
    with k = 1/h, q = v/h, v_space = v (1 %); cross-sections count v T / h vehicles per
    interval (an integer: within one vehicle, and within one over the three together)."""
    rec = TrafficRecorder(DT, (0.0, 1000.0), (250.0, 500.0), 20.0, 10.0)
    for st in platoon(v, h, 700):
        rec.record(st, [])
    rec.finish(70.0)
    rows = rec.rows
    assert [(r["t_start_s"], r["t_end_s"]) for r in rows] == [(10, 30), (30, 50), (50, 70)]
    q_vph = v / h * 3600.0
    k_vpkm = 1000.0 / h
    for r in rows:
        assert r["edie_density_vpkm"] == pytest.approx(k_vpkm, rel=0.01)
        assert r["edie_flow_vph"] == pytest.approx(q_vph, rel=0.01)
        assert r["space_mean_speed_mps"] == pytest.approx(v, rel=0.01)
        for x in ("250", "500"):
            count = r[f"flow_x{x}_vph"] * 20.0 / 3600.0
            assert count == pytest.approx(round(count))
            assert abs(count - v * 20.0 / h) <= 1.0
        assert r["min_gap_m"] == pytest.approx(h - L)
        assert r["median_time_headway_s"] == pytest.approx((h - L) / v)
    for x in ("250", "500"):
        total = sum(r[f"flow_x{x}_vph"] for r in rows) * 20.0 / 3600.0
        assert abs(total - v * 60.0 / h) <= 1.0
    s = rec.summary()
    assert s["n_intervals"] == 3
    assert s["edie_flow_vph"] == pytest.approx(q_vph, rel=0.01)
    assert s["edie_density_vpkm"] == pytest.approx(k_vpkm, rel=0.01)
    assert s["space_mean_speed_mps"] == pytest.approx(v, rel=0.01)
    assert s["min_gap_m"] == pytest.approx(h - L)
    assert s["min_side_clearance_m"] == math.inf  # nobody beside anybody
    assert s["collisions_geometric_cav"] == 0 and s["boundary_vehicle_steps"] == 0


def test_interval_boundaries_and_partial_interval_dropped():
    """Steps at t in (t0, t0 + T] belong to [t0, t0 + T]; the last partial one is dropped."""
    rec = TrafficRecorder(DT, (0.0, 1000.0), (), 20.0, 10.0)
    for st in platoon(20.0, 25.0, 699):  # up to t = 69.9 s
        rec.record(st, [])
    rec.finish(69.9)
    assert [(r["t_start_s"], r["t_end_s"]) for r in rec.rows] == [(10, 30), (30, 50)]
    # every interval saw exactly 200 steps of 40 vehicles: TTS = 200 * 40 * 0.1 s = 800 s
    # over 1 km x 20 s, i.e. 40 veh/km (one step more or less would give 39.8 or 40.2)
    for r in rec.rows:
        assert r["edie_density_vpkm"] == pytest.approx(40.0, abs=1e-9)


def test_warmup_is_excluded_from_the_measurement():
    """A crowd standing in the zone up to t = 10 s (the warm-up) changes nothing."""
    rec = TrafficRecorder(DT, (0.0, 1000.0), (500.0,), 20.0, 10.0)
    crowd = np.linspace(10.0, 990.0, 300)
    for st in platoon(20.0, 25.0, 300):
        if st.t <= 10.0 + 1e-9:
            both = state(st.t, np.concatenate([st.s, crowd]),
                         d=np.concatenate([st.d, np.full(300, 3.0)]),
                         v=np.concatenate([st.v, np.zeros(300)]))
            rec.record(both, [])
        else:
            rec.record(st, [])
    rec.finish(30.0)
    (row,) = rec.rows
    assert row["edie_density_vpkm"] == pytest.approx(40.0)
    assert row["flow_x500_vph"] == pytest.approx(2880.0)


def test_cross_sections_on_a_ring_count_across_the_wrap():
    """Ring of 300 m, 12 vehicles 25 m apart at 15 m/s: a section at 1 m, at 150 m and
    at 299 m each count v/h = 2160 veh/h, including the fronts that wrap past s = 0."""
    period = 300.0
    rec = TrafficRecorder(DT, (0.0, period), (1.0, 150.0, 299.0), 20.0, 0.0, period)
    for st in platoon(15.0, 25.0, 400, period=period):
        st.s_front = np.mod(st.s_front, period)
        rec.record(st, [])
    rec.finish(40.0)
    assert len(rec.rows) == 2
    for r in rec.rows:
        for x in ("1", "150", "299"):
            assert r[f"flow_x{x}_vph"] == pytest.approx(15.0 / 25.0 * 3600.0, rel=0.01)
        assert r["edie_density_vpkm"] == pytest.approx(1000.0 / 25.0, rel=0.01)
        assert r["min_gap_m"] == pytest.approx(25.0 - L)


# --------------------------------------------------------------------------------------
# Gaps and overlaps
# --------------------------------------------------------------------------------------


def test_gaps_are_bumper_to_bumper_and_side_to_side():
    # 0: 4 m car at s 0; 1: 5 m car at s 10, 0.5 m to the left (overlapping laterally);
    # 2: 1.6 m wide car beside 0 (ds 1 m), 2.5 m to the left (2.0 m from 1: no overlap).
    st = state(0.0, [0.0, 10.0, 1.0], d=[0.0, 0.5, 2.5], length=[4.0, 5.0, 4.5],
               width=[1.8, 1.8, 1.6])
    g_long, g_side = gaps(st, None)
    assert g_long[0] == pytest.approx(10.0 - 4.5)  # 10 m centres, half lengths 2 + 2.5
    assert math.isinf(g_long[1])  # nobody ahead
    assert math.isinf(g_long[2])  # 1 is ahead of 2 but does not overlap it laterally
    assert g_side[0] == pytest.approx(2.5 - 0.5 * (1.8 + 1.6))
    assert g_side[2] == pytest.approx(2.5 - 0.5 * (1.8 + 1.6))
    assert math.isinf(g_side[1])


def test_gap_ignores_a_vehicle_ahead_without_lateral_overlap():
    st = state(0.0, [0.0, 20.0], d=[0.0, 1.85])  # side gap 0.05 m: no overlap
    g_long, _ = gaps(st, None)
    assert math.isinf(g_long[0])
    st = state(0.0, [0.0, 20.0], d=[0.0, 1.75])  # overlap 0.05 m
    g_long, _ = gaps(st, None)
    assert g_long[0] == pytest.approx(20.0 - L)


def test_overlap_is_strict():
    touching = state(0.0, [0.0, L], d=[0.0, 0.0])  # bumpers touch
    assert len(overlapping_pairs(touching, None)) == 0
    assert len(overlapping_pairs(state(0.0, [0.0, L - 1e-6]), None)) == 1
    side = state(0.0, [0.0, 0.0], d=[0.0, W])  # sides touch
    assert len(overlapping_pairs(side, None)) == 0
    assert len(overlapping_pairs(state(0.0, [0.0, 0.0], d=[0.0, W - 1e-6]), None)) == 1


def test_ring_gaps_and_overlaps_across_s_zero():
    """Period 300 m: a car at s = 298 m with its leader at s = 10 m is 12 m behind it
    (bumper gap 7.5 m); cars at 299.5 m and 0.5 m overlap, but not on an open road."""
    st = state(0.0, [298.0, 10.0])
    g_long, _ = gaps(st, 300.0)
    assert g_long[0] == pytest.approx(12.0 - L)
    assert math.isinf(g_long[1])  # its leader is 288 m ahead: beyond the 150 m reach
    wrap = state(0.0, [299.5, 0.5, 150.0])
    assert overlapping_pairs(wrap, 300.0).tolist() == [[0, 1]]
    assert len(overlapping_pairs(wrap, None)) == 0
    g_long, _ = gaps(state(0.0, [299.0, 3.0]), 300.0)
    assert g_long[0] == pytest.approx(4.0 - L)  # overlapping: negative gap


# --------------------------------------------------------------------------------------
# Boundary violations and collisions
# --------------------------------------------------------------------------------------


def test_boundary_violations_count_vehicle_steps_vehicles_and_worst_excursion():
    rec = TrafficRecorder(DT, (0.0, 1000.0), (), 10.0, 0.0)
    inside = HALF_ROAD - 0.5 * W  # 4.2 m: the body touches the edge, not outside
    for k in range(1, 11):
        d = [inside, -inside, 0.0]
        if k > 5:
            d = [inside + 0.1, -(inside + 0.25), 0.0]  # 0.1 m out left, 0.25 m out right
        rec.record(state(k * DT, [0.0, 50.0, 100.0], d=d, ids=["a", "b", "c"]), [])
    s = rec.summary()
    assert s["boundary_vehicle_steps"] == 10  # 2 vehicles x 5 steps
    assert s["boundary_vehicles"] == 2
    assert s["worst_boundary_excursion_m"] == pytest.approx(0.25)


def test_collisions_are_counted_as_events_by_both_checks():
    """A collision event is a pair that starts to overlap, in our check and in SUMO's
    (SUMO lists a pair in every step it overlaps; we count it once per contact)."""
    rec = TrafficRecorder(DT, (0.0, 1000.0), (), 10.0, 0.0)
    # b overlaps a for steps 2-4, separates at 5, overlaps again at 6-7
    plan = [10.0, 3.0, 3.0, 3.0, 10.0, 3.0, 3.0]
    for k, ds in enumerate(plan, start=1):
        st = state(k * DT, [0.0, ds, 200.0, 203.0], ids=["cav.a", "hdv.b", "hdv.c", "hdv.d"],
                   is_cav=[True, False, False, False])
        sumo = [("hdv.b", "cav.a")] if ds < L else []
        rec.record(st, sumo)
    s = rec.summary()
    assert s["collisions_geometric_cav"] == 2
    assert s["collisions_geometric_hdv_only"] == 1  # c and d overlap from the start
    assert s["collisions_sumo_cav"] == 2  # two contacts, five listed steps
    assert s["collisions_sumo_hdv_only"] == 0
    geo = [r for r in rec.collision_log if r["source"] == "geometric" and r["kind"] == "cav"]
    assert [round(r["t_s"], 6) for r in geo] == [0.2, 0.6]
    assert (geo[0]["a"], geo[0]["b"]) == ("cav.a", "hdv.b")


def test_summary_of_an_empty_zone_has_zero_flow_and_undefined_speed():
    rec = TrafficRecorder(DT, (100.0, 200.0), (150.0,), 10.0, 0.0)
    for k in range(1, 201):
        rec.record(state(k * DT, [10.0], v=0.0), [])  # parked before the zone
    rec.finish(20.0)
    assert len(rec.rows) == 2
    s = rec.summary()
    assert s["edie_flow_vph"] == 0.0
    assert s["edie_density_vpkm"] == 0.0
    assert math.isnan(s["space_mean_speed_mps"])


# --------------------------------------------------------------------------------------
# Time to collision (Hayward 1972) and its exposure (Minderhoud & Bovy 2001)
# --------------------------------------------------------------------------------------


def test_leader_is_the_nearest_laterally_overlapping_vehicle_ahead():
    # 0 at s 0; 1 at s 30 (overlapping); 2 at s 15 but 2.5 m to the side (no overlap);
    # 3 at s 50 (overlapping, farther than 1).
    st = state(0.0, [0.0, 30.0, 15.0, 50.0], d=[0.0, 0.5, 2.5, 0.0])
    g_long, _, leader = gaps_and_leaders(st, None)
    assert leader.tolist() == [1, 3, -1, -1]
    assert g_long[0] == pytest.approx(30.0 - L)
    assert g_long[1] == pytest.approx(20.0 - L)


def test_time_to_collision_closing_opening_and_overlapping():
    g = np.array([15.0, 15.0, -0.2, 7.0])
    v = np.array([20.0, 6.0, 12.0, 8.0])
    leader = np.array([3, 3, 3, -1])  # all follow vehicle 3 (8 m/s), which follows nobody
    ttc = time_to_collision(g, v, leader)
    assert ttc[0] == pytest.approx(15.0 / 12.0)  # closing at 12 m/s
    assert math.isinf(ttc[1])  # slower than its leader: not closing in
    assert ttc[2] == 0.0  # already overlapping and closing
    assert math.isinf(ttc[3])  # no leader


def closing_pair(k_steps: int, gap0: float, v_follow: float, v_lead: float, follower_cav=True):
    """A follower closing in on a leader ahead in the same band, t = k dt, k = 1..k_steps."""
    for k in range(1, k_steps + 1):
        t = round(k * DT, 10)
        s = np.array([0.0 + v_follow * t, L + gap0 + v_lead * t])
        st = state(t, s, ids=["f", "l"], is_cav=[follower_cav, True])
        st.v = np.array([v_follow, v_lead])
        yield st


@pytest.mark.parametrize("threshold, tet_s, tit_s2", [(1.5, 1.0, 0.5), (3.0, 2.5, 3.125)])
def test_ttc_exposure_of_a_closing_pair(threshold, tet_s, tit_s2):
    """Gap 20.25 m closing at 5 m/s: TTC = 4.05 - t. Steps t = 0.1..3.5 s; TTC <= TTC*
    from t = 4.05 - TTC* on: TET = dt x those steps, TIT = sum (TTC* - TTC) dt."""
    rec = TrafficRecorder(DT, (0.0, 1000.0), (), 10.0, 0.0, ttc_threshold_s=threshold)
    for st in closing_pair(35, 20.25, 15.0, 10.0):
        rec.record(st, [])
    rec.finish(3.5)
    s = rec.summary()
    assert s["min_ttc_s"] == pytest.approx(4.05 - 3.5)
    assert s["min_cav_ttc_s"] == pytest.approx(4.05 - 3.5)
    assert s["tet_veh_s"] == pytest.approx(tet_s)
    assert s["tit_veh_s2"] == pytest.approx(tit_s2)
    assert s["measured_vehicle_s"] == pytest.approx(2 * 3.5)
    assert s["tet_share"] == pytest.approx(tet_s / 7.0)
    assert s["ttc_threshold_s"] == threshold


def test_ttc_exposure_is_zero_for_a_steady_platoon_and_hdv_followers_are_not_cavs():
    rec = TrafficRecorder(DT, (0.0, 1000.0), (), 10.0, 0.0)
    for st in platoon(25.0, 30.0, 50):
        rec.record(st, [])
    s = rec.summary()
    assert math.isinf(s["min_ttc_s"]) and s["tet_veh_s"] == 0.0 and s["tet_share"] == 0.0
    rec = TrafficRecorder(DT, (0.0, 1000.0), (), 10.0, 0.0)
    for st in closing_pair(35, 20.25, 15.0, 10.0, follower_cav=False):
        rec.record(st, [])
    s = rec.summary()
    assert s["min_ttc_s"] == pytest.approx(0.55)
    assert math.isinf(s["min_cav_ttc_s"])  # the only closing vehicle is human-driven


def test_ttc_is_not_recorded_during_warmup():
    rec = TrafficRecorder(DT, (0.0, 1000.0), (), 10.0, 5.0)  # warm-up longer than the run
    for st in closing_pair(35, 20.25, 15.0, 10.0):
        rec.record(st, [])
    s = rec.summary()
    assert math.isinf(s["min_ttc_s"]) and s["tet_veh_s"] == 0.0
    assert s["measured_vehicle_s"] == 0.0 and math.isnan(s["tet_share"])
