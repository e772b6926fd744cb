"""A road's entries and exits: its on-ramps and off-ramps in the road frame.

An :class:`OnRamp` is a route of edges that ends on a main-route edge; where it joins a
main-route edge beside the road's own lanes (an acceleration strip, the lanes of that edge
reached from the ramp) the strip's extent is known. An :class:`OffRamp` is a route of
edges whose first edge leaves a main-route edge (the diverge edge) from some of its lanes
(the exit lanes: a deceleration strip or the road's outer lane). A network has any number
of each; they are named for demand (:attr:`OnRamp.name`: ``ramp``, ``ramp2``, ...;
:attr:`OffRamp.name`: ``off``, ``off2``, ...) in the order they are given.

A strip's extent is ``(s_start, s_end, d_right, d_left)`` (m) in the road frame
(:mod:`cosim.road.frame`): ``s`` where its lanes start and end (for an exit, the end is the
gore, where the off-ramp leaves) and the right and left border of the lanes side by side.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.demand.od_names import offramp_name, ramp_name
from cosim.errors import NetworkError
from cosim.road.lane_tables import Tables, frame_of
from cosim.road.sumo_net import connections, lanes_of, via_chain

#: (s_start, s_end, d_right, d_left), m
Strip = tuple[float, float, float, float]


@dataclass(frozen=True)
class OnRamp:
    """An on-ramp of the road.

    Attributes:
        name: its name in the demand (``ramp``, ``ramp2``, ...).
        route: its edges, ramp edge(s) then the main-route edge it joins.
        join_index: index in ``route`` of its first main-route edge.
        merge_s_m: ``s`` (m) where the ramp route's last edge starts (ramp traffic is on
            the main road from here on).
        length_m: SUMO's length of the ramp route up to the main road (ramp lanes and
            their junction lanes; along the ramp, not along ``s``), m.
        width_m: width of the ramp's first edge, m.
        entry_lanes: the lanes of the joined edge reached from the ramp, when they are not
            all of its lanes (an acceleration strip); else empty.
        entry_strip: their extent (module docstring), or None.
    """

    name: str
    route: tuple[str, ...]
    join_index: int
    merge_s_m: float
    length_m: float
    width_m: float
    entry_lanes: tuple[str, ...] = ()
    entry_strip: Strip | None = None


@dataclass(frozen=True)
class OffRamp:
    """An off-ramp of the road.

    Attributes:
        name: its name in the demand (``off``, ``off2``, ...).
        route: its edges; the first leaves the main route.
        diverge_edge: the main-route edge it leaves (the last one with a lane connected to
            its first edge).
        exit_lanes: the lanes of ``diverge_edge`` that lead onto it.
        exit_strip: their extent (module docstring; ``s_end`` is the gore).
    """

    name: str
    route: tuple[str, ...]
    diverge_edge: str
    exit_lanes: tuple[str, ...]
    exit_strip: Strip


def check_ramp_edges(net: Any, path: Path, ramp: Sequence[str], what: str) -> None:
    """NetworkError for a ramp route with an edge missing or a junction lane in it."""
    for eid in ramp:
        if not net.hasEdge(eid):
            raise NetworkError(f"edge {eid!r} of the {what} route is not in network "
                               f"{path.name}")
        if net.getEdge(eid).getFunction() == "internal":
            raise NetworkError(f"{what} route edge {eid!r} is a junction lane, not an edge")


def join_index(ramp: Sequence[str], main_route: Sequence[str], path: Path) -> int:
    """Index of the on-ramp route's first main-route edge; NetworkError for a ramp that
    does not end on the main route or starts on it."""
    if not ramp or ramp[-1] not in main_route:
        raise NetworkError(f"ramp route must end on a main-route edge (ends on "
                           f"{ramp[-1] if ramp else None!r}; network {path.name})")
    i = next(i for i, e in enumerate(ramp) if e in main_route)
    if i == 0:
        raise NetworkError(f"ramp route {list(ramp)} starts on the main route: it must "
                           f"start on a ramp edge")
    return i


def diverge_edge(net: Any, main_route: Sequence[str], offramp: Sequence[str],
                 path: Path) -> str:
    """The main-route edge the off-ramp ``offramp`` leaves (the last one with a lane
    connected to its first edge); NetworkError for an off-ramp the frame cannot use."""
    check_ramp_edges(net, path, offramp, "off-ramp")
    if not offramp:
        raise NetworkError("an off-ramp route lists no edge")
    if offramp[0] in main_route:
        raise NetworkError(f"the off-ramp route's first edge {offramp[0]!r} is on the main "
                           f"route: it must leave it")
    diverge = [e for e in main_route if connections(net.getEdge(e), offramp[0])]
    if not diverge:
        raise NetworkError(f"no main-route edge leads onto the off-ramp's first edge "
                           f"{offramp[0]!r}")
    return diverge[-1]


def strip(tb: Tables, lane_offsets: Mapping[str, float], lane_d: Mapping[str, float],
          lane_width: Mapping[str, float], lanes: Sequence[str]) -> Strip:
    """``(s_start, s_end, d_right, d_left)`` (m) of route lanes ``lanes`` side by side."""
    keys = np.array([tb.index[x] for x in lanes])
    s_end, _ = frame_of(tb, keys, tb.lane_len[keys], np.zeros(len(keys)))
    right = min(lane_d[x] - 0.5 * lane_width[x] for x in lanes)
    left = max(lane_d[x] + 0.5 * lane_width[x] for x in lanes)
    return (float(min(lane_offsets[x] for x in lanes)), float(s_end.max()), float(right),
            float(left))


def on_ramp(net: Any, k: int, route: Sequence[str], main_route: Sequence[str], path: Path,
            lane_offsets: Mapping[str, float], strip_of) -> OnRamp:
    """The ``k``-th on-ramp (route ``route``) of the road; ``strip_of(lanes)`` gives the
    extent of route lanes (:func:`strip` bound to the road's tables)."""
    i = join_index(route, main_route, path)
    length = 0.0
    for j in range(i):
        conn = connections(net.getEdge(route[j]), route[j + 1])[0]
        length += conn.getFromLane().getLength()
        length += sum(ln.getLength() for ln in via_chain(net, conn, route[j + 1]))
    joined = net.getEdge(route[i])
    reached = sorted({c.getToLane().getID() for c in connections(
        net.getEdge(route[i - 1]), joined.getID())})
    beside = bool(reached) and len(reached) < len(lanes_of(joined))
    return OnRamp(
        name=ramp_name(k), route=tuple(route), join_index=i,
        merge_s_m=float(lane_offsets[route[-1]]), length_m=float(length),
        width_m=float(sum(ln.getWidth() for ln in lanes_of(net.getEdge(route[0])))),
        entry_lanes=tuple(reached) if beside else (),
        entry_strip=strip_of(reached) if beside else None)


def off_ramp(net: Any, k: int, route: Sequence[str], main_route: Sequence[str], path: Path,
             strip_of) -> OffRamp:
    """The ``k``-th off-ramp (route ``route``) of the road (``strip_of`` as in
    :func:`on_ramp`)."""
    edge = diverge_edge(net, main_route, route, path)
    lanes = sorted({c.getFromLane().getID() for c in connections(net.getEdge(edge), route[0])})
    return OffRamp(name=offramp_name(k), route=tuple(route), diverge_edge=edge,
                   exit_lanes=tuple(lanes), exit_strip=strip_of(lanes))
