"""Checks that need several sections at once: geometry, vehicles and time fit together.

Run when a :class:`~cosim.config.scenario.Scenario` is built (before anything is
written or started); :func:`check_against_network` repeats the geometric ones on the
built network (a user's ``.net.xml`` is only known then). Each failure is one
:class:`~cosim.errors.ConfigError` line that names the keys involved.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cosim.errors import ConfigError

if TYPE_CHECKING:
    from cosim.config.scenario import Scenario


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
    widths = road_widths_m(sc)
    if widths:
        _check_widths(sc, min(widths))
    length = road_length_m(sc)
    if length is not None:
        _check_obstacle(sc, length, min(widths) if widths else None)
    _check_obstacle_joints(sc)


def check_against_network(sc: Scenario, net) -> None:
    """The geometric checks again on the built network ``net`` (a RoadNetwork)."""
    widths = [float(w) for w in net.segment_width]
    if sc.network.kind == "three_lane":
        widths = [w / 3.0 for w in widths]
    _check_widths(sc, min(widths))
    _check_obstacle(sc, float(net.length_m), float(min(widths)), net=net)


def _check_widths(sc: Scenario, narrowest_m: float) -> None:
    widest = max(c[1] for c in sc.demand.size_classes)
    margin = 2.0 * sc.safety.edge_margin_m
    if widest + margin >= narrowest_m:
        raise ConfigError(
            f"the road's narrowest part ({narrowest_m:g} m) is no wider than the widest "
            f"vehicle (demand.size_classes: {widest:g} m) plus the edge margins "
            f"(2 x safety.edge_margin_m = {margin:g} m)"
        )
    if sc.network.kind != "three_lane" and sc.scenario.lateral_resolution_m > narrowest_m:
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
