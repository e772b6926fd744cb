"""The freeway corridor: its network, the origin-destination demand, exits reached.

Built corridors and a user's network drawn with netconvert's defaults (an on-ramp that
adds a lane, an off-ramp that leaves from an added lane); SUMO runs in their own
processes (``tests/sumo_cases/isolated.py``).
"""

from __future__ import annotations

import os
import subprocess

import numpy as np
import pytest
from sumo_cases.isolated import run_isolated

from cosim.config import load_scenario
from cosim.demand.spec import DemandSpec
from cosim.errors import ConfigError
from cosim.road.spec import NetworkSpec

SMALL = {"network.length_m": 1700.0, "network.merge_position_m": 300.0,
         "network.acceleration_lane_m": 250.0, "network.diverge_position_m": 1300.0,
         "network.deceleration_lane_m": 250.0, "network.offramp_length_m": 150.0,
         "outputs.zone_start_m": 560.0, "outputs.zone_end_m": 1040.0,
         "outputs.cross_sections_m": [400.0, 800.0, 1500.0]}
OD = [["main", "main", 3000.0], ["main", "off", 800.0], ["ramp", "main", 500.0],
      ["ramp", "off", 300.0]]


def test_corridor_geometry_is_checked():
    with pytest.raises(ConfigError, match="strips overlap"):
        NetworkSpec(kind="corridor", length_m=3500.0, merge_position_m=1000.0,
                    acceleration_lane_m=1200.0, diverge_position_m=2500.0)
    with pytest.raises(ConfigError, match="lanes must be 1 or 3"):
        NetworkSpec(kind="corridor", length_m=3500.0, lanes=2)
    with pytest.raises(ConfigError, match="diverge_position_m"):
        NetworkSpec(kind="corridor", length_m=2510.0, diverge_position_m=2500.0)


@pytest.mark.parametrize("rows, match", [
    ([["main", "exit", 10.0]], "destination one of"),
    ([["side", "main", 10.0]], "origin must be one of"),
    ([["main", "main", -1.0]], "finite number >= 0"),
    ([["main", "main", 1.0], ["main", "main", 2.0]], "twice"),
    ([["main", "main"]], "must be"),
])
def test_bad_od_rows_are_refused(rows, match):
    with pytest.raises(ConfigError, match=match):
        DemandSpec(od_vph=rows)


def test_od_flows_replace_the_inflows():
    d = DemandSpec(inflow_vph=999.0, od_vph=OD)
    assert d.origin_flows() == {"main": {"main": 3000.0, "off": 800.0},
                                "ramp": {"main": 500.0, "off": 300.0}}
    assert d.total_vph() == 4600.0 and d.total_vph("ramp") == 800.0
    plain = DemandSpec(inflow_vph=999.0, ramp_inflow_vph=11.0)
    assert plain.total_vph() == 1010.0


def test_an_exit_the_road_does_not_have_is_refused_before_the_run(tmp_path):
    sc = load_scenario("default", {"demand.od_vph": [["main", "off", 100.0]],
                                   "scenario.world": "road"})
    from cosim.sim.runner import run_scenario

    with pytest.raises(ConfigError, match="off-ramp"):
        run_scenario(sc, out_dir=tmp_path / "run")
    assert not (tmp_path / "run").exists() or not any((tmp_path / "run").iterdir())


@pytest.mark.sumo
def test_corridor_routes_strips_and_destinations(tmp_path):
    from cosim.demand.plan import plan_vehicles
    from cosim.road.build import build_network

    sc = load_scenario("corridor", {**SMALL, "demand.od_vph": OD})
    net = build_network(sc.network, tmp_path)
    assert net.origins == ("main", "ramp") and net.destinations == ("main", "off")
    assert net.od_route("ramp", "off")[0] == "ramp" and net.od_route("ramp", "off")[-1] == \
        "offramp"
    assert net.od_route("main", "main") == net.main_route
    s0, gore, d_r, d_l = net.exit_strips[0]
    assert abs(gore - 1300.0) < 5.0 and 200.0 < gore - s0 <= 250.0
    assert abs(d_l - (-5.1)) < 1e-6 and abs(d_r - (-8.1)) < 1e-6
    e0, e1, *_ = net.entry_strips[0]
    assert abs(e0 - 300.0) < 5.0 and abs(e1 - 550.0) < 5.0
    plan = plan_vehicles(net, sc.demand, 7, 3600.0)
    main = [v for v in plan.vehicles if v.vid.split(".")[1] == "main"]
    share_off = np.mean([v.destination == "off" for v in main])
    assert abs(share_off - 800.0 / 3800.0) < 0.03
    assert {v.route for v in plan.vehicles} == {"main", "main.off", "ramp", "ramp.off"}
    # prefix-stable: a shorter horizon plans the same first vehicles
    short = plan_vehicles(net, sc.demand, 7, 600.0)
    first = {v.vid: v.destination for v in short.vehicles}
    assert all(first[v.vid] == v.destination for v in plan.vehicles if v.vid in first)


def corridor_summary(overrides: dict) -> dict:
    from cosim.sim.runner import run_scenario

    res = run_scenario(load_scenario("corridor", overrides))
    row = res.summary.iloc[0].to_dict()
    row["reached"] = res.trips.groupby(["destination", "reached"]).size().to_dict()
    return row


def sumo_env(tmp_path) -> dict:
    e = dict(os.environ)
    e["COSIM_NETWORK_CACHE"] = str(tmp_path / "nets")
    return e


CLEAN = ("collisions_geometric_cav", "collisions_sumo_cav", "boundary_vehicle_steps_cav",
         "missed_exits_cav", "wrong_exits_cav", "exit_backstop_cav")


