"""Every registered controller kind drives the ring in SUMO, and seed 002's formation
holds its shape on the road.

* ``cosim run ring --set controller.kind=KIND --set scenario.duration_s=30`` for each
  registered kind (one SUMO process each, 30 s simulated): exit 0, no collision
  with a CAV, and config.toml records the kind's resolved parameters (every parameter
  with a value, road defaults included) and reads back to the same law.
* ``formation`` (controllers/road/formation.py): unit properties of the group law, the
  built-in scenario ``formation`` in the SUMO-free road world (hexagons and 2 x 3
  blocks) and in SUMO: from a random start the six hexagons converge within 45 s and
  then hold their shape to 0.1 m while the ring flows at 25 m/s, with no collision and
  no boundary violation. Measured in SUMO, worst group below 0.1 m from: hexagons
  31-41 s, 2 x 3 blocks (36 veh/km) 39-44 s, seeds 1, 2, 3, 7, 42 (32 s for seed 42).
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from sumo_cases.isolated import cosim_cli, run_isolated

from controllers import registry
from controllers.observation import Observation
from controllers.road.formation import RoadFormation, RoadFormationParams
from cosim.config.scenario import load_scenario
from cosim.sim.runner import run_scenario

KINDS = ["flocking", "flocking_timegap", "boundary_points", "formation", "vicsek", "sumo"]
#: The run's measurement must fit in 30 s (ring.toml measures after 60 s).
SHORT = ["--set", "scenario.warmup_s=10", "--set", "scenario.interval_s=20"]


@pytest.fixture(scope="module")
def sumo_env(tmp_path_factory) -> dict:
    env = dict(os.environ)
    env["COSIM_NETWORK_CACHE"] = str(tmp_path_factory.mktemp("network_cache"))
    return env


def _cosim_run(tmp_path: Path, env: dict, *args: str) -> tuple[SimpleNamespace, Path]:
    """``cosim run ARGS`` in a process of its own (``sumo_cases/isolated.py``): its exit
    status and stdout, and its output folder."""
    out = tmp_path / "out"
    code, stdout = run_isolated(cosim_cli, ["run", *args, "--quiet", "--out", str(out)],
                                str(tmp_path), env=env)
    assert code == 0, f"cosim run {' '.join(args)}: exit {code}\n{stdout[-2000:]}"
    return SimpleNamespace(returncode=code, stdout=stdout), out


def _plain(value):
    """A parameter as TOML writes it back (tuples as lists)."""
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def test_every_kind_of_the_issue_is_registered():
    assert set(KINDS) <= set(registry.kinds())


# --------------------------------------------------------------------------------------
# Every kind on the ring in SUMO
# --------------------------------------------------------------------------------------


@pytest.mark.sumo
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.slow(seconds=5)
def test_every_kind_drives_the_ring_in_sumo(tmp_path, sumo_env, kind):
    proc, out = _cosim_run(tmp_path, sumo_env, "ring", "--set", f"controller.kind={kind}",
                           "--set", "scenario.duration_s=30", *SHORT)
    assert f"{kind} CAVs, sumo world" in proc.stdout
    s = pd.read_csv(out / "summary.csv").iloc[0]
    assert s["collisions_geometric_cav"] == 0 and s["collisions_sumo_cav"] == 0
    assert s["vehicles_inserted"] == 60 and s["teleports"] == 0
    assert s["space_mean_speed_mps"] > 5.0  # the ring moves

    cfg = tomllib.loads((out / "config.toml").read_text())["controller"]
    assert cfg["kind"] == kind
    e = registry.entry(kind)
    resolved = registry.params_dict(registry.make_params(kind, {}))
    for field in e.run_fields:  # set by the run (the law's step), never written as a param
        resolved.pop(field)
    expected = {k: _plain(v) for k, v in resolved.items() if v is not None}
    assert cfg.get("params", {}) == expected
    if e.params_type is not None:
        assert len(expected) >= 3  # the gains are there, not an empty table
    # the written config reads back to the same law with the same parameters
    back = load_scenario(out / "config.toml")
    assert back.controller.kind == kind
    assert registry.params_dict(back.controller.law_params()) == registry.params_dict(
        registry.make_params(kind, {}))


# --------------------------------------------------------------------------------------
# The formation law: unit properties
# --------------------------------------------------------------------------------------


def _shape_obs(params: RoadFormationParams, order, offset=(100.0, 0.0), v=25.0,
               period=None, desired=25.0, jitter=None) -> Observation:
    """One group at its shape, members listed in ``order`` (slot numbers)."""
    ref, _ = params.shape_m()
    q = ref[list(order)] + np.asarray(offset)
    if jitter is not None:
        q = q + jitter
    if period is not None:
        q[:, 0] = np.mod(q[:, 0], period)
    n = len(q)
    return Observation(q=q, p=np.tile([v, 0.0], (n, 1)), ids=np.array(
        [f"cav.{k}" for k in order], dtype=object), desired_speed=np.full(n, desired),
        road_edges=np.tile([-5.1, 5.1], (n, 1)), period_s=period)


@pytest.mark.parametrize("shape", ["hexagon", "block"])
def test_a_group_at_its_shape_and_speed_is_at_rest(shape):
    params = RoadFormationParams(shape=shape)
    law = RoadFormation(params)
    order = np.random.default_rng(3).permutation(law.size)  # ids in no spatial order
    u = law.compute(_shape_obs(params, order))
    np.testing.assert_allclose(u, 0.0, atol=1e-12)
    m = law.extra_metrics()
    assert m["formation_error_m"] == pytest.approx(0.0, abs=1e-12)
    assert m["formation_groups"] == 1
    # slots were assigned by position: every member got the slot it stands on
    assert [law._slot[f"cav.{k}"] for k in order] == list(order)


def test_the_shape_is_seed_002s_hexagon_scaled_to_the_road():
    params = RoadFormationParams()
    ref, pairs = params.shape_m()
    assert ref.shape == (7, 2) and len(pairs) == 15  # 30 ordered constraints
    assert np.ptp(ref[:, 0]) == pytest.approx(2 * params.d_long_m)  # 40 m long
    assert np.ptp(ref[:, 1]) == pytest.approx(np.sqrt(3) * params.d_lat_m)  # 5.5 m wide
    block = RoadFormationParams(shape="block").shape_m()
    assert block[0].shape == (6, 2) and len(block[1]) == 3 + 4 + 2 * 2  # rows, cols, diags


def test_formation_forces_do_not_move_the_group_and_track_the_reference():
    """Shape forces are internal (they sum to zero over the group); the group's mean
    speed tracks the smallest desired speed; the ring's seam changes nothing."""
    rng = np.random.default_rng(0)
    params = RoadFormationParams(K_ref=0.0, K_centre=0.0)
    jitter = rng.normal(0, 3.0, (7, 2)) * [1, 0.3]
    law = RoadFormation(params)
    u = law.compute(_shape_obs(params, range(7), jitter=jitter))
    assert np.abs(u).max() > 0.1
    np.testing.assert_allclose(u.sum(axis=0), 0.0, atol=1e-9)
    assert law.extra_metrics()["formation_error_m"] > 0.5
    # across a ring's seam: the same accelerations
    seam = RoadFormation(params)
    u_seam = seam.compute(_shape_obs(params, range(7), offset=(995.0, 0.0), period=1000.0,
                                     jitter=jitter))
    np.testing.assert_allclose(u_seam, u, atol=1e-9)
    # reference: 23 m/s desired for one member -> the whole group accelerates equally
    law = RoadFormation(RoadFormationParams())
    obs = _shape_obs(RoadFormationParams(), range(7), v=20.0)
    desired = np.full(7, 30.0)
    desired[4] = 23.0
    obs = Observation(q=obs.q, p=obs.p, ids=obs.ids, desired_speed=desired,
                      road_edges=obs.road_edges)
    u = law.compute(obs)
    np.testing.assert_allclose(u[:, 0], 0.5 * (23.0 - 20.0), atol=1e-12)


