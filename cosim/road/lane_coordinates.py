"""SUMO's lane coordinates on a route: where each lane's position 0 and centre lie in the
road frame, as SUMO carries a vehicle's lane position and lateral lane position from lane
to lane (:mod:`cosim.road.frame` maps every main-route lane by them).

SUMO moves a vehicle from a lane onto the junction lane and the next lane keeping its
lateral lane position, shifted only where the lanes' shapes do not meet (``MSLink``;
:func:`link_shift`, 0 on netconvert's networks); its collision check and its drivers
compare those positions. ``tb`` below is the frame's lane tables
(:class:`cosim.road.lane_tables.Tables`: ``index``, ``measure``, ``par``, ``par_s0``,
``par_d0``); lengths in m.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from cosim.road.sumo_net import connections, lanes_of, reference_lane, via_chain


def centre_on_edge(lane: Any) -> float:
    """Lateral position (m) of a lane's centre on its edge, from the edge's right side (the
    lanes of lower index are to the right: SUMO's ``getRightSideOnEdge`` plus half a width)."""
    edge = lane.getEdge()
    right = sum(float(ln.getWidth()) for ln in edge.getLanes() if ln.getIndex() < lane.getIndex())
    return right + 0.5 * float(lane.getWidth())


def link_shift(before: Any, after: Any) -> float:
    """SUMO's lateral shift (m, added to the lateral lane position) of a vehicle passing from
    lane ``before`` onto ``after`` (``MSLink``: only where the two shapes do not meet, and
    only for links through or out of a junction lane; netconvert's junction lanes always
    meet the lanes they join, so this is 0 on every network netconvert builds).

    Where the shapes do not meet SUMO keeps the vehicle where it is: ``after``'s start lies
    ``dist`` to the right of ``before``'s end gives ``+dist`` (the vehicle is that much
    left of the new centre)."""
    internal = after.getEdge().getFunction() == "internal" or \
        before.getEdge().getFunction() == "internal"
    a = np.asarray(before.getShape(), dtype=float)[:, :2]
    b = np.asarray(after.getShape(), dtype=float)[:, :2]
    gap = b[0] - a[-1]
    dist = float(np.hypot(*gap))
    if not internal or dist == 0.0 or len(a) < 2:
        return 0.0
    t = a[-1] - a[-2]
    n_left = np.array([-t[1], t[0]]) / max(float(np.hypot(*t)), 1e-12)
    return dist if float(gap @ n_left) < 0.0 else -dist


def lane_coordinates(net: Any, tb: Any, route: Sequence[str], periodic: bool,
                      chain_off: dict[int, float]) -> dict[int, tuple[float, float]]:
    """SUMO's own lane coordinates of every main-route lane: table key -> ``(s0, d0)`` (m)
    such that a vehicle at lane position ``pos`` and lateral lane position ``lat`` is at
    ``s = s0 + pos``, ``d = d0 + lat``.

    SUMO moves a vehicle from lane to lane keeping its lateral lane position (plus
    :func:`link_shift`, 0 on netconvert's networks): its collision check, its drivers'
    view of each other and the lateral bookkeeping of a vehicle's back on the lanes it
    still occupies all compare lateral lane positions as if the lanes' centres lined up
    across every joint (MSVehicle, MSLane::detectCollisionBetween). Where a lane's centre
    moves sideways at a joint (a width change built with netconvert's defaults hangs the
    narrower lane from the left border), SUMO draws a vehicle that keeps its lateral lane
    position jumping sideways along the short junction lane between them, at an angle;
    in SUMO's own coordinates it drives straight, and the neck lies centred. The road
    frame follows SUMO's coordinates on the main route, so that what the law keeps apart
    SUMO keeps apart (tests/test_user_roads.py).

    ``d0``: the first edge's lanes are placed across it as SUMO places them (the middle
    lane's centre, or the border between the two middle lanes, at 0); each connection
    carries the lateral position from a lane onto its junction lanes and the next edge's
    lane; the next edge's other lanes are placed across that edge. ``s0``: the measure's
    chain offsets (SUMO's lane lengths summed); a lane beside the chain starts where its
    edge's chain lane starts, a junction lane where the lane before it ends.
    """
    out: dict[int, tuple[float, float]] = {}
    idx = tb.index
    period = tb.measure.s_period if periodic else None

    def put(lane: Any, s0: float, d0: float) -> None:
        k = idx[lane.getID()]
        if k not in out:
            if period is not None:
                s0 = float(np.mod(s0, period))
            out[k] = (float(chain_off.get(k, s0)), d0)

    edges = [net.getEdge(e) for e in route]
    first = lanes_of(edges[0])
    mid = first[len(first) // 2]
    centre = centre_on_edge(mid) - (0.0 if len(first) % 2 else 0.5 * float(mid.getWidth()))
    d_edge = {ln.getID(): centre_on_edge(ln) - centre for ln in first}
    for k, edge in enumerate(edges):
        ref = reference_lane(edge)
        nxt_id = route[k + 1] if k + 1 < len(route) else (route[0] if periodic else None)
        conns = connections(edge, nxt_id) if nxt_id is not None else []
        main_conn = next((c for c in conns if c.getFromLane() is ref), conns[0]) \
            if conns else None
        chain_lane = main_conn.getFromLane() if main_conn is not None else ref
        s_edge = float(chain_off[idx[chain_lane.getID()]])
        for ln in lanes_of(edge):
            put(ln, s_edge, d_edge[ln.getID()])
        if main_conn is None:
            break
        d_next = None
        for conn in [main_conn] + [c for c in conns if c is not main_conn]:
            a = conn.getFromLane()
            s = out[idx[a.getID()]][0] + float(a.getLength())
            d = out[idx[a.getID()]][1]
            prev = a
            for via in via_chain(net, conn, nxt_id):
                d += link_shift(prev, via)
                put(via, s, d)
                s += float(via.getLength())
                prev = via
            d += link_shift(prev, conn.getToLane())
            if conn is main_conn:
                d_next = (conn.getToLane(), d)
        if k + 1 < len(edges):
            to_lane, d_to = d_next
            c_to = centre_on_edge(to_lane)
            d_edge = {ln.getID(): d_to + centre_on_edge(ln) - c_to
                      for ln in lanes_of(edges[k + 1])}
    return out


def use_lane_coordinates(tb: Any, coords: dict[int, tuple[float, float]],
                          chain_off: dict[int, float]) -> None:
    """Map every main-route lane by SUMO's lane coordinates (:func:`lane_coordinates`):
    ``s = s0 + pos``, ``d = d0 + lat`` (the parallel path); the other lanes (an on-ramp
    before it joins the road) keep the projection onto the reference line."""
    for k, (s0, d0) in coords.items():
        tb.par[k] = True
        tb.par_s0[k] = s0
        tb.par_d0[k] = round(d0, 9)
    keys = np.array(sorted(chain_off, key=chain_off.get), dtype=np.int64)
    object.__setattr__(tb, "chain_keys", keys)
    object.__setattr__(tb, "chain_s0", np.array([chain_off[int(k)] for k in keys]))
