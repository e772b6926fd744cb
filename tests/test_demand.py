"""Tests of cosim.demand: route files, their randomness and SUMO's reading of them.

SUMO runs (libsumo: one simulation per process) each run in a process of their own,
forked by ``sumo_cases/isolated.py`` (``sumo_cases/demand_cases.py``, ``run_case.main``).
"""

from __future__ import annotations

import json
import os
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from sumo_cases import demand_cases, run_case
from sumo_cases.isolated import run_isolated

from cosim.demand.plan import KIND_BLOCK, arrival_times, plan_vehicles
from cosim.demand.routes import write_routes
from cosim.demand.spec import DemandSpec
from cosim.errors import ConfigError
from cosim.road.build import build_network
from cosim.road.frame import RoadNetwork
from cosim.road.spec import NetworkSpec
from cosim.sumo.binaries import sumo_binary
from cosim.sumo.detectors import write_detectors

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("netcache")


@pytest.fixture(scope="module")
def straight(cache: Path) -> RoadNetwork:
    return build_network(NetworkSpec(kind="straight", length_m=200.0), cache)


@pytest.fixture(scope="module")
def ring(cache: Path) -> RoadNetwork:
    return build_network(NetworkSpec(kind="ring", circumference_m=300.0), cache)


def _vehicles(path: Path) -> list[ET.Element]:
    return list(ET.parse(path).getroot().iter("vehicle"))


def _vtypes(path: Path) -> dict[str, ET.Element]:
    return {v.get("id"): v for v in ET.parse(path).getroot().iter("vType")}


def _run_case(out_dir: Path, spec: dict, env: dict, timeout: float = 300.0) -> dict:
    """``sumo_cases/run_case.py``'s result for ``spec``, run in a process of its own."""
    result = run_isolated(run_case.main, str(out_dir), json.dumps(spec), env=env,
                          timeout_s=timeout)
    return json.loads(json.dumps(result))  # as the RESULT line would carry it


# --------------------------------------------------------------------------------------
# Open roads
# --------------------------------------------------------------------------------------


