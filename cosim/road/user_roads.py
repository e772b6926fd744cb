"""Roads as a user draws them: plain ``.nod.xml`` / ``.edg.xml`` built with netconvert's
defaults, in classes, each drawn at random from a seed.

Our own generators (:mod:`cosim.road.build`) centre every edge (``spreadType="center"``); a
user does not. netconvert's default hangs an edge's lanes to the right of the line drawn
through its nodes, so a narrower edge is aligned with the wider one's left border, its
centre line moves sideways, and the junction lane between them is a short S (3-4 m long at
netconvert's default junction size) that shifts by the difference. These classes produce
such roads, with the geometry drawn at random within each class (seeded), so that a law
and the SUMO adapter are checked on the class, not on a few cases:

==================  =====================================================================
``step``            an abrupt width drop to a neck and an abrupt widening after it; the
                    neck aligned left (netconvert's default), right (its edge drawn lower)
                    or centred (``spreadType="center"``)
``taper``           a width drop drawn as 2-5 short pieces, each narrower than the last
``s_curve``         narrowing pieces, then a curved narrow edge (a bend of 20-60 degrees
                    drawn with shape points), and a wide edge after
``bend``            a bend at constant width (the control case: nothing moves sideways)
``long_junction``   an abrupt drop at a node with a junction radius of 8-20 m (long
                    junction lanes)
``lane_drop``       a road drawn with 3.4 m lanes: 3 lanes, 2 lanes, 3 lanes (the lane
                    count changes at both joints)
==================  =====================================================================

Every class can carry a stopped vehicle in its narrow section (``obstacle=True``).
:func:`draw_freeway` draws a freeway with two on-ramps and two off-ramps.

:func:`draw` returns a :class:`UserRoad`: the sources, the main route and where the narrow
section lies; :func:`build` runs netconvert (defaults only: no option but the output) and
returns the ``.net.xml``. Lengths in m, widths in m, speeds in m/s.
"""

from __future__ import annotations

import math
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cosim.errors import NetworkError

CLASSES = ("step", "taper", "s_curve", "bend", "long_junction", "lane_drop")
ALIGNMENTS = ("left", "right", "centre")
#: The wide road's width, m (three 3.4 m lanes' worth, TUM LaneFreeDrive's road).
WIDE_M = 10.2
SPEED_MPS = 40.0


@dataclass(frozen=True)
class UserRoad:
    """A drawn road: plain-XML sources and what a scenario needs to drive it.

    Attributes:
        name: ``class-seed`` (with the alignment for ``step``).
        nod, edg: the plain-XML sources' text.
        route: the main route's edge ids in driving order.
        narrow_from_m, narrow_to_m: x (m, along the drawing's first edge direction) of
            the narrow section's start and end, approximately ``s``.
        narrow_width_m: the narrowest width drawn, m.
        obstacle: ``(edge, fraction, side)``: a stopped car's centre at this fraction of
            the narrow section's edge, on its ``"right"`` or ``"left"`` half; or None.
        params: the drawn numbers (for the record).
    """

    name: str
    nod: str
    edg: str
    route: tuple[str, ...]
    narrow_from_m: float
    narrow_to_m: float
    narrow_width_m: float
    obstacle: tuple[str, float, str] | None = None
    params: dict = field(default_factory=dict)
    #: a freeway's on-ramp and off-ramp routes (``network.ramp_edges``, ``offramp_edges``)
    ramps: tuple[tuple[str, ...], ...] = ()
    offramps: tuple[tuple[str, ...], ...] = ()


def _nodes(points: list[tuple[str, float, float]], radius: dict | None = None) -> str:
    radius = radius or {}
    rows = []
    for nid, x, y in points:
        extra = f' radius="{radius[nid]:.2f}"' if nid in radius else ""
        rows.append(f'    <node id="{nid}" x="{x:.2f}" y="{y:.2f}"{extra}/>')
    return "<nodes>\n" + "\n".join(rows) + "\n</nodes>\n"


def _edges(rows: list[str]) -> str:
    return "<edges>\n" + "\n".join("    " + r for r in rows) + "\n</edges>\n"


def _edge(eid: str, a: str, b: str, width: float, lanes: int = 1, spread: str | None = None,
          shape: list[tuple[float, float]] | None = None) -> str:
    extra = f' spreadType="{spread}"' if spread else ""
    if shape:
        extra += ' shape="' + " ".join(f"{x:.2f},{y:.2f}" for x, y in shape) + '"'
    return (f'<edge id="{eid}" from="{a}" to="{b}" numLanes="{lanes}" '
            f'width="{width / lanes:.2f}" speed="{SPEED_MPS:.2f}"{extra}/>')


