"""Built-in scenario and sweep files, found as package data of ``experiments``.

``importlib.resources`` locates them wherever the package is installed (an
editable checkout or site-packages), so nothing depends on the current folder.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path


def _folder(kind: str) -> Path:
    return Path(str(resources.files("experiments") / kind))


def scenario_dir() -> Path:
    """Folder of the built-in scenario files."""
    return _folder("scenarios")


def sweep_dir() -> Path:
    """Folder of the built-in sweep files."""
    return _folder("sweeps")


def builtin_scenarios() -> dict[str, Path]:
    """Built-in scenario files by name (``experiments/scenarios/NAME.toml``)."""
    return {p.stem: p for p in sorted(scenario_dir().glob("*.toml"))}


def builtin_sweeps() -> dict[str, Path]:
    """Built-in sweep files by name (``experiments/sweeps/NAME.toml``)."""
    return {p.stem: p for p in sorted(sweep_dir().glob("*.toml"))}


def description(path: Path, section: str) -> str:
    """The one-line ``description`` of a built-in file's ``[section]`` ("" if none)."""
    try:
        return str(tomllib.loads(path.read_text(encoding="utf-8")).get(section, {})
                   .get("description", ""))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return "(unreadable)"
