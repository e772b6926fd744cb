"""Build SUMO road networks from a :class:`NetworkSpec`: plain-XML sources and netconvert.

:func:`build_network` writes ``.nod.xml`` and ``.edg.xml`` sources, runs ``netconvert``
and returns the :class:`~cosim.road.frame.RoadNetwork`. Built networks are cached under
``<cache>/<kind>-<hash>/`` (:func:`default_cache_dir`, a directory you pass, or
``$COSIM_NETWORK_CACHE``); the hash covers the parameters that matter for the kind,
the SUMO version and :data:`BUILDER_VERSION`, so a second build with the same inputs
reuses the file.

Geometry conventions (all lengths in m, speeds in m/s):

* Lane-free roads have ONE wide lane per edge; SUMO's sublane model
  (``--lateral-resolution``) lets vehicles sit anywhere across it.
* Every generated edge uses ``spreadType="center"``: the edge's centre line is the
  road's centre line, and consecutive edges of different widths share it. The one
  exception, the on-ramp's acceleration lane, is a second lane beside the road (see
  :func:`_sources_onramp_acceleration_lane`).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from cosim.errors import NetworkError
from cosim.road.frame import RoadNetwork, load_road_network
from cosim.road.spec import RING_ARC_POINTS, RING_EDGES, NetworkSpec, _n_edges
from cosim.sumo.binaries import netconvert_binary, sumo_version

#: Bump when the generated geometry changes, so old cache entries are not reused.
BUILDER_VERSION = 4


#: Relative tolerance between the requested ring circumference and SUMO's lane length.
RING_LENGTH_TOLERANCE = 0.01


NET_FILE_NAME = "road.net.xml"


SPEC_FILE_NAME = "spec.json"




def default_cache_dir() -> Path:
    """The network cache: ``$COSIM_NETWORK_CACHE``, else ``$XDG_CACHE_HOME/lanefree-cosim/networks``
    (``~/.cache/lanefree-cosim/networks``): a per-user folder, never inside the installed
    package, so a non-editable install works from any folder."""
    env = os.environ.get("COSIM_NETWORK_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "lanefree-cosim" / "networks"


def _run_netconvert(nod: Path, edg: Path, out: Path, extra: Sequence[str] = ()) -> None:
    """Run netconvert on plain-XML sources; NetworkError with its first error line on failure."""
    cmd = [
        str(netconvert_binary()),
        "--node-files", str(nod),
        "--edge-files", str(edg),
        "--output-file", str(out),
        "--no-turnarounds", "true",
        "--offset.disable-normalization", "true",
        "--output.street-names", "false",
        *extra,
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    (out.parent / "netconvert.log").write_text(proc.stdout + proc.stderr)
    if proc.returncode != 0 or not out.is_file():
        lines = [ln.strip() for ln in proc.stderr.splitlines() if ln.strip()]
        errors = [ln for ln in lines if ln.lower().startswith("error")]
        first = (errors or lines or [f"exit code {proc.returncode}"])[0]
        raise NetworkError(f"netconvert failed for {out.parent.name}: {first}")


@dataclass
class _Sources:
    """Plain-XML node and edge lines plus the routes they define."""

    nodes: list[str]
    edges: list[str]
    main_route: tuple[str, ...]
    ramp_route: tuple[str, ...] | None = None
    offramp_route: tuple[str, ...] | None = None
    periodic: bool = False
    netconvert_options: tuple[str, ...] = ()
    connections: tuple[str, ...] = ()


def _node(nid: str, x: float, y: float, ntype: str = "priority") -> str:
    return f'    <node id="{nid}" x="{x:.3f}" y="{y:.3f}" type="{ntype}"/>'


def _edge(
    eid: str, frm: str, to: str, width: float, speed: float,
    lanes: int = 1, priority: int = 2, shape: str | None = None,
    spread: str = "center", lane_widths: Sequence[float] = (),
) -> str:
    """One edge line; ``lane_widths`` (right to left, m) gives each lane its own width."""
    shape_attr = f' shape="{shape}"' if shape else ""
    head = (
        f'    <edge id="{eid}" from="{frm}" to="{to}" numLanes="{lanes}" width="{width:.3f}"'
        f' speed="{speed:.3f}" priority="{priority}" spreadType="{spread}"{shape_attr}'
    )
    if not lane_widths:
        return head + "/>"
    body = [f'        <lane index="{i}" width="{w:.3f}"/>' for i, w in enumerate(lane_widths)]
    return "\n".join([head + ">", *body, "    </edge>"])


def _sources_straight(spec: NetworkSpec) -> _Sources:
    v = spec.speed_limit_mps
    n = _n_edges(spec.length_m, spec.max_edge_length_m)
    if n == 1:
        return _Sources(
            nodes=[_node("start", 0.0, 0.0, "dead_end"),
                   _node("end", spec.length_m, 0.0, "dead_end")],
            edges=[_edge("main", "start", "end", spec.width_m, v)],
            main_route=("main",),
        )
    names = ["start", *(f"j{k}" for k in range(1, n)), "end"]
    nodes = [
        _node(name, spec.length_m * k / n, 0.0, "dead_end" if k in (0, n) else "priority")
        for k, name in enumerate(names)
    ]
    route = tuple(f"main{k}" for k in range(n))
    edges = [_edge(route[k], names[k], names[k + 1], spec.width_m, v) for k in range(n)]
    # Without internal links vehicles step straight from one edge onto the next; with
    # them every joint would add a 0.1 m junction lane (SUMO's minimum lane length).
    return _Sources(nodes=nodes, edges=edges, main_route=route,
                    netconvert_options=("--no-internal-links", "true"))


def _sources_three_lane(spec: NetworkSpec) -> _Sources:
    v = spec.speed_limit_mps
    return _Sources(
        nodes=[_node("start", 0.0, 0.0, "dead_end"), _node("end", spec.length_m, 0.0, "dead_end")],
        edges=[_edge("main", "start", "end", spec.width_m / 3, v, lanes=3)],
        main_route=("main",),
    )


def _sources_ring(spec: NetworkSpec) -> _Sources:
    n = _n_edges(spec.circumference_m, spec.max_edge_length_m, minimum=RING_EDGES)
    # The lanes are polygons of n * RING_ARC_POINTS chords; scale the radius so that the
    # polygon (what SUMO measures), not the circle, has the requested circumference.
    half_angle = math.pi / (n * RING_ARC_POINTS)
    radius = spec.circumference_m / (2 * math.pi) * half_angle / math.sin(half_angle)
    nodes, edges = [], []
    for i in range(n):
        a = 2 * math.pi * i / n
        nodes.append(_node(f"r{i}", radius * math.cos(a), radius * math.sin(a)))
    for i in range(n):
        a0, a1 = 2 * math.pi * i / n, 2 * math.pi * (i + 1) / n
        angles = np.linspace(a0, a1, RING_ARC_POINTS + 1)
        shape = " ".join(f"{radius * math.cos(a):.4f},{radius * math.sin(a):.4f}" for a in angles)
        edges.append(
            _edge(f"ring{i}", f"r{i}", f"r{(i + 1) % n}", spec.width_m, spec.speed_limit_mps,
                  shape=shape)
        )
    return _Sources(nodes, edges, tuple(f"ring{i}" for i in range(n)), periodic=True)


def _sources_onramp(spec: NetworkSpec) -> _Sources:
    if spec.acceleration_lane_m > 0:
        return _sources_onramp_acceleration_lane(spec)
    v = spec.speed_limit_mps
    th = math.radians(spec.ramp_angle_deg)
    m = spec.merge_position_m
    rx, ry = m - spec.ramp_length_m * math.cos(th), -spec.ramp_length_m * math.sin(th)
    nodes = [
        _node("start", 0.0, 0.0, "dead_end"),
        _node("merge", m, 0.0, "priority"),
        _node("end", spec.length_m, 0.0, "dead_end"),
        _node("ramp_start", rx, ry, "dead_end"),
    ]
    edges = [
        _edge("main_up", "start", "merge", spec.width_m, v, priority=2),
        _edge("main_down", "merge", "end", spec.width_m, v, priority=2),
        _edge("ramp", "ramp_start", "merge", spec.ramp_width_m or spec.width_m, v, priority=1),
    ]
    # One wide lane takes both streams: SUMO would make every vehicle on one link wait for
    # any vehicle on the other (its junction logic is per lane, blind to lateral position),
    # so a ramp vehicle would wait for a gap across the whole road. The links pass without
    # waiting; the streams are side by side (ramp traffic joins at the right, see
    # NetworkSpec.ramp_width_m) and keep their distance as they merge on the road.
    connections = (
        '    <connection from="main_up" to="main_down" fromLane="0" toLane="0" pass="true"/>',
        '    <connection from="ramp" to="main_down" fromLane="0" toLane="0" pass="true"/>',
    )
    return _Sources(nodes, edges, ("main_up", "main_down"), ramp_route=("ramp", "main_down"),
                    connections=connections)


def _sources_onramp_acceleration_lane(spec: NetworkSpec) -> _Sources:
    """The on-ramp with an acceleration lane (:attr:`NetworkSpec.acceleration_lane_m`).

    Main route ``main_up, acc, main_down``; edge ``acc`` has two lanes, ``acc_0`` (the
    acceleration lane, ``ramp_width_m`` wide, right) and ``acc_1`` (the road, in line
    with ``main_up_0`` and ``main_down_0``); ``acc_0`` has no connection onward, so it
    ends where ``acc`` does. The ramp (route ``ramp, acc, main_down``) meets ``acc_0`` at
    the ramp's angle. The streams never share a junction lane: ramp traffic crosses onto
    the road along the acceleration lane (SUMO's drivers change lanes; our CAVs cross
    where the law takes them, :meth:`SumoRoadWorld.apply`). The main road's edges spread
    their lanes to the right of a line drawn along the road's left edge (``y = width/2``),
    so the added lane leaves the road's centre line (the road frame's reference line,
    which follows the lanes the road continues on) straight at ``y = 0``.
    """
    v = spec.speed_limit_mps
    w, wr = spec.width_m, spec.ramp_width_m or spec.width_m
    th = math.radians(spec.ramp_angle_deg)
    m, acc_end = spec.merge_position_m, spec.merge_position_m + spec.acceleration_lane_m
    top = 0.5 * w  # the main road's left edge: its edges are drawn here
    ye = -0.5 * w - 0.5 * wr  # the acceleration lane's centre
    rx, ry = m - spec.ramp_length_m * math.cos(th), ye - spec.ramp_length_m * math.sin(th)
    nodes = [
        _node("start", 0.0, top, "dead_end"),
        _node("merge", m, top, "priority"),
        _node("acc_end", acc_end, top, "priority"),
        _node("end", spec.length_m, top, "dead_end"),
        _node("ramp_start", rx, ry, "dead_end"),
    ]
    edges = [
        _edge("main_up", "start", "merge", w, v, spread="right"),
        _edge("acc", "merge", "acc_end", w, v, lanes=2, spread="right", lane_widths=(wr, w)),
        _edge("main_down", "acc_end", "end", w, v, spread="right"),
        _edge("ramp", "ramp_start", "merge", wr, v, priority=1,
              shape=f"{rx:.3f},{ry:.3f} {m:.3f},{ye:.3f}"),
    ]
    connections = (
        '    <connection from="main_up" to="acc" fromLane="0" toLane="1"/>',
        '    <connection from="ramp" to="acc" fromLane="0" toLane="0"/>',
        '    <connection from="acc" to="main_down" fromLane="1" toLane="0"/>',
    )
    return _Sources(nodes, edges, ("main_up", "acc", "main_down"),
                    ramp_route=("ramp", "acc", "main_down"), connections=connections)


def _split(prefix: str, x0: float, x1: float, y: float, max_len: float, first: str,
           last: str) -> tuple[list[str], list[tuple[str, str, str]]]:
    """Nodes (between ``first`` and ``last``) and ``(edge, from, to)`` of a straight stretch
    from ``x0`` to ``x1`` (m) at height ``y``, in equal edges no longer than ``max_len``."""
    n = _n_edges(x1 - x0, max_len)
    names = [first, *(f"{prefix}_j{k}" for k in range(1, n)), last]
    nodes = [_node(names[k], x0 + (x1 - x0) * k / n, y) for k in range(1, n)]
    edges = [(prefix if n == 1 else f"{prefix}{k}", names[k], names[k + 1]) for k in range(n)]
    return nodes, edges


def _sources_corridor(spec: NetworkSpec) -> _Sources:
    """The freeway corridor (:attr:`NetworkSpec.kind` ``corridor``).

    Main route: ``main_up*`` (start to the merge), ``acc`` (the on-ramp's acceleration
    strip: lane 0, ``ramp_width_m`` wide, beside the road's lane(s); it ends with the edge),
    ``weave*`` (the weaving section), ``dec`` (the off-ramp's deceleration strip: lane 0
    again, added beside the road where ``dec`` starts), ``main_down*`` (gore to end). The
    on-ramp ``ramp`` joins ``acc_0``; the off-ramp ``offramp`` leaves ``dec_0`` at the gore.
    As for the on-ramp network, every main edge spreads its lanes to the right of the road's
    left edge (``y = width/2``), so the road's centre line stays at ``y = 0``. Long
    stretches are split into edges of at most ``max_edge_length_m`` (SUMO's sublane model
    costs more on long lanes, :attr:`NetworkSpec.max_edge_length_m`).
    """
    v = spec.speed_limit_mps
    w, wr, k = spec.width_m, spec.ramp_width_m, spec.lanes
    lane_w = w / k
    th = math.radians(spec.ramp_angle_deg)
    m, acc_end = spec.merge_position_m, spec.merge_position_m + spec.acceleration_lane_m
    gore = spec.diverge_position_m
    dec_start = gore - spec.deceleration_lane_m
    top = 0.5 * w
    ye = -0.5 * w - 0.5 * wr  # the strips' centre line
    rx, ry = m - spec.ramp_length_m * math.cos(th), ye - spec.ramp_length_m * math.sin(th)
    ox, oy = gore + spec.offramp_length_m * math.cos(th), ye - spec.offramp_length_m * math.sin(th)
    nodes = [
        _node("start", 0.0, top, "dead_end"), _node("merge", m, top),
        _node("acc_end", acc_end, top), _node("dec_start", dec_start, top),
        _node("gore", gore, top), _node("end", spec.length_m, top, "dead_end"),
        _node("ramp_start", rx, ry, "dead_end"), _node("off_end", ox, oy, "dead_end"),
    ]
    mx = spec.max_edge_length_m
    up_n, up = _split("main_up", 0.0, m, top, mx, "start", "merge")
    wv_n, wv = _split("weave", acc_end, dec_start, top, mx, "acc_end", "dec_start")
    dn_n, dn = _split("main_down", gore, spec.length_m, top, mx, "gore", "end")
    nodes += up_n + wv_n + dn_n
    main = lambda e: _edge(e[0], e[1], e[2], lane_w, v, lanes=k, spread="right")  # noqa: E731
    strip_widths = (wr, *([lane_w] * k))
    edges = [main(e) for e in up]
    edges.append(_edge("acc", "merge", "acc_end", lane_w, v, lanes=k + 1, spread="right",
                       lane_widths=strip_widths))
    edges += [main(e) for e in wv]
    edges.append(_edge("dec", "dec_start", "gore", lane_w, v, lanes=k + 1, spread="right",
                       lane_widths=strip_widths))
    edges += [main(e) for e in dn]
    edges.append(_edge("ramp", "ramp_start", "merge", wr, v, priority=1,
                       shape=f"{rx:.3f},{ry:.3f} {m:.3f},{ye:.3f}"))
    edges.append(_edge("offramp", "gore", "off_end", wr, v, priority=1,
                       shape=f"{gore:.3f},{ye:.3f} {ox:.3f},{oy:.3f}"))
    con = '    <connection from="{}" to="{}" fromLane="{}" toLane="{}"/>'.format
    connections = [con("ramp", "acc", 0, 0), con("dec", "offramp", 0, 0)]
    for i in range(k):
        connections += [con(up[-1][0], "acc", i, i + 1), con("acc", wv[0][0], i + 1, i),
                        con(wv[-1][0], "dec", i, i + 1), con("dec", dn[0][0], i + 1, i)]
    route = (*(e[0] for e in up), "acc", *(e[0] for e in wv), "dec", *(e[0] for e in dn))
    return _Sources(nodes, edges, route, ramp_route=("ramp", "acc"),
                    offramp_route=("offramp",), connections=tuple(connections))


def _sources_varying(spec: NetworkSpec) -> _Sources:
    v = spec.speed_limit_mps
    nodes = [_node("w0", 0.0, 0.0, "dead_end")]
    edges = []
    x = 0.0
    last = len(spec.width_profile)
    for i, (length, width) in enumerate(spec.width_profile):
        x += length
        nodes.append(_node(f"w{i + 1}", x, 0.0, "dead_end" if i + 1 == last else "priority"))
        edges.append(_edge(f"seg{i}", f"w{i}", f"w{i + 1}", width, v))
    return _Sources(nodes, edges, tuple(f"seg{i}" for i in range(last)))


_SOURCE_BUILDERS = {
    "straight": _sources_straight,
    "three_lane": _sources_three_lane,
    "ring": _sources_ring,
    "onramp": _sources_onramp,
    "varying_width": _sources_varying,
    "corridor": _sources_corridor,
}


def spec_hash(spec: NetworkSpec) -> str:
    """Hex digest (16 chars) of the kind's parameters, SUMO version and builder version."""
    payload = {
        "params": spec.cache_params(),
        "sumo": sumo_version(),
        "builder": BUILDER_VERSION,
    }
    blob = json.dumps(payload, sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def build_network(spec: NetworkSpec, cache_dir: Path | str | None = None) -> RoadNetwork:
    """Build (or reuse from the cache) the network for ``spec`` and return its road frame.

    Raises:
        NetworkError: netconvert failed, or (kind ``file``) the file is missing or
            unreadable, or the route's edges are not connected.
    """
    if spec.kind == "file":
        return _load_user_network(spec, cache_dir)
    root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    target = root / f"{spec.kind}-{spec_hash(spec)}"
    sources = _SOURCE_BUILDERS[spec.kind](spec)
    if not (target / NET_FILE_NAME).is_file():
        _build_into(target, spec, sources)
    net = load_road_network(
        target / NET_FILE_NAME,
        kind=spec.kind,
        main_route=sources.main_route,
        ramp_routes=(sources.ramp_route,) if sources.ramp_route else (),
        offramp_routes=(sources.offramp_route,) if sources.offramp_route else (),
        periodic=sources.periodic,
        speed_limit_mps=spec.speed_limit_mps,
    )
    if spec.kind == "ring":
        _check_ring_length(net, spec)
    return net


def _build_into(target: Path, spec: NetworkSpec, sources: _Sources) -> None:
    """Write sources and run netconvert in a temp dir, then move it into place atomically."""
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}-", dir=target.parent))
    tmp.chmod(0o755)  # mkdtemp makes it private; the cache is shared
    try:
        nod, edg = tmp / "road.nod.xml", tmp / "road.edg.xml"
        nod.write_text("<nodes>\n" + "\n".join(sources.nodes) + "\n</nodes>\n")
        edg.write_text("<edges>\n" + "\n".join(sources.edges) + "\n</edges>\n")
        options = list(sources.netconvert_options)
        if sources.connections:
            con = tmp / "road.con.xml"
            con.write_text("<connections>\n" + "\n".join(sources.connections)
                           + "\n</connections>\n")
            options += ["--connection-files", str(con)]
        _run_netconvert(nod, edg, tmp / NET_FILE_NAME, tuple(options))
        meta = {"spec": asdict(spec), "sumo": sumo_version(), "builder": BUILDER_VERSION}
        (tmp / SPEC_FILE_NAME).write_text(json.dumps(meta, indent=2, sort_keys=True))
        try:
            os.rename(tmp, target)
        except OSError:
            # Another process finished the same build first: keep theirs.
            if not (target / NET_FILE_NAME).is_file():
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def _check_ring_length(net: RoadNetwork, spec: NetworkSpec) -> None:
    rel = abs(net.length_m - spec.circumference_m) / spec.circumference_m
    if rel > RING_LENGTH_TOLERANCE:
        raise NetworkError(
            f"ring built with circumference {net.length_m:.2f} m instead of "
            f"{spec.circumference_m:.2f} m (more than {RING_LENGTH_TOLERANCE:.0%} off)"
        )


def _load_user_network(spec: NetworkSpec, cache_dir: Path | str | None = None) -> RoadNetwork:
    """The road frame of the user's network: of a copy without the forks onto its
    off-ramps' strips when it has any (:mod:`cosim.road.forks`; ``source_file`` and
    ``forks_removed`` record it), else of the file itself."""
    from cosim.road.forks import forks, without_forks
    from cosim.road.sumo_net import read_sumo_net

    path = Path(str(spec.net_file)).expanduser()
    if not path.is_file():
        raise NetworkError(f"network file not found: {path}")
    taken_out = tuple(forks(read_sumo_net(path), spec.route_edges, spec.offramp_routes()))
    source = path
    if taken_out:
        root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        path = without_forks(path, taken_out, root)
    net = load_road_network(
        path,
        kind="file",
        main_route=spec.route_edges,
        ramp_routes=spec.ramp_routes(),
        offramp_routes=spec.offramp_routes(),
        periodic=False,
        speed_limit_mps=None,
    )
    return replace(net, source_file=source.resolve(), forks_removed=taken_out)
