"""A hostile new user: bad inputs to the ``cosim`` command line and the Python API.

Every bad input below is refused the way the command line promises
(cosim/cli/main.py): exit status 2, exactly one line ``error: ...`` on stderr naming
what is wrong, no traceback, and nothing written: no output folder is left behind
(the case's working folder holds the same files after the command as before).

The cases are data, grouped by the classes of issue 14:

* files that are not text or not what they claim (scenario, sweep, network files);
* output locations (``--out``, ``--replace``, ``--resume``);
* non-finite numbers: NaN in every float of every scenario section, of the default
  law's parameters and of the communication layer (generated from the dataclasses, so
  a new parameter is covered when it is added), +-inf and overflowing literals, and
  every numeric command-line option;
* physically impossible geometry (roads, vehicles, obstacles, user networks);
* time (steps, durations);
* command-line options (workers, Dask, seeds, ``--set``), ``cosim list | head`` and
  ``--gui`` without a display;
* the Python API (the same errors as :class:`~cosim.errors.CosimError` with one line).

Most cases are refused before SUMO starts and run in this process (``cosim.cli.main
.main``); the few that need SUMO, a pipe or another environment run as subprocesses.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import subprocess
import sys
import time
import typing
from dataclasses import dataclass, field
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
COSIM = [sys.executable, "-m", "cosim.cli.main"]
EXAMPLES = REPO / "networks" / "examples"

#: A short valid scenario the cases start from (300 m road, 10 s).
SHORT = ("[scenario]\nduration_s = 10.0\nwarmup_s = 2.0\ninterval_s = 4.0\n"
         "[network]\nlength_m = 300.0\n")
#: A valid sweep (refused only for what a case adds).
SWEEP = ("seeds = [1]\n[sweep]\nname = \"bad\"\n[overrides]\n\"scenario.duration_s\" = 10.0\n"
         "\"scenario.warmup_s\" = 2.0\n\"scenario.interval_s\" = 4.0\n")


@dataclass(frozen=True)
class Case:
    """One bad input: ``cosim ARGV`` run in a folder holding ``files``.

    ``files`` maps a relative path to its content (str, bytes, or ``"@name"`` for a
    network built by the module fixture); ``says`` are fragments the error line holds.
    """

    id: str
    argv: tuple[str, ...]
    files: dict = field(default_factory=dict)
    says: tuple[str, ...] = ()


def case(id: str, *argv: str, files: dict | None = None, says: tuple | str = ()) -> Case:
    return Case(id, tuple(argv), dict(files or {}), (says,) if isinstance(says, str) else says)


def run_short(*extra: str, files: dict | None = None) -> tuple[tuple[str, ...], dict]:
    return ("run", "s.toml", "--quiet", *extra), {"s.toml": SHORT, **(files or {})}


# --------------------------------------------------------------------------------------
# 1. Files that are not text, or not what they claim
# --------------------------------------------------------------------------------------

LATIN1_SCENARIO = "[scenario]\nname = \"caf\xe9\"\n".encode("latin-1")
LATIN1_COMMENT = "# r\xe9seau\n[scenario]\nduration_s = 10.0\n".encode("latin-1")
UTF16 = "[scenario]\nduration_s = 10.0\n".encode("utf-16")
BINARY = bytes(range(256)) * 4


def _file_scenario(net: str, route: str = '["wide", "narrow"]', extra: str = "") -> str:
    return (f"{SHORT.split('[network]')[0]}[network]\nkind = \"file\"\nnet_file = \"{net}\"\n"
            f"route_edges = {route}\n{extra}")


FILES = [
    case("scenario_binary", "run", "s.toml", files={"s.toml": BINARY}, says="not UTF-8"),
    case("scenario_latin1", "run", "s.toml", files={"s.toml": LATIN1_SCENARIO},
         says=("s.toml", "not UTF-8")),
    case("scenario_latin1_comment", "run", "s.toml", files={"s.toml": LATIN1_COMMENT},
         says="not UTF-8"),
    case("scenario_utf16", "run", "s.toml", files={"s.toml": UTF16}, says="not UTF-8"),
    case("scenario_not_toml", "run", "s.toml", files={"s.toml": "[scenario\nx = \n"},
         says="not valid TOML"),
    case("scenario_is_a_folder", "run", "s.toml", files={"s.toml/x": "a"}, says="folder"),
    case("scenario_missing", "run", "missing.toml", says="not found"),
    case("scenario_dangling_link", "run", "link.toml", files={"link.toml": "->nowhere.toml"},
         says="not found"),
    case("config_latin1", "config", "s.toml", files={"s.toml": LATIN1_COMMENT},
         says="not UTF-8"),
    case("config_binary", "config", "s.toml", files={"s.toml": BINARY}, says="not UTF-8"),
    case("sweep_binary", "sweep", "w.toml", files={"w.toml": BINARY}, says="not UTF-8"),
    case("sweep_latin1", "sweep", "w.toml",
         files={"w.toml": ("# caf\xe9\n" + SWEEP).encode("latin-1")}, says="not UTF-8"),
    case("sweep_utf16", "sweep", "w.toml", files={"w.toml": SWEEP.encode("utf-16")},
         says="not UTF-8"),
    case("sweep_not_toml", "sweep", "w.toml", files={"w.toml": "[sweep\n"},
         says="not valid TOML"),
    case("sweep_is_a_folder", "sweep", "w.toml", files={"w.toml/x": "a"}, says="w.toml"),
    case("sweep_base_latin1", "sweep", "w.toml",
         files={"w.toml": SWEEP.replace('name = "bad"', 'name = "bad"\nbase = "b.toml"'),
                "b.toml": LATIN1_COMMENT}, says=("base scenario", "not UTF-8")),
    case("sweep_base_binary", "sweep", "w.toml",
         files={"w.toml": SWEEP.replace('name = "bad"', 'name = "bad"\nbase = "b.toml"'),
                "b.toml": BINARY}, says="not UTF-8"),
    case("net_binary", *run_short()[0][:2],
         files={"s.toml": _file_scenario("n.net.xml"), "n.net.xml": BINARY},
         says="cannot read network"),
    case("net_latin1", "run", "s.toml",
         files={"s.toml": _file_scenario("n.net.xml"), "n.net.xml": "@wc_latin1"},
         says="cannot read network"),
    case("net_truncated", "run", "s.toml",
         files={"s.toml": _file_scenario("n.net.xml"), "n.net.xml": "@wc_truncated"},
         says="cannot read network"),
    case("net_not_a_network", "run", "s.toml",
         files={"s.toml": _file_scenario("n.net.xml"), "n.net.xml": "<foo/>\n"},
         says="no edges"),
    case("net_edge_without_lanes", "run", "s.toml",
         files={"s.toml": _file_scenario("n.net.xml"), "n.net.xml": "@wc_nolane"},
         says="edge 'narrow' has no <lane>"),
    case("net_missing", "run", "s.toml", files={"s.toml": _file_scenario("gone.net.xml")},
         says="not found"),
    case("net_is_a_folder", "run", "s.toml",
         files={"s.toml": _file_scenario("n.net.xml"), "n.net.xml/x": "a"}, says="not found"),
    case("net_route_edge_unknown", "run", "s.toml",
         files={"s.toml": _file_scenario("n.net.xml", '["wide", "nope"]'),
                "n.net.xml": "@wc"}, says="'nope'"),
    case("net_route_not_connected", "run", "s.toml",
         files={"s.toml": _file_scenario("n.net.xml", '["narrow", "wide"]'),
                "n.net.xml": "@wc"}, says="not connected"),
    case("net_lane_backwards", "run", "s.toml",
         files={"s.toml": _file_scenario("n.net.xml"), "n.net.xml": "@wc_backwards"},
         says="narrow_0"),
    case("analyse_missing_folder", "analyse", "nowhere", says="no such folder"),
    case("analyse_a_file", "analyse", "f", files={"f": "x"}, says="results.csv"),
    case("analyse_binary_results", "analyse", "d", files={"d/results.csv": BINARY},
         says="unreadable results table"),
]

# --------------------------------------------------------------------------------------
# 2. Output locations
# --------------------------------------------------------------------------------------

OUTPUTS = [
    case("run_out_is_a_file", *run_short("--out", "f")[0], files={**run_short()[1], "f": "x"},
         says="existing file"),
    case("run_out_under_a_file", *run_short("--out", "f/x")[0],
         files={**run_short()[1], "f": "x"}, says="which is a file"),
    case("run_out_not_empty", *run_short("--out", "o")[0],
         files={**run_short()[1], "o/trajectories.csv": "old run"}, says="--replace"),
    case("run_out_unwritable", *run_short("--out", "/proc/cosim_out")[0], files=run_short()[1],
         says="/proc"),
    case("run_out_broken_link", *run_short("--out", "lnk/x")[0],
         files={**run_short()[1], "lnk": "->missing_dir"}, says="broken symbolic link"),
    case("run_out_empty_string", *run_short("--out", "")[0], files=run_short()[1],
         says="--out"),
    case("run_replace_the_current_folder", *run_short("--out", ".", "--replace")[0],
         files=run_short()[1], says="current folder"),
    case("run_replace_a_checkout", *run_short("--out", "src", "--replace")[0],
         files={**run_short()[1], "src/pyproject.toml": "[project]\n"}, says="source folder"),
    case("run_name_escapes_outputs", *run_short("--set", "scenario.name='../../x'")[0],
         files=run_short()[1], says="scenario.name"),
    case("plane_out_is_a_file", "plane", "seed001", "--out", "f", files={"f": "x"},
         says="existing file"),
    case("plane_out_not_empty", "plane", "seed001", "--out", "o", files={"o/x.csv": "old"},
         says="--replace"),
    case("plane_out_empty_string", "plane", "seed001", "--out", "", says="--out"),
    case("sweep_out_is_a_file", "sweep", "w.toml", "--out", "f",
         files={"w.toml": SWEEP, "f": "x"}, says="existing file"),
    case("sweep_out_under_a_file", "sweep", "w.toml", "--out", "f/x",
         files={"w.toml": SWEEP, "f": "x"}, says="which is a file"),
    case("sweep_out_not_empty", "sweep", "w.toml", "--out", "o",
         files={"w.toml": SWEEP, "o/notes.txt": "mine"}, says="--resume"),
    case("sweep_resume_a_foreign_folder", "sweep", "w.toml", "--out", "o", "--resume",
         files={"w.toml": SWEEP, "o/notes.txt": "mine"}, says="not a sweep folder"),
    case("sweep_resume_and_replace", "sweep", "w.toml", "--out", "o", "--resume", "--replace",
         files={"w.toml": SWEEP}, says="--resume"),
    case("sweep_out_unwritable", "sweep", "w.toml", "--out", "/proc/cosim_sweep",
         files={"w.toml": SWEEP}, says="/proc"),
]

# --------------------------------------------------------------------------------------
# 3. Non-finite numbers: every float of every section, law parameter and option
# --------------------------------------------------------------------------------------


def _bad_literal(default, hint, bad: str) -> str | None:
    """A TOML value for a field of type ``hint`` (default ``default``) whose first float is
    ``bad`` (nan, inf, ...); None if the field holds no float."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        if float in args:
            return bad
        return None
    if hint is float:
        return bad
    if origin is tuple:
        inner = args[0] if args else None
        if args and args[-1] is Ellipsis:
            if typing.get_origin(inner) is tuple:  # rows of floats, e.g. size_classes
                row = list(default[0]) if default else [1.0] * len(typing.get_args(inner))
                return "[[" + ", ".join([bad, *map(repr, map(float, row[1:]))]) + "]]"
            return f"[{bad}]" if inner is float else None
        if all(a is float for a in args):
            return "[" + ", ".join([bad, *map(repr, map(float, list(default)[1:]))]) + "]"
    return None


