"""A user's freeway with several on-ramps and off-ramps (netconvert's defaults).

Two on-ramps (each adds a lane that ends at the next junction) and two off-ramps (each
leaves a lane added before it), named ``ramp``, ``ramp2`` and ``off``, ``off2`` in the
order the network lists them; the demand is an OD matrix over them. SUMO runs in its own
process (``tests/sumo_cases/isolated.py``).
"""

from __future__ import annotations

import pytest
from sumo_cases.isolated import run_isolated
from test_corridor import CLEAN, netconvert_defaults, sumo_env

from cosim.config import load_scenario
from cosim.demand.od_names import destination_number, origin_number
from cosim.demand.spec import DemandSpec
from cosim.errors import ConfigError, NetworkError
from cosim.road.spec import NetworkSpec

#: main road a..j (3 lanes of netconvert's default width); ramp r1 joins at b (adds a
#: lane on m2), off-ramp o1 leaves e (from m4's added lane), ramp r2 joins at f (m6),
#: off-ramp o2 leaves i (from m8's added lane)
NODES = """<nodes>
  <node id="a" x="0" y="0"/> <node id="b" x="400" y="0"/> <node id="c" x="650" y="0"/>
  <node id="d" x="950" y="0"/> <node id="e" x="1200" y="0"/> <node id="f" x="1600" y="0"/>
  <node id="g" x="1850" y="0"/> <node id="h" x="2150" y="0"/> <node id="i" x="2400" y="0"/>
  <node id="j" x="2800" y="0"/>
  <node id="r1" x="150" y="-60"/> <node id="o1" x="1400" y="-60"/>
  <node id="r2" x="1350" y="-60"/> <node id="o2" x="2600" y="-60"/>
</nodes>"""
EDGES = """<edges>
  <edge id="m1" from="a" to="b" numLanes="3" speed="33"/>
  <edge id="m2" from="b" to="c" numLanes="4" speed="33"/>
  <edge id="m3" from="c" to="d" numLanes="3" speed="33"/>
  <edge id="m4" from="d" to="e" numLanes="4" speed="33"/>
  <edge id="m5" from="e" to="f" numLanes="3" speed="33"/>
  <edge id="m6" from="f" to="g" numLanes="4" speed="33"/>
  <edge id="m7" from="g" to="h" numLanes="3" speed="33"/>
  <edge id="m8" from="h" to="i" numLanes="4" speed="33"/>
  <edge id="m9" from="i" to="j" numLanes="3" speed="33"/>
  <edge id="in1" from="r1" to="b" numLanes="1" speed="33"/>
  <edge id="in2" from="r2" to="f" numLanes="1" speed="33"/>
  <edge id="out1" from="e" to="o1" numLanes="1" speed="33"/>
  <edge id="out2" from="i" to="o2" numLanes="1" speed="33"/>
</edges>"""
ROUTE = [f"m{k}" for k in range(1, 10)]
RAMPS = [["in1", "m2"], ["in2", "m6"]]
OFFRAMPS = [["out1"], ["out2"]]
#: every pair the road connects (ramp2 joins after the first off-ramp: no ramp2 -> off)
OD = [["main", "main", 2000.0], ["main", "off", 500.0], ["main", "off2", 500.0],
      ["ramp", "main", 300.0], ["ramp", "off", 200.0], ["ramp", "off2", 200.0],
      ["ramp2", "main", 400.0], ["ramp2", "off2", 300.0]]


def _net(tmp_path) -> str:
    return netconvert_defaults(tmp_path, NODES, EDGES)


def _spec(net_file: str, **kw) -> NetworkSpec:
    return NetworkSpec(kind="file", net_file=net_file, route_edges=ROUTE,
                       ramp_edges=kw.get("ramps", RAMPS),
                       offramp_edges=kw.get("offramps", OFFRAMPS))


