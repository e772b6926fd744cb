"""Sweeps: grid expansion and validation, stable run ids, surviving results, crash
recovery and --resume, the shipped sweep files, and the Dask executor.

SUMO runs happen only in worker processes (the process pool or Dask's workers); the
tests marked ``sumo`` use a tiny scenario: a 300 m road, 20 s, one 5 s interval each.
A run's process costs more than its simulation (a spawned worker imports cosim, libsumo
and the numba kernels: ~2 s of CPU, the 20 s run ~0.3 s), so the sweeps of several runs
go through :func:`_cli_sweep`: ``cosim sweep --start-method forkserver`` in a process of
its own, whose runs are forked from one server that imported all of it once (and that
inherits the test's environment, which the workers read: the network cache, the
test-only hooks).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
import tomllib
from collections import Counter
from pathlib import Path

import pandas as pd
import pytest

import cosim.sweeps as sw
from cosim.errors import ConfigError

TINY = """
seeds = [1]

[sweep]
name = "tiny"
description = "a 300 m road, 20 s"

[overrides]
scenario.duration_s = 20.0
scenario.warmup_s = 5.0
scenario.interval_s = 5.0
network.length_m = 300.0
demand.cav_share = 0.5
outputs.zone_start_m = 50.0
outputs.zone_end_m = 250.0

[axes]
"demand.inflow_vph" = [1500.0, 3000.0, 4500.0]

[smoke]
[smoke.axes]
"demand.inflow_vph" = [2000.0]
"""


def _write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _plan(text: str, smoke: bool = False) -> sw.SweepPlan:
    return sw.sweep_from_dict(tomllib.loads(text), smoke=smoke)


# --------------------------------------------------------------------------------------
# The plan
# --------------------------------------------------------------------------------------


def test_grid_is_the_product_of_axes_and_seeds_with_overrides_applied():
    plan = _plan("""
seeds = [3, 4]
[overrides]
network.length_m = 500.0
[axes]
"demand.inflow_vph" = [1000, 2000]
demand.cav_share = [0.0, 0.5, 1.0]
controller.params.time_gap_s = [0.5, 0.6]
""")
    assert len(plan.points) == 2 * 3 * 2 * 2
    assert len({p.run_id for p in plan.points}) == len(plan.points)
    combos = {(p.scenario.demand.inflow_vph, p.scenario.demand.cav_share,
               p.scenario.controller.law_params().time_gap_s, p.seed) for p in plan.points}
    assert len(combos) == 24
    assert all(p.scenario.network.length_m == 500.0 for p in plan.points)
    # integer axis values become the field's type (float) through scenario_from_dict
    assert isinstance(plan.points[0].scenario.demand.inflow_vph, float)
    assert plan.demand_axis == "demand.inflow_vph"
    assert plan.points[0].label().endswith("seed=3")


def test_nested_and_quoted_dotted_keys_mean_the_same():
    a = _plan('[axes]\n"network.width_m" = [8.0, 10.2]\n')
    b = _plan("[axes.network]\nwidth_m = [8.0, 10.2]\n")
    assert [p.run_id for p in a.points] == [p.run_id for p in b.points]


def test_run_id_is_stable_and_changes_with_the_scenario():
    first = [p.run_id for p in _plan(TINY).points]
    assert first == [p.run_id for p in _plan(TINY).points]
    # the same scenarios in another axis order: same ids
    swapped = _plan(TINY.replace("[1500.0, 3000.0, 4500.0]", "[4500.0, 1500.0, 3000.0]"))
    assert sorted(first) == sorted(p.run_id for p in swapped.points)
    # any real change of the scenario changes every id
    longer = _plan(TINY.replace("duration_s = 20.0", "duration_s = 25.0"))
    assert not set(first) & {p.run_id for p in longer.points}


def test_smoke_replaces_named_axes_seeds_and_adds_overrides():
    plan = _plan("""
seeds = [1, 2, 3]
[sweep]
name = "x"
[overrides]
scenario.duration_s = 600.0
[axes]
"demand.inflow_vph" = [2000.0, 4000.0, 6000.0]
"demand.cav_share" = [0.0, 1.0]
[smoke]
seeds = [7]
[smoke.overrides]
scenario.duration_s = 30.0
scenario.warmup_s = 10.0
scenario.interval_s = 10.0
[smoke.axes]
"demand.inflow_vph" = [3000.0]
""", smoke=True)
    assert plan.name == "x_smoke" and plan.smoke
    assert len(plan.points) == 2  # 1 demand x 2 shares (kept) x 1 seed
    assert {p.seed for p in plan.points} == {7}
    assert all(p.scenario.scenario.duration_s == 30.0 for p in plan.points)
    with pytest.raises(ConfigError, match="no \\[smoke\\]"):
        _plan('[axes]\n"demand.cav_share" = [0.5]\n', smoke=True)


def test_variants_are_named_parameter_sets_times_the_axes():
    plan = _plan("""
