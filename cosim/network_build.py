"""Build SUMO road networks from a few parameters, and the road frame on them.

A :class:`NetworkSpec` describes a road (straight, ring, on-ramp, varying width,
a conventional three-lane baseline, or the user's own ``.net.xml``).
:func:`build_network` writes plain-XML sources (``.nod.xml``, ``.edg.xml``),
runs ``netconvert`` and returns a :class:`RoadNetwork`: the ``.net.xml`` plus
the road frame (longitudinal ``s`` along the main route, road edges in ``d``).

Built networks are cached under ``networks/cache/<kind>-<hash>/`` (or a
directory you pass, or ``$COSIM_NETWORK_CACHE``). The hash covers the
parameters that matter for the kind, the SUMO version and
:data:`BUILDER_VERSION`, so a second build with the same inputs reuses the file
and does not run netconvert.

Geometry conventions (all lengths in m, speeds in m/s):

* Lane-free roads have ONE wide lane per edge; SUMO's sublane model
  (``--lateral-resolution``) lets vehicles sit anywhere across it.
* Every edge uses ``spreadType="center"``: the edge's centre line is the road's
  centre line, so ``d`` (lateral offset, positive to the left) is the same
  quantity as SUMO's ``vehicle.getLateralLanePosition`` on single-lane roads
  and consecutive edges of different widths share their centre line.
* ``s`` is measured along lanes as SUMO measures positions (the lane ``length``
  attribute), including the internal junction lanes (``:node_0_0``), so that
  ``s = offset(lane) + lanePosition`` is continuous across junctions.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cosim.errors import ConfigError, NetworkError

#: Bump when the generated geometry changes, so old cache entries are not reused.
BUILDER_VERSION = 2

KINDS = ("straight", "ring", "onramp", "varying_width", "three_lane", "file")

#: Fewest edges of the ring; each is a circular arc drawn with RING_ARC_POINTS segments.
RING_EDGES = 4
RING_ARC_POINTS = 16

#: Width of one conventional lane in the three-lane baseline, m (3 x 3.4 = 10.2).
CONVENTIONAL_LANE_WIDTH_M = 3.4

#: Relative tolerance between the requested ring circumference and SUMO's lane length.
RING_LENGTH_TOLERANCE = 0.01

NET_FILE_NAME = "road.net.xml"
SPEC_FILE_NAME = "spec.json"

_REPO_ROOT = Path(__file__).resolve().parents[1]


def default_cache_dir() -> Path:
    """The network cache: ``$COSIM_NETWORK_CACHE`` or ``<repo>/networks/cache``."""
    env = os.environ.get("COSIM_NETWORK_CACHE")
    return Path(env) if env else _REPO_ROOT / "networks" / "cache"


# --------------------------------------------------------------------------------------
# Specification
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class NetworkSpec:
    """Parameters of a road network (lengths and widths in m, speeds in m/s).

    Attributes:
        kind: one of ``straight``, ``ring``, ``onramp``, ``varying_width``,
            ``three_lane``, ``file``.
        length_m: road length (straight, three_lane) or main-road length (onramp).
        width_m: width of the single wide lane (three_lane: total width of 3 lanes).
        circumference_m: ring circumference along the road centre line.
        ramp_length_m: straight-line distance from the ramp's start to the merge
            node; SUMO's measured ramp length is reported in
            :attr:`RoadNetwork.ramp_length_m` (the junction takes its share).
        ramp_width_m: width of the ramp's single lane.
        ramp_angle_deg: angle between ramp and main road at the merge, degrees.
        merge_position_m: distance from the main road's start to the merge node.
        width_profile: varying_width only: consecutive ``(length_m, width_m)``
            segments, one edge each, in driving order.
        speed_limit_mps: speed limit on every edge.
        max_edge_length_m: straight and ring roads are split into equal edges no
            longer than this (0: one edge per road; the ring has at least 4).
            Vehicles cross the joints unchanged, but SUMO's sublane model works
            per lane, and on one 2 km lane its step costs about 3.8 times as much
            as on 100 m edges (benchmarks/bench_sumo_options.py, 12 000 veh/h).
        net_file: kind ``file``: path to the user's ``.net.xml``.
        route_edges: kind ``file``: edge ids of the main route in driving order.
        ramp_edges: kind ``file`` (optional): edge ids of a ramp route that ends
            on a main-route edge.
    """

    kind: str = "straight"
    length_m: float = 2000.0
    width_m: float = 10.2
    circumference_m: float = 1000.0
    ramp_length_m: float = 300.0
    ramp_width_m: float = 3.4
    ramp_angle_deg: float = 8.0
    merge_position_m: float = 500.0
    width_profile: tuple[tuple[float, float], ...] = ()
    speed_limit_mps: float = 40.0
    max_edge_length_m: float = 100.0
    net_file: str | None = None
    route_edges: tuple[str, ...] = ()
    ramp_edges: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        # Accept lists from TOML/JSON but store hashable tuples.
        profile = tuple(tuple(float(v) for v in seg) for seg in self.width_profile)
        object.__setattr__(self, "width_profile", profile)
        object.__setattr__(self, "route_edges", tuple(str(e) for e in self.route_edges))
        object.__setattr__(self, "ramp_edges", tuple(str(e) for e in self.ramp_edges))
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ConfigError` (naming the field) for impossible values."""
        if self.kind not in KINDS:
            raise ConfigError(
                f"network.kind must be one of {', '.join(KINDS)} (got {self.kind!r})"
            )
        _positive("speed_limit_mps", self.speed_limit_mps)
        m = self.max_edge_length_m
        if isinstance(m, bool) or not isinstance(m, int | float) or not math.isfinite(m) or m < 0:
            raise ConfigError(f"network.max_edge_length_m must be >= 0 (got {m!r})")
        check = {
            "straight": self._validate_straight,
            "three_lane": self._validate_three_lane,
            "ring": self._validate_ring,
            "onramp": self._validate_onramp,
            "varying_width": self._validate_varying,
            "file": self._validate_file,
        }[self.kind]
        check()

    def _validate_straight(self) -> None:
        _positive("length_m", self.length_m)
        _positive("width_m", self.width_m)

    def _validate_three_lane(self) -> None:
        self._validate_straight()
        if self.width_m / 3 < 2.0:
            raise ConfigError(
                f"network.width_m must be >= 6 m for three_lane (3 lanes; got {self.width_m})"
            )

    def _validate_ring(self) -> None:
        _positive("width_m", self.width_m)
        _positive("circumference_m", self.circumference_m)
        radius = self.circumference_m / (2 * math.pi)
        if radius < 1.5 * self.width_m:
            raise ConfigError(
                f"network.circumference_m={self.circumference_m} is too small for "
                f"width_m={self.width_m} (radius must be >= 1.5 x width)"
            )

    def _validate_onramp(self) -> None:
        self._validate_straight()
        _positive("ramp_length_m", self.ramp_length_m)
        _positive("ramp_width_m", self.ramp_width_m)
        if not 0.0 < self.ramp_angle_deg < 90.0:
            raise ConfigError(
                f"network.ramp_angle_deg must be in (0, 90) (got {self.ramp_angle_deg})"
            )
        if not 0.0 < self.merge_position_m < self.length_m:
            raise ConfigError(
                f"network.merge_position_m must be in (0, length_m={self.length_m}) "
                f"(got {self.merge_position_m})"
            )

    def _validate_varying(self) -> None:
        if not self.width_profile:
            raise ConfigError("network.width_profile must list (length_m, width_m) segments")
        for i, seg in enumerate(self.width_profile):
            if len(seg) != 2:
                raise ConfigError(
                    f"network.width_profile[{i}] must be (length_m, width_m) (got {seg})"
                )
            _positive(f"width_profile[{i}] length", seg[0])
            _positive(f"width_profile[{i}] width", seg[1])

    def _validate_file(self) -> None:
        if not self.net_file:
            raise ConfigError("network.net_file is required for kind 'file'")
        if not self.route_edges:
            raise ConfigError("network.route_edges must list the main route's edges")

    def joints_m(self) -> tuple[float, ...]:
        """Positions along the road (m) where a built straight road or ring joins two
        edges (empty for other kinds; ring joints are approximate: SUMO's junctions)."""
        if self.kind == "straight":
            n, length = _n_edges(self.length_m, self.max_edge_length_m), self.length_m
            return tuple(length * k / n for k in range(1, n))
        if self.kind == "ring":
            n = _n_edges(self.circumference_m, self.max_edge_length_m, minimum=RING_EDGES)
            return tuple(self.circumference_m * k / n for k in range(n))
        return ()

    def cache_params(self) -> dict[str, Any]:
        """The parameters that determine the built network for this kind (for the hash)."""
        keys = {
            "straight": ("length_m", "width_m", "max_edge_length_m"),
            "three_lane": ("length_m", "width_m"),
            "ring": ("circumference_m", "width_m", "max_edge_length_m"),
            "onramp": (
                "length_m", "width_m", "ramp_length_m", "ramp_width_m",
                "ramp_angle_deg", "merge_position_m",
            ),
            "varying_width": ("width_profile",),
            "file": ("net_file", "route_edges", "ramp_edges"),
        }[self.kind]
        params = {k: getattr(self, k) for k in keys}
        params.update(kind=self.kind, speed_limit_mps=self.speed_limit_mps)
        return json.loads(json.dumps(params))  # tuples -> lists, stable for hashing


