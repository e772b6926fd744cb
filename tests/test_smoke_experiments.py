"""Every shipped experiment runs in its --smoke form and writes its outputs (CI runs these).

Each script runs in its own process (SUMO-based sweeps start one libsumo per run).
"""

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]


def _run(args: list[str], timeout: float = 600.0) -> subprocess.CompletedProcess:
    proc = subprocess.run(args, cwd=REPO, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


@pytest.mark.parametrize(
    "script",
    ["seed002_formation.py", "seed004_vicsek.py", "seed001_delays.py", "seed003_obstacles.py"],
)
def test_seed_experiment_smoke_writes_csv_and_png(tmp_path, script):
    _run([sys.executable, str(REPO / "experiments" / script), "--smoke", "--out", str(tmp_path)])
    assert list(tmp_path.rglob("*.csv")), "no CSV written"
    assert list(tmp_path.rglob("*.png")), "no figure written"


@pytest.mark.parametrize("name", ["seed000", "seed001"])
def test_plane_reproduction_command_writes_outputs(tmp_path, name):
    _run([sys.executable, "-m", "cosim.cli.main", "plane", name, "--duration", "2", "--plot",
          "--out", str(tmp_path)])
    metrics = pd.read_csv(tmp_path / "metrics.csv")
    assert metrics["t_s"].iloc[-1] == pytest.approx(2.0)
    assert (tmp_path / "trajectories.png").exists()


@pytest.mark.sumo
@pytest.mark.parametrize(
    "sweep", ["open_road_capacity", "ring_fd", "baselines", "capacity_quick", "capacity_hdv5"]
)
def test_shipped_sweep_smoke_runs_every_point_ok(tmp_path, sweep):
    out = tmp_path / sweep
    _run([sys.executable, "-m", "cosim.cli.main", "sweep", sweep, "--smoke", "--out", str(out),
          "--quiet"], timeout=900.0)
    rows = pd.read_csv(out / "results.csv")
    assert len(rows) >= 1
    assert (rows["status"] == "ok").all(), rows[["run_id", "status"]].to_string()


@pytest.mark.sumo
def test_calibrate_humans_smoke_writes_every_measure(tmp_path):
    """``experiments/calibrate_humans.py --smoke``: every measure of the README's calibration
    table is written, with a finite value."""
    _run([sys.executable, str(REPO / "experiments" / "calibrate_humans.py"), "--smoke",
          "--out", str(tmp_path)])
    table = pd.read_csv(tmp_path / "calibrate_humans.csv")
    assert {"lane", "obstacle", "ring", "gaps"} <= set(table["table"])
    lane = table[table["table"] == "lane"]
    # one lane of calibrated drivers: 2 164 veh/h at capacity (README); HCM 2 000-2 400
    assert lane["q_lane_vph"].between(1500.0, 3000.0).all(), lane
    ring = table[table["table"] == "ring"].iloc[0]
    # TUM's ring at 225 veh/km with 0 % CAVs: their human model 6 613 veh/h
    assert 4500.0 < ring["flow_vph"] < 9000.0
    assert (table["collision_vehicles"].fillna(0) == 0).all()
