"""Sweep analysis and figures on a synthetic sweep folder (no SUMO): capacity with a
t-based confidence interval across seeds, fundamental-diagram tables, safety /
boundary / flock aggregation, failed runs, Markdown, figures and the command line."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

import cosim.analysis as an
from cosim.analysis import figures as fg

PNG = b"\x89PNG\r\n\x1a\n"
DEMANDS = (1000.0, 2000.0, 3000.0)
SEEDS = (1, 2, 3)


def _flow(share: float, demand: float, seed: int) -> float:
    """Share 0 peaks at 2000 veh/h (1800 + 10 seed); share 1 grows to the last level."""
    if share == 0.0:
        return {1000.0: 900.0, 2000.0: 1800.0, 3000.0: 1500.0}[demand] + 10.0 * seed
    return 0.9 * demand + 5.0 * seed


@pytest.fixture
def sweep_dir(tmp_path):
    rows = []
    for share in (0.0, 1.0):
        for demand in DEMANDS:
            for seed in SEEDS:
                rid = f"r{int(share)}{int(demand)}{seed}"
                q = _flow(share, demand, seed)
                v = 30.0 - demand / 1000.0
                rows.append({
                    "run_id": rid, "status": "ok", "error": "", "sweep": "synthetic",
                    "demand.inflow_vph": demand, "demand.cav_share": share,
                    "controller.kind": "flocking", "network.kind": "straight", "seed": seed,
                    "cosim_version": "0.1.0", "sumo_version": "1.28.0",
                    "edie_flow_vph": q, "edie_density_vpkm": q / (3.6 * v),
                    "space_mean_speed_mps": v,
                    "collisions_sumo_cav": int(share == 1.0 and demand == 3000.0),
                    "collisions_geometric_cav": 2 * int(share == 1.0 and demand == 3000.0),
                    "teleports": 0,
                    "min_gap_m": 10.0 - demand / 1000.0 + seed, "min_side_clearance_m": 0.5,
                    "median_time_headway_s": 1.0 + seed, "p05_time_headway_s": 0.5 * seed,
                    "boundary_vehicle_steps": seed, "boundary_vehicle_steps_cav": 0,
                    "boundary_vehicles": 1, "worst_boundary_excursion_m": 0.1 * seed,
                    "vehicle_steps": 1000,
                    "min_ttc_s": 2.0 + seed, "min_cav_ttc_s": 2.5 + seed,
                    "tet_veh_s": 0.5 * seed, "tit_veh_s2": 0.1 * seed,
                    "measured_vehicle_s": 100.0,
                    "flock_min_agent_distance_m": 3.0 + seed if share else np.nan,
                    "flock_velocity_alignment": 0.9 if share else np.nan,
                    "clip_rate_acceleration_box": 0.01 * seed,
                })
                run = tmp_path / "runs" / rid
                run.mkdir(parents=True)
                pd.DataFrame({
                    "t_start_s": [60.0, 120.0], "t_end_s": [120.0, 180.0],
                    "edie_flow_vph": [q - 50, q + 50],
                    "edie_density_vpkm": [q / (3.6 * v)] * 2,
                    "space_mean_speed_mps": [v, v],
                }).to_csv(run / "intervals.csv", index=False)
    rows.append({"run_id": "bad", "status": "failed", "error": "SumoStartError: boom",
                 "demand.inflow_vph": 3000.0, "demand.cav_share": 0.5,
                 "controller.kind": "flocking", "network.kind": "straight", "seed": 1})
    pd.DataFrame(rows).to_csv(tmp_path / "results.csv", index=False)
    (tmp_path / "sweep.json").write_text(json.dumps({
        "name": "synthetic", "axes": {"demand.inflow_vph": list(DEMANDS),
                                      "demand.cav_share": [0.0, 1.0]},
        "seeds": list(SEEDS), "variants": [], "demand_axis": "demand.inflow_vph",
        "n_points": 19,
    }))
    _trajectory_run(tmp_path / "runs" / "r130001")
    return tmp_path


def _trajectory_run(run, period=None):
    """12 vehicles, 50 steps of 0.2 s, on a 10.2 m road; half CAVs."""
    rows = []
    for k in range(12):
        for j in range(50):
            t = 0.2 * j
            s = 20.0 * k + 25.0 * t
            rows.append({"t_s": t, "id": f"v{k}", "s_m": s % period if period else s,
                         "d_m": -3.4 + 3.4 * (k % 3), "v_mps": 25.0, "v_lat_mps": 0.0,
                         "length_m": 4.5, "width_m": 1.8, "is_cav": k % 2 == 0})
    pd.DataFrame(rows).to_csv(run / "trajectories.csv", index=False)
    (run / "config.toml").write_text(
        '[network]\nkind = "three_lane"\nwidth_m = 10.2\nlength_m = 600.0\n'
    )


# --------------------------------------------------------------------------------------


def test_t_interval_is_the_student_t_half_width():
    mean, half, n = an.t_interval([1.0, 2.0, 4.0, np.nan])
    assert (mean, n) == (pytest.approx(7 / 3), 3)
    sd = np.std([1.0, 2.0, 4.0], ddof=1)
    assert half == pytest.approx(stats.t.ppf(0.975, 2) * sd / math.sqrt(3))
    assert math.isnan(an.t_interval([5.0])[1])
    assert an.t_interval([])[2] == 0


def test_series_and_demand_columns(sweep_dir):
    res = an.load_results(sweep_dir)
    assert res.demand_col == "demand.inflow_vph"
    assert res.series_cols == ["demand.cav_share", "controller.kind"]
    assert len(res.ok) == 18 and len(res.failed) == 1


def test_capacity_is_the_seed_mean_of_per_seed_maxima_with_a_t_interval(sweep_dir):
    cap = an.capacity_table(an.load_results(sweep_dir)).set_index("demand.cav_share")
    peaks0 = np.array([1810.0, 1820.0, 1830.0])  # share 0: at 2000 veh/h
    half0 = stats.t.ppf(0.975, 2) * peaks0.std(ddof=1) / math.sqrt(3)
    assert cap.loc[0.0, "capacity_vph"] == pytest.approx(1820.0)
    assert cap.loc[0.0, "capacity_ci_low_vph"] == pytest.approx(1820.0 - half0)
    assert cap.loc[0.0, "capacity_ci_high_vph"] == pytest.approx(1820.0 + half0)
    assert cap.loc[0.0, "demand_at_max"] == 2000.0
    assert not cap.loc[0.0, "at_grid_edge"]
    assert cap.loc[1.0, "capacity_vph"] == pytest.approx(2700.0 + 10.0)
    assert cap.loc[1.0, "at_grid_edge"]  # the maximum is at the highest demand tested
    assert (cap["n_seeds"] == 3).all() and (cap["n_demand_levels"] == 3).all()
    assert cap.loc[0.0, "capacity_of_mean_curve_vph"] == pytest.approx(1820.0)


def test_fundamental_diagram_tables(sweep_dir):
    res = an.load_results(sweep_dir)
    runs = an.fd_runs(res)
    assert len(runs) == 18 and "bad" not in set(runs["run_id"])
    iv = an.fd_intervals(res)
    assert len(iv) == 36
    assert list(iv.columns[:5]) == ["run_id", "demand.cav_share", "controller.kind",
                                    "demand.inflow_vph", "seed"]
    summ = an.fd_summary(res).set_index(["demand.cav_share", "demand.inflow_vph"])
    assert summ.loc[(0.0, 2000.0), "edie_flow_vph"] == pytest.approx(1820.0)
    assert summ.loc[(0.0, 2000.0), "n_runs"] == 3
    assert summ.loc[(0.0, 2000.0), "space_mean_speed_mps_ci"] == pytest.approx(0.0)


def test_safety_boundary_and_flock_aggregate_over_seeds(sweep_dir):
    res = an.load_results(sweep_dir)
    s = an.safety_table(res).set_index(["demand.cav_share", "demand.inflow_vph"])
    assert s.loc[(1.0, 3000.0), "collisions_sumo_cav_sum"] == 3
    assert s.loc[(1.0, 3000.0), "collisions_geometric_cav_sum"] == 6
    # geometric events: 6 over 3 runs x 1000 vehicle-steps
    assert s.loc[(1.0, 3000.0), "collisions_cav_per_1e6_vehicle_steps"] == pytest.approx(2000.0)
    assert s.loc[(0.0, 1000.0), "min_gap_m_min"] == pytest.approx(10.0)
    assert s.loc[(0.0, 1000.0), "median_time_headway_s_mean"] == pytest.approx(3.0)
    assert s.loc[(0.0, 1000.0), "min_ttc_s_min"] == pytest.approx(3.0)
    assert s.loc[(0.0, 1000.0), "min_cav_ttc_s_min"] == pytest.approx(3.5)
    assert s.loc[(0.0, 1000.0), "tit_veh_s2_sum"] == pytest.approx(0.6)
    # time exposed: 0.5 + 1.0 + 1.5 vehicle-s over 3 runs x 100 vehicle-s
    assert s.loc[(0.0, 1000.0), "tet_share"] == pytest.approx(3.0 / 300.0)
    b = an.boundary_table(res).set_index(["demand.cav_share", "demand.inflow_vph"])
    assert b.loc[(0.0, 1000.0), "boundary_vehicle_steps_sum"] == 6
    assert b.loc[(0.0, 1000.0), "worst_boundary_excursion_m_max"] == pytest.approx(0.3)
    assert b.loc[(0.0, 1000.0), "boundary_share"] == pytest.approx(6 / 3000)
    f = an.flock_table(res).set_index(["demand.cav_share", "demand.inflow_vph"])
    assert f.loc[(1.0, 1000.0), "flock_min_agent_distance_m_min"] == pytest.approx(4.0)
    assert math.isnan(f.loc[(0.0, 1000.0), "flock_min_agent_distance_m_min"])
    assert f.loc[(1.0, 1000.0), "clip_rate_acceleration_box_mean"] == pytest.approx(0.02)


def test_markdown_table_formats_numbers_and_blanks():
    df = pd.DataFrame({"a": [1.0, 2.5, np.inf], "b": ["x|y", None, "z"], "c": [True, False, True]})
    md = an.markdown_table(df).splitlines()
    assert md[0] == "| a | b | c |" and md[1] == "|---|---|---|"
    assert md[2] == "| 1 | x\\|y | yes |"
    assert md[3] == "| 2.5 |  | no |"
    assert md[4].startswith("| inf |")
    assert an.markdown_table(pd.DataFrame({"q": [12419.6]})).splitlines()[2] == "| 12420 |"


def test_series_columns_with_variants_drop_what_the_variant_fixes():
    table = pd.DataFrame({
        "variant": ["a", "a", "b", "b"], "network.kind": ["straight"] * 2 + ["three_lane"] * 2,
        "demand.cav_share": 0.0, "controller.kind": "sumo", "demand.inflow_vph": [1, 2, 1, 2],
        "network.width_m": [10.2, 8.0, 10.2, 8.0],
    })
    cols = an.series_columns(table, {}, "demand.inflow_vph")
    assert cols == ["variant", "demand.cav_share", "controller.kind", "network.width_m"]


def test_analyse_writes_tables_report_and_figures(sweep_dir):
    a = an.analyse(sweep_dir)
    out = sweep_dir / "analysis"
    for name in ("capacity", "fd_summary", "safety", "boundary", "flock", "failed"):
        assert (out / f"{name}.csv").is_file() and (out / f"{name}.md").is_file()
    assert (out / "fd_runs.csv").is_file() and (out / "fd_intervals.csv").is_file()
    failed = pd.read_csv(out / "failed.csv")
    assert list(failed["run_id"]) == ["bad"] and "boom" in failed.loc[0, "error"]
    report = (out / "report.md").read_text()
    assert "18 ok, 1 failed" in report and "## Capacity" in report
    figs = {p.name for p in a.files if p.suffix == ".png"}
    assert figs == {"fundamental_diagram.png", "capacity.png",
                    "r130001_time_space.png", "r130001_top_view.png"}
    for name in figs:
        assert (out / "figures" / name).read_bytes()[:8] == PNG


def test_command_line(sweep_dir, tmp_path, capsys):
    assert an.main([str(sweep_dir), "--no-figures", "--out", str(tmp_path / "a")]) == 0
    text = capsys.readouterr().out
    assert "capacity" in text and "1 failed runs" in text
    assert not (tmp_path / "a" / "figures").exists()
    assert an.main([str(tmp_path / "nowhere")]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert an.main([str(sweep_dir), "--run", "r010001"]) == 2  # no trajectories there
    assert "trajectories" in capsys.readouterr().err
    # a single run's folder: the run figures
    run = sweep_dir / "runs" / "r130001"
    (run / "summary.csv").write_text("edie_flow_vph\n1.0\n")
    assert an.main([str(run), "--times", "1", "5"]) == 0
    assert (run / "analysis" / "top_view.png").is_file()


def test_road_geometry_from_the_network_table():
    edges, lanes, period = fg.road_geometry(
        {"kind": "varying_width", "width_profile": [[100.0, 10.2], [50.0, 6.8], [100.0, 10.2]]}
    )
    r, l = edges(np.array([50.0, 120.0, 200.0]))
    assert np.allclose(l, [5.1, 3.4, 5.1]) and np.allclose(r, -l)
    assert lanes == [] and period is None
    edges, lanes, period = fg.road_geometry({"kind": "three_lane", "width_m": 10.2})
    assert np.allclose(lanes, [-1.7, 1.7])
    _, _, period = fg.road_geometry({"kind": "ring", "circumference_m": 500.0})
    assert period == 500.0
    assert fg.road_geometry({"kind": "file"})[0] is None


def test_run_figures_on_a_ring(tmp_path):
    run = tmp_path / "ring_run"
    run.mkdir()
    _trajectory_run(run, period=100.0)
    (run / "config.toml").write_text('[network]\nkind = "ring"\ncircumference_m = 100.0\n')
    paths = fg.plot_run(run, tmp_path / "figs", times=[2.0])
    assert [p.name for p in paths] == ["time_space.png", "top_view.png"]
    assert all(p.read_bytes()[:8] == PNG for p in paths)
    assert fg.series_label(["demand.cav_share", "controller.kind", "network.width_m"],
                           [0.25, "flocking", 8.0]) == "CAV 25 %, flocking, width 8 m"


def test_animated_top_view_has_one_frame_per_interval_and_vehicles_move(tmp_path):
    from PIL import Image, ImageChops

    run = tmp_path / "run"
    run.mkdir()
    _trajectory_run(run)
    paths = fg.plot_run(run, tmp_path / "figs", animate=True, t_range=(2.0, 8.0))
    gif = paths[-1]
    assert gif.name == "top_view.gif" and gif.read_bytes()[:6] == b"GIF89a"
    with Image.open(gif) as im:
        assert im.n_frames == 13  # 2.0, 2.5, ..., 8.0 s
        im.seek(0)
        first = im.convert("RGB")
        im.seek(12)
        last = im.convert("RGB")
    assert ImageChops.difference(first, last).getbbox() is not None  # the cars moved


def test_animate_refuses_a_backwards_time_range(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    _trajectory_run(run)
    pd.DataFrame([{"edie_flow_vph": 1.0}]).to_csv(run / "summary.csv", index=False)
    proc = subprocess.run([sys.executable, "-m", "cosim.cli.main", "analyse", str(run), "--animate",
                           "--t-range", "8", "2"], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "--t-range must be increasing" in proc.stderr
    assert "Traceback" not in proc.stderr



# --------------------------------------------------------------------------------------
# The smoke report describes the grid that ran
# --------------------------------------------------------------------------------------


def test_a_smoke_report_describes_the_smoke_grid_not_the_full_one(tmp_path):
    import tomllib

    from cosim.sweeps.plan import sweep_from_dict

    text = """