def draw(kind: str, seed: int, alignment: str | None = None, obstacle: bool = False
         ) -> UserRoad:
    """A road of class ``kind`` drawn from ``seed`` (see the module docstring).

    ``alignment`` (``step`` only): ``left``, ``right`` or ``centre``; default drawn from the
    seed. ``obstacle``: a stopped car (5 m x 2 m) in the narrow section, on its right or
    left half (drawn)."""
    if kind not in CLASSES:
        raise NetworkError(f"user road class must be one of {', '.join(CLASSES)}, got {kind!r}")
    rng = np.random.default_rng([seed, CLASSES.index(kind)])
    fn = {"step": _step, "taper": _taper, "s_curve": _s_curve, "bend": _bend,
          "long_junction": _long_junction, "lane_drop": _lane_drop}[kind]
    road = fn(rng, seed, alignment)
    if obstacle:
        frac = float(rng.uniform(0.35, 0.65))
        side = str(rng.choice(["right", "left"]))
        road = UserRoad(road.name + "-obstacle", road.nod, road.edg, road.route,
                        road.narrow_from_m, road.narrow_to_m, road.narrow_width_m,
                        (road.params["narrow_edge"], frac, side),
                        {**road.params, "obstacle_fraction": frac, "obstacle_side": side})
    return road


def _approach(rng) -> float:
    return float(rng.uniform(450.0, 650.0))


def _step(rng, seed: int, alignment: str | None) -> UserRoad:
    align = alignment or str(rng.choice(ALIGNMENTS))
    if align not in ALIGNMENTS:
        raise NetworkError(f"alignment must be one of {', '.join(ALIGNMENTS)}, got {align!r}")
    w = float(rng.uniform(6.2, 7.6))
    x1 = _approach(rng)
    x2 = x1 + float(rng.uniform(250.0, 450.0))
    x3 = x2 + 400.0
    spread = "center" if align == "centre" else None
    shape = None
    if align == "right":  # drawn lower by the width difference: right borders in line
        dy = -(WIDE_M - w)
        shape = [(x1, dy), (x2, dy)]
    nod = _nodes([("a", 0, 0), ("b", x1, 0), ("c", x2, 0), ("d", x3, 0)])
    edg = _edges([_edge("wide", "a", "b", WIDE_M, spread=spread),
                  _edge("neck", "b", "c", w, spread=spread, shape=shape),
                  _edge("after", "c", "d", WIDE_M, spread=spread)])
    return UserRoad(f"step-{align}-{seed}", nod, edg, ("wide", "neck", "after"), x1, x2, w,
                    params={"alignment": align, "neck_width_m": w, "neck_m": x2 - x1,
                            "narrow_edge": "neck"})


def _taper(rng, seed: int, alignment: str | None) -> UserRoad:
    n = int(rng.integers(2, 6))
    w_end = float(rng.uniform(6.2, 7.6))
    widths = list(np.linspace(WIDE_M, w_end, n + 1)[1:])
    lengths = list(rng.uniform(12.0, 40.0, n))
    x = _approach(rng)
    pts = [("a", 0.0, 0.0), ("t0", x, 0.0)]
    rows = []
    prev = "t0"
    rows.append(_edge("wide", "a", "t0", WIDE_M))
    for i, (wi, li) in enumerate(zip(widths[:-1], lengths[:-1], strict=True)):
        x += li
        pts.append((f"t{i + 1}", x, 0.0))
        rows.append(_edge(f"taper{i}", prev, f"t{i + 1}", wi))
        prev = f"t{i + 1}"
    narrow_from = x
    neck = float(rng.uniform(200.0, 400.0))
    x += neck
    pts.append(("n1", x, 0.0))
    rows.append(_edge("neck", prev, "n1", w_end))
    narrow_to = x
    x += 400.0
    pts.append(("e", x, 0.0))
    rows.append(_edge("after", "n1", "e", WIDE_M))
    route = ("wide", *[f"taper{i}" for i in range(n - 1)], "neck", "after")
    return UserRoad(f"taper-{seed}", _nodes(pts), _edges(rows), route, narrow_from, narrow_to,
                    w_end, params={"pieces": n, "widths_m": widths, "lengths_m": lengths,
                                   "narrow_edge": "neck"})


def _arc(cx: float, cy: float, r: float, a0: float, a1: float, n: int = 12):
    return [(cx + r * math.cos(a), cy + r * math.sin(a)) for a in np.linspace(a0, a1, n)]


