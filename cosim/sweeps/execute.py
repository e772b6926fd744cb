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
  thread ends the worker (within :data:`PARENT_POLL_S`) when the sweep process (local
  pool) or its parent process (the Dask worker) is gone, so no orphan keeps running;
* ``--resume`` first waits (up to :data:`IN_FLIGHT_WAIT_S`) until no run of the folder
  is locked by a live process, and refuses to start if one still is.

Nothing is written before every option, the output folder (:mod:`cosim.output_dir`),
the networks and the Dask scheduler are checked: a bad input leaves no half-made folder.
"""

from __future__ import annotations

import dataclasses
import json
import math
import multiprocessing
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
import uuid
from collections import Counter
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any
from urllib.parse import urlsplit

from cosim.errors import ConfigError, CosimError
from cosim.output_dir import check_output_dir, is_nonempty_dir, prepare_output_dir
from cosim.sweeps.plan import DEMAND_PATHS, SweepPlan, _cell, _value_at
from cosim.sweeps.results import (
    ROW_FILE,
    read_plan,
    read_row,
    write_plan,
    write_results,
    write_row,
)

try:  # POSIX; without it (Windows) the locks are not taken
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

#: Test-only hook: a worker whose run id is listed here (comma-separated) calls
#: ``os._exit(1)`` right after starting, as if the process had been killed.
CRASH_ENV = "COSIM_SWEEP_TEST_CRASH"
#: Test-only hook: workers append ``start|end|orphaned RUN_ID PID TIME_S`` lines to this file.
TEST_LOG_ENV = "COSIM_SWEEP_TEST_LOG"

STARTED_FILE = "STARTED"
INTERRUPTED_FILE = "INTERRUPTED"
LOCK_FILE = ".sweep.lock"
WHAT = "sweep output folder"
START_METHODS = ("spawn", "forkserver")

#: A run interrupted (SIGTERM) only because another worker broke the pool is run again
#: at most this many times before it is recorded failed.
MAX_INTERRUPTS = 3
#: How often a worker checks that the sweep process (its parent) is alive, s.
PARENT_POLL_S = 0.25
#: How long a sweep waits for runs of its folder that live processes still hold, s.
IN_FLIGHT_WAIT_S = 15.0
#: Connecting to a Dask scheduler gives up after this long, s.
DASK_CONNECT_TIMEOUT_S = 10.0


# --------------------------------------------------------------------------------------
# Tasks
# --------------------------------------------------------------------------------------


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


def _one_line(exc: BaseException, limit: int = 400) -> str:
    text = " ".join(str(exc).split()) or repr(exc)
    text = f"{type(exc).__name__}: {text}"
    return text if len(text) <= limit else text[: limit - 3] + "..."


# --------------------------------------------------------------------------------------
# Markers, locks and process liveness
# --------------------------------------------------------------------------------------


def _marker(run_dir: Path, name: str, token: str) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    info = {"token": token, "pid": os.getpid(), "host": socket.gethostname(), "t": time.time()}
    (run_dir / name).write_text(json.dumps(info))


def _marker_token(run_dir: Path, name: str) -> str | None:
    try:
        return json.loads((Path(run_dir) / name).read_text()).get("token")
    except (OSError, ValueError):
        return None


def _hold_started(run_dir: Path, token: str) -> IO[str]:
    """Write the ``STARTED`` marker and keep it locked (``flock``) while this process runs."""
    run_dir.mkdir(parents=True, exist_ok=True)
    fh = open(run_dir / STARTED_FILE, "w")  # noqa: SIM115 (held open until the run ends)
    if fcntl is not None:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            pass  # a file system without locks: the watchdog still ends orphans
    info = {"token": token, "pid": os.getpid(), "host": socket.gethostname(), "t": time.time()}
    fh.write(json.dumps(info))
    fh.flush()
    return fh


def _lock_holder(path: Path) -> int | None:
    """The pid written in a lock file that a live process holds locked, else None
    (-1 when it is held but names no pid)."""
    if fcntl is None or not path.is_file():
        return None
    try:
        fh = open(path)  # noqa: SIM115
    except OSError:
        return None
    with fh:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                return int(json.loads(fh.read() or "{}").get("pid", -1))
            except (ValueError, AttributeError, TypeError):
                return -1
        except OSError:
            return None
        fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
        return None


def run_in_flight(run_dir: str | Path) -> int | None:
    """The pid of a live process that is running this run now (it holds the ``STARTED``
    lock), else None."""
    return _lock_holder(Path(run_dir) / STARTED_FILE)


def sweep_lock_holder(out_dir: str | Path) -> int | None:
    """The pid of a live ``cosim sweep`` that works in ``out_dir``, else None."""
    return _lock_holder(Path(out_dir) / LOCK_FILE)


def _acquire_sweep_lock(out: Path) -> IO[str] | None:
    """Lock ``OUT/.sweep.lock`` for this process (released when it exits or on close)."""
    if fcntl is None:
        return None
    fh = open(out / LOCK_FILE, "a+")  # noqa: SIM115 (held for the whole sweep)
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        fh.close()
        raise ConfigError(
            f"{out} is in use by another 'cosim sweep' (process "
            f"{sweep_lock_holder(out)}): wait for it to end, or choose another --out"
        ) from None
    except OSError:
        return fh  # no locks on this file system
    fh.seek(0)
    fh.truncate()
    fh.write(json.dumps({"pid": os.getpid(), "host": socket.gethostname()}))
    fh.flush()
    return fh


def _proc_start(pid: int) -> str:
    """Start time of a process (``/proc/PID/stat`` field 22, clock ticks); "" if unknown."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return ""
    return stat.rsplit(")", 1)[1].split()[19]