def test_cav_share_and_counts(straight: RoadNetwork, tmp_path: Path) -> None:
    demand = DemandSpec(inflow_vph=3600.0, cav_share=0.3)
    info = write_routes(straight, demand, seed=7, path=tmp_path / "r.rou.xml", horizon_s=600.0)
    vehicles = _vehicles(info.path)
    n = len(vehicles)
    n_cav = sum(v.get("type").startswith("cav") for v in vehicles)
    assert n == info.n_main == info.n_cav + info.n_hdv
    assert n_cav == info.n_cav == len(info.cav_ids)
    # exact up to rounding in whole blocks of KIND_BLOCK vehicles, and the last block
    full = (n // KIND_BLOCK) * KIND_BLOCK
    assert abs(n_cav - 0.3 * n) <= 0.5 + int(round(0.3 * KIND_BLOCK))
    cav_mask = [v.get("type").startswith("cav") for v in sorted(
        vehicles, key=lambda v: int(v.get("id").rsplit(".", 1)[1]))]
    assert sum(cav_mask[:full]) == round(0.3 * full)
    assert all(v.get("id").startswith(v.get("type")[:3] + ".") for v in vehicles)
    assert info.arrival_process == "poisson"


@pytest.mark.parametrize("ramp", [False, True])
def test_a_longer_run_keeps_the_vehicles_of_a_shorter_one(cache: Path, ramp: bool) -> None:
    """Prefix stability: the same seed over 600 s and 200 s gives the same vehicles up to
    200 s (id, kind, size, desired speed, departure, lateral position), on both origins."""
    net = (build_network(NetworkSpec(kind="onramp", length_m=600.0, merge_position_m=300.0,
                                     ramp_length_m=150.0), cache) if ramp else
           build_network(NetworkSpec(kind="straight", length_m=200.0), cache))
    demand = DemandSpec(inflow_vph=3000.0, ramp_inflow_vph=800.0 if ramp else 0.0,
                        cav_share=0.35)

    def key(v):
        return (v.vid, v.vtype, v.is_cav, v.length_m, v.speed, v.depart, v.lat_m)

    short = [key(v) for v in plan_vehicles(net, demand, 11, 200.0).vehicles]
    long_ = [key(v) for v in plan_vehicles(net, demand, 11, 600.0).vehicles]
    assert len(long_) > 2 * len(short) > 100
    assert long_[: len(short)] == short
    if ramp:
        assert any(".ramp." in k[0] for k in short)


def test_same_seed_same_file_other_seed_differs(straight: RoadNetwork, tmp_path: Path) -> None:
    demand = DemandSpec(inflow_vph=2000.0)
    a = write_routes(straight, demand, seed=1, path=tmp_path / "a.rou.xml", horizon_s=120.0)
    b = write_routes(straight, demand, seed=1, path=tmp_path / "b.rou.xml", horizon_s=120.0)
    c = write_routes(straight, demand, seed=2, path=tmp_path / "c.rou.xml", horizon_s=120.0)
    text_a = a.path.read_text()
    assert text_a == b.path.read_text()
    assert text_a != c.path.read_text()
    assert a.vehicle_ids == b.vehicle_ids


def test_desired_speed_distribution(straight: RoadNetwork, tmp_path: Path) -> None:
    low, high = 22.0, 30.0
    demand = DemandSpec(inflow_vph=3600.0, desired_speed_mps=(low, high))
    info = write_routes(straight, demand, seed=3, path=tmp_path / "r.rou.xml", horizon_s=1000.0)
    vehicles = _vehicles(info.path)
    v0 = np.array([float(v.get("speedFactor")) * straight.speed_limit_mps for v in vehicles])
    param = np.array([float(v.find("param").get("value")) for v in vehicles])
    np.testing.assert_allclose(v0, param, atol=1e-3)
    assert v0.min() >= low - 1e-3 and v0.max() <= high + 1e-3
    # Uniform: mean and spread of the distribution (n ~ 1000, 5 standard errors).
    sd = (high - low) / np.sqrt(12)
    assert abs(v0.mean() - 0.5 * (low + high)) < 5 * sd / np.sqrt(len(v0))
    assert v0.std() == pytest.approx(sd, rel=0.1)
    assert info.desired_speed_mps[vehicles[0].get("id")] == pytest.approx(param[0], abs=1e-3)


@pytest.mark.parametrize("process", ["poisson", "uniform"])
def test_arrival_processes(process: str) -> None:
    rng = np.random.default_rng(0)
    t = arrival_times(1800.0, 3600.0, process, rng)
    assert t.min() >= 0 and t.max() < 3600.0
    assert abs(len(t) - 1800) < 4 * np.sqrt(1800)
    cv = np.diff(t).std() / np.diff(t).mean()
    if process == "poisson":
        assert cv == pytest.approx(1.0, abs=0.1)  # exponential headways
    else:
        assert cv < 1e-6  # constant headways


def test_lateral_departures_stay_on_the_road(straight: RoadNetwork, tmp_path: Path) -> None:
    demand = DemandSpec(inflow_vph=3600.0)
    info = write_routes(straight, demand, seed=5, path=tmp_path / "r.rou.xml", horizon_s=300.0)
    types = _vtypes(info.path)
    lat = np.array([float(v.get("departPosLat")) for v in _vehicles(info.path)])
    width = np.array([float(types[v.get("type")].get("width")) for v in _vehicles(info.path)])
    assert np.all(np.abs(lat) + width / 2 <= straight.width_m / 2)
    assert lat.min() < -3.0 and lat.max() > 3.0  # spread across the lane, not centred
    hdv = types["hdv_0"]
    assert hdv.get("laneChangeModel") == "SL2015" and hdv.get("latAlignment") == "arbitrary"
    assert {k for k in types} == {f"{p}_{i}" for p in ("cav", "hdv") for i in range(4)}
    sizes = [(float(t.get("length")), float(t.get("width"))) for t in types.values()]
    assert min(sizes) >= (3.2, 1.6) and max(sizes) <= (5.15, 1.84)


def test_onramp_demand_has_ramp_vehicles(cache: Path, tmp_path: Path) -> None:
    net = build_network(
        NetworkSpec(kind="onramp", length_m=400.0, merge_position_m=150.0, ramp_length_m=100.0,
                    acceleration_lane_m=100.0),
        cache,
    )
    demand = DemandSpec(inflow_vph=1800.0, ramp_inflow_vph=600.0)
    info = write_routes(net, demand, seed=1, path=tmp_path / "r.rou.xml", horizon_s=600.0)
    vehicles = _vehicles(info.path)
    ramp = [v for v in vehicles if v.get("route") == "ramp"]
    assert len(ramp) == info.n_ramp and 60 < info.n_ramp < 140
    assert all(abs(float(v.get("departPosLat"))) < net.ramp_width_m / 2 for v in ramp)
    departs = [float(v.get("depart")) for v in vehicles]
    assert departs == sorted(departs)  # SUMO needs route files sorted by departure


def test_three_lane_demand_uses_lanes(cache: Path, tmp_path: Path) -> None:
    net = build_network(NetworkSpec(kind="three_lane", length_m=200.0), cache)
    info = write_routes(net, DemandSpec(), seed=1, path=tmp_path / "r.rou.xml", horizon_s=300.0)
    vehicles = _vehicles(info.path)
    assert {v.get("departLane") for v in vehicles} == {"0", "1", "2"}
    assert all(v.get("departPosLat") is None for v in vehicles)
    assert _vtypes(info.path)["hdv_0"].get("laneChangeModel") == "LC2013"


# --------------------------------------------------------------------------------------
# Ring
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("placement", ["even", "random"])
def test_ring_density_is_exact_and_vehicles_do_not_overlap(
    ring: RoadNetwork, tmp_path: Path, placement: str
) -> None:
    demand = DemandSpec(ring_density_vpkm=80.0, ring_placement=placement)
    info = write_routes(ring, demand, seed=4, path=tmp_path / "ring.rou.xml", horizon_s=60.0)
    n = round(80.0 * ring.length_m / 1000.0)
    assert info.n_ring == n == len(info.ring_vehicle_ids)
    assert info.ring_density_vpkm == pytest.approx(1000.0 * n / ring.length_m)
    types = _vtypes(info.path)
    routes = {r.get("id"): r for r in ET.parse(info.path).getroot().iter("route")}
    front, lat, length, width = [], [], [], []
    for v in _vehicles(info.path):
        assert v.get("depart") == "0.00" and v.get("insertionChecks") == "none"
        route = routes[v.get("route")]
        assert int(route.get("repeat")) == info.ring_route_repeat
        first_edge = route.get("edges").split()[0]
        front.append(ring.s_of(first_edge, float(v.get("departPos"))))
        lat.append(float(v.get("departPosLat")))
        length.append(float(types[v.get("type")].get("length")))
        width.append(float(types[v.get("type")].get("width")))
    centre = np.array(front) - 0.5 * np.array(length)
    lat, length, width = np.array(lat), np.array(length), np.array(width)
    assert np.all(np.abs(lat) + width / 2 <= ring.width_m / 2)
    ds = np.abs(centre[:, None] - centre[None, :])
    ds = np.minimum(ds, ring.length_m - ds)
    overlap = (ds < 0.5 * (length[:, None] + length[None, :])) & (
        np.abs(lat[:, None] - lat[None, :]) < 0.5 * (width[:, None] + width[None, :])
    )
    np.fill_diagonal(overlap, False)
    assert not overlap.any()
    # Routes are long enough to circle for the demand's duration at the vType's max speed.
    assert info.ring_route_repeat * ring.length_m >= 60.0 * 60.0


def test_ring_density_too_high_is_a_config_error(ring: RoadNetwork, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="ring_density_vpkm"):
        write_routes(ring, DemandSpec(ring_density_vpkm=2000.0), 1, tmp_path / "r.rou.xml")
    with pytest.raises(ConfigError, match="ring_density_vpkm"):
        write_routes(ring, DemandSpec(ring_density_vpkm=0.0), 1, tmp_path / "r.rou.xml")


#: TUM LaneFreeDrive's car sizes (length m, width m, probability).
TUM_SIZES = ((3.2, 1.6, 0.2), (3.9, 1.7, 0.2), (4.5, 1.78, 0.2), (5.15, 1.84, 0.2),
             (5.2, 1.88, 0.2))


def _min_bumper_gap_of_overlapping(s: np.ndarray, d: np.ndarray, length: np.ndarray,
                                   width: np.ndarray, period: float) -> float:
    """Smallest bumper gap (m) between any two vehicles whose bodies overlap laterally,
    centres ``s`` on a ring of ``period`` m (across the wrap too): a sorted scan, pairs k
    places apart for k = 1, 2, ... until none can be closer (no N x N array)."""
    order = np.argsort(s)
    s, d, length, width = s[order], d[order], length[order], width[order]
    n, best, idx = len(s), np.inf, np.arange(len(s))
    for k in range(1, n):
        j = (idx + k) % n
        ds = np.mod(s[j] - s, period)
        overlap = np.abs(d[j] - d) < 0.5 * (width[j] + width)
        if overlap.any():
            best = min(best, float((ds - 0.5 * (length[j] + length))[overlap].min()))
        if ds.min() - length.max() > best:
            break
    return best


@pytest.mark.parametrize(("density", "placement"), [
    *((x, "even") for x in (30.0, 150.0, 225.0, 300.0, 400.0)),
    # random sequential placement runs out of room earlier (refused: tested below)
    *((x, "random") for x in (30.0, 150.0, 225.0, 300.0)),
])
def test_ring_placement_is_collision_free_up_to_400_vpkm(density: float, placement: str) -> None:
    """1 km x 10.2 m ring, TUM's sizes (3.2-5.2 m long): every laterally overlapping pair
    is at least RING_MIN_GAP_M apart bumper to bumper, across the wrap too (at 225 veh/km
    the last vehicle used to sit 0.73 m inside the first), every body on the road."""
    from cosim.demand.plan import plan_vehicles
    from cosim.demand.spec import RING_MIN_GAP_M
    from cosim.road.geometry import road_geometry

    net = road_geometry(NetworkSpec(kind="ring", circumference_m=1000.0, width_m=10.2))
    for seed in (1, 2, 3):
        demand = DemandSpec(ring_density_vpkm=density, size_classes=TUM_SIZES,
                            ring_placement=placement)
        vs = plan_vehicles(net, demand, seed, 60.0).vehicles
        assert len(vs) == round(density)
        s = np.array([v.centre_s_m for v in vs])
        d = np.array([v.lat_m for v in vs])
        length = np.array([v.length_m for v in vs])
        width = np.array([v.width_m for v in vs])
        assert np.all((s >= 0.0) & (s < 1000.0))
        assert np.all(np.abs(d) + 0.5 * width <= 5.1 + 1e-9)
        gap = _min_bumper_gap_of_overlapping(s, d, length, width, 1000.0)
        assert gap >= RING_MIN_GAP_M - 1e-9, (seed, gap)


def test_ring_density_beyond_what_fits_is_refused_naming_the_maximum() -> None:
    """4 rows of cars up to 5.2 m with 1 m gaps: 4 x floor(1000 / 6.2) = 644 vehicles on
    1 km. 644 veh/km are placed; 645 are refused in one line that names 644 veh/km;
    random placement, when it runs out of room, names the same figure."""
    from cosim.demand.plan import plan_vehicles, ring_max_vehicles
    from cosim.road.geometry import road_geometry

    assert ring_max_vehicles(1000.0, 10.2, 5.2, 1.88) == 644
    net = road_geometry(NetworkSpec(kind="ring", circumference_m=1000.0, width_m=10.2))
    big = ((5.2, 1.88, 1.0),)
    assert len(plan_vehicles(net, DemandSpec(ring_density_vpkm=644.0, size_classes=big),
                             1, 60.0).vehicles) == 644
    with pytest.raises(ConfigError, match=r"ring_density_vpkm=645 .*at most 644 veh/km") as e:
        plan_vehicles(net, DemandSpec(ring_density_vpkm=645.0, size_classes=big), 1, 60.0)
    assert "\n" not in str(e.value)
    with pytest.raises(ConfigError, match="random placement.*up to 644 veh/km"):
        plan_vehicles(net, DemandSpec(ring_density_vpkm=640.0, size_classes=big,
                                      ring_placement="random"), 1, 60.0)


@pytest.mark.parametrize("density", [225.0, 400.0])
def test_dense_ring_starts_without_collision_in_the_road_world(density: float) -> None:
    """The whole loop, SUMO-free (scenario.world = "road"): 100 % CAVs, TUM's sizes, no
    collision in the first step (the issue: one at t = 0.1 s at 225 veh/km)."""
    from cosim.config.scenario import scenario_from_dict
    from cosim.sim.runner import run_scenario

    sc = scenario_from_dict({
        "scenario": {"name": "dense_ring", "duration_s": 0.2, "warmup_s": 0.0,
                     "interval_s": 0.2, "world": "road"},
        "network": {"kind": "ring", "circumference_m": 1000.0, "width_m": 10.2},
        "demand": {"ring_density_vpkm": density, "cav_share": 1.0,
                   "size_classes": [list(c) for c in TUM_SIZES]},
    })
    s = run_scenario(sc).summary.iloc[0]
    assert s["vehicles_inserted"] == round(density)
    assert s["collisions_geometric_cav"] == 0 and s["collisions_geometric_hdv_only"] == 0
    assert s["min_gap_m"] >= 1.0


@pytest.mark.sumo
def test_dense_ring_starts_without_collision_in_sumo(tmp_path: Path) -> None:
    """The same at 225 veh/km in SUMO: every vehicle inserted, no collision (SUMO's or
    ours) at t = 0.1 s."""
    spec = {
        "scenario": {"name": "dense_ring", "duration_s": 0.2, "warmup_s": 0.0,
                     "interval_s": 0.2},
        "network": {"kind": "ring", "circumference_m": 1000.0, "width_m": 10.2},
        "demand": {"ring_density_vpkm": 225.0, "cav_share": 1.0,
                   "size_classes": [list(c) for c in TUM_SIZES]},
    }
    env = {**os.environ, "PYTHONPATH": str(REPO),
           "COSIM_NETWORK_CACHE": str(tmp_path / "nets")}
    s = _run_case(tmp_path / "out", spec, env)["summary"]
    assert s["vehicles_inserted"] == 225
    assert s["collisions_sumo_cav"] == 0 and s["collisions_sumo_hdv_only"] == 0
    assert s["collisions_geometric_cav"] == 0 and s["collisions_geometric_hdv_only"] == 0


@pytest.mark.sumo
def test_sumo_inserts_the_whole_ring_at_t0_and_keeps_it(ring: RoadNetwork, tmp_path: Path) -> None:
    demand = DemandSpec(ring_density_vpkm=40.0)
    info = write_routes(ring, demand, seed=9, path=tmp_path / "ring.rou.xml", horizon_s=60.0)
    out = run_isolated(demand_cases.ring_insertion, str(Path(ring.net_file).parents[1]),
                       str(info.path), env={**os.environ, "PYTHONPATH": str(REPO)},
                       timeout_s=60.0)
    assert out["n0"] == info.n_ring == 12
    assert out["pos_err"] < 1e-9 and out["lat_err"] < 1e-9 and out["factor"] < 1e-9
    assert out["n60"] == info.n_ring and out["arrived"] == 0
    assert out["collisions"] == 0


# --------------------------------------------------------------------------------------
# Detectors
# --------------------------------------------------------------------------------------


@pytest.mark.sumo
def test_sumo_writes_detector_outputs(straight: RoadNetwork, tmp_path: Path) -> None:
    demand = DemandSpec(inflow_vph=2400.0)
    routes = write_routes(straight, demand, seed=2, path=tmp_path / "r.rou.xml", horizon_s=60.0)
    out_dir = tmp_path / "out"
    det = write_detectors(straight, [50.0, 150.0], tmp_path / "det.add.xml", 30.0, out_dir)
    assert det.loop_s_m == pytest.approx((50.0, 150.0))
    proc = subprocess.run(
        [
            str(sumo_binary("sumo")),
            "-n",
            str(straight.net_file),
            "-r",
            str(routes.path),
            "-a",
            str(det.path),
            "--lateral-resolution",
            "0.8",
            "--end",
            "60",
            "--no-step-log",
            "true",
            "--seed",
            "2",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-1000:]
    counts = []
    for f in det.loop_files:
        intervals = list(ET.parse(f).getroot().iter("interval"))
        assert [float(i.get("end")) for i in intervals] == [30.0, 60.0]
        counts.append(sum(int(i.get("nVehContrib")) for i in intervals))
    edges = list(ET.parse(det.edgedata_file).getroot().iter("edge"))
    departed = sum(int(e.get("departed")) for e in edges)
    arrived = sum(int(e.get("arrived")) for e in edges)
    assert departed > 20
    # Loops across the whole 10.2 m lane catch every vehicle whatever its lateral position:
    # everyone who arrived at 200 m passed 150 m, and at most a few are between the two.
    assert counts[0] >= counts[1] >= arrived
    assert counts[1] - arrived <= 3
    assert departed - counts[0] <= 3


# --------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"cav_share": 1.5}, "cav_share"),
        ({"cav_share": -0.1}, "cav_share"),
        ({"inflow_vph": -1.0}, "inflow_vph"),
        ({"ramp_inflow_vph": float("inf")}, "ramp_inflow_vph"),
        ({"ring_density_vpkm": -3.0}, "ring_density_vpkm"),
        ({"desired_speed_mps": (30.0, 20.0)}, "desired_speed_mps"),
        ({"desired_speed_mps": (0.0, 20.0)}, "desired_speed_mps"),
        ({"depart_lateral": "left"}, "depart_lateral"),
        ({"depart_speed": "fast"}, "depart_speed"),
        ({"arrivals": "bursty"}, "arrivals"),
        ({"ring_placement": "grid"}, "ring_placement"),
        ({"size_classes": ((4.0, -1.0, 1.0),)}, "size_classes"),
        ({"size_classes": ((4.0, 1.8, 0.0),)}, "size_classes"),
        ({"size_classes": ()}, "size_classes"),
    ],
)
def test_bad_demand_raises_config_error_naming_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field) as err:
        DemandSpec(**kwargs)
    assert "\n" not in str(err.value)


