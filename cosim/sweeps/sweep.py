"""Parameter sweeps: a grid of scenarios run in parallel, resumable, one tidy results table.

A sweep file (TOML) names a base scenario, inline overrides and axes::

    seeds = [1, 2, 3]                 # optional; or [sweep] seeds, or an axis scenario.seed

    [sweep]
    name = "open_road_capacity"
    description = "..."
    base = "default"                  # built-in scenario name or a path (relative to
                                      # this file); default: the built-in default

    [overrides]                       # scenario sections applied on top of the base
    scenario.duration_s = 600.0
    network.length_m = 2000.0

    [axes]                            # any scenario parameter by dotted path
    "demand.inflow_vph" = [2000.0, 4000.0]
    "demand.cav_share" = [0.0, 0.5, 1.0]
    "controller.params.c1_alpha" = [0.2, 0.3]

    [[variants]]                      # optional named parameter sets (not a product
    name = "lanefree"                 # among themselves): grid = variants x axes x seeds
    "network.kind" = "straight"

    [smoke]                           # `cosim sweep FILE --smoke`: replaces seeds,
    seeds = [1]                       # the axes it names (others are kept), variants;
    [smoke.overrides]                 # its overrides are applied on top
    scenario.duration_s = 40.0
    [smoke.axes]
    "demand.inflow_vph" = [4000.0]

Dotted keys may be quoted (``"demand.cav_share"``) or TOML-dotted; both mean the same.
Every grid point is validated with :func:`cosim.config.scenario_from_dict` before any
run starts, so a typo fails with one line.

Output directory (``--out``, default ``outputs/sweeps/<name>[_smoke]``)::

    sweep.json            the plan: axes, seeds, variants, run ids
    results.csv           one row per grid point run so far (rebuilt atomically after
                          every completion from the row files)
    runs/<run_id>/        the run's outputs (summary.csv, intervals.csv, ...; see
                          cosim.sim.runner) and, written last and atomically, row.csv

``run_id`` is a hash of the resolved scenario (every parameter, seed included), so the
same grid point always gets the same directory and ``--resume`` runs only the points
without an ``ok`` row. Row columns: ``run_id, status (ok|failed), error, variant``,
every swept parameter and a few descriptors (``network.kind``, ``demand.cav_share``,
``controller.kind``, the demand level, ...) by dotted path, ``seed``, the versions
(``cosim_version``, ``sumo_version``, ...), ``wall_time_s`` (whole task, s),
``sim_wall_time_s`` (the run itself, s), then the run's summary metrics
(cosim.sim.runner / cosim.metrics.traffic; units in the names).

Execution: one process per run, because libsumo holds one simulation per process.
Locally a ``ProcessPoolExecutor`` (spawn, ``max_tasks_per_child=1``; ``--start-method
forkserver`` forks each run from a server that preloaded numpy/pandas/cosim, never SUMO,
which saves ~1.5-2.5 s of imports per run on a busy 2-core machine); on Dask
(``--scheduler ADDRESS`` or ``--dask-local N``) each task starts its run in a fresh
subprocess of the Dask worker. A run that raises is recorded ``failed`` with its reason;
a worker process that dies (crash, ``kill``) breaks the local pool: its run is recorded
failed, runs that were interrupted only because the pool was torn down are run again
in a new pool, and no finished run is lost (its row file is on disk). On Dask the
output directory must be on a file system the workers share.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import itertools
import json
import math
import multiprocessing
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import tomllib
import traceback
import uuid
from collections import Counter
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cosim.cli.errors import run_command
from cosim.config.builtins import scenario_dir, sweep_dir
from cosim.errors import ConfigError, CosimError

if TYPE_CHECKING:  # cosim.config.scenario (numpy, ...) is imported where used: the CLI stays fast
    from cosim.config.scenario import Scenario


#: Test-only hook: a worker whose run id is listed here (comma-separated) calls
#: ``os._exit(1)`` right after starting, as if the process had been killed.
CRASH_ENV = "COSIM_SWEEP_TEST_CRASH"

ROW_FILE = "row.csv"
STARTED_FILE = "STARTED"
INTERRUPTED_FILE = "INTERRUPTED"
RESULTS_FILE = "results.csv"
PLAN_FILE = "sweep.json"

#: Demand-level parameters (the x of a fundamental diagram), in order of preference.
DEMAND_PATHS = ("demand.inflow_vph", "demand.ring_density_vpkm")
#: Parameters every row carries even when not swept (the analysis groups by them).
DESCRIPTOR_PATHS = (
    "network.kind",
    "network.width_m",
    "demand.cav_share",
    "controller.kind",
    "scenario.duration_s",
)
#: A run interrupted (SIGTERM) only because another worker broke the pool is run again
#: at most this many times before it is recorded failed.
MAX_INTERRUPTS = 3

_TOP_KEYS = {"sweep", "seeds", "overrides", "axes", "variants", "smoke"}
_SWEEP_KEYS = {"name", "description", "base", "seeds"}
_SMOKE_KEYS = {"name", "description", "seeds", "overrides", "axes", "variants"}


# --------------------------------------------------------------------------------------
# The plan: parsing and validating a sweep file
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GridPoint:
    """One run of a sweep: its parameters (dotted path -> value) and resolved scenario."""

    index: int
    run_id: str
    params: dict[str, Any]
    variant: str | None
    scenario: Scenario

    @property
    def seed(self) -> int:
        return self.scenario.scenario.seed

    def label(self) -> str:
        parts = [f"variant={self.variant}"] if self.variant else []
        parts += [f"{k}={_fmt(v)}" for k, v in self.params.items() if k != "scenario.seed"]
        parts.append(f"seed={self.seed}")
        return ", ".join(parts)


@dataclass(frozen=True)
class SweepPlan:
    """A validated sweep: the grid of points and what it was built from."""

    name: str
    description: str
    source: Path | None
    smoke: bool
    base: str
    overrides: dict[str, Any]
    axes: dict[str, list]
    seeds: list[int] | None
    variants: list[dict[str, Any]]
    points: list[GridPoint] = field(repr=False)

    @property
    def demand_axis(self) -> str | None:
        """The swept demand parameter (x of the fundamental diagram), if any."""
        for p in DEMAND_PATHS:
            if p in self.axes or any(p in v for v in self.variants):
                return p
        return None

    def param_columns(self) -> list[str]:
        """Parameter columns of the rows: swept ones first, then the descriptors."""
        cols = list(self.axes)
        for v in self.variants:
            cols += [k for k in v if k != "name"]
        cols += list(DESCRIPTOR_PATHS)
        cols += [p for p in DEMAND_PATHS]
        return [c for c in dict.fromkeys(cols) if c != "scenario.seed"]

    def to_json(self) -> dict:
        return {
            "name": self.name,
            "description": self.description,
            "source": str(self.source) if self.source else None,
            "smoke": self.smoke,
            "base": self.base,
            "overrides": self.overrides,
            "axes": self.axes,
            "seeds": self.seeds,
            "variants": self.variants,
            "demand_axis": self.demand_axis,
            "param_columns": self.param_columns(),
            "n_points": len(self.points),
            "run_ids": [p.run_id for p in self.points],
        }


def _fmt(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def resolve_sweep_file(arg: str | Path) -> Path:
    """A sweep file by path, or by name from ``experiments/sweeps/``."""
    path = Path(arg)
    if path.is_file():
        return path
    named = sweep_dir() / f"{arg}.toml"
    if path.suffix != ".toml" and named.is_file():
        return named
    known = ", ".join(sorted(p.stem for p in sweep_dir().glob("*.toml")))
    raise ConfigError(f"no sweep file or built-in sweep named {str(arg)!r} (built-in: {known})")


def load_sweep(path: str | Path, smoke: bool = False) -> SweepPlan:
    """Read a sweep file (path or built-in name), validate every grid point, return the plan."""
    path = resolve_sweep_file(path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    try:
        return sweep_from_dict(data, source=path, smoke=smoke)
    except ConfigError as exc:
        raise ConfigError(f"{path.name}: {exc}") from None


def sweep_from_dict(data: dict, source: Path | None = None, smoke: bool = False) -> SweepPlan:
    """Build and validate a :class:`SweepPlan` from a parsed sweep file."""
    from cosim.config.scenario import scenario_from_dict

    _check_keys(data, _TOP_KEYS, "top level")
    head = data.get("sweep", {})
    _check_table(head, "[sweep]")
    _check_keys(head, _SWEEP_KEYS, "[sweep]")
    if "seeds" in head and "seeds" in data:
        raise ConfigError("seeds given both at the top level and in [sweep]")
    default_name = source.stem if source else "sweep"
    name = head.get("name", default_name)
    description = head.get("description", "")
    base_arg = head.get("base")
    seeds = data.get("seeds", head.get("seeds"))
    overrides = _flatten(data.get("overrides", {}), "[overrides]")
    axes = _axes(data.get("axes", {}), "[axes]")
    variants = _variants(data.get("variants", []), "[[variants]]")

    if smoke:
        sm = data.get("smoke")
        if sm is None:
            raise ConfigError("--smoke given but the sweep file has no [smoke] table")
        _check_table(sm, "[smoke]")
        _check_keys(sm, _SMOKE_KEYS, "[smoke]")
        name = sm.get("name", f"{name}_smoke")
        description = sm.get("description", description)
        if "seeds" in sm:
            seeds = sm["seeds"]
        overrides = {**overrides, **_flatten(sm.get("overrides", {}), "[smoke.overrides]")}
        for path, values in _axes(sm.get("axes", {}), "[smoke.axes]").items():
            axes[path] = values
        if "variants" in sm:
            variants = _variants(sm["variants"], "[smoke.variants]")
    if not isinstance(name, str) or not name:
        raise ConfigError("sweep.name must be a non-empty string")

    if seeds is not None:
        if (
            not isinstance(seeds, list) or not seeds
            or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds)
        ):
            raise ConfigError(f"seeds must be a non-empty list of integers >= 0, got {seeds!r}")
        if len(set(seeds)) != len(seeds):
            raise ConfigError(f"seeds has duplicates: {seeds}")
        if "scenario.seed" in axes:
            raise ConfigError("give either seeds or an axis scenario.seed, not both")
    for path in list(overrides) + list(axes) + [k for v in variants for k in v if k != "name"]:
        _check_path(path)

    base_sc, base_label = _resolve_base(base_arg, source)
    seed_axis = {"scenario.seed": list(seeds)} if seeds is not None else {}
    grid_axes = {**axes, **seed_axis}
    names = list(grid_axes)
    combos = list(itertools.product(*grid_axes.values())) if names else [()]
    points: list[GridPoint] = []
    seen: dict[str, int] = {}
    variant_list = variants or [{}]
    n_total = len(variant_list) * len(combos)
    for variant in variant_list:
        vparams = {k: v for k, v in variant.items() if k != "name"}
        for combo in combos:
            point = dict(zip(names, combo, strict=True))
            flat = {**overrides, **vparams, **point}
            where = ", ".join(
                ([f"variant={variant['name']}"] if variant else [])
                + [f"{'seed' if k == 'scenario.seed' else k}={_fmt(v)}" for k, v in point.items()]
            )
            try:
                sc = scenario_from_dict(_unflatten(flat), base=base_sc)
            except ConfigError as exc:
                raise ConfigError(
                    f"grid point {len(points) + 1}/{n_total} ({where}): {exc}"
                ) from None
            rid = run_id(sc)
            if rid in seen:
                raise ConfigError(
                    f"grid points {seen[rid] + 1} and {len(points) + 1} ({where}) are the "
                    "same scenario (duplicate axis values or variants?)"
                )
            seen[rid] = len(points)
            points.append(
                GridPoint(len(points), rid, {**vparams, **point}, variant.get("name"), sc)
            )
    return SweepPlan(
        name=name, description=description, source=source, smoke=smoke, base=base_label,
        overrides=overrides, axes=axes, seeds=list(seeds) if seeds is not None else None,
        variants=variants, points=points,
    )


def run_id(sc: Scenario) -> str:
    """Stable id of a run: 12 hex digits of the SHA-256 of its resolved settings that differ
    from the built-in defaults (seed included).

    Hashing the difference, not the whole config, keeps ids (and ``--resume``) valid when
    a new option with a default is added to the scenario schema; any real change of the
    scenario (base file, overrides, axes) changes the id.
    """
    from cosim.config.scenario import Scenario

    diff = _diff(sc.to_dict(), Scenario().to_dict())
    blob = json.dumps(diff, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:12]


def _diff(value: Any, default: Any) -> Any:
    if isinstance(value, dict) and isinstance(default, dict):
        out = {}
        for k, v in value.items():
            if k not in default:
                out[k] = v
            elif v != default[k]:
                out[k] = _diff(v, default[k])
        return out
    return value


def _check_table(value: Any, where: str) -> None:
    if not isinstance(value, dict):
        raise ConfigError(f"{where} must be a table")


def _check_keys(data: dict, known: set[str], where: str) -> None:
    for key in data:
        if key not in known:
            raise ConfigError(f"{where}: unknown key {key!r} (known: {', '.join(sorted(known))})")


def _flatten(data: Any, where: str, prefix: str = "") -> dict[str, Any]:
    """Nested or dotted-key tables -> {dotted path: leaf value}."""
    _check_table(data, where)
    out: dict[str, Any] = {}
    for key, value in data.items():
        path = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, dict):
            out.update(_flatten(value, where, path))
        else:
            out[path] = value
    return out


def _axes(data: Any, where: str) -> dict[str, list]:
    axes = _flatten(data, where)
    for path, values in axes.items():
        if not isinstance(values, list) or not values:
            raise ConfigError(f"{where}: axis {path!r} must be a non-empty list of values")
        keys = [json.dumps(v, sort_keys=True) for v in values]
        if len(set(keys)) != len(keys):
            raise ConfigError(f"{where}: axis {path!r} has duplicate values: {values}")
    return axes


def _variants(data: Any, where: str) -> list[dict[str, Any]]:
    if not isinstance(data, list) or not all(isinstance(v, dict) for v in data):
        raise ConfigError(f"{where} must be an array of tables ([[variants]])")
    out = []
    for k, v in enumerate(data):
        flat = _flatten(v, where)
        name = flat.get("name", f"v{k + 1}")
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{where} #{k + 1}: name must be a non-empty string")
        flat["name"] = name
        out.append(flat)
    names = [v["name"] for v in out]
    if len(set(names)) != len(names):
        raise ConfigError(f"{where}: duplicate variant names {names}")
    return out


def _check_path(path: str) -> None:
    """A dotted path must name a scenario parameter: section.key or controller.params.key."""
    from controllers.params import FlockingParams
    from cosim.config.scenario import _SECTION_TYPES

    parts = path.split(".")
    if parts[0] not in _SECTION_TYPES:
        raise ConfigError(
            f"unknown parameter {path!r}: no section [{parts[0]}] "
            f"(known: {', '.join(_SECTION_TYPES)})"
        )
    if parts[:2] == ["controller", "params"]:
        known = {f.name for f in fields(FlockingParams)}
        if len(parts) != 3 or parts[2] not in known:
            raise ConfigError(
                f"unknown parameter {path!r} (controller.params keys: {', '.join(sorted(known))})"
            )
        return
    cls = _SECTION_TYPES[parts[0]]
    known = {f.name for f in fields(cls) if f.init}
    if len(parts) != 2 or parts[1] not in known:
        raise ConfigError(
            f"unknown parameter {path!r} ([{parts[0]}] keys: {', '.join(sorted(known))})"
        )


def _unflatten(flat: dict[str, Any]) -> dict:
    out: dict = {}
    for path, value in flat.items():
        node = out
        parts = path.split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return out


def _resolve_base(arg: Any, source: Path | None) -> tuple[Scenario, str]:
    from cosim.config.scenario import default_scenario

    if arg is None:
        return default_scenario(), "default"
    if not isinstance(arg, str) or not arg:
        raise ConfigError(f"sweep.base must be a scenario name or path, got {arg!r}")
    named = scenario_dir() / f"{arg}.toml"
    if not arg.endswith(".toml") and "/" not in arg and named.is_file():
        return _load_base(named), arg
    path = Path(arg).expanduser()
    if not path.is_absolute() and source is not None:
        path = source.parent / path
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in scenario_dir().glob("*.toml")))
        raise ConfigError(
            f"sweep.base: no scenario file {str(path)!r} and no built-in scenario {arg!r} "
            f"(built-in: {known})"
        )
    return _load_base(path), str(path)


def _load_base(path: Path) -> Scenario:
    from cosim.config.scenario import load_scenario

    try:
        return load_scenario(path)
    except ConfigError as exc:
        raise ConfigError(f"base scenario {path}: {exc}") from None


def _value_at(sc: Scenario, path: str) -> Any:
    parts = path.split(".")
    if parts[:2] == ["controller", "params"]:
        return getattr(sc.controller.flocking_params(), parts[2])
    return getattr(getattr(sc, parts[0]), parts[1])


def _cell(v: Any) -> Any:
    """A parameter value as a CSV cell (lists and tuples as JSON)."""
    if isinstance(v, list | tuple):
        return json.dumps(v)
    return v


# --------------------------------------------------------------------------------------
# Tasks and the worker side
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RunTask:
    """What a worker needs for one run (plain data, picklable)."""

    run_id: str
    run_dir: str
    config: dict
    row_base: dict
    token: str = ""  # one per submission: tells this attempt's markers from older ones


def make_tasks(plan: SweepPlan, out_dir: Path) -> list[RunTask]:
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


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    with open(tmp, "w") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def write_row(run_dir: Path, row: dict) -> Path:
    """Write a run's row as a one-row CSV, atomically (temp file + rename)."""
    import pandas as pd

    run_dir.mkdir(parents=True, exist_ok=True)
    path = run_dir / ROW_FILE
    _atomic_write_text(path, pd.DataFrame([row]).to_csv(index=False))
    return path


