"""One user-drawn road (cosim.road.user_roads) driven by the lane-free law in SUMO, with
every CAV read back from SUMO every step (run in a child process by
tests/test_user_roads.py).

Read back per step, for every vehicle SUMO has (after ``advance``, before the law):

* SUMO's own x, y of the front bumper's centre (``vehicle.getPosition``) against our
  frame's (s, d) of that point mapped back to x, y (``RoadNetwork.xy_of``): the two
  frames agree wherever the vehicle is, joints and junction lanes included;
* for each CAV, its lateral position in SUMO's lane coordinates one step after the law
  commanded it, against the command (``d`` where SUMO put it against ``d_next``): the
  command lands;
* the run's collision counts, SUMO's check and ours, and the CAV-steps outside the road.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def run(kind: str, alignment: str | None, seed: int, cav_share: float, inflow_vph: float,
        duration_s: float, folder: str) -> dict:
    from cosim.config import load_scenario
    from cosim.road.user_roads import build, draw
    from cosim.sim.runner import run_scenario

    road = draw(kind, seed, alignment)
    net_file = build(road, Path(folder))
    sc = load_scenario("default", {
        "network.kind": "file", "network.net_file": str(net_file),
        "network.route_edges": list(road.route), "demand.inflow_vph": inflow_vph,
        "demand.cav_share": cav_share, "controller.kind": "flocking",
        "scenario.seed": seed, "scenario.duration_s": duration_s, "scenario.warmup_s": 30.0,
        "scenario.interval_s": 30.0, "outputs.sumo_collisions": True})
    out = {"worst_xy_m": 0.0, "where_xy_m": None, "worst_xy_beside_m": 0.0,
           "where_xy_beside_m": None, "worst_command_m": 0.0, "command_where": None,
           "n_vehicle_steps": 0, "n_junction_steps": 0, "n_commands": 0}
    commanded: dict[str, float] = {}

    def attach(loop) -> None:
        net = loop.world.net
        chain = set(net.tables.chain_keys.tolist())

        def read_back(step) -> None:
            veh = loop.world.ts.vehicle  # SUMO starts after the hooks are attached
            snap = step.state
            if snap is None or not len(snap.ids):
                return
            ids = list(snap.ids)
            xy = np.array([veh.getPosition(v) for v in ids], dtype=float)
            lanes = [veh.getLaneID(v) for v in ids]
            ok = np.isfinite(snap.s_front)
            # a junction lane beside the chain of lanes the frame follows (where the lane
            # count changes): SUMO's lane coordinates carry the lateral position along it
            # from the lane before, the frame too; SUMO draws it on its own curve
            beside = np.array([ln.startswith(":") and net.lane_keys([ln])[0] not in chain
                               for ln in lanes], dtype=bool)
            err = np.hypot(*(net.xy_of(snap.s_front[ok], snap.d[ok]) - xy[ok]).T)
            for name, sel in (("worst_xy_m", ~beside[ok]), ("worst_xy_beside_m", beside[ok])):
                if sel.any() and err[sel].max() > out[name]:
                    i = int(np.flatnonzero(ok)[np.flatnonzero(sel)[int(np.argmax(err[sel]))]])
                    out[name] = float(err[sel].max())
                    out[name.replace("worst", "where")] = [ids[i], lanes[i],
                                                          float(snap.s_front[i])]
            out["n_vehicle_steps"] += int(ok.sum())
            out["n_junction_steps"] += sum(ln.startswith(":") for ln in lanes)
            for i, v in enumerate(ids):
                if v in commanded:
                    e = abs(float(snap.d[i]) - commanded[v])
                    out["n_commands"] += 1
                    if e > out["worst_command_m"]:
                        out["worst_command_m"] = e
                        out["command_where"] = [v, veh.getLaneID(v), float(snap.s_front[i])]
            commanded.clear()

        def remember(step) -> None:  # what the law commanded, for the next read-back
            if step.cav_ids is None or step.d_next is None:
                return
            commanded.update(zip(list(step.cav_ids), np.asarray(step.d_next).tolist(),
                                 strict=True))

        loop.hooks.add("observe", read_back, "after")
        loop.hooks.add("apply", remember, "after")

    row = run_scenario(sc, hooks=attach).summary.iloc[0]
    for k in ("collisions_geometric_cav", "collisions_sumo_cav", "boundary_vehicle_steps_cav",
              "max_standstill_s", "blocked_windows", "vehicles_arrived",
              "safety_edge_activations", "sumo_lateral_resolution_m"):
        out[k] = float(row[k])
    return out
