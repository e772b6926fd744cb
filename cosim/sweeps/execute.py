"""Executing a sweep: one run per process, a local process pool or Dask, markers and locks.

Execution: one process per run, because libsumo holds one simulation per process.
Locally a ``ProcessPoolExecutor`` (spawn, ``max_tasks_per_child=1``; ``--start-method
forkserver`` forks each run from a server that preloaded cosim, libsumo's library and the
numba kernels, never a SUMO simulation (:mod:`cosim.sim.preload`), which saves the imports
and the kernels' cache loads of every run, ~1.5-2.5 s on a busy 2-core machine); on Dask
(``--scheduler ADDRESS`` or ``--dask-local N``) each task starts its run in a fresh
subprocess of the Dask worker. A run that raises is recorded ``failed`` with its reason;
a worker process that dies (crash, ``kill``) breaks the local pool: its run is recorded
failed, runs that were interrupted only because the pool was torn down are run again
in a new pool, and no finished run is lost (its row file is on disk). On Dask the
output directory must be on a file system the workers share.

Nothing runs twice at once, even when the sweep process is killed (``kill -9``):

* the sweep process holds a lock on ``OUT/.sweep.lock`` (``flock``, released by the
  kernel when the process dies): a second ``cosim sweep`` on the same folder is refused;
* a worker holds a lock on its run's ``STARTED`` marker while it runs, and a watchdog
  thread ends the worker (within :data:`cosim.sweeps.tasks.PARENT_POLL_S`) when the sweep
  process (local pool) or its parent process (the Dask worker) is gone, so no orphan
  keeps running;
* ``--resume`` first waits (up to :data:`IN_FLIGHT_WAIT_S`) until no run of the folder
  is locked by a live process, and refuses to start if one still is.

Nothing is written before every option, the output folder (:mod:`cosim.output_dir`),
the networks and the Dask scheduler are checked: a bad input leaves no half-made folder.

This module is the driver (:func:`run_sweep`: options and folder checks, the sweep
lock, the results table); the parts it drives:

* :mod:`cosim.sweeps.tasks`: one run as a task and its execution in a worker process;
* :mod:`cosim.sweeps.local_backend`: the local process pool;
* :mod:`cosim.sweeps.dask_backend`: Dask;
* :mod:`cosim.sweeps.locks`: markers, locks and process liveness.
"""

from __future__ import annotations

import os
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from cosim.errors import ConfigError
from cosim.output_dir import check_output_dir, is_nonempty_dir, prepare_output_dir
from cosim.sweeps.dask_backend import dask_client, run_dask
from cosim.sweeps.local_backend import START_METHODS, run_local
from cosim.sweeps.locks import acquire_sweep_lock, run_in_flight, sweep_lock_holder
from cosim.sweeps.plan import SweepPlan
from cosim.sweeps.results import (
    ROW_FILE,
    read_plan,
    read_row,
    write_plan,
    write_results,
    write_row,
)
from cosim.sweeps.tasks import make_tasks

WHAT = "sweep output folder"
#: How long a sweep waits for runs of its folder that live processes still hold, s.
IN_FLIGHT_WAIT_S = 15.0


@dataclass
class SweepOutcome:
    """What a sweep call did: counts, the results table and where it is."""

    plan: SweepPlan
    out_dir: Path
    n_run: int
    n_ok: int
    n_failed: int
    n_skipped: int
    wall_time_s: float
    results_csv: Path
    failed: list[dict] = field(default_factory=list)


def _runs(n: int) -> str:
    return f"{n} run" if n == 1 else f"{n} runs"