def read_row(run_dir: Path) -> dict | None:
    """The row of a run directory, or None if there is none (or it is unreadable)."""
    import pandas as pd

    path = Path(run_dir) / ROW_FILE
    if not path.is_file():
        return None
    try:
        df = pd.read_csv(path)
    except Exception:
        return None
    if len(df) != 1 or "status" not in df:
        return None
    row = df.iloc[0].to_dict()
    for key in ("error", "variant"):
        if key in row and not isinstance(row[key], str):
            row[key] = "" if key == "error" else None
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in row.items()}


def _one_line(exc: BaseException, limit: int = 400) -> str:
    text = " ".join(str(exc).split()) or repr(exc)
    text = f"{type(exc).__name__}: {text}"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _marker(run_dir: Path, name: str, token: str) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    info = {"token": token, "pid": os.getpid(), "host": socket.gethostname(), "t": time.time()}
    (run_dir / name).write_text(json.dumps(info))


def _marker_token(run_dir: Path, name: str) -> str | None:
    try:
        return json.loads((Path(run_dir) / name).read_text()).get("token")
    except (OSError, ValueError):
        return None


def execute_task(task: RunTask) -> dict:
    """Run one grid point in this process; write its run directory, then its row.

    Never raises for a failing run: the row says ``failed`` and why (the traceback is
    in ``error.txt``). Meant to run in a fresh process (libsumo: one run per process).
    """
    t0 = time.perf_counter()
    run_dir = Path(task.run_dir)

    def on_term(signum, frame):  # the pool is torn down because another worker died
        try:
            _marker(run_dir, INTERRUPTED_FILE, task.token)
        finally:
            os._exit(128 + signum)

    signal.signal(signal.SIGTERM, on_term)
    if run_dir.exists():
        shutil.rmtree(run_dir)
    _marker(run_dir, STARTED_FILE, task.token)
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
    return row


