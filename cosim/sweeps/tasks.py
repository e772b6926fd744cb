"""One run of a sweep as a task, and its execution in a worker process.

* :class:`RunTask`: what a worker needs for one run (plain, picklable data);
  :func:`make_tasks` makes one per grid point;
* :func:`execute_task`: runs one task in this process (meant to be a fresh one: libsumo
  holds one simulation per process), writes its run folder and row, and ends the
  process if the sweep dies (:func:`_watch_parent`); :func:`execute_task_isolated` runs
  it in a fresh Python subprocess (for Dask workers);
* :func:`failed_row`: the row of a run that could not report itself;
* the test-only hooks :data:`CRASH_ENV` and :data:`TEST_LOG_ENV`.

:func:`execute_task` and :func:`execute_task_isolated` are sent to other processes
(multiprocessing spawn/forkserver, Dask): they and :class:`RunTask` stay module-level.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.sweeps.locks import (
    INTERRUPTED_FILE,
    STARTED_FILE,
    hold_started,
    marker_token,
    process_alive,
    write_marker,
)
from cosim.sweeps.plan import DEMAND_PATHS, SweepPlan, _cell, _value_at
from cosim.sweeps.results import read_row, write_row

#: Test-only hook: a worker whose run id is listed here (comma-separated) calls
#: ``os._exit(1)`` right after starting, as if the process had been killed.
CRASH_ENV = "COSIM_SWEEP_TEST_CRASH"
#: Test-only hook: workers append ``start|end|orphaned RUN_ID PID TIME_S`` lines to this file.
TEST_LOG_ENV = "COSIM_SWEEP_TEST_LOG"

#: How often a worker checks that the sweep process (its parent) is alive, s.
PARENT_POLL_S = 0.25

#: What a backend hands each finished run's row to (the sweep driver's sink).
Sink = Callable[[dict], None]


@dataclass(frozen=True)
class RunTask:
    """What a worker needs for one run (plain data, picklable)."""

    run_id: str
    run_dir: str
    config: dict
    row_base: dict
    token: str = ""  # one per submission: tells this attempt's markers from older ones
    #: The sweep process to watch (local pool; 0: watch the parent process only) and its
    #: start time (``/proc/PID/stat`` field 22, "" if unknown), so a reused pid is not
    #: taken for the sweep.
    parent_pid: int = 0
    parent_start: str = ""


def make_tasks(plan: SweepPlan, out_dir: Path) -> list[RunTask]:
    """One task per grid point: the resolved scenario and the row's parameter columns."""
    cols = plan.param_columns()
    tasks = []
    for pt in plan.points:
        sc = pt.scenario
        row: dict[str, Any] = {"run_id": pt.run_id, "sweep": plan.name}
        if plan.variants:
            row["variant"] = pt.variant
        periodic = sc.network.kind == "ring"
        for c in cols:
            if c in DEMAND_PATHS and c not in pt.params and c not in plan.axes:
                # only the demand that applies to this road (ring: density; else inflow)
                if (c == "demand.ring_density_vpkm") != periodic:
                    continue
            row[c] = _cell(_value_at(sc, c))
        row["seed"] = sc.scenario.seed
        row["scenario"] = sc.scenario.name
        row["run_dir"] = f"runs/{pt.run_id}"
        tasks.append(RunTask(pt.run_id, str(out_dir / "runs" / pt.run_id), sc.to_dict(), row))
    return tasks


def failed_row(task: RunTask, reason: str) -> dict:
    """A ``failed`` row for a run that could not report itself (its process died)."""
    from cosim.sim.runner import versions

    row = dict(task.row_base)
    row.update(status="failed", error=reason)
    row.update({f"{k}_version": v for k, v in versions().items()})
    return row


