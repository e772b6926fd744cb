"""The Dask backend: runs on a Dask cluster (``--scheduler ADDRESS`` or ``--dask-local N``).

:func:`dask_client` connects to (or starts) the cluster before anything is written,
failing fast in one line when the scheduler does not answer; :func:`run_dask` submits
one task per run, each starting its run in a fresh subprocess of the Dask worker
(:func:`cosim.sweeps.tasks.execute_task_isolated`). The output directory must be on a
file system the workers share.
"""

from __future__ import annotations

import dataclasses
import socket
import uuid
from concurrent.futures import as_completed
from pathlib import Path
from urllib.parse import urlsplit

from cosim.errors import ConfigError, CosimError
from cosim.sweeps.results import read_row
from cosim.sweeps.tasks import RunTask, Sink, execute_task_isolated, failed_row, one_line

#: Connecting to a Dask scheduler gives up after this long, s.
DASK_CONNECT_TIMEOUT_S = 10.0


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
            f"cannot reach the Dask scheduler {address}: {exc.strerror or one_line(exc)}"
        ) from None


def dask_client(scheduler: str | None, local_workers: int | None):
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
            raise CosimError(f"cannot start a local Dask cluster: {one_line(exc)}") from None
    _probe_scheduler(scheduler)
    try:
        return Client(scheduler, timeout=DASK_CONNECT_TIMEOUT_S), None
    except Exception as exc:
        raise CosimError(
            f"cannot connect to the Dask scheduler {scheduler}: {one_line(exc)}"
        ) from None


def run_dask(tasks: list[RunTask], sink: Sink, client) -> None:
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
                row = failed_row(t, f"dask task failed: {one_line(exc)}")
        sink(row)