_SUBPROCESS_CODE = (
    "import json, sys\n"
    "from cosim.sweeps.sweep import RunTask, execute_task\n"
    "execute_task(RunTask(**json.loads(sys.stdin.read())))\n"
)


def execute_task_isolated(task: RunTask) -> dict:
    """Run one grid point in a fresh Python subprocess (for Dask workers, which are
    long-lived and may run several tasks at once: libsumo needs a process per run)."""
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


def failed_row(task: RunTask, reason: str) -> dict:
    """A ``failed`` row for a run that could not report itself (its process died)."""
    from cosim.sim.runner import versions

    row = dict(task.row_base)
    row.update(status="failed", error=reason)
    row.update({f"{k}_version": v for k, v in versions().items()})
    return row


# --------------------------------------------------------------------------------------
# Executors
# --------------------------------------------------------------------------------------

Sink = Callable[[dict], None]


START_METHODS = ("spawn", "forkserver")


def _mp_context(start_method: str):
    """``spawn`` (default): every run in a fresh interpreter. ``forkserver``: runs are
    forked from a server process that imported numpy/pandas/scipy and cosim once (never
    SUMO), which saves that import (~1.5-2.5 s per run on a busy 2-core machine)."""
    if start_method not in START_METHODS:
        raise ConfigError(f"start method must be one of {', '.join(START_METHODS)}, "
                          f"got {start_method!r}")
    ctx = multiprocessing.get_context(start_method)
    if start_method == "forkserver":
        ctx.set_forkserver_preload(["cosim.sim.runner", "cosim.sweeps.sweep"])
    return ctx


