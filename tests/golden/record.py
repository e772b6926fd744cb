"""Record the golden summaries (``python tests/golden/record.py``): one process per SUMO case.

Each case is a short scenario (nested dict, as ``cosim.config.scenario_from_dict``
takes it); the summary metrics of its run and the final metrics of the plane-world
seed reproductions are written to ``tests/golden/golden.json``. They were first
recorded on the code before the controller-seam refactor (commit 905c9c6) and are
compared by ``tests/test_golden.py``.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
GOLDEN = HERE / "golden.json"

SHORT = {"duration_s": 60.0, "warmup_s": 20.0, "interval_s": 20.0}

CASES: dict[str, dict] = {
    "flocking_mixed": {
        "scenario": {"name": "g_flocking", "seed": 3, **SHORT},
        "network": {"kind": "straight", "length_m": 600.0},
        "demand": {"inflow_vph": 3000.0, "cav_share": 0.6},
        "controller": {"kind": "flocking_timegap"},
    },
    "flocking_ring": {
        "scenario": {"name": "g_ring", "seed": 5, **SHORT},
        "network": {"kind": "ring", "circumference_m": 500.0},
        "demand": {"ring_density_vpkm": 80.0, "cav_share": 1.0},
        "controller": {"kind": "flocking_timegap"},
    },
    "boundary_points_obstacle": {
        # the sublane width the golden was recorded at ("auto" would take 0.4 m here)
        "scenario": {"name": "g_bp", "seed": 2, "lateral_resolution_m": 0.8, **SHORT},
        "network": {"kind": "straight", "length_m": 600.0},
        "demand": {"inflow_vph": 2000.0, "cav_share": 0.8},
        "controller": {"kind": "boundary_points"},
        "obstacle": {"s_m": 350.0, "d_m": -3.4, "length_m": 5.0, "width_m": 2.0},
    },
    "communication": {
        "scenario": {"name": "g_comm", "seed": 4, **SHORT},
        "network": {"kind": "straight", "length_m": 600.0},
        "demand": {"inflow_vph": 3000.0, "cav_share": 0.8},
        "controller": {"kind": "flocking_timegap", "comm": {
            "r_comm_m": 150.0, "delay_min_s": 0.05, "delay_max_s": 0.3, "loss_prob": 0.1,
            "period_s": 0.1, "expiry_s": 1.0, "mode": "asynchronous", "seed": 1}},
    },
    "sumo_drives": {
        "scenario": {"name": "g_sumo", "seed": 6, **SHORT},
        "network": {"kind": "straight", "length_m": 600.0},
        "demand": {"inflow_vph": 3000.0, "cav_share": 0.5},
        "controller": {"kind": "sumo"},
    },
}

#: Summary keys compared (the ones every version of the runner writes).
KEYS = (
    "edie_flow_vph", "edie_density_vpkm", "space_mean_speed_mps", "vehicles_inserted",
    "vehicles_arrived", "min_gap_m", "min_side_clearance_m", "collisions_geometric_cav",
    "boundary_vehicle_steps", "safety_speed_activations", "safety_side_activations",
    "safety_edge_activations",
)


def _plain(v):
    if hasattr(v, "item"):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def run_case(name: str) -> dict:
    """Run one case in this process; its summary values for KEYS."""
    from cosim.config.scenario import scenario_from_dict
    from cosim.sim.runner import run_scenario

    spec = json.loads(json.dumps(CASES[name]))
    res = run_scenario(scenario_from_dict(spec))
    row = res.summary.iloc[0].to_dict()
    return {k: _plain(row.get(k)) for k in KEYS}


def run_plane(name: str) -> dict:
    """Final-row metrics of a plane-world seed reproduction."""
    from cosim.plane.scenarios import run_plane_scenario

    res = run_plane_scenario(name)
    last = res.metrics.iloc[-1].to_dict()
    return {k: _plain(v) for k, v in last.items()}


def record() -> dict:
    out = {"sumo": {}, "plane": {}}
    for name in CASES:
        proc = subprocess.run([sys.executable, __file__, "case", name], capture_output=True,
                              text=True, check=True)
        out["sumo"][name] = json.loads(proc.stdout.strip().splitlines()[-1])
        print(name, out["sumo"][name], file=sys.stderr)
    for name in ("seed000", "seed001"):
        out["plane"][name] = run_plane(name)
    return out


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "case":
        print(json.dumps(run_case(sys.argv[2])))
    elif len(sys.argv) > 2 and sys.argv[1] == "plane":
        print(json.dumps(run_plane(sys.argv[2])))
    else:
        GOLDEN.write_text(json.dumps(record(), indent=1, sort_keys=True) + "\n")
        print(f"wrote {GOLDEN}")