def _float_paths() -> list[tuple[str, object, object]]:
    """(dotted path, default, type hint) of every float-holding parameter: the sections,
    the default law's parameters and the communication layer."""
    from controllers import registry
    from controllers.comm import CommConfig
    from cosim.config.scenario import SECTIONS
    from cosim.config.sections import ControllerSpec

    out = []
    for name, cls in SECTIONS.items():
        if cls is ControllerSpec:
            continue
        hints = typing.get_type_hints(cls)
        base = cls() if name != "network" else cls(kind="straight")
        for f in dataclasses.fields(cls):
            if f.init:
                out.append((f"{name}.{f.name}", getattr(base, f.name), hints[f.name]))
    entry = registry.entry(ControllerSpec().kind)
    params = entry.params_type()
    hints = typing.get_type_hints(entry.params_type)
    for f in dataclasses.fields(entry.params_type):
        if f.init and f.name not in entry.run_fields:
            out.append((f"controller.params.{f.name}", getattr(params, f.name), hints[f.name]))
    comm = CommConfig()
    hints = typing.get_type_hints(CommConfig)
    for f in dataclasses.fields(CommConfig):
        out.append((f"controller.comm.{f.name}", getattr(comm, f.name), hints[f.name]))
    return [(p, d, h) for p, d, h in out if _bad_literal(d, h, "nan") is not None]


