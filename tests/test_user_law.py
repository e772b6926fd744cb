"""A user's own controller through the seam: ``controller.kind = "module:Class"``.

The README's smallest law (examples/zeroctl.py, u = 0) and a law with a parameter
(examples/cruise.py) run in SUMO from a folder of the user's, with the examples folder
copied there and put on PYTHONPATH (the ``examples`` folder is not an installed
package); the safety layer keeps them collision-free and the run's config.toml records
the law's parameters. A bad user law is one ``error:`` line and exit status 2.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from cosim.cli.main import main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: The run's measurement must fit in 30 s (the built-in files measure after 60 s).
SHORT = ["--set", "scenario.warmup_s=10", "--set", "scenario.interval_s=20"]


def _cosim() -> list[str]:
    script = Path(sys.executable).with_name("cosim")
    return [str(script)] if script.is_file() else [sys.executable, "-m", "cosim"]


@pytest.fixture
def user_folder(tmp_path) -> tuple[Path, dict]:
    """A user's working folder (the cwd) and a separate folder with their laws."""
    laws = tmp_path / "mylaws"
    laws.mkdir()
    for name in ("zeroctl.py", "cruise.py"):
        shutil.copy(EXAMPLES / name, laws / name)
    work = tmp_path / "work"
    work.mkdir()
    env = dict(os.environ)
    env["PYTHONPATH"] = str(laws)
    env["COSIM_NETWORK_CACHE"] = str(tmp_path / "network_cache")
    return work, env


def _cosim_run(work: Path, env: dict, *args: str, timeout: float = 300.0):
    proc = subprocess.run([*_cosim(), "run", *args, "--quiet", "--out", "OUT"], cwd=work,
                          env=env, capture_output=True, text=True, timeout=timeout, check=False)
    out = work / "OUT"
    return proc, out


def _summary(out: Path) -> dict:
    return pd.read_csv(out / "summary.csv").iloc[0].to_dict()


def _config(out: Path) -> dict:
    return tomllib.loads((out / "config.toml").read_text())


def test_examples_are_the_readme_protocol_example():
    text = (EXAMPLES / "zeroctl.py").read_text()
    assert "class Zero:" in text and "def compute(self, obs):" in text
    assert "return np.zeros((len(obs.q), 2))" in text
    assert not (EXAMPLES / "__init__.py").exists()  # not a package: found on PYTHONPATH