seeds = [1, 2, 3]
[sweep]
name = "big"
description = "FULL GRID: demand 1000-9000 veh/h x 3 shares, 3 seeds"
[overrides]
scenario.duration_s = 600.0
[axes]
"demand.inflow_vph" = [1000.0, 5000.0, 9000.0]
"demand.cav_share" = [0.0, 0.5, 1.0]
[smoke]
seeds = [7]
[smoke.overrides]
scenario.duration_s = 40.0
scenario.warmup_s = 10.0
scenario.interval_s = 15.0
[smoke.axes]
"demand.inflow_vph" = [4000.0]
"""
    plan = sweep_from_dict(tomllib.loads(text), smoke=True)
    (tmp_path / "sweep.json").write_text(json.dumps(plan.to_json(), default=str))
    rows = [{"run_id": p.run_id, "status": "ok", "error": "", "demand.inflow_vph": 4000.0,
             "demand.cav_share": p.scenario.demand.cav_share, "controller.kind": "flocking",
             "seed": 7, "edie_flow_vph": 3000.0, "edie_density_vpkm": 40.0,
             "space_mean_speed_mps": 20.8} for p in plan.points]
    pd.DataFrame(rows).to_csv(tmp_path / "results.csv", index=False)
    an.analyse(tmp_path, figures=False)
    report = (tmp_path / "analysis" / "report.md").read_text()
    grid = report.split("## Grid that ran", 1)[1].split("\n## ", 1)[0]
    assert report.startswith("# Sweep analysis: big_smoke")
    assert "Smoke test** of the sweep 'big'" in report
    assert "FULL GRID" not in report
    assert "- demand.inflow_vph: 4000 (1 value)" in grid
    assert "- demand.cav_share: 0, 0.5, 1 (3 values)" in grid
    assert "- seeds: 7\n" in grid
    assert "- grid points: 1 x 3 x 1 = 3" in grid
    assert "scenario.duration_s = 40" in grid and "600" not in grid
    for full_only in ("1000", "9000", "seeds: 1, 2, 3"):
        assert full_only not in grid


def test_a_full_sweep_report_keeps_its_description_and_grid(sweep_dir):
    an.analyse(sweep_dir, figures=False)
    report = (sweep_dir / "analysis" / "report.md").read_text()
    assert "Smoke test" not in report
    assert "- demand.inflow_vph: 1000, 2000, 3000 (3 values)" in report
    assert "- seeds: 1, 2, 3" in report


# --------------------------------------------------------------------------------------
# Figure style: checked on the matplotlib objects
# --------------------------------------------------------------------------------------

UNIT = r", (veh/km|veh/h|m/s|s|m|%)( |\)|$)"


def _axes_with_units(fig):
    import re

    for ax in fig.axes:
        if ax.get_label() == "<colorbar>":
            assert re.search(UNIT, ax.get_ylabel() or ax.get_xlabel()), ax.get_ylabel()
            continue
        if not ax.get_visible():
            continue
        for label in (ax.get_xlabel(), ax.get_ylabel()):
            if label:
                assert re.search(UNIT, label), label
    # every panel's y axis is labelled, and the bottom panel's x axis
    assert all(ax.get_ylabel() for ax in fig.axes)
    assert [ax for ax in fig.axes if ax.get_label() != "<colorbar>" and ax.get_xlabel()]


def _series_lines(ax):
    return [ln for ln in ax.get_lines() if not ln.get_label().startswith("_")]


def _fd(rows: list[dict], intervals: pd.DataFrame | None = None, series=None, title="s"):
    runs = pd.DataFrame(rows)
    series = series or ["demand.cav_share", "controller.kind"]
    return fg.fundamental_diagram_figure(runs, series, "demand.inflow_vph", intervals, title)


def _fd_rows(shares, speeds=(25.0, 24.0, 23.0), extra=None):
    rows = []
    for share in shares:
        for demand, v in zip((1000.0, 2000.0, 3000.0), speeds, strict=True):
            q = 0.9 * demand
            rows.append({"demand.cav_share": share, "controller.kind": "flocking",
                         "demand.inflow_vph": demand, "edie_flow_vph": q,
                         "edie_density_vpkm": q / (3.6 * v), "space_mean_speed_mps": v,
                         **(extra or {})})
    return rows


def test_fd_series_have_distinct_colours_markers_and_readable_labels(sweep_dir):
    """The capacity_hdv5 case: 95 % and 100 % CAVs must not share colour or marker."""
    import matplotlib.colors as mcolors
    import matplotlib.pyplot as plt

    fig = _fd(_fd_rows([1.0, 0.95]), title="capacity_hdv5")
    ax_q, ax_v = fig.axes
    lines = _series_lines(ax_q)
    assert [ln.get_label() for ln in lines] == ["CAV 95 %, flocking", "CAV 100 %, flocking"]
    colours = {mcolors.to_hex(ln.get_color()) for ln in lines}
    markers = {ln.get_marker() for ln in lines}
    assert len(colours) == 2 and len(markers) == 2
    assert colours <= {c.lower() for c in fg.PALETTE}  # the colour-blind-safe palette
    assert "capacity_hdv5" in fig._suptitle.get_text()
    _axes_with_units(fig)
    plt.close(fig)


def test_fd_baseline_variants_get_three_colours_and_variant_labels():
    """The baselines case: three variants, no CAVs: three colours, labels by variant."""
    import matplotlib.colors as mcolors
    import matplotlib.pyplot as plt

    rows = []
    for variant in ("lanefree_sl2015", "lanefree_sl2015_sumo", "three_lane_lc2013"):
        rows += _fd_rows([0.0], extra={"variant": variant})
    for r in rows:
        r["controller.kind"] = "sumo"
    fig = _fd(rows, series=["variant", "demand.cav_share", "controller.kind"], title="baselines")
    labels = [ln.get_label() for ln in _series_lines(fig.axes[0])]
    assert labels == ["lanefree sl2015, HDV only", "lanefree sl2015 sumo, HDV only",
                      "three lane lc2013, HDV only"]
    assert len({mcolors.to_hex(ln.get_color()) for ln in _series_lines(fig.axes[0])}) == 3
    assert len({ln.get_marker() for ln in _series_lines(fig.axes[0])}) == 3
    plt.close(fig)


def test_series_labels_stay_distinct_when_the_short_form_is_ambiguous():
    keys = ["demand.cav_share", "controller.kind"]
    assert fg.series_labels(keys, [[0.0, "flocking"], [0.5, "flocking"]]) == [
        "HDV only", "CAV 50 %, flocking"]
    # two controllers at 0 % CAVs: the short form would read "HDV only" twice
    assert fg.series_labels(keys, [[0.0, "flocking"], [0.0, "sumo"]]) == [
        "CAV 0 %, flocking", "CAV 0 %, SUMO-driven"]
    styles = [fg.series_style(k) for k in range(20)]
    assert len({(s["color"], s["marker"], s["linestyle"]) for s in styles}) == 20
    assert len({s["color"] for s in styles[:8]}) == 8
    assert len({s["marker"] for s in styles[:8]}) == 8


def test_fd_legend_shows_grey_per_interval_dots(sweep_dir):
    import matplotlib.colors as mcolors
    import matplotlib.pyplot as plt

    res = an.load_results(sweep_dir)
    fig = fg.fundamental_diagram_figure(an.fd_runs(res), res.series_cols, res.demand_col,
                                        an.fd_intervals(res), "synthetic")
    ax_q = fig.axes[0]
    legend = ax_q.get_legend()
    texts = [t.get_text() for t in legend.get_texts()]
    assert texts[:2] == ["HDV only", "CAV 100 %, flocking"]
    assert "per interval" in texts and any(t.startswith("per run") for t in texts)
    handle = legend.legend_handles[texts.index("per interval")]
    r, g, b, _ = mcolors.to_rgba(handle.get_color())
    assert r == g == b and 0.3 < r < 0.8  # grey
    # the interval dots themselves are that grey, and there are all 36 of them
    grey = [c for c in ax_q.collections
            if len(c.get_offsets()) == 36 and np.allclose(c.get_facecolor()[0][:3], r)]
    assert len(grey) == 1
    assert "synthetic" in fig._suptitle.get_text()
    _axes_with_units(fig)
    plt.close(fig)


def test_fd_says_when_it_holds_only_the_free_flow_branch():
    import matplotlib.pyplot as plt

    def note(fig):
        return [t.get_text() for t in fig.axes[0].texts if "free-flow" in t.get_text()]

    free = _fd(_fd_rows([1.0], speeds=(25.0, 24.5, 22.0)))  # all >= 80 % of 25 m/s
    assert len(note(free)) == 1
    assert note(free)[0].startswith("free-flow branch only: no congested point")
    assert "25.0 m/s" in note(free)[0]
    congested = _fd(_fd_rows([1.0], speeds=(25.0, 24.0, 12.0)))  # 12 < 0.8 x 25
    assert note(congested) == []
    # a congested interval is a congested point too
    iv = pd.DataFrame({"edie_density_vpkm": [80.0], "edie_flow_vph": [2000.0],
                       "space_mean_speed_mps": [6.9]})
    assert note(_fd(_fd_rows([1.0], speeds=(25.0, 24.5, 22.0)), intervals=iv)) == []
    plt.close("all")


def test_capacity_figure_style(sweep_dir):
    import matplotlib.pyplot as plt

    cap = an.capacity_table(an.load_results(sweep_dir))
    two = pd.concat([cap, cap.assign(**{"controller.kind": "sumo"})], ignore_index=True)
    fig = fg.capacity_figure(two, ["demand.cav_share", "controller.kind"], "synthetic")
    ax = fig.axes[0]
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert texts == ["flocking", "SUMO-driven"]
    lines = [c.lines[0] for c in ax.containers]  # errorbar: (data line, caps, bars)
    assert [c.get_label() for c in ax.containers] == ["flocking", "SUMO-driven"]
    assert len({ln.get_color() for ln in lines}) == 2
    assert len({ln.get_marker() for ln in lines}) == 2
    assert ax.get_xlabel() == "CAV share, %" and "veh/h" in ax.get_ylabel()
    assert "synthetic" in ax.get_title()
    plt.close(fig)


def test_time_space_diagram_tells_cavs_from_hdvs(tmp_path):
    import matplotlib.pyplot as plt

    run = tmp_path / "run"
    run.mkdir()
    _trajectory_run(run)
    tr = pd.read_csv(run / "trajectories.csv")
    fig = fg.time_space_figure(tr, title="Time-space diagram: demo")
    panels = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    assert [ax.get_title(loc="left") for ax in panels] == ["CAVs (6 vehicles)",
                                                            "HDVs (6 vehicles)"]
    segs = [ax.collections[0] for ax in panels]
    n_cav = 6 * 49  # 6 vehicles x 49 steps each
    assert [len(c.get_segments()) for c in segs] == [n_cav, n_cav]
    assert segs[0].get_cmap().name == segs[1].get_cmap().name == fg.SPEED_CMAP
    assert segs[0].get_clim() == segs[1].get_clim()
    assert panels[-1].get_xlabel() == "time, s"
    assert [c for c in fig.axes if c.get_label() == "<colorbar>"][0].get_ylabel() == \
        "speed, m/s"
    assert "demo" in fig._suptitle.get_text()
    _axes_with_units(fig)
    # a run without HDVs says so in its HDV panel
    only_cav = fg.time_space_figure(tr[tr["is_cav"]])
    hdv_panel = [ax for ax in only_cav.axes if ax.get_label() != "<colorbar>"][1]
    assert [t.get_text() for t in hdv_panel.texts] == ["no HDVs in this run"]
    plt.close("all")


def test_run_figures_are_titled_by_scenario_and_top_views_have_units(tmp_path):
    import matplotlib.pyplot as plt

    run = tmp_path / "run"
    run.mkdir()
    _trajectory_run(run)
    fig = fg.top_view_figure(run / "trajectories.csv", times=[1.0, 5.0], title="Top view: x")
    _axes_with_units(fig)
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert legend == ["CAV", "HDV"]
    plt.close(fig)
    (run / "config.toml").write_text('[scenario]\nname = "ring_demo"\n[network]\nkind = "ring"\n'
                                     'circumference_m = 600.0\n')
    seen = {}
    real = fg.save

    def spy(fig, out_path):
        seen[Path(out_path).name] = fig._suptitle.get_text()
        return real(fig, out_path)

    import unittest.mock

    with unittest.mock.patch("cosim.analysis.figures.runs.save", spy):
        fg.plot_run(run, tmp_path / "figs")
    assert seen == {"time_space.png": "Time-space diagram: ring_demo (run run)",
                    "top_view.png": "Top view: ring_demo (run run)"}


def test_gif_frames_keep_their_x_axis_label_inside_the_picture(tmp_path):
    import matplotlib.pyplot as plt

    run = tmp_path / "run"
    run.mkdir()
    _trajectory_run(run)
    fig, anim = fg.top_view_animation(run / "trajectories.csv", t_range=(2.0, 4.0),
                                      title="Top view: demo")
    fig.set_dpi(fg.ANIMATION_DPI)
    anim._init_draw()
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    ax = fig.axes[0]
    assert ax.get_xlabel() == "position s, m (lateral axis stretched)"
    box = ax.xaxis.label.get_window_extent(renderer)
    width, height = fig.canvas.get_width_height()
    assert box.y0 >= 0 and box.x0 >= 0 and box.x1 <= width and box.y1 <= height
    assert ax.yaxis.label.get_window_extent(renderer).x0 >= 0
    assert ax.get_title() == "Top view: demo"
    _axes_with_units(fig)
    plt.close(fig)


# --------------------------------------------------------------------------------------
# Rejected points and the headline experiment (issue 13)
# --------------------------------------------------------------------------------------


def _headline_rows():
    """A synthetic headline sweep: bottleneck arms, TUM's ring, a ring FD."""
    rows = []

    def row(variant, **kw):
        base = {"run_id": variant.replace("/", "_").replace("#", "_"), "status": "ok",
                "error": "", "sweep": "headline", "variant": variant, "seed": 1,
                "controller.kind": "flocking", "controller.params.time_gap_s": 0.6,
                "collisions_geometric_cav": 0, "collisions_geometric_hdv_only": 0,
                "min_ttc_s": 2.0, "tet_veh_s": 1.0, "measured_vehicle_s": 1000.0,
                "harsh_accel_share_cav": 0.01, "harsh_accel_share_hdv": np.nan,
                "safety_activations_per_cav_km": 0.5, "stationary": True,
                "safety_edge_activations": 2, "safety_side_activations": 3,
                "safety_speed_activations": 5, "safety_agent_steps": 1000,
                "flow_drift": 0.005, "entrance_limited": False, "bottleneck_kind": "",
                "bottleneck_active": False, "discharge_flow_vph": np.nan,
                "discharge_stationary": False, "capacity_note": ""}
        base.update(kw)
        rows.append(base)

    for seed, q in zip((1, 2, 3), (5000.0, 5200.0, 5400.0), strict=True):
        row(f"bottleneck/lanefree#{seed}", seed=seed, **{
            "network.kind": "varying_width", "demand.inflow_vph": 7000.0,
            "demand.cav_share": 1.0, "bottleneck_kind": "width_drop",
            "bottleneck_active": True, "discharge_flow_vph": q, "edie_flow_vph": q,
            "discharge_stationary": seed != 3})
    row("bottleneck/cav95#1", **{"network.kind": "varying_width", "demand.inflow_vph": 7000.0,
        "demand.cav_share": 0.95, "bottleneck_kind": "width_drop", "bottleneck_active": True,
        "discharge_flow_vph": 4900.0, "edie_flow_vph": 4900.0, "discharge_stationary": True})
    for seed, q in ((1, 4000.0), (2, 4200.0), (3, 4100.0)):
        row(f"bottleneck/hdv_lc2013_3lanes#{seed}", seed=seed, **{
            "network.kind": "three_lane", "demand.inflow_vph": 7000.0,
            "demand.cav_share": 0.0, "bottleneck_kind": "obstacle",
            "bottleneck_active": True, "discharge_flow_vph": q, "edie_flow_vph": q,
            "discharge_stationary": True})
    for seed in (1, 2):
        row(f"bottleneck/hdv_sl2015#{seed}", seed=seed, **{
            "network.kind": "varying_width", "demand.inflow_vph": 7000.0,
            "demand.cav_share": 0.0, "bottleneck_kind": "width_drop", "edie_flow_vph": 1500.0,
            "entrance_limited": seed == 2,
            "capacity_note": "bottleneck never active (no queue upstream with unqueued flow "
                             "downstream)"})
    for share, flows in ((0.0, (8000.0, 8100.0, 8200.0)), (0.95, (9000.0, 9400.0, 9800.0)),
                         (1.0, (12000.0, 12100.0, 12200.0))):
        for seed, q in enumerate(flows, start=1):
            row(f"tum_ring/cav{round(100 * share)}#{seed}", seed=seed, **{
                "network.kind": "ring", "demand.ring_density_vpkm": 225.0,
                "demand.cav_share": share, "edie_flow_vph": q, "edie_density_vpkm": 225.0,
                "space_mean_speed_mps": q / 225.0 / 3.6,
                "stationary": not (share == 0.95 and seed == 3),
                "flow_drift": 0.05 if (share == 0.95 and seed == 3) else 0.0})
    for mode, factor in (("lanefree", 1.0), ("fixed4", 1.25), ("rows3", 0.95)):
        for k in (125.0, 225.0):
            q = factor * (12000.0 if k == 125.0 else 9000.0)
            row(f"ring_fd/{mode}_T0.6#k{k:g}_s1", **{
                "network.kind": "ring", "demand.ring_density_vpkm": k, "demand.cav_share": 1.0,
                "controller.params.lateral_mode": "free" if mode == "lanefree" else "fixed",
                "edie_flow_vph": q, "edie_density_vpkm": k, "space_mean_speed_mps": q / k / 3.6,
                "stationary": not (mode == "lanefree" and k == 225.0),
                "flow_drift": 0.03 if (mode == "lanefree" and k == 225.0) else 0.0})
    return rows


