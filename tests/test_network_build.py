"""Tests of cosim.road: generated networks, the road frame and the cache."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import sumolib

from cosim.errors import ConfigError, NetworkError
from cosim.road import build as nb
from cosim.road.build import build_network
from cosim.road.spec import NetworkSpec

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("netcache")


def _read(path: Path):
    return sumolib.net.readNet(str(path), withInternal=True)


def run_python(code: str, timeout: float = 60.0) -> dict:
    """Run ``code`` in a fresh interpreter (libsumo: one simulation per process).

    The code must print one JSON object as its last line of stdout.
    """
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


# --------------------------------------------------------------------------------------
# Geometry of the built networks
# --------------------------------------------------------------------------------------


def test_straight_road_is_one_wide_lane_of_given_length(cache: Path) -> None:
    net = build_network(NetworkSpec(kind="straight", length_m=200.0, max_edge_length_m=0.0),
                        cache)
    sumo_net = _read(net.net_file)
    edges = sumo_net.getEdges(withInternal=False)
    assert [e.getID() for e in edges] == list(net.main_route) == ["main"]
    lanes = edges[0].getLanes()
    assert len(lanes) == 1
    assert lanes[0].getWidth() == pytest.approx(10.2)
    assert lanes[0].getLength() == pytest.approx(200.0, abs=0.01)
    assert net.length_m == pytest.approx(200.0, abs=0.01)
    right, left = net.edges_at(np.array([0.0, 100.0, 199.0]))
    np.testing.assert_allclose(right, -5.1)
    np.testing.assert_allclose(left, 5.1)
    assert not net.periodic


def test_long_straight_road_is_split_into_edges_no_longer_than_the_maximum(cache: Path) -> None:
    net = build_network(NetworkSpec(kind="straight", length_m=1050.0), cache)  # default 100 m
    sumo_net = _read(net.net_file)
    edges = sumo_net.getEdges(withInternal=False)
    assert len(net.main_route) == 11
    assert {e.getID() for e in edges} == set(net.main_route)
    lengths = [sumo_net.getEdge(e).getLanes()[0].getLength() for e in net.main_route]
    assert max(lengths) <= 100.0 + 0.01
    assert all(len(sumo_net.getEdge(e).getLanes()) == 1 for e in net.main_route)
    assert all(sumo_net.getEdge(e).getLanes()[0].getWidth() == pytest.approx(10.2)
               for e in net.main_route)
    assert net.length_m == pytest.approx(1050.0, abs=0.05)  # joints add no length
    # s is continuous along the route: each edge starts where the previous one ended
    starts = [net.s_of(e, 0.0) for e in net.main_route]
    assert starts[0] == 0.0 and np.all(np.diff(starts) > 90.0)
    with pytest.raises(ConfigError, match="max_edge_length_m"):
        NetworkSpec(kind="straight", max_edge_length_m=-1.0)


def test_ring_edges_follow_the_maximum_edge_length(cache: Path) -> None:
    net = build_network(NetworkSpec(kind="ring", circumference_m=1000.0), cache)
    assert len(net.main_route) == 10
    assert abs(net.length_m - 1000.0) / 1000.0 < 0.01


def test_ring_circumference_within_one_percent(cache: Path) -> None:
    net = build_network(NetworkSpec(kind="ring", circumference_m=300.0), cache)
    assert net.periodic
    assert abs(net.length_m - 300.0) / 300.0 < 0.01
    sumo_net = _read(net.net_file)
    lanes = [ln for e in sumo_net.getEdges(withInternal=True) for ln in e.getLanes()]
    # The loop is every lane of the network, junction lanes included.
    assert sum(ln.getLength() for ln in lanes) == pytest.approx(net.length_m, abs=1e-6)
    assert net.ring_route_edges(net.main_route[2])[0] == net.main_route[2]
    assert sorted(net.ring_route_edges(net.main_route[2])) == sorted(net.main_route)
    assert net.s_of(net.main_route[0], 0.0) == 0.0
    assert net.s_of(net.main_route[0], net.length_m + 5.0) == pytest.approx(5.0)


@pytest.mark.sumo
def test_ring_vehicle_circles_and_s_wraps_continuously(cache: Path, tmp_path: Path) -> None:
    net = build_network(NetworkSpec(kind="ring", circumference_m=300.0), cache)
    rou = tmp_path / "ring.rou.xml"
    rou.write_text(
        "<routes>\n"
        '  <vType id="car" speedDev="0" laneChangeModel="SL2015" latAlignment="arbitrary"/>\n'
        f'  <route id="loop" edges="{" ".join(net.ring_route_edges())}" repeat="20"/>\n'
        '  <vehicle id="v" type="car" route="loop" depart="0" departPos="10" '
        'departSpeed="20" departPosLat="2.0"/>\n'
        "</routes>\n"
    )
    out = run_python(f"""
        import json
        import libsumo as t
        from cosim.road import NetworkSpec, build_network
        net = build_network(NetworkSpec(kind="ring", circumference_m=300.0), {str(cache)!r})
        t.start(["sumo", "-n", str(net.net_file), "-r", {str(rou)!r}, "--no-step-log", "true",
                 "--lateral-resolution", "0.8", "--step-length", "0.1"])
        t.simulationStep()
        s0 = prev = net.s_of(t.vehicle.getLaneID("v"), t.vehicle.getLanePosition("v"))
        d0 = t.vehicle.getDistance("v")
        unwrapped, laps, worst = 0.0, 0, 0.0
        for _ in range(600):
            t.simulationStep()
            s = net.s_of(t.vehicle.getLaneID("v"), t.vehicle.getLanePosition("v"))
            ds = (s - prev) % net.length_m
            laps += s < prev
            worst = max(worst, abs(ds - 0.1 * t.vehicle.getSpeed("v")))
            unwrapped += ds
            prev = s
        print(json.dumps({{"laps": laps, "unwrapped": unwrapped, "worst": worst,
                          "sumo_dist": t.vehicle.getDistance("v") - d0,
                          "lat": t.vehicle.getLateralLanePosition("v"),
                          "alive": "v" in t.vehicle.getIDList()}}))
        t.close()
    """)
    assert out["alive"]
    assert out["laps"] >= 2  # passed s = 0 at least twice
    assert out["worst"] < 1e-6  # s advances by exactly v*dt, across junctions and the wrap
    assert out["unwrapped"] == pytest.approx(out["sumo_dist"], abs=1e-6)


@pytest.mark.sumo
def test_vehicles_cross_the_joints_of_a_split_road_unchanged(cache: Path, tmp_path: Path) -> None:
    """Sublane vehicle on a 600 m road of 100 m edges: s advances by exactly v*dt and the
    lateral offset stays put across every joint."""
    spec = NetworkSpec(kind="straight", length_m=600.0)
    net = build_network(spec, cache)
    rou = tmp_path / "r.rou.xml"
    rou.write_text(
        "<routes>\n"
        '  <vType id="car" speedDev="0" laneChangeModel="SL2015" latAlignment="arbitrary"/>\n'
        f'  <route id="r" edges="{" ".join(net.main_route)}"/>\n'
        '  <vehicle id="v" type="car" route="r" depart="0" departPos="5" '
        'departSpeed="25" departPosLat="3.1"/>\n'
        "</routes>\n"
    )
    out = run_python(f"""
        import json
        import libsumo as t
        from cosim.road import NetworkSpec, build_network
        net = build_network(NetworkSpec(kind="straight", length_m=600.0), {str(cache)!r})
        t.start(["sumo", "-n", str(net.net_file), "-r", {str(rou)!r}, "--no-step-log", "true",
                 "--lateral-resolution", "0.8", "--step-length", "0.1"])
        t.simulationStep()
        t.vehicle.setLaneChangeMode("v", 0)
        prev = net.s_of(t.vehicle.getLaneID("v"), t.vehicle.getLanePosition("v"))
        worst, lat_dev, edges = 0.0, 0.0, set()
        while "v" in t.vehicle.getIDList():
            v = t.vehicle.getSpeed("v")
            t.simulationStep()
            if "v" not in t.vehicle.getIDList():
                break
            lane = t.vehicle.getLaneID("v")
            s = net.s_of(lane, t.vehicle.getLanePosition("v"))
            worst = max(worst, abs(s - prev - 0.1 * t.vehicle.getSpeed("v")))
            d = net.d_of(lane, t.vehicle.getLateralLanePosition("v"))
            lat_dev = max(lat_dev, abs(d - 3.1))
            edges.add(t.vehicle.getRoadID("v"))
            prev = s
        print(json.dumps({{"worst": worst, "lat_dev": lat_dev, "end_s": prev,
                          "n_edges": len([e for e in edges if not e.startswith(":")])}}))
        t.close()
    """)
    assert out["n_edges"] == 6
    assert out["end_s"] > 590.0
    assert out["worst"] < 1e-6
    assert out["lat_dev"] < 1e-6


def test_onramp_offsets_increase_along_the_main_route(cache: Path) -> None:
    """Without an acceleration lane: the ramp's lane joins the road's in the junction."""
    spec = NetworkSpec(kind="onramp", length_m=400.0, merge_position_m=150.0, ramp_length_m=100.0,
                       acceleration_lane_m=0.0, ramp_width_m=0.0)
    net = build_network(spec, cache)
    assert net.main_route == ("main_up", "main_down")
    assert net.ramp_route == ("ramp", "main_down")
    sumo_net = _read(net.net_file)
    via = sumo_net.getLane("main_up_0").getOutgoing()[0].getViaLaneID()
    assert via.startswith(":merge")
    offs = [net.lane_offsets[x] for x in ("main_up_0", via, "main_down_0")]
    assert offs[0] == 0.0 and offs[0] < offs[1] < offs[2]
    assert offs[2] == pytest.approx(offs[1] + sumo_net.getLane(via).getLength())
    assert net.length_m == pytest.approx(400.0, abs=0.05)
    # The ramp's s ends exactly where the main road's downstream lane begins.
    ramp_via = sumo_net.getLane("ramp_0").getOutgoing()[0].getViaLaneID()
    ramp_end = net.s_of(ramp_via, sumo_net.getLane(ramp_via).getLength())
    assert ramp_end == pytest.approx(net.merge_s_m)
    # ramp_length_m is SUMO's length along the ramp (its lane and junction lane) ...
    assert net.ramp_length_m == pytest.approx(
        sumo_net.getLane("ramp_0").getLength() + sumo_net.getLane(ramp_via).getLength())
    assert net.ramp_width_m == pytest.approx(spec.width_m)  # 0: as wide as the road
    # ... while s and d place the ramp in the main road's frame: it starts 100 m x cos 8 deg
    # upstream of the merge node (at 150 m) and its centre lies right of the main road's
    # right edge (-5.1 m) by more than half its width until the junction.
    assert net.lane_offsets["ramp_0"] == pytest.approx(150.0 - 100.0 * np.cos(np.radians(8.0)),
                                                       abs=0.02)
    pos = np.linspace(0.0, sumo_net.getLane("ramp_0").getLength(), 20)
    s, d = net.lane_frame(["ramp_0"] * 20, pos, np.zeros(20))
    assert np.all(np.diff(s) > 0)
    assert np.all(d < -5.1 - 1.7)
    assert d[0] == pytest.approx(-100.0 * np.sin(np.radians(8.0)), abs=0.05)


@pytest.mark.sumo
@pytest.mark.parametrize("acc_m", [0.0, 100.0])
def test_onramp_vehicles_reach_the_end_with_continuous_s(cache: Path, tmp_path: Path,
                                                         acc_m: float) -> None:
    """With and without an acceleration lane (SUMO's driver changes off it)."""
    spec = NetworkSpec(kind="onramp", length_m=400.0, merge_position_m=150.0, ramp_length_m=100.0,
                       acceleration_lane_m=acc_m)
    net = build_network(spec, cache)
    rou = tmp_path / "onramp.rou.xml"
    rou.write_text(
        "<routes>\n"
        '  <vType id="car" laneChangeModel="SL2015" latAlignment="arbitrary"/>\n'
        f'  <route id="main" edges="{" ".join(net.main_route)}"/>\n'
        f'  <route id="ramp" edges="{" ".join(net.ramp_route)}"/>\n'
        '  <vehicle id="m" type="car" route="main" depart="0" departSpeed="max"/>\n'
        '  <vehicle id="r" type="car" route="ramp" depart="0" departSpeed="max"/>\n'
        "</routes>\n"
    )
    out = run_python(f"""
        import json
        import libsumo as t
        from cosim.road import NetworkSpec, build_network
        net = build_network(NetworkSpec(kind="onramp", length_m=400.0, merge_position_m=150.0,
                                        ramp_length_m=100.0, acceleration_lane_m={acc_m}),
                            {str(cache)!r})
        t.start(["sumo", "-n", str(net.net_file), "-r", {str(rou)!r}, "--no-step-log", "true",
                 "--lateral-resolution", "0.8", "--step-length", "0.1"])
        prev, worst, lanes, arrived, last_s = {{}}, {{}}, {{}}, [], {{}}
        for _ in range(600):
            t.simulationStep()
            arrived += t.simulation.getArrivedIDList()
            for v in t.vehicle.getIDList():
                lane = t.vehicle.getLaneID(v)
                lanes.setdefault(v, []).append(lane)
                s = net.s_of(lane, t.vehicle.getLanePosition(v))
                if v in prev:  # s advance per step relative to the distance driven
                    ratio = (s - prev[v]) / max(0.1 * t.vehicle.getSpeed(v), 1e-9)
                    worst.setdefault(v, [1.0, 1.0])
                    worst[v] = [min(worst[v][0], ratio), max(worst[v][1], ratio)]
                prev[v] = last_s[v] = s
        print(json.dumps({{"worst": worst, "arrived": arrived, "last_s": last_s,
                          "lanes": {{v: sorted(set(x)) for v, x in lanes.items()}}}}))
        t.close()
    """)
    assert sorted(out["arrived"]) == ["m", "r"]
    # On the main road s advances by exactly v dt; on the ramp by v dt cos(angle to the main
    # road) (s runs along the main road: 8 deg on the ramp, up to 17 deg on the zipper's
    # junction lane), never backwards, never faster than the vehicle.
    assert out["worst"]["m"] == pytest.approx([1.0, 1.0], abs=1e-6)
    lo, hi = out["worst"]["r"]
    assert np.cos(np.radians(20.0)) < lo and hi < 1.0 + 1e-6
    for v in ("m", "r"):
        assert out["last_s"][v] > net.length_m - 45.0  # last seen near the road's end
        assert "main_down_0" in out["lanes"][v]
        assert any(lane.startswith(":merge") for lane in out["lanes"][v])
    assert "ramp_0" in out["lanes"]["r"]
    if acc_m:
        assert "acc_0" in out["lanes"]["r"] and "acc_1" in out["lanes"]["r"]


def test_acceleration_lane_lies_beside_the_road_in_the_frame(cache: Path) -> None:
    """The acceleration lane (``acc_0``, 3.4 m) is a second lane of edge ``acc`` right of
    the road's lane ``acc_1``, which stays on the reference line (d = 0, as the lanes
    before and after it); the road's right edge steps out by 3.4 m from the merge
    junction's start to the lane's end and back where it ends (the junction after it holds
    only the road's lane); the ramp ends on the acceleration lane, and ``merge_s_m`` is
    where the road is one lane again."""
    spec = NetworkSpec(kind="onramp", length_m=600.0, merge_position_m=200.0,
                       ramp_length_m=100.0, acceleration_lane_m=150.0)
    net = build_network(spec, cache)
    assert net.main_route == ("main_up", "acc", "main_down")
    assert net.ramp_route == ("ramp", "acc", "main_down")
    assert net.n_lanes == 1  # the sublane model stays on
    for lane in ("main_up_0", "acc_1", "main_down_0"):
        assert net.lane_d[lane] == pytest.approx(0.0, abs=1e-9)
    assert net.lane_d["acc_0"] == pytest.approx(-5.1 - 1.7, abs=1e-9)
    assert net.lane_width["acc_0"] == pytest.approx(3.4)
    assert {"acc_0", "acc_1"} <= set(net.main_lanes)
    spans = {e: (a, b) for e, a, b in net.edge_spans}
    up_end, (acc0, acc1), down0 = spans["main_up"][1], spans["acc"], spans["main_down"][0]
    right, left = net.edges_at(np.array([100.0, up_end + 0.01, acc0, 0.5 * (acc0 + acc1),
                                         acc1, 0.5 * (acc1 + down0), down0 + 1.0]))
    assert np.allclose(left, 5.1, atol=0.02)
    assert right[0] == pytest.approx(-5.1, abs=0.02)
    assert np.allclose(right[1:4], -8.5, atol=0.02)  # paved from the junction's start
    assert np.allclose(right[4:], -5.1, atol=0.02)  # the lane ends with its edge
    assert net.merge_s_m == pytest.approx(net.lane_offsets["main_down"])
    s, d = net.lane_frame(["ramp_0"], np.array([net.ramp_length_m]), np.zeros(1))
    assert d[0] < -5.1


def test_locate_inverts_s_of(cache: Path) -> None:
    spec = NetworkSpec(kind="onramp", length_m=400.0, merge_position_m=150.0, ramp_length_m=100.0,
                       acceleration_lane_m=0.0)
    net = build_network(spec, cache)
    (_, a0, a1), (_, b0, b1) = net.edge_spans
    for s in (0.0, 0.5 * (a0 + a1), a1, b0, 0.5 * (b0 + b1), net.length_m):
        edge, pos = net.locate(s)
        assert not edge.startswith(":")
        assert net.s_of(edge, pos) == pytest.approx(s)
    # A position inside the merge junction moves to the start of the downstream edge.
    inside = 0.5 * (net.lane_offsets["main_down"] + net.edge_spans[0][2])
    assert net.locate(inside) == ("main_down", 0.0)
    with pytest.raises(ConfigError, match="outside the road"):
        net.locate(net.length_m + 10.0)


def test_varying_width_edges_have_the_given_widths(cache: Path) -> None:
    profile = ((80.0, 10.2), (40.0, 6.8), (80.0, 8.5))
    net = build_network(NetworkSpec(kind="varying_width", width_profile=profile), cache)
    sumo_net = _read(net.net_file)
    widths = [sumo_net.getEdge(e).getLanes()[0].getWidth() for e in net.main_route]
    assert widths == pytest.approx([w for _, w in profile])
    assert net.length_m == pytest.approx(200.0, abs=0.05)
    mids = [(s0 + s1) / 2 for _, s0, s1 in net.edge_spans]
    right, left = net.edges_at(np.array(mids))
    np.testing.assert_allclose(left, [w / 2 for _, w in profile])
    np.testing.assert_allclose(right, [-w / 2 for _, w in profile])
    assert net.width_m == pytest.approx(10.2)


def test_three_lane_baseline_has_three_conventional_lanes(cache: Path) -> None:
    net = build_network(NetworkSpec(kind="three_lane", length_m=200.0), cache)
    lanes = _read(net.net_file).getEdge("main").getLanes()
    assert [ln.getWidth() for ln in lanes] == pytest.approx([3.4, 3.4, 3.4])
    assert net.n_lanes == 3
    assert [net.lane_d[f"main_{i}"] for i in range(3)] == pytest.approx([-3.4, 0.0, 3.4])
    assert net.d_of("main_2", 0.5) == pytest.approx(3.9)
    assert net.edges_at(np.array([10.0]))[1][0] == pytest.approx(5.1)


# --------------------------------------------------------------------------------------
# Cache
# --------------------------------------------------------------------------------------


def test_second_build_reuses_the_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    spec = NetworkSpec(kind="straight", length_m=150.0)
    calls = []
    real = nb._run_netconvert
    monkeypatch.setattr(nb, "_run_netconvert", lambda *a: (calls.append(a), real(*a)))
    first = build_network(spec, tmp_path)
    mtime = first.net_file.stat().st_mtime_ns
    second = build_network(spec, tmp_path)
    assert len(calls) == 1
    assert second.net_file == first.net_file
    assert second.net_file.stat().st_mtime_ns == mtime
    other = build_network(NetworkSpec(kind="straight", length_m=151.0), tmp_path)
    assert len(calls) == 2 and other.net_file != first.net_file
    # Parameters another kind ignores do not change the hash.
    assert nb.spec_hash(spec) == nb.spec_hash(
        NetworkSpec(kind="straight", length_m=150.0, circumference_m=5.0)
    )


def test_netconvert_failure_gives_one_line(tmp_path: Path) -> None:
    nod, edg = tmp_path / "x.nod.xml", tmp_path / "x.edg.xml"
    nod.write_text('<nodes><node id="a" x="0" y="0"/></nodes>')
    edg.write_text('<edges><edge id="e" from="a" to="missing"/></edges>')
    with pytest.raises(NetworkError) as err:
        nb._run_netconvert(nod, edg, tmp_path / "x.net.xml")
    msg = str(err.value)
    assert "\n" not in msg and "netconvert failed" in msg and "missing" in msg


# --------------------------------------------------------------------------------------
# Validation and user files
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"kind": "straight", "width_m": 0.0}, "width_m"),
        ({"kind": "straight", "length_m": -5.0}, "length_m"),
        ({"kind": "ring", "circumference_m": 0.0}, "circumference_m"),
        ({"kind": "ring", "circumference_m": 40.0}, "circumference_m"),
        ({"kind": "onramp", "merge_position_m": 3000.0}, "merge_position_m"),
        ({"kind": "onramp", "ramp_width_m": -1.0}, "ramp_width_m"),
        ({"kind": "varying_width"}, "width_profile"),
        ({"kind": "varying_width", "width_profile": ((10.0, 0.0),)}, "width_profile"),
        ({"kind": "straight", "speed_limit_mps": float("nan")}, "speed_limit_mps"),
        ({"kind": "motorway"}, "kind"),
        ({"kind": "file"}, "net_file"),
        ({"kind": "file", "net_file": "x.net.xml"}, "route_edges"),
    ],
)
def test_bad_specs_raise_config_error_naming_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field) as err:
        NetworkSpec(**kwargs)
    assert "\n" not in str(err.value)