NON_FINITE = [
    case(f"nan_{path}", *run_short("--set", f"{path}={_bad_literal(default, hint, 'nan')}")[0],
         files=run_short()[1], says=path)
    for path, default, hint in _float_paths()
] + [
    case("inf_scenario.duration_s", *run_short("--set", "scenario.duration_s=inf")[0],
         files=run_short()[1], says="scenario.duration_s"),
    case("minus_inf_obstacle.d_m", *run_short("--set", "obstacle.d_m=-inf")[0],
         files=run_short()[1], says="obstacle.d_m"),
    case("inf_network.width_m", *run_short("--set", "network.width_m=inf")[0],
         files=run_short()[1], says="network.width_m"),
    case("inf_demand.inflow_vph", *run_short("--set", "demand.inflow_vph=inf")[0],
         files=run_short()[1], says="demand.inflow_vph"),
    case("inf_size_class_width", *run_short("--set", "demand.size_classes=[[4.5, inf, 1.0]]")[0],
         files=run_short()[1], says="demand.size_classes"),
    case("inf_limits.jerk_max_mps3", *run_short("--set", "limits.jerk_max_mps3=inf")[0],
         files=run_short()[1], says="limits.jerk_max_mps3"),
    case("inf_controller.params.time_gap_s", *run_short(
        "--set", "controller.kind='flocking_timegap'",
        "--set", "controller.params.time_gap_s=inf")[0],
        files=run_short()[1], says="time_gap_s"),
    case("overflow_literal_in_file", "run", "s.toml",
         files={"s.toml": SHORT + "[demand]\ninflow_vph = 1e999\n"}, says="demand.inflow_vph"),
    case("nan_literal_in_file", "run", "s.toml",
         files={"s.toml": SHORT + "[safety]\nmin_gap_m = nan\n"}, says="safety.min_gap_m"),
    case("run_duration_nan", *run_short("--duration", "nan")[0], files=run_short()[1],
         says="duration_s"),
    case("run_duration_inf", *run_short("--duration", "inf")[0], files=run_short()[1],
         says="duration_s"),
    case("run_duration_negative", *run_short("--duration", "-1")[0], files=run_short()[1],
         says="duration_s"),
    case("run_warmup_nan", *run_short("--warmup", "nan")[0], files=run_short()[1],
         says="warmup_s"),
    case("run_warmup_negative", *run_short("--warmup", "-5")[0], files=run_short()[1],
         says="warmup_s"),
    case("plane_saturation_nan", "plane", "seed001", "--saturation", "nan", says="'nan'"),
    case("plane_saturation_inf", "plane", "seed001", "--saturation", "inf", says="'inf'"),
    case("plane_saturation_zero", "plane", "seed001", "--saturation", "0", says="> 0"),
    case("plane_duration_negative", "plane", "seed001", "--duration", "-1", says="> 0"),
    case("plane_duration_nan", "plane", "seed001", "--duration", "nan", says="'nan'"),
    case("sweep_axis_nan", "sweep", "w.toml",
         files={"w.toml": SWEEP + "[axes]\n\"demand.cav_share\" = [0.5, nan]\n"},
         says="demand.cav_share"),
    case("sweep_override_inf", "sweep", "w.toml",
         files={"w.toml": SWEEP.replace("10.0", "inf")}, says="scenario.duration_s"),
    case("analyse_confidence_nan", "analyse", "d", "--confidence", "nan",
         files={"d/results.csv": "run_id,status\na,ok\n"}, says="confidence"),
]