def check_options(
    resume: bool = False,
    replace: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    dask_local: int | None = None,
    start_method: str = "spawn",
) -> None:
    """Refuse contradictory or impossible execution options (one ConfigError line)."""
    if resume and replace:
        raise ConfigError("give either --resume (complete the sweep in --out) or --replace "
                          "(delete it and start again), not both")
    if scheduler is not None and dask_local is not None:
        raise ConfigError("give either --scheduler or --dask-local, not both")
    if workers is not None:
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ConfigError(f"--workers must be an integer >= 1, got {workers}")
        if scheduler is not None or dask_local is not None:
            raise ConfigError("--workers sets the local process pool; on Dask give the "
                              "number of workers with --dask-local N (or the cluster's own)")
    if dask_local is not None and (
        isinstance(dask_local, bool) or not isinstance(dask_local, int) or dask_local < 1
    ):
        raise ConfigError(f"--dask-local must be an integer >= 1, got {dask_local}")
    if scheduler is not None and (not isinstance(scheduler, str) or not scheduler.strip()):
        raise ConfigError(f"--scheduler must be an address (tcp://HOST:PORT), got {scheduler!r}")
    if start_method not in START_METHODS:
        raise ConfigError(f"--start-method must be one of {', '.join(START_METHODS)}, "
                          f"got {start_method!r}")


def check_output(plan: SweepPlan, out: Path, resume: bool = False, replace: bool = False) -> None:
    """The output folder rule (:mod:`cosim.output_dir`) for a sweep, nothing written.

    Without ``--resume`` or ``--replace`` the folder must be new or empty; ``--resume``
    accepts a non-empty folder only if it holds the same plan (the same grid points).
    """
    check_output_dir(out, replace=replace, what=WHAT, keep=True)
    holder = sweep_lock_holder(out)
    if holder is not None:
        raise ConfigError(
            f"{out} is in use by another 'cosim sweep' (process {holder}): wait for it to "
            "end, or choose another --out"
        )
    if not is_nonempty_dir(out) or replace:
        return
    if resume:
        _check_same_plan(plan, out)
        return
    runs = out / "runs"
    n_rows = len(list(runs.glob(f"*/{ROW_FILE}"))) if runs.is_dir() else 0
    held = f"holds results of {_runs(n_rows)}" if n_rows else "is not empty"
    raise ConfigError(
        f"{out} {held}: pass --resume to complete that sweep, --replace to delete it and "
        "start again, or choose another --out"
    )


def _check_same_plan(plan: SweepPlan, out: Path) -> None:
    old = read_plan(out)
    if old is None:
        raise ConfigError(
            f"--resume: {out} is not empty and holds no sweep plan (sweep.json): "
            "not a sweep folder; choose another --out"
        )
    mine = {p.run_id for p in plan.points}
    theirs = set(map(str, old["run_ids"]))
    if mine != theirs:
        raise ConfigError(
            f"--resume: {out} holds another plan (sweep '{old.get('name', '?')}', "
            f"{_runs(len(theirs))}; this one: '{plan.name}', {_runs(len(mine))}, "
            f"{len(mine - theirs)} not in the folder): use the same sweep file and options, "
            "--replace, or another --out"
        )


def _wait_for_runs_in_flight(plan: SweepPlan, out: Path, wait_s: float) -> None:
    """Wait until no live process runs a grid point of ``out`` (orphans of a killed sweep
    end themselves within a second); refuse if some still do after ``wait_s`` s."""
    runs = out / "runs"
    if not runs.is_dir():
        return
    deadline = time.monotonic() + wait_s
    while True:
        busy = {}
        for p in plan.points:
            pid = run_in_flight(runs / p.run_id)
            if pid is not None:
                busy[p.run_id] = pid
        if not busy:
            return
        if time.monotonic() >= deadline:
            pids = ", ".join(sorted({str(v) for v in busy.values()}))
            raise ConfigError(
                f"{_runs(len(busy))} of {out} still running in other processes (pid {pids}) "
                f"after {wait_s:g} s: wait for them to end or stop them, then run again"
            )
        time.sleep(0.2)