def _run_local(tasks: list[RunTask], workers: int, sink: Sink, start_method: str = "spawn") -> None:
    """Process pool (one task per process); recreated when a worker dies."""
    ctx = _mp_context(start_method)
    pending = list(tasks)
    interrupts: Counter = Counter()
    stalled = 0
    while pending:
        n = max(1, min(workers, len(pending)))
        ex = ProcessPoolExecutor(max_workers=n, mp_context=ctx, max_tasks_per_child=1)
        futures = {}
        for t in pending:
            t = dataclasses.replace(t, token=uuid.uuid4().hex)
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


def _run_dask(
    tasks: list[RunTask], sink: Sink, scheduler: str | None, local_workers: int | None
) -> None:
    """Dask distributed: the same submit / as_completed seam through Client.get_executor()."""
    import logging

    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise CosimError(
            "Dask is not installed: pip install 'lanefree-cosim[dask]'"
        ) from None
    cluster = None
    try:
        if local_workers is not None:
            if local_workers < 1:
                raise ConfigError(f"--dask-local must be >= 1, got {local_workers}")
            cluster = LocalCluster(
                n_workers=local_workers, threads_per_worker=1, processes=True,
                dashboard_address=None, silence_logs=logging.ERROR,
            )
            client = Client(cluster)
        else:
            try:
                client = Client(scheduler, timeout=20)
            except (OSError, TimeoutError) as exc:
                raise CosimError(
                    f"cannot connect to the Dask scheduler {scheduler}: {_one_line(exc)}"
                ) from None
        try:
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
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()


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


