"""A standing queue placed at t = 0 on an open road (``demand.queue_vpkm`` over
``demand.queue_span_m``; :func:`cosim.demand.plan._queue_vehicles`): a bottleneck is
queued from the start, so its discharge is the road's even when the entrance alone could
not queue it. The plan (counts, spacing, rows, lanes, seeds), its refusals, the capacity
recorder's backlog (the queue is not demand), the road world and SUMO (in a process of
its own) placing it where the plan says.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from sumo_cases import queue_cases
from sumo_cases.isolated import run_isolated

from cosim.demand.plan import plan_vehicles
from cosim.demand.routes import write_routes
from cosim.demand.spec import RING_MIN_GAP_M, DemandSpec
from cosim.errors import ConfigError
from cosim.metrics import capacity as cap
from cosim.road.build import build_network
from cosim.road.frame import RoadNetwork
from cosim.road.spec import NetworkSpec
from cosim.sim.recording import CapacityRecorder

REPO = Path(__file__).resolve().parents[1]
#: a road of three pieces (three edges): the queue reaches onto the second
PROFILE = ((150.0, 10.2), (250.0, 10.2), (100.0, 6.8))


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("netcache")


@pytest.fixture(scope="module")
def road(cache: Path) -> RoadNetwork:
    return build_network(NetworkSpec(kind="varying_width", width_profile=PROFILE), cache)


@pytest.fixture(scope="module")
def even(cache: Path) -> RoadNetwork:
    """Two edges of one width (SUMO's drivers collide among themselves at a width drop's
    junction: the SUMO test is about the placement, not about them)."""
    return build_network(NetworkSpec(kind="varying_width",
                                     width_profile=((200.0, 10.2), (300.0, 10.2))), cache)


@pytest.fixture(scope="module")
def lanes(cache: Path) -> RoadNetwork:
    return build_network(NetworkSpec(kind="three_lane", length_m=500.0, width_m=10.2), cache)


def _queue(net: RoadNetwork, seed: int = 1, **kw) -> list:
    demand = DemandSpec(**{"inflow_vph": 3000.0, "cav_share": 0.5, "queue_vpkm": 250.0,
                           "queue_span_m": (60.0, 390.0), **kw})
    return [v for v in plan_vehicles(net, demand, seed, 60.0).vehicles if ".queue." in v.vid]


def _overlaps(q: list) -> int:
    """Pairs of queue vehicles closer than RING_MIN_GAP_M bumper to bumper while less than
    0.1 m apart laterally (a sorted scan, no N x N array)."""
    order = sorted(q, key=lambda v: v.centre_s_m)
    bad = 0
    for i, a in enumerate(order):
        for b in order[i + 1:]:
            gap = b.centre_s_m - a.centre_s_m - 0.5 * (a.length_m + b.length_m)
            if gap >= RING_MIN_GAP_M - 1e-9:
                break
            bad += abs(a.lat_m - b.lat_m) < 0.5 * (a.width_m + b.width_m) + 0.1
    return bad


def _in_junction(net: RoadNetwork, s: float) -> bool:
    return not any(s0 <= s <= s1 for _, s0, s1 in net.edge_spans)


def test_the_queue_stands_in_its_span_in_rows_without_overlap(road: RoadNetwork) -> None:
    q = _queue(road)
    # round(density x span), less those whose front would stand in a junction
    assert round(250.0 * 330.0 / 1000.0) - 3 <= len(q) <= round(250.0 * 330.0 / 1000.0)
    assert not any(_in_junction(road, v.centre_s_m + 0.5 * v.length_m) for v in q)
    front = np.array([v.centre_s_m + 0.5 * v.length_m for v in q])
    rear = front - np.array([v.length_m for v in q])
    assert front.max() <= 390.0 + 1e-9 and rear.min() >= 60.0 - 1e-9
    assert all(v.depart == 0.0 and v.v0_mps == 0.0 and v.depart_speed == "0" for v in q)
    assert _overlaps(q) == 0
    half = 0.5 * 10.2
    assert all(abs(v.lat_m) + 0.5 * v.width_m <= half for v in q)
    assert {v.depart_edge for v in q} == {0, 1}  # on the road's first two edges
    share = np.mean([v.is_cav for v in q])
    assert 0.4 <= share <= 0.6
    assert len({round(v.lat_m) for v in q}) >= 4  # rows across the width, not one file


def test_the_queue_is_fixed_by_the_seed_and_leaves_the_arrivals_alone(
        road: RoadNetwork) -> None:
    a, b, c = _queue(road, 3), _queue(road, 3), _queue(road, 4)
    key = [(v.vid, v.vtype, v.centre_s_m, v.lat_m, v.speed) for v in a]
    assert key == [(v.vid, v.vtype, v.centre_s_m, v.lat_m, v.speed) for v in b]
    assert key != [(v.vid, v.vtype, v.centre_s_m, v.lat_m, v.speed) for v in c]
    plain = DemandSpec(inflow_vph=3000.0, cav_share=0.5)
    with_q = DemandSpec(inflow_vph=3000.0, cav_share=0.5, queue_vpkm=250.0,
                        queue_span_m=(60.0, 390.0))
    arrivals = [[(v.vid, v.depart, v.lat_m, v.speed) for v in
                 plan_vehicles(road, d, 3, 60.0).vehicles if ".queue." not in v.vid]
                for d in (plain, with_q)]
    assert arrivals[0] == arrivals[1] and len(arrivals[0]) > 10


def test_on_a_lane_network_the_rows_are_the_lanes(lanes: RoadNetwork) -> None:
    q = _queue(lanes)
    assert {v.depart_lane for v in q} == {"0", "1", "2"}
    assert all(v.depart_lat is None for v in q)
    assert {round(v.lat_m, 2) for v in q} == {-3.4, 0.0, 3.4}
    assert _overlaps(q) == 0


def test_impossible_queues_are_refused_with_one_line(road: RoadNetwork) -> None:
    with pytest.raises(ConfigError, match="at most .* veh/km") as err:
        _queue(road, queue_vpkm=2000.0)
    assert "\n" not in str(err.value)
    with pytest.raises(ConfigError, match="beyond the road"):
        _queue(road, queue_span_m=(100.0, 900.0))
    for span in ((300.0, 200.0), (-5.0, 20.0), (0.0, float("nan")), (1.0, 2.0, 3.0)):
        with pytest.raises(ConfigError, match="queue_span_m"):
            DemandSpec(queue_vpkm=100.0, queue_span_m=span)
    with pytest.raises(ConfigError, match="queue_vpkm"):
        DemandSpec(queue_vpkm=-1.0)
    ring = build_network(NetworkSpec(kind="ring", circumference_m=300.0),
                         Path(road.net_file).parents[1])
    with pytest.raises(ConfigError, match="open roads"):
        _queue(ring, queue_span_m=(10.0, 100.0))


def test_scenario_check_refuses_a_span_beyond_the_road_before_any_run() -> None:
    from cosim.config.scenario import scenario_from_dict

    with pytest.raises(ConfigError, match="beyond the 500 m road"):
        scenario_from_dict({"network": {"kind": "straight", "length_m": 500.0},
                            "demand": {"queue_vpkm": 100.0, "queue_span_m": [100.0, 600.0]}})
    with pytest.raises(ConfigError, match="open roads"):
        scenario_from_dict({"network": {"kind": "ring"},
                            "demand": {"queue_vpkm": 100.0, "queue_span_m": [10.0, 60.0]}})


def test_the_queue_is_not_demand_in_the_entrance_backlog() -> None:
    layout = cap.layout_for(1000.0, False, cap.find_bottleneck([0.0, 600.0], [10.2, 6.8]))
    rec = CapacityRecorder(0.1, layout, 0.0, 100.0, demand_vph=3600.0, preloaded=40)
    from cosim.metrics.traffic import StepState

    z = np.zeros(0)
    empty = StepState(t=0.1, ids=[], s=z, s_front=z, d=z, v=z, v_lat=z, length=z, width=z,
                      is_cav=np.zeros(0, dtype=bool), edge_right=z, edge_left=z)
    rec.record(empty, n_departed=41)  # the queue and one arrival
    assert rec.inserted[0] == 1


def test_the_road_world_places_the_queue_where_the_plan_says(road: RoadNetwork) -> None:
    from cosim.road.geometry import road_geometry
    from cosim.sim.road_world import RoadWorld

    demand = DemandSpec(inflow_vph=0.0, cav_share=0.0, queue_vpkm=250.0,
                        queue_span_m=(60.0, 390.0))
    plan = plan_vehicles(road, demand, 2, 30.0)
    world = RoadWorld(road_geometry(NetworkSpec(kind="varying_width", width_profile=PROFILE)),
                      plan, 0.1)
    world.step()
    snap = world.observe()
    want = {v.vid: (v.centre_s_m, v.lat_m) for v in plan.vehicles}
    assert len(snap.ids) == len(want)
    got = dict(zip(snap.ids, zip(snap.s, snap.d, strict=True), strict=True))
    assert max(abs(got[i][0] - want[i][0]) for i in want) < 0.01  # one step at <= 0.03 m/s
    assert max(abs(got[i][1] - want[i][1]) for i in want) < 1e-9


@pytest.fixture(scope="module")
def user_taper(cache: Path) -> RoadNetwork:
    """A taper drawn as a user draws it (netconvert's defaults, 3 m junctions between its
    pieces): cosim.road.user_roads."""
    from cosim.road import user_roads

    drawn = user_roads.draw("taper", 3)
    net_file = user_roads.build(drawn, cache / "user")
    return build_network(NetworkSpec(kind="file", net_file=str(net_file),
                                     route_edges=tuple(drawn.route)), cache)


def test_on_a_users_taper_no_vehicle_stands_in_a_junction(user_taper: RoadNetwork) -> None:
    gaps = [(a[2], b[1]) for a, b in zip(user_taper.edge_spans, user_taper.edge_spans[1:],
                                         strict=False)]
    assert len(gaps) >= 5 and all(hi - lo > 1.0 for lo, hi in gaps)
    q = _queue(user_taper, queue_vpkm=300.0, queue_span_m=(300.0, 660.0))
    fronts = [v.centre_s_m + 0.5 * v.length_m for v in q]
    assert not any(_in_junction(user_taper, f) for f in fronts)
    assert len({v.depart_edge for v in q}) >= 4  # on the wide piece and the taper's
    assert _overlaps(q) == 0
    right, left = user_taper.edges_at(np.array([v.centre_s_m for v in q]))
    half_w = np.array([0.5 * v.width_m for v in q])
    lat = np.array([v.lat_m for v in q])
    assert np.all(lat - half_w >= right - 1e-9) and np.all(lat + half_w <= left + 1e-9)


@pytest.mark.sumo
@pytest.mark.parametrize("kind", ["road", "lanes", "user"])
def test_sumo_inserts_the_queue_at_t0_where_the_plan_says(kind: str, even: RoadNetwork,
                                                         lanes: RoadNetwork,
                                                         user_taper: RoadNetwork,
                                                         tmp_path: Path) -> None:
    """SUMO's drivers (CAVs on a user's taper: SUMO's own drivers collide among
    themselves in a taper, which is not what this test is about)."""
    net = {"road": even, "lanes": lanes, "user": user_taper}[kind]
    span = (300.0, 660.0) if kind == "user" else (60.0, 390.0)
    demand = DemandSpec(inflow_vph=0.0, cav_share=1.0 if kind == "user" else 0.0,
                        queue_vpkm=150.0, queue_span_m=span)
    info = write_routes(net, demand, seed=5, path=tmp_path / "q.rou.xml", horizon_s=60.0)
    out = run_isolated(queue_cases.queue_insertion, str(net.net_file), str(info.path),
                       kind != "lanes", env={**os.environ, "PYTHONPATH": str(REPO)},
                       timeout_s=120.0)
    assert out["n0"] == info.n_hdv + info.n_cav
    assert round(150.0 * (span[1] - span[0]) / 1000.0) - 3 <= out["n0"]
    assert out["edges"] == {"road": 2, "lanes": 1}.get(kind, out["edges"])
    if kind == "user":
        assert out["edges"] >= 4  # departEdge on every piece
    assert out["wrong_edge"] == 0 and out["lanes_err"] == 0
    assert out["pos_err"] < 1e-6 and out["lat_err"] < 1e-6
    assert out["v_max"] < 3.0  # a standing queue (one step of acceleration at most)
    assert out["collisions"] == 0 and out["teleports"] == 0
    assert out["stopped_at_40s"] == 0  # it dissolved: nobody stuck
