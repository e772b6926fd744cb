"""Every shipped experiment runs in its --smoke form and writes its outputs (CI runs these).

Each script runs in its own process, and a sweep's runs each in a process of their own
(SUMO-based sweeps start one libsumo per run).
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


def _seed001_results(out: Path) -> None:
    """Seed 001: ideal and prompt synchronous messages finish the mission (both waypoints)
    without a collision; 0.3 s of delay breaks the flock (the seed's warning)."""
    sweep = pd.read_csv(out / "delay_sweep.csv").set_index("case")
    for case in ("ideal", "synch_T0.05_D0"):
        assert sweep.loc[case, "waypoints_reached"] == 2, case
        assert not sweep.loc[case, "collision"], case
    delayed = sweep.loc["synch_T0.05_D0.3"]
    assert delayed["collision"] or delayed["broken"]


def _seed002_results(out: Path) -> None:
    """Seed 002: the hexagon closes (final rms error under a tenth of the initial one);
    the K_for sweep settles at K_for = 0.001 and not at 0.0001."""
    err = pd.read_csv(out / "hexagon_error.csv")
    assert err["e_rms"].iloc[-1] < 0.1 * err["e_rms"].iloc[0]
    kfor = pd.read_csv(out / "kfor_sweep_summary.csv").set_index("K_for")
    assert kfor.loc[0.001, "settled"] == 1.0 and kfor.loc[0.0001, "settled"] == 0.0


def _seed003_results(out: Path) -> None:
    """Seed 003: the boundary-point law never collides and passes the obstacles faster
    than Olfati-Saber's projection (measured: 83-84 % less time in the smoke form)."""
    summary = pd.read_csv(out / "summary.csv")
    proposed = summary[summary["controller"] == "proposed"]
    assert len(proposed) >= 2 and (proposed["collision_share"] == 0.0).all()
    speed = pd.read_csv(out / "speedup.csv")
    t_pass = speed[speed["time"] == "t_pass"]
    assert len(t_pass) >= 2 and (t_pass["reduction_bound"] > 0.5).all(), t_pass


def _seed004_results(out: Path) -> None:
    """Seed 004 (Vicsek): the flock orders without noise and loses its order at high noise."""
    noise = pd.read_csv(out / "noise.csv")
    vicsek = noise[noise["rule"] == "vicsek"].sort_values("eta")
    assert vicsek["order_parameter"].iloc[0] > 0.7
    assert vicsek["order_parameter"].iloc[-1] < 0.3


SEED_RESULTS = {"seed001_delays.py": _seed001_results, "seed002_formation.py": _seed002_results,
                "seed003_obstacles.py": _seed003_results, "seed004_vicsek.py": _seed004_results}


@pytest.mark.parametrize("script", sorted(SEED_RESULTS))
@pytest.mark.slow(seconds=10)
def test_seed_experiment_smoke_writes_its_results(tmp_path, script):
    _run([sys.executable, str(REPO / "experiments" / script), "--smoke", "--out", str(tmp_path)])
    assert list(tmp_path.rglob("*.png")), "no figure written"
    SEED_RESULTS[script](tmp_path)


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
@pytest.mark.slow(seconds=6)
def test_shipped_sweep_smoke_runs_every_point_ok(tmp_path, sweep):
    out = tmp_path / sweep
    # The sweep's parent runs in this test process (it starts no SUMO: every run is a
    # child of its own); forkserver: each run forks from a server with cosim imported, one
    # server for the five sweeps (spawn, the default, imports cosim again per run: about
    # 1 s each; both are tested in test_sweep.py, the console script in test_config_cli.py).
    from cosim.cli.main import main

    rc = main(["sweep", sweep, "--smoke", "--out", str(out), "--quiet",
               "--start-method", "forkserver"])
    assert rc == 0
    rows = pd.read_csv(out / "results.csv")
    assert len(rows) >= 1
    assert (rows["status"] == "ok").all(), rows[["run_id", "status"]].to_string()


@pytest.mark.sumo
@pytest.mark.slow(seconds=17)
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