_FIRST_COLUMNS = ("run_id", "status", "error", "sweep", "variant")
_VERSION_COLUMNS = (
    "cosim_version", "sumo_version", "numpy_version", "pandas_version", "python_version",
    "host", "wall_time_s", "sim_wall_time_s",
)


def results_frame(rows: Iterable[dict], param_columns: Iterable[str] = ()):
    """Rows -> the tidy results DataFrame with a stable column order."""
    import pandas as pd

    rows = list(rows)
    seen: dict[str, None] = {}
    for r in rows:
        seen.update(dict.fromkeys(r))
    first = [c for c in _FIRST_COLUMNS if c in seen]
    params = [c for c in param_columns if c in seen]
    middle = [c for c in ("seed", "scenario", "run_dir", *_VERSION_COLUMNS) if c in seen]
    rest = [c for c in seen if c not in set(first) | set(params) | set(middle)]
    return pd.DataFrame(rows, columns=first + params + middle + rest)


def write_results(out_dir: Path, plan: SweepPlan, rows: dict[str, dict]) -> Path:
    """Rebuild ``results.csv`` (plan order) from the rows, atomically."""
    ordered = [rows[p.run_id] for p in plan.points if p.run_id in rows]
    df = results_frame(ordered, plan.param_columns())
    path = out_dir / RESULTS_FILE
    _atomic_write_text(path, df.to_csv(index=False))
    return path


