"""The floor on the benchmark's rings (benchmarks/bench_cosim.py, issue 15): it drives the
vehicles of the ring scenario cosim starts, every one of them every step."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_cosim as bc  # noqa: E402

pytestmark = pytest.mark.sumo


@pytest.mark.parametrize("variant", sorted(set(bc.RING_FLOORS.values())))
def test_ring_floor_drives_every_vehicle_of_the_ring_every_step(variant):
    n, duration_s, skip = 40, 4.0, 10
    res = bc.run_cosim("ring", bc.ring_overrides(n, duration_s, 2000.0), skip=skip,
                       floor=True, variant=variant)
    steps = int(round(duration_s / bc.bf.STEP_S)) - skip
    assert res["veh_steps_after"] == n * steps  # nobody leaves a ring, nobody is missed
    assert 0.0 < res["sumo_s"] < res["cpu_after_s"]
