"""Scenario configuration and the ``cosim`` command line.

Contract (cosim/cli.py): every user error (bad config, missing or broken network,
SUMO failing) prints exactly one line ``error: ...`` on stderr, exits with status 2 and
shows no traceback. A run writes summary.csv, intervals.csv, meta.json (seed and
versions, SUMO's included) and config.toml, and the same seed gives the same results.

Three ways to run ``cosim``, networks always in the module's temporary cache:

* a subprocess (``python -m cosim.cli.main``, :func:`cosim`): the whole command-line
  path end to end, interpreter start-up and imports included (~2 s each), so only for a
  few cases: a config error, a missing scenario file and the run whose outputs are read;
* this test process (``cosim.cli.main.main``, fixture ``cosim_here``): every error raised
  before SUMO starts, with stdout and stderr captured at the file descriptors as a
  subprocess's pipes would be; SUMO's world is replaced by a tripwire there, since
  libsumo keeps global state and every SUMO simulation needs a process of its own;
* a child forked from a server with cosim loaded (:func:`cosim_forked`,
  ``sumo_cases/isolated.py``): the cases that start SUMO.
"""

from __future__ import annotations

import csv
import importlib.metadata
import json
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path
from types import SimpleNamespace

import pytest
from sumo_cases.cli_output import cosim_cli_output
from sumo_cases.isolated import run_isolated

from cosim.cli.main import main
from cosim.config.builtins import builtin_scenarios
from cosim.config.scenario import Scenario, load_scenario, scenario_from_dict
from cosim.config.toml_write import dumps_toml
from cosim.errors import ConfigError, CosimError
from cosim.road.build import build_network
from cosim.road.spec import NetworkSpec

COSIM = [sys.executable, "-m", "cosim.cli.main"]

TINY = """\
[scenario]
name = "tiny"
duration_s = 30.0
warmup_s = 5.0
interval_s = 10.0

[network]
kind = "straight"
length_m = 300.0

[demand]
inflow_vph = 1800.0
cav_share = 0.5
"""


@pytest.fixture(scope="module")
def cli_env(tmp_path_factory) -> dict:
    env = dict(os.environ)
    env["COSIM_NETWORK_CACHE"] = str(tmp_path_factory.mktemp("network_cache"))
    return env


