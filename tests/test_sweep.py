"""Sweeps: grid expansion and validation, stable run ids, surviving results, crash
recovery and --resume, the shipped sweep files, and the Dask executor.

SUMO runs happen only in worker processes (the process pool or Dask's workers); the
tests marked ``sumo`` use a tiny scenario: a 300 m road, 20 s, one 5 s interval each.
"""

from __future__ import annotations

import argparse
import os
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from cosim.errors import ConfigError
from cosim.sweeps import sweep as sw

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
controller.params.c1_alpha = [0.2, 0.4]
""")
    assert len(plan.points) == 2 * 3 * 2 * 2
    assert len({p.run_id for p in plan.points}) == len(plan.points)
    combos = {(p.scenario.demand.inflow_vph, p.scenario.demand.cav_share,
               p.scenario.controller.flocking_params().c1_alpha, p.seed) for p in plan.points}
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
    ('[axes]\n"controller.params.c9" = [1.0]\n', "unknown parameter 'controller.params.c9'"),
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
    (tmp_path / "my.toml").write_text('[scenario]\nduration_s = 33.0\nwarmup_s = 3.0\n')
    by_path = sw.load_sweep(_write(tmp_path, '[sweep]\nbase = "my.toml"\n'))
    assert by_path.points[0].scenario.scenario.duration_s == 33.0
    by_name = sw.load_sweep(_write(tmp_path, '[sweep]\nbase = "ring"\n', "r.toml"))
    assert by_name.points[0].scenario.network.kind == "ring"
    (tmp_path / "bad.toml").write_text('[scenario]\nduration_s = 33.0\n')
    with pytest.raises(ConfigError, match="base scenario .*bad.toml: scenario.warmup_s"):
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
        gains = {tuple(p.scenario.controller.flocking_params().c2_gamma) for p in full.points}
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
    from cosim.analysis.analysis import add_analyse_parser

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


@pytest.mark.sumo
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
    assert sw.main([str(f), "--out", str(out), "--workers", "2", "--quiet"]) == 1
    assert "1 run failed" in capsys.readouterr().out
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
    from cosim.analysis.analysis import main as analyse_main

    assert analyse_main([str(out), "--no-figures"]) == 0
    iv = pd.read_csv(out / "analysis" / "fd_intervals.csv")
    assert set(iv["run_id"]) == set(ids) and len(iv) == 3 * 3  # 15 s after warm-up / 5 s
    cap = pd.read_csv(out / "analysis" / "capacity.csv")
    assert len(cap) == 1 and cap.loc[0, "capacity_vph"] == pytest.approx(
        res["edie_flow_vph"].max())


@pytest.mark.sumo
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
    outcome = sw.run_sweep(sw.load_sweep(f), out, workers=2, progress=False)
    assert (outcome.n_ok, outcome.n_failed) == (1, 1)
    res = pd.read_csv(out / "results.csv")
    bad = res[res["status"] == "failed"].iloc[0]
    assert bad["demand.ring_density_vpkm"] == 2000.0
    assert "ring_density_vpkm" in bad["error"] and "too high" in bad["error"]
    assert (out / "runs" / bad["run_id"] / "error.txt").is_file()


@pytest.mark.sumo
def test_the_sweep_runs_on_a_local_dask_cluster(tmp_path, sumo_env):
    """LocalCluster with 2 worker processes; each run in a subprocess of a Dask worker."""
    pytest.importorskip("distributed")
    f = _write(tmp_path, TINY.replace("[1500.0, 3000.0, 4500.0]", "[1500.0, 3000.0]"))
    out = tmp_path / "out"
    assert sw.main([str(f), "--out", str(out), "--dask-local", "2", "--quiet"]) == 0
    res = _results(out)
    assert len(res) == 2 and (res["status"] == "ok").all()
    assert (res["edie_flow_vph"] > 0).all()
    assert res["host"].notna().all()
    assert os.environ.get(sw.CRASH_ENV) is None