# --------------------------------------------------------------------------------------
# 4. Physically impossible geometry
# --------------------------------------------------------------------------------------

OB = ("--set", "obstacle.length_m=5.0", "--set", "obstacle.width_m=2.0")
GEOMETRY = [
    case("road_narrower_than_the_widest_car", *run_short("--set", "network.width_m=1.5")[0],
         files=run_short()[1], says="narrowest"),
    case("car_wider_than_the_road",
         *run_short("--set", "demand.size_classes=[[4.5, 12.0, 1.0]]")[0],
         files=run_short()[1], says="widest vehicle"),
    case("car_longer_than_the_road",
         *run_short("--set", "demand.size_classes=[[1000.0, 1.8, 1.0]]")[0],
         files=run_short()[1], says="1000 m long vehicle"),
    case("lateral_resolution_wider_than_the_road",
         *run_short("--set", "scenario.lateral_resolution_m=20.0")[0], files=run_short()[1],
         says="lateral_resolution_m"),
    case("sublanes_by_the_hundred_thousand",
         *run_short("--set", "scenario.lateral_resolution_m=0.0001")[0], files=run_short()[1],
         says="sublanes"),
    case("road_a_hundred_km_wide", *run_short("--set", "network.width_m=100000.0")[0],
         files=run_short()[1], says="sublanes"),
    case("road_a_million_km_long", *run_short("--set", "network.length_m=1e9")[0],
         files=run_short()[1], says="1000 km"),
    case("road_of_a_million_edges",
         *run_short("--set", "network.length_m=900000.0", "--set",
                    "network.max_edge_length_m=1.0")[0], files=run_short()[1], says="edges"),
    case("a_billion_vehicles_an_hour", *run_short("--set", "demand.inflow_vph=1e9")[0],
         files=run_short()[1], says="plans"),
    case("obstacle_beyond_the_road_end", *run_short(*OB, "--set", "obstacle.s_m=5000.0")[0],
         files=run_short()[1], says="does not lie on the road"),
    case("obstacle_before_the_road_start", *run_short(*OB, "--set", "obstacle.s_m=1.0")[0],
         files=run_short()[1], says="does not lie on the road"),
    case("obstacle_beside_the_road",
         *run_short(*OB, "--set", "obstacle.s_m=150.0", "--set", "obstacle.d_m=8.0")[0],
         files=run_short()[1], says="outside the road"),
    case("obstacle_wider_than_the_road",
         *run_short("--set", "obstacle.length_m=5.0", "--set", "obstacle.width_m=20.0",
                    "--set", "obstacle.s_m=150.0")[0], files=run_short()[1],
         says="covers the whole road"),
    case("obstacle_on_an_edge_joint", *run_short(*OB, "--set", "obstacle.s_m=200.0")[0],
         files=run_short()[1], says="joint"),
    case("obstacle_after_the_run", *run_short(*OB, "--set", "obstacle.s_m=150.0",
                                              "--set", "obstacle.appear_s=99.0")[0],
         files=run_short()[1], says="obstacle.appear_s"),
    case("obstacle_on_a_user_network_junction", "run", "s.toml",
         files={"s.toml": _file_scenario(
             "n.net.xml", extra="[obstacle]\ns_m = 200.0\nlength_m = 4.0\nwidth_m = 2.0\n"),
             "n.net.xml": "@wc"}, says="junction"),
    case("obstacle_beside_a_user_road", "run", "s.toml",
         files={"s.toml": _file_scenario(
             "n.net.xml", extra="[obstacle]\ns_m = 300.0\nd_m = -3.0\nlength_m = 4.0\n"
                                "width_m = 2.0\n"), "n.net.xml": "@wc"},
         says="outside the road"),
    case("three_lanes_in_five_metres", *run_short("--set", "network.kind='three_lane'",
                                                  "--set", "network.width_m=5.0")[0],
         files=run_short()[1], says="network.width_m"),
    case("ring_too_tight_for_its_width",
         *run_short("--set", "network.kind='ring'", "--set", "network.circumference_m=20.0")[0],
         files=run_short()[1], says="circumference_m"),
    case("ring_denser_than_it_holds", "run", "ring", "--quiet",
         "--set", "demand.ring_density_vpkm=1000.0", "--duration", "10", "--warmup", "2",
         "--set", "scenario.interval_s=4", says="at most"),
    case("merge_beyond_the_road",
         *run_short("--set", "network.kind='onramp'", "--set", "network.merge_position_m=900.0")[0],
         files=run_short()[1], says="merge_position_m"),
    case("ramp_at_right_angles",
         *run_short("--set", "network.kind='onramp'", "--set", "network.ramp_angle_deg=90.0")[0],
         files=run_short()[1], says="ramp_angle_deg"),
    case("segment_narrower_than_the_cars",
         *run_short("--set", "network.kind='varying_width'",
                    "--set", "network.width_profile=[[100.0, 10.2], [100.0, 1.5]]")[0],
         files=run_short()[1], says="narrowest"),
    case("zone_beyond_the_road", *run_short("--set", "outputs.zone_start_m=900.0")[0],
         files=run_short()[1], says="zone_start_m"),
    case("cross_section_beyond_the_road",
         *run_short("--set", "outputs.cross_sections_m=[1e6]")[0], files=run_short()[1],
         says="cross_sections_m"),
    case("zero_width_road", *run_short("--set", "network.width_m=0.0")[0],
         files=run_short()[1], says="network.width_m"),
    case("negative_car_length", *run_short("--set", "demand.size_classes=[[-4.5, 1.8, 1.0]]")[0],
         files=run_short()[1], says="size_classes"),
]

