"""The must-show checks script (experiments/lanefree_checks.py) judges what it claims, and
the lateral-use measures (cosim/analysis/lateral.py) count what they claim. No SUMO."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cosim.analysis.lateral import (
    lateral_histogram,
    overtakes_per_vehicle_km,
    row_peaks,
    unwrapped_positions,
)
from cosim.sweeps.plan import sweep_from_dict
from experiments.lanefree_checks import evaluate, plan_data, tum_table


def test_every_arm_and_seed_is_a_valid_grid_point():
    full = sweep_from_dict(plan_data(smoke=False))
    smoke = sweep_from_dict(plan_data(smoke=True))
    names = [p.variant for p in full.points]
    assert sum(n.startswith("tum_ring/cav100#") for n in names) == 5
    assert {n.split("#")[0] for n in names} >= {"obstacle/cav60", "width_drop/cav0",
                                               "onramp/cav50", "free_road/cav100"}
    assert len(smoke.points) < len(full.points) / 5


def _row(variant: str, **kw) -> dict:
    base = {"variant": variant, "status": "ok", "collisions_geometric_cav": 0,
            "collisions_sumo_cav": 0, "boundary_vehicle_steps_cav": 0,
            "edie_flow_vph": 16500.0, "flow_drift": 0.01, "safety_speed_activations": 10,
            "safety_agent_steps": 100000, "space_mean_speed_mps": 20.0}
    return {**base, **kw}


def test_a_single_bad_seed_fails_a_per_seed_check_and_is_shown():
    rows = [_row(f"tum_ring/cav100#{s}") for s in (1, 2, 3)]
    rows[1]["edie_flow_vph"] = 15000.0
    rows[2]["collisions_geometric_cav"] = 1
    out = evaluate(pd.DataFrame(rows)).set_index("check")
    assert not out.loc["Edie flow", "passed"]
    assert out.loc["Edie flow", "measured"] == 15000.0
    assert not out.loc["CAV collisions (SUMO + geometric)", "passed"]
    assert out.loc["|flow drift|", "passed"]
    assert out.loc["safety speed interventions", "passed"]


def test_smoke_reports_but_does_not_judge_stationary_numbers():
    rows = [_row("tum_ring/cav100#1", edie_flow_vph=9000.0, flow_drift=0.2,
                 safety_speed_activations=5000)]
    out = evaluate(pd.DataFrame(rows), smoke=True).set_index("check")
    assert out.loc["Edie flow", "passed"] and "smoke" in out.loc["Edie flow", "note"]
    assert not out.loc["safety speed interventions", "passed"]  # judged in smoke too


def test_failed_runs_fail_their_arm_and_human_arms_skip_cav_checks():
    rows = [_row("obstacle/cav60#1", max_standstill_s=5.0, blocked_windows=0,
                 flow_x562_vph=3900.0),
            _row("obstacle/cav60#2", status="failed"),
            _row("width_drop/cav0#1", collisions_geometric_cav=3)]
    out = evaluate(pd.DataFrame(rows))
    ob = out[out["arm"] == "obstacle/cav60"]
    assert len(ob) and not ob["passed"].any() and (ob["note"] == "runs failed").all()
    assert out[out["arm"] == "width_drop/cav0"].empty


def test_tum_table_sets_our_flow_beside_theirs():
    rows = [_row("tum_ring/cav0#1", edie_flow_vph=6000.0),
            _row("tum_ring/cav0#2", edie_flow_vph=7000.0)]
    t = tum_table(pd.DataFrame(rows)).iloc[0]
    assert t["flow_vph_mean"] == 6500.0 and t["tum_flow_vph"] == 6613.0
    assert t["ours_over_tum"] == pytest.approx(6500.0 / 6613.0)


def _traj(samples: dict[float, dict[str, tuple[float, float]]]) -> pd.DataFrame:
    return pd.DataFrame([{"t_s": t, "id": i, "s_m": s, "d_m": d, "width_m": 1.8, "is_cav": True}
                         for t, veh in samples.items() for i, (s, d) in veh.items()])


def test_overtakes_count_each_swapped_pair_once_and_unwrap_the_ring():
    tr = _traj({0.0: {"a": (990.0, 0.0), "b": (995.0, 2.0), "c": (100.0, -2.0)},
                1.0: {"a": (20.0, 0.0), "b": (15.0, 2.0), "c": (110.0, -2.0)},
                2.0: {"a": (50.0, 0.0), "b": (40.0, 2.0), "c": (120.0, -2.0)}})
    un = unwrapped_positions(tr, 1000.0)
    a = un[un["id"] == "a"]["s_unwrapped_m"].to_list()
    assert a == [990.0, 1020.0, 1050.0]
    per_km, n, km = overtakes_per_vehicle_km(tr, 1000.0)
    assert n == 1  # a passed b between 0 and 1 s; nobody else swapped
    assert km == pytest.approx((30 + 20 + 10 + 30 + 25 + 10) / 1000.0)
    assert per_km == pytest.approx(n / km)


def test_histogram_finds_two_rows():
    rng = np.random.default_rng(0)
    samples = {float(t): {f"v{k}": (10.0 * k, (-2.0 if k % 2 else 2.0) + rng.normal(0, 0.05))
                          for k in range(10)} for t in range(50)}
    h = lateral_histogram(_traj(samples), edges_m=(-5.1, 5.1))
    assert h["all"].sum() == pytest.approx(1.0)
    peaks = row_peaks(h)
    assert len(peaks) == 2
    assert peaks[0] == pytest.approx(-2.0, abs=0.15) and peaks[1] == pytest.approx(2.0, abs=0.15)
