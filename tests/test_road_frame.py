"""The road frame on user networks: (lane, lane position, lateral position) <-> (s, d) in
SUMO's lane coordinates on the main route, the projection onto the reference line off it
(cosim/road/frame.py).

The example networks are the plain-XML sources in networks/examples/, built here with
netconvert's defaults (lanes hang to the right of the drawn edge, so after a width change
the narrow lane is not centred on the wide one as drawn; in SUMO's lane coordinates, which
carry a vehicle's lateral position across the joint, it is):

* width_change: 10.2 m narrowing to 6.8 m on a straight road;
* curve: a 90 degree bend of radius 120 m drawn as two arcs, straight approaches;
* multi_edge: five edges with kinks of +6 and -10 degrees and widths 10.2 / 8.5 m;
* the built-in on-ramp (a 3.4 m ramp at 8 degrees joining a 10.2 m road at a zipper).

The SUMO checks run each network in its own process (libsumo: one simulation per
process; ``tests/sumo_cases/road_frame_case.py``, forked by ``sumo_cases/isolated.py``):
every vehicle, every step, SUMO's own x, y (``vehicle.getPosition``) against our (s, d)
mapped back to x, y (``RoadNetwork.xy_of``); a third of the vehicles are moved across the
road by commands in the road frame (``lateral_lane_position`` at the position they reach
in the step), and the d they reach is compared with the command.
"""

from __future__ import annotations

import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import NetworkError
from cosim.road.frame import load_road_network

REPO = Path(__file__).resolve().parents[1]

EXAMPLES = REPO / "networks" / "examples"
ROUTES = {
    "width_change": ("wide", "narrow"),
    "curve": ("in", "bend1", "bend2", "out"),
    "multi_edge": ("e0", "e1", "e2", "e3", "e4"),
}
#: Agreement asked of the frame with SUMO's x, y, m.
TOL_M = 0.05