# --------------------------------------------------------------------------------------
# 5. Time
# --------------------------------------------------------------------------------------

TIME = [
    case("step_longer_than_the_run", *run_short("--set", "scenario.step_length_s=50.0")[0],
         files=run_short()[1], says="step_length_s"),
    case("step_below_a_millisecond", *run_short("--set", "scenario.step_length_s=1e-6")[0],
         files=run_short()[1], says="step_length_s"),
    case("step_of_half_a_millisecond", *run_short("--set", "scenario.step_length_s=0.0005")[0],
         files=run_short()[1], says="milliseconds"),
    case("step_not_whole_milliseconds",
         *run_short("--set", "scenario.step_length_s=0.1234")[0], files=run_short()[1],
         says="milliseconds"),
    case("zero_step", *run_short("--set", "scenario.step_length_s=0.0")[0],
         files=run_short()[1], says="step_length_s"),
    case("a_billion_steps", *run_short("--set", "scenario.duration_s=1e308",
                                       "--set", "scenario.interval_s=10.0")[0],
         files=run_short()[1], says="steps"),
    case("zero_duration", *run_short("--duration", "0")[0], files=run_short()[1],
         says="duration_s"),
    case("warmup_as_long_as_the_run", *run_short("--warmup", "10")[0], files=run_short()[1],
         says=("warmup_s", "nothing would be measured")),
    case("warmup_longer_than_the_run", *run_short("--duration", "5")[0],
         files=run_short()[1], says=("warmup_s", "nothing would be measured")),
    case("interval_longer_than_what_is_left",
         *run_short("--set", "scenario.interval_s=9.0")[0], files=run_short()[1],
         says=("interval", "nothing would be measured")),
    case("sublane_width_a_word", *run_short("--set", "scenario.lateral_resolution_m='fine'")[0],
         files=run_short()[1], says=("lateral_resolution_m", "auto")),
    case("interval_shorter_than_a_step", *run_short("--set", "scenario.interval_s=0.01")[0],
         files=run_short()[1], says="interval_s"),
    case("cav_action_step_shorter_than_a_step",
         *run_short("--set", "scenario.cav_action_step_s=0.05")[0], files=run_short()[1],
         says="cav_action_step_s"),
    case("cav_action_step_over_a_second",
         *run_short("--set", "scenario.cav_action_step_s=2.0")[0], files=run_short()[1],
         says="cav_action_step_s"),
    case("negative_interval", *run_short("--set", "scenario.interval_s=-4.0")[0],
         files=run_short()[1], says="interval_s"),
    case("obstacle_appears_at_negative_time",
         *run_short(*OB, "--set", "obstacle.s_m=150.0", "--set", "obstacle.appear_s=-1.0")[0],
         files=run_short()[1], says="obstacle.appear_s"),
    case("standstill_threshold_zero", *run_short("--set", "outputs.long_standstill_s=0.0")[0],
         files=run_short()[1], says="long_standstill_s"),
]

# --------------------------------------------------------------------------------------
# 6. Command-line options
# --------------------------------------------------------------------------------------