def test_bad_detector_period(straight: RoadNetwork, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="period_s"):
        write_detectors(straight, [50.0], tmp_path / "d.add.xml", 0.0, tmp_path)
    with pytest.raises(ConfigError, match="outside the road"):
        write_detectors(straight, [500.0], tmp_path / "d.add.xml", 10.0, tmp_path)


def test_slot_insertion_keeps_headway_and_never_departs_faster_than_the_slot_leader(tmp_path):
    """Slot insertion: in each lateral slot, departures are at least slot_headway_s apart,
    the follower's depart speed is at most its slot leader's, and the gap at departure is
    at least s0 + v * tau with the follower's own tau (CAV 0.5 s, human 1 s)."""
    import xml.etree.ElementTree as ET

    from cosim.demand.routes import write_routes
    from cosim.demand.spec import CAV_TAU_S, HDV_TAU_S, MIN_GAP_M, DemandSpec
    from cosim.road.build import build_network
    from cosim.road.spec import NetworkSpec

    net = build_network(NetworkSpec(kind="straight", length_m=300.0), cache_dir=tmp_path)
    demand = DemandSpec(inflow_vph=16000.0, cav_share=0.5,
                        slot_headway_s=0.6)
    info = write_routes(net, demand, 7, tmp_path / "r.rou.xml", horizon_s=120.0)
    root = ET.parse(info.path).getroot()
    lengths = {v.get("id"): float(v.get("length")) for v in root.iter("vType")}
    by_slot: dict = {}
    for v in root.iter("vehicle"):
        by_slot.setdefault(v.get("departPosLat"), []).append(
            (float(v.get("depart")), float(v.get("departSpeed")), lengths[v.get("type")],
             CAV_TAU_S if v.get("type").startswith("cav") else HDV_TAU_S)
        )
    assert len(by_slot) == 4  # 10.2 m road, slots 2.55 m apart
    tight = {CAV_TAU_S: 0, HDV_TAU_S: 0}
    for rows in by_slot.values():
        for (t0, v0, l0, _), (t1, v1, _, tau1) in zip(rows, rows[1:], strict=False):
            assert t1 - t0 >= demand.slot_headway_s - 0.011
            assert v1 <= v0 + 1e-3
            gap = v0 * (t1 - t0) - l0
            assert gap >= MIN_GAP_M + v1 * tau1 - 0.35  # depart times rounded to 0.01 s
            tight[tau1] += gap < MIN_GAP_M + v1 * 1.0 - 0.5  # closer than a human may
    assert tight[CAV_TAU_S] > 0  # CAVs do use their shorter reaction time
    assert tight[HDV_TAU_S] == 0