def _s_curve(rng, seed: int, alignment: str | None) -> UserRoad:
    n = int(rng.integers(2, 4))
    w_end = float(rng.uniform(6.6, 7.8))
    widths = list(np.linspace(WIDE_M, w_end, n + 1)[1:])
    x = _approach(rng)
    pts = [("a", 0.0, 0.0), ("t0", x, 0.0)]
    rows = [_edge("wide", "a", "t0", WIDE_M)]
    prev = "t0"
    for i, wi in enumerate(widths[:-1]):
        x += 30.0
        pts.append((f"t{i + 1}", x, 0.0))
        rows.append(_edge(f"taper{i}", prev, f"t{i + 1}", wi))
        prev = f"t{i + 1}"
    narrow_from = x
    turn = math.radians(float(rng.uniform(20.0, 60.0))) * float(rng.choice([-1.0, 1.0]))
    r = float(rng.uniform(120.0, 250.0))
    # a bend starting at (x, 0) heading east, turning left (turn > 0) or right
    sign = 1.0 if turn > 0 else -1.0
    cx, cy = x, sign * r
    a0 = -sign * math.pi / 2
    arc = _arc(cx, cy, r, a0, a0 + turn)
    ex, ey = arc[-1]
    pts.append(("c1", ex, ey))
    rows.append(_edge("curve", prev, "c1", w_end, shape=arc))
    narrow_to = narrow_from + r * abs(turn)
    hx, hy = math.cos(turn), math.sin(turn)
    pts.append(("e", ex + 400.0 * hx, ey + 400.0 * hy))
    rows.append(_edge("after", "c1", "e", WIDE_M))
    route = ("wide", *[f"taper{i}" for i in range(n - 1)], "curve", "after")
    return UserRoad(f"s_curve-{seed}", _nodes(pts), _edges(rows), route, narrow_from,
                    narrow_to, w_end, params={"widths_m": widths, "turn_deg":
                                              math.degrees(turn), "radius_m": r,
                                              "narrow_edge": "curve"})


def _bend(rng, seed: int, alignment: str | None) -> UserRoad:
    x = _approach(rng)
    turn = math.radians(float(rng.uniform(30.0, 90.0))) * float(rng.choice([-1.0, 1.0]))
    r = float(rng.uniform(120.0, 300.0))
    sign = 1.0 if turn > 0 else -1.0
    a0 = -sign * math.pi / 2
    arc = _arc(x, sign * r, r, a0, a0 + turn, 16)
    ex, ey = arc[-1]
    hx, hy = math.cos(turn), math.sin(turn)
    pts = [("a", 0.0, 0.0), ("b", x, 0.0), ("c", ex, ey), ("d", ex + 400 * hx, ey + 400 * hy)]
    rows = [_edge("in", "a", "b", WIDE_M), _edge("bend", "b", "c", WIDE_M, shape=arc),
            _edge("out", "c", "d", WIDE_M)]
    return UserRoad(f"bend-{seed}", _nodes(pts), _edges(rows), ("in", "bend", "out"), x,
                    x + r * abs(turn), WIDE_M, params={"turn_deg": math.degrees(turn),
                                                       "radius_m": r, "narrow_edge": "bend"})


def _long_junction(rng, seed: int, alignment: str | None) -> UserRoad:
    w = float(rng.uniform(6.2, 7.6))
    x1 = _approach(rng)
    x2 = x1 + float(rng.uniform(250.0, 450.0))
    radius = {"b": float(rng.uniform(8.0, 20.0)), "c": float(rng.uniform(8.0, 20.0))}
    nod = _nodes([("a", 0, 0), ("b", x1, 0), ("c", x2, 0), ("d", x2 + 400.0, 0)], radius)
    edg = _edges([_edge("wide", "a", "b", WIDE_M), _edge("neck", "b", "c", w),
                  _edge("after", "c", "d", WIDE_M)])
    return UserRoad(f"long_junction-{seed}", nod, edg, ("wide", "neck", "after"), x1, x2, w,
                    params={"neck_width_m": w, "radius_m": radius, "narrow_edge": "neck"})


def _lane_drop(rng, seed: int, alignment: str | None) -> UserRoad:
    x1 = _approach(rng)
    x2 = x1 + float(rng.uniform(250.0, 450.0))
    nod = _nodes([("a", 0, 0), ("b", x1, 0), ("c", x2, 0), ("d", x2 + 400.0, 0)])
    edg = _edges([_edge("three", "a", "b", 10.2, lanes=3), _edge("two", "b", "c", 6.8, lanes=2),
                  _edge("three_after", "c", "d", 10.2, lanes=3)])
    return UserRoad(f"lane_drop-{seed}", nod, edg, ("three", "two", "three_after"), x1, x2,
                    6.8, params={"narrow_edge": "two"})


