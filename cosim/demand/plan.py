"""Which vehicles depart when and where: the demand as plain data (no SUMO).

:func:`plan_vehicles` draws every vehicle of a run from the :class:`DemandSpec`, the
road and the seed (one generator per origin and quantity, seeded with
``SeedSequence([seed, origin, quantity])``; a ring's placement: ``default_rng(seed)``):
kind (CAV or human driver), size class, desired speed, departure time, lateral position
and speed. The SUMO
route file (:mod:`cosim.demand.routes`) and the SUMO-free road world
(:mod:`cosim.sim.road_world`) both consume this plan.

* Open roads: arrivals (Poisson or uniform headways) over ``[0, horizon_s)``, placed
  in lateral slots (``insertion = "slots"``) or at random lateral positions.
* Rings: ``round(density x length)`` vehicles placed at t = 0, evenly staggered over
  the width or at random without overlaps.
* A standing queue (open roads, ``demand.queue_vpkm``): ``round(density x span)``
  vehicles placed at t = 0 at standstill in rows across the road (:func:`_queue_vehicles`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cosim.demand.od_names import origin_number
from cosim.demand.spec import (
    CAV_PREFIX,
    CAV_TAU_S,
    DEPART_EDGE_MARGIN_M,
    HDV_PREFIX,
    HDV_TAU_S,
    MIN_GAP_LAT_M,
    MIN_GAP_M,
    RING_INITIAL_HEADWAY_S,
    RING_LEADER_LATERAL_REACH_M,
    RING_MIN_GAP_M,
    VTYPE_MAX_SPEED_MPS,
    DemandSpec,
)
from cosim.errors import ConfigError
from cosim.road.frame import RoadNetwork


@dataclass
class _Vehicle:
    """One vehicle to write (internal)."""

    vid: str
    vtype: str
    route: str
    depart: float
    speed: float
    factor: float
    depart_pos: str
    depart_lat: str | None
    depart_lane: str
    depart_speed: str
    insertion_checks: str | None = None
    # plain numbers for worlds that do not read SUMO's strings
    is_cav: bool = False
    length_m: float = 0.0
    width_m: float = 0.0
    lat_m: float | None = None  # lateral centre at departure, m (None: lane centre)
    centre_s_m: float | None = None  # ring: centre position at t = 0, m (None: road start)
    v0_mps: float | None = None  # departure speed, m/s (None: the desired speed)
    destination: str = "main"  # "main" (the road's end) or an off-ramp ("off", "off2"...)
    depart_edge: int | None = None  # index of the departure edge in the route (None: first)


#: Exponential headways are drawn in chunks of this many (any horizon draws the same
#: sequence: a longer run's first departures are a shorter run's).
ARRIVAL_CHUNK = 256
#: Vehicles per block of the CAV/HDV assignment (see :func:`_kinds`).
KIND_BLOCK = 20
#: Independent random streams of an open-road origin (each its own generator).
_STREAMS = ("arrivals", "kinds", "classes", "speeds", "lateral", "lanes", "ramp_lateral",
            "destinations")
#: The ``SeedSequence`` origin number of the standing queue (:func:`_queue_vehicles`), far
#: from the on-ramps' (1, 2, ...).
QUEUE_STREAM = 1000


def arrival_times(
    rate_vph: float, duration_s: float, process: str, rng: np.random.Generator
) -> np.ndarray:
    """Departure times (s) in [0, duration_s) for a stream of ``rate_vph`` veh/h.

    Prefix-stable: with the same generator state, the times below any ``T`` do not depend
    on ``duration_s >= T`` (uniform: one phase draw; Poisson: headways drawn in chunks of
    :data:`ARRIVAL_CHUNK`).
    """
    if rate_vph <= 0:
        return np.zeros(0)
    mean_h = 3600.0 / rate_vph
    if process == "uniform":
        n = int(math.ceil(duration_s / mean_h)) + 1
        times = (np.arange(n) + rng.uniform()) * mean_h
    else:
        parts = [np.cumsum(rng.exponential(mean_h, size=ARRIVAL_CHUNK))]
        while parts[-1][-1] < duration_s:
            parts.append(np.cumsum(rng.exponential(mean_h, size=ARRIVAL_CHUNK)) + parts[-1][-1])
        times = np.concatenate(parts)
    return times[times < duration_s]


def _kinds(n: int, share: float, rng: np.random.Generator) -> np.ndarray:
    """Boolean CAV mask for n vehicles in arrival order, prefix-stable.

    Block ``b`` of :data:`KIND_BLOCK` vehicles holds ``round(share B (b+1)) -
    round(share B b)`` CAVs at random places within it, so every whole-block prefix holds
    exactly ``round(share x its length)`` CAVs; a prefix that ends inside a block is off by
    at most that block's CAV count.
    """
    n_blocks = -(-n // KIND_BLOCK)
    out = np.zeros(n_blocks * KIND_BLOCK, dtype=bool)
    for b in range(n_blocks):
        k = int(round(share * KIND_BLOCK * (b + 1))) - int(round(share * KIND_BLOCK * b))
        out[b * KIND_BLOCK + rng.permutation(KIND_BLOCK)[:k]] = True
    return out[:n]


def _kinds_exact(n: int, share: float, rng: np.random.Generator) -> np.ndarray:
    """Boolean CAV mask for n vehicles placed at once (a ring): exactly round(share * n)
    True, at random places."""
    is_cav = np.zeros(n, dtype=bool)
    is_cav[rng.permutation(n)[: int(round(share * n))]] = True
    return is_cav


def _streams(seed: int, origin: str) -> dict[str, np.random.Generator]:
    """One generator per quantity of an origin's stream (``SeedSequence([seed, o, q])``):
    every quantity is prefix-stable on its own, whatever the number of vehicles."""
    o = origin_number(origin)  # main 0, ramp 1, ramp2 2, ...
    return {name: np.random.default_rng(np.random.SeedSequence([seed, o, q]))
            for q, name in enumerate(_STREAMS)}


def _draw_common(n: int, demand: DemandSpec, rng: np.random.Generator,
                 streams: dict[str, np.random.Generator] | None = None):
    """Kind mask, size class index and desired speed (m/s) for n vehicles (from
    ``streams`` when given, else all from ``rng``)."""
    g = streams or {"kinds": rng, "classes": rng, "speeds": rng}
    kinds = _kinds if streams else _kinds_exact
    is_cav = kinds(n, demand.cav_share, g["kinds"])
    cls = g["classes"].choice(len(demand.size_classes), size=n, p=demand.class_probabilities)
    low, high = demand.desired_speed_mps
    speed = g["speeds"].uniform(low, high, size=n)
    return is_cav, cls, speed


def _lateral(width_road: float, width_car: np.ndarray, how: str, rng: np.random.Generator):
    """Lateral depart offsets (m) from the lane centre keeping the body inside the road."""
    room = np.maximum(0.5 * width_road - 0.5 * width_car - DEPART_EDGE_MARGIN_M, 0.0)
    if how == "center":
        return np.zeros_like(width_car)
    return rng.uniform(-1.0, 1.0, size=len(width_car)) * room


def route_id(origin: str, destination: str) -> str:
    """The route file's id of an OD pair: the origin's name for the road's end (``main``,
    ``ramp``), ``<origin>.<destination>`` otherwise (``main.off``)."""
    return origin if destination == "main" else f"{origin}.{destination}"


def _open_stream(
    net: RoadNetwork, demand: DemandSpec, seed: int,
    origin: str, flows_vph: dict[str, float], road_width: float, horizon_s: float,
) -> list[_Vehicle]:
    """An origin's vehicles (arrivals of the total of ``flows_vph``, veh/h per destination,
    each vehicle's destination drawn in proportion): each quantity from its own generator,
    so a longer horizon only appends vehicles (prefix-stable)."""
    g = _streams(seed, origin)
    rate_vph = sum(flows_vph.values())
    times = arrival_times(rate_vph, horizon_s, demand.arrivals, g["arrivals"])
    n = len(times)
    dests = sorted(flows_vph)
    if len(dests) > 1 and n:
        cum = np.cumsum([flows_vph[d] for d in dests]) / rate_vph
        pick = np.minimum(np.searchsorted(cum, g["destinations"].uniform(size=n), side="right"),
                          len(dests) - 1)
        dest = [dests[k] for k in pick]
    else:
        dest = [dests[0] if dests else "main"] * n
    is_cav, cls, speed = _draw_common(n, demand, g["kinds"], g)
    widths = np.array([demand.size_classes[c][1] for c in cls])
    lat = _lateral(road_width, widths, demand.depart_lateral, g["lateral"])
    if origin != "main":  # at the ramp's right side: it joins the road on the right
        lat = -(0.5 * road_width - 0.5 * widths - DEPART_EDGE_MARGIN_M) + g[
            "ramp_lateral"].uniform(0.0, 0.4, size=n)
    lanes = (_depart_lanes(net, n, demand.depart_lateral, g["lanes"]) if origin == "main"
             else None)
    slotted = demand.insertion == "slots" and origin == "main" and net.n_lanes == 1 and n > 0
    if slotted:
        lengths = np.array([demand.size_classes[c][0] for c in cls])
        taus = np.where(is_cav, CAV_TAU_S, HDV_TAU_S)
        times, lat, v_depart = _slot_schedule(times, road_width, widths, lengths, speed, demand,
                                              taus)
    out = []
    for i in range(n):
        kind = CAV_PREFIX if is_cav[i] else HDV_PREFIX
        multi = lanes is not None and net.n_lanes > 1
        out.append(
            _Vehicle(
                vid=f"{kind}.{origin}.{i}",
                vtype=f"{kind}_{cls[i]}",
                route=route_id(origin, dest[i]),
                depart=round(float(times[i]), 2),
                speed=float(speed[i]),
                factor=float(speed[i]) / net.speed_limit_mps,
                depart_pos="base",
                depart_lat=None if multi else f"{lat[i]:.3f}",
                depart_lane=str(lanes[i]) if multi else "0",
                depart_speed=f"{v_depart[i]:.3f}" if slotted else demand.depart_speed,
                is_cav=bool(is_cav[i]),
                length_m=float(demand.size_classes[cls[i]][0]),
                width_m=float(widths[i]),
                lat_m=None if multi else float(lat[i]),
                v0_mps=float(v_depart[i]) if slotted else float(speed[i]),
                destination=dest[i],
            )
        )
    return out


def _slot_schedule(times: np.ndarray, road_width: float, widths: np.ndarray,
                   lengths: np.ndarray, speeds: np.ndarray, demand: DemandSpec,
                   taus: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Departure times (s), lateral offsets (m) and depart speeds (m/s) for slot insertion.

    Slots are ``slot_spacing_m`` apart, centred on the road, as many as fit with
    the widest car inside the edges. Each arrival takes the slot where it can
    depart earliest; it departs no earlier than ``slot_headway_s`` after the
    slot's previous vehicle, at no more than that vehicle's depart speed (it
    then accelerates to its desired speed), and only once the gap is at least
    ``s0 + v tau`` (standstill gap plus the vehicle's own reaction time ``taus``
    (s) of travel: its vType's ``tau``, 0.5 s for CAVs and 1 s for human
    drivers). Later departures are a queue, as at SUMO's own insertion.
    Deterministic.
    """
    room = road_width - float(widths.max()) - 2 * DEPART_EDGE_MARGIN_M
    k = max(1, int(room // demand.slot_spacing_m) + 1)
    centres = (np.arange(k) - 0.5 * (k - 1)) * demand.slot_spacing_m
    last_t = np.full(k, -np.inf)
    last_v = np.ones(k)
    last_len = np.zeros(k)
    out_t = np.empty(len(times))
    out_d = np.empty(len(times))
    out_v = np.empty(len(times))
    last_v[:] = np.inf
    t_prev = -np.inf
    s0 = MIN_GAP_M
    for n, t in enumerate(times):
        v = np.minimum(float(speeds[n]), last_v)  # never faster than the slot's leader
        need = s0 + v * float(taus[n]) + last_len
        earliest = np.maximum(last_t + demand.slot_headway_s,
                              last_t + need / np.where(np.isfinite(last_v), last_v, 1.0))
        earliest = np.maximum(earliest, max(float(t), t_prev))
        # Earliest departure first; among equal times the fastest allowed speed.
        slot = int(np.lexsort((-v, np.round(earliest, 6)))[0])
        depart = float(earliest[slot])
        last_t[slot], last_v[slot], last_len[slot] = depart, float(v[slot]), float(lengths[n])
        t_prev = depart
        out_t[n] = depart
        out_d[n] = centres[slot]
        out_v[n] = float(v[slot])
    return out_t, out_d, out_v


def _depart_lanes(net: RoadNetwork, n: int, how: str, rng: np.random.Generator) -> np.ndarray:
    if net.n_lanes <= 1:
        return np.zeros(n, dtype=int)
    if how == "center":
        return np.full(n, net.n_lanes // 2, dtype=int)
    return rng.integers(0, net.n_lanes, size=n)


def _ring_slots(width_road: float, max_car_width: float) -> int:
    """Number of lateral rows of width >= widest car + lateral gap across the road."""
    return max(1, int(width_road // (max_car_width + MIN_GAP_LAT_M)))


def ring_max_vehicles(length: float, width_road: float, max_length: float,
                      max_width: float) -> int:
    """Most vehicles :func:`_ring_even` places on a ring of ``length`` x ``width_road`` (m)
    whatever their sizes (up to ``max_length`` x ``max_width``, m): as many rows as fit
    across, each holding vehicles at least the longest car plus RING_MIN_GAP_M apart."""
    rows = _ring_slots(width_road, max_width)
    return rows * int(length // (max_length + RING_MIN_GAP_M))


def _ring_even(
    n: int, length: float, width_road: float, lengths: np.ndarray, widths: np.ndarray,
    density: float, rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Centres ``(s, d)`` (m) of ``n`` vehicles spread evenly over the ring, in as many
    lateral rows as fit (:func:`_ring_slots`; rows do not overlap laterally: a lateral gap
    of at least MIN_GAP_LAT_M).

    First choice, a staggered lattice: vehicles equally spaced in ``s`` (``length / n``,
    m), taking the rows in turn in blocks (``0, 1, ..., b-1``) of nearly equal sizes
    ``b <= rows``, so that two vehicles of one row are at least a block apart, across the
    wrap too (``n`` a multiple of the rows: every block holds every row). When that leaves
    a bumper gap in a row below RING_MIN_GAP_M (near the most the ring holds), each row's
    vehicles are spaced equally around the ring instead (``length / n_row``), the rows
    staggered. If that does not fit either, the density is refused, naming the most the
    ring takes (:func:`ring_max_vehicles`)."""
    m = _ring_slots(width_road, float(widths.max()))
    spacing = length / n
    u = rng.uniform(0.0, spacing)
    n_blocks = -(-n // m)  # ceil: as few blocks, as many rows per block, as possible
    starts = (np.arange(n_blocks + 1) * n) // n_blocks  # nearly equal block sizes
    block = np.repeat(np.arange(n_blocks), np.diff(starts))
    rows = np.arange(n) - starts[block]
    s = u + spacing * np.arange(n)
    if not _rows_fit(s, rows, lengths, length, m):
        rows = np.arange(n) % m
        per_row = np.bincount(rows, minlength=m)
        s = u + spacing * rows + (np.arange(n) // m) * (length / per_row[rows])
        if not _rows_fit(s, rows, lengths, length, m):
            n_max = ring_max_vehicles(length, width_road, float(lengths.max()),
                                      float(widths.max()))
            raise ConfigError(
                f"demand.ring_density_vpkm={density:g} does not fit on the "
                f"{length:.0f} m x {width_road:.1f} m ring with cars up to "
                f"{lengths.max():g} m long: {m} rows across, each car "
                f"{lengths.max() + RING_MIN_GAP_M:g} m (longest car + {RING_MIN_GAP_M:g} m "
                f"gap) from the next, hold at most {1000.0 * n_max / length:.0f} veh/km "
                f"({n_max} vehicles)"
            )
    slot_w = width_road / m
    centres = -0.5 * width_road + (rows + 0.5) * slot_w
    room = np.maximum(0.5 * (slot_w - widths - MIN_GAP_LAT_M), 0.0)
    d = centres + rng.uniform(-1.0, 1.0, size=n) * room
    return s, d


def _rows_fit(s: np.ndarray, rows: np.ndarray, lengths: np.ndarray, length: float,
              m: int) -> bool:
    """Every bumper gap between consecutive vehicles of one row (centres ``s`` increasing,
    m; the last to the first across the wrap) is at least RING_MIN_GAP_M."""
    for k in range(m):
        members = np.flatnonzero(rows == k)
        if len(members) < 2:
            continue
        ahead = np.roll(members, -1)
        ds = np.mod(s[ahead] - s[members], length)
        if (ds - 0.5 * (lengths[members] + lengths[ahead])).min() < RING_MIN_GAP_M - 1e-9:
            return False
    return True


def _ring_random(
    n: int, length: float, width_road: float, lengths: np.ndarray, widths: np.ndarray,
    density: float, rng: np.random.Generator, max_tries: int = 2000,
) -> tuple[np.ndarray, np.ndarray]:
    """Random sequential placement of non-overlapping rectangles (centre s, d), m.

    A candidate is kept when its bumper gap to every laterally overlapping vehicle
    (lateral gap < MIN_GAP_LAT_M) is at least RING_MIN_GAP_M, across the wrap too; only
    the vehicles within reach along ``s`` are checked (a sorted list, no N x N array).
    """
    import bisect

    s = np.empty(n)
    d = np.empty(n)
    placed_s: list[float] = []  # sorted centres
    placed_i: list[int] = []  # vehicle index of each, same order
    reach = float(lengths.max()) + RING_MIN_GAP_M
    for i in range(n):
        room = 0.5 * width_road - 0.5 * widths[i] - DEPART_EDGE_MARGIN_M
        for _ in range(max_tries):
            cs, cd = rng.uniform(0.0, length), rng.uniform(-room, room)
            near = _ring_neighbours(placed_s, placed_i, cs, reach, length, bisect)
            if near.size:
                ds = np.abs(cs - s[near])
                ds = np.minimum(ds, length - ds)
                clash = (ds < 0.5 * (lengths[i] + lengths[near]) + RING_MIN_GAP_M) & (
                    np.abs(cd - d[near]) < 0.5 * (widths[i] + widths[near]) + MIN_GAP_LAT_M
                )
                if clash.any():
                    continue
            s[i], d[i] = cs, cd
            k = bisect.bisect_left(placed_s, cs)
            placed_s.insert(k, cs)
            placed_i.insert(k, i)
            break
        else:
            n_max = ring_max_vehicles(length, width_road, float(lengths.max()),
                                      float(widths.max()))
            raise ConfigError(
                f"demand.ring_density_vpkm={density:g} is too high for random placement "
                f"(no free spot for vehicle {i + 1} of {n}); ring_placement = 'even' takes "
                f"up to {1000.0 * n_max / length:.0f} veh/km here"
            )
    return s, d


def _ring_neighbours(placed_s: list, placed_i: list, cs: float, reach: float,
                     length: float, bisect) -> np.ndarray:
    """Indices of placed vehicles whose centre lies within ``reach`` (m) of ``cs`` along
    the ring (across the wrap too)."""
    if not placed_s:
        return np.zeros(0, dtype=int)
    out: list[int] = []
    for lo, hi in ((cs - reach, cs + reach), (cs - reach + length, cs + reach + length),
                   (cs - reach - length, cs + reach - length)):
        a = bisect.bisect_left(placed_s, lo)
        b = bisect.bisect_right(placed_s, hi)
        out.extend(placed_i[a:b])
    return np.unique(np.array(out, dtype=int))


def _min_leader_gap(
    s: np.ndarray, d: np.ndarray, lengths: np.ndarray, widths: np.ndarray, period: float
) -> float:
    """Smallest bumper gap (m) from any vehicle to a leader within lateral reach (periodic
    s): a sorted scan, vehicle k places ahead for k = 1, 2, ... until no closer leader can
    follow (no N x N array)."""
    n = len(s)
    if n < 2:
        return float("inf")
    order = np.argsort(s, kind="stable")
    s, d, lengths, widths = s[order], d[order], lengths[order], widths[order]
    best = np.inf
    max_len = float(lengths.max())
    idx = np.arange(n)
    for k in range(1, n):
        j = (idx + k) % n
        ds = np.mod(s[j] - s, period)  # how far j is ahead of i
        gap = ds - 0.5 * (lengths[j] + lengths)
        near = np.abs(d[j] - d) < 0.5 * (widths[j] + widths) + RING_LEADER_LATERAL_REACH_M
        near &= gap >= 0.0  # side-by-side neighbours are not leaders
        if near.any():
            best = min(best, float(gap[near].min()))
        # every later leader is at least this far ahead: no smaller gap can follow
        if float(ds.min()) - max_len > best:
            break
    return float(best)


def ring_route_repeat(net: RoadNetwork, duration_s: float) -> int:
    """``repeat`` count so a vehicle at the vType max speed circles for ``duration_s``."""
    return int(math.ceil(duration_s * VTYPE_MAX_SPEED_MPS / net.length_m)) + 1


def _ring_vehicles(net: RoadNetwork, demand: DemandSpec, rng: np.random.Generator):
    n = int(round(demand.ring_density_vpkm * net.length_m / 1000.0))
    if n < 1:
        raise ConfigError(
            f"demand.ring_density_vpkm={demand.ring_density_vpkm} puts no vehicle on a "
            f"{net.length_m:.0f} m ring"
        )
    is_cav, cls, speed = _draw_common(n, demand, rng)
    lengths = np.array([demand.size_classes[c][0] for c in cls])
    widths = np.array([demand.size_classes[c][1] for c in cls])
    place = _ring_even if demand.ring_placement == "even" else _ring_random
    centre_s, d = place(n, net.length_m, net.width_m, lengths, widths,
                        demand.ring_density_vpkm, rng)
    order = np.argsort(np.mod(centre_s + 0.5 * lengths, net.length_m), kind="stable")
    v_init = demand.ring_initial_speed_mps
    if v_init is None:
        gap = _min_leader_gap(centre_s, d, lengths, widths, net.length_m)
        v_init = min(demand.desired_speed_mps[0], gap / RING_INITIAL_HEADWAY_S)
    out = []
    for k, i in enumerate(order):
        edge, pos = net.locate(float(centre_s[i] + 0.5 * lengths[i]))  # SUMO: front bumper
        kind = CAV_PREFIX if is_cav[i] else HDV_PREFIX
        v0 = float(speed[i])
        out.append(
            _Vehicle(
                vid=f"{kind}.ring.{k}",
                vtype=f"{kind}_{cls[i]}",
                route=f"ring.{edge}",
                depart=0.0,
                speed=v0,
                factor=v0 / net.speed_limit_mps,
                depart_pos=f"{pos:.3f}",
                depart_lat=f"{d[i]:.3f}",
                depart_lane="0",
                depart_speed=f"{v_init:.3f}",
                insertion_checks="none",
                is_cav=bool(is_cav[i]),
                length_m=float(lengths[i]),
                width_m=float(widths[i]),
                lat_m=float(d[i]),
                centre_s_m=float(np.mod(centre_s[i], net.length_m)),
                v0_mps=float(v_init),
            )
        )
    return out


def _queue_rows(net: RoadNetwork, span: tuple[float, float], max_width: float):
    """``(centres, row_width, lanes)``: row centres ``d`` (m) across the queue's span,
    each row's width (m) and whether the rows are lanes: a lane network's lanes (SUMO's
    lane 0 on the right), else as many rows as fit (:func:`_ring_slots`) on the narrowest
    part of the span, between its edges."""
    s = np.linspace(span[0], span[1], 64)
    right, left = net.edges_at(s)
    lo, hi = float(np.max(right)), float(np.min(left))
    m = net.n_lanes if net.n_lanes > 1 else _ring_slots(hi - lo, max_width)
    row_w = (hi - lo) / m
    return lo + (np.arange(m) + 0.5) * row_w, row_w, net.n_lanes > 1


def _queue_vehicles(net: RoadNetwork, demand: DemandSpec, seed: int) -> list[_Vehicle]:
    """The standing queue at t = 0 (``demand.queue_vpkm`` veh/km over
    ``demand.queue_span_m``): ``n = round(density x span)`` vehicles at 0 m/s, the rows
    (:func:`_queue_rows`) taken in turn from the head; row ``r`` of ``m`` holds its ``n_r``
    vehicles at a pitch ``p = span / (n_r + (m - 1) / m)`` (front to front, m), its first
    front ``r p / m`` behind the span's end (the rows staggered), so every body lies in the
    span. Refused (ConfigError) when a pitch leaves less than RING_MIN_GAP_M behind the
    longest car. Kinds, sizes and desired speeds from their own generators
    (``SeedSequence([seed, QUEUE_STREAM, q])``); lateral jitter within each row's room as
    on a ring. Every vehicle drives to the road's end. A vehicle whose front would stand
    inside a junction (between two edges of a SUMO network) is left out."""
    if demand.queue_vpkm <= 0:
        return []
    if net.periodic:
        raise ConfigError("demand.queue_vpkm is for open roads (a ring's density is "
                          "demand.ring_density_vpkm)")
    start, end = (float(x) for x in demand.queue_span_m)
    if end > net.length_m:
        raise ConfigError(f"demand.queue_span_m = ({start:g}, {end:g}) ends beyond the "
                          f"road ({net.length_m:.0f} m)")
    span = end - start
    n = int(round(demand.queue_vpkm * span / 1000.0))
    if n < 1:
        return []
    g = {name: np.random.default_rng(np.random.SeedSequence([seed, QUEUE_STREAM, q]))
         for q, name in enumerate(_STREAMS)}
    is_cav, cls, speed = _draw_common(n, demand, g["kinds"], g)
    lengths = np.array([demand.size_classes[c][0] for c in cls])
    widths = np.array([demand.size_classes[c][1] for c in cls])
    widest = max(c[1] for c in demand.size_classes)
    centres, row_w, lanes = _queue_rows(net, (start, end), widest)
    m = len(centres)
    rows = np.arange(n) % m
    per_row = np.bincount(rows, minlength=m)
    pitch = span / (per_row[rows] + (m - 1) / m)
    longest = max(c[0] for c in demand.size_classes)
    if float(pitch.min()) < longest + RING_MIN_GAP_M:
        most = m * math.floor(span / (longest + RING_MIN_GAP_M) - (m - 1) / m)
        raise ConfigError(
            f"demand.queue_vpkm={demand.queue_vpkm:g} does not fit on {span:g} m: {m} rows, "
            f"each car {longest + RING_MIN_GAP_M:g} m (longest car + {RING_MIN_GAP_M:g} m "
            f"gap) from the next, hold at most {1000.0 * most / span:.0f} veh/km")
    front = end - pitch * (np.arange(n) // m + rows / m)
    d = centres[rows]
    if not lanes:
        room = np.maximum(0.5 * (row_w - widths - MIN_GAP_LAT_M), 0.0)
        d = d + g["lateral"].uniform(-1.0, 1.0, size=n) * room
    route = route_id("main", "main")
    od_route = getattr(net, "od_route", None)  # SUMO's edges (the road world has one)
    main_edges = od_route("main", "main") if od_route is not None else ("road",)
    spans = getattr(net, "edge_spans", ())
    out = []
    for i in range(n):
        if spans and not any(s0 <= front[i] <= s1 for _, s0, s1 in spans):
            continue  # its front inside a junction: SUMO places vehicles on edges only
        edge, pos = net.locate(float(front[i]))
        kind = CAV_PREFIX if is_cav[i] else HDV_PREFIX
        out.append(_Vehicle(
            vid=f"{kind}.queue.{i}", vtype=f"{kind}_{cls[i]}", route=route, depart=0.0,
            speed=float(speed[i]), factor=float(speed[i]) / net.speed_limit_mps,
            depart_pos=f"{pos:.3f}", depart_lat=None if lanes else f"{d[i]:.3f}",
            depart_lane=str(rows[i]) if lanes else "0", depart_speed="0",
            insertion_checks="none", is_cav=bool(is_cav[i]), length_m=float(lengths[i]),
            width_m=float(widths[i]), lat_m=float(d[i]),
            centre_s_m=float(front[i] - 0.5 * lengths[i]), v0_mps=0.0,
            depart_edge=main_edges.index(edge)))
    return out


@dataclass(frozen=True)
class DemandPlan:
    """Every vehicle of a run and how they arrive.

    Attributes:
        vehicles: the planned vehicles in departure order.
        process: "poisson", "uniform" or "ring_initial" (all placed at t = 0).
        ring_route_repeat: the ``repeat`` count of the ring routes (ring only).
    """

    vehicles: list
    process: str
    ring_route_repeat: int | None = None


def plan_vehicles(net: RoadNetwork, demand: DemandSpec, seed: int, horizon_s: float) -> DemandPlan:
    """The run's vehicles (see the module docstring): departures in ``[0, horizon_s)``, s.

    Deterministic in (``net``, ``demand``, ``seed``, ``horizon_s``), and prefix-stable on
    open roads: a longer horizon keeps every vehicle of a shorter one (same id, kind,
    size, desired speed, departure) and appends the rest.
    """
    queue = _queue_vehicles(net, demand, seed)  # ConfigError on a ring
    if net.periodic:
        vehicles = _ring_vehicles(net, demand, np.random.default_rng(seed))
        return DemandPlan(vehicles, "ring_initial", ring_route_repeat(net, horizon_s))
    flows = demand.origin_flows()
    for origin, dest, q in demand.od_vph:  # ConfigError for a pair the road cannot connect
        od_route = getattr(net, "od_route", None)
        if q > 0 and od_route is not None:
            od_route(origin, dest)
        elif q > 0 and (origin, dest) != ("main", "main"):
            raise ConfigError(f"demand.od_vph: {origin!r} -> {dest!r} needs a SUMO network "
                              f"with {'an on-ramp' if origin != 'main' else 'an off-ramp'}")
    vehicles = queue + _open_stream(net, demand, seed, "main", flows.get("main", {}),
                                    float(net.width_at(0)), horizon_s)
    for ramp in getattr(net, "ramps", ()):
        if sum(flows.get(ramp.name, {}).values()) > 0:
            vehicles += _open_stream(net, demand, seed, ramp.name, flows[ramp.name],
                                     ramp.width_m or net.width_m, horizon_s)
    vehicles.sort(key=lambda v: (v.depart, v.vid))
    return DemandPlan(vehicles, demand.arrivals)