@pytest.fixture
def headline_dir(tmp_path):
    pd.DataFrame(_headline_rows()).to_csv(tmp_path / "results.csv", index=False)
    (tmp_path / "sweep.json").write_text(json.dumps({"name": "headline", "axes": {},
                                                     "variants": [], "seeds": None}))
    return tmp_path


def test_runs_named_arm_hash_run_are_grouped_by_arm(headline_dir):
    res = an.load_results(headline_dir)
    assert res.series_cols == ["arm"] and res.demand_col == "demand_level"
    assert set(res.table["part"]) == {"bottleneck", "tum_ring", "ring_fd"}
    fd = res.table[res.table["arm"] == "ring_fd/lanefree_T0.6"]
    assert sorted(fd["demand_level"]) == [125.0, 225.0]  # ring: the density
    bn = res.table[res.table["arm"] == "bottleneck/lanefree"]
    assert set(bn["demand_level"]) == {7000.0}  # open road: the inflow
    runs = an.fd_runs(res)
    assert {"stationary", "entrance_limited", "flow_drift"} <= set(runs.columns)
    assert runs["stationary"].dtype == "boolean"


def test_discharge_table_counts_only_active_runs_not_limited_by_their_entrance(headline_dir):
    d = an.discharge_table(an.load_results(headline_dir)).set_index("arm")
    lf = d.loc["bottleneck/lanefree"]
    assert (lf["n_runs"], lf["n_valid"], lf["n_stationary"]) == (3, 3, 2)
    half = stats.t.ppf(0.975, 2) * 200.0 / math.sqrt(3)
    assert lf["discharge_vph"] == pytest.approx(5200.0)
    assert lf["discharge_ci_low_vph"] == pytest.approx(5200.0 - half)
    hdv = d.loc["bottleneck/hdv_sl2015"]
    assert hdv["n_valid"] == 0 and math.isnan(hdv["discharge_vph"])
    assert "never active" in hdv["why_rejected"]
    assert "tum_ring/cav0" not in d.index  # rings have no bottleneck


