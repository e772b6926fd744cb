"""Parameter sweeps: a grid of scenarios run in parallel, resumable, one tidy results table.

Modules, by job:

* :mod:`cosim.sweeps.plan`: the sweep file (TOML) parsed and validated into a
  :class:`SweepPlan` of grid points, each with its stable ``run_id``;
* :mod:`cosim.sweeps.execute`: running the plan, :func:`run_sweep`: options and folder
  checks, the sweep lock, the results table; it drives
* :mod:`cosim.sweeps.tasks`: one run as a task (:class:`RunTask`) and its execution in
  its own process (:func:`execute_task`; libsumo holds one simulation per process);
* :mod:`cosim.sweeps.local_backend` and :mod:`cosim.sweeps.dask_backend`: where the
  tasks run: the local process pool, or Dask;
* :mod:`cosim.sweeps.locks`: markers, locks and process liveness (no run twice at once,
  workers end when the sweep dies);
* :mod:`cosim.sweeps.results`: row files and ``results.csv`` on disk;
* :mod:`cosim.sweeps.cli`: ``cosim sweep`` (argparse parser and command).

Python use::

    from cosim.sweeps import load_sweep, run_sweep
    outcome = run_sweep(load_sweep("open_road_capacity", smoke=True), "outputs/s")
"""

from cosim.sweeps.cli import add_sweep_parser, cmd_sweep, main
from cosim.sweeps.execute import SweepOutcome, run_sweep
from cosim.sweeps.plan import (
    GridPoint,
    SweepPlan,
    default_out_dir,
    load_sweep,
    resolve_sweep_file,
    run_id,
    sweep_from_dict,
)
from cosim.sweeps.results import read_row, results_frame, write_results, write_row
from cosim.sweeps.tasks import CRASH_ENV, TEST_LOG_ENV, RunTask, execute_task

__all__ = [
    "CRASH_ENV",
    "TEST_LOG_ENV",
    "GridPoint",
    "RunTask",
    "SweepOutcome",
    "SweepPlan",
    "add_sweep_parser",
    "cmd_sweep",
    "default_out_dir",
    "execute_task",
    "load_sweep",
    "main",
    "read_row",
    "resolve_sweep_file",
    "results_frame",
    "run_id",
    "run_sweep",
    "sweep_from_dict",
    "write_results",
    "write_row",
]
