"""The local backend: a process pool on this machine, one run per process.

:func:`run_local` runs the tasks in a ``ProcessPoolExecutor`` (``max_tasks_per_child=1``,
start method from :func:`mp_context`: ``spawn`` or ``forkserver``). A worker process
that dies breaks the pool: its run is recorded failed, runs interrupted only because the
pool was torn down are run again in a new pool (at most :data:`MAX_INTERRUPTS` times),
and no finished run is lost (its row file is on disk).
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import uuid
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from cosim.errors import ConfigError
from cosim.sweeps.locks import INTERRUPTED_FILE, STARTED_FILE, marker_token, proc_start
from cosim.sweeps.results import read_row
from cosim.sweeps.tasks import RunTask, Sink, execute_task, failed_row, one_line

START_METHODS = ("spawn", "forkserver")

#: A run interrupted (SIGTERM) only because another worker broke the pool is run again
#: at most this many times before it is recorded failed.
MAX_INTERRUPTS = 3


def mp_context(start_method: str):
    """``spawn`` (default): every run in a fresh interpreter. ``forkserver``: runs are
    forked from a server process that loaded cosim, libsumo's library and the numba
    kernels once (:mod:`cosim.sim.preload`; never a SUMO simulation), which saves that
    start-up (~1.5-2.5 s per run on a busy 2-core machine)."""
    if start_method not in START_METHODS:
        raise ConfigError(f"start method must be one of {', '.join(START_METHODS)}, "
                          f"got {start_method!r}")
    ctx = multiprocessing.get_context(start_method)
    if start_method == "forkserver":
        ctx.set_forkserver_preload(["cosim.sim.preload", "cosim.sweeps.tasks"])
    return ctx


def run_local(tasks: list[RunTask], workers: int, sink: Sink, start_method: str = "spawn") -> None:
    """Process pool (one task per process); recreated when a worker dies."""
    ctx = mp_context(start_method)
    me, my_start = os.getpid(), proc_start(os.getpid())
    pending = list(tasks)
    interrupts: Counter = Counter()
    stalled = 0
    while pending:
        n = max(1, min(workers, len(pending)))
        ex = ProcessPoolExecutor(max_workers=n, mp_context=ctx, max_tasks_per_child=1)
        futures = {}
        for t in pending:
            t = dataclasses.replace(t, token=uuid.uuid4().hex, parent_pid=me,
                                    parent_start=my_start)
            futures[ex.submit(execute_task, t)] = t
        pending = []
        lost: list[RunTask] = []
        progressed = False
        try:
            for fut in as_completed(futures):
                t = futures[fut]
                try:
                    row = fut.result()
                except BrokenProcessPool:
                    lost.append(t)
                    continue
                except Exception as exc:  # e.g. the task could not be sent to the worker
                    row = failed_row(t, f"worker error: {one_line(exc)}")
                sink(row)
                progressed = True
        finally:
            # After a worker died, the executor terminates the others (SIGTERM): wait
            # until they are gone so that their INTERRUPTED markers are on disk.
            ex.shutdown(wait=True, cancel_futures=True)
        for t in lost:
            run_dir = Path(t.run_dir)
            row = read_row(run_dir)
            if row is not None and row["status"] == "ok":
                sink(row)  # finished, but the result was lost with the pool
                progressed = True
            elif marker_token(run_dir, INTERRUPTED_FILE) == t.token:
                interrupts[t.run_id] += 1
                if interrupts[t.run_id] >= MAX_INTERRUPTS:
                    sink(failed_row(t, f"interrupted {MAX_INTERRUPTS} times (worker pool "
                                       "torn down because other workers died)"))
                    progressed = True
                else:
                    pending.append(t)
            elif marker_token(run_dir, STARTED_FILE) == t.token:
                sink(failed_row(t, "worker process died during the run (crashed or killed; "
                                   "BrokenProcessPool)"))
                progressed = True
            else:
                pending.append(t)  # never started
        stalled = 0 if progressed else stalled + 1
        if stalled >= 3:
            for t in pending:
                sink(failed_row(t, "worker processes die before starting a run"))
            return
