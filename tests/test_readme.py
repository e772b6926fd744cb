"""The README's walk-through runs as written: every command of its first ``sh`` block, in
order, in a fresh folder (``.venv/bin/cosim`` is this interpreter's ``cosim`` script), and
each writes what the README says it writes."""

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"


def walk_through_commands() -> list[str]:
    """The command lines of the ``sh`` block under ``## Walk-through`` (comments cut)."""
    text = README.read_text()
    section = text.split("## Walk-through", 1)[1]
    block = re.search(r"```sh\n(.*?)```", section, re.S)
    assert block, "README: no ```sh block under '## Walk-through'"
    lines = [ln.split("  #", 1)[0].strip() for ln in block.group(1).splitlines()]
    return [ln for ln in lines if ln and not ln.startswith("#")]


def _cosim() -> list[str]:
    script = Path(sys.executable).with_name("cosim")
    return [str(script)] if script.is_file() else [sys.executable, "-m", "cosim"]


def test_the_walk_through_names_only_cosim_commands():
    commands = walk_through_commands()
    assert len(commands) >= 5
    for cmd in commands:
        assert cmd.startswith(".venv/bin/cosim "), cmd


@pytest.mark.sumo
@pytest.mark.slow(seconds=32)
def test_the_walk_through_runs_as_written(tmp_path):
    outputs: list[Path] = []
    for cmd in walk_through_commands():
        args = shlex.split(cmd)[1:]
        proc = subprocess.run([*_cosim(), *args], cwd=tmp_path, capture_output=True, text=True,
                              timeout=900, check=False)
        assert proc.returncode == 0, f"{cmd}\n{proc.stdout[-1500:]}\n{proc.stderr[-1500:]}"
        if "--out" in args:
            outputs.append(tmp_path / args[args.index("--out") + 1])
    for out in outputs:
        assert out.is_dir() and any(out.iterdir()), out
    runs = [p for p in (tmp_path / "outputs").iterdir() if (p / "summary.csv").exists()]
    assert runs, "no run folder under outputs/"
    assert list((tmp_path / "outputs").rglob("*.png")), "analyse drew no figure"