def cosim(*args, cwd: Path, env: dict, timeout: float = 180.0):
    """``cosim ARGS`` as a subprocess (the console path end to end)."""
    return subprocess.run([*COSIM, *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=env, timeout=timeout, check=False)


def cosim_forked(*args, cwd: Path, env: dict, timeout: float = 180.0) -> SimpleNamespace:
    """``cosim ARGS`` in a process of its own forked from a server with cosim and libsumo
    loaded (for cases that start SUMO); its exit status, stdout and stderr as
    :func:`cosim` gives them."""
    code, out, err = run_isolated(cosim_cli_output, [str(a) for a in args], str(cwd),
                                  env=env, timeout_s=timeout)
    return SimpleNamespace(returncode=code, stdout=out, stderr=err)


class _SumoStarted(AssertionError):
    """Raised in place of SUMO's world in this test process."""


def _no_sumo_here(*_args, **_kwargs):
    raise _SumoStarted("this case starts SUMO: run it in a process of its own "
                       "(cosim_forked), never in the test process")


@pytest.fixture
def cosim_here(tmp_path, monkeypatch, capfd, cli_env):
    """``cosim ARGS`` in this test process, in ``tmp_path`` with the module's network cache
    (cwd and environment restored afterwards): for commands that end before SUMO starts
    (SUMO's world is a tripwire here). Output captured at file descriptors 1 and 2, so
    anything netconvert or a C library prints counts too."""
    import cosim.sumo.world

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("COSIM_NETWORK_CACHE", cli_env["COSIM_NETWORK_CACHE"])
    monkeypatch.setattr(cosim.sumo.world, "SumoWorld", _no_sumo_here)

    def run(*args) -> SimpleNamespace:
        capfd.readouterr()
        try:
            code = main([str(a) for a in args])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
        out, err = capfd.readouterr()
        return SimpleNamespace(returncode=int(code or 0), stdout=out, stderr=err)

    return run


def assert_one_error_line(proc, *fragments: str) -> str:
    err_lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr and "Traceback" not in proc.stdout
    assert len(err_lines) == 1, proc.stderr
    line = err_lines[0]
    assert line.startswith("error: ")
    for frag in fragments:
        assert frag in line, line
    return line


@pytest.fixture(scope="module")
def straight_net_xml(tmp_path_factory) -> str:
    """Text of a valid 300 m straight .net.xml (built by netconvert, no SUMO run)."""
    net = build_network(NetworkSpec(kind="straight", length_m=300.0, max_edge_length_m=0.0),
                        cache_dir=tmp_path_factory.mktemp("nets"))
    return net.net_file.read_text()


def _file_scenario(tmp_path: Path, net_name: str, net_text: str | None) -> Path:
    if net_text is not None:
        (tmp_path / net_name).write_text(net_text)
    toml = tmp_path / "scenario.toml"
    toml.write_text(
        "[scenario]\nduration_s = 5.0\nwarmup_s = 1.0\ninterval_s = 4.0\n"
        f'[network]\nkind = "file"\nnet_file = "{net_name}"\nroute_edges = ["main"]\n'
    )
    return toml


# --------------------------------------------------------------------------------------
# Errors: one line, exit 2, no traceback
# --------------------------------------------------------------------------------------

CONFIG_ERRORS = [
    ("unknown_key", "[scenario]\nbogus = 1\n", ["scenario", "'bogus'"]),
    ("unknown_section", "[bogus]\nx = 1\n", ["[bogus]"]),
    ("wrong_type", '[scenario]\nseed = "x"\n', ["scenario.seed", "integer"]),
    ("negative_width", "[network]\nwidth_m = -3.0\n", ["network.width_m"]),
    ("share_above_one", "[demand]\ncav_share = 1.5\n", ["demand.cav_share", "[0, 1]"]),
    ("bad_toml", "[scenario\nname = 1\n", ["not valid TOML"]),
]

#: the config error also checked end to end, as a subprocess (the others in-process)
END_TO_END_CONFIG_ERROR = "unknown_key"


@pytest.mark.parametrize(("name", "text", "fragments"), CONFIG_ERRORS,
                         ids=[c[0] for c in CONFIG_ERRORS])
def test_config_error_is_one_line_exit_2(tmp_path, cli_env, cosim_here, name, text, fragments):
    (tmp_path / "s.toml").write_text(text)
    args = ("run", "s.toml", "--quiet", "--out", tmp_path / "out")
    if name == END_TO_END_CONFIG_ERROR:
        proc = cosim(*args, cwd=tmp_path, env=cli_env)
    else:
        proc = cosim_here(*args)
    assert_one_error_line(proc, *fragments)
    assert proc.stdout == ""  # rejected before anything ran
    assert not (tmp_path / "out").exists()


def test_missing_network_file(tmp_path, cosim_here):
    toml = _file_scenario(tmp_path, "missing.net.xml", None)
    proc = cosim_here("run", toml, "--quiet", "--out", tmp_path / "out")
    assert_one_error_line(proc, "network file not found", "missing.net.xml")
    assert not (tmp_path / "out").exists()


def test_corrupt_network_file(tmp_path, cosim_here):
    toml = _file_scenario(tmp_path, "corrupt.net.xml", "this is not <xml at all")
    proc = cosim_here("run", toml, "--quiet", "--out", tmp_path / "out")
    assert_one_error_line(proc, "cannot read network", "corrupt.net.xml")
    assert not (tmp_path / "out").exists()


def test_missing_scenario_file_and_unknown_name(tmp_path, cli_env, cosim_here):
    proc = cosim("run", "nowhere.toml", cwd=tmp_path, env=cli_env)  # end to end
    assert_one_error_line(proc, "scenario file not found")
    proc = cosim_here("run", "no_such_builtin")
    assert_one_error_line(proc, "no_such_builtin", "cosim list")


@pytest.mark.sumo
def test_a_negative_lane_speed_is_one_line(tmp_path, cli_env, straight_net_xml):
    """A lane speed of -5 m/s in a user's network: the network check refuses it (the edge's
    speed limit must be > 0 m/s) before SUMO starts; forked, in case it ever got to SUMO."""
    text = straight_net_xml.replace('speed="40.00"', 'speed="-5.00"')
    assert text != straight_net_xml
    toml = _file_scenario(tmp_path, "neg.net.xml", text)
    proc = cosim_forked("run", toml, "--quiet", "--out", tmp_path / "out", cwd=tmp_path,
                        env=cli_env)
    assert_one_error_line(proc, "speed limit")


@pytest.mark.sumo
def test_sumo_refusing_the_network_is_one_line(tmp_path, cli_env, straight_net_xml):
    """Junction elements removed: sumolib reads the file, SUMO refuses it
    ("Unknown from-node 'start' for edge 'main'")."""
    text = "\n".join(ln for ln in straight_net_xml.splitlines() if "<junction " not in ln)
    toml = _file_scenario(tmp_path, "nojunction.net.xml", text)
    proc = cosim_forked("run", toml, "--quiet", "--out", tmp_path / "out", cwd=tmp_path,
                        env=cli_env)
    assert_one_error_line(proc, "start")


def test_zero_lane_speed_network_is_one_line(tmp_path, cosim_here, straight_net_xml):
    text = straight_net_xml.replace('speed="40.00"', 'speed="0.00"')
    toml = _file_scenario(tmp_path, "zero.net.xml", text)
    proc = cosim_here("run", toml, "--quiet", "--out", tmp_path / "out")
    assert_one_error_line(proc, "speed")


@pytest.mark.sumo
def test_scenario_without_traffic_runs(tmp_path, cli_env):
    (tmp_path / "s.toml").write_text(TINY.replace("inflow_vph = 1800.0", "inflow_vph = 0.0"))
    proc = cosim_forked("run", "s.toml", "--quiet", "--out", tmp_path / "out", cwd=tmp_path,
                        env=cli_env)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "out" / "summary.csv").is_file()


