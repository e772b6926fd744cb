"""The road frame against SUMO on one network, in a process of its own (libsumo: one
simulation per process): run by tests/test_road_frame.py through
:func:`sumo_cases.isolated.run_isolated`.

Every vehicle, every step: SUMO's own x, y (``vehicle.getPosition``) against our (s, d)
mapped back to x, y (``RoadNetwork.xy_of``); a third of the vehicles are moved across the
road by commands in the road frame (``lateral_lane_position`` at the position they reach
in the step), and the d they reach is compared with the command; our road edges against
SUMO's lane borders.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from cosim.road.frame import load_road_network


def sumo_case(name: str, folder: str, net_file: str | None = None,
              route: list[str] | None = None, steps: int = 400, dt: float = 0.1) -> dict:
    """SUMO's x, y against the frame's on network ``name`` (``onramp``: the built-in
    on-ramp, built here in ``$COSIM_NETWORK_CACHE``; else the example network
    ``net_file`` with main route ``route``), route file written to ``folder``. Starts
    SUMO: call it in a process of its own. Returns the result as JSON carries it."""
    import libsumo as t

    folder = Path(folder)
    if name == "onramp":
        from cosim.road.build import build_network
        from cosim.road.spec import NetworkSpec

        rn = build_network(NetworkSpec(kind="onramp", length_m=600.0, merge_position_m=300.0,
                                       ramp_length_m=200.0))
        net_file, route, ramp = rn.net_file, rn.main_route, rn.ramp_route
    else:
        ramp = None
        rn = load_road_network(net_file, kind="file", main_route=tuple(route))
    rng = np.random.default_rng(1)
    rou = folder / f"{name}.rou.xml"
    lines = ["<routes>",
             '  <vType id="car" length="4.5" width="1.8" laneChangeModel="SL2015" '
             'latAlignment="arbitrary" minGapLat="0.3"/>',
             f'  <route id="main" edges="{" ".join(route)}"/>']
    if ramp:
        lines.append(f'  <route id="ramp" edges="{" ".join(ramp)}"/>')
    w_main = float(rn.width_at(np.array([1.0]))[0])
    for i in range(40):
        for r in ("main", "ramp") if ramp else ("main",):
            w = w_main if r == "main" else rn.ramp_width_m
            lat = rng.uniform(-0.5 * w + 1.0, 0.5 * w - 1.0)
            lines.append(f'  <vehicle id="{r}{i}" type="car" route="{r}" depart="{i:.1f}" '
                         f'departSpeed="max" departPosLat="{lat:.2f}"/>')
    rou.write_text("\n".join([*lines, "</routes>"]) + "\n")
    t.start(["sumo", "-n", str(net_file), "-r", str(rou), "--no-step-log", "true",
             "--lateral-resolution", "0.8", "--step-length", str(dt),
             "--collision.action", "none", "--no-warnings", "true"])
    out = {"n": 0, "worst_xy_m": 0.0, "where": None, "on_junction_lanes": 0,
           "worst_command_m": 0.0, "n_commanded": 0, "worst_edge_m": 0.0,
           "ramp_samples": 0, "ramp_max_d_minus_right_m": -math.inf, "seen_on": {}}
    commanded: dict[str, tuple] = {}
    # SUMO's borders of each main-route lane's edge, in that lane's lateral coordinate (m):
    # right of the rightmost lane, left of the leftmost (an acceleration lane beside)
    borders = {}
    for e in route:
        ws = [t.lane.getWidth(f"{e}_{i}") for i in range(t.edge.getLaneNumber(e))]
        for i, w in enumerate(ws):
            borders[f"{e}_{i}"] = (-0.5 * w - sum(ws[:i]), 0.5 * w + sum(ws[i + 1:]))
    for step in range(steps):
        t.simulationStep()
        ids = list(t.vehicle.getIDList())
        if not ids:
            continue
        lanes = [t.vehicle.getLaneID(v) for v in ids]
        pos = np.array([t.vehicle.getLanePosition(v) for v in ids])
        lat = np.array([t.vehicle.getLateralLanePosition(v) for v in ids])
        xy = np.array([t.vehicle.getPosition(v) for v in ids])
        s, d = rn.lane_frame(lanes, pos, lat)
        err = np.hypot(*(rn.xy_of(s, d) - xy).T)
        i = int(np.argmax(err))
        if err[i] > out["worst_xy_m"]:
            out["worst_xy_m"] = float(err[i])
            out["where"] = [ids[i], lanes[i], float(pos[i]), float(lat[i])]
        out["n"] += len(ids)
        out["on_junction_lanes"] += sum(x.startswith(":") for x in lanes)
        for x in lanes:
            out["seen_on"][x] = out["seen_on"].get(x, 0) + 1
        for j, v in enumerate(ids):
            if v in commanded:
                e = abs(d[j] - commanded[v][0])
                if e > out["worst_command_m"]:
                    out["worst_command_m"] = e
                    out["where_command"] = [v, lanes[j], float(pos[j]), *commanded[v][1:]]
                out["n_commanded"] += 1
        right, left = rn.edges_at(s)
        # our road edges against SUMO's lane borders, for vehicles on the main road's
        # lanes: how far the body reaches beyond the edge, in our frame and in SUMO's
        on_lane = np.array([x in borders for x in lanes], dtype=bool)
        if on_lane.any():
            b = np.array([borders.get(x, (0.0, 0.0)) for x in lanes])[on_lane]
            ours = np.maximum(right[on_lane] - (d[on_lane] - 0.9),
                              (d[on_lane] + 0.9) - left[on_lane])
            theirs = np.maximum(b[:, 0] - (lat[on_lane] - 0.9), (lat[on_lane] + 0.9) - b[:, 1])
            e = np.abs(ours - theirs)
            if e.max() > out["worst_edge_m"]:
                out["worst_edge_m"] = float(e.max())
                j = np.flatnonzero(on_lane)[int(np.argmax(e))]
                out["where_edge"] = [ids[j], lanes[j], float(pos[j]), float(lat[j])]
        if ramp:
            on_ramp = np.array([x == f"{ramp[0]}_0" for x in lanes], dtype=bool)
            if on_ramp.any():
                out["ramp_samples"] += int(on_ramp.sum())
                out["ramp_max_d_minus_right_m"] = max(out["ramp_max_d_minus_right_m"],
                                                      float((d - right)[on_ramp].max()))
        # a third of the main vehicles: a lateral target sweeping across the road, set in
        # the road frame at the position each reaches in the step
        commanded = {}
        for j, v in enumerate(ids):
            if not (v.startswith("main") and int(v[4:]) % 3 == 0):
                continue
            t.vehicle.setLaneChangeMode(v, 0)
            t.vehicle.setSpeedMode(v, 0)  # as our CAVs: x += v_next dt exactly
            v_next = t.vehicle.getSpeed(v)
            t.vehicle.setSpeed(v, v_next)
            frac = 0.5 + 0.45 * math.sin(0.05 * step + int(v[4:]))
            target = right[j] + 0.9 + frac * (left[j] - right[j] - 1.8)
            la = rn.lateral_lane_position([lanes[j]], pos[j:j + 1] + v_next * dt,
                                          np.array([target]))
            t.vehicle.setLateralLanePosition(v, float(la[0]))
            commanded[v] = (target, lanes[j], float(pos[j]), float(la[0]))
    t.close()
    return json.loads(json.dumps(out))
