"""Analysis of sweeps and runs: tables, a report and figures.

Modules, by job:

* :mod:`cosim.analysis.tables`: a sweep's results loaded and turned into tables
  (fundamental diagrams, capacity with t-based confidence intervals, safety, boundary,
  flock, failed runs);
* :mod:`cosim.analysis.headline`: the headline experiment's tables (capacity per arm,
  TUM's ring, the lane-free gain at equal time gap, the 5 %-HDV loss) and report;
* :mod:`cosim.analysis.report`: :func:`analyse` writes every table (CSV and Markdown),
  ``report.md`` (with the grid that actually ran) and the figures;
* :mod:`cosim.analysis.figures`: matplotlib figures in one style, a package by kind
  (style, saving, sweep, run and headline figures; imported on use: it loads matplotlib);
* :mod:`cosim.analysis.cli`: ``cosim analyse`` (argparse parser and command).
"""

from cosim.analysis.cli import add_analyse_parser, cmd_analyse, main
from cosim.analysis.report import Analysis, analyse, grid_lines, markdown_table
from cosim.analysis.tables import (
    SweepResults,
    boundary_table,
    capacity_table,
    demand_column,
    discharge_table,
    failures_table,
    fd_intervals,
    fd_runs,
    fd_summary,
    flock_table,
    load_results,
    safety_table,
    series_columns,
    t_interval,
)

__all__ = [
    "Analysis",
    "SweepResults",
    "add_analyse_parser",
    "analyse",
    "boundary_table",
    "capacity_table",
    "cmd_analyse",
    "demand_column",
    "discharge_table",
    "failures_table",
    "fd_intervals",
    "fd_runs",
    "fd_summary",
    "flock_table",
    "grid_lines",
    "load_results",
    "main",
    "markdown_table",
    "safety_table",
    "series_columns",
    "t_interval",
]