@pytest.mark.sumo
def test_measurement_zone_beyond_the_road_is_a_config_error(tmp_path, cosim_here):
    """Refused once the network is built, before SUMO starts."""
    (tmp_path / "s.toml").write_text(TINY + "\n[outputs]\nzone_start_m = 500.0\n")
    proc = cosim_here("run", "s.toml", "--quiet", "--out", tmp_path / "out")
    assert_one_error_line(proc, "zone_start_m")


# --------------------------------------------------------------------------------------
# cosim list
# --------------------------------------------------------------------------------------


def test_cosim_list(cosim_here):
    proc = cosim_here("list")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    names = set(builtin_scenarios())
    assert {"default", "ring", "onramp"} <= names
    listed = {ln.split()[0] for ln in proc.stdout.splitlines() if ln.startswith("  ")}
    assert names <= listed
    assert {"seed000", "seed001"} <= listed


def test_console_script_is_installed(tmp_path, cli_env):
    exe = Path(sys.executable).parent / "cosim"
    if not exe.exists():
        pytest.skip("no cosim console script next to this interpreter")
    proc = subprocess.run([str(exe), "--help"], capture_output=True, text=True, cwd=tmp_path,
                          env=cli_env, timeout=60, check=False)
    assert proc.returncode == 0
    assert "run" in proc.stdout and "list" in proc.stdout


# --------------------------------------------------------------------------------------
# Outputs and reproducibility
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def runs(tmp_path_factory, cli_env) -> dict:
    """The tiny scenario run three times: seed 7 twice, seed 8 once; the first run as a
    subprocess (the console path end to end), the other two forked (SUMO starts in each:
    a process of its own), so the same seed is also compared across the two."""
    root = tmp_path_factory.mktemp("runs")
    (root / "tiny.toml").write_text(TINY)
    out = {}
    for name, seed, run in (("a", 7, cosim), ("b", 7, cosim_forked), ("c", 8, cosim_forked)):
        proc = run("run", "tiny.toml", "--seed", seed, "--quiet", "--out", root / name,
                   cwd=root, env=cli_env)
        assert proc.returncode == 0, proc.stderr
        out[name] = (root / name, proc)
    out["toml"] = root / "tiny.toml"
    return out