def _positive(name: str, value: float) -> None:
    if not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
        raise ConfigError(f"network.{name} must be a positive number (got {value!r})")


# --------------------------------------------------------------------------------------
# Result: the road frame on a built network
# --------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------
# netconvert
# --------------------------------------------------------------------------------------


def sumo_binary(name: str = "sumo") -> Path:
    """Path of a SUMO program (``sumo``, ``netconvert``, ``sumo-gui``...).

    Looked up in the eclipse-sumo package, then ``$SUMO_HOME/bin``, then PATH.
    """
    candidates: list[Path] = []
    try:
        import sumo  # the eclipse-sumo wheel

        candidates.append(Path(sumo.SUMO_HOME) / "bin" / name)
    except ImportError:
        pass
    if os.environ.get("SUMO_HOME"):
        candidates.append(Path(os.environ["SUMO_HOME"]) / "bin" / name)
    which = shutil.which(name)
    if which:
        candidates.append(Path(which))
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return c
    raise NetworkError(f"{name} not found: install eclipse-sumo (pip install eclipse-sumo)")


def netconvert_binary() -> Path:
    """Path of ``netconvert``."""
    return sumo_binary("netconvert")


@functools.lru_cache(maxsize=1)
def sumo_version() -> str:
    """SUMO version string of the netconvert in use, e.g. ``"1.28.0"``."""
    out = subprocess.run(
        [str(netconvert_binary()), "--version"], capture_output=True, text=True, check=False
    ).stdout
    m = re.search(r"netconvert\s+v?(?:ersion\s+)?(\S+)", out, flags=re.IGNORECASE)
    return m.group(1) if m else "unknown"


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


