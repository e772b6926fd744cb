"""Run a function in a process of its own, without paying the imports each time.

SUMO tests run every simulation in its own process (libsumo keeps global state). A new
child without them pays the imports and first calls (numpy, pandas, cosim, libsumo's
library, numba's cached kernels) before the simulation runs (a built-in scenario's 90 s
test run: 2.75 s, against 1.58 s with them preloaded); :func:`run_isolated`
forks each process instead from a server process that has loaded all of it once
(``multiprocessing``'s ``forkserver`` with :mod:`cosim.sim.preload`: the server is
single-threaded and has never started a SUMO simulation, so every child starts clean).
One server per test process, started on first use.
"""

from __future__ import annotations

import multiprocessing
import os
import traceback
from collections.abc import Callable
from typing import Any

#: modules the server imports once, so that children start with them loaded
PRELOAD = ["cosim.sim.preload"]

_context = None


def _ctx():
    global _context
    if _context is None:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        _context = ctx
    return _context


def _child(conn, fn: Callable, args: tuple, env: dict | None) -> None:
    try:
        if env is not None:
            os.environ.clear()
            os.environ.update(env)
        conn.send((True, fn(*args)))
    except BaseException:  # the test process shows the child's traceback
        conn.send((False, traceback.format_exc()))
    finally:
        conn.close()


def run_isolated(fn: Callable, *args: Any, env: dict | None = None,
                 timeout_s: float = 600.0) -> Any:
    """``fn(*args)`` in a new process (``env``: its environment, else the server's);
    returns its (picklable) result, raises RuntimeError with the child's traceback if it
    raised, TimeoutError after ``timeout_s`` seconds. ``fn`` must be importable by name
    (a module-level function)."""
    ctx = _ctx()
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, args, env), daemon=True)
    proc.start()
    send.close()
    try:
        if not receive.poll(timeout_s):
            raise TimeoutError(f"{getattr(fn, '__name__', fn)} took more than {timeout_s} s")
        ok, value = receive.recv()
    except EOFError:
        proc.join(5.0)
        raise RuntimeError(f"the child process died (exit code {proc.exitcode})") from None
    finally:
        if proc.is_alive():
            proc.join(5.0)
        if proc.is_alive():
            proc.kill()
            proc.join()
        receive.close()
    if not ok:
        raise RuntimeError(value)
    return value


def cosim_cli(argv: list[str], cwd: str) -> tuple[int, str]:
    """``cosim ARGV`` run in ``cwd`` (in the child: pass it to :func:`run_isolated`);
    returns the exit status and what it printed on stdout."""
    import contextlib
    import io

    from cosim.cli.main import main

    os.chdir(cwd)
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        try:
            code = int(main(argv) or 0)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
    return code, text.getvalue()