def run_sweep(
    plan: SweepPlan,
    out_dir: str | Path,
    resume: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    dask_local: int | None = None,
    progress: bool = True,
    start_method: str = "spawn",
) -> SweepOutcome:
    """Run the plan's grid points (the missing ones with ``resume``) and write the results.

    Args:
        plan: from :func:`load_sweep` / :func:`sweep_from_dict`.
        out_dir: the sweep's output directory.
        resume: run only the grid points without an ``ok`` row in ``out_dir``; without
            it, ``out_dir`` must not hold results of an earlier sweep.
        workers: local worker processes (default ``os.cpu_count()``).
        scheduler: address of a Dask scheduler (``tcp://host:8786``), or
        dask_local: run on a local Dask cluster of that many worker processes.
        progress: show a tqdm progress bar (stderr).
        start_method: local pool: ``"spawn"`` or ``"forkserver"`` (see :func:`_mp_context`).
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    runs = out / "runs"
    existing = sorted(runs.glob(f"*/{ROW_FILE}")) if runs.is_dir() else []
    if existing and not resume:
        raise ConfigError(
            f"{out} already holds results of {_runs(len(existing))}: pass --resume to "
            "complete that sweep, or choose another --out"
        )
    if scheduler is not None and dask_local is not None:
        raise ConfigError("give either --scheduler or --dask-local, not both")
    workers = workers or os.cpu_count() or 1
    if workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")
    runs.mkdir(parents=True, exist_ok=True)
    _atomic_write_text(out / PLAN_FILE, json.dumps(plan.to_json(), indent=2, default=str))

    rows: dict[str, dict] = {}
    for pt in plan.points:
        row = read_row(runs / pt.run_id)
        if row is not None:
            rows[pt.run_id] = row
    done_ok = {rid for rid, r in rows.items() if r["status"] == "ok"}
    tasks = [t for t in make_tasks(plan, out) if t.run_id not in done_ok]
    _prebuild_networks(plan, {t.run_id for t in tasks})
    write_results(out, plan, rows)

    bar = None
    if progress and tasks:
        from tqdm import tqdm

        bar = tqdm(total=len(tasks), unit="run", desc=plan.name, file=sys.stderr)
    counts = Counter()

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
            if scheduler is not None or dask_local is not None:
                _run_dask(tasks, sink, scheduler, dask_local)
            else:
                _run_local(tasks, workers, sink, start_method)
    finally:
        if bar is not None:
            bar.close()
        results = write_results(out, plan, rows)
    failed = [r for rid, r in rows.items() if r["status"] != "ok"
              and rid in {p.run_id for p in plan.points}]
    return SweepOutcome(
        plan=plan, out_dir=out, n_run=len(tasks), n_ok=counts["ok"], n_failed=counts["failed"],
        n_skipped=len(plan.points) - len(tasks), wall_time_s=time.perf_counter() - t0,
        results_csv=results, failed=failed,
    )


def _prebuild_networks(plan: SweepPlan, todo: set[str]) -> None:
    """Build each distinct network once, before any run (netconvert errors fail early)."""
    from cosim.road.build import build_network

    specs = {p.scenario.network for p in plan.points if p.run_id in todo}
    for spec in specs:
        build_network(spec)


def default_out_dir(plan: SweepPlan) -> Path:
    return Path("outputs") / "sweeps" / plan.name


# --------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="sweep TOML file, or a built-in sweep name (experiments/sweeps)")
    p.add_argument("--smoke", action="store_true",
                   help="the file's [smoke] variant: small grid, short runs")
    p.add_argument("--out", help="output folder (default outputs/sweeps/NAME[_smoke])")
    p.add_argument("--resume", action="store_true",
                   help="run only the grid points without an ok row in --out")
    p.add_argument("--workers", type=int,
                   help="local worker processes (default: the number of CPUs)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on this Dask scheduler (e.g. tcp://host:8786)")
    g.add_argument("--dask-local", type=int, metavar="N",
                   help="run on a local Dask cluster of N worker processes")
    p.add_argument("--start-method", choices=START_METHODS, default="spawn",
                   help="local worker processes: fresh interpreters (spawn, default) or "
                        "forked from a preloaded server (forkserver: less start-up time)")
    p.add_argument("--dry-run", action="store_true",
                   help="validate the grid and list it; run nothing")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep)


def add_sweep_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``cosim sweep`` on an argparse subparsers object; returns the subparser."""
    p = subparsers.add_parser(
        "sweep", help="run a grid of scenarios in parallel (resumable; local or Dask)",
        description="Run a sweep file's grid of scenarios; one row per run in results.csv.",
    )
    _add_arguments(p)
    return p