def test_origin_and_destination_names():
    assert [origin_number(x) for x in ("main", "ramp", "ramp2", "ramp12")] == [0, 1, 2, 12]
    assert [destination_number(x) for x in ("main", "off", "off3")] == [0, 1, 3]
    for bad in ("ramp1", "ramp0", "ramp02", "rampx", "off1", "exit", ""):
        assert origin_number(bad) is None and destination_number(bad) is None
    d = DemandSpec(od_vph=OD)
    assert d.total_vph("ramp2") == 700.0 and d.total_vph() == 4400.0
    with pytest.raises(ConfigError, match="origin must be one of main, ramp, ramp2"):
        DemandSpec(od_vph=[["ramp1", "main", 1.0]])


def test_ramp_lists_are_read_as_one_route_or_several():
    one = NetworkSpec(kind="file", net_file="x.net.xml", route_edges=ROUTE,
                      ramp_edges=["in1", "m2"], offramp_edges=["out1"])
    assert one.ramp_routes() == (("in1", "m2"),) and one.offramp_routes() == (("out1",),)
    two = NetworkSpec(kind="file", net_file="x.net.xml", route_edges=ROUTE,
                      ramp_edges=RAMPS, offramp_edges=OFFRAMPS)
    assert two.ramp_routes() == (("in1", "m2"), ("in2", "m6"))
    with pytest.raises(ConfigError, match="ramp_edges"):
        NetworkSpec(kind="file", net_file="x.net.xml", route_edges=ROUTE,
                    ramp_edges=["in1", ["in2", "m6"]])
    with pytest.raises(ConfigError, match="no edge"):
        NetworkSpec(kind="file", net_file="x.net.xml", route_edges=ROUTE,
                    ramp_edges=[["in1", "m2"], []])


@pytest.mark.sumo
def test_the_frame_finds_every_ramp_its_strip_and_route(tmp_path):
    from cosim.road.build import build_network

    net = build_network(_spec(_net(tmp_path)))
    assert net.origins == ("main", "ramp", "ramp2")
    assert net.destinations == ("main", "off", "off2")
    assert [o.diverge_edge for o in net.offramps] == ["m4", "m8"]
    # each on-ramp joins beside the road (an added lane), each exit leaves an added lane
    entries, exits = net.entry_strips, net.exit_strips
    assert entries.shape == (2, 4) and exits.shape == (2, 4)
    assert abs(entries[0, 0] - 400.0) < 60.0 and abs(entries[1, 0] - 1600.0) < 60.0
    assert abs(exits[0, 1] - 1200.0) < 60.0 and abs(exits[1, 1] - 2400.0) < 60.0
    assert (exits[:, 3] < 0).all() and (entries[:, 3] < 0).all()  # right of the road
    assert net.od_route("ramp2", "off2") == ("in2", "m6", "m7", "m8", "out2")
    assert net.od_route("ramp", "off") == ("in1", "m2", "m3", "m4", "out1")
    assert net.od_route("main", "main") == tuple(ROUTE)
    assert [net.exit_number(d) for d in net.destinations] == [0, 1, 2]
    with pytest.raises(ConfigError, match="leaves the road before"):
        net.od_route("ramp2", "off")
    with pytest.raises(ConfigError, match="no route"):
        net.od_route("ramp3", "main")


@pytest.mark.sumo
def test_ramps_the_frame_cannot_use_are_refused(tmp_path):
    from cosim.road.build import build_network

    path = _net(tmp_path)
    with pytest.raises(NetworkError, match="two off-ramps leave"):
        build_network(_spec(path, offramps=[["out1"], ["out1"]]))
    with pytest.raises(NetworkError, match="must end on a main-route edge"):
        build_network(_spec(path, ramps=[["in1", "m2"], ["in2"]]))
    with pytest.raises(NetworkError, match="not in network"):
        build_network(_spec(path, offramps=[["out1"], ["nowhere"]]))


