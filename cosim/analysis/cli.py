"""``cosim analyse``: the argument parser and the command (a sweep folder or one run's folder)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from cosim.analysis.report import analyse
from cosim.analysis.tables import load_results
from cosim.cli.errors import run_command
from cosim.errors import ConfigError


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("results_dir",
                   help="sweep output folder (with results.csv), or one run's folder")
    p.add_argument("--out", help="where to write tables and figures (default RESULTS_DIR/analysis)")
    p.add_argument("--no-figures", action="store_true", help="tables only")
    p.add_argument("--run", action="append", metavar="RUN_ID",
                   help="draw the time-space diagram and top view of this run (repeatable)")
    p.add_argument("--times", type=float, nargs="+", metavar="T",
                   help="top views at these times, s (default: 3 spread over the run)")
    p.add_argument("--confidence", type=float, default=0.95, help="CI level (default 0.95)")
    p.add_argument("--animate", action="store_true",
                   help="one run's folder: also an animated top view, top_view.gif")
    p.add_argument("--t-range", type=float, nargs=2, metavar=("T0", "T1"),
                   help="time span of the animation, s (default: the last 30 s)")
    p.set_defaults(func=cmd_analyse)


def add_analyse_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``cosim analyse`` on an argparse subparsers object; returns the subparser."""
    p = subparsers.add_parser(
        "analyse", help="tables and figures from a sweep's results (or one run's outputs)",
        description="Fundamental diagrams, capacity, safety, boundary and flock tables "
                    "(CSV + Markdown) and PNG figures from a sweep output folder.",
    )
    _add_arguments(p)
    return p


def _check_options(ns: argparse.Namespace) -> None:
    """Every option checked before anything is read or written (one ``error:`` line)."""
    if ns.out is not None:
        if not ns.out.strip():
            raise ConfigError("--out must not be empty")
        if Path(ns.out).exists() and not Path(ns.out).is_dir():
            raise ConfigError(f"--out {ns.out} is an existing file, not a folder")
    if not math.isfinite(ns.confidence) or not 0.0 < ns.confidence < 1.0:
        raise ConfigError(f"--confidence must be between 0 and 1 (got {ns.confidence:g})")
    for t in ns.times or ():
        if not math.isfinite(t) or t < 0.0:
            raise ConfigError(f"--times must be finite times >= 0 s (got {t:g})")
    if ns.t_range is not None:
        t0, t1 = ns.t_range
        if not (math.isfinite(t0) and math.isfinite(t1)) or not t0 < t1:
            raise ConfigError(f"--t-range must be increasing finite times "
                              f"(got {t0:g} {t1:g})")


def _check_summary(path: Path) -> None:
    """One run's ``summary.csv`` readable as a table, or one ``error:`` line."""
    import pandas as pd

    try:
        text = path.read_text(encoding="utf-8")
        if "\x00" in text:
            raise ConfigError(f"{path}: unreadable run summary: binary data")
        pd.read_csv(path)
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError,
            OSError) as exc:
        raise ConfigError(f"{path}: unreadable run summary: {exc}") from None


def cmd_analyse(ns: argparse.Namespace) -> int:
    _check_options(ns)
    if not ns.results_dir.strip():
        raise ConfigError("the results folder must not be an empty string")
    root = Path(ns.results_dir)
    if not root.exists():
        raise ConfigError(f"no such folder: {root}")
    if root.is_dir() and not (root / "results.csv").is_file() and (root / "summary.csv").is_file():
        from cosim.analysis.figures import plot_run

        out = Path(ns.out) if ns.out else root / "analysis"
        _check_summary(root / "summary.csv")
        if not (root / "trajectories.csv").is_file():
            raise ConfigError(f"{root}: no trajectories.csv to draw "
                              "(run with [outputs] trajectories = true)")
        t_range = tuple(ns.t_range) if ns.t_range else None
        for p in plot_run(root, out, times=ns.times, animate=ns.animate, t_range=t_range):
            print(f"figure: {p}")
        return 0
    a = analyse(root, ns.out, figures=not ns.no_figures, confidence=ns.confidence,
                runs=ns.run, times=ns.times)
    cap = a.tables["capacity"]
    if not cap.empty:
        cols = [c for c in (*load_results(root).series_cols, "capacity_vph",
                            "capacity_ci_low_vph", "capacity_ci_high_vph", "n_seeds",
                            "at_grid_edge") if c in cap]
        shown = cap[cols].copy()
        for c in ("capacity_vph", "capacity_ci_low_vph", "capacity_ci_high_vph"):
            if c in shown:
                shown[c] = shown[c].round().astype("Int64")
        print("capacity (max over demand levels of the mean flow, veh/h):")
        print(shown.to_string(index=False))
    n_failed = len(a.tables["failed"])
    if n_failed:
        print(f"{n_failed} failed runs are listed in {a.out_dir / 'failed.csv'}")
    print(f"tables and figures written to {a.out_dir}/ (report.md)")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``cosim analyse`` without the rest of the CLI: ``main(["RESULTS_DIR", ...])``."""
    ap = argparse.ArgumentParser(
        prog="cosim analyse", description="Tables and figures from a sweep's results."
    )
    _add_arguments(ap)
    ns = ap.parse_args(argv)
    return run_command(ns.func, ns)