def test_headline_tables_beside_tum_with_losses_and_gains(headline_dir):
    from cosim.analysis import headline as hl

    res = an.load_results(headline_dir)
    t = hl.headline_tables(res)
    bn = t["headline_bottleneck"].set_index("arm")
    assert bn.loc["bottleneck/lanefree", "capacity_vph"] == pytest.approx(5200.0)
    assert bn.loc["bottleneck/lanefree", "label"] == "lane-free flocking CAVs, T = 0.6 s"
    assert bn.loc["bottleneck/hdv_sl2015", "label"] == "SL2015 drivers, lane-free"
    assert bn.loc["bottleneck/lanefree", "tet_share"] == pytest.approx(1e-3)
    assert bn.loc["bottleneck/lanefree", "safety_share_cav_steps"] == pytest.approx(0.01)
    tum = t["headline_tum_ring"].set_index("cav_share")
    assert tum.loc[1.0, "tum_vph"] == 15504.0 and tum.loc[0.0, "tum_vph"] == 6613.0
    assert tum.loc[1.0, "ours_over_tum"] == pytest.approx(12100.0 / 15504.0)
    assert tum.loc[0.95, "n_stationary"] == 2 and tum.loc[0.95, "n_runs"] == 3
    loss = t["headline_hdv5_loss"].set_index("where")
    ring = loss.loc["TUM ring, flow at 225 veh/km"]
    assert ring["loss"] == pytest.approx(1 - 9400.0 / 12100.0) and ring["separated"]
    bn_loss = loss.loc["bottleneck, queue discharge"]  # one 95 % run: no interval
    assert bn_loss["loss"] == pytest.approx(1 - 4900.0 / 5200.0)
    assert math.isnan(bn_loss["ci_low"])
    vs = t["headline_bottleneck_gain"].set_index("arm")
    lanes = vs.loc["bottleneck/hdv_lc2013_3lanes"]
    assert lanes["gain"] == pytest.approx(5200.0 / 4100.0 - 1) and lanes["separated"]
    va, vb = 200.0 ** 2 / 3, 100.0 ** 2 / 3  # Welch: variances of the means, dof
    half = stats.t.ppf(0.975, (va + vb) ** 2 / (va ** 2 / 2 + vb ** 2 / 2)) * math.sqrt(va + vb)
    assert lanes["ci_low"] == pytest.approx((1100.0 - half) / 4100.0, rel=1e-6)
    assert (lanes["n_lanefree"], lanes["n_arm"]) == (3, 3)
    assert vs.loc["bottleneck/hdv_sl2015", "n_arm"] == 0  # never active: no value
    assert math.isnan(vs.loc["bottleneck/hdv_sl2015", "gain"])
    gain = t["headline_lanefree_gain"].set_index("ring_density_vpkm")
    assert gain.loc[125.0, "gain_vs_fixed4"] == pytest.approx(1 / 1.25 - 1)
    assert gain.loc[225.0, "gain_vs_rows3"] == pytest.approx(1 / 0.95 - 1)
    assert gain.loc[125.0, "all_stationary"] and not gain.loc[225.0, "all_stationary"]