def test_user_network_file(cache: Path, tmp_path: Path) -> None:
    built = build_network(NetworkSpec(kind="straight", length_m=200.0, width_m=7.0,
                                      max_edge_length_m=0.0), cache)
    mine = tmp_path / "mine.net.xml"
    mine.write_bytes(built.net_file.read_bytes())
    net = build_network(NetworkSpec(kind="file", net_file=str(mine), route_edges=("main",)))
    assert net.net_file == mine.resolve()
    assert net.length_m == pytest.approx(200.0, abs=0.01)
    assert net.width_m == pytest.approx(7.0)
    assert net.speed_limit_mps == pytest.approx(40.0)


def test_user_network_file_errors(tmp_path: Path) -> None:
    corrupt = tmp_path / "corrupt.net.xml"
    corrupt.write_text('<net version="1.20"><edge id="a"><lane id="a_0" ')
    with pytest.raises(NetworkError, match="cannot read network") as err:
        build_network(NetworkSpec(kind="file", net_file=str(corrupt), route_edges=("a",)))
    assert "\n" not in str(err.value)
    with pytest.raises(NetworkError, match="not found"):
        build_network(
            NetworkSpec(kind="file", net_file=str(tmp_path / "no.net.xml"), route_edges=("a",))
        )


def test_user_network_unknown_edge(cache: Path) -> None:
    built = build_network(NetworkSpec(kind="straight", length_m=200.0, max_edge_length_m=0.0),
                          cache)
    with pytest.raises(NetworkError, match="'nowhere'"):
        build_network(
            NetworkSpec(kind="file", net_file=str(built.net_file), route_edges=("main", "nowhere"))
        )
