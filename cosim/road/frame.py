"""The road frame on a SUMO network: ``s`` along the main route, ``d`` across it.

:func:`load_road_network` reads a ``.net.xml`` with sumolib and computes, for the main
route (and an optional ramp route), the offset ``s`` of every lane and junction lane,
the lateral offset of every lane's centre and the road's edges along ``s``:
:class:`RoadNetwork`.

Conventions: ``s`` is measured along lanes as SUMO measures positions (the lane
``length`` attribute), including the internal junction lanes (``:node_0_0``), so that
``s = offset(lane) + lanePosition`` is continuous across junctions; ``d`` is positive
to the left of the road's centre line.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controllers.observation import RoadProfile
from cosim.errors import ConfigError, NetworkError


@dataclass(frozen=True)
class RoadNetwork:
    """A built SUMO network and its road frame.

    Attributes:
        net_file: the ``.net.xml``.
        kind: the spec's kind.
        main_route: edge ids of the main route in driving order; ``s`` is
            continuous along them (and across the junction lanes between them).
        ramp_route: edge ids of the on-ramp route (ramp edge(s) then the main
            road's edge after the merge), or None.
        length_m: length of the main route as SUMO measures it (lane lengths plus
            junction lanes); on the ring, the circumference including the
            junction lanes that close the loop.
        width_m: nominal (widest) road width on the main route, m.
        periodic: True on the ring: ``s`` wraps at ``length_m``.
        speed_limit_mps: speed limit on the main route.
        merge_s_m: onramp: ``s`` where the main road's lane leaves the merge
            junction (ramp traffic is on the main lane from here on), else None.
        ramp_length_m: onramp: SUMO's length of the ramp route up to
            ``merge_s_m`` (ramp lane plus its junction lane), else None.
        ramp_width_m: onramp: width of the ramp's first edge, else None.
        n_lanes: number of lanes on the main route's first edge (1 when lane-free).
        lane_offsets: ``s`` of position 0 of every lane and edge on the main and
            ramp routes, internal junction lanes included. Ramp lanes get offsets
            so that ``s`` runs on continuously into the main road (negative
            values mean "upstream of the main route's start").
        lane_d: lateral offset of each lane's centre from the road centre line
            (0 for one-lane edges; +-3.4 m for the outer lanes of three_lane). Ramp
            lanes are measured from the ramp's own centre line.

    The ring keeps vehicles circling through routes with a ``repeat``
    attribute: :meth:`ring_route_edges` gives the loop starting on a given
    edge and :mod:`cosim.demand` writes ``<route edges=... repeat=N>`` with N
    large enough for the run (SUMO then repeats the edge list N more times).
    """

    net_file: Path
    kind: str
    main_route: tuple[str, ...]
    ramp_route: tuple[str, ...] | None
    length_m: float
    width_m: float
    periodic: bool
    speed_limit_mps: float
    merge_s_m: float | None = None
    ramp_length_m: float | None = None
    ramp_width_m: float | None = None
    n_lanes: int = 1
    lane_offsets: Mapping[str, float] = field(default_factory=dict, repr=False, compare=False)
    lane_d: Mapping[str, float] = field(default_factory=dict, repr=False, compare=False)
    segment_s0: tuple[float, ...] = field(default=(0.0,), repr=False, compare=False)
    segment_width: tuple[float, ...] = field(default=(10.2,), repr=False, compare=False)
    edge_spans: tuple[tuple[str, float, float], ...] = field(
        default=(), repr=False, compare=False
    )

    def s_of(self, lane_or_edge: str, pos_m: float) -> float:
        """Continuous ``s`` (m) of lane position ``pos_m`` on a lane or edge; NaN if off-route."""
        off = self.lane_offsets.get(lane_or_edge)
        if off is None:
            return float("nan")
        s = off + float(pos_m)
        return s % self.length_m if self.periodic else s

    def s_of_many(self, lanes: Sequence[str], pos_m: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`s_of`: ``s`` (m) for each (lane or edge id, lane position)."""
        offs = np.array([self.lane_offsets.get(x, np.nan) for x in lanes], dtype=float)
        s = offs + np.asarray(pos_m, dtype=float)
        return np.mod(s, self.length_m) if self.periodic else s

    def d_of(self, lane_or_edge: str, lateral_lane_pos_m: float) -> float:
        """Road-frame ``d`` (m, left positive) from SUMO's lateral position on a lane."""
        return self.lane_d.get(lane_or_edge, 0.0) + float(lateral_lane_pos_m)

    def profile(self) -> RoadProfile:
        """The main route's lateral edges along ``s`` as a pure-numpy profile (controllers)."""
        w = np.asarray(self.segment_width, dtype=float)
        if self.n_lanes > 1:
            w = w.copy()
        return RoadProfile(np.asarray(self.segment_s0, dtype=float), -0.5 * w, 0.5 * w,
                           float(self.length_m), self.periodic)

    def width_at(self, s: np.ndarray) -> np.ndarray:
        """Road width (m) at each ``s`` (m); beyond the ends the end segments' widths."""
        s = np.asarray(s, dtype=float)
        if self.periodic:
            s = np.mod(s, self.length_m)
        idx = np.searchsorted(np.asarray(self.segment_s0), s, side="right") - 1
        idx = np.clip(idx, 0, len(self.segment_width) - 1)
        return np.asarray(self.segment_width)[idx]

    def edges_at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lateral road edges ``(d_right, d_left)`` (m) at each ``s`` (m), from the centre line.

        One wide lane of width w gives ``(-w/2, +w/2)``; on varying_width roads w is
        the width of the edge (or junction lane) that contains ``s``.
        """
        half = 0.5 * self.width_at(s)
        return -half, half

    def ring_route_edges(self, start_edge: str | None = None) -> tuple[str, ...]:
        """Ring only: the loop's edges starting at ``start_edge`` (default: the first)."""
        if not self.periodic:
            raise NetworkError(f"ring_route_edges: network kind {self.kind!r} is not a ring")
        start = self.main_route[0] if start_edge is None else start_edge
        if start not in self.main_route:
            raise NetworkError(f"ring_route_edges: edge {start!r} is not on the ring")
        k = self.main_route.index(start)
        return self.main_route[k:] + self.main_route[:k]

    def locate(self, s: float) -> tuple[str, float]:
        """The main-route edge (not a junction) and lane position (m) at ``s`` (m).

        A position inside a junction is moved to the start of the next edge (SUMO
        detectors cannot sit on junction lanes); on open roads ``s`` must lie in
        ``[0, length_m]``.
        """
        s = float(s)
        if self.periodic:
            s %= self.length_m
        elif not 0.0 <= s <= self.length_m:
            raise ConfigError(f"position s={s} m is outside the road [0, {self.length_m:.2f}] m")
        for i, (edge, s0, s1) in enumerate(self.edge_spans):
            if s0 <= s <= s1:
                return edge, s - s0
            if s < s0:  # inside the junction before this edge
                return edge, 0.0
            if i + 1 == len(self.edge_spans) and self.periodic:
                return self.edge_spans[0][0], 0.0
        edge, s0, s1 = self.edge_spans[-1]
        return edge, s1 - s0


def _read_sumo_net(path: Path) -> Any:
    import sumolib

    try:
        net = sumolib.net.readNet(str(path), withInternal=True)
    except Exception as exc:  # sumolib raises SAX, KeyError, ValueError... on bad files
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise NetworkError(f"cannot read network {path}: {type(exc).__name__}: {msg}") from None
    if not net.getEdges(withInternal=False):
        raise NetworkError(f"network {path} has no edges (is it a .net.xml?)")
    return net


def _edge_width(edge: Any) -> float:
    return float(sum(lane.getWidth() for lane in edge.getLanes()))


def _lane_d(edge: Any) -> dict[str, float]:
    """Offset of each lane centre from the edge's centre, m (lanes stacked right to left)."""
    total = _edge_width(edge)
    out, right = {}, -0.5 * total
    for lane in sorted(edge.getLanes(), key=lambda ln: ln.getIndex()):
        out[lane.getID()] = round(right + 0.5 * lane.getWidth(), 9)
        right += lane.getWidth()
    return out


def _reference_lane(edge: Any) -> Any:
    lanes = sorted(edge.getLanes(), key=lambda ln: ln.getIndex())
    return lanes[len(lanes) // 2]


def _via_chain(net: Any, conn: Any, to_edge: str) -> list[Any]:
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


def _connections(edge: Any, to_edge: str) -> list[Any]:
    return [c for ln in edge.getLanes() for c in ln.getOutgoing() if c.getTo().getID() == to_edge]


@dataclass
class _Frame:
    offsets: dict[str, float] = field(default_factory=dict)
    lane_d: dict[str, float] = field(default_factory=dict)
    seg_s0: list[float] = field(default_factory=list)
    seg_w: list[float] = field(default_factory=list)
    spans: list[tuple[str, float, float]] = field(default_factory=list)
    length: float = 0.0


def _main_frame(net: Any, route: Sequence[str], periodic: bool) -> _Frame:
    """Offsets along the main route; the reference path uses each edge's middle lane."""
    fr = _Frame()
    s = 0.0
    single_lane = all(len(net.getEdge(e).getLanes()) == 1 for e in route)
    for k, eid in enumerate(route):
        edge = net.getEdge(eid)
        ref = _reference_lane(edge)
        fr.offsets[eid] = s
        for lane in edge.getLanes():
            fr.offsets[lane.getID()] = s
        fr.lane_d.update(_lane_d(edge))
        fr.seg_s0.append(s)
        fr.seg_w.append(_edge_width(edge))
        fr.spans.append((eid, s, s + ref.getLength()))
        nxt = route[k + 1] if k + 1 < len(route) else (route[0] if periodic else None)
        if nxt is None:
            s += ref.getLength()
            break
        conns = _connections(edge, nxt)
        if not conns:
            raise NetworkError(f"route edge {eid!r} is not connected to the next edge {nxt!r}")
        ref_conn = next((c for c in conns if c.getFromLane() is ref), conns[0])
        for conn in conns:
            pos = s + conn.getFromLane().getLength()
            for lane in _via_chain(net, conn, nxt):
                fr.offsets.setdefault(lane.getID(), pos)
                fr.offsets.setdefault(lane.getEdge().getID(), pos)
                fr.lane_d.setdefault(lane.getID(), fr.lane_d[conn.getFromLane().getID()])
                if conn is ref_conn:
                    fr.seg_s0.append(pos)
                    fr.seg_w.append(lane.getWidth() if single_lane else _edge_width(edge))
                pos += lane.getLength()
        s += ref_conn.getFromLane().getLength()
        s += sum(ln.getLength() for ln in _via_chain(net, ref_conn, nxt))
    fr.length = s
    return fr


def _ramp_offsets(net: Any, ramp_route: Sequence[str], fr: _Frame) -> float:
    """Give ramp lanes offsets so s runs on into the main route; return the ramp's length (m)."""
    join = ramp_route[-1]
    if join not in fr.offsets:
        raise NetworkError(f"ramp route must end on a main-route edge (ends on {join!r})")
    s_end = fr.offsets[join]
    total = 0.0
    for k in range(len(ramp_route) - 2, -1, -1):
        edge = net.getEdge(ramp_route[k])
        conns = _connections(edge, ramp_route[k + 1])
        if not conns:
            raise NetworkError(
                f"ramp edge {ramp_route[k]!r} is not connected to {ramp_route[k + 1]!r}"
            )
        conn = conns[0]
        chain = _via_chain(net, conn, ramp_route[k + 1])
        for lane in reversed(chain):
            s_end -= lane.getLength()
            total += lane.getLength()
            fr.offsets.setdefault(lane.getID(), s_end)
            fr.offsets.setdefault(lane.getEdge().getID(), s_end)
        s_end -= conn.getFromLane().getLength()
        total += conn.getFromLane().getLength()
        fr.offsets[edge.getID()] = s_end
        for lane in edge.getLanes():
            fr.offsets[lane.getID()] = s_end
        fr.lane_d.update(_lane_d(edge))
    return total


def load_road_network(
    net_file: Path | str,
    *,
    kind: str,
    main_route: Sequence[str],
    ramp_route: Sequence[str] | None = None,
    periodic: bool = False,
    speed_limit_mps: float | None = None,
) -> RoadNetwork:
    """Read a ``.net.xml`` with sumolib and compute the road frame of ``main_route``."""
    path = Path(net_file)
    net = _read_sumo_net(path)
    for eid in (*main_route, *(ramp_route or ())):
        if not net.hasEdge(eid):
            raise NetworkError(f"edge {eid!r} of the route is not in network {path.name}")
    fr = _main_frame(net, main_route, periodic)
    merge_s = ramp_len = ramp_width = None
    if ramp_route:
        ramp_len = _ramp_offsets(net, ramp_route, fr)
        merge_s = fr.offsets[ramp_route[-1]]
        ramp_width = _edge_width(net.getEdge(ramp_route[0]))
    if speed_limit_mps is None:
        speed_limit_mps = float(_reference_lane(net.getEdge(main_route[0])).getSpeed())
    if not speed_limit_mps > 0:
        raise NetworkError(
            f"network {path.name}: the speed limit of edge {main_route[0]!r} must be > 0 m/s "
            f"(got {speed_limit_mps})"
        )
    return RoadNetwork(
        net_file=path.resolve(),
        kind=kind,
        main_route=tuple(main_route),
        ramp_route=tuple(ramp_route) if ramp_route else None,
        length_m=float(fr.length),
        width_m=float(max(fr.seg_w)),
        periodic=periodic,
        speed_limit_mps=float(speed_limit_mps),
        merge_s_m=merge_s,
        ramp_length_m=ramp_len,
        ramp_width_m=ramp_width,
        n_lanes=len(net.getEdge(main_route[0]).getLanes()),
        lane_offsets=dict(fr.offsets),
        lane_d=dict(fr.lane_d),
        segment_s0=tuple(fr.seg_s0),
        segment_width=tuple(fr.seg_w),
        edge_spans=tuple(fr.spans),
    )
