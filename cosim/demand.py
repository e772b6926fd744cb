"""Traffic demand: SUMO route files (``.rou.xml``) and measurement detectors.

Everything random is drawn here with ``numpy.random.default_rng(seed)`` and
written out explicitly, one ``<vehicle>`` element per vehicle (type, depart
time, lateral depart position, desired speed), so a route file is fully
determined by the :class:`DemandSpec`, the network and the seed. SUMO's own
randomness (the Krauss driver imperfection ``sigma`` of human drivers) is
governed by SUMO's ``--seed``, which the runner must pass.

Vehicle types (``vType``): one per (kind, size class), ids ``cav_<k>`` and
``hdv_<k>``; the co-simulation recognises CAVs by the type-id prefix
:data:`CAV_PREFIX`. Vehicle ids are ``<kind>.<origin>.<n>``, e.g.
``cav.main.17``, ``hdv.ramp.3``, ``cav.ring.0``.

Desired speed: each vehicle's desired speed v0 (m/s) is drawn uniformly from
``desired_speed_mps`` and written as ``speedFactor = v0 / speed limit`` (SUMO's
human drivers then aim for v0) and as ``<param key="desiredSpeed">`` (the CAV
controllers read it with ``vehicle.getParameter``).

Open-road arrivals (``arrivals``): ``"poisson"`` gives exponential headways
with mean ``3600 / inflow_vph`` s; ``"uniform"`` gives constant headways
``3600 / inflow_vph`` s after a random phase. These are the *requested*
departure times: SUMO delays an insertion while the entry is blocked.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from cosim.errors import ConfigError
from cosim.network_build import RoadNetwork

CAV_PREFIX = "cav"
HDV_PREFIX = "hdv"

#: Car size classes (length m, width m, probability), spanning the lane-free
#: literature's range of 3.2-5.15 m long and 1.6-1.84 m wide passenger cars.
DEFAULT_SIZE_CLASSES: tuple[tuple[float, float, float], ...] = (
    (3.2, 1.60, 0.2),
    (3.9, 1.70, 0.3),
    (4.5, 1.78, 0.3),
    (5.15, 1.84, 0.2),
)

ACCEL_MPS2 = 2.6
DECEL_MPS2 = 4.5
EMERGENCY_DECEL_MPS2 = 9.0
#: Longitudinal standstill gap of SUMO's car-following model, m.
MIN_GAP_M = 2.5
#: Lateral gap SL2015 drivers keep to their side neighbours, m.
MIN_GAP_LAT_M = 0.5
#: Maximum lateral speed of SL2015 drivers, m/s.
MAX_SPEED_LAT_MPS = 1.5
#: Krauss driver imperfection of human drivers (CAVs: 0).
CAV_TAU_S = 0.5  # s
HDV_TAU_S = 1.0  # s, SUMO's default
HDV_SIGMA = 0.5
#: vType maxSpeed, m/s: a cap above any desired speed so SUMO never clips a controller.
VTYPE_MAX_SPEED_MPS = 60.0
#: Clearance kept between a departing vehicle's side and the road edge, m.
DEPART_EDGE_MARGIN_M = 0.1
#: Minimum bumper-to-bumper gap between vehicles placed on the ring at t=0, m.
RING_MIN_GAP_M = 1.0
#: Default ring start: time headway (s) the smallest initial gap must allow, and the
#: lateral reach (m, beyond the half-widths) within which a vehicle counts as a leader
#: (covers SUMO's sublane discretisation: neighbours 0.5 m apart may share a sublane).
RING_INITIAL_HEADWAY_S = 1.0
RING_LEADER_LATERAL_REACH_M = 1.0

ARRIVALS = ("poisson", "uniform")
DEPART_LATERAL = ("random", "center")
DEPART_SPEED = ("desired", "max")
RING_PLACEMENT = ("even", "random")


@dataclass(frozen=True)
class DemandSpec:
    """What traffic to generate (flows in veh/h, density in veh/km, speeds in m/s, time in s).

    Attributes:
        inflow_vph: main-road inflow on open roads, veh/h.
        cav_share: fraction of CAVs among all vehicles, 0..1 (exact up to rounding
            per stream: main, ramp, ring).
        ramp_inflow_vph: on-ramp inflow (onramp networks), veh/h.
        ring_density_vpkm: ring only: vehicles per km placed on the ring at t=0.
        desired_speed_mps: (low, high) of the uniform desired-speed distribution.
        duration_s: demand horizon: departures in [0, duration_s); on the ring,
            routes are long enough to circle for duration_s at the vType's max speed.
        depart_lateral: ``"random"`` (uniform across the lane, body inside the
            road) or ``"center"``; on multi-lane roads: random lane or middle lane.
        depart_speed: open roads: ``"desired"`` (the vehicle's desired speed) or
            ``"max"`` (SUMO's highest safe speed at insertion).
        ring_initial_speed_mps: ring: common speed of all vehicles at t=0, m/s;
            None = the low end of ``desired_speed_mps`` (so that nobody starts
            closing in on a slower leader), capped so that the smallest gap to a
            leader within reach laterally is at least RING_INITIAL_HEADWAY_S of travel.
        arrivals: ``"poisson"`` or ``"uniform"`` headways on open roads.
        ring_placement: ``"even"`` (equal spacing in s, staggered across the width)
            or ``"random"`` (uniform in s and d, without overlaps).
        size_classes: (length_m, width_m, probability) per car class.
        insertion: open roads on one wide lane: ``"slots"`` (default) spreads
            departures over lateral slots across the road, each vehicle in the
            slot that has been free longest, never two in one slot closer than
            ``slot_headway_s`` (a later departure if needed), at no more than
            the speed of the slot's previous vehicle; SUMO's own insertion check
            still applies (it respects lateral positions), so a vehicle waits
            when its slot is blocked. ``"sumo"``: random lateral positions and
            SUMO's departure speeds, which caps the inflow of one wide lane near
            4 000-5 500 veh/h.
        slot_headway_s: minimum time between two departures in one slot, s.
        slot_spacing_m: lateral distance between slot centres, m.
    """

    inflow_vph: float = 1800.0
    cav_share: float = 0.5
    ramp_inflow_vph: float = 0.0
    ring_density_vpkm: float = 30.0
    desired_speed_mps: tuple[float, float] = (25.0, 35.0)
    duration_s: float = 600.0
    depart_lateral: str = "random"
    depart_speed: str = "desired"
    ring_initial_speed_mps: float | None = None
    arrivals: str = "poisson"
    ring_placement: str = "even"
    size_classes: tuple[tuple[float, float, float], ...] = DEFAULT_SIZE_CLASSES
    insertion: str = "slots"
    slot_headway_s: float = 1.2
    slot_spacing_m: float = 2.55

    def __post_init__(self) -> None:
        object.__setattr__(self, "desired_speed_mps", tuple(self.desired_speed_mps))
        object.__setattr__(
            self, "size_classes", tuple(tuple(float(v) for v in c) for c in self.size_classes)
        )
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ConfigError` naming the field for impossible values."""
        _finite_nonneg("inflow_vph", self.inflow_vph)
        _finite_nonneg("ramp_inflow_vph", self.ramp_inflow_vph)
        _finite_nonneg("ring_density_vpkm", self.ring_density_vpkm)
        _finite_nonneg("duration_s", self.duration_s)
        if self.ring_initial_speed_mps is not None:
            _finite_nonneg("ring_initial_speed_mps", self.ring_initial_speed_mps)
        if self.duration_s <= 0:
            raise ConfigError(f"demand.duration_s must be > 0 (got {self.duration_s})")
        _finite_nonneg("cav_share", self.cav_share)
        if not 0.0 <= self.cav_share <= 1.0:
            raise ConfigError(f"demand.cav_share must be in [0, 1] (got {self.cav_share})")
        self._validate_speeds()
        _choice("depart_lateral", self.depart_lateral, DEPART_LATERAL)
        _choice("depart_speed", self.depart_speed, DEPART_SPEED)
        _choice("arrivals", self.arrivals, ARRIVALS)
        _choice("ring_placement", self.ring_placement, RING_PLACEMENT)
        self._validate_sizes()
        _choice("insertion", self.insertion, ("slots", "sumo"))
        if not (math.isfinite(self.slot_headway_s) and self.slot_headway_s > 0):
            raise ConfigError(f"demand.slot_headway_s must be > 0 (got {self.slot_headway_s})")
        if not (math.isfinite(self.slot_spacing_m) and self.slot_spacing_m > 0):
            raise ConfigError(f"demand.slot_spacing_m must be > 0 (got {self.slot_spacing_m})")

    def _validate_speeds(self) -> None:
        v = self.desired_speed_mps
        if len(v) != 2:
            raise ConfigError(f"demand.desired_speed_mps must be (low, high) (got {v})")
        low, high = float(v[0]), float(v[1])
        if not (math.isfinite(low) and math.isfinite(high)) or low <= 0 or low > high:
            raise ConfigError(
                f"demand.desired_speed_mps must satisfy 0 < low <= high (got {v})"
            )
        if high > VTYPE_MAX_SPEED_MPS:
            raise ConfigError(
                f"demand.desired_speed_mps high={high} exceeds {VTYPE_MAX_SPEED_MPS} m/s"
            )

    def _validate_sizes(self) -> None:
        if not self.size_classes:
            raise ConfigError("demand.size_classes must list (length_m, width_m, probability)")
        for i, c in enumerate(self.size_classes):
            if len(c) != 3 or c[0] <= 0 or c[1] <= 0 or c[2] < 0:
                raise ConfigError(
                    f"demand.size_classes[{i}] must be (length_m > 0, width_m > 0, "
                    f"probability >= 0) (got {c})"
                )
        if sum(c[2] for c in self.size_classes) <= 0:
            raise ConfigError("demand.size_classes probabilities must not all be 0")

    @property
    def class_probabilities(self) -> np.ndarray:
        """Size-class probabilities normalised to sum 1."""
        p = np.array([c[2] for c in self.size_classes], dtype=float)
        return p / p.sum()


def _finite_nonneg(name: str, value: float) -> None:
    if not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
        raise ConfigError(f"demand.{name} must be a finite number >= 0 (got {value!r})")


def _choice(name: str, value: str, allowed: Sequence[str]) -> None:
    if value not in allowed:
        raise ConfigError(f"demand.{name} must be one of {', '.join(allowed)} (got {value!r})")


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


# --------------------------------------------------------------------------------------
# Random draws
# --------------------------------------------------------------------------------------


def arrival_times(
    rate_vph: float, duration_s: float, process: str, rng: np.random.Generator
) -> np.ndarray:
    """Departure times (s) in [0, duration_s) for a stream of ``rate_vph`` veh/h."""
    if rate_vph <= 0:
        return np.zeros(0)
    mean_h = 3600.0 / rate_vph
    if process == "uniform":
        n = int(math.ceil(duration_s / mean_h)) + 1
        times = (np.arange(n) + rng.uniform()) * mean_h
    else:
        n_guess = int(duration_s / mean_h * 1.5) + 20
        times = np.cumsum(rng.exponential(mean_h, size=n_guess))
        while times[-1] < duration_s:
            more = np.cumsum(rng.exponential(mean_h, size=n_guess)) + times[-1]
            times = np.concatenate([times, more])
    return times[times < duration_s]


def _kinds(n: int, share: float, rng: np.random.Generator) -> np.ndarray:
    """Boolean CAV mask for n vehicles: exactly round(share * n) True, at random places."""
    is_cav = np.zeros(n, dtype=bool)
    is_cav[rng.permutation(n)[: int(round(share * n))]] = True
    return is_cav


def _draw_common(n: int, demand: DemandSpec, rng: np.random.Generator):
    """Kind mask, size class index and desired speed (m/s) for n vehicles."""
    is_cav = _kinds(n, demand.cav_share, rng)
    cls = rng.choice(len(demand.size_classes), size=n, p=demand.class_probabilities)
    low, high = demand.desired_speed_mps
    speed = rng.uniform(low, high, size=n)
    return is_cav, cls, speed


def _lateral(width_road: float, width_car: np.ndarray, how: str, rng: np.random.Generator):
    """Lateral depart offsets (m) from the lane centre keeping the body inside the road."""
    room = np.maximum(0.5 * width_road - 0.5 * width_car - DEPART_EDGE_MARGIN_M, 0.0)
    if how == "center":
        return np.zeros_like(width_car)
    return rng.uniform(-1.0, 1.0, size=len(width_car)) * room


# --------------------------------------------------------------------------------------
# Open roads
# --------------------------------------------------------------------------------------


def _open_stream(
    net: RoadNetwork, demand: DemandSpec, rng: np.random.Generator,
    origin: str, rate_vph: float, road_width: float,
) -> list[_Vehicle]:
    times = arrival_times(rate_vph, demand.duration_s, demand.arrivals, rng)
    n = len(times)
    is_cav, cls, speed = _draw_common(n, demand, rng)
    widths = np.array([demand.size_classes[c][1] for c in cls])
    lat = _lateral(road_width, widths, demand.depart_lateral, rng)
    lanes = _depart_lanes(net, n, demand.depart_lateral, rng) if origin == "main" else None
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
                route=origin,
                depart=round(float(times[i]), 2),
                speed=float(speed[i]),
                factor=float(speed[i]) / net.speed_limit_mps,
                depart_pos="base",
                depart_lat=None if multi else f"{lat[i]:.3f}",
                depart_lane=str(lanes[i]) if multi else "0",
                depart_speed=f"{v_depart[i]:.3f}" if slotted else demand.depart_speed,
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


# --------------------------------------------------------------------------------------
# Ring
# --------------------------------------------------------------------------------------


def _ring_slots(width_road: float, max_car_width: float) -> int:
    """Number of lateral slots of width >= car width + lateral gap across the road."""
    return max(1, int(width_road // (max_car_width + MIN_GAP_LAT_M)))


def _ring_even(
    n: int, length: float, width_road: float, lengths: np.ndarray, widths: np.ndarray,
    density: float, rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Equal spacing in s, vehicle i in lateral slot i mod m (a staggered lattice)."""
    m = _ring_slots(width_road, float(widths.max()))
    spacing = length / n
    if m * spacing < lengths.max() + RING_MIN_GAP_M:
        max_density = 1000.0 * m / (lengths.max() + RING_MIN_GAP_M)
        raise ConfigError(
            f"demand.ring_density_vpkm={density} is too high for even placement on a "
            f"{width_road:.1f} m wide ring (at most {max_density:.0f} veh/km)"
        )
    s = rng.uniform(0.0, spacing) + spacing * np.arange(n)
    slot_w = width_road / m
    centres = -0.5 * width_road + (np.arange(n) % m + 0.5) * slot_w
    room = np.maximum(0.5 * (slot_w - widths - MIN_GAP_LAT_M), 0.0)
    d = centres + rng.uniform(-1.0, 1.0, size=n) * room
    return s, d


def _ring_random(
    n: int, length: float, width_road: float, lengths: np.ndarray, widths: np.ndarray,
    density: float, rng: np.random.Generator, max_tries: int = 2000,
) -> tuple[np.ndarray, np.ndarray]:
    """Random sequential placement of non-overlapping rectangles (centre s, d)."""
    s = np.empty(n)
    d = np.empty(n)
    for i in range(n):
        for _ in range(max_tries):
            room = 0.5 * width_road - 0.5 * widths[i] - DEPART_EDGE_MARGIN_M
            cs, cd = rng.uniform(0.0, length), rng.uniform(-room, room)
            ds = np.abs(cs - s[:i])
            ds = np.minimum(ds, length - ds)
            clash = (ds < 0.5 * (lengths[i] + lengths[:i]) + RING_MIN_GAP_M) & (
                np.abs(cd - d[:i]) < 0.5 * (widths[i] + widths[:i]) + MIN_GAP_LAT_M
            )
            if not clash.any():
                s[i], d[i] = cs, cd
                break
        else:
            raise ConfigError(
                f"demand.ring_density_vpkm={density} is too high for random placement "
                f"(no free spot for vehicle {i + 1} of {n}); use ring_placement='even'"
            )
    return s, d


def _min_leader_gap(
    s: np.ndarray, d: np.ndarray, lengths: np.ndarray, widths: np.ndarray, period: float
) -> float:
    """Smallest bumper gap (m) from any vehicle to a leader within lateral reach (periodic s)."""
    ds = np.mod(s[None, :] - s[:, None], period)  # [i, j]: how far j is ahead of i
    gap = ds - 0.5 * (lengths[None, :] + lengths[:, None])
    near = np.abs(d[None, :] - d[:, None]) < (
        0.5 * (widths[None, :] + widths[:, None]) + RING_LEADER_LATERAL_REACH_M
    )
    np.fill_diagonal(near, False)
    near &= gap >= 0.0  # side-by-side neighbours are not leaders
    return float(gap[near].min()) if near.any() else float("inf")


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
            )
        )
    return out


# --------------------------------------------------------------------------------------
# XML
# --------------------------------------------------------------------------------------


def vtype_lines(demand: DemandSpec, lanes: bool) -> list[str]:
    """``<vType>`` elements: ``cav_<k>`` and ``hdv_<k>`` for every size class.

    ``lanes=False`` (lane-free road) gives SUMO's sublane model SL2015 with
    ``latAlignment="arbitrary"``; ``lanes=True`` (three_lane baseline) gives LC2013.
    """
    out = []
    # CAVs get a short reaction time ``tau`` so that SUMO's insertion check lets
    # them enter at CAV headways (our controller drives them from the first step).
    for kind, colour, sigma, tau in (
        (CAV_PREFIX, "0,90,255", 0.0, CAV_TAU_S),
        (HDV_PREFIX, "200,200,200", HDV_SIGMA, HDV_TAU_S),
    ):
        for k, (length, width, _p) in enumerate(demand.size_classes):
            lc = (
                'laneChangeModel="LC2013"'
                if lanes
                else f'laneChangeModel="SL2015" latAlignment="arbitrary" '
                f'minGapLat="{MIN_GAP_LAT_M}" maxSpeedLat="{MAX_SPEED_LAT_MPS}"'
            )
            out.append(
                f'    <vType id="{kind}_{k}" vClass="passenger" length="{length}" '
                f'width="{width}" minGap="{MIN_GAP_M}" accel="{ACCEL_MPS2}" '
                f'decel="{DECEL_MPS2}" emergencyDecel="{EMERGENCY_DECEL_MPS2}" '
                f'maxSpeed="{VTYPE_MAX_SPEED_MPS}" speedDev="0" sigma="{sigma}" tau="{tau}" '
                f'color="{colour}" {lc}>\n'
                f'        <param key="cosim.kind" value="{kind}"/>\n'
                f"    </vType>"
            )
    return out


def _route_lines(net: RoadNetwork, repeat: int | None) -> list[str]:
    if net.periodic:
        return [
            f'    <route id="ring.{e}" edges="{" ".join(net.ring_route_edges(e))}" '
            f'repeat="{repeat}"/>'
            for e in net.main_route
        ]
    lines = [f'    <route id="main" edges="{" ".join(net.main_route)}"/>']
    if net.ramp_route:
        lines.append(f'    <route id="ramp" edges="{" ".join(net.ramp_route)}"/>')
    return lines


def _vehicle_line(v: _Vehicle) -> str:
    lat = f' departPosLat="{v.depart_lat}"' if v.depart_lat is not None else ""
    checks = f' insertionChecks="{v.insertion_checks}"' if v.insertion_checks else ""
    return (
        f"    <vehicle id={quoteattr(v.vid)} type=\"{v.vtype}\" route=\"{v.route}\" "
        f'depart="{v.depart:.2f}" departLane="{v.depart_lane}" departPos="{v.depart_pos}"'
        f'{lat} departSpeed="{v.depart_speed}" speedFactor="{v.factor:.6f}"{checks}>\n'
        f'        <param key="desiredSpeed" value="{v.speed:.4f}"/>\n'
        f"    </vehicle>"
    )


def write_routes(net: RoadNetwork, demand: DemandSpec, seed: int, path: Path | str) -> RouteInfo:
    """Write the vTypes, routes and vehicles of ``demand`` on ``net`` to ``path``.

    Ring networks get ``ring_density_vpkm`` vehicles placed at t=0 (exact count
    ``round(density * length)``), each on a route that starts on its edge and
    repeats the loop (see :func:`ring_route_repeat`). Open roads get arrivals
    on the main road and, on an on-ramp network, on the ramp.
    """
    rng = np.random.default_rng(seed)
    path = Path(path)
    repeat = None
    if net.periodic:
        vehicles = _ring_vehicles(net, demand, rng)
        repeat = ring_route_repeat(net, demand.duration_s)
        process = "ring_initial"
    else:
        vehicles = _open_stream(net, demand, rng, "main", demand.inflow_vph, float(net.width_at(0)))
        if net.ramp_route and demand.ramp_inflow_vph > 0:
            ramp_w = net.ramp_width_m or net.width_m
            vehicles += _open_stream(net, demand, rng, "ramp", demand.ramp_inflow_vph, ramp_w)
        vehicles.sort(key=lambda v: (v.depart, v.vid))
        process = demand.arrivals
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', f"<!-- cosim demand, seed {seed} -->",
             "<routes>"]
    lines += vtype_lines(demand, lanes=net.n_lanes > 1)
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
    )


# --------------------------------------------------------------------------------------
# Detectors
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DetectorInfo:
    """What :func:`write_detectors` wrote.

    Attributes:
        path: the additional file (pass to SUMO with ``-a``).
        loop_ids: induction-loop ids, one per lane per cross-section.
        loop_s_m: main-route ``s`` (m) of each loop (a requested position inside
            a junction is moved to the start of the next edge).
        loop_files: output file of each loop.
        edgedata_file: output file of the edge meandata.
        period_s: aggregation period, s.
    """

    path: Path
    loop_ids: tuple[str, ...]
    loop_s_m: tuple[float, ...]
    loop_files: tuple[Path, ...]
    edgedata_file: Path
    period_s: float


def write_detectors(
    net: RoadNetwork, positions_m: Sequence[float], path: Path | str, period_s: float,
    out_dir: Path | str,
) -> DetectorInfo:
    """Write E1 induction loops at main-route cross-sections ``positions_m`` (s, m) and an
    ``<edgeData>`` meandata, all aggregating over ``period_s`` s, outputs in ``out_dir``.

    Loops: ``e1.<k>.<lane index>`` on every lane of the edge at cross-section k,
    written to ``out_dir/e1_<k>.xml``; edge data to ``out_dir/edgedata.xml``.
    """
    if not (isinstance(period_s, int | float) and math.isfinite(period_s) and period_s > 0):
        raise ConfigError(f"detector period_s must be > 0 (got {period_s!r})")
    path, out_dir = Path(path), Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    ids, s_list, files, lines = [], [], [], ["<additional>"]
    for k, s in enumerate(positions_m):
        edge, pos = net.locate(float(s))
        out = out_dir / f"e1_{k}.xml"
        for lane in range(net_lanes_of(net, edge)):
            did = f"e1.{k}.{lane}"
            lines.append(
                f'    <inductionLoop id="{did}" lane="{edge}_{lane}" pos="{pos:.3f}" '
                f'period="{period_s}" file={quoteattr(str(out))} friendlyPos="true"/>'
            )
            ids.append(did)
            s_list.append(net.s_of(edge, pos))
            files.append(out)
    edge_file = out_dir / "edgedata.xml"
    lines.append(
        f'    <edgeData id="cosim_edges" period="{period_s}" file={quoteattr(str(edge_file))}/>'
    )
    lines.append("</additional>")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return DetectorInfo(path, tuple(ids), tuple(s_list), tuple(files), edge_file, float(period_s))


def net_lanes_of(net: RoadNetwork, edge: str) -> int:
    """Number of lanes of a main-route edge (from the road frame's lane ids)."""
    n = sum(1 for lane in net.lane_d if lane.rsplit("_", 1)[0] == edge and not lane.startswith(":"))
    return max(n, 1)
