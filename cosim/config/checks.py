"""Checks that need several sections at once: geometry, vehicles and time fit together.

Run when a :class:`~cosim.config.scenario.Scenario` is built (before anything is
written or started); :func:`check_against_network` repeats the geometric ones on the
built network (a user's ``.net.xml`` is only known then). Each failure is one
:class:`~cosim.errors.ConfigError` line that names the keys involved.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from cosim.errors import ConfigError
from cosim.sumo.sublanes import CHOICES_M

#: a :class:`cosim.config.scenario.Scenario` (not imported: that module calls this one
#: when a scenario is built, and the checks read its sections by name only)
Scenario = Any

#: Most vehicles a run may plan (open roads: inflows x duration; rings: density x length).
MAX_PLANNED_VEHICLES = 1_000_000
#: Longest main road a scenario may describe, m.
MAX_ROAD_LENGTH_M = 1_000_000.0
#: Most edges of a generated straight road or ring (its length / max_edge_length_m).
MAX_GENERATED_EDGES = 10_000
#: Most SUMO sublanes across the road (width / lateral resolution).
MAX_SUBLANES = 1000
#: An obstacle closer than this (m) to the joint of two edges sits on the junction.
JOINT_CLEARANCE_M = 0.5


def road_widths_m(sc: Scenario) -> list[float]:
    """Widths (m) of every part of the main road the spec describes (empty: a user's file)."""
    net = sc.network
    if net.kind == "file":
        return []
    if net.kind == "varying_width":
        return [w for _, w in net.width_profile]
    if net.kind == "three_lane":
        return [net.width_m / 3.0]
    return [net.width_m]


def road_length_m(sc: Scenario) -> float | None:
    """Length (m) of the main route as specified (None: a user's file)."""
    net = sc.network
    if net.kind == "ring":
        return net.circumference_m
    if net.kind == "varying_width":
        return sum(length for length, _ in net.width_profile)
    if net.kind == "file":
        return None
    return net.length_m


def check_scenario(sc: Scenario) -> None:
    """Everything that can be checked from the specs alone."""
    check_sections(sc)
    _check_size(sc)
    widths = road_widths_m(sc)
    if widths:
        _check_widths(sc, min(widths))
    length = road_length_m(sc)
    if length is not None:
        road_width = (sc.network.width_m if sc.network.kind == "three_lane"
                      else min(widths) if widths else None)
        _check_obstacle(sc, length, road_width)
    _check_obstacle_joints(sc)
    _check_queue(sc, length)
    if sc.scenario.world != "sumo" and sc.demand.human_model != "sl2015":
        raise ConfigError(f"demand.human_model={sc.demand.human_model!r} is a model of SUMO's "
                          f"drivers: it needs scenario.world = \"sumo\" (got "
                          f"{sc.scenario.world!r})")


def _check_queue(sc: Scenario, length_m: float | None) -> None:
    """A standing queue (``demand.queue_vpkm``) needs an open road that holds its span."""
    demand = sc.demand
    if demand.queue_vpkm <= 0:
        return
    if sc.network.kind == "ring":
        raise ConfigError("demand.queue_vpkm is for open roads (a ring's density is "
                          "demand.ring_density_vpkm)")
    end = demand.queue_span_m[1]
    if length_m is not None and end > length_m:
        raise ConfigError(f"demand.queue_span_m ends at {end:g} m, beyond the {length_m:g} m "
                          f"road")


def check_sections(sc: Scenario) -> None:
    """Every value of every section against its type: numbers finite, integers integral.

    Scenarios read from TOML are checked key by key on the way in
    (:mod:`cosim.config.schema`); this catches sections built in Python
    (``Scenario(demand=DemandSpec(size_classes=((nan, 1.8, 1.0),)))``).
    """
    from cosim.config.schema import check_value, type_hints

    for part in dataclasses.fields(sc):
        section = getattr(sc, part.name)
        if not dataclasses.is_dataclass(section):
            continue
        hints = type_hints(type(section))
        for f in dataclasses.fields(section):
            if f.init and f.name in hints:
                check_value(f"{part.name}.{f.name}", getattr(section, f.name), hints[f.name])


def _check_size(sc: Scenario) -> None:
    """Refuse runs too big to be meant: roads, sublanes, vehicles (each one line)."""
    net, run, demand = sc.network, sc.scenario, sc.demand
    length = road_length_m(sc)
    if length is not None and length > MAX_ROAD_LENGTH_M:
        raise ConfigError(f"the main road is {length:g} m long: at most "
                          f"{MAX_ROAD_LENGTH_M:g} m (1000 km)")
    if net.kind in ("straight", "ring") and net.max_edge_length_m > 0 and length is not None:
        edges = length / net.max_edge_length_m
        if edges > MAX_GENERATED_EDGES:
            raise ConfigError(
                f"a {length:g} m road in edges of at most network.max_edge_length_m = "
                f"{net.max_edge_length_m:g} m makes {edges:.0f} edges (at most "
                f"{MAX_GENERATED_EDGES}): raise network.max_edge_length_m"
            )
    widths = road_widths_m(sc)
    if widths and sc.network.kind != "three_lane":
        # "auto" takes at most the coarsest width (0.8 m): at least these sublanes
        res = (CHOICES_M[0] if _auto(run.lateral_resolution_m)
               else run.lateral_resolution_m)
        sublanes = max(widths) / res
        if sublanes > MAX_SUBLANES:
            raise ConfigError(
                f"a {max(widths):g} m wide road at scenario.lateral_resolution_m = "
                f"{run.lateral_resolution_m!s} ({res:g} m) makes {sublanes:.0f} SUMO sublanes "
                f"(at most {MAX_SUBLANES}): narrow the road or raise the lateral resolution"
            )
    if net.kind == "ring":
        planned = demand.ring_density_vpkm * net.circumference_m / 1000.0
        what = (f"demand.ring_density_vpkm = {demand.ring_density_vpkm:g} veh/km on "
                f"{net.circumference_m:g} m")
    else:
        ramps = net.kind in ("onramp", "file", "corridor")  # every origin's flow
        total = demand.total_vph() if ramps else demand.total_vph("main")
        planned = total * run.duration_s / 3600.0
        what = f"a demand of {total:g} veh/h for {run.duration_s:g} s"
    if planned > MAX_PLANNED_VEHICLES:
        raise ConfigError(f"{what} plans {planned:.3g} vehicles (at most "
                          f"{MAX_PLANNED_VEHICLES:.0e})")
    longest = max(c[0] for c in demand.size_classes)
    if length is not None and longest >= length:
        raise ConfigError(f"demand.size_classes has a {longest:g} m long vehicle: no shorter "
                          f"than the {length:g} m road")


def _auto(resolution) -> bool:
    """``scenario.lateral_resolution_m = "auto"``: chosen on the built road
    (:mod:`cosim.sumo.sublanes`: at most 0.8 m, at least 0.2 m)."""
    return isinstance(resolution, str)


def check_against_network(sc: Scenario, net) -> None:
    """The geometric checks again on the built network ``net`` (a RoadNetwork)."""
    widths = [float(w) for w in net.segment_width]
    if sc.network.kind == "three_lane":
        widths = [w / 3.0 for w in widths]
    _check_widths(sc, min(widths))
    _check_obstacle(sc, float(net.length_m), float(min(widths)), net=net)
    _check_obstacle_junctions(sc, net)
    longest = max(c[0] for c in sc.demand.size_classes)
    if longest >= float(net.length_m):
        raise ConfigError(f"demand.size_classes has a {longest:g} m long vehicle: no shorter "
                          f"than the {float(net.length_m):g} m main route")


def _check_obstacle_junctions(sc: Scenario, net) -> None:
    """The obstacle must stand on one edge of the built network, clear of its junctions
    (SUMO keeps a stopped vehicle's back on the previous lane and reports collisions
    with it there; a junction lane is no place to park)."""
    ob = sc.obstacle
    spans = list(getattr(net, "edge_spans", ()) or ())
    if not ob.present or len(spans) < 2 and not net.periodic:
        return
    back, front = ob.s_m - 0.5 * ob.length_m, ob.s_m + 0.5 * ob.length_m
    gaps = [(a[0], b[0], a[2], b[1]) for a, b in zip(spans, spans[1:], strict=False)]
    if net.periodic:  # the junction that closes the ring
        gaps.append((spans[-1][0], spans[0][0], spans[-1][2], spans[0][1] + net.length_m))
    length = float(net.length_m)
    for e0, e1, g0, g1 in gaps:
        for shift in ((0.0, -length, length) if net.periodic else (0.0,)):
            lo, hi = g0 + shift - JOINT_CLEARANCE_M, g1 + shift + JOINT_CLEARANCE_M
            if back < hi and front > lo:
                raise ConfigError(
                    f"obstacle ({back:g}..{front:g} m along the road) lies on the junction "
                    f"of edges {e0!r} and {e1!r} (s = {g0:.2f}..{g1:.2f} m): move "
                    "obstacle.s_m onto one edge"
                )


def _check_widths(sc: Scenario, narrowest_m: float) -> None:
    widest = max(c[1] for c in sc.demand.size_classes)
    margin = 2.0 * sc.safety.edge_margin_m
    if widest + margin >= narrowest_m:
        raise ConfigError(
            f"the road's narrowest part ({narrowest_m:g} m) is no wider than the widest "
            f"vehicle (demand.size_classes: {widest:g} m) plus the edge margins "
            f"(2 x safety.edge_margin_m = {margin:g} m)"
        )
    res = sc.scenario.lateral_resolution_m
    if sc.network.kind != "three_lane" and not _auto(res) and res > narrowest_m:
        raise ConfigError(
            f"scenario.lateral_resolution_m = {sc.scenario.lateral_resolution_m:g} m is wider "
            f"than the road's narrowest part ({narrowest_m:g} m)"
        )


def _check_obstacle(sc: Scenario, length_m: float, width_m: float | None, net=None) -> None:
    ob = sc.obstacle
    if not ob.present:
        return
    back, front = ob.s_m - 0.5 * ob.length_m, ob.s_m + 0.5 * ob.length_m
    if sc.network.kind != "ring" and (back < 0.0 or front > length_m):
        raise ConfigError(
            f"obstacle ({back:g}..{front:g} m along the road) does not lie on the road "
            f"(main route 0..{length_m:g} m): set obstacle.s_m"
        )
    if ob.appear_s >= sc.scenario.duration_s:
        raise ConfigError(f"obstacle.appear_s = {ob.appear_s:g} s is after the run ends "
                          f"(scenario.duration_s = {sc.scenario.duration_s:g} s)")
    if net is not None:
        right, left = net.edges_at([ob.s_m])
        right, left = float(right[0]), float(left[0])
    elif width_m is not None:
        right, left = -0.5 * width_m, 0.5 * width_m
    else:
        return
    if ob.width_m >= left - right:
        raise ConfigError(
            f"obstacle.width_m = {ob.width_m:g} m covers the whole road "
            f"({left - right:g} m wide at s = {ob.s_m:g} m): nothing could pass"
        )
    lo, hi = ob.d_m - 0.5 * ob.width_m, ob.d_m + 0.5 * ob.width_m
    if lo < right - 1e-9 or hi > left + 1e-9:
        raise ConfigError(
            f"obstacle (d = {lo:g}..{hi:g} m) reaches outside the road "
            f"({right:g}..{left:g} m at s = {ob.s_m:g} m): set obstacle.d_m"
        )


def _check_obstacle_joints(sc: Scenario) -> None:
    ob = sc.obstacle
    if not ob.present:
        return
    back, front = ob.s_m - 0.5 * ob.length_m, ob.s_m + 0.5 * ob.length_m
    for x in sc.network.joints_m():
        if back - 0.5 <= x <= front + 0.5:
            # SUMO keeps the back of a vehicle that never moves at the centre of the
            # previous edge's lane and reports phantom collisions there.
            raise ConfigError(
                f"obstacle ({back:g}..{front:g} m) lies on the joint of two road "
                f"edges at s = {x:g} m: move obstacle.s_m or set "
                "network.max_edge_length_m (0: one edge)"
            )
