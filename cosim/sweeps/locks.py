"""Markers, locks and process liveness of a sweep (nothing runs twice at once).

* ``OUT/.sweep.lock``: the sweep process holds it locked (``flock``, released by the
  kernel when the process dies): :func:`acquire_sweep_lock`, :func:`sweep_lock_holder`;
* a run's ``STARTED`` marker: the worker writes it and holds it locked while it runs
  (:func:`hold_started`); :func:`run_in_flight` names the live process that does;
* a run's ``INTERRUPTED`` marker (:func:`write_marker`, :func:`marker_token`): the
  worker's pool was torn down under it;
* :func:`process_alive` and :func:`proc_start`: is a process (still the same one) alive.

Without ``fcntl`` (Windows) the locks are not taken.
"""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path
from typing import IO

from cosim.errors import ConfigError

try:  # POSIX; without it (Windows) the locks are not taken
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

STARTED_FILE = "STARTED"
INTERRUPTED_FILE = "INTERRUPTED"
LOCK_FILE = ".sweep.lock"


def write_marker(run_dir: Path, name: str, token: str) -> None:
    """Write marker file ``name`` in ``run_dir``: this attempt's token, pid, host, time."""
    run_dir.mkdir(parents=True, exist_ok=True)
    info = {"token": token, "pid": os.getpid(), "host": socket.gethostname(), "t": time.time()}
    (run_dir / name).write_text(json.dumps(info))


def marker_token(run_dir: Path, name: str) -> str | None:
    """The token in marker file ``name`` of ``run_dir`` (None if absent or unreadable)."""
    try:
        return json.loads((Path(run_dir) / name).read_text()).get("token")
    except (OSError, ValueError):
        return None


def hold_started(run_dir: Path, token: str) -> IO[str]:
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


def acquire_sweep_lock(out: Path) -> IO[str] | None:
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


def proc_start(pid: int) -> str:
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
