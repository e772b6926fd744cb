"""``pip install .`` (not editable), then ``cosim run`` from an unrelated folder.

The repository's files (what git would hold: no ``.venv``, build or cache folders) are
copied to a temporary folder, built into a wheel offline
(``pip wheel --no-deps --no-build-isolation --no-index``: the venv's setuptools builds
it, so setuptools >= 70.1 or the ``wheel`` package must be installed, as the ``dev``
extra should bring) and installed with ``pip install --no-deps --target SITE``. The
test's own interpreter (the .venv, which supplies numpy, pandas and SUMO) then runs
from another temporary folder with ``PYTHONPATH=SITE``.

The editable install of the checkout does not shadow SITE: setuptools' editable finder
sits at the end of ``sys.meta_path``, after the path finder that searches PYTHONPATH,
so ``cosim`` is imported from SITE; the test asserts it (``cosim.__file__``) rather
than relying on it. Built-in scenario and sweep names resolve from the installed
package data (``importlib.resources``), and a run needs no network.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]
#: Not part of the package's source: never copied into the build.
IGNORE = shutil.ignore_patterns(".git", ".venv", "build", "dist", "outputs", "*.egg-info",
                                "__pycache__", ".pytest_cache", ".ruff_cache", "cache")


def _pip(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pip", *args, "--no-input",
                           "--disable-pip-version-check"], cwd=cwd, capture_output=True,
                          text=True, timeout=600, check=False)


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> dict:
    """Build and install the package; returns the folders and the environment to use."""
    root = tmp_path_factory.mktemp("install")
    src, wheels, site = root / "src", root / "wheels", root / "site"
    shutil.copytree(REPO, src, ignore=IGNORE)
    proc = _pip("wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w", str(wheels),
                str(src), cwd=root)
    assert proc.returncode == 0, (
        "building the wheel offline failed; the venv needs setuptools >= 70.1 (or the "
        f"'wheel' package) from the dev extra:\n{proc.stderr[-3000:]}")
    wheel = sorted(wheels.glob("lanefree_cosim-*.whl"))
    assert len(wheel) == 1, list(wheels.iterdir())
    proc = _pip("install", "--no-deps", "--no-index", "--target", str(site), str(wheel[0]),
                cwd=root)
    assert proc.returncode == 0, proc.stderr[-3000:]
    elsewhere = root / "elsewhere"
    elsewhere.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["PYTHONPATH"] = str(site)
    env["COSIM_NETWORK_CACHE"] = str(root / "network_cache")
    return {"site": site, "cwd": elsewhere, "env": env, "wheel": wheel[0]}


def _python(installed: dict, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], cwd=installed["cwd"], env=installed["env"],
                          capture_output=True, text=True, timeout=300, check=False)


PROBE = """
import json
import controllers, cosim, experiments, networks
from cosim.config.builtins import builtin_scenarios, builtin_sweeps
from cosim.config.scenario import load_scenario
from cosim.sweeps.plan import load_sweep
sc = load_scenario("formation")
plan = load_sweep("ring_fd_quick", smoke=True)
print(json.dumps({
    "files": [m.__file__ for m in (cosim, controllers, experiments, networks)],
    "scenarios": {k: str(v) for k, v in builtin_scenarios().items()},
    "sweeps": {k: str(v) for k, v in builtin_sweeps().items()},
    "formation_kind": sc.controller.kind,
    "sweep_source": str(plan.source), "sweep_points": len(plan.points),
}))
"""


def test_the_package_and_its_data_come_from_the_install(installed):
    proc = _python(installed, "-c", PROBE)
    assert proc.returncode == 0, proc.stderr[-3000:]
    info = json.loads(proc.stdout.strip().splitlines()[-1])
    site = str(installed["site"])
    for f in info["files"]:
        assert f.startswith(site + os.sep), f"{f} is not from the installed package"
    for name in ("default", "ring", "formation", "obstacle"):
        assert info["scenarios"][name].startswith(site), info["scenarios"]
    for name in ("ring_fd", "ring_fd_quick", "open_road_capacity"):
        assert info["sweeps"][name].startswith(site), info["sweeps"]
    assert info["formation_kind"] == "formation"
    assert info["sweep_source"].startswith(site) and info["sweep_points"] >= 1
    # package data only: no network cache, no tests, no examples in the install
    assert not (installed["site"] / "networks" / "cache").exists()
    assert not (installed["site"] / "tests").exists()
    assert not (installed["site"] / "examples").exists()


@pytest.mark.slow(seconds=3)
def test_cosim_run_from_an_unrelated_folder(installed):
    # The installed copy's numba kernels have no cache yet (it lives next to the sources):
    # compiling them would cost this test some 15 s. They run as plain Python here
    # (NUMBA_DISABLE_JIT); every other test runs them compiled, from the checkout.
    env = {**installed["env"], "NUMBA_DISABLE_JIT": "1"}
    proc = subprocess.run([sys.executable, "-m", "cosim", "run", "default", "--set",
                           "scenario.duration_s=10", "--set", "scenario.world=road", "--set",
                           "scenario.warmup_s=2", "--set", "scenario.interval_s=5", "--quiet",
                           "--out", "OUT"], cwd=installed["cwd"], env=env,
                          capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = installed["cwd"] / "OUT"
    s = pd.read_csv(out / "summary.csv").iloc[0]
    assert s["scenario"] == "default" and s["vehicles_inserted"] > 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["world"] == "road" and meta["config"]["scenario"]["duration_s"] == 10.0
    assert sorted(p.name for p in installed["cwd"].iterdir()) == ["OUT"]  # nothing else


def test_the_cosim_command_of_the_install_lists_the_builtins(installed):
    script = installed["site"] / "bin" / "cosim"
    assert script.is_file()
    proc = subprocess.run([sys.executable, str(script), "list"], cwd=installed["cwd"],
                          env=installed["env"], capture_output=True, text=True, timeout=120,
                          check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for name in ("default", "ring", "formation", "ring_fd_quick", "boundary_points"):
        assert name in proc.stdout