def run_sweep(
    plan: SweepPlan,
    out_dir: str | Path,
    resume: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    dask_local: int | None = None,
    progress: bool = True,
    start_method: str = "spawn",
    replace: bool = False,
) -> SweepOutcome:
    """Run the plan's grid points (the missing ones with ``resume``) and write the results.

    Args:
        plan: from :func:`cosim.sweeps.plan.load_sweep` / ``sweep_from_dict``.
        out_dir: the sweep's output directory (:mod:`cosim.output_dir` rule).
        resume: run only the grid points without an ``ok`` row in ``out_dir``, which must
            hold the same plan; without it (or ``replace``), ``out_dir`` must be new or empty.
        workers: local worker processes (default ``os.cpu_count()``), >= 1.
        scheduler: address of a Dask scheduler (``tcp://host:8786``), or
        dask_local: run on a local Dask cluster of that many worker processes (>= 1).
        progress: show a tqdm progress bar (stderr).
        start_method: local pool: ``"spawn"`` or ``"forkserver"`` (see
            :func:`cosim.sweeps.local_backend.mp_context`).
        replace: delete the contents of ``out_dir`` first (refused while a sweep runs there).

    Every option, the folder, the networks and the Dask connection are checked before
    anything is written.
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    check_options(resume, replace, workers, scheduler, dask_local, start_method)
    check_output(plan, out, resume=resume, replace=replace)
    if is_nonempty_dir(out):
        _wait_for_runs_in_flight(plan, out, IN_FLIGHT_WAIT_S)
    n_workers = workers if workers is not None else (os.cpu_count() or 1)
    runs = out / "runs"
    rows: dict[str, dict] = {}
    if resume:
        for pt in plan.points:
            row = read_row(runs / pt.run_id)
            if row is not None:
                rows[pt.run_id] = row
    done_ok = {rid for rid, r in rows.items() if r["status"] == "ok"}
    tasks = [t for t in make_tasks(plan, out) if t.run_id not in done_ok]

    client = cluster = None
    lock = None
    bar = None
    counts: Counter = Counter()
    try:
        if tasks and (scheduler is not None or dask_local is not None):
            client, cluster = dask_client(scheduler, dask_local)
        _prebuild_networks(plan, {t.run_id for t in tasks})
        prepare_output_dir(out, replace=replace, what=WHAT, keep=resume)
        lock = acquire_sweep_lock(out)
        runs.mkdir(exist_ok=True)
        write_plan(out, plan)
        write_results(out, plan, rows)

        if progress and tasks:
            from tqdm import tqdm

            bar = tqdm(total=len(tasks), unit="run", desc=plan.name, file=sys.stderr)

        def sink(row: dict) -> None:
            write_row(runs / row["run_id"], row)
            rows[row["run_id"]] = row
            write_results(out, plan, rows)
            counts[row["status"]] += 1
            if bar is not None:
                bar.set_postfix(done=counts["ok"], failed=counts["failed"],
                                remaining=len(tasks) - sum(counts.values()), refresh=False)
                bar.update(1)

        try:
            if tasks:
                if client is not None:
                    run_dask(tasks, sink, client)
                else:
                    run_local(tasks, n_workers, sink, start_method)
        finally:
            if bar is not None:
                bar.close()
            results = write_results(out, plan, rows)
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
        if lock is not None:
            lock.close()
    ids = {p.run_id for p in plan.points}
    failed = [r for rid, r in rows.items() if r["status"] != "ok" and rid in ids]
    return SweepOutcome(
        plan=plan, out_dir=out, n_run=len(tasks), n_ok=counts["ok"], n_failed=counts["failed"],
        n_skipped=len(plan.points) - len(tasks), wall_time_s=time.perf_counter() - t0,
        results_csv=results, failed=failed,
    )


def _prebuild_networks(plan: SweepPlan, todo: set[str]) -> None:
    """Build each distinct network once, before any run (netconvert errors fail early)."""
    from cosim.road.build import build_network

    specs = {p.scenario.network for p in plan.points
             if p.run_id in todo and p.scenario.scenario.world == "sumo"}
    for spec in specs:
        build_network(spec)
