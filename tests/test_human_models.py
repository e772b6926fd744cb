"""TUM's human model beside SUMO's calibrated drivers (``demand.human_model``).

Route files without SUMO: every human driver gets a reaction time drawn from N(1.5, 0.5) s
and a vType of its class and reaction time with TUM's constants; the draw is the seed's;
CAVs and the default drivers are untouched. Bad values are one ``error:`` line. One short
SUMO run (its own process) with TUM's drivers on TUM's ring.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from sumo_cases.isolated import run_isolated

from cosim.demand.humans import TAU_MIN_S, TUM_MODELS
from cosim.demand.routes import write_routes
from cosim.demand.spec import DemandSpec
from cosim.errors import ConfigError
from cosim.road.build import build_network
from cosim.road.frame import RoadNetwork
from cosim.road.spec import NetworkSpec


@pytest.fixture(scope="module")
def ring(tmp_path_factory: pytest.TempPathFactory) -> RoadNetwork:
    return build_network(NetworkSpec(kind="ring", circumference_m=1000.0, width_m=10.2),
                         tmp_path_factory.mktemp("netcache"))


def _parse(path: Path):
    root = ET.parse(path).getroot()
    return ({v.get("id"): v for v in root.iter("vType")},
            {v.get("id"): v.get("type") for v in root.iter("vehicle")})


def test_every_human_driver_has_his_reaction_time_and_tums_constants(ring, tmp_path):
    demand = DemandSpec(ring_density_vpkm=300.0, cav_share=0.2, human_model="tum_trb2024",
                        ring_placement="random")
    write_routes(ring, demand, seed=3, path=tmp_path / "r.rou.xml", horizon_s=60.0)
    vtypes, types = _parse(tmp_path / "r.rou.xml")
    humans = {v: t for v, t in types.items() if v.startswith("hdv.")}
    cavs = {v: t for v, t in types.items() if v.startswith("cav.")}
    assert len(humans) == 240 and len(cavs) == 60
    model = TUM_MODELS["tum_trb2024"]
    taus = []
    for vid, tid in humans.items():
        base, tau_cs = tid.rsplit("_t", 1)
        vt = vtypes[tid]
        tau = float(vt.get("tau"))
        assert abs(tau - int(tau_cs) / 100.0) < 1e-9, (vid, tid)
        assert vt.get("length") == vtypes[base.replace("hdv", "cav")].get("length")
        assert float(vt.get("accel")) == model.accel_mps2
        assert float(vt.get("decel")) == model.decel_mps2
        assert float(vt.get("emergencyDecel")) == model.emergency_decel_mps2
        assert float(vt.get("minGap")) == model.min_gap_m
        assert float(vt.get("sigma")) == 0.0
        assert float(vt.get("maxSpeedLat")) == model.max_speed_lat_mps
        taus.append(tau)
    taus = np.array(taus)
    assert taus.min() >= TAU_MIN_S
    # N(1.5, 0.5): 240 draws, mean within 4 standard errors, sd within 20 %
    assert abs(taus.mean() - 1.5) < 4 * 0.5 / np.sqrt(len(taus)), taus.mean()
    assert 0.4 < taus.std() < 0.6, taus.std()
    assert len(set(taus.round(2))) > 50  # one per vehicle, not one per class
    assert all(t.startswith("cav_") and "_t" not in t for t in cavs.values())
    assert not any(t.startswith("hdv_") and "_t" not in t for t in vtypes)  # none unused


def test_the_draw_is_the_seeds(ring, tmp_path):
    demand = DemandSpec(ring_density_vpkm=100.0, cav_share=0.0, human_model="tum_trc2025")
    runs = []
    for name, seed in (("a", 1), ("b", 1), ("c", 2)):
        write_routes(ring, demand, seed=seed, path=tmp_path / f"{name}.rou.xml",
                     horizon_s=60.0)
        runs.append((tmp_path / f"{name}.rou.xml").read_text())
    assert runs[0] == runs[1]
    assert _parse(tmp_path / "a.rou.xml")[1] != _parse(tmp_path / "c.rou.xml")[1]
    human_types = [v for k, v in _parse(tmp_path / "a.rou.xml")[0].items()
                   if k.startswith("hdv_")]
    assert any(float(v.get("minGap")) == 2.0 for v in human_types)  # TRC 2025: 2 m gap


def test_default_drivers_are_unchanged(ring, tmp_path):
    write_routes(ring, DemandSpec(ring_density_vpkm=100.0), seed=1,
                 path=tmp_path / "r.rou.xml", horizon_s=60.0)
    vtypes, types = _parse(tmp_path / "r.rou.xml")
    assert sorted(vtypes) == sorted([f"{k}_{c}" for k in ("cav", "hdv") for c in range(4)])
    assert float(vtypes["hdv_0"].get("tau")) == 1.3


def test_bad_human_models_are_config_errors():
    from cosim.config import load_scenario

    with pytest.raises(ConfigError, match="human_model must be one of sl2015"):
        DemandSpec(human_model="krauss")
    with pytest.raises(ConfigError, match='needs scenario.world = "sumo"'):
        load_scenario("tum_ring", {"demand.human_model": "tum_trb2024",
                                   "scenario.world": "road"})


def _tum_humans_run() -> dict:
    from cosim.config import load_scenario
    from cosim.sim.runner import run_scenario

    sc = load_scenario("tum_ring", {
        "demand.human_model": "tum_trb2024", "demand.cav_share": 0.5,
        "demand.ring_density_vpkm": 150.0, "scenario.step_length_s": 0.25,
        "scenario.duration_s": 60.0, "scenario.warmup_s": 20.0,
        "scenario.interval_s": 20.0, "outputs.sumo_collisions": True})
    res = run_scenario(sc)
    row = res.summary.iloc[0]
    return {"flow": float(row["edie_flow_vph"]), "speed": float(row["space_mean_speed_mps"]),
            "coll": int(row["collisions_sumo_cav"]) + int(row["collisions_geometric_cav"]),
            "teleports": int(row["teleports"])}


@pytest.mark.sumo
@pytest.mark.slow(seconds=30)
def test_tums_drivers_drive_on_tums_ring():
    got = run_isolated(_tum_humans_run, timeout_s=600)
    assert got["coll"] == 0 and got["teleports"] == 0, got
    assert got["flow"] > 1000.0 and got["speed"] > 2.0, got