def test_analyse_writes_the_headline_report_and_figures(headline_dir):
    a = an.analyse(headline_dir)
    md = (a.out_dir / "headline.md").read_text()
    for title in ("Road-limited capacity", "TUM LaneFreeDrive's ring",
                  "Capacity loss with 5 % human drivers", "Lane-free gain at equal time gap",
                  "Lane-free CAVs against the other arms at the bottleneck",
                  "Ring fundamental diagram"):
        assert f"## {title}" in md
    assert "| lane-free flocking CAVs, T = 0.6 s | 5 200 |" in md and "| 0 / 0 |" in md
    assert "| 100 % | 12 100 |" in md and "| 15 504 |" in md
    # every Markdown table row has as many cells as its header
    for block in md.split("\n\n"):
        rows = [r for r in block.splitlines() if r.startswith("|")]
        if rows:
            assert len({r.count("|") for r in rows}) == 1, block
    for name in ("headline_capacity", "headline_mixed", "headline_fd", "headline_gain"):
        p = a.out_dir / "figures" / f"{name}.png"
        assert p.read_bytes()[:8] == PNG and f"({p.relative_to(a.out_dir)})" in md
    assert "headline.md" in (a.out_dir / "report.md").read_text()
    assert (a.out_dir / "discharge.csv").is_file()


