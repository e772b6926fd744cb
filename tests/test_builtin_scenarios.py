"""Every built-in scenario is clean on every seed: no collision involving a CAV, no CAV
outside the road, no jam (nobody stands still longer than 30 s, no cross-section blocked); traffic
moves.

Each scenario runs for its first 90 s (warm-up 30 s) in SUMO, one process per run
(forked from a server with cosim imported: ``tests/sumo_cases/isolated.py``), on three
seeds. The shipped scenario files set the rest (demand, network, law, obstacle).
"""

from __future__ import annotations

import os

import pytest
from sumo_cases.isolated import run_isolated

from cosim.config.builtins import builtin_scenarios

pytestmark = pytest.mark.sumo

SEEDS = (1, 2, 3)
SHORT = {"scenario.duration_s": 90.0, "scenario.warmup_s": 30.0, "scenario.interval_s": 30.0,
         "outputs.trajectories": False}

KEYS = ("collisions_geometric_cav", "collisions_sumo_cav", "boundary_vehicle_steps_cav",
        "max_standstill_s", "blocked_windows", "vehicles_inserted", "space_mean_speed_mps")


def builtin_summary(name: str, seed: int) -> dict:
    """The summary fields the test reads, of the built-in ``name`` on ``seed`` (runs in
    a child process: :func:`sumo_cases.isolated.run_isolated`)."""
    from cosim.config import load_scenario
    from cosim.sim.runner import run_scenario

    row = run_scenario(load_scenario(name, {**SHORT, "scenario.seed": seed})).summary.iloc[0]
    return {k: (None if row[k] is None else float(row[k])) for k in KEYS}


@pytest.fixture(scope="module")
def env(tmp_path_factory) -> dict:
    e = dict(os.environ)
    e["COSIM_NETWORK_CACHE"] = str(tmp_path_factory.mktemp("nets"))
    return e


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", sorted(builtin_scenarios()))
@pytest.mark.slow(seconds=4.5)
def test_builtin_scenario_is_clean(name, seed, env):
    r = run_isolated(builtin_summary, name, seed, env=env)
    assert r["vehicles_inserted"] > 0
    assert r["collisions_geometric_cav"] == 0, r
    assert r["collisions_sumo_cav"] in (0, None), r
    assert r["boundary_vehicle_steps_cav"] == 0, r
    assert r["max_standstill_s"] <= 30.0, r
    assert r["blocked_windows"] == 0, r
    assert r["space_mean_speed_mps"] > 1.0, r  # traffic moves
