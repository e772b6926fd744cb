"""Output folders: one rule for every command that writes results (``cosim run``, ``cosim sweep``).

The rule, checked before anything is written:

* the path must not be an existing file, nor lie under one (``results.csv/x``);
* its nearest existing folder must be writable (probed with a temporary folder that is
  removed at once, so that read-only file systems and ``/sys``-like places are caught
  even for root);
* an existing non-empty folder is refused unless the caller asks to ``replace`` it; then
  its contents (and only its contents: symbolic links are removed, never followed) are
  deleted before the new run writes. Folders that hold the current working directory,
  the home folder, the file-system root or a version-control checkout are never cleared.

Every refusal is one :class:`~cosim.errors.ConfigError` line naming the path and what
to do. :func:`safe_name` turns a scenario or sweep name into one safe folder name, so a
name like ``../../x`` cannot write outside the outputs folder.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from pathlib import Path

from cosim.errors import ConfigError

#: Longest folder name :func:`safe_name` returns (characters).
MAX_NAME_CHARS = 100
#: A folder holding one of these is a source checkout, never cleared by ``replace``.
_PROTECTED_MARKERS = (".git", ".hg", ".svn", "pyproject.toml")


def safe_name(name: str) -> str:
    """``name`` as one folder name: no path separators, no ``..``, no leading dot.

    Letters, digits, ``_``, ``-`` and ``.`` are kept; every other run of characters
    becomes ``_``; runs of dots become one dot; leading and trailing ``.``, ``_`` and
    ``-`` are stripped. An empty result becomes ``"unnamed"``. Examples:
    ``"../../x"`` -> ``"x"``, ``"ring fd/2"`` -> ``"ring_fd_2"``.
    """
    text = re.sub(r"[^\w.-]+", "_", str(name))
    text = re.sub(r"\.{2,}", ".", text)
    text = text.strip("._-")[:MAX_NAME_CHARS].strip("._-")
    return text or "unnamed"


def is_nonempty_dir(path: str | Path) -> bool:
    """True if ``path`` is a folder with at least one entry."""
    p = Path(path)
    if not p.is_dir():
        return False
    with os.scandir(p) as it:
        return any(True for _ in it)


def check_output_dir(
    path: str | Path, *, replace: bool = False, what: str = "output folder", keep: bool = False
) -> Path:
    """Check ``path`` as an output folder without writing anything to it.

    Args:
        path: the folder.
        replace: a non-empty folder is accepted (:func:`prepare_output_dir` clears it).
        what: how the messages name the folder (e.g. ``"sweep output folder"``).
        keep: a non-empty folder is accepted as it is (``--resume``).

    Returns:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        ConfigError: an existing file, a path under a file, an unwritable place, or a
            non-empty folder without ``replace``/``keep``.
    """
    p = Path(path).expanduser()
    if p.exists() and not p.is_dir():
        raise ConfigError(f"{what} {p} is an existing file, not a folder: choose another path")
    parent = p
    while not parent.exists():
        if parent.is_symlink():  # a dangling link: the folder would be made elsewhere
            raise ConfigError(f"{what} {p}: {parent} is a broken symbolic link")
        if parent.parent == parent:
            break
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise ConfigError(f"{what} {p} lies under {parent}, which is a file, not a folder")
    _check_writable(parent, p, what)
    if is_nonempty_dir(p) and not (replace or keep):
        raise ConfigError(
            f"{what} {p} already exists and is not empty: pass --replace to delete its "
            "contents, or choose another folder"
        )
    if replace and p.is_dir():
        _check_clearable(p, what)
    return p


def prepare_output_dir(path: str | Path, *, replace: bool, what: str, keep: bool = False) -> Path:
    """Check ``path`` (:func:`check_output_dir`), clear it if ``replace``, create it.

    Args:
        path: the output folder.
        replace: delete the contents of an existing non-empty folder (only that folder).
        what: how error messages name the folder, e.g. ``"run output folder"``.
        keep: accept a non-empty folder and keep its contents (``--resume``).

    Returns:
        The folder, existing and writable (empty unless ``keep``).
    """
    p = check_output_dir(path, replace=replace, what=what, keep=keep)
    if replace and is_nonempty_dir(p):
        clear_dir(p)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"cannot create {what} {p}: {exc.strerror or exc}") from None
    return p


def clear_dir(path: Path) -> None:
    """Delete every entry of the folder ``path`` (links are removed, not followed)."""
    with os.scandir(path) as it:
        entries = list(it)
    for e in entries:
        try:
            if e.is_dir(follow_symlinks=False):
                shutil.rmtree(e.path)
            else:
                os.unlink(e.path)
        except OSError as exc:
            raise ConfigError(f"cannot clear {path}: {e.path}: {exc.strerror or exc}") from None


def _check_writable(existing: Path, target: Path, what: str) -> None:
    """The nearest existing folder of ``target`` must accept a new entry (probed)."""
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ConfigError(f"{what} {target}: {existing} is not writable")
    try:
        probe = tempfile.mkdtemp(prefix=".cosim-probe-", dir=existing)
    except OSError as exc:
        raise ConfigError(
            f"{what} {target}: cannot write in {existing} ({exc.strerror or exc})"
        ) from None
    os.rmdir(probe)


def _check_clearable(p: Path, what: str) -> None:
    """Refuse to clear folders whose loss would hurt more than an old result."""
    real = p.resolve()
    cwd = Path.cwd().resolve()
    if real == Path(real.anchor) or real == Path.home().resolve():
        raise ConfigError(f"{what} {p}: refusing to clear the root or home folder")
    if real == cwd or real in cwd.parents:
        raise ConfigError(
            f"{what} {p}: refusing to clear a folder that holds the current folder"
        )
    for marker in _PROTECTED_MARKERS:
        if (real / marker).exists():
            raise ConfigError(
                f"{what} {p}: refusing to clear a source folder (it holds {marker})"
            )
