"""The reference line of the main route, built from the lanes as sumolib reads them.

The reference line (:func:`reference_line`): the centre line of the main route's lanes,
edge after edge, joined through the junction lanes SUMO drives on (an edge whose lanes sit
elsewhere relative to the edge as drawn than the first edge's is moved sideways onto the
first edge's course and joined by a smooth curve). It serves the parts of the network
that are not on the main route (an on-ramp before it joins) and the measure: ``s`` (m)
runs as SUMO measures the main route (lane lengths plus junction lanes:
:class:`cosim.road.lane_tables.Measure`), across junctions and the ring's seam. ``d`` (m)
is positive to the left. On the networks :mod:`cosim.road.build` generates (every edge
``spreadType="center"``) ``d`` is SUMO's lateral lane position. An on-ramp's lanes lie
right of the main road until they merge: a ramp vehicle's ``d`` is beyond the main road's
right edge, and its ``s`` advances by ``v dt cos(angle)`` (the main road's direction).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from cosim.errors import NetworkError
from cosim.road.polyline import Line, dedupe, offset_polyline
from cosim.road.sumo_net import (
    connections,
    continuing_lanes,
    lanes_of,
    reference_lane,
    via_chain,
)

#: Lanes that move sideways by less than this (m) keep their place (net.xml rounds
#: coordinates to 0.01 m).
SHIFT_TOL_M = 0.02
#: Spacing (m) and least number of the points of a smooth bridge across a junction (a
#: turn of 10 degrees then bends by 0.2 degrees per point: at d = 5 m a point off the
#: line in the outside corner of a bend is represented to 0.02 m).
BRIDGE_STEP_M = 0.1
BRIDGE_POINTS = 48


def _centre_shape(edge: Any, lanes: Sequence[Any] | None = None) -> np.ndarray:
    """Centre line of an edge's lanes as SUMO lays them out: the middle lane's centre (an
    even count: the border between the two middle lanes), (V, 2) m. ``lanes``: only
    these (adjacent) lanes of the edge, e.g. the ones the road continues on."""
    lanes = list(lanes) if lanes else lanes_of(edge)
    mid = lanes[len(lanes) // 2]
    shape = dedupe(np.asarray(mid.getShape(), dtype=float)[:, :2])
    if len(lanes) % 2 == 0:  # the right border of the left middle lane
        shape = offset_polyline(shape, -0.5 * float(mid.getWidth()), False)
    return shape


def reference_line(net: Any, route: Sequence[str], periodic: bool) -> Line:
    """The reference line (see the module docstring) of the main route ``route`` (edge ids
    in driving order; ``periodic``: the ring, the line closes on itself) of sumolib network
    ``net``, as a polyline (m).

    Each route edge contributes its lanes' centre line (:func:`_centre_shape`; of the
    lanes the previous edge's lanes lead onto, when a lane is added beside them), moved
    sideways by ``shift = delta_0 - delta_k`` where ``delta_k`` is how far that centre
    lies from the edge as drawn (its raw shape) and ``delta_0`` the same for the first
    edge. Between two unshifted edges the line runs along the junction lanes SUMO drives
    through; elsewhere (the lanes changed their place, e.g. after a width change built
    with netconvert's defaults) it bridges the junction with a smooth cubic curve tangent
    to both sides (points every BRIDGE_STEP_M). So on generated
    networks, and wherever lanes keep their place, the line is exactly the lanes' centre
    line, junction lanes included (vehicles there have ``d = lat``).

    Raises NetworkError for an edge without length or a route that turns back on itself.
    """
    edges = [net.getEdge(e) for e in route]
    centres, shifts = [], []
    delta0 = None
    for k, edge in enumerate(edges):
        centre = _centre_shape(edge, continuing_lanes(edges[k - 1], edge) if k else None)
        raw = _raw_shape(edge, centre)
        if len(raw) < 2 or len(centre) < 2:
            raise NetworkError(f"route edge {edge.getID()!r} has no length")
        _, d, _ = Line.of(raw, False).nearest(_point_at(centre, 0.5)[None, :])
        delta = float(d[0])
        delta0 = delta if delta0 is None else delta0
        shift = delta0 - delta
        shift = 0.0 if abs(shift) < SHIFT_TOL_M else shift
        centres.append(centre if shift == 0.0 else offset_polyline(centre, shift, False))
        shifts.append(shift)
    n = len(edges)
    chain = centres[0]
    for k in range(n if periodic else n - 1):
        nk = (k + 1) % n
        nxt = centres[nk] if nk else centres[0][:1]
        bridge = None
        if shifts[k] == 0.0 and shifts[nk] == 0.0:  # the lanes are the line: keep them
            bridge = _junction_lanes(net, edges[k], edges[nk])
            if bridge is not None and (np.hypot(*(bridge[0] - chain[-1])) > SHIFT_TOL_M
                                       or np.hypot(*(bridge[-1] - centres[nk][0])) > SHIFT_TOL_M):
                bridge = None  # the junction lanes do not join these lanes: bridge smoothly
        if bridge is None and np.hypot(*(centres[nk][0] - chain[-1])) > 1e-6:
            bridge = _hermite(chain[-2:], centres[nk][:2])
        if bridge is not None:
            chain = _join(chain, bridge)
        chain = _join(chain, nxt)
    chain = dedupe(chain)
    if periodic:
        chain[-1] = chain[0]
    if len(chain) < 2:
        raise NetworkError(f"the main route {list(route)} has no length")
    return Line.of(chain, periodic)


def _raw_shape(edge: Any, centre: np.ndarray) -> np.ndarray:
    """The edge as drawn (its raw shape), m; the lanes' centre line when the file does not
    tell (sumolib needs the nodes' positions: a file without junctions has none, and SUMO
    refuses it when it starts)."""
    try:
        raw = edge.getRawShape()
        return dedupe(np.asarray(raw, dtype=float)[:, :2])
    except (TypeError, ValueError, IndexError):
        return centre


def _junction_lanes(net: Any, edge: Any, nxt: Any) -> np.ndarray | None:
    """The junction lanes from ``edge``'s middle lane to ``nxt`` as one polyline, or None
    (no junction lanes)."""
    conns = connections(edge, nxt.getID())
    if not conns:
        return None
    ref = reference_lane(edge)
    conn = next((c for c in conns if c.getFromLane() is ref), conns[0])
    chain = via_chain(net, conn, nxt.getID())
    if not chain:
        return None
    pts = dedupe(np.concatenate([np.asarray(ln.getShape(), dtype=float)[:, :2]
                                 for ln in chain]))
    return pts if len(pts) >= 2 else None


def _hermite(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """A cubic curve from ``before[-1]`` (leaving along ``before``'s last direction) to
    ``after[0]`` (arriving along ``after``'s first direction), at least BRIDGE_POINTS
    points, at most BRIDGE_STEP_M apart."""
    p0, p1 = before[-1], after[0]
    t0 = before[-1] - before[-2]
    t1 = after[1] - after[0]
    t0, t1 = t0 / np.hypot(*t0), t1 / np.hypot(*t1)
    chord = float(np.hypot(*(p1 - p0)))
    n = max(BRIDGE_POINTS, int(math.ceil(chord / BRIDGE_STEP_M)))
    u = np.linspace(0.0, 1.0, n + 1)[:, None]
    h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
    h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
    return h00 * p0 + h10 * chord * t0 + h01 * p1 + h11 * chord * t1


def _join(chain: np.ndarray, piece: np.ndarray) -> np.ndarray:
    """``chain`` continued by ``piece`` (a straight segment between them); points of the
    piece that lie behind the chain's end (lanes overlapping in a junction) are dropped."""
    end = chain[-1]
    t = chain[-1] - chain[-2]
    t = t / np.hypot(*t)
    ahead = (piece - end) @ t > 1e-6
    if not ahead.any():
        if len(piece) == 1:  # closing a loop onto its start
            return np.vstack([chain, piece])
        raise NetworkError("the main route turns back on itself: the road frame cannot follow it")
    first = int(np.argmax(ahead))
    return np.vstack([chain, piece[first:]])


def _point_at(shape: np.ndarray, frac: float) -> np.ndarray:
    """The point (2,) m a fraction ``frac`` of the way along polyline ``shape`` (V, 2)."""
    seg = np.hypot(*np.diff(shape, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    g = frac * cum[-1]
    return np.array([np.interp(g, cum, shape[:, 0]), np.interp(g, cum, shape[:, 1])])