[[variants]]
name = "lanefree"
"network.kind" = "straight"
[[variants]]
name = "lanes"
network.kind = "three_lane"
[axes]
"demand.inflow_vph" = [2000.0, 4000.0]
""")
    assert [(p.variant, p.scenario.network.kind) for p in plan.points] == [
        ("lanefree", "straight"), ("lanefree", "straight"),
        ("lanes", "three_lane"), ("lanes", "three_lane"),
    ]
    assert "network.kind" in plan.param_columns()


@pytest.mark.parametrize("text, message", [
    ('[axes]\n"demand.inflow" = [1.0]\n', "unknown parameter 'demand.inflow'"),
    ('[axes]\n"demnd.cav_share" = [1.0]\n', "no section \\[demnd\\]"),
    ('[axes]\n"controller.params.c9" = [1.0]\n', "controller.params: unknown key 'c9'"),
    ('[axes]\n"demand.cav_share" = [0.5, 1.5]\n', "grid point 2/2 .*cav_share"),
    ('[axes]\n"demand.cav_share" = []\n', "non-empty list"),
    ('[axes]\n"demand.cav_share" = [0.5, 0.5]\n', "duplicate values"),
    ('seeds = [1]\n[axes]\n"scenario.seed" = [2]\n', "either seeds or an axis"),
    ("seeds = [-1]\n", "seeds must be"),
    ('[sweep]\nbase = "nope"\n', "sweep.base"),
    ('[sweep]\nnmae = "x"\n', "unknown key 'nmae'"),
    ('[overrides]\nnetwork.widht_m = 3.0\n', "widht_m"),
])
def test_config_errors_name_the_problem(text, message):
    with pytest.raises(ConfigError, match=message):
        _plan(text)


def test_a_typo_fails_with_one_line_before_any_run(tmp_path, capsys):
    f = _write(tmp_path, TINY.replace('"demand.inflow_vph" = [1500.0', '"demand.inflow" = [1500.0'))
    out = tmp_path / "out"
    assert sw.main([str(f), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert err.startswith("error: s.toml:") and "'demand.inflow'" in err
    assert not out.exists()


def test_base_scenario_by_name_and_by_relative_path(tmp_path):
    (tmp_path / "my.toml").write_text(
        '[scenario]\nduration_s = 33.0\nwarmup_s = 3.0\ninterval_s = 10.0\n'
    )
    by_path = sw.load_sweep(_write(tmp_path, '[sweep]\nbase = "my.toml"\n'))
    assert by_path.points[0].scenario.scenario.duration_s == 33.0
    by_name = sw.load_sweep(_write(tmp_path, '[sweep]\nbase = "ring"\n', "r.toml"))
    assert by_name.points[0].scenario.network.kind == "ring"
    (tmp_path / "bad.toml").write_text('[scenario]\nduration_s = -33.0\n')
    with pytest.raises(ConfigError, match="base scenario .*bad.toml: scenario.duration_s"):
        sw.load_sweep(_write(tmp_path, '[sweep]\nbase = "bad.toml"\n', "b.toml"))


@pytest.mark.parametrize("name, n_full, n_smoke", [
    ("open_road_capacity", 13 * 5 * 3, 6),
    ("ring_fd", 8 * 5 * 5, 6),
    ("baselines", 3 * 13 * 3, 6),
    ("capacity_hdv5", 4 * 2 * 3, 1),
    ("ring_gamma", 8 * 3 * 2, 2),
])
def test_shipped_sweeps_validate(name, n_full, n_smoke):
    full = sw.load_sweep(name)
    smoke = sw.load_sweep(name, smoke=True)
    assert len(full.points) == n_full and len(smoke.points) == n_smoke
    shares = {p.scenario.demand.cav_share for p in full.points}
    want = {"baselines": {0.0}, "capacity_hdv5": {1.0, 0.95}, "ring_gamma": {1.0}}.get(
        name, {0.0, 0.25, 0.5, 0.75, 1.0})
    assert shares == want
    assert all(p.scenario.scenario.duration_s <= 40.0 for p in smoke.points)
    if name.startswith("ring"):
        assert {p.scenario.network.circumference_m for p in full.points} == {1000.0}
        assert smoke.demand_axis == "demand.ring_density_vpkm"
    else:
        assert {p.scenario.network.length_m for p in full.points} == {2000.0}
        assert {p.scenario.network.width_m for p in full.points} == {10.2}
        levels = sorted({p.scenario.demand.inflow_vph for p in full.points})
        want_levels = (12000.0, 18000.0) if name == "capacity_hdv5" else (2000.0, 14000.0)
        assert (levels[0], levels[-1]) == want_levels
    if name == "baselines":
        assert {p.scenario.network.kind for p in full.points} == {"straight", "three_lane"}
    if name == "ring_gamma":
        gains = {tuple(p.scenario.controller.law_params().c2_gamma) for p in full.points}
        assert gains == {(0.5, 0.0), (1.0, 0.0), (2.0, 0.0)}


# --------------------------------------------------------------------------------------
# Rows and the results table
# --------------------------------------------------------------------------------------


def test_rows_are_written_atomically_and_read_back(tmp_path):
    row = {"run_id": "abc", "status": "failed", "error": "x, \"quoted\"\nsecond line",
           "demand.cav_share": 0.5, "seed": 1, "variant": None}
    sw.write_row(tmp_path / "abc", row)
    assert [p.name for p in (tmp_path / "abc").iterdir()] == ["row.csv"]  # no temp file left
    back = sw.read_row(tmp_path / "abc")
    assert back["error"] == row["error"] and back["demand.cav_share"] == 0.5
    assert back["variant"] is None
    assert sw.read_row(tmp_path / "missing") is None


def test_results_frame_puts_keys_parameters_and_versions_first():
    df = sw.results_frame(
        [{"edie_flow_vph": 1.0, "seed": 1, "status": "ok", "run_id": "a",
          "demand.cav_share": 0.5, "sumo_version": "1.28.0", "error": ""},
         {"run_id": "b", "status": "failed", "error": "boom", "seed": 2,
          "demand.cav_share": 1.0}],
        ["demand.cav_share"],
    )
    assert list(df.columns) == ["run_id", "status", "error", "demand.cav_share", "seed",
                                "sumo_version", "edie_flow_vph"]
    assert df["edie_flow_vph"].isna().tolist() == [False, True]


def test_parsers_register_subcommands():
    ap = argparse.ArgumentParser(prog="cosim")
    sub = ap.add_subparsers(dest="command", required=True)
    from cosim.analysis import add_analyse_parser

    sw.add_sweep_parser(sub)
    add_analyse_parser(sub)
    ns = ap.parse_args(["sweep", "x.toml", "--smoke", "--resume", "--dask-local", "2"])
    assert ns.func is sw.cmd_sweep and ns.smoke and ns.resume and ns.dask_local == 2
    ns = ap.parse_args(["analyse", "out", "--no-figures"])
    assert ns.func.__name__ == "cmd_analyse" and ns.no_figures
    with pytest.raises(SystemExit):
        ap.parse_args(["sweep", "x.toml", "--scheduler", "tcp://h:1", "--dask-local", "2"])


# --------------------------------------------------------------------------------------
# Running (SUMO in worker processes only)
# --------------------------------------------------------------------------------------


@pytest.fixture
def sumo_env(tmp_path_factory, monkeypatch):
    """Workers inherit the environment: a private network cache for the tests."""
    monkeypatch.setenv("COSIM_NETWORK_CACHE", str(tmp_path_factory.mktemp("network_cache")))
    monkeypatch.delenv(sw.CRASH_ENV, raising=False)


def _results(out: Path) -> pd.DataFrame:
    return pd.read_csv(out / "results.csv").set_index("run_id")


REPO = Path(__file__).resolve().parents[1]


def _cli_sweep(*args: str) -> subprocess.CompletedProcess:
    """``cosim sweep ARGS --start-method forkserver`` in a new process (the environment
    inherited): one import of cosim for all of the sweep's runs, each still in a process
    of its own. Exit status and output in the result."""
    cmd = [sys.executable, "-m", "cosim.cli.main", "sweep", *args,
           "--start-method", "forkserver"]
    return subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600)


@pytest.mark.sumo
@pytest.mark.slow(seconds=8)
def test_a_dying_worker_loses_no_finished_run_and_resume_completes(
    tmp_path, sumo_env, monkeypatch, capsys
):
    """One grid point's worker dies (os._exit(1), as if killed): the pool breaks, the
    other runs are finished (or re-run if the broken pool interrupted them), the dead
    one is recorded failed with its reason; --resume then runs only that one."""
    f = _write(tmp_path, TINY)
    plan = sw.load_sweep(f)
    ids = [p.run_id for p in plan.points]
    victim = ids[1]
    out = tmp_path / "out"
    monkeypatch.setenv(sw.CRASH_ENV, victim)
    # the runs forked from one preloaded server (up to four worker processes: the victim,
    # its neighbour and the runs re-run after the pool broke); --resume below spawns its run
    first = _cli_sweep(str(f), "--out", str(out), "--workers", "2", "--quiet")
    assert first.returncode == 1, first.stderr
    assert "1 run failed" in first.stdout
    res = _results(out)
    assert list(res.index) == ids
    assert res.loc[victim, "status"] == "failed"
    assert "worker process died" in res.loc[victim, "error"]
    survivors = [i for i in ids if i != victim]
    assert (res.loc[survivors, "status"] == "ok").all()
    assert (res.loc[survivors, "vehicles_inserted"] > 0).all()
    assert res.loc[victim, "sumo_version"] == res.loc[survivors[0], "sumo_version"]
    for i in survivors:
        assert (out / "runs" / i / "summary.csv").is_file()
        assert (out / "runs" / i / "intervals.csv").is_file()
    kept = {i: (out / "runs" / i / "row.csv").read_text() for i in survivors}
    mtimes = {i: (out / "runs" / i / "row.csv").stat().st_mtime_ns for i in survivors}
    for col in ("demand.inflow_vph", "demand.cav_share", "controller.kind", "seed",
                "cosim_version", "wall_time_s", "edie_flow_vph", "min_gap_m"):
        assert col in res.columns

    # an existing sweep folder is not silently reused
    monkeypatch.delenv(sw.CRASH_ENV)
    assert sw.main([str(f), "--out", str(out), "--quiet"]) == 2
    assert "--resume" in capsys.readouterr().err

    assert sw.main([str(f), "--out", str(out), "--workers", "2", "--quiet", "--resume"]) == 0
    assert "1 run in" in capsys.readouterr().out
    res = _results(out)
    assert (res["status"] == "ok").all() and list(res.index) == ids
    for i in survivors:  # finished runs were not run again
        assert (out / "runs" / i / "row.csv").read_text() == kept[i]
        assert (out / "runs" / i / "row.csv").stat().st_mtime_ns == mtimes[i]

    # and the analysis reads the real run folders
    from cosim.analysis import main as analyse_main

    assert analyse_main([str(out), "--no-figures"]) == 0
    iv = pd.read_csv(out / "analysis" / "fd_intervals.csv")
    assert set(iv["run_id"]) == set(ids) and len(iv) == 3 * 3  # 15 s after warm-up / 5 s
    cap = pd.read_csv(out / "analysis" / "capacity.csv")
    assert len(cap) == 1 and cap.loc[0, "capacity_vph"] == pytest.approx(
        res["edie_flow_vph"].max())


@pytest.mark.sumo
@pytest.mark.slow(seconds=4)
def test_a_failing_run_is_recorded_and_the_others_continue(tmp_path, sumo_env):
    """A run that raises (here: a ring too dense to place its vehicles) is a failed row."""
    f = _write(tmp_path, """
