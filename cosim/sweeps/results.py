"""A sweep's results on disk: one row file per run and the tidy ``results.csv``.

Output directory of a sweep::

    sweep.json            the plan: axes, seeds, variants, run ids
    results.csv           one row per grid point run so far (rebuilt atomically after
                          every completion from the row files)
    runs/<run_id>/        the run's outputs (summary.csv, intervals.csv, ...; see
                          cosim.sim.runner) and, written last and atomically, row.csv

Row columns: ``run_id, status (ok|failed), error, variant``, every swept parameter and a
few descriptors (``network.kind``, ``demand.cav_share``, ``controller.kind``, the demand
level, ...) by dotted path, ``seed``, the versions (``cosim_version``, ``sumo_version``,
...), ``wall_time_s`` (whole task, s), ``sim_wall_time_s`` (the run itself, s), then the
run's summary metrics (cosim.sim.runner / cosim.metrics.traffic; units in the names).
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from cosim.errors import ConfigError

if TYPE_CHECKING:
    from cosim.sweeps.plan import SweepPlan

ROW_FILE = "row.csv"
RESULTS_FILE = "results.csv"
PLAN_FILE = "sweep.json"

_FIRST_COLUMNS = ("run_id", "status", "error", "sweep", "variant")
_VERSION_COLUMNS = (
    "cosim_version", "sumo_version", "numpy_version", "pandas_version", "python_version",
    "host", "wall_time_s", "sim_wall_time_s",
)


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename (never half a file)."""
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
    atomic_write_text(path, pd.DataFrame([row]).to_csv(index=False))
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
    atomic_write_text(path, df.to_csv(index=False))
    return path


def write_plan(out_dir: Path, plan: SweepPlan) -> Path:
    """Write the plan (``sweep.json``), atomically."""
    path = Path(out_dir) / PLAN_FILE
    atomic_write_text(path, json.dumps(plan.to_json(), indent=2, default=str))
    return path


def read_plan(out_dir: Path) -> dict | None:
    """The ``sweep.json`` of a sweep folder (None if there is none).

    Raises:
        ConfigError: it exists but is not a sweep plan.
    """
    path = Path(out_dir) / PLAN_FILE
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise ConfigError(f"{path}: unreadable sweep plan ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("run_ids"), list):
        raise ConfigError(f"{path}: not a sweep plan (no run_ids)")
    return data
