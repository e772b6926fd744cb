"""A run's results: tables in memory, written as CSV with the resolved config and versions.

Files (``RunResult.write``): ``summary.csv`` (one row), ``intervals.csv`` (one row per
measurement interval), ``flock.csv`` (CAV flock metrics every second),
``collisions.csv`` (every collision event), ``trajectories.csv`` (optional),
``trips.csv`` (open roads in SUMO: every vehicle's origin, destination and times),
``config.toml`` (the resolved scenario: every parameter, the law's gains included),
``meta.json`` (seed, versions, world, demand and measurement layout, wall time), and
the SUMO world's inputs and detector outputs: ``routes.rou.xml``, ``detectors.add.xml``
and ``sumo/`` (paths in meta.json are relative to the run folder).
"""

from __future__ import annotations

import json
import platform
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from cosim import __version__
from cosim.config.toml_write import dumps_toml


def versions() -> dict[str, str]:
    """Versions of this package, SUMO, numpy, pandas and Python (recorded in every output)."""
    from cosim.sumo.binaries import sumo_version

    return {
        "cosim": __version__,
        "sumo": sumo_version(),
        "numpy": np.__version__,
        "pandas": pd.__version__,
        "python": platform.python_version(),
    }


@dataclass
class RunResult:
    """Outputs of one run: summary (1 row), intervals, flock samples, collisions, trajectories."""

    summary: pd.DataFrame
    intervals: pd.DataFrame
    flock: pd.DataFrame
    collisions: pd.DataFrame
    trajectories: pd.DataFrame | None
    meta: dict = field(default_factory=dict)
    out_dir: Path | None = None
    #: the world's input and detector files, by path relative to the run folder
    inputs: dict[str, bytes] = field(default_factory=dict)
    #: one row per planned vehicle of an open road (origin, destination, times; see
    #: :func:`cosim.sim.runner.trip_table`), or None
    trips: pd.DataFrame | None = None

    def write(self, out_dir: str | Path) -> Path:
        """Write every table as CSV plus meta.json and config.toml into ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        self.summary.to_csv(out / "summary.csv", index=False)
        self.intervals.to_csv(out / "intervals.csv", index=False)
        self.flock.to_csv(out / "flock.csv", index=False)
        self.collisions.to_csv(out / "collisions.csv", index=False)
        if self.trajectories is not None:
            self.trajectories.to_csv(out / "trajectories.csv", index=False)
        if self.trips is not None:
            self.trips.to_csv(out / "trips.csv", index=False)
        for rel, data in self.inputs.items():
            target = out / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        self.write_meta(out)
        (out / "config.toml").write_text(dumps_toml(self.meta["config"]))
        self.out_dir = out
        return out

    def write_meta(self, out_dir: str | Path) -> None:
        """(Re)write meta.json."""
        (Path(out_dir) / "meta.json").write_text(json.dumps(self.meta, indent=2, default=str))