[sweep]
name = "ringfail"
base = "ring"
[overrides]
scenario.duration_s = 10.0
scenario.warmup_s = 2.0
scenario.interval_s = 4.0
network.circumference_m = 300.0
[axes]
"demand.ring_density_vpkm" = [30.0, 2000.0]
""")
    out = tmp_path / "out"
    done = _cli_sweep(str(f), "--out", str(out), "--workers", "2", "--quiet")
    assert done.returncode == 1, done.stderr
    assert "2 runs in " in done.stdout and ": 1 ok, 1 failed" in done.stdout  # the counts
    res = pd.read_csv(out / "results.csv")
    bad = res[res["status"] == "failed"].iloc[0]
    assert bad["demand.ring_density_vpkm"] == 2000.0
    assert "ring_density_vpkm" in bad["error"]
    assert "too high" in bad["error"] or "does not fit" in bad["error"]
    assert (out / "runs" / bad["run_id"] / "error.txt").is_file()


@pytest.mark.sumo
@pytest.mark.slow(seconds=7)
def test_the_sweep_runs_on_a_local_dask_cluster(tmp_path, sumo_env):
    """A LocalCluster of one worker process (each extra one costs ~1 s of CPU to start);
    each run in a subprocess of it: the two runs go through the same long-lived worker,
    one after the other (libsumo's one simulation per process holds because each run is
    a subprocess of its own)."""
    pytest.importorskip("distributed")
    f = _write(tmp_path, TINY.replace("[1500.0, 3000.0, 4500.0]", "[1500.0, 3000.0]"))
    out = tmp_path / "out"
    assert sw.main([str(f), "--out", str(out), "--dask-local", "1", "--quiet"]) == 0
    res = _results(out)
    assert len(res) == 2 and (res["status"] == "ok").all()
    assert (res["edie_flow_vph"] > 0).all()
    assert res["host"].notna().all()
    assert os.environ.get(sw.CRASH_ENV) is None


# --------------------------------------------------------------------------------------
# Bad options and output folders: one line, exit 2, nothing written
# --------------------------------------------------------------------------------------


def _one_error(capsys, *needles: str) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("args, needle", [
    (["--workers", "0"], "--workers must be an integer >= 1, got 0"),
    (["--workers", "-3"], "--workers must be an integer >= 1, got -3"),
    (["--dask-local", "0"], "--dask-local must be an integer >= 1, got 0"),
    (["--dask-local", "-1"], "--dask-local must be an integer >= 1"),
    (["--workers", "2", "--dask-local", "2"], "--workers sets the local process pool"),
    (["--resume", "--replace"], "either --resume"),
    (["--scheduler", "tcp://127.0.0.1:1"], "cannot reach the Dask scheduler tcp://127.0.0.1:1"),
    (["--scheduler", "tcp://nohost"], "not an address"),
])
def test_bad_execution_options_leave_no_folder(tmp_path, sumo_env, capsys, args, needle):
    f = _write(tmp_path, TINY)
    out = tmp_path / "out"
    assert sw.main([str(f), "--out", str(out), "--quiet", *args]) == 2
    _one_error(capsys, needle)
    assert not out.exists()


def test_output_locations_are_checked_before_anything_is_written(tmp_path, sumo_env, capsys):
    f = _write(tmp_path, TINY)
    a_file = tmp_path / "file.csv"
    a_file.write_text("x")
    assert sw.main([str(f), "--out", str(a_file), "--quiet"]) == 2
    _one_error(capsys, "is an existing file")
    assert sw.main([str(f), "--out", str(a_file / "sub"), "--quiet"]) == 2
    _one_error(capsys, "which is a file")
    assert sw.main([str(f), "--out", "/sys/cosim_sweep_test", "--quiet"]) == 2
    _one_error(capsys, "cosim_sweep_test")
    assert not os.path.exists("/sys/cosim_sweep_test")
    # a folder that is not a sweep's: refused without flags, refused for --resume
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    assert sw.main([str(f), "--out", str(other), "--quiet"]) == 2
    _one_error(capsys, "is not empty", "--replace")
    assert sw.main([str(f), "--out", str(other), "--quiet", "--resume"]) == 2
    _one_error(capsys, "holds no sweep plan")
    assert [p.name for p in other.iterdir()] == ["notes.txt"]


def test_resume_checks_that_the_folder_holds_the_same_plan(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "runs").mkdir()
    plan = sw.load_sweep(_write(tmp_path, TINY))
    sw.results.write_plan(out, plan)
    other = _write(tmp_path, TINY.replace("[1500.0, 3000.0, 4500.0]", "[1500.0, 3500.0]"), "o.toml")
    before = sorted(p.name for p in out.rglob("*"))
    assert sw.main([str(other), "--out", str(out), "--resume", "--quiet"]) == 2
    _one_error(capsys, "holds another plan", "'tiny', 3 runs", "1 not in the folder")
    assert sorted(p.name for p in out.rglob("*")) == before


def test_a_sweep_name_cannot_leave_the_outputs_folder():
    plan = _plan('[sweep]\nname = "../../evil"\n')
    assert sw.default_out_dir(plan) == Path("outputs") / "sweeps" / "evil"


def test_a_folder_in_use_by_a_live_sweep_is_refused(tmp_path, capsys):
    """Another process holds OUT/.sweep.lock (as a running sweep does): no --resume,
    no --replace into it."""
    f = _write(tmp_path, TINY)
    out = tmp_path / "out"
    out.mkdir()
    plan = sw.load_sweep(f)
    sw.results.write_plan(out, plan)
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import fcntl, sys, time\n"
         f"fh = open({str(out / '.sweep.lock')!r}, 'a+')\n"
         "fcntl.flock(fh.fileno(), fcntl.LOCK_EX)\n"
         "fh.write('{\"pid\": 4242}'); fh.flush(); print('locked', flush=True)\n"
         "time.sleep(60)\n"],
        stdout=subprocess.PIPE, text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        for flag in ("--resume", "--replace"):
            assert sw.main([str(f), "--out", str(out), "--quiet", flag]) == 2
            _one_error(capsys, "in use by another 'cosim sweep' (process 4242)")
        assert (out / "sweep.json").is_file()
    finally:
        holder.kill()
        holder.wait()


def test_resume_refuses_while_a_run_is_still_held_by_a_live_process(tmp_path, monkeypatch):
    """A run's STARTED marker locked by a live process (an orphan that has not ended):
    resume waits IN_FLIGHT_WAIT_S, then refuses without touching the folder."""
    from cosim.sweeps import execute, locks

    monkeypatch.setattr(execute, "IN_FLIGHT_WAIT_S", 0.2)
    f = _write(tmp_path, TINY)
    plan = sw.load_sweep(f)
    out = tmp_path / "out"
    run = out / "runs" / plan.points[0].run_id
    run.mkdir(parents=True)
    sw.results.write_plan(out, plan)
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import fcntl, json, os, time\n"
         f"fh = open({str(run / 'STARTED')!r}, 'w')\n"
         "fcntl.flock(fh.fileno(), fcntl.LOCK_EX)\n"
         "fh.write(json.dumps({'pid': os.getpid()})); fh.flush(); print('locked', flush=True)\n"
         "time.sleep(60)\n"],
        stdout=subprocess.PIPE, text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        assert locks.run_in_flight(run) == holder.pid
        with pytest.raises(ConfigError, match=f"1 run of .* still running .*pid {holder.pid}"):
            sw.run_sweep(plan, out, resume=True, progress=False)
        assert sorted(p.name for p in run.iterdir()) == ["STARTED"]
    finally:
        holder.kill()
        holder.wait()
    assert locks.run_in_flight(run) is None  # the kernel released the lock


@pytest.mark.sumo
@pytest.mark.slow(seconds=2.5)
def test_replace_clears_the_old_sweep_and_runs_again(tmp_path, sumo_env, capsys):
    f = _write(tmp_path, TINY.replace("[1500.0, 3000.0, 4500.0]", "[1500.0]"))
    out = tmp_path / "out"
    (out / "runs" / "stale").mkdir(parents=True)
    (out / "runs" / "stale" / "trajectories.csv").write_text("old")
    (out / "results.csv").write_text("run_id,status\nstale,ok\n")
    assert sw.main([str(f), "--out", str(out), "--quiet", "--replace"]) == 0
    assert not (out / "runs" / "stale").exists()
    res = _results(out)
    assert len(res) == 1 and (res["status"] == "ok").all() and "stale" not in res.index


# --------------------------------------------------------------------------------------
# A sweep whose process is killed: its workers end, resume does not run anything twice
# --------------------------------------------------------------------------------------


def _log(path: Path) -> list[tuple[str, str, int, float]]:
    if not path.is_file():
        return []
    out = []
    for ln in path.read_text().splitlines():
        event, rid, pid, t = ln.split()
        out.append((event, rid, int(pid), float(t)))
    return out


@pytest.mark.sumo
@pytest.mark.parametrize("start_method", [
    pytest.param("spawn", marks=pytest.mark.slow(seconds=5)),
    pytest.param("forkserver", marks=pytest.mark.slow(seconds=7)),
])
def test_killing_the_sweep_ends_its_workers_and_resume_runs_each_run_once(
    tmp_path, sumo_env, monkeypatch, start_method
):
    """kill -9 of the sweep process while two runs are in progress: both workers end
    within a few seconds (their watchdog sees the parent gone), none finishes its run;
    a --resume started at once completes the grid, and no run ran twice at a time."""
    from cosim.sweeps.locks import process_alive

    # two runs, long enough to be killed in flight: a forked run starts simulating at once
    # (150 s simulated: ~0.8 s of wall time from both starts to the first end); a spawned
    # one logs its start before it imports the simulator and loads the kernels (~1.5 s),
    # so TINY's 20 s keep it in flight as long (~1.8 s) and cost the resume less
    duration = {"forkserver": "150.0", "spawn": "20.0"}[start_method]
    f = _write(tmp_path, TINY.replace("duration_s = 20.0", f"duration_s = {duration}")
               .replace("[1500.0, 3000.0, 4500.0]", "[1500.0, 3000.0]"))
    out = tmp_path / "out"
    log = tmp_path / "log.txt"
    monkeypatch.setenv(sw.TEST_LOG_ENV, str(log))
    sweep = [sys.executable, "-m", "cosim.cli.main", "sweep", str(f), "--out", str(out),
             "--workers", "2", "--quiet"]
    parent = subprocess.Popen(sweep + ["--start-method", start_method], cwd=REPO,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    deadline = time.monotonic() + 120
    while sum(e == "start" for e, *_ in _log(log)) < 2:
        assert time.monotonic() < deadline, "the runs did not start"
        assert parent.poll() is None, "the sweep ended before it was killed"
        time.sleep(0.05)
    os.kill(parent.pid, signal.SIGKILL)
    t_kill = time.time()
    parent.wait()
    orphans = {pid: rid for e, rid, pid, _ in _log(log) if e == "start"}
    assert len(orphans) == 2

    # the resume forks its runs from a preloaded server whichever way the killed sweep
    # started them (what is tested here is which runs it runs, not how it starts them)
    resume = subprocess.Popen(sweep + ["--start-method", "forkserver", "--resume"], cwd=REPO,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    while any(process_alive(pid) for pid in orphans):
        assert time.time() - t_kill < 5.0, "workers still running 5 s after their sweep died"
        time.sleep(0.05)
    stdout, stderr = resume.communicate(timeout=600)
    assert resume.returncode == 0, stderr
    assert "2 runs in" in stdout  # both killed runs, again

    events = _log(log)
    ended_early = {pid for e, _, pid, _ in events if e == "orphaned"}
    assert ended_early == set(orphans)
    assert not [e for e in events if e[0] == "end" and e[2] in orphans]
    ends = Counter(rid for e, rid, _, _ in events if e == "end")
    res = _results(out)
    assert sorted(ends) == sorted(res.index) and set(ends.values()) == {1}
    assert (res["status"] == "ok").all() and len(res) == 2
    for e, rid, pid, t in events:  # a run restarts only after its orphan ended
        if e == "start" and pid not in orphans:
            gone = [t_o for e_o, r_o, p_o, t_o in events if e_o == "orphaned" and r_o == rid]
            assert all(t > t_o for t_o in gone)


# --------------------------------------------------------------------------------------
# A sweep varies any kind's parameters (SUMO-free road world: fast)
# --------------------------------------------------------------------------------------

KINDS_SWEEP = """
seeds = [1]