def process_alive(pid: int, start: str = "") -> bool:
    """True if process ``pid`` runs (not a zombie) and, if ``start`` is given, is the one
    that started then (not a later process that reused the pid)."""
    if pid <= 0:
        return False
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    except OSError:  # no /proc: ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True
    fields_ = stat.rsplit(")", 1)[1].split()
    if fields_[0] in ("Z", "X"):
        return False
    return not start or fields_[19] == start


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


# --------------------------------------------------------------------------------------
# The worker side
# --------------------------------------------------------------------------------------


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
            _marker(run_dir, INTERRUPTED_FILE, task.token)
        finally:
            os._exit(128 + signum)

    signal.signal(signal.SIGTERM, on_term)
    if run_dir.exists():
        shutil.rmtree(run_dir)
    started = _hold_started(run_dir, task.token)
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
        row.update(status="failed", error=_one_line(exc))
        row["wall_time_s"] = time.perf_counter() - t0
        (run_dir / "error.txt").write_text(traceback.format_exc())
    write_row(run_dir, row)
    _test_log("end", task)
    started.close()
    return row


_SUBPROCESS_CODE = (
    "import json, sys\n"
    "from cosim.sweeps.execute import RunTask, execute_task\n"
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
    if row is not None and _marker_token(run_dir, STARTED_FILE) == task.token:
        return row
    tail = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()][-1:]
    reason = f"worker process exited with code {proc.returncode}"
    if tail:
        reason += f": {tail[0].strip()[:300]}"
    return failed_row(task, reason)


# --------------------------------------------------------------------------------------
# Executors
# --------------------------------------------------------------------------------------

Sink = Callable[[dict], None]


def _mp_context(start_method: str):
    """``spawn`` (default): every run in a fresh interpreter. ``forkserver``: runs are
    forked from a server process that loaded cosim, libsumo's library and the numba
    kernels once (:mod:`cosim.sim.preload`; never a SUMO simulation), which saves that
    start-up (~1.5-2.5 s per run on a busy 2-core machine)."""
    if start_method not in START_METHODS:
        raise ConfigError(f"start method must be one of {', '.join(START_METHODS)}, "
                          f"got {start_method!r}")
    ctx = multiprocessing.get_context(start_method)
    if start_method == "forkserver":
        ctx.set_forkserver_preload(["cosim.sim.preload", "cosim.sweeps.execute"])
    return ctx