# --------------------------------------------------------------------------------------
# Plain-XML sources per kind
# --------------------------------------------------------------------------------------


@dataclass
class _Sources:
    """Plain-XML node and edge lines plus the routes they define."""

    nodes: list[str]
    edges: list[str]
    main_route: tuple[str, ...]
    ramp_route: tuple[str, ...] | None = None
    periodic: bool = False
    netconvert_options: tuple[str, ...] = ()


def _node(nid: str, x: float, y: float, ntype: str = "priority") -> str:
    return f'    <node id="{nid}" x="{x:.3f}" y="{y:.3f}" type="{ntype}"/>'


def _edge(
    eid: str, frm: str, to: str, width: float, speed: float,
    lanes: int = 1, priority: int = 2, shape: str | None = None,
) -> str:
    shape_attr = f' shape="{shape}"' if shape else ""
    return (
        f'    <edge id="{eid}" from="{frm}" to="{to}" numLanes="{lanes}" width="{width:.3f}"'
        f' speed="{speed:.3f}" priority="{priority}" spreadType="center"{shape_attr}/>'
    )


def _n_edges(length_m: float, max_edge_length_m: float, minimum: int = 1) -> int:
    """How many equal edges split a road of ``length_m`` (m) into pieces <= the maximum."""
    if max_edge_length_m <= 0:
        return minimum
    return max(minimum, math.ceil(length_m / max_edge_length_m - 1e-9))


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
    v = spec.speed_limit_mps
    th = math.radians(spec.ramp_angle_deg)
    m = spec.merge_position_m
    rx, ry = m - spec.ramp_length_m * math.cos(th), -spec.ramp_length_m * math.sin(th)
    nodes = [
        _node("start", 0.0, 0.0, "dead_end"),
        _node("merge", m, 0.0, "zipper"),  # zipper: ramp and main traffic alternate
        _node("end", spec.length_m, 0.0, "dead_end"),
        _node("ramp_start", rx, ry, "dead_end"),
    ]
    edges = [
        _edge("main_up", "start", "merge", spec.width_m, v, priority=2),
        _edge("main_down", "merge", "end", spec.width_m, v, priority=2),
        _edge("ramp", "ramp_start", "merge", spec.ramp_width_m, v, priority=1),
    ]
    return _Sources(nodes, edges, ("main_up", "main_down"), ramp_route=("ramp", "main_down"))


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
}


# --------------------------------------------------------------------------------------
# Building and caching
# --------------------------------------------------------------------------------------


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
        return _load_user_network(spec)
    root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    target = root / f"{spec.kind}-{spec_hash(spec)}"
    sources = _SOURCE_BUILDERS[spec.kind](spec)
    if not (target / NET_FILE_NAME).is_file():
        _build_into(target, spec, sources)
    net = load_road_network(
        target / NET_FILE_NAME,
        kind=spec.kind,
        main_route=sources.main_route,
        ramp_route=sources.ramp_route,
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
        _run_netconvert(nod, edg, tmp / NET_FILE_NAME, sources.netconvert_options)
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


def _load_user_network(spec: NetworkSpec) -> RoadNetwork:
    path = Path(str(spec.net_file)).expanduser()
    if not path.is_file():
        raise NetworkError(f"network file not found: {path}")
    return load_road_network(
        path,
        kind="file",
        main_route=spec.route_edges,
        ramp_route=spec.ramp_edges or None,
        periodic=False,
        speed_limit_mps=None,
    )


# --------------------------------------------------------------------------------------
# Reading a .net.xml into the road frame
# --------------------------------------------------------------------------------------


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
