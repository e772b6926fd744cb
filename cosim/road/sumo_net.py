"""A SUMO network as sumolib reads it, and the few questions the road frame asks of it:
its lanes in index order, the reference lane of an edge, the connections between two
edges, the junction lanes a connection passes through and the lanes a road continues on
after a lane is added beside it. Every failure is one :class:`~cosim.errors.NetworkError`
line."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from cosim.errors import NetworkError


def read_sumo_net(path: Path) -> Any:
    import sumolib

    try:
        net = sumolib.net.readNet(str(path), withInternal=True)
    except Exception as exc:  # sumolib raises SAX, KeyError, ValueError... on bad files
        why = _diagnose(path)
        if why:
            raise NetworkError(f"network {path.name}: {why}") from None
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise NetworkError(f"cannot read network {path}: {type(exc).__name__}: {msg}") from None
    if not net.getEdges(withInternal=False):
        raise NetworkError(f"network {path} has no edges (is it a .net.xml?)")
    return net


def _diagnose(path: Path) -> str | None:
    """Why sumolib could not read a file we can parse as XML (None: no idea)."""
    try:
        lanes: dict[str, int] = {}
        current = None
        for event, el in ET.iterparse(str(path), events=("start", "end")):
            if event == "start" and el.tag == "edge":
                current = el.get("id")
                lanes[current] = 0
            elif event == "start" and el.tag == "lane" and current is not None:
                lanes[current] += 1
            elif event == "end" and el.tag == "edge":
                current = None
                el.clear()
    except (ET.ParseError, OSError, UnicodeDecodeError):
        return None
    empty = [e for e, n in lanes.items() if n == 0]
    if empty:
        more = f" (and {len(empty) - 1} more)" if len(empty) > 1 else ""
        return f"edge {empty[0]!r}{more} has no <lane>: every edge needs at least one lane"
    return None


def lanes_of(edge: Any) -> list[Any]:
    lanes = sorted(edge.getLanes(), key=lambda ln: ln.getIndex())
    if not lanes:
        raise NetworkError(f"edge {edge.getID()!r} has no lanes: every route edge needs one")
    return lanes


def reference_lane(edge: Any) -> Any:
    lanes = lanes_of(edge)
    return lanes[len(lanes) // 2]


def via_chain(net: Any, conn: Any, to_edge: str) -> list[Any]:
    """Internal lanes a connection passes through, in order (split junction lanes included)."""
    chain = []
    via = conn.getViaLaneID()
    for _ in range(16):
        if not via:
            return chain
        lane = net.getLane(via)
        chain.append(lane)
        nxt = [c for c in lane.getOutgoing() if c.getTo().getID() == to_edge]
        nxt = nxt or list(lane.getOutgoing())
        via = nxt[0].getViaLaneID() if nxt else ""
    raise NetworkError(f"junction lanes after {conn.getFrom().getID()} do not reach {to_edge}")


def connections(edge: Any, to_edge: str) -> list[Any]:
    return [c for ln in edge.getLanes() for c in ln.getOutgoing() if c.getTo().getID() == to_edge]


def continuing_lanes(prev: Any, edge: Any) -> list[Any] | None:
    """The lanes of ``edge`` that the lanes of ``prev`` lead onto, right to left, when
    they are not all of them (a lane added beside the road, e.g. an acceleration lane);
    else None."""
    reached = {c.getToLane().getID() for c in connections(prev, edge.getID())}
    lanes = [ln for ln in lanes_of(edge) if ln.getID() in reached]
    return lanes if lanes and len(lanes) < len(lanes_of(edge)) else None