CLI = [
    case("workers_zero", "sweep", "w.toml", "--workers", "0", files={"w.toml": SWEEP},
         says="--workers"),
    case("workers_negative", "sweep", "w.toml", "--workers", "-3", files={"w.toml": SWEEP},
         says="--workers"),
    case("workers_not_an_integer", "sweep", "w.toml", "--workers", "1.5",
         files={"w.toml": SWEEP}, says="--workers"),
    case("dask_local_zero", "sweep", "w.toml", "--dask-local", "0", files={"w.toml": SWEEP},
         says="--dask-local"),
    case("dask_local_negative", "sweep", "w.toml", "--dask-local", "-1",
         files={"w.toml": SWEEP}, says="--dask-local"),
    case("scheduler_unreachable", "sweep", "w.toml", "--scheduler", "tcp://127.0.0.1:1",
         files={"w.toml": SWEEP}, says="cannot reach the Dask scheduler"),
    case("scheduler_not_an_address", "sweep", "w.toml", "--scheduler", "garbage",
         files={"w.toml": SWEEP}, says="--scheduler"),
    case("scheduler_blank", "sweep", "w.toml", "--scheduler", " ", files={"w.toml": SWEEP},
         says="--scheduler"),
    case("scheduler_and_dask_local", "sweep", "w.toml", "--scheduler", "tcp://127.0.0.1:1",
         "--dask-local", "2", files={"w.toml": SWEEP}, says="not allowed with"),
    case("workers_on_dask", "sweep", "w.toml", "--workers", "2", "--dask-local", "2",
         files={"w.toml": SWEEP}, says="--workers"),
    case("start_method_unknown", "sweep", "w.toml", "--start-method", "fork",
         files={"w.toml": SWEEP}, says="--start-method"),
    case("sweep_smoke_without_smoke_table", "sweep", "w.toml", "--smoke",
         files={"w.toml": SWEEP}, says="[smoke]"),
    case("sweep_unknown_builtin", "sweep", "no_such_sweep", says="no sweep file"),
    case("sweep_seed_huge", "sweep", "w.toml",
         files={"w.toml": SWEEP.replace("[1]", "[99999999999]")}, says="scenario.seed"),
    case("sweep_seed_fraction", "sweep", "w.toml",
         files={"w.toml": SWEEP.replace("[1]", "[1.5]")}, says="seeds"),
    case("seed_huge", *run_short("--seed", "99999999999999")[0], files=run_short()[1],
         says="scenario.seed"),
    case("seed_negative", *run_short("--seed", "-1")[0], files=run_short()[1],
         says="scenario.seed"),
    case("seed_not_a_number", *run_short("--seed", "abc")[0], files=run_short()[1],
         says="--seed"),
    case("seed_fraction_by_set", *run_short("--set", "scenario.seed=1.5")[0],
         files=run_short()[1], says="scenario.seed"),
    case("plane_seed_huge", "plane", "seed001", "--seed", "999999999999999999999",
         says="--seed"),
    case("plane_unknown", "plane", "seed999", says="seed999"),
    case("plane_saturation_elsewhere", "plane", "seed000", "--saturation", "5.0",
         says="--saturation"),
    case("unknown_subcommand", "fly", says="invalid choice"),
    case("unknown_option", "run", "--fast", says="--fast"),
    case("set_without_equals", *run_short("--set", "demand.cav_share")[0], files=run_short()[1],
         says="KEY=VALUE"),
    case("set_unknown_section", *run_short("--set", "bogus.key=1")[0], files=run_short()[1],
         says="bogus"),
    case("set_unknown_key", *run_short("--set", "scenario.bogus=1")[0], files=run_short()[1],
         says="'bogus'"),
    case("set_empty_value", *run_short("--set", "scenario.duration_s=")[0],
         files=run_short()[1], says="scenario.duration_s"),
    case("set_wrong_type", *run_short("--set", "demand.cav_share='half'")[0],
         files=run_short()[1], says="demand.cav_share"),
    case("set_share_above_one", *run_short("--set", "demand.cav_share=1.5")[0],
         files=run_short()[1], says="demand.cav_share"),
    case("unknown_law", *run_short("--set", "controller.kind='nope'")[0], files=run_short()[1],
         says="nope"),
    case("user_law_not_importable", *run_short("--set", "controller.kind='nosuchmod:Law'")[0],
         files=run_short()[1], says="nosuchmod"),
    case("user_law_not_a_class", *run_short("--set", "controller.kind='os:path'")[0],
         files=run_short()[1], says="os"),
    case("unknown_builtin_scenario", "run", "no_such_scenario", says="no_such_scenario"),
    case("world_unknown", *run_short("--set", "scenario.world='moon'")[0], files=run_short()[1],
         says="scenario.world"),
    case("gui_in_the_road_world", *run_short("--set", "scenario.world='road'", "--gui")[0],
         files=run_short()[1], says="gui"),
]

# Reading results (cosim analyse) and sweep options
# --------------------------------------------------------------------------------------

ANALYSE = [
    case("analyse_latin1_results", "analyse", "d",
         files={"d/results.csv": "run_id,status\ncaf\xe9,ok\n".encode("latin-1")},
         says="results.csv"),
    case("analyse_binary_run_folder", "analyse", "d",
         files={"d/summary.csv": BINARY, "d/trajectories.csv": BINARY}, says="summary.csv"),
    case("analyse_out_is_a_file", "analyse", "d", "--out", "f",
         files={"d/results.csv": "run_id,status\na,ok\n", "f": "x"}, says="existing file"),
    case("analyse_out_empty", "analyse", "d", "--out", "",
         files={"d/results.csv": "run_id,status\na,ok\n"}, says="--out"),
    case("analyse_times_nan", "analyse", "d", "--times", "nan",
         files={"d/results.csv": "run_id,status\na,ok\n"}, says="--times"),
    case("analyse_times_outside_the_run", "analyse", "d", "--times", "1e9",
         files={"d/summary.csv": "a\n1\n", "d/trajectories.csv":
                "t_s,id,s_m,d_m\n0.0,a,1.0,0.0\n1.0,a,2.0,0.0\n"}, says="outside"),
    case("analyse_binary_trajectories", "analyse", "d",
         files={"d/summary.csv": "a\n1\n", "d/trajectories.csv": BINARY},
         says="trajectories.csv"),
    case("analyse_confidence_above_one", "analyse", "d", "--confidence", "2",
         files={"d/results.csv": "run_id,status\na,ok\n"}, says="--confidence"),
    case("analyse_empty_path", "analyse", "", says="empty"),
    case("sweep_out_empty", "sweep", "w.toml", "--out", "", files={"w.toml": SWEEP},
         says="--out"),
    case("sweep_nothing_to_sweep", "sweep", "w.toml", files={"w.toml": ""},
         says="nothing to sweep"),
]

CASES = FILES + OUTPUTS + NON_FINITE + GEOMETRY + TIME + CLI + ANALYSE


def test_the_bad_inputs_number_about_150_and_cover_every_float():
    assert len(CASES) >= 150
    assert len({c.id for c in CASES}) == len(CASES)
    paths = {p for p, _, _ in _float_paths()}
    for must in ("scenario.duration_s", "network.width_profile", "demand.size_classes",
                 "limits.jerk_max_mps3", "safety.edge_margin_m", "obstacle.d_m",
                 "outputs.cross_sections_m", "controller.comm.loss_prob"):
        assert must in paths
    assert any(p.startswith("controller.params.") for p in paths)