def _hollow(ax) -> int:
    """Markers drawn hollow (face alpha 0) in the scatter collections of ``ax``."""
    from matplotlib.collections import PathCollection

    n = 0
    for c in ax.collections:
        if not isinstance(c, PathCollection):  # scatter markers only (not error bars)
            continue
        fc = c.get_facecolor()
        if len(c.get_offsets()) and (len(fc) == 0 or np.allclose(fc[:, 3], 0.0)):
            n += len(c.get_offsets())
    return n


def test_non_stationary_points_are_hollow_in_the_figures(headline_dir):
    import matplotlib.pyplot as plt

    from cosim.analysis import headline as hl

    res = an.load_results(headline_dir)
    fig = fg.headline_fd_figure(hl.ring_fd_runs(res), "headline")
    assert _hollow(fig.axes[0]) == 1  # lane-free at 225 veh/km drifted 3 %
    texts = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert texts[:3] == ["lane-free flocking", "4 fixed rows", "3 fixed rows (lanes)"]
    assert any("not stationary" in t for t in texts)
    tum = hl.tum_ring_table(res)
    fig2 = fg.headline_mixed_figure(tum, res.ok[res.ok["part"] == "tum_ring"],
                                    hl.TUM_RING_VPH, "headline")
    assert _hollow(fig2.axes[0]) == 1
    # the generic fundamental diagram too
    runs = an.fd_runs(res)
    fig3 = fg.fundamental_diagram_figure(runs[runs["arm"].str.startswith("tum_ring")],
                                         ["arm"], "demand_level")
    assert _hollow(fig3.axes[0]) == 1
    plt.close("all")
