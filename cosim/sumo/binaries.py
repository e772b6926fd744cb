"""Where SUMO's programs are (the eclipse-sumo wheel, ``$SUMO_HOME``, PATH) and their version."""

from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
from pathlib import Path

from cosim.errors import NetworkError


def sumo_binary(name: str = "sumo") -> Path:
    """Path of a SUMO program (``sumo``, ``netconvert``, ``sumo-gui``...).

    Looked up in the eclipse-sumo package, then ``$SUMO_HOME/bin``, then PATH.
    """
    candidates: list[Path] = []
    try:
        import sumo  # the eclipse-sumo wheel

        candidates.append(Path(sumo.SUMO_HOME) / "bin" / name)
    except ImportError:
        pass
    if os.environ.get("SUMO_HOME"):
        candidates.append(Path(os.environ["SUMO_HOME"]) / "bin" / name)
    which = shutil.which(name)
    if which:
        candidates.append(Path(which))
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return c
    raise NetworkError(f"{name} not found: install eclipse-sumo (pip install eclipse-sumo)")


def netconvert_binary() -> Path:
    """Path of ``netconvert``."""
    return sumo_binary("netconvert")


@functools.lru_cache(maxsize=1)
def sumo_version() -> str:
    """SUMO version string of the netconvert in use, e.g. ``"1.28.0"``."""
    out = subprocess.run(
        [str(netconvert_binary()), "--version"], capture_output=True, text=True, check=False
    ).stdout
    m = re.search(r"netconvert\s+v?(?:ersion\s+)?(\S+)", out, flags=re.IGNORECASE)
    return m.group(1) if m else "unknown"