# --------------------------------------------------------------------------------------
# The harness
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> dict[str, str | bytes]:
    """Network files for the cases: the width-change example built by netconvert, and
    broken copies of it."""
    from cosim.sumo.binaries import netconvert_binary

    folder = tmp_path_factory.mktemp("bad_input_nets")
    net = folder / "wc.net.xml"
    subprocess.run([str(netconvert_binary()), "-n", str(EXAMPLES / "width_change.nod.xml"),
                    "-e", str(EXAMPLES / "width_change.edg.xml"), "-o", str(net)],
                   check=True, capture_output=True)
    text = net.read_text()
    nolane = re.sub(r'(<edge id="narrow"[^>]*>)\s*<lane[^>]*/>', r"\1", text, count=1)
    assert nolane != text
    back = text.replace('shape="201.50,-3.40 400.00,-3.40"', 'shape="400.00,-3.40 201.50,-3.40"')
    assert back != text
    return {
        "wc": text,
        "wc_nolane": nolane,
        "wc_backwards": back,
        "wc_truncated": text[: len(text) // 2],
        "wc_latin1": text.replace("<net ", "<!-- r\xe9seau --><net ", 1).encode("latin-1"),
    }


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("bad_input_cache")


def _materialise(folder: Path, files: dict, built: dict) -> None:
    for rel, content in files.items():
        p = folder / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, str) and content.startswith("->"):
            p.symlink_to(folder / content[2:])
            continue
        if isinstance(content, str) and content.startswith("@"):
            content = built[content[1:]]
        if isinstance(content, bytes):
            p.write_bytes(content)
        else:
            p.write_text(content)