def test_an_incomplete_group_only_tracks_its_desired_speed():
    params = RoadFormationParams()
    law = RoadFormation(params)
    obs = _shape_obs(params, range(5), v=20.0)  # 5 of 7 on the road
    u = law.compute(obs)
    np.testing.assert_allclose(u[:, 0], params.K_ref * (25.0 - 20.0))
    np.testing.assert_allclose(u[:, 1], 0.0)
    assert np.isnan(law.extra_metrics()["formation_error_m"])
    assert law.extra_metrics()["formation_groups"] == 0


# --------------------------------------------------------------------------------------
# The built-in scenario: SUMO-free road world and SUMO
# --------------------------------------------------------------------------------------


def _converged(flock: pd.DataFrame, bound_m: float) -> float:
    """First time (s) after which the worst group's error stays below ``bound_m``."""
    t = flock["t_s"].to_numpy()
    bad = np.flatnonzero(flock["formation_error_max_m"].to_numpy() >= bound_m)
    return float(t[0]) if not len(bad) else (float(t[bad[-1] + 1]) if bad[-1] + 1 < len(t)
                                             else np.inf)


@pytest.mark.parametrize("over, n_groups", [
    ({}, 6),
    ({"controller.params.shape": "block", "demand.ring_density_vpkm": 36.0}, 6),
    ({"demand.ring_placement": "even"}, 6),
])
def test_formation_scenario_converges_in_the_road_world(over, n_groups):
    sc = load_scenario("formation", {"scenario.world": "road", "scenario.warmup_s": 0.5,
                                     "scenario.duration_s": 90.0, **over})
    res = run_scenario(sc)
    s = res.summary.iloc[0]
    assert s["collisions_geometric_cav"] == 0 and s["boundary_vehicle_steps"] == 0
    f = res.flock
    assert (f["formation_groups"] == n_groups).all()
    assert f["formation_error_max_m"].iloc[0] > 10.0  # it had something to converge from
    assert _converged(f, 0.1) < 60.0
    assert s["space_mean_speed_mps"] > 23.0