def _runs(n: int) -> str:
    return f"{n} run" if n == 1 else f"{n} runs"


def cmd_sweep(ns: argparse.Namespace) -> int:
    plan = load_sweep(ns.file, smoke=ns.smoke)
    out = Path(ns.out) if ns.out else default_out_dir(plan)
    axes = [f"{k} x{len(v)}" for k, v in plan.axes.items()]
    if plan.seeds is not None:
        axes.append(f"seeds x{len(plan.seeds)}")
    if plan.variants:
        axes.insert(0, f"variants x{len(plan.variants)}")
    print(f"sweep '{plan.name}': {_runs(len(plan.points))} ({', '.join(axes) or 'one point'}) "
          f"-> {out}/", flush=True)
    if ns.dry_run:
        for pt in plan.points:
            row = read_row(out / "runs" / pt.run_id)
            state = row["status"] if row else "todo"
            print(f"  {pt.run_id}  {state:<6}  {pt.label()}")
        return 0
    res = run_sweep(plan, out, resume=ns.resume, workers=ns.workers, scheduler=ns.scheduler,
                    dask_local=ns.dask_local, progress=not ns.quiet,
                    start_method=ns.start_method)
    print(f"{_runs(res.n_run)} in {res.wall_time_s:.1f} s: {res.n_ok} ok, {res.n_failed} failed"
          + (f" ({res.n_skipped} already done)" if res.n_skipped else ""))
    for r in res.failed[:10]:
        print(f"  failed {r['run_id']}: {r.get('error', '')}")
    if len(res.failed) > 10:
        print(f"  ... and {len(res.failed) - 10} more (see results.csv)")
    print(f"results: {res.results_csv}")
    if res.failed:
        print(f"{_runs(len(res.failed))} failed: 'cosim sweep {ns.file}"
              f"{' --smoke' if ns.smoke else ''} --out {out} --resume' runs them again")
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    """``cosim sweep`` without the rest of the CLI: ``main(["FILE", "--smoke", ...])``."""
    ap = argparse.ArgumentParser(prog="cosim sweep", description=__doc__.splitlines()[0])
    _add_arguments(ap)
    ns = ap.parse_args(argv)
    return run_command(ns.func, ns, "interrupted (finished runs are kept; use --resume)")