def one_line(exc: BaseException, limit: int = 400) -> str:
    """``"ExcType: message"`` on one line, cut to ``limit`` characters (for rows, errors)."""
    text = " ".join(str(exc).split()) or repr(exc)
    text = f"{type(exc).__name__}: {text}"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _watch_parent(task: RunTask) -> None:
    """End this worker process when the sweep (or the parent process) is gone.

    A daemon thread polls every :data:`PARENT_POLL_S`: the parent pid changing (the
    process was re-parented because its parent died) or the task's ``parent_pid`` no
    longer running ends the process at once (``os._exit``), run unfinished, no row
    written: ``--resume`` runs it again.
    """
    ppid = os.getppid()

    def watch() -> None:
        while True:
            time.sleep(PARENT_POLL_S)
            if os.getppid() != ppid or (
                task.parent_pid and not process_alive(task.parent_pid, task.parent_start)
            ):
                _test_log("orphaned", task)
                os._exit(70)

    threading.Thread(target=watch, name="cosim-parent-watchdog", daemon=True).start()


def _test_log(event: str, task: RunTask) -> None:
    path = os.environ.get(TEST_LOG_ENV)
    if path:
        with open(path, "a") as fh:
            fh.write(f"{event} {task.run_id} {os.getpid()} {time.time():.3f}\n")


def execute_task(task: RunTask) -> dict:
    """Run one grid point in this process; write its run directory, then its row.

    Never raises for a failing run: the row says ``failed`` and why (the traceback is
    in ``error.txt``). Meant to run in a fresh process (libsumo: one run per process);
    the process ends itself if the sweep dies (:func:`_watch_parent`).
    """
    t0 = time.perf_counter()
    run_dir = Path(task.run_dir)
    _watch_parent(task)

    def on_term(signum, frame):  # the pool is torn down because another worker died
        try:
            write_marker(run_dir, INTERRUPTED_FILE, task.token)
        finally:
            os._exit(128 + signum)

    signal.signal(signal.SIGTERM, on_term)
    if run_dir.exists():
        shutil.rmtree(run_dir)
    started = hold_started(run_dir, task.token)
    _test_log("start", task)
    if task.run_id in os.environ.get(CRASH_ENV, "").split(","):
        os._exit(1)  # test hook: die like a killed worker

    row = dict(task.row_base)
    row.update(status="ok", error="")
    try:
        from cosim.config.scenario import scenario_from_dict
        from cosim.sim.runner import run_scenario, versions

        row.update({f"{k}_version": v for k, v in versions().items()})
        row["host"] = socket.gethostname()
        sc = scenario_from_dict(task.config)
        res = run_scenario(sc, out_dir=run_dir)
        summary = res.summary.iloc[0].to_dict()
        row["wall_time_s"] = time.perf_counter() - t0
        row["sim_wall_time_s"] = summary.pop("wall_time_s", math.nan)
        summary.pop("seed", None)
        summary.pop("scenario", None)
        row.update({k: (v.item() if hasattr(v, "item") else v) for k, v in summary.items()})
    except Exception as exc:
        row.update(status="failed", error=one_line(exc))
        row["wall_time_s"] = time.perf_counter() - t0
        (run_dir / "error.txt").write_text(traceback.format_exc())
    write_row(run_dir, row)
    _test_log("end", task)
    started.close()
    return row


_SUBPROCESS_CODE = (
    "import json, sys\n"
    "from cosim.sweeps.tasks import RunTask, execute_task\n"
    "execute_task(RunTask(**json.loads(sys.stdin.read())))\n"
)


def execute_task_isolated(task: RunTask) -> dict:
    """Run one grid point in a fresh Python subprocess (for Dask workers, which are
    long-lived and may run several tasks at once: libsumo needs a process per run).
    The subprocess ends itself if this process dies (:func:`_watch_parent`)."""
    proc = subprocess.run(
        [sys.executable, "-c", _SUBPROCESS_CODE],
        input=json.dumps(dataclasses.asdict(task)), capture_output=True, text=True,
        check=False,
    )
    run_dir = Path(task.run_dir)
    row = read_row(run_dir) if proc.returncode == 0 else None
    if row is not None and marker_token(run_dir, STARTED_FILE) == task.token:
        return row
    tail = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()][-1:]
    reason = f"worker process exited with code {proc.returncode}"
    if tail:
        reason += f": {tail[0].strip()[:300]}"
    return failed_row(task, reason)