def build_example(name: str, folder: Path, edg_text: str | None = None) -> Path:
    """netconvert (defaults) on networks/examples/NAME.{nod,edg}.xml -> FOLDER/NAME.net.xml."""
    from cosim.sumo.binaries import netconvert_binary

    folder.mkdir(parents=True, exist_ok=True)
    edg = EXAMPLES / f"{name}.edg.xml"
    if edg_text is not None:
        edg = folder / f"{name}.edg.xml"
        edg.write_text(edg_text)
    out = folder / f"{name}.net.xml"
    proc = subprocess.run(
        [str(netconvert_binary()), "-n", str(EXAMPLES / f"{name}.nod.xml"), "-e", str(edg),
         "-o", str(out)], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.fixture(scope="module")
def nets(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("example_nets")
    return {name: build_example(name, folder) for name in ROUTES}


def frame(nets, name):
    return load_road_network(nets[name], kind="file", main_route=ROUTES[name])


# --------------------------------------------------------------------------------------
# The frame's geometry (no SUMO run)
# --------------------------------------------------------------------------------------


def test_example_sources_are_package_data_and_documented():
    names = sorted(p.name for p in EXAMPLES.glob("*.xml"))
    assert names == sorted(f"{n}.{k}.xml" for n in ROUTES for k in ("nod", "edg"))
    readme = (REPO / "networks" / "README.md").read_text()
    for name in ROUTES:
        assert f"examples/{name}" in readme


def test_width_change_is_framed_in_sumos_lane_coordinates(nets):
    """netconvert's default hangs both lanes from the drawn line (their left border), so the
    narrow lane's centre lies 1.7 m left of the wide lane's as drawn. SUMO carries a
    vehicle's lateral lane position across the joint unchanged (its collision check and
    its drivers compare lateral lane positions as if the centres lined up), so the frame
    does too: d is the lateral lane position on every lane, the road is +-5.1 m, then
    +-3.4 m from where the junction lane (as wide as the narrow lane) starts, and s runs
    on by SUMO's lane lengths."""
    net = frame(nets, "width_change")
    assert net.lane_d["wide_0"] == pytest.approx(0.0, abs=1e-9)
    assert net.lane_d["narrow_0"] == pytest.approx(0.0, abs=1e-9)
    assert net.width_m == pytest.approx(10.2)
    (_, w0, w1), (_, n0, n1) = net.edge_spans
    s = np.linspace(0.0, net.length_m, 4001)
    right, left = net.edges_at(s)
    np.testing.assert_allclose(left[s < w1], 5.1, atol=1e-9)
    np.testing.assert_allclose(right[s < w1], -5.1, atol=1e-9)
    np.testing.assert_allclose(left[s > w1 + 1e-6], 3.4, atol=1e-9)
    np.testing.assert_allclose(right[s > w1 + 1e-6], -3.4, atol=1e-9)
    assert len(net.profile().s0) == 2
    # s as SUMO measures it: lane lengths plus the junction lane
    sumo_len = 198.5 + 3.58 + 198.5
    assert net.length_m == pytest.approx(sumo_len, abs=0.02)
    lanes = ["wide_0", ":b_0_0", "narrow_0"]
    s, d = net.lane_frame(lanes, np.array([10.0, 1.0, 10.0]), np.array([0.5, -1.0, 2.0]))
    np.testing.assert_allclose(d, [0.5, -1.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(s, [10.0, w1 + 1.0, n0 + 10.0], atol=1e-9)


def test_curve_frame_is_the_lane_centre_line(nets):
    """One lane, 10.2 m, through a 90 degree bend: the reference line is the lane's centre
    line (junction lanes included), so d is SUMO's lateral position and s advances by
    lane metres, and the road is +-5.1 m everywhere."""
    net = frame(nets, "curve")
    lanes = [f"{e}_0" for e in ROUTES["curve"]]
    rng = np.random.default_rng(3)
    lane = [lanes[i] for i in rng.integers(0, 4, 500)]
    pos = rng.uniform(0.0, 90.0, 500)
    lat = rng.uniform(-5.0, 5.0, 500)
    s, d = net.lane_frame(lane, pos, lat)
    np.testing.assert_allclose(d, lat, atol=1e-9)
    offs = np.array([net.lane_offsets[x] for x in lane])
    np.testing.assert_allclose(s, offs + pos, atol=1e-6)
    right, left = net.edges_at(np.linspace(0.0, net.length_m, 500))
    np.testing.assert_allclose(right, -5.1, atol=1e-3)
    np.testing.assert_allclose(left, 5.1, atol=1e-3)
    spans = [x[1:] for x in net.edge_spans]
    assert all(a1 <= b0 for (_, a1), (b0, _) in zip(spans, spans[1:], strict=False))


def test_multi_edge_frame(nets):
    """Kinks and width changes: every lane in SUMO's lane coordinates (d = lateral lane
    position: the 8.5 m edges are +-4.25 m wide), s increases edge after edge."""
    net = frame(nets, "multi_edge")
    for e in ("e0", "e1", "e2", "e3", "e4"):
        assert net.lane_d[f"{e}_0"] == pytest.approx(0.0, abs=1e-9)
    starts = [s0 for _, s0, _ in net.edge_spans]
    assert starts == sorted(starts)
    for _, s0, s1 in net.edge_spans:
        right, left = net.edges_at(np.array([0.5 * (s0 + s1)]))
        assert left[0] in (pytest.approx(5.1, abs=1e-9), pytest.approx(4.25, abs=1e-9))
        assert right[0] == pytest.approx(-left[0], abs=1e-9)


@pytest.mark.parametrize("name", list(ROUTES))
def test_inverse_mapping_round_trips(nets, name):
    """lateral_lane_position inverts lane_frame at a fixed position (every lane of the
    routes, junction lanes included), and xy_of(lane_frame) is sumolib's own position of
    the lane point (SUMO's geometryPositionAtOffset: shape scaled to the lane's length,
    offset along the segment's normal)."""
    import sumolib

    net = frame(nets, name)
    sn = sumolib.net.readNet(str(nets[name]), withInternal=True)
    lanes = [x for x in net.lane_d]
    rng = np.random.default_rng(7)
    lane = [lanes[i] for i in rng.integers(0, len(lanes), 400)]
    length = np.array([sn.getLane(x).getLength() for x in lane])
    pos = rng.uniform(0.0, 1.0, 400) * length
    lat = rng.uniform(-3.0, 3.0, 400)
    s, d = net.lane_frame(lane, pos, lat)
    back = net.lateral_lane_position(lane, pos, d)
    # exact where a segment of the reference line holds the point's foot; in the outer
    # corner of a bend of the line (the multi-edge route's smoothed junctions: 0.2 degrees
    # per point) the two directions pick neighbouring segments: d x 0.2 degrees apart
    np.testing.assert_allclose(back, lat, atol=1e-9 if name != "multi_edge" else 1e-3)
    ours = net.xy_of(s, d)
    ref = np.array([_sumolib_xy(sn.getLane(x), p, la) for x, p, la in zip(lane, pos, lat,
                                                                            strict=True)])
    err = np.hypot(*(ours - ref).T)
    assert err.max() < TOL_M, (err.max(), lane[int(np.argmax(err))])


def _sumolib_xy(lane, pos: float, lat: float) -> tuple[float, float]:
    """SUMO's point of (pos, lat) on a lane, with sumolib's geometry helpers."""
    from sumolib import geomhelper

    shape = lane.getShape()
    geo = geomhelper.polyLength(shape)
    g = pos * geo / lane.getLength()
    x, y = geomhelper.positionAtShapeOffset(shape, g)
    seen = 0.0
    for a, b in zip(shape, shape[1:], strict=False):
        seg = math.dist(a, b)
        if seen + seg >= g or b == shape[-1]:
            nx, ny = -(b[1] - a[1]) / seg, (b[0] - a[0]) / seg
            return x + lat * nx, y + lat * ny
        seen += seg
    raise AssertionError("unreachable")


def test_generated_networks_keep_s_offset_plus_pos_and_d_lat(tmp_path):
    """On the networks cosim builds (every edge centred) nothing changes: s = offset +
    lane position and d = lateral lane position, on the ring across its seam too."""
    from cosim.road.build import build_network
    from cosim.road.spec import NetworkSpec

    rng = np.random.default_rng(1)
    for spec in (NetworkSpec(kind="ring", circumference_m=500.0),
                 NetworkSpec(kind="straight", length_m=600.0),
                 NetworkSpec(kind="varying_width", width_profile=((100.0, 10.2), (80.0, 6.8)))):
        net = build_network(spec, tmp_path)
        lanes = [f"{e}_0" for e in net.main_route]
        lane = [lanes[i] for i in rng.integers(0, len(lanes), 300)]
        pos = rng.uniform(0.0, 40.0, 300)
        lat = rng.uniform(-3.0, 3.0, 300)
        s, d = net.lane_frame(lane, pos, lat)
        want = np.array([net.lane_offsets[x] for x in lane]) + pos
        if net.periodic:
            want = np.mod(want, net.length_m)
        np.testing.assert_allclose(s, want, atol=1e-6)
        np.testing.assert_allclose(d, lat, atol=1e-9)
        # off the routes: no s, d is the lateral position
        s2, d2 = net.lane_frame(["nowhere_0"], np.array([1.0]), np.array([0.4]))
        assert np.isnan(s2[0]) and d2[0] == 0.4


# --------------------------------------------------------------------------------------
# What the frame refuses
# --------------------------------------------------------------------------------------


def _edited(nets, name: str, tmp_path: Path, old: str, new: str) -> Path:
    text = nets[name].read_text()
    assert old in text
    out = tmp_path / f"{name}_edited.net.xml"
    out.write_text(text.replace(old, new, 1))
    return out


def test_refuses_a_lane_that_runs_backwards(nets, tmp_path):
    path = _edited(nets, "width_change", tmp_path, 'shape="201.50,-3.40 400.00,-3.40"',
                   'shape="400.00,-3.40 201.50,-3.40"')
    with pytest.raises(NetworkError, match="narrow_0.*(backwards|degrees)") as exc:
        load_road_network(path, kind="file", main_route=ROUTES["width_change"])
    assert "\n" not in str(exc.value)


def test_refuses_lanes_that_cross(tmp_path):
    edg = ('<edges>\n  <edge id="wide" from="a" to="b" numLanes="2" width="3.40" speed="30"/>\n'
           '  <edge id="narrow" from="b" to="c" numLanes="2" width="3.40" speed="30"/>\n'
           '</edges>\n')
    path = build_example("width_change", tmp_path, edg_text=edg)
    text = path.read_text()
    import re

    l0 = re.search(r'(<lane id="narrow_0"[^>]*shape=")([^"]*)"', text)
    l1 = re.search(r'(<lane id="narrow_1"[^>]*shape=")([^"]*)"', text)
    a, b = l0.group(2).split(), l1.group(2).split()
    # narrow_0 runs from the right to the left of narrow_1: the two lanes cross
    text = text.replace(l0.group(0), f'{l0.group(1)}{a[0]} {b[1]}"')
    text = text.replace(l1.group(0), f'{l1.group(1)}{b[0]} {a[1]}"')
    path.write_text(text)
    with pytest.raises(NetworkError, match="cross"):
        load_road_network(path, kind="file", main_route=ROUTES["width_change"])


def test_refuses_a_ramp_at_right_angles(tmp_path):
    nod = ('<nodes>\n  <node id="a" x="0" y="0" type="priority"/>\n'
           '  <node id="b" x="200" y="0" type="priority"/>\n'
           '  <node id="c" x="400" y="0" type="priority"/>\n'
           '  <node id="r" x="200" y="-150" type="priority"/>\n</nodes>\n')
    edg = ('<edges>\n  <edge id="up" from="a" to="b" numLanes="1" width="10.2" speed="30"/>\n'
           '  <edge id="down" from="b" to="c" numLanes="1" width="10.2" speed="30"/>\n'
           '  <edge id="side" from="r" to="b" numLanes="1" width="3.4" speed="30"/>\n'
           '</edges>\n')
    (tmp_path / "t.nod.xml").write_text(nod)
    (tmp_path / "t.edg.xml").write_text(edg)
    from cosim.sumo.binaries import netconvert_binary

    subprocess.run([str(netconvert_binary()), "-n", str(tmp_path / "t.nod.xml"), "-e",
                    str(tmp_path / "t.edg.xml"), "-o", str(tmp_path / "t.net.xml")],
                   check=True, capture_output=True)
    with pytest.raises(NetworkError, match="side_0.*degrees"):
        load_road_network(tmp_path / "t.net.xml", kind="file", main_route=("up", "down"),
                          ramp_routes=[("side", "down")])
    # the same network without the ramp is fine
    net = load_road_network(tmp_path / "t.net.xml", kind="file", main_route=("up", "down"))
    assert net.length_m > 390.0


def test_refuses_route_edges_that_do_not_connect_or_repeat(nets):
    with pytest.raises(NetworkError, match="not connected"):
        load_road_network(nets["multi_edge"], kind="file", main_route=("e0", "e2"))
    with pytest.raises(NetworkError, match="twice"):
        load_road_network(nets["multi_edge"], kind="file", main_route=("e0", "e1", "e0"))


def test_an_edge_without_lanes_is_named(nets, tmp_path):
    import re

    text = nets["width_change"].read_text()
    text = re.sub(r'(<edge id="narrow"[^>]*>)\s*<lane[^>]*/>', r"\1", text, count=1)
    path = tmp_path / "nolane.net.xml"
    path.write_text(text)
    with pytest.raises(NetworkError, match="edge 'narrow' has no <lane>"):
        load_road_network(path, kind="file", main_route=ROUTES["width_change"])


# --------------------------------------------------------------------------------------
# Against SUMO (one process per network)
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sumo_env(tmp_path_factory) -> dict:
    env = dict(os.environ)
    env["COSIM_NETWORK_CACHE"] = str(tmp_path_factory.mktemp("network_cache"))
    return env


def _case(name: str, env: dict, folder: Path) -> dict:
    """``sumo_cases/road_frame_case.py``'s result on network ``name`` (an example network is
    built here into ``folder``; the on-ramp in the child, in ``env``'s network cache), in a
    process of its own."""
    # imported here: benchmarks import this module (ROUTES, build_example) outside pytest
    from sumo_cases.isolated import run_isolated
    from sumo_cases.road_frame_case import sumo_case

    if name == "onramp":
        return run_isolated(sumo_case, name, str(folder), env=env, timeout_s=300.0)
    net_file = build_example(name, folder)
    return run_isolated(sumo_case, name, str(folder), str(net_file), list(ROUTES[name]),
                        env=env, timeout_s=300.0)


@pytest.mark.sumo
@pytest.mark.parametrize("name", [*ROUTES, "onramp"])
def test_frame_agrees_with_sumo_positions(name, sumo_env, tmp_path):
    """Every vehicle, every step: SUMO's x, y and our (s, d) mapped back to x, y agree to
    0.05 m (measured: 1e-13 m where the lanes are the reference line, <= 0.01 m on the
    kinked multi-edge route's junction lanes); commanded d's are reached to 0.05 m."""
    r = _case(name, sumo_env, tmp_path)
    assert r["n"] > 3000 and r["on_junction_lanes"] > 5  # vehicles crossed the junctions
    assert r["worst_xy_m"] < TOL_M, r["where"]
    assert r["n_commanded"] > 500
    assert r["worst_command_m"] < TOL_M
    # our road edges are SUMO's lane borders: a body reaches equally far beyond both
    assert r["worst_edge_m"] < TOL_M, r["where_edge"]
    if name == "onramp":
        # ramp vehicles come out in the main road's frame: right of its right edge
        assert r["ramp_samples"] > 200
        assert r["ramp_max_d_minus_right_m"] < -0.5
    if name == "width_change":
        assert r["seen_on"]["narrow_0"] > 500 and r["seen_on"][":b_0_0"] > 20
