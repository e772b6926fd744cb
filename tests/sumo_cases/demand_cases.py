"""SUMO runs of tests/test_demand.py, one simulation per call: each function starts libsumo,
so the tests call it in a process of its own (:func:`sumo_cases.isolated.run_isolated`),
never in the test process. Results come back as JSON would carry them."""

from __future__ import annotations

import contextlib
import io
import json


def human_driver_attributes(net_file: str, routes: str, extra: list[str]) -> dict:
    """The first vehicle's vType as SUMO holds it (Krauss tau and imperfection, lateral gap
    and speed) and its SL2015 ``lcPushy``, ``lcAssertive``, ``lcTimeToImpatience`` (None
    where the lane-change model has no such parameter)."""
    import libsumo as t

    t.start(["sumo", "-n", net_file, "-r", routes, "--no-step-log", "true",
             "--step-length", "0.1", *extra])
    while t.vehicle.getIDCount() == 0:
        t.simulationStep()
    vid = t.vehicle.getIDList()[0]
    typ = t.vehicle.getTypeID(vid)
    lc = {}
    for key in ("lcPushy", "lcAssertive", "lcTimeToImpatience"):
        try:
            lc[key] = float(t.vehicle.getParameter(vid, "laneChangeModel." + key))
        except Exception:
            lc[key] = None
    res = {"tau": t.vehicletype.getTau(typ),
           "minGapLat": t.vehicletype.getMinGapLat(typ),
           "maxSpeedLat": t.vehicletype.getMaxSpeedLat(typ),
           "imperfection": t.vehicletype.getImperfection(typ), **lc}
    t.close()
    return json.loads(json.dumps(res))


def ring_insertion(cache_dir: str, routes: str) -> dict:
    """The 300 m ring (built in ``cache_dir``) with the route file ``routes``: after the
    first step, the vehicles SUMO has and how far their lane position, lateral position
    and speed factor are from the file's; after 60 s more, the vehicles, collisions and
    arrivals."""
    import xml.etree.ElementTree as ET

    import libsumo as t

    from cosim.road import NetworkSpec, build_network

    net = build_network(NetworkSpec(kind="ring", circumference_m=300.0), cache_dir)
    t.start(["sumo", "-n", str(net.net_file), "-r", routes, "--no-step-log",
             "true", "--lateral-resolution", "0.8", "--step-length", "0.1", "--seed", "9",
             "--collision.action", "warn"])
    t.simulationStep()
    n0 = t.vehicle.getIDCount()
    xml = {v.get("id"): v for v in ET.parse(routes).getroot().iter("vehicle")}
    pos_err = max(abs(t.vehicle.getLanePosition(v) - float(xml[v].get("departPos")))
                  for v in t.vehicle.getIDList())
    lat_err = max(abs(t.vehicle.getLateralLanePosition(v) - float(xml[v].get("departPosLat")))
                  for v in t.vehicle.getIDList())
    factor = max(abs(t.vehicle.getSpeedFactor(v) - float(xml[v].get("speedFactor")))
                 for v in t.vehicle.getIDList())
    collisions = 0
    for _ in range(600):
        t.simulationStep()
        collisions += t.simulation.getCollidingVehiclesNumber()
    out = {"n0": n0, "n60": t.vehicle.getIDCount(), "pos_err": pos_err,
           "lat_err": lat_err, "factor": factor, "collisions": collisions,
           "arrived": t.simulation.getArrivedNumber()}
    t.close()
    return json.loads(json.dumps(out))


def calibrate_humans_child(task: dict) -> dict:
    """``experiments/calibrate_humans.py --child TASK`` in this process: its ``child_main``
    (vType overrides, then the task), and the ``RESULT <json>`` line it prints, read."""
    from experiments import calibrate_humans

    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        calibrate_humans.child_main(task)
    lines = [ln for ln in text.getvalue().splitlines() if ln.startswith("RESULT ")]
    assert lines, f"no RESULT line from calibrate_humans.child_main:\n{text.getvalue()[-2000:]}"
    return json.loads(lines[-1][len("RESULT "):])
