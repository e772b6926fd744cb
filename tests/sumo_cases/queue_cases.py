"""SUMO run of tests/test_standing_queue.py: one simulation per call, in a process of its
own (:func:`sumo_cases.isolated.run_isolated`). Results come back as JSON would carry them."""

from __future__ import annotations

import json


def queue_insertion(net_file: str, routes: str, sublanes: bool) -> dict:
    """The route file's standing queue in SUMO: after the first step, the vehicles SUMO has,
    how far their edge, lane position and lateral position are from the file's (the edge
    is the route's ``departEdge``-th), the edges they stand on, their largest speed; after
    40 s more, collisions, teleports and the vehicles still stopped. ``sublanes``: SUMO's
    sublane model (a lane-free road; off for a lane network's LC2013)."""
    import xml.etree.ElementTree as ET

    import libsumo as t

    lateral = ["--lateral-resolution", "0.2"] if sublanes else []
    t.start(["sumo", "-n", net_file, "-r", routes, "--no-step-log", "true", *lateral,
             "--step-length", "0.1", "--seed", "1", "--collision.action", "warn"])
    t.simulationStep()
    root = ET.parse(routes).getroot()
    edges = {r.get("id"): r.get("edges").split() for r in root.iter("route")}
    xml = {v.get("id"): v for v in root.iter("vehicle")}
    queue = [v for v in t.vehicle.getIDList() if ".queue." in v]
    wrong_edge = sum(
        t.vehicle.getRoadID(v) != edges[xml[v].get("route")][int(xml[v].get("departEdge", 0))]
        for v in queue)
    pos_err = max(abs(t.vehicle.getLanePosition(v) - float(xml[v].get("departPos")))
                  for v in queue)
    lat = [v for v in queue if xml[v].get("departPosLat") is not None]
    lat_err = max((abs(t.vehicle.getLateralLanePosition(v) - float(xml[v].get("departPosLat")))
                   for v in lat), default=0.0)
    lanes_err = sum(t.vehicle.getLaneIndex(v) != int(xml[v].get("departLane")) for v in queue)
    v_max = max(t.vehicle.getSpeed(v) for v in queue)
    n_edges = len({t.vehicle.getRoadID(v) for v in queue})
    collisions = teleports = 0
    for _ in range(400):
        t.simulationStep()
        collisions += t.simulation.getCollidingVehiclesNumber()
        teleports += t.simulation.getStartingTeleportNumber()
    stopped = sum(t.vehicle.getSpeed(v) < 0.1 for v in t.vehicle.getIDList())
    out = {"n0": len(queue), "wrong_edge": wrong_edge, "pos_err": pos_err, "lat_err": lat_err,
           "lanes_err": lanes_err, "v_max": v_max, "edges": n_edges, "collisions": collisions,
           "teleports": teleports, "stopped_at_40s": stopped}
    t.close()
    return json.loads(json.dumps(out))