@pytest.mark.sumo
@pytest.mark.slow(seconds=25)
@pytest.mark.parametrize("share", [1.0, 0.7])
def test_cavs_reach_their_exits_on_the_corridor(share, tmp_path):
    ov = {**SMALL, "demand.od_vph": OD, "demand.cav_share": share,
          "scenario.duration_s": 150.0, "scenario.warmup_s": 30.0,
          "scenario.interval_s": 30.0, "outputs.sumo_collisions": True}
    r = run_isolated(corridor_summary, ov, env=sumo_env(tmp_path))
    for key in CLEAN:
        assert r[key] == 0, (key, r[key])
    assert r["max_standstill_s"] <= 30.0
    # vehicles arrived at both destinations, each where it was going
    assert r["trips_main_off"] >= 5 and r["trips_ramp_off"] >= 2, r["reached"]
    assert r["trips_main_main"] >= 20 and r["trips_ramp_main"] >= 5
    assert np.isfinite(r["travel_time_main_off_s"])


#: a user's freeway drawn in plain XML and built with netconvert's defaults (3 lanes of its
#: default width; an on-ramp that adds a lane on e2, an off-ramp that leaves e4's added lane)
USER_NODES = """<nodes>
  <node id="a" x="0" y="0"/> <node id="b" x="400" y="0"/> <node id="c" x="650" y="0"/>
  <node id="d" x="950" y="0"/> <node id="e" x="1200" y="0"/> <node id="f" x="1700" y="0"/>
  <node id="r" x="150" y="-60"/> <node id="o" x="1400" y="-60"/>
</nodes>"""
USER_EDGES = """<edges>
  <edge id="e1" from="a" to="b" numLanes="3" speed="33"/>
  <edge id="e2" from="b" to="c" numLanes="4" speed="33"/>
  <edge id="e3" from="c" to="d" numLanes="3" speed="33"/>
  <edge id="e4" from="d" to="e" numLanes="4" speed="33"/>
  <edge id="e5" from="e" to="f" numLanes="3" speed="33"/>
  <edge id="ramp" from="r" to="b" numLanes="1" speed="33"/>
  <edge id="off" from="e" to="o" numLanes="1" speed="33"/>
</edges>"""


def netconvert_defaults(folder, nodes: str, edges: str) -> str:
    """A network built from plain ``nodes`` / ``edges`` XML with netconvert's defaults
    only, as a user builds one; the ``.net.xml`` path."""
    from cosim.sumo.binaries import netconvert_binary

    (folder / "u.nod.xml").write_text(nodes)
    (folder / "u.edg.xml").write_text(edges)
    out = folder / "u.net.xml"
    subprocess.run([str(netconvert_binary()), "-n", str(folder / "u.nod.xml"), "-e",
                    str(folder / "u.edg.xml"), "-o", str(out)], check=True,
                   capture_output=True)
    return str(out)


def _user_net(tmp_path) -> str:
    return netconvert_defaults(tmp_path, USER_NODES, USER_EDGES)


def user_summary(net_file: str, share: float) -> dict:
    from cosim.sim.runner import run_scenario

    sc = load_scenario("default", {
        "network.kind": "file", "network.net_file": net_file,
        "network.route_edges": ["e1", "e2", "e3", "e4", "e5"], "network.ramp_edges":
        ["ramp", "e2"], "network.offramp_edges": ["off"], "demand.od_vph": OD,
        "demand.cav_share": share, "scenario.duration_s": 120.0, "scenario.warmup_s": 30.0,
        "scenario.interval_s": 30.0, "outputs.sumo_collisions": True,
        "outputs.zone_start_m": 100.0, "outputs.zone_end_m": 900.0,
        "outputs.cross_sections_m": [300.0]})
    res = run_scenario(sc)
    return res.summary.iloc[0].to_dict()


@pytest.mark.sumo
@pytest.mark.slow(seconds=15)
def test_cavs_reach_their_exits_on_a_users_network(tmp_path):
    net_file = _user_net(tmp_path)
    r = run_isolated(user_summary, net_file, 1.0, env=sumo_env(tmp_path))
    for key in CLEAN:
        assert r[key] == 0, (key, r[key])
    assert r["trips_main_off"] >= 5 and r["trips_ramp_off"] >= 2
    assert r["trips_main_main"] >= 20


def test_corridor_checks_judge_exits_collisions_and_standstills():
    import pandas as pd

    from experiments.corridor_checks import evaluate

    def run(variant, **cols):
        base = {"variant": variant, "status": "ok", "collisions_sumo_cav": 0,
                "collisions_geometric_cav": 0, "boundary_vehicle_steps_cav": 0,
                "missed_exits_cav": 0, "wrong_exits_cav": 0, "exit_backstop_cav": 0,
                "max_standstill_s": 5.0, "blocked_windows": 0, "edie_flow_vph": 6000.0}
        return {**base, **cols}

    rows = [run("corridor/cav100#1"), run("corridor/cav100#2", missed_exits_cav=1),
            run("corridor/cav40#1", max_standstill_s=90.0),
            run("corridor/cav70#1", max_standstill_s=31.0), run("corridor/sl2015#1")]
    checks, arms = evaluate(pd.DataFrame(rows))
    failed = set(map(tuple, checks[~checks["passed"]][["arm", "check"]].to_numpy()))
    assert failed == {("corridor/cav100", "CAV exits missed, wrong or by the backstop"),
                      ("corridor/cav70", "longest standstill")}
    assert set(checks["arm"]) == {"corridor/cav100", "corridor/cav70", "corridor/cav40"}
    assert arms.set_index("arm").loc["corridor/cav100", "n_runs"] == 2