# --------------------------------------------------------------------------------------
# Human drivers' vTypes (calibrated by experiments/calibrate_humans.py)
# --------------------------------------------------------------------------------------

#: SL2015-only attributes that the calibrated human drivers carry on lane-free roads.
SL2015_HDV_KEYS = ("minGapLat", "maxSpeedLat", "lcPushy", "lcAssertive", "lcTimeToImpatience")


def test_human_vtypes_carry_the_calibrated_drivers_and_cavs_are_unchanged(
    straight: RoadNetwork, cache: Path, tmp_path: Path
) -> None:
    """Lane-free: human drivers get SL2015 with the calibrated lateral gap, lateral speed,
    pushiness, assertiveness and impatience, and the calibrated Krauss tau and sigma; CAVs
    keep SUMO's 0.5 m lateral gap, no lc* attributes, sigma 0 and their short tau. Three
    lanes: LC2013 with the same human car following (the two human arms differ only in
    lanes) and none of the SL2015-only attributes. Colours stay blue / orange."""
    from cosim.demand import spec
    from cosim.demand.routes import CAV_RGB, HDV_RGB, lane_change_attributes

    free = _vtypes(write_routes(straight, DemandSpec(cav_share=0.5), 1,
                                tmp_path / "free.rou.xml", horizon_s=60.0).path)
    lanes_net = build_network(NetworkSpec(kind="three_lane", length_m=200.0), cache)
    laned = _vtypes(write_routes(lanes_net, DemandSpec(cav_share=0.5), 1,
                                 tmp_path / "lanes.rou.xml", horizon_s=60.0).path)
    expected_hdv = {
        "laneChangeModel": "SL2015", "latAlignment": "arbitrary",
        "minGapLat": spec.HDV_MIN_GAP_LAT_M, "maxSpeedLat": spec.HDV_MAX_SPEED_LAT_MPS,
        "lcPushy": spec.HDV_LC_PUSHY, "lcAssertive": spec.HDV_LC_ASSERTIVE,
        "lcTimeToImpatience": spec.HDV_LC_TIME_TO_IMPATIENCE_S,
        "tau": spec.HDV_TAU_S, "sigma": spec.HDV_SIGMA,
    }
    for k in range(4):
        hdv, cav = free[f"hdv_{k}"], free[f"cav_{k}"]
        for key, value in expected_hdv.items():
            got = hdv.get(key)
            assert (got == value if isinstance(value, str) else float(got) == value), key
        assert hdv.get("color") == ",".join(map(str, HDV_RGB))
        assert cav.get("laneChangeModel") == "SL2015"
        assert float(cav.get("minGapLat")) == spec.MIN_GAP_LAT_M == 0.5
        assert float(cav.get("maxSpeedLat")) == spec.MAX_SPEED_LAT_MPS
        assert float(cav.get("tau")) == spec.CAV_TAU_S and float(cav.get("sigma")) == 0.0
        assert not [a for a in cav.attrib if a.startswith("lc")]
        assert cav.get("color") == ",".join(map(str, CAV_RGB))
        lane_hdv = laned[f"hdv_{k}"]
        assert lane_hdv.get("laneChangeModel") == "LC2013"
        assert not [a for a in SL2015_HDV_KEYS + ("latAlignment",) if a in lane_hdv.attrib]
        for key in ("tau", "sigma", "minGap", "accel", "decel", "length", "width"):
            assert lane_hdv.get(key) == hdv.get(key), key  # same human car following
    # The calibrated drivers differ from SUMO's defaults (tau 1 s, minGapLat 0.6 m / our 0.5).
    assert spec.HDV_TAU_S > 1.0 and spec.HDV_MIN_GAP_LAT_M > spec.MIN_GAP_LAT_M
    assert spec.HDV_LC_PUSHY > 0 and spec.HDV_LC_ASSERTIVE > 1.0
    assert lane_change_attributes("hdv", lanes=True) == {"laneChangeModel": "LC2013"}
    assert list(lane_change_attributes("hdv", lanes=False))[:2] == ["laneChangeModel",
                                                                    "latAlignment"]