def _snapshot(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def assert_refused(rc, out: str, err: str, says: tuple = ()) -> str:
    """Exit 2, one ``error:`` line on stderr (naming ``says``), no traceback."""
    lines = [x for x in err.splitlines() if x.strip()]
    assert "Traceback" not in err and "Traceback" not in out, err[-2000:]
    assert rc == 2, (rc, err[-1000:], out[-500:])
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ")
    for frag in says:
        assert frag in lines[0], (frag, lines[0])
    return lines[0]


@pytest.mark.parametrize("c", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_refused_in_one_line_and_leaves_nothing(c: Case, tmp_path, monkeypatch,
                                                             capfd, built, cache):
    from cosim.cli.main import main

    work = tmp_path / "work"
    work.mkdir()
    _materialise(work, c.files, built)
    before = _snapshot(work)
    monkeypatch.chdir(work)
    monkeypatch.setenv("COSIM_NETWORK_CACHE", str(cache))
    capfd.readouterr()
    try:
        rc = main(list(c.argv))
    except SystemExit as exc:  # argparse's own exit
        rc = exc.code
    out, err = capfd.readouterr()
    assert_refused(rc, out, err, c.says)
    assert _snapshot(work) == before, sorted(_snapshot(work) - before)


# --------------------------------------------------------------------------------------
# Cases that need SUMO, a pipe or another environment: subprocesses
# --------------------------------------------------------------------------------------


def _cosim(*argv: str, cwd: Path, env: dict | None = None, timeout: float = 120.0):
    full = {**os.environ, **(env or {})}
    return subprocess.run([*COSIM, *argv], cwd=cwd, env=full, capture_output=True,
                          text=True, timeout=timeout, check=False)


@pytest.mark.sumo
@pytest.mark.parametrize(("argv", "says"), [
    # SUMO refuses the vehicles' speed factors at start
    (("--set", "demand.desired_speed_mps=[1e-9, 1e-9]"), "speedFactor"),
    # SUMO refuses a departure mid-run (a road limited to 1 nm/s)
    (("--set", "network.speed_limit_mps=1e-9"), "SUMO failed"),
], ids=["sumo_refuses_at_start", "sumo_refuses_during_the_run"])
def test_what_only_sumo_finds_is_one_line_too(argv, says, tmp_path, cache):
    (tmp_path / "s.toml").write_text(SHORT)
    before = _snapshot(tmp_path)
    proc = _cosim("run", "s.toml", "--quiet", *argv, cwd=tmp_path,
                  env={"COSIM_NETWORK_CACHE": str(cache)})
    assert_refused(proc.returncode, proc.stdout, proc.stderr, (says,))
    assert _snapshot(tmp_path) == before


def test_cosim_list_into_a_closed_pipe_is_quiet(tmp_path):
    """``cosim list | head -1``: the reader leaves early; no BrokenPipe traceback, exit 0
    (the reader's choice is not an error)."""
    proc = subprocess.run(f"{' '.join(COSIM)} list | head -1; exit ${{PIPESTATUS[0]}}",
                          shell=True, executable="/bin/bash", cwd=tmp_path,
                          capture_output=True, text=True, timeout=60, check=False)
    assert proc.stdout.startswith("built-in scenarios")
    assert proc.stderr == "", proc.stderr
    assert proc.returncode == 0


@pytest.mark.parametrize("display", [None, ":77", "not-a-display"],
                         ids=["unset", "no_server", "malformed"])
def test_gui_without_a_display_is_one_line_within_two_seconds(display, tmp_path):
    (tmp_path / "s.toml").write_text(SHORT)
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    if display is not None:
        env["DISPLAY"] = display
    t0 = time.monotonic()
    proc = subprocess.run([*COSIM, "run", "s.toml", "--gui", "--quiet"], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=60, check=False)
    took = time.monotonic() - t0
    assert_refused(proc.returncode, proc.stdout, proc.stderr, ("display",))
    assert _snapshot(tmp_path) == {"s.toml"}
    assert took < 15.0  # start-up and the scenario included; the check itself: below


@pytest.mark.parametrize("display", [None, ":77", "not-a-display", "127.0.0.1:93"])
def test_the_display_check_answers_within_two_seconds(display, monkeypatch):
    from cosim.errors import SumoStartError
    from cosim.sumo.gui import check_display

    if display is None:
        monkeypatch.delenv("DISPLAY", raising=False)
    else:
        monkeypatch.setenv("DISPLAY", display)
    t0 = time.monotonic()
    with pytest.raises(SumoStartError) as exc:
        check_display()
    assert time.monotonic() - t0 < 2.0
    assert "\n" not in str(exc.value) and "display" in str(exc.value).lower()


# --------------------------------------------------------------------------------------
# The Python API: the same errors, as CosimError with a one-line message
# --------------------------------------------------------------------------------------


def _api_cases():
    from cosim.config.scenario import Scenario, load_scenario, scenario_from_dict
    from cosim.config.sections import ObstacleSpec, OutputSpec, RunSpec
    from cosim.demand.plan import plan_vehicles
    from cosim.demand.spec import DemandSpec
    from cosim.output_dir import check_output_dir, prepare_output_dir
    from cosim.road.frame import load_road_network
    from cosim.road.geometry import road_geometry
    from cosim.road.spec import NetworkSpec
    from cosim.sweeps.plan import load_sweep, sweep_from_dict

    nan, inf = math.nan, math.inf
    ring = road_geometry(NetworkSpec(kind="ring", circumference_m=1000.0))
    return {
        "load_latin1_scenario": lambda tmp: load_scenario(_w(tmp / "a.toml", LATIN1_COMMENT)),
        "load_binary_scenario": lambda tmp: load_scenario(_w(tmp / "a.toml", BINARY)),
        "load_latin1_sweep": lambda tmp: load_sweep(_w(tmp / "w.toml", ("# \xe9\n" + SWEEP)
                                                       .encode("latin-1"))),
        "load_utf16_sweep": lambda tmp: load_sweep(_w(tmp / "w.toml", SWEEP.encode("utf-16"))),
        "scenario_from_dict_nan": lambda tmp: scenario_from_dict(
            {"demand": {"cav_share": nan}}),
        "scenario_from_dict_unknown": lambda tmp: scenario_from_dict({"scenario": {"x": 1}}),
        "demand_sizes_nan": lambda tmp: Scenario(
            demand=DemandSpec(size_classes=((nan, 1.8, 1.0),))),
        "demand_probability_inf": lambda tmp: Scenario(
            demand=DemandSpec(size_classes=((4.5, 1.8, inf),))),
        "run_seed_bool": lambda tmp: RunSpec(seed=True),
        "run_seed_fraction": lambda tmp: RunSpec(seed=1.5),
        "run_step_odd": lambda tmp: RunSpec(step_length_s=0.0005),
        "run_duration_nan": lambda tmp: RunSpec(duration_s=nan),
        "obstacle_nan": lambda tmp: ObstacleSpec(d_m=nan),
        "outputs_inf": lambda tmp: OutputSpec(cross_sections_m=(inf,)),
        "network_width_nan": lambda tmp: NetworkSpec(width_m=nan),
        "sweep_axis_nan": lambda tmp: sweep_from_dict(
            {"seeds": [1], "axes": {"demand.cav_share": [nan]}}),
        "ring_too_dense": lambda tmp: plan_vehicles(
            ring, DemandSpec(ring_density_vpkm=900.0), 1, 60.0),
        "net_edge_without_lanes": lambda tmp: load_road_network(
            _w(tmp / "n.net.xml", _nolane(tmp)), kind="file", main_route=("wide", "narrow")),
        "output_dir_is_a_file": lambda tmp: check_output_dir(_w(tmp / "f", "x")),
        "output_dir_not_empty": lambda tmp: prepare_output_dir(
            _w(tmp / "o" / "x.csv", "old").parent, replace=False, what="output folder"),
        "run_into_a_file": lambda tmp: _run_into(_w(tmp / "f", "x")),
    }


def _run_into(out: Path):
    from cosim.config.scenario import scenario_from_dict
    from cosim.sim.runner import run_scenario

    sc = scenario_from_dict({"scenario": {"duration_s": 0.2, "warmup_s": 0.0, "interval_s": 0.2,
                                          "world": "road"}, "network": {"length_m": 300.0}})
    return run_scenario(sc, out_dir=out)


def _w(path: Path, content) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
    return path


def _nolane(tmp: Path) -> str:
    from cosim.sumo.binaries import netconvert_binary

    net = tmp / "wc.net.xml"
    subprocess.run([str(netconvert_binary()), "-n", str(EXAMPLES / "width_change.nod.xml"),
                    "-e", str(EXAMPLES / "width_change.edg.xml"), "-o", str(net)],
                   check=True, capture_output=True)
    return re.sub(r'(<edge id="narrow"[^>]*>)\s*<lane[^>]*/>', r"\1", net.read_text(), count=1)


API = sorted(_api_cases())


@pytest.mark.parametrize("name", API)
def test_python_api_raises_one_line_cosim_errors(name, tmp_path):
    from cosim.errors import CosimError

    with pytest.raises(CosimError) as exc:
        _api_cases()[name](tmp_path)
    text = str(exc.value)
    assert text and "\n" not in text