[sweep]
name = "kinds"
base = "ring"

[overrides]
scenario.world = "road"
scenario.duration_s = 20.0
scenario.warmup_s = 5.0
scenario.interval_s = 5.0
demand.cav_share = 1.0
demand.ring_density_vpkm = 42.0

[[variants]]
name = "vicsek_soft"
controller.kind = "vicsek"
controller.params.align_gain_per_s = 0.1

[[variants]]
name = "vicsek_stiff"
controller.kind = "vicsek"
controller.params.align_gain_per_s = 2.0

[[variants]]
name = "formation_soft"
controller.kind = "formation"
controller.params.max_pull_mps2 = 0.2

[[variants]]
name = "formation_stiff"
controller.kind = "formation"
controller.params.max_pull_mps2 = 1.5
"""

_KIND_PARAMS = {  # variant -> (kind, its parameter column, value)
    "vicsek_soft": ("vicsek", "controller.params.align_gain_per_s", 0.1),
    "vicsek_stiff": ("vicsek", "controller.params.align_gain_per_s", 2.0),
    "formation_soft": ("formation", "controller.params.max_pull_mps2", 0.2),
    "formation_stiff": ("formation", "controller.params.max_pull_mps2", 1.5),
}


def test_variants_of_two_kinds_each_vary_their_own_parameter():
    plan = _plan(KINDS_SWEEP)
    assert [p.variant for p in plan.points] == list(_KIND_PARAMS)
    for p in plan.points:
        kind, col, value = _KIND_PARAMS[p.variant]
        assert p.scenario.controller.kind == kind
        assert p.scenario.controller.resolved_params()[col.rsplit(".", 1)[1]] == value
        assert p.scenario.scenario.world == "road"
    cols = plan.param_columns()
    assert {"controller.kind", "controller.params.align_gain_per_s",
            "controller.params.max_pull_mps2"} <= set(cols)


@pytest.mark.parametrize("text, message", [
    # a parameter of the other kind: refused for the variant that does not have it
    (KINDS_SWEEP.replace("max_pull_mps2 = 1.5", "radius_m = 9.0"),
     r"grid point 4/4 \(variant=formation_stiff.*unknown key 'radius_m' \(known: .*K_for"),
    # an axis every variant gets: fine for one kind, named for the other
    (KINDS_SWEEP + '\n[axes]\n"controller.params.K_vel" = [0.1, 0.2]\n',
     r"grid point 1/8 \(variant=vicsek_soft, controller.params.K_vel=0.1.*"
     r"unknown key 'K_vel' \(known: align_gain_per_s"),
])
def test_a_parameter_the_grid_points_kind_lacks_is_one_line(text, message):
    with pytest.raises(ConfigError, match=message):
        _plan(text)


@pytest.mark.slow(seconds=3.5)
def test_a_sweep_of_two_kinds_fills_each_kinds_parameter_column(tmp_path, sumo_env):
    f = _write(tmp_path, KINDS_SWEEP)
    out = tmp_path / "out"
    done = _cli_sweep(str(f), "--out", str(out), "--workers", "2", "--quiet")
    assert done.returncode == 0, done.stderr
    res = pd.read_csv(out / "results.csv").set_index("variant")
    assert list(res.index) == list(_KIND_PARAMS) and (res["status"] == "ok").all()
    for variant, (kind, col, value) in _KIND_PARAMS.items():
        row = res.loc[variant]
        assert row["controller.kind"] == kind and row[col] == value
        other = ({"controller.params.align_gain_per_s", "controller.params.max_pull_mps2"}
                 - {col}).pop()
        assert pd.isna(row[other])  # not a parameter of this kind: empty, not a default
        assert row["collisions_geometric_cav"] == 0
        cfg = tomllib.loads((out / row["run_dir"] / "config.toml").read_text())["controller"]
        assert cfg["kind"] == kind and cfg["params"][col.rsplit(".", 1)[1]] == value
    # the parameter reached the law: the runs differ where it acts (a weaker pull
    # forms the groups more slowly)
    assert res.loc["formation_stiff", "flock_formation_error_m"] < 0.8 * res.loc[
        "formation_soft", "flock_formation_error_m"]
    # strong alignment keeps the ring's spacing; weak lets faster CAVs close in
    assert res.loc["vicsek_stiff", "min_gap_m"] > 1.5 * res.loc["vicsek_soft", "min_gap_m"]


# --------------------------------------------------------------------------------------
# The headline experiment (issue 13)
# --------------------------------------------------------------------------------------


def test_the_headline_sweep_is_fair_stationary_and_small_enough():
    """`cosim sweep headline`: named PART/ARM#RUN runs; the SUMO-free road world only
    without human drivers; ring runs stationary by design (>= 300 s warm-up, >= 600 s
    measured); the bottleneck arms at one taper (the lane arm: a closed lane), queued from
    t = 0 by a standing queue upstream, 900 s measured, 5 seeds; TUM's ring set-up; equal
    vehicles and desired speeds in every arm; the three time gaps for the CAV arms; a
    smoke form of a few short runs."""
    full = sw.load_sweep("headline")
    smoke = sw.load_sweep("headline", smoke=True)
    assert len(full.points) == 67 and len(smoke.points) == 4
    parts = Counter(p.variant.split("/")[0] for p in full.points)
    assert parts == {"bottleneck": 25, "tum_ring": 24, "ring_fd": 18}
    arms = Counter(p.variant.split("#")[0] for p in full.points
                   if p.variant.startswith("bottleneck"))
    assert set(arms.values()) == {5} and len(arms) == 5
    for p in full.points + smoke.points:
        sc, part = p.scenario, p.variant.split("/")[0]
        assert "#" in p.variant
        if sc.scenario.world == "road":
            assert sc.demand.cav_share == 1.0, p.variant  # no human drivers
        assert sc.demand.desired_speed_mps == (25.0, 35.0)
        assert [c[:2] for c in sc.demand.size_classes] == [
            (3.2, 1.6), (3.9, 1.7), (4.25, 1.8), (4.55, 1.82), (5.2, 1.88)]
        if p in smoke.points:
            assert sc.scenario.duration_s <= 90.0
            continue
        if part in ("tum_ring", "ring_fd"):
            assert sc.network.kind == "ring" and sc.network.circumference_m == 1000.0
            assert sc.scenario.warmup_s >= 300.0
            assert sc.scenario.duration_s - sc.scenario.warmup_s >= 600.0
        if part == "tum_ring":
            assert sc.scenario.world == "sumo" and sc.network.width_m == 10.2
            assert sc.demand.ring_density_vpkm == 225.0
        if part == "bottleneck" and "lc2013" in p.variant:  # 3 -> 2 lanes at 600 m
            assert sc.network.kind == "three_lane" and sc.demand.cav_share == 0.0
            assert (sc.obstacle.s_m, sc.obstacle.d_m, sc.network.length_m) == (
                600.0, -3.4, 900.0)
        elif part == "bottleneck":
            assert sc.scenario.world == "sumo" and sc.network.kind == "varying_width"
            widths = [w for _, w in sc.network.width_profile]
            assert widths[0] == 10.2 and widths[-1] == 6.8 and widths == sorted(widths)[::-1]
            assert sc.network.width_profile[0][0] == 520.0  # the taper starts at 520 m
        if part == "bottleneck":
            assert sc.demand.queue_vpkm == 200.0 and sc.demand.queue_span_m[0] == 200.0
            assert sc.scenario.duration_s - sc.scenario.warmup_s >= 900.0
    shares = Counter(p.scenario.demand.cav_share for p in full.points
                     if p.variant.startswith("tum_ring"))
    assert shares == {s: 3 for s in (0.0, 0.1, 0.2, 0.5, 0.9, 0.95, 0.99, 1.0)}
    gaps = {(p.variant.split("#")[0], p.scenario.controller.law_params().time_gap_s)
            for p in full.points if p.variant.startswith("ring_fd")}
    assert {g for _, g in gaps} == {0.6, 0.8, 1.0}
    modes = {p.scenario.controller.law_params().lateral_mode for p in full.points}
    assert modes == {"free", "fixed"}


def test_the_tum_protocol_sweep_is_their_protocol():
    """`cosim sweep tum_protocol`: TUM LaneFreeDrive's ring runs (TRB 2024): 8 densities x
    their table's 7 CAV shares x 3 seeds on a 1 km x 10.2 m ring, their ring's five car
    sizes, random start at rest, step 0.25 s, a detector at 339.09 m counted in 300 s
    intervals from 2 100 to 3 900 s; seeds first (an interrupted sweep has whole seeds)."""
    full = sw.load_sweep("tum_protocol")
    smoke = sw.load_sweep("tum_protocol", smoke=True)
    assert len(full.points) == 8 * 7 * 3 and len(smoke.points) == 4
    grid = Counter((p.scenario.demand.ring_density_vpkm, p.scenario.demand.cav_share)
                   for p in full.points)
    assert set(grid.values()) == {3}
    assert {k for k, _ in grid} == {50.0 * i for i in range(1, 9)}
    assert {s for _, s in grid} == {0.0, 0.1, 0.5, 0.9, 0.95, 0.99, 1.0}
    assert [p.scenario.scenario.seed for p in full.points[:56]] == [1] * 56
    for p in full.points:
        sc = p.scenario
        assert (sc.network.kind, sc.network.circumference_m, sc.network.width_m) == (
            "ring", 1000.0, 10.2)
        assert [c[:2] for c in sc.demand.size_classes] == [
            (3.2, 1.6), (3.4, 1.7), (3.9, 1.7), (4.55, 1.82), (5.2, 1.88)]
        assert sc.demand.desired_speed_mps == (25.0, 35.0)
        assert (sc.demand.ring_placement, sc.demand.ring_initial_speed_mps) == ("random", 0.0)
        s = sc.scenario
        assert (s.step_length_s, s.warmup_s, s.duration_s, s.interval_s) == (
            0.25, 2100.0, 3900.0, 300.0)
        assert sc.outputs.cross_sections_m == (339.09,)
    assert all(p.scenario.scenario.duration_s <= 40.0 for p in smoke.points)