@pytest.mark.sumo
def test_sumo_reads_the_human_driver_attributes(
    straight: RoadNetwork, cache: Path, tmp_path: Path
) -> None:
    """SUMO accepts the written vTypes (an unknown or out-of-range lane-change attribute
    stops it: e.g. lcImpatience < 0 is refused) and holds the calibrated values: Krauss
    tau, lateral gap and speed, and SL2015's lcPushy, lcAssertive, lcTimeToImpatience;
    the three-lane file loads with LC2013 and the same tau."""
    from cosim.demand import spec

    free = write_routes(straight, DemandSpec(cav_share=0.0, inflow_vph=3600.0), 3,
                        tmp_path / "free.rou.xml", horizon_s=30.0)
    lanes_net = build_network(NetworkSpec(kind="three_lane", length_m=200.0), cache)
    laned = write_routes(lanes_net, DemandSpec(cav_share=0.0, inflow_vph=3600.0), 3,
                         tmp_path / "lanes.rou.xml", horizon_s=30.0)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = {  # each file in a SUMO of its own
        name: run_isolated(demand_cases.human_driver_attributes, str(net), str(routes), extra,
                           env=env, timeout_s=60.0)
        for name, net, routes, extra in (
            ("free", straight.net_file, free.path, ["--lateral-resolution", "0.8"]),
            ("lanes", lanes_net.net_file, laned.path, []))
    }
    free_hdv = out["free"]
    assert free_hdv["tau"] == pytest.approx(spec.HDV_TAU_S)
    assert free_hdv["imperfection"] == pytest.approx(spec.HDV_SIGMA)
    assert free_hdv["minGapLat"] == pytest.approx(spec.HDV_MIN_GAP_LAT_M)
    assert free_hdv["maxSpeedLat"] == pytest.approx(spec.HDV_MAX_SPEED_LAT_MPS)
    assert free_hdv["lcPushy"] == pytest.approx(spec.HDV_LC_PUSHY)
    assert free_hdv["lcAssertive"] == pytest.approx(spec.HDV_LC_ASSERTIVE)
    assert free_hdv["lcTimeToImpatience"] == pytest.approx(spec.HDV_LC_TIME_TO_IMPATIENCE_S)
    assert out["lanes"]["tau"] == pytest.approx(spec.HDV_TAU_S)


