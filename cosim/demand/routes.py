"""SUMO route files (``.rou.xml``) of a demand plan: vehicle types, routes, vehicles.

Every vehicle is written explicitly, one ``<vehicle>`` element each (type, depart time,
lateral depart position, desired speed), so a route file is fully determined by the
:class:`DemandSpec`, the network, the seed and the horizon. SUMO's own randomness
(the Krauss driver imperfection ``sigma`` of human drivers) is governed by SUMO's
``--seed``, which the runner passes.

Vehicle types (``vType``): one per (kind, size class), ids ``cav_<k>`` and ``hdv_<k>``;
the co-simulation recognises CAVs by the type-id prefix ``cav``. Vehicle ids are
``<kind>.<origin>.<n>``, e.g. ``cav.main.17``, ``hdv.ramp.3``, ``cav.ring.0``. The
desired speed v0 is written as ``speedFactor = v0 / speed limit`` (SUMO's drivers aim
for v0) and as ``<param key="desiredSpeed">``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from xml.sax.saxutils import quoteattr

from cosim.demand.humans import TUM_MODELS, reaction_times, vtype_id
from cosim.demand.plan import DemandPlan, _Vehicle, plan_vehicles, route_id
from cosim.demand.spec import (
    ACCEL_MPS2,
    CAV_PREFIX,
    CAV_TAU_S,
    DECEL_MPS2,
    EMERGENCY_DECEL_MPS2,
    HDV_LC_ASSERTIVE,
    HDV_LC_PUSHY,
    HDV_LC_TIME_TO_IMPATIENCE_S,
    HDV_MAX_SPEED_LAT_MPS,
    HDV_MIN_GAP_LAT_M,
    HDV_PREFIX,
    HDV_SIGMA,
    HDV_TAU_S,
    MAX_SPEED_LAT_MPS,
    MIN_GAP_LAT_M,
    MIN_GAP_M,
    VTYPE_MAX_SPEED_MPS,
    DemandSpec,
)
from cosim.errors import ConfigError
from cosim.road.frame import RoadNetwork


@dataclass(frozen=True)
class RouteInfo:
    """What :func:`write_routes` wrote.

    Attributes:
        path: the route file.
        seed: the seed used.
        n_cav, n_hdv: vehicles of each kind (all origins).
        n_main, n_ramp, n_ring: vehicles per origin.
        vehicle_ids: all vehicle ids in departure order.
        cav_ids: ids of the CAVs.
        ring_vehicle_ids: ids of the vehicles placed on the ring at t=0 (ring only).
        arrival_process: "poisson", "uniform" or "ring_initial" (all at t=0).
        desired_speed_mps: desired speed (m/s) per vehicle id.
        ring_density_vpkm: realised ring density n / circumference, veh/km (ring only).
        ring_route_repeat: the ``repeat`` count of the ring routes (ring only).
        ring_initial_speed_mps: common speed of the ring vehicles at t=0 (ring only).
        destination: ``"main"`` or ``"off"`` per vehicle id (open roads).
    """

    path: Path
    seed: int
    n_cav: int
    n_hdv: int
    n_main: int
    n_ramp: int
    n_ring: int
    vehicle_ids: tuple[str, ...]
    cav_ids: tuple[str, ...]
    ring_vehicle_ids: tuple[str, ...]
    arrival_process: str
    desired_speed_mps: Mapping[str, float] = field(repr=False, compare=False)
    ring_density_vpkm: float | None = None
    ring_route_repeat: int | None = None
    ring_initial_speed_mps: float | None = None
    destination: Mapping[str, str] = field(default_factory=dict, repr=False, compare=False)


# Vehicle colours in sumo-gui (8-bit RGB), the same as the figures'
# (cosim/analysis/figures/style.py): matplotlib's tab:blue for CAVs and tab:orange for HDVs,
# a colour-blind-safe pair that also differs in lightness (relative luminance 0.17 vs 0.36).
CAV_RGB = (31, 119, 180)
HDV_RGB = (255, 127, 14)


def lane_change_attributes(kind: str, lanes: bool) -> dict[str, str]:
    """The lane-change attributes of a ``<vType>`` of ``kind`` (``"cav"`` or ``"hdv"``).

    ``lanes=True`` (three_lane baseline): SUMO's LC2013 with its defaults for both kinds.
    ``lanes=False`` (lane-free road): SUMO's sublane model SL2015 with
    ``latAlignment="arbitrary"``; CAVs keep SUMO's lateral gap :data:`MIN_GAP_LAT_M`
    (our controller drives them), human drivers get the calibrated lateral gap, lateral
    speed, pushiness, assertiveness and impatience of :mod:`cosim.demand.spec`
    (``HDV_*``; measured by experiments/calibrate_humans.py).
    Values are strings, in the order they are written.
    """
    if lanes:
        return {"laneChangeModel": "LC2013"}
    attrs = {"laneChangeModel": "SL2015", "latAlignment": "arbitrary"}
    if kind == CAV_PREFIX:
        attrs.update(minGapLat=f"{MIN_GAP_LAT_M}", maxSpeedLat=f"{MAX_SPEED_LAT_MPS}")
    else:
        attrs.update(
            minGapLat=f"{HDV_MIN_GAP_LAT_M}",  # m
            maxSpeedLat=f"{HDV_MAX_SPEED_LAT_MPS}",  # m/s
            lcPushy=f"{HDV_LC_PUSHY}",
            lcAssertive=f"{HDV_LC_ASSERTIVE}",
            lcTimeToImpatience=f"{HDV_LC_TIME_TO_IMPATIENCE_S}",  # s
        )
    return attrs


def vtype_lines(demand: DemandSpec, lanes: bool, human_taus=()) -> list[str]:
    """``<vType>`` elements: ``cav_<k>`` and ``hdv_<k>`` for every size class.

    Car following is SUMO's Krauss model: CAVs with ``sigma = 0`` and ``tau =``
    :data:`CAV_TAU_S`, human drivers with :data:`HDV_SIGMA` and :data:`HDV_TAU_S` on both
    road kinds (the lane-free and three-lane human arms differ only in lanes). Lane
    changing: :func:`lane_change_attributes` (``lanes=False``: lane-free road, SL2015;
    ``lanes=True``: three_lane baseline, LC2013).
    With one of TUM's human models (``demand.human_model``, :mod:`cosim.demand.humans`)
    the human types are ``hdv_<k>_t<centiseconds>`` instead, one per (class k, reaction
    time) in ``human_taus`` (pairs ``(k, tau_s)``), with that model's attributes.
    CAV types are drawn in :data:`CAV_RGB` (blue), HDV types in :data:`HDV_RGB` (orange).
    """
    out = []
    # CAVs get a short reaction time ``tau`` so that SUMO's insertion check lets
    # them enter at CAV headways (our controller drives them from the first step).
    kinds = [(CAV_PREFIX, CAV_RGB, 0.0, CAV_TAU_S)]
    if demand.human_model == "sl2015":
        kinds.append((HDV_PREFIX, HDV_RGB, HDV_SIGMA, HDV_TAU_S))
    for kind, colour, sigma, tau in kinds:
        colour = ",".join(str(c) for c in colour)
        lc = " ".join(f'{k}="{v}"' for k, v in lane_change_attributes(kind, lanes).items())
        for k, (length, width, _p) in enumerate(demand.size_classes):
            out.append(
                f'    <vType id="{kind}_{k}" vClass="passenger" length="{length}" '
                f'width="{width}" minGap="{MIN_GAP_M}" accel="{ACCEL_MPS2}" '
                f'decel="{DECEL_MPS2}" emergencyDecel="{EMERGENCY_DECEL_MPS2}" '
                f'maxSpeed="{VTYPE_MAX_SPEED_MPS}" speedDev="0" sigma="{sigma}" tau="{tau}" '
                f'color="{colour}" {lc}>\n'
                f'        <param key="cosim.kind" value="{kind}"/>\n'
                f"    </vType>"
            )
    if demand.human_model != "sl2015":
        model = TUM_MODELS[demand.human_model]
        colour = ",".join(str(c) for c in HDV_RGB)
        for k, tau in sorted(set(human_taus)):
            length, width, _p = demand.size_classes[k]
            attrs = " ".join(f'{a}="{v}"' for a, v in model.vtype_attributes(tau, lanes).items())
            out.append(
                f'    <vType id="{vtype_id(f"{HDV_PREFIX}_{k}", tau)}" vClass="passenger" '
                f'length="{length}" width="{width}" maxSpeed="{VTYPE_MAX_SPEED_MPS}" '
                f'speedDev="0" color="{colour}" {attrs}>\n'
                f'        <param key="cosim.kind" value="{HDV_PREFIX}"/>\n'
                f"    </vType>"
            )
    return out


def with_human_model(vehicles: list[_Vehicle], demand: DemandSpec, seed: int):
    """``(vehicles, human_taus)``: with one of TUM's human models every human driver gets
    its reaction time (:func:`cosim.demand.humans.reaction_times`, in the order of
    ``vehicles``) and the vType of its class and reaction time; ``human_taus`` the pairs
    ``(class, tau_s)`` used. Unchanged, with no pairs, for ``"sl2015"``."""
    if demand.human_model == "sl2015":
        return vehicles, []
    hdv = [i for i, v in enumerate(vehicles) if not v.is_cav]
    taus = reaction_times(len(hdv), TUM_MODELS[demand.human_model], seed)
    out = list(vehicles)
    pairs = []
    for i, tau in zip(hdv, taus.tolist(), strict=True):
        out[i] = replace(vehicles[i], vtype=vtype_id(vehicles[i].vtype, tau))
        pairs.append((int(vehicles[i].vtype.rsplit("_", 1)[1]), tau))
    return out, pairs


def _route_lines(net: RoadNetwork, repeat: int | None) -> list[str]:
    """Ring: one looping route per start edge. Open roads: a route per origin and
    destination (:func:`~cosim.demand.plan.route_id`; :meth:`RoadNetwork.od_route`),
    those the network cannot connect left out."""
    if net.periodic:
        return [
            f'    <route id="ring.{e}" edges="{" ".join(net.ring_route_edges(e))}" '
            f'repeat="{repeat}"/>'
            for e in net.main_route
        ]
    lines = []
    for origin in net.origins:
        for dest in net.destinations:
            try:
                edges = net.od_route(origin, dest)
            except ConfigError:
                continue
            lines.append(f'    <route id="{route_id(origin, dest)}" edges="{" ".join(edges)}"/>')
    return lines


def _vehicle_line(v: _Vehicle) -> str:
    lat = f' departPosLat="{v.depart_lat}"' if v.depart_lat is not None else ""
    checks = f' insertionChecks="{v.insertion_checks}"' if v.insertion_checks else ""
    edge = f' departEdge="{v.depart_edge}"' if v.depart_edge else ""
    return (
        f"    <vehicle id={quoteattr(v.vid)} type=\"{v.vtype}\" route=\"{v.route}\" "
        f'depart="{v.depart:.2f}"{edge} departLane="{v.depart_lane}" departPos="{v.depart_pos}"'
        f'{lat} departSpeed="{v.depart_speed}" speedFactor="{v.factor:.6f}"{checks}>\n'
        f'        <param key="desiredSpeed" value="{v.speed:.4f}"/>\n'
        f"    </vehicle>"
    )


def write_routes(net: RoadNetwork, demand: DemandSpec, seed: int, path: Path | str,
                 horizon_s: float = 600.0, plan: DemandPlan | None = None) -> RouteInfo:
    """Write the vTypes, routes and vehicles of ``demand`` on ``net`` to ``path``.

    Ring networks get ``ring_density_vpkm`` vehicles placed at t=0 (exact count
    ``round(density * length)``), each on a route that starts on its edge and
    repeats the loop often enough for ``horizon_s`` (s). Open roads get arrivals in
    ``[0, horizon_s)`` on the main road and, on an on-ramp network, on the ramp.
    """
    path = Path(path)
    if plan is None:
        plan = plan_vehicles(net, demand, seed, horizon_s)
    vehicles, process, repeat = plan.vehicles, plan.process, plan.ring_route_repeat
    vehicles, human_taus = with_human_model(vehicles, demand, seed)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', f"<!-- cosim demand, seed {seed} -->",
             "<routes>"]
    lines += vtype_lines(demand, lanes=net.lane_based, human_taus=human_taus)
    lines += _route_lines(net, repeat)
    lines += [_vehicle_line(v) for v in vehicles]
    lines.append("</routes>")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return _route_info(path, seed, vehicles, process, net, repeat)


def _route_info(
    path: Path, seed: int, vehicles: list[_Vehicle], process: str, net: RoadNetwork,
    repeat: int | None,
) -> RouteInfo:
    ids = tuple(v.vid for v in vehicles)
    cavs = tuple(i for i in ids if i.startswith(CAV_PREFIX + "."))
    origin = [i.split(".")[1] for i in ids]
    n_ring = origin.count("ring")
    return RouteInfo(
        path=path,
        seed=seed,
        n_cav=len(cavs),
        n_hdv=len(ids) - len(cavs),
        n_main=origin.count("main"),
        n_ramp=origin.count("ramp"),
        n_ring=n_ring,
        vehicle_ids=ids,
        cav_ids=cavs,
        ring_vehicle_ids=ids if net.periodic else (),
        arrival_process=process,
        desired_speed_mps={v.vid: v.speed for v in vehicles},
        ring_density_vpkm=1000.0 * n_ring / net.length_m if net.periodic else None,
        ring_route_repeat=repeat,
        ring_initial_speed_mps=float(vehicles[0].depart_speed) if n_ring else None,
        destination={v.vid: v.destination for v in vehicles},
    )