def _run_local(tasks: list[RunTask], workers: int, sink: Sink, start_method: str = "spawn") -> None:
    """Process pool (one task per process); recreated when a worker dies."""
    ctx = _mp_context(start_method)
    me, my_start = os.getpid(), _proc_start(os.getpid())
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
                    row = failed_row(t, f"worker error: {_one_line(exc)}")
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
            elif _marker_token(run_dir, INTERRUPTED_FILE) == t.token:
                interrupts[t.run_id] += 1
                if interrupts[t.run_id] >= MAX_INTERRUPTS:
                    sink(failed_row(t, f"interrupted {MAX_INTERRUPTS} times (worker pool "
                                       "torn down because other workers died)"))
                    progressed = True
                else:
                    pending.append(t)
            elif _marker_token(run_dir, STARTED_FILE) == t.token:
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


def _probe_scheduler(address: str) -> None:
    """Fail fast (one line) when a ``tcp://host:port`` scheduler does not answer."""
    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme not in ("tcp", ""):
        return  # tls://, ucx://, ...: left to Dask
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        raise ConfigError(f"--scheduler: not an address: {address!r} "
                          "(expected tcp://HOST:PORT)") from None
    if not host or port is None:
        raise ConfigError(f"--scheduler: not an address: {address!r} (expected tcp://HOST:PORT)")
    try:
        with socket.create_connection((host, port), timeout=DASK_CONNECT_TIMEOUT_S):
            pass
    except OSError as exc:
        raise CosimError(
            f"cannot reach the Dask scheduler {address}: {exc.strerror or _one_line(exc)}"
        ) from None


def _dask_client(scheduler: str | None, local_workers: int | None):
    """Connect to (or start) Dask before anything is written: (client, cluster or None)."""
    import logging

    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise CosimError(
            "Dask is not installed: pip install 'lanefree-cosim[dask]'"
        ) from None
    if local_workers is not None:
        try:
            cluster = LocalCluster(
                n_workers=local_workers, threads_per_worker=1, processes=True,
                dashboard_address=None, silence_logs=logging.ERROR,
            )
            return Client(cluster), cluster
        except Exception as exc:
            raise CosimError(f"cannot start a local Dask cluster: {_one_line(exc)}") from None
    _probe_scheduler(scheduler)
    try:
        return Client(scheduler, timeout=DASK_CONNECT_TIMEOUT_S), None
    except Exception as exc:
        raise CosimError(
            f"cannot connect to the Dask scheduler {scheduler}: {_one_line(exc)}"
        ) from None


def _run_dask(tasks: list[RunTask], sink: Sink, client) -> None:
    """Dask distributed: the same submit / as_completed seam through Client.get_executor()."""
    ex = client.get_executor(pure=False)
    futures = {}
    for t in tasks:
        t = dataclasses.replace(t, token=uuid.uuid4().hex)
        futures[ex.submit(execute_task_isolated, t)] = t
    for fut in as_completed(futures):
        t = futures[fut]
        try:
            row = fut.result()
        except Exception as exc:  # KilledWorker, lost connection, ...
            row = read_row(Path(t.run_dir))
            if row is None or row["status"] != "ok":
                row = failed_row(t, f"dask task failed: {_one_line(exc)}")
        sink(row)


# --------------------------------------------------------------------------------------
# Running a sweep
# --------------------------------------------------------------------------------------


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
        start_method: local pool: ``"spawn"`` or ``"forkserver"`` (see :func:`_mp_context`).
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
            client, cluster = _dask_client(scheduler, dask_local)
        _prebuild_networks(plan, {t.run_id for t in tasks})
        prepare_output_dir(out, replace=replace, what=WHAT, keep=resume)
        lock = _acquire_sweep_lock(out)
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
                    _run_dask(tasks, sink, client)
                else:
                    _run_local(tasks, n_workers, sink, start_method)
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