@pytest.mark.sumo
@pytest.mark.slow(seconds=3)
def test_human_drivers_get_around_a_stopped_vehicle(tmp_path: Path) -> None:
    """Issue 12's obstacle, human drivers only: a stopped vehicle 5 m x 3.4 m covering the
    right third of a 1 km x 10.2 m road at s = 550 m, 4 000 veh/h. With SUMO's default
    drivers some stood still for 244-274 s (calibrate_humans.py --sumo-defaults); the
    calibrated ones get around it: nobody stands still for more than 30 s, the flow past
    the obstacle is never zero in a 30 s interval after the warm-up, no collision."""
    case = {
        "scenario": {"name": "hdv_obstacle", "seed": 2, "duration_s": 240.0,
                     "warmup_s": 120.0, "interval_s": 30.0},
        "network": {"kind": "straight", "length_m": 1000.0},
        "demand": {"inflow_vph": 4000.0, "cav_share": 0.0},
        "obstacle": {"s_m": 550.0, "d_m": -3.4, "length_m": 5.0, "width_m": 3.4},
        "outputs": {"zone_start_m": 100.0, "zone_end_m": 900.0},
    }
    env = {**os.environ, "PYTHONPATH": str(REPO),
           "COSIM_NETWORK_CACHE": str(tmp_path / "nets")}
    s = _run_case(tmp_path / "out", case, env)["summary"]
    assert s["max_standstill_s"] <= 30.0 and s["vehicles_stopped_long"] == 0
    assert s["collisions_sumo_hdv_only"] == 0
    import pandas as pd

    past = pd.read_csv(tmp_path / "out" / "intervals.csv")["flow_x562.5_vph"]
    assert len(past) == 4 and (past > 0).all()


@pytest.mark.sumo
@pytest.mark.slow(seconds=3.5)
def test_one_lane_carries_2000_to_2400_vph_with_the_calibrated_drivers() -> None:
    """Road-limited lane capacity of the three-lane baseline: on a 1 km ring of three
    3.4 m lanes (no entrance) with LC2013 human drivers, Edie's flow per lane near the
    flow-density curve's maximum (24 and 27 veh/km per lane, 300 s after 300 s) lies in
    2 000-2 400 veh/h (SUMO's default tau = 1 s: about 2 500-2 600 veh/h there)."""
    flows = []
    for k in (24.0, 27.0):
        task = {"kind": "lane_ring", "k_lane_vpkm": k, "seed": 1, "length_m": 1000.0,
                "lanes": 3, "lane_width_m": 3.4, "duration_s": 600.0, "warmup_s": 300.0}
        # calibrate_humans.py --child TASK, in a process of its own
        r = run_isolated(demand_cases.calibrate_humans_child, task,
                         env={**os.environ, "PYTHONPATH": str(REPO)}, timeout_s=300.0)
        assert r["collision_vehicles"] == 0
        flows.append(r["q_lane_vph"])
    assert 2000.0 <= max(flows) <= 2400.0, flows