def several_ramps_summary(net_file: str, share: float) -> dict:
    from cosim.sim.runner import run_scenario

    sc = load_scenario("default", {
        "network.kind": "file", "network.net_file": net_file, "network.route_edges": ROUTE,
        "network.ramp_edges": RAMPS, "network.offramp_edges": OFFRAMPS,
        "demand.od_vph": OD, "demand.cav_share": share, "scenario.duration_s": 200.0,
        "scenario.warmup_s": 30.0, "scenario.interval_s": 30.0,
        "outputs.sumo_collisions": True, "outputs.zone_start_m": 1250.0,
        "outputs.zone_end_m": 1550.0, "outputs.cross_sections_m": [300.0, 1400.0]})
    res = run_scenario(sc)
    row = res.summary.iloc[0].to_dict()
    done = res.trips[res.trips.reached != ""]
    row["reached"] = done.groupby(["destination", "reached"]).size().to_dict()
    return row


@pytest.mark.sumo
@pytest.mark.slow(seconds=30)
@pytest.mark.parametrize("share", [1.0, 0.7])
def test_cavs_reach_each_of_several_exits(share, tmp_path):
    r = run_isolated(several_ramps_summary, _net(tmp_path), share, env=sumo_env(tmp_path))
    for key in CLEAN:
        assert r[key] == 0, (key, r[key], r["reached"])
    assert r["max_standstill_s"] <= 30.0
    # every OD pair carried trips, each to where it was going
    for o, d in [(o, d) for o, d, _ in OD]:
        assert r[f"trips_{o}_{d}"] >= 2, (o, d, r["reached"])
    assert r["reached"].get(("off2", "off2"), 0) >= 10


def test_the_console_summary_lists_every_pairs_travel_time():
    from cosim.cli.run import format_summary

    text = format_summary({"travel_time_main_off2_s": 92.81, "travel_time_ramp2_main_s":
                           float("nan"), "teleports": 0})
    assert "travel time main -> off2" in text and "92.8" in text
    assert "travel time ramp2 -> main" in text and "no trip arrived" in text


def test_n_curves_have_a_panel_per_ramp_and_exit():
    import matplotlib

    matplotlib.use("Agg")
    import pandas as pd

    from cosim.analysis.figures.runs import n_curves_figure

    rows = [("cav.main.0", "cav", "main", "off2", 1.0, float("nan"), 80.0),
            ("hdv.ramp.0", "hdv", "ramp", "main", 2.0, 12.0, float("nan")),
            ("cav.ramp2.0", "cav", "ramp2", "off2", 3.0, 15.0, 40.0),
            ("cav.main.1", "cav", "main", "off", 4.0, float("nan"), 30.0)]
    tr = pd.DataFrame(rows, columns=["vehicle", "kind", "origin", "destination", "depart_s",
                                     "merge_s", "exit_s"])
    fig = n_curves_figure(tr)
    titles = [ax.get_title() for ax in fig.axes]
    assert titles == ["on-ramp merge (ramp)", "on-ramp merge (ramp2)", "off-ramp (off)",
                      "off-ramp (off2)"]


@pytest.mark.sumo
@pytest.mark.parametrize("seed", [1, 4])
def test_a_drawn_user_freeway_has_two_on_ramps_and_two_off_ramps_in_order(seed, tmp_path):
    from cosim.road.frame import load_road_network
    from cosim.road.user_roads import build, draw_freeway

    road = draw_freeway(seed)
    net = load_road_network(build(road, tmp_path), kind="file", main_route=road.route,
                            ramp_routes=road.ramps, offramp_routes=road.offramps)
    assert net.origins == ("main", "ramp", "ramp2")
    assert net.destinations == ("main", "off", "off2")
    entries, exits = net.entry_strips, net.exit_strips
    # along the road: acceleration strip, deceleration strip, acceleration, deceleration
    starts = [entries[0, 0], exits[0, 0], entries[1, 0], exits[1, 0]]
    assert starts == sorted(starts)
    p = road.params
    for i in (0, 1):  # the strips as drawn, give or take what the junctions take and add
        acc = entries[i, 1] - entries[i, 0]
        dec = exits[i, 1] - exits[i, 0]
        assert abs(acc - p[f"acceleration_{i + 1}_m"]) < 60.0
        assert abs(dec - p[f"deceleration_{i + 1}_m"]) < 60.0
        assert 150.0 <= p[f"weaving_{i + 1}_m"] <= 600.0
    assert draw_freeway(seed) == road  # a seed draws the same road
