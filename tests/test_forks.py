"""Forks onto an off-ramp's strip at the joints of a user's main route
(``cosim/road/forks.py``).

The freeway of ``tests/test_several_ramps.py``, built with netconvert's defaults: where a
deceleration strip is added beside the road (m3 -> m4, m7 -> m8) the rightmost lane
leads both straight on and onto the strip. SUMO's drivers bound for the exit took the
second connection and jumped a lane's width sideways in one step. The runs here are SUMO's
drivers alone, in a process of their own.
"""

from __future__ import annotations

import numpy as np
import pytest
from sumo_cases.isolated import run_isolated
from test_corridor import netconvert_defaults, sumo_env
from test_several_ramps import EDGES, NODES, OD, OFFRAMPS, RAMPS, ROUTE

from cosim.road.spec import NetworkSpec

pytestmark = pytest.mark.sumo


def _spec(net_file: str) -> NetworkSpec:
    return NetworkSpec(kind="file", net_file=net_file, route_edges=ROUTE, ramp_edges=RAMPS,
                       offramp_edges=OFFRAMPS)


def test_the_forks_before_each_strip_are_found_and_taken_out_of_a_copy(tmp_path):
    from cosim.road.build import build_network
    from cosim.road.forks import forks
    from cosim.road.frame import load_road_network
    from cosim.road.sumo_net import read_sumo_net

    path = netconvert_defaults(tmp_path, NODES, EDGES)
    before = (tmp_path / "u.net.xml").read_bytes()
    assert forks(read_sumo_net(path), ROUTE, OFFRAMPS) == [("m3", "m4", 0, 0),
                                                           ("m7", "m8", 0, 0)]
    assert forks(read_sumo_net(path), ROUTE, []) == []  # forks into lanes that carry on stay
    net = build_network(_spec(path), cache_dir=tmp_path / "cache")
    assert net.forks_removed == (("m3", "m4", 0, 0), ("m7", "m8", 0, 0))
    assert net.source_file == (tmp_path / "u.net.xml").resolve()
    assert net.net_file != net.source_file
    assert (tmp_path / "u.net.xml").read_bytes() == before  # the user's file untouched
    assert forks(read_sumo_net(net.net_file), ROUTE, OFFRAMPS) == []
    # the same road: strips where they were (the junction lanes at the forks differ by
    # tenths of a metre in length), as wide as they were
    kept = load_road_network(path, kind="file", main_route=ROUTE, ramp_routes=RAMPS,
                             offramp_routes=OFFRAMPS)
    assert abs(net.length_m - kept.length_m) < 1.0
    assert np.abs(net.exit_strips - kept.exit_strips).max() < 0.5
    assert np.abs(net.entry_strips - kept.entry_strips).max() < 0.5
    mid = np.concatenate([net.exit_strips[:, :2].mean(axis=1),
                          net.entry_strips[:, :2].mean(axis=1), [100.0, 800.0, 1400.0]])
    assert np.abs(net.profile().edges(mid) - kept.profile().edges(mid)).max() < 1e-6
    # built once: the second load reads the same copy
    again = build_network(_spec(path), cache_dir=tmp_path / "cache")
    assert again.net_file == net.net_file


def _lateral_jumps(net_file: str, keep_forks: bool) -> dict:
    """SUMO's drivers alone on the freeway for 150 s: the largest lateral step (m) of a
    vehicle on the main road in one 0.1 s step, and how many exceed 1 m."""
    from cosim.config import load_scenario
    from cosim.sim.runner import run_scenario

    if keep_forks:
        import cosim.road.forks as forks_module

        forks_module.forks = lambda net, route, offramps: []
    sc = load_scenario("default", {
        "network.kind": "file", "network.net_file": net_file, "network.route_edges": ROUTE,
        "network.ramp_edges": RAMPS, "network.offramp_edges": OFFRAMPS,
        "demand.od_vph": OD, "demand.cav_share": 0.0, "scenario.duration_s": 150.0,
        "scenario.warmup_s": 30.0, "scenario.interval_s": 30.0,
        "outputs.trajectories": True, "outputs.sumo_collisions": True})
    res = run_scenario(sc)
    t = res.trajectories.sort_values(["id", "t_s"])
    step = t.groupby("id")["d_m"].diff().abs()
    dt = t.groupby("id")["t_s"].diff()
    step = step[np.isclose(dt, 0.1)]
    row = res.summary.iloc[0]
    return {"max_step_m": float(step.max()), "jumps": int((step > 1.0).sum()),
            "missed": int(row["missed_exits_hdv"]), "exits": int((res.trips.exit_s > 0).sum())}


@pytest.mark.slow(seconds=40)
def test_sumos_drivers_no_longer_jump_onto_a_strip(tmp_path):
    path = netconvert_defaults(tmp_path, NODES, EDGES)
    kept = run_isolated(_lateral_jumps, path, True, env=sumo_env(tmp_path))
    assert kept["jumps"] >= 5 and kept["max_step_m"] > 3.0, kept  # the artefact
    fixed = run_isolated(_lateral_jumps, path, False, env=sumo_env(tmp_path))
    assert fixed["jumps"] == 0 and fixed["max_step_m"] < 0.5, fixed
    # and they still leave by the exits, moving onto the strip along it
    assert fixed["exits"] >= 10 and fixed["missed"] <= max(2, fixed["exits"] // 10), fixed