#: A drawn freeway's lane count and netconvert's default lane width, m.
FREEWAY_LANES = 3
DEFAULT_LANE_M = 3.2


def draw_freeway(seed: int) -> UserRoad:
    """A freeway as a user draws one (netconvert's defaults: 3.2 m lanes, every edge's lanes
    hung right of its nodes), drawn from ``seed``: two on-ramps, each adding a lane to the
    road's edge after it (an acceleration strip of 150-300 m), and two off-ramps, each
    leaving from a lane added to the road's edge before it (a deceleration strip of
    120-300 m), in the order on-ramp, off-ramp, on-ramp, off-ramp; the weaving section
    between an acceleration strip and the next deceleration strip 150-600 m, the road
    between the first off-ramp and the second on-ramp 150-500 m. The ramps meet the road
    at 8-20 degrees from 200 m away. Its demand names: ``ramp``, ``ramp2``, ``off``,
    ``off2``; ``narrow_from_m``/``narrow_to_m`` span the first weaving section."""
    rng = np.random.default_rng([seed, len(CLASSES) + 1])
    k = FREEWAY_LANES
    pieces = [("m0", k, float(rng.uniform(300.0, 500.0)))]  # (edge, lanes, length)
    drawn = {}
    for i in (1, 2):
        acc, weave, dec = (float(rng.uniform(150.0, 300.0)), float(rng.uniform(150.0, 600.0)),
                           float(rng.uniform(120.0, 300.0)))
        after = float(rng.uniform(150.0, 500.0)) if i == 1 else 400.0
        pieces += [(f"acc{i}", k + 1, acc), (f"weave{i}", k, weave), (f"dec{i}", k + 1, dec),
                   (f"after{i}", k, after)]
        drawn.update({f"acceleration_{i}_m": acc, f"weaving_{i}_m": weave,
                      f"deceleration_{i}_m": dec, f"after_{i}_m": after})
    xs = np.cumsum([0.0] + [p[2] for p in pieces])
    nodes = [(f"n{j}", float(x), 0.0) for j, x in enumerate(xs)]
    edges = [_edge(eid, f"n{j}", f"n{j + 1}", lanes * DEFAULT_LANE_M, lanes=lanes)
             for j, (eid, lanes, _) in enumerate(pieces)]
    names = [p[0] for p in pieces]
    ramps, offramps = [], []
    for i in (1, 2):
        angle = math.radians(float(rng.uniform(8.0, 20.0)))
        j_in, j_out = names.index(f"acc{i}"), names.index(f"dec{i}") + 1
        x_in, x_out = xs[j_in], xs[j_out]
        dx, dy = 200.0 * math.cos(angle), -200.0 * math.sin(angle)
        nodes += [(f"r{i}", float(x_in - dx), float(dy)), (f"o{i}", float(x_out + dx), float(dy))]
        edges += [_edge(f"in{i}", f"r{i}", f"n{j_in}", DEFAULT_LANE_M),
                  _edge(f"out{i}", f"n{j_out}", f"o{i}", DEFAULT_LANE_M)]
        ramps.append((f"in{i}", f"acc{i}"))
        offramps.append((f"out{i}",))
        drawn[f"ramp_angle_{i}_deg"] = math.degrees(angle)
    w0 = names.index("weave1")
    return UserRoad(f"freeway-{seed}", _nodes(nodes), _edges(edges), tuple(names),
                    float(xs[w0]), float(xs[w0 + 1]), k * DEFAULT_LANE_M, params=drawn,
                    ramps=tuple(ramps), offramps=tuple(offramps))


def build(road: UserRoad, folder: Path) -> Path:
    """Write the road's sources into ``folder`` and run netconvert with its defaults;
    returns the ``.net.xml``."""
    from cosim.sumo.binaries import netconvert_binary

    folder.mkdir(parents=True, exist_ok=True)
    nod, edg = folder / f"{road.name}.nod.xml", folder / f"{road.name}.edg.xml"
    nod.write_text(road.nod)
    edg.write_text(road.edg)
    out = folder / f"{road.name}.net.xml"
    proc = subprocess.run([str(netconvert_binary()), "-n", str(nod), "-e", str(edg),
                           "-o", str(out)], capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise NetworkError(f"netconvert failed on {road.name}: {proc.stderr.strip()[:300]}")
    return out