def _summary(path: Path) -> dict:
    with open(path / "summary.csv", newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    row.pop("wall_time_s")
    return row


@pytest.mark.sumo
def test_run_writes_its_outputs(runs):
    out, proc = runs["a"]
    for name in ("summary.csv", "intervals.csv", "flock.csv", "collisions.csv",
                 "meta.json", "config.toml", "routes.rou.xml"):
        assert (out / name).is_file(), name
    assert proc.stderr == ""
    assert "outputs written to" in proc.stdout
    assert re.search(r"vehicles inserted\s+\d+", proc.stdout)
    s = _summary(out)
    assert s["seed"] == "7" and s["scenario"] == "tiny"
    assert int(s["vehicles_inserted"]) > 5
    with open(out / "intervals.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    # warm-up 5 s, 10 s intervals, 30 s: [5, 15], [15, 25]; [25, 35] is partial
    assert [(float(r["t_start_s"]), float(r["t_end_s"])) for r in rows] == [(5, 15), (15, 25)]


@pytest.mark.sumo
def test_meta_records_seed_and_versions(runs):
    out, _ = runs["a"]
    meta = json.loads((out / "meta.json").read_text())
    assert meta["seed"] == 7
    assert meta["config"]["scenario"]["seed"] == 7
    v = meta["versions"]
    assert {"cosim", "sumo", "numpy", "pandas", "python"} <= set(v)
    assert v["sumo"] == importlib.metadata.version("eclipse-sumo")
    assert re.fullmatch(r"\d+\.\d+\.\d+.*", v["sumo"])
    assert meta["demand"]["vehicles"] > 0 and meta["demand"]["n_cav"] > 0


@pytest.mark.sumo
def test_written_config_reloads_to_the_same_scenario(runs):
    out, _ = runs["a"]
    again = load_scenario(out / "config.toml")
    assert again == load_scenario(runs["toml"]).with_seed(7)


@pytest.mark.sumo
def test_same_seed_same_results_other_seed_other_results(runs):
    a, b, c = (runs[k][0] for k in "abc")
    assert _summary(a) == _summary(b)
    for name in ("intervals.csv", "collisions.csv", "flock.csv", "routes.rou.xml"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert (a / "routes.rou.xml").read_bytes() != (c / "routes.rou.xml").read_bytes()
    assert _summary(a) != _summary(c)


# --------------------------------------------------------------------------------------
# Config in-process (no subprocess)
# --------------------------------------------------------------------------------------


def test_empty_config_is_the_default_scenario():
    assert scenario_from_dict({}) == Scenario()


@pytest.mark.parametrize(
    ("data", "where"),
    [
        ({"scenario": {"seed": True}}, "scenario.seed"),
        ({"scenario": {"warmup_s": -1.0}}, "scenario.warmup_s"),
        ({"scenario": {"step_length_s": 0.0}}, "scenario.step_length_s"),
        ({"scenario": {"duration_s": float("inf")}}, "scenario.duration_s"),
        ({"network": {"kind": "spiral"}}, "network.kind"),
        ({"network": {"kind": "ring", "circumference_m": 20.0}}, "network.circumference_m"),
        ({"network": {"kind": "file"}}, "network.net_file"),
        ({"demand": {"cav_share": -0.1}}, "demand.cav_share"),
        ({"demand": {"desired_speed_mps": [30.0, 20.0]}}, "demand.desired_speed_mps"),
        ({"demand": {"size_classes": [[4.0, 1.8]]}}, "demand.size_classes"),
        ({"limits": {"emergency_decel_mps2": 2.0}}, "limits.emergency_decel_mps2"),
        ({"safety": {"enabled": "yes"}}, "safety.enabled"),
        ({"obstacle": {"length_m": -1.0}}, "obstacle.length_m"),
        ({"outputs": {"zone_start_m": 500.0, "zone_end_m": 100.0}}, "outputs.zone_end_m"),
        ({"outputs": {"ttc_threshold_s": 0.0}}, "outputs.ttc_threshold_s"),
        ({"controller": {"params": {"zzz": 1.0}}}, "controller.params"),
        ({"controller": {"kind": "magic"}}, "controller.kind"),
    ],
)
def test_config_errors_name_the_offending_key(data, where):
    with pytest.raises(ConfigError) as info:
        scenario_from_dict(data)
    assert where in str(info.value)
    assert "\n" not in str(info.value)
    assert isinstance(info.value, CosimError)


def test_relative_net_file_resolves_against_the_toml(tmp_path):
    sub = tmp_path / "cfg"
    sub.mkdir()
    (sub / "s.toml").write_text(
        '[network]\nkind = "file"\nnet_file = "../nets/road.net.xml"\nroute_edges = ["main"]\n'
    )
    sc = load_scenario(sub / "s.toml")
    assert Path(sc.network.net_file) == (tmp_path / "nets" / "road.net.xml").resolve()


@pytest.mark.parametrize("name", sorted(builtin_scenarios()))
def test_builtin_scenarios_round_trip_through_config_toml(name):
    sc = load_scenario(builtin_scenarios()[name])
    again = scenario_from_dict(tomllib.loads(dumps_toml(sc.to_dict())))
    assert again == sc


def test_an_obstacle_on_an_edge_joint_is_refused_in_one_line():
    """A stopped vehicle across the joint of two 100 m edges makes SUMO report phantom
    collisions: the scenario is refused, naming both ways out."""
    data = {"network": {"kind": "straight", "length_m": 1000.0},
            "obstacle": {"s_m": 500.0, "length_m": 5.0, "width_m": 2.0}}
    with pytest.raises(ConfigError, match="joint") as err:
        scenario_from_dict(data)
    assert "max_edge_length_m" in str(err.value) and "\n" not in str(err.value)
    data["obstacle"]["s_m"] = 550.0
    assert scenario_from_dict(data).obstacle.s_m == 550.0
    data["obstacle"]["s_m"] = 500.0
    data["network"]["max_edge_length_m"] = 0.0  # one edge: no joint
    assert scenario_from_dict(data).network.joints_m() == ()
