"""The seed 001 communication layer and seed 003's boundary-point law drive CAVs on the
obstacle road in SUMO with the default controller's safety guarantees (each run in its
own process)."""

import json
import subprocess
import sys

import pytest

CODE = r"""
import json, sys, dataclasses
from cosim.config.builtins import builtin_scenarios
from cosim.config.scenario import load_scenario
from cosim.sim.runner import run_scenario
sc = load_scenario(builtin_scenarios()[sys.argv[1]])
sc = dataclasses.replace(sc, scenario=dataclasses.replace(
    sc.scenario, duration_s=90.0, warmup_s=30.0, interval_s=30.0))
s = run_scenario(sc).summary.iloc[0].to_dict()
print("RESULT " + json.dumps({k: (v if isinstance(v, (int, float, str)) else str(v))
                              for k, v in s.items()}))
"""


def _summary(name: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", CODE, name], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


@pytest.mark.sumo
@pytest.mark.parametrize("name", ["comm_delay", "obstacle_seed003"])
def test_controller_on_the_road_causes_no_collision_and_stays_inside(name):
    s = _summary(name)
    assert s["vehicles_inserted"] > 20
    assert s["collisions_sumo_cav"] == 0
    assert s["collisions_geometric_cav"] == 0
    assert s["boundary_vehicle_steps_cav"] == 0
    assert s["space_mean_speed_mps"] > 1.0  # traffic moves