@pytest.mark.sumo
def test_zeroctl_runs_and_a_run_too_short_to_measure_is_refused(user_folder):
    """``cosim run default --set controller.kind=zeroctl:Zero --set scenario.duration_s=30``
    measures nothing (the default warm-up is 60 s): one error line, exit 2, nothing
    written; with a warm-up and an interval that fit it runs."""
    work, env = user_folder
    proc, out = _cosim_run(work, env, "default", "--set", "controller.kind=zeroctl:Zero",
                           "--set", "scenario.duration_s=30")
    assert proc.returncode == 2 and proc.stderr.startswith("error:"), proc.stderr
    assert "nothing would be measured" in proc.stderr and not out.exists()
    proc, out = _cosim_run(work, env, "default", "--set", "controller.kind=zeroctl:Zero",
                           "--set", "scenario.duration_s=30", *SHORT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert _summary(out)["collisions_geometric_cav"] == 0


def test_a_law_in_the_current_folder_is_found_without_pythonpath(user_folder):
    """``python -m`` finds modules in the folder it runs in; so does ``cosim``: a user who
    keeps ``mylaw.py`` beside their work needs no PYTHONPATH."""
    work, env = user_folder
    shutil.copy(EXAMPLES / "zeroctl.py", work / "herelaw.py")
    env = {k: v for k, v in env.items() if k != "PYTHONPATH"}
    proc, out = _cosim_run(work, env, "default", "--set", "controller.kind=herelaw:Zero",
                           "--set", "scenario.duration_s=30", *SHORT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "herelaw:Zero CAVs" in proc.stdout
    assert _config(out)["controller"]["kind"] == "herelaw:Zero"
    proc, _ = _cosim_run(work, env, "default", "--set", "controller.kind=nowhere:Zero")
    assert proc.returncode == 2 and proc.stderr.startswith("error:")
    assert "current folder" in proc.stderr


@pytest.mark.sumo
def test_zeroctl_runs_in_sumo_and_the_safety_layer_keeps_it_collision_free(user_folder):
    work, env = user_folder
    proc, out = _cosim_run(work, env, "default", "--set", "controller.kind=zeroctl:Zero",
                           "--set", "scenario.duration_s=30", *SHORT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "zeroctl:Zero CAVs, sumo world" in proc.stdout
    s = _summary(out)
    assert s["collisions_geometric_cav"] == 0 and s["collisions_sumo_cav"] == 0
    assert s["boundary_vehicle_steps_cav"] == 0
    assert s["vehicles_inserted"] >= 10
    cfg = _config(out)["controller"]
    assert cfg["kind"] == "zeroctl:Zero" and cfg.get("params", {}) == {}
    assert not (work / "outputs").exists()  # only where --out said


@pytest.mark.sumo
@pytest.mark.parametrize("gain", [None, 0.8])
def test_a_law_with_a_parameter_runs_and_its_params_are_written(user_folder, gain):
    work, env = user_folder
    params = [] if gain is None else ["--set", f"controller.params.gain_per_s={gain}"]
    proc, out = _cosim_run(work, env, "default", "--set", "controller.kind=cruise:Cruise",
                           *params, "--set", "scenario.duration_s=30", *SHORT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    s = _summary(out)
    assert s["collisions_geometric_cav"] == 0 and s["collisions_sumo_cav"] == 0
    assert s["space_mean_speed_mps"] > 20.0  # cruising, not standing
    cfg = _config(out)["controller"]
    assert cfg["kind"] == "cruise:Cruise"
    assert cfg["params"] == {"gain_per_s": 0.5 if gain is None else gain}  # resolved


# --------------------------------------------------------------------------------------
# Bad user laws: one line, exit 2 (no SUMO needed: they fail before or at the first step)
# --------------------------------------------------------------------------------------

BAD = '''
import numpy as np

class Plain:
    """No compute method."""

class Cruise:
    def __init__(self, gain_per_s=0.5):
        self.gain_per_s = gain_per_s
    def compute(self, obs):
        return np.zeros((len(obs.q), 2))

class BadShape:
    def compute(self, obs):
        return np.zeros(len(obs.q))
'''


@pytest.fixture
def bad_laws(tmp_path, monkeypatch):
    (tmp_path / "badlaws.py").write_text(textwrap.dedent(BAD))
    (tmp_path / "brokenlaw.py").write_text("import numpy as np\nclass Law(:\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.chdir(tmp_path)
    yield tmp_path
    for mod in ("badlaws", "brokenlaw"):
        sys.modules.pop(mod, None)


@pytest.mark.parametrize("sets, needles", [
    (["controller.kind=nosuch_cosim_law:Zero"],
     ["cannot import module 'nosuch_cosim_law'", "PYTHONPATH"]),
    (["controller.kind=brokenlaw:Law"], ["cannot import module 'brokenlaw'", "SyntaxError"]),
    (["controller.kind=badlaws:Nope"], ["module 'badlaws' has no class 'Nope'"]),
    (["controller.kind=badlaws:Plain"], ["Plain has no compute(obs) method"]),
    (["controller.kind=badlaws:Cruise", "controller.params.gain=0.8"],
     ["badlaws:Cruise", "unexpected keyword argument 'gain'"]),
    (["controller.kind=badlaws:BadShape"],
     ["BadShape.compute returned shape (", ", expected (", "2)"]),
    (["controller.kind=badlaws"], ["not registered", "module.path:ClassName"]),
])
def test_a_bad_user_law_is_one_error_line_and_exit_2(bad_laws, capsys, sets, needles):
    argv = ["run", "default", "--quiet", "--out", "OUT", "--set", "scenario.world=road",
            "--set", "scenario.duration_s=30", *SHORT]
    for item in sets:
        argv += ["--set", item]
    assert main(argv) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    for needle in needles:
        assert needle in lines[0], lines[0]
    assert not (bad_laws / "OUT").exists()  # nothing written