@pytest.mark.sumo
@pytest.mark.slow(seconds=4.5)
def test_formation_scenario_in_sumo_converges_and_holds_its_shape(tmp_path, sumo_env):
    """Measured from t = 0.5 s: worst group's error from > 20 m to < 0.1 m within 45 s,
    then held for the remaining 2 minutes."""
    _, out = _cosim_run(tmp_path, sumo_env, "formation", "--set", "scenario.warmup_s=0.5")
    s = pd.read_csv(out / "summary.csv").iloc[0]
    assert s["collisions_geometric_cav"] == 0 and s["collisions_sumo_cav"] == 0
    assert s["boundary_vehicle_steps"] == 0 and s["teleports"] == 0
    f = pd.read_csv(out / "flock.csv")
    assert (f["formation_groups"] == 6).all()
    assert f["formation_error_max_m"].iloc[0] > 20.0
    t_conv = _converged(f, 0.1)
    assert t_conv < 45.0
    held = f[f["t_s"] >= t_conv]
    assert held["t_s"].iloc[-1] > 170.0 and held["formation_error_max_m"].max() < 0.1
    assert s["flock_formation_error_m"] == pytest.approx(f["formation_error_m"].mean())
    assert s["space_mean_speed_mps"] > 23.0  # the ring flows (desired 25 m/s)


@pytest.mark.sumo
def test_formation_builtin_scenario_summary(tmp_path, sumo_env):
    """``cosim run formation`` as shipped: measured after the 60 s warm-up, the shape
    error is below 5 cm and every figure of safety is clean."""
    _, out = _cosim_run(tmp_path, sumo_env, "formation")
    s = pd.read_csv(out / "summary.csv").iloc[0]
    assert s["flock_formation_error_m"] < 0.05 and s["flock_formation_error_max_m"] < 0.1
    assert s["collisions_geometric_cav"] == 0 and s["boundary_vehicle_steps"] == 0
    assert s["max_standstill_s"] < 2.0 and s["vehicles_stopped_long"] == 0  # it flows
    cfg = tomllib.loads((out / "config.toml").read_text())["controller"]
    assert cfg["kind"] == "formation" and cfg["params"]["shape"] == "hexagon"
