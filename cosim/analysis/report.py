"""Write a sweep's analysis: every table as CSV and Markdown, ``report.md`` and the figures.

``analyse(RESULTS_DIR)`` writes to ``RESULTS_DIR/analysis/``: ``<table>.csv`` and
``<table>.md`` for every table of :mod:`cosim.analysis.tables`, ``report.md`` (the sweep,
the grid that actually ran, e.g. a smoke grid, and the tables) and PNG figures in
``figures/`` (:mod:`cosim.analysis.figures`). For the headline experiment (variants named
``PART/ARM#RUN``, :mod:`cosim.analysis.headline`) also ``headline.md`` (the README's
tables), ``headline_*.csv`` and the ``figures/headline_*.png``; for a ring sweep counting at
TUM LaneFreeDrive's detector (:mod:`cosim.analysis.tum_protocol`) also ``tum_protocol.md``,
``tum_protocol_*.csv`` and ``figures/tum_protocol_fd.png``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from cosim.analysis import headline as hl
from cosim.analysis import tum_protocol as tp
from cosim.analysis.tables import (
    SweepResults,
    boundary_table,
    capacity_table,
    discharge_table,
    failures_table,
    fd_intervals,
    fd_runs,
    fd_summary,
    flock_table,
    is_parameter_column,
    load_results,
    pd_numeric,
    safety_table,
)
from cosim.errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd


def _md_cell(v) -> str:
    import numpy as np

    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    if isinstance(v, bool | np.bool_):
        return "yes" if v else "no"
    if isinstance(v, float | np.floating):
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        if float(v).is_integer() and abs(v) < 1e15:
            return f"{int(v)}"
        if abs(v) >= 1000:
            return f"{v:.0f}"
        return f"{v:.4g}"
    return str(v).replace("|", "\\|").replace("\n", " ")


def markdown_table(df: pd.DataFrame) -> str:
    """A GitHub-flavoured Markdown table (numbers to 4 significant digits)."""
    if df.empty:
        return "(no rows)\n"
    header = "| " + " | ".join(str(c) for c in df.columns) + " |"
    sep = "|" + "|".join("---" for _ in df.columns) + "|"
    body = ["| " + " | ".join(_md_cell(v) for v in row) + " |" for row in df.itertuples(False)]
    return "\n".join([header, sep, *body]) + "\n"


@dataclass
class Analysis:
    """Tables by name and the files written."""
    tables: dict[str, pd.DataFrame]
    files: list[Path]
    out_dir: Path


TABLE_TITLES = {
    "capacity": "Capacity (maximum sustained flow; entrance-limited maxima are lower bounds)",
    "discharge": "Road-limited capacity (queue discharge at an active bottleneck)",
    "fd_summary": "Fundamental diagram (mean over seeds)",
    "safety": "Safety",
    "boundary": "Boundary violations",
    "flock": "Flock metrics",
    "failed": "Failed runs",
}


def analyse(
    results_dir: str | Path,
    out_dir: str | Path | None = None,
    figures: bool = True,
    confidence: float = 0.95,
    runs: Sequence[str] | None = None,
    max_run_figures: int = 2,
    times: Sequence[float] | None = None,
) -> Analysis:
    """Compute every table, write CSV + Markdown + report.md (and figures) to ``out_dir``.

    Args:
        results_dir: the sweep output directory.
        out_dir: default ``results_dir/analysis``.
        figures: also write PNG figures (fundamental diagram, capacity, and per run a
            time-space diagram and a top view when it has trajectories.csv).
        confidence: level of the t-based confidence intervals.
        runs: run ids to draw run figures for (default: the first ``max_run_figures``
            ok runs that have trajectories).
        times: instants of the top views, s (default: 3 spread over the run).
    """
    if not 0 < confidence < 1:
        raise ConfigError(f"confidence must be in (0, 1), got {confidence}")
    res = load_results(results_dir)
    out = Path(out_dir) if out_dir else res.root / "analysis"
    out.mkdir(parents=True, exist_ok=True)
    tables = {
        "fd_runs": fd_runs(res),
        "fd_intervals": fd_intervals(res),
        "fd_summary": fd_summary(res, confidence),
        "capacity": capacity_table(res, confidence),
        "discharge": discharge_table(res, confidence),
        "safety": safety_table(res),
        "boundary": boundary_table(res),
        "flock": flock_table(res),
        "failed": failures_table(res),
    }
    files: list[Path] = []
    for name, df in tables.items():
        p = out / f"{name}.csv"
        df.to_csv(p, index=False)
        files.append(p)
        if name in TABLE_TITLES:
            p = out / f"{name}.md"
            p.write_text(f"## {TABLE_TITLES[name]}\n\n" + markdown_table(df))
            files.append(p)

    fig_files: list[Path] = []
    if figures:
        fig_files = _figures(res, tables, out / "figures", runs, max_run_figures, times)
        files += fig_files
    if hl.is_headline(res):
        files += _headline(res, tables, out, confidence, figures)
    if tp.is_tum_protocol(res):
        files += _tum_protocol(res, tables, out, confidence, figures)
    report = out / "report.md"
    report.write_text(_report(res, tables, confidence, fig_files, out))
    files.append(report)
    return Analysis(tables, files, out)


def _figures(res, tables, fig_dir: Path, runs, max_run_figures, times) -> list[Path]:
    from cosim.analysis import figures as fg

    fig_dir.mkdir(parents=True, exist_ok=True)
    made = []
    name = res.plan.get("name") or res.root.name
    if not tables["fd_runs"].empty:
        made.append(fg.save(fg.fundamental_diagram_figure(
            tables["fd_runs"], res.series_cols, demand_col=res.demand_col,
            intervals=tables["fd_intervals"], title=name,
        ), fig_dir / "fundamental_diagram.png"))
    if not tables["capacity"].empty and "demand.cav_share" in tables["capacity"]:
        made.append(fg.save(fg.capacity_figure(tables["capacity"], res.series_cols, title=name),
                            fig_dir / "capacity.png"))
    if runs is None:
        runs = [r for r in res.ok["run_id"]
                if (res.run_dir(r) / "trajectories.csv").is_file()][:max_run_figures]
    for rid in runs:
        rdir = res.run_dir(rid)
        if not (rdir / "trajectories.csv").is_file():
            raise ConfigError(f"run {rid}: no trajectories.csv in {rdir} "
                              "(set [outputs] trajectories = true)")
        made += fg.plot_run(rdir, fig_dir, times=times, prefix=f"{rid}_")
    return made


def _headline(res: SweepResults, tables: dict, out: Path, confidence: float,
              figures: bool) -> list[Path]:
    """The headline tables (CSV, into ``tables``), ``headline.md`` and its figures."""
    from cosim.analysis import figures as fg

    head = hl.headline_tables(res, confidence)
    tables.update(head)
    files = []
    for name, df in head.items():
        p = out / f"{name}.csv"
        df.to_csv(p, index=False)
        files.append(p)
    figs: list[Path] = []
    if figures:
        fig_dir = out / "figures"
        fig_dir.mkdir(parents=True, exist_ok=True)
        name = res.plan.get("name") or res.root.name
        if not head["headline_bottleneck"].empty:
            figs.append(fg.save(fg.headline_capacity_figure(head["headline_bottleneck"], name),
                                fig_dir / "headline_capacity.png"))
        ok = res.ok
        if not head["headline_tum_ring"].empty:
            ring = ok[ok["part"] == "tum_ring"]
            figs.append(fg.save(fg.headline_mixed_figure(head["headline_tum_ring"], ring,
                                                         hl.TUM_RING_VPH, name),
                                fig_dir / "headline_mixed.png"))
        fd_runs_ = hl.ring_fd_runs(res)
        if len(fd_runs_):
            ring = ok[(ok["part"] == "tum_ring")]
            ref = ring[pd_numeric(ring, "demand.cav_share") == 1.0]
            figs.append(fg.save(fg.headline_fd_figure(fd_runs_, name, ref),
                                fig_dir / "headline_fd.png"))
        if not head["headline_lanefree_gain"].empty:
            figs.append(fg.save(fg.headline_gain_figure(head["headline_lanefree_gain"], name),
                                fig_dir / "headline_gain.png"))
    md = out / "headline.md"
    md.write_text(hl.headline_markdown(head, confidence,
                                       [p.relative_to(out).as_posix() for p in figs],
                                       res.plan.get("name") or res.root.name))
    return files + figs + [md]


def _tum_protocol(res: SweepResults, tables: dict, out: Path, confidence: float,
                  figures: bool) -> list[Path]:
    """TUM's ring protocol: ``tum_protocol_shares.csv``, ``tum_protocol_densities.csv``
    (into ``tables``), ``tum_protocol.md`` and its figure."""
    from cosim.analysis import figures as fg

    shares = tp.share_table(res, confidence)
    dens = tp.density_table(res)
    tables.update({"tum_protocol_shares": shares, "tum_protocol_densities": dens})
    files = []
    for name, df in (("tum_protocol_shares", shares), ("tum_protocol_densities", dens)):
        p = out / f"{name}.csv"
        df.to_csv(p, index=False)
        files.append(p)
    figs: list[Path] = []
    name = res.plan.get("name") or res.root.name
    if figures and len(dens):
        figs.append(fg.save(fg.tum_protocol_fd_figure(dens, tp.TUM_FIGURE_VPH,
                                                      tp.TUM_DENSITIES_VPKM, name),
                            out / "figures" / "tum_protocol_fd.png"))
    md = out / "tum_protocol.md"
    md.write_text(_tum_protocol_markdown(shares, dens,
                                       [p.relative_to(out).as_posix() for p in figs], name))
    return files + figs + [md]


def _report(res: SweepResults, tables, confidence, fig_files, out: Path) -> str:
    plan = res.plan
    n_ok, n_all = len(res.ok), len(res.table)
    name = plan.get("name", res.root.name)
    lines = [f"# Sweep analysis: {name}", ""]
    if plan.get("smoke"):
        full = plan.get("full_name") or str(name).removesuffix("_smoke")
        lines += [f"**Smoke test** of the sweep '{full}': the reduced grid below, with short "
                  "runs. It checks that the sweep runs; its numbers are not the sweep's "
                  "results.", ""]
        own = plan.get("description", "")
        if plan.get("full_name") and own and not own.startswith("smoke test of the sweep"):
            lines += [own, ""]  # the [smoke] table's own description
    elif plan.get("description"):
        lines += [plan["description"], ""]
    lines += [
        f"- runs: {n_all} in results.csv, {n_ok} ok, {n_all - n_ok} failed"
        + (f" (grid: {plan['n_points']} points)" if "n_points" in plan else ""),
        f"- series (one curve each): {', '.join(res.series_cols) or '-'}",
        f"- demand level: {res.demand_col or '-'}",
        f"- confidence intervals: t-based, {confidence:.0%}, across seeds",
    ]
    for col in ("cosim_version", "sumo_version"):
        if col in res.table:
            vals = ", ".join(str(v) for v in res.table[col].dropna().unique())
            lines.append(f"- {col.replace('_', ' ')}: {vals}")
    lines.append("")
    lines += grid_lines(plan, res.table)
    if "headline_bottleneck" in tables:
        lines += ["The headline tables and figures: [headline.md](headline.md).", ""]
    if "tum_protocol_shares" in tables:
        lines += ["TUM's ring protocol, tables and figure: [tum_protocol.md](tum_protocol.md).",
                  ""]
    for name in ("capacity", "discharge", "fd_summary", "safety", "boundary", "flock",
                 "failed"):
        if name in ("failed", "discharge") and tables[name].empty:
            continue
        lines += [f"## {TABLE_TITLES[name]}", "", markdown_table(tables[name])]
    if fig_files:
        lines += ["## Figures", ""]
        lines += [f"![{p.stem}]({p.relative_to(out)})" for p in fig_files]
        lines.append("")
    return "\n".join(lines)


def _value(v) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, list | dict):
        return json.dumps(v)
    return str(v)


def grid_lines(plan: dict, table: pd.DataFrame | None = None) -> list[str]:
    """Markdown lines describing the grid that ran (from ``sweep.json``, which the sweep
    writes for the plan it runs: a smoke sweep's own axes, seeds and overrides).

    Without a plan, the distinct values of the parameter columns of ``table``.
    """
    lines = ["## Grid that ran", ""]
    if not plan.get("axes") and not plan.get("variants") and plan.get("seeds") is None:
        if table is None or table.empty:
            return lines + ["(no sweep.json and no results)", ""]
        lines.append("(no sweep.json: parameter values found in results.csv)")
        for col in [c for c in table.columns if is_parameter_column(c) or c == "seed"]:
            vals = table[col].dropna().unique()
            if 0 < len(vals) <= 20:
                lines.append(f"- {col}: {', '.join(_value(v) for v in sorted(vals, key=str))}")
        return lines + [""]
    lines.append(f"- base scenario: {plan.get('base', '-')}")
    sizes = []
    if plan.get("variants"):
        sizes.append(len(plan["variants"]))
        lines.append(f"- variants ({len(plan['variants'])}):")
        for v in plan["variants"]:
            params = ", ".join(f"{k} = {_value(x)}" for k, x in v.items() if k != "name")
            lines.append(f"  - {v.get('name', '?')}: {params or '-'}")
    for path, values in (plan.get("axes") or {}).items():
        sizes.append(len(values))
        lines.append(f"- {path}: {', '.join(_value(v) for v in values)} "
                     f"({len(values)} value{'s' if len(values) != 1 else ''})")
    if plan.get("seeds") is not None:
        sizes.append(len(plan["seeds"]))
        lines.append(f"- seeds: {', '.join(str(s) for s in plan['seeds'])}")
    if "n_points" in plan:
        product = " x ".join(str(n) for n in sizes) or "1"
        lines.append(f"- grid points: {product} = {plan['n_points']}")
    if plan.get("overrides"):
        fixed = ", ".join(f"{k} = {_value(v)}" for k, v in plan["overrides"].items())
        lines.append(f"- fixed for every run: {fixed}")
    return lines + [""]


def _tum_protocol_markdown(shares: pd.DataFrame, densities: pd.DataFrame, figures: list[str],
                      name: str) -> str:
    """``tum_protocol.md``: TUM's table computed on our runs, the flows per density
    beside TUM's figure, the 5 %-HDV loss both ways, the figures."""
    lines = [f"# TUM LaneFreeDrive's ring protocol: {name}", "",
             "Flow: vehicles crossing x = 339.09 m, mean of the 300 s intervals from 2 100 "
             "to 3 900 s (TUM's E1 detector and window). TUM's table is the mean over the "
             "densities 50-400 veh/km and 3 seeds; `flow_vph` below is computed the same "
             "way on our runs.", "",
             "## Per CAV share (TUM's table)", "", markdown_table(shares)]
    for col, what in (("flow_vph", "density-averaged flow"), ("max_flow_vph", "peak flow")):
        ours = tp.hdv_loss(shares, col)
        tum = tp.hdv_loss(shares, "tum_vph" if col == "flow_vph" else "tum_max_vph")
        if math.isfinite(ours):
            lines.append(f"- loss at 5 % human drivers, {what}: ours {100 * ours:.1f} %, "
                         f"TUM's {100 * tum:.1f} %")
    lines += ["", "## Per density (TUM's values read off their figure, +-150 veh/h)", "",
              markdown_table(densities)]
    if figures:
        lines += ["## Figures", ""] + [f"![{f}]({f})" for f in figures] + [""]
    return "\n".join(lines)
