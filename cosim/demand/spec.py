"""What traffic a scenario generates: the ``[demand]`` section and the vehicle constants.

Flows in veh/h, densities in veh/km, speeds in m/s, sizes in m. The demand's time
horizon is the run's duration (``[scenario] duration_s``), passed in by the runner.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cosim.demand.humans import HUMAN_MODELS
from cosim.demand.od_names import destination_number, origin_number
from cosim.errors import ConfigError

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


#: Lateral gap the CAV vTypes' SL2015 model keeps to side neighbours, m (it matters when
#: SUMO drives the CAVs, controller kind "sumo"); also the ring lattice's row gap (plan.py).
MIN_GAP_LAT_M = 0.5


#: Maximum lateral speed of the CAV vTypes' SL2015 model, m/s.
MAX_SPEED_LAT_MPS = 1.5


#: Krauss reaction time (desired time gap) of CAV vTypes, s: short, so that SUMO's insertion
#: check lets CAVs enter at CAV headways (our controller drives them from the first step).
CAV_TAU_S = 0.5


# --------------------------------------------------------------------------------------
# Human drivers (HDVs). Calibrated and measured by experiments/calibrate_humans.py
# (SUMO 1.28, step 0.1 s); the numbers quoted below are its output.
# Car following (both the lane-free SL2015 arm and the three-lane LC2013 arm, so that the
# two human arms differ only in lanes): SUMO's Krauss model with the constants below.
# --------------------------------------------------------------------------------------

#: Krauss reaction time (desired time gap) of human drivers, s. 1.3 s puts the road-limited
#: capacity of one lane at about 2 160 veh/h (the maximum, at 27 veh/km per lane, of the
#: flow-density curve on a 1 km ring of three 3.4 m lanes with LC2013: no entrance, mean of
#: 3 seeds; SUMO's default 1.0 s gives about 2 640 veh/h), inside a 2 000-2 400 veh/h target
#: and the HCM's 2 250-2 400 pc/h/ln for basic freeway segments. With it
#: SUMO's lane-free drivers carry about 6 700 veh/h on TUM's 225 veh/km ring (SUMO's
#: defaults: 8 840), beside TUM's strip-based human model (6 613 veh/h).
HDV_TAU_S = 1.3


#: Krauss driver imperfection (dawdling) of human drivers, 0..1: SUMO's default (CAVs: 0).
HDV_SIGMA = 0.5


# Lateral behaviour of human drivers on lane-free roads: SUMO's sublane model SL2015.
# SUMO 1.28 limitations measured while calibrating (details in calibrate_humans.py):
# * minGapLat is the same at every speed: SL2015 defines a speed scaling (a gap growing up to
#   50 km/h) but disables it (LATGAP_SPEED_THRESHOLD == LATGAP_SPEED_THRESHOLD2 in
#   MSLCM_SL2015.cpp), so gaps cannot be made to grow with speed through the vType;
# * lcMaxSpeedLatStanding / lcMaxSpeedLatFactor had no measurable effect on SL2015 lateral
#   speeds (a car at 2.3 m/s still moved sideways at 1.5 m/s with a 0.11 m/s bound), so they
#   are not written;
# * lcImpatience < 0 is refused ("must be equal or greater than 0") although documented
#   down to -1.

#: Lateral gap human drivers want to their side neighbours at any speed, m. Measured car-car
#: lateral clearances in traffic without lane discipline grow with speed (Budhkar & Maurya
#: 2017, J. Modern Transportation 25(2): regressions on speed with positive slopes); SL2015
#: cannot scale it (see above), so one value serves all speeds: 1.0 m, twice SUMO's 0.5 m.
#: SL2015 treats it as a wish, not a bound (it only reacts to neighbours already alongside):
#: the gaps measured at speed are in calibrate_humans.py's table.
HDV_MIN_GAP_LAT_M = 1.0


#: Maximum lateral speed of human drivers, m/s: SUMO's sublane example value, a brisk lane
#: change (3.4 m in about 3 s with lcAccelLat's default 1 m/s^2).
HDV_MAX_SPEED_LAT_MPS = 1.5


#: SL2015 lcPushy, 0..1: willingness to encroach laterally on others during a needed
#: (strategic) manoeuvre, accepting down to (1 - lcPushy) of minGapLat; any lcPushy > 0 also
#: lets a driver start a lateral move before all of it is free. Without it SUMO's drivers
#: stand still for 130-275 s behind a stopped vehicle covering the right third of a 10.2 m
#: road at 4 000 veh/h; with lcPushy alone, at most 45-55 s.
HDV_LC_PUSHY = 0.5


#: SL2015 lcAssertive, > 0: required front and rear gaps for a lateral move are divided by
#: it. Together with lcPushy and lcTimeToImpatience: longest standstill behind that
#: obstacle 15-22 s (seeds 1-5; no vehicle stopped > 30 s, flow past it >= 3 000 veh/h in
#: every 30 s after the warm-up).
HDV_LC_ASSERTIVE = 2.0


#: SL2015 lcTimeToImpatience, s: impatience grows from 0 to 1 over this time while a
#: manoeuvre is blocked, multiplying lcAssertive and lcPushy by up to 1.5 (it decays back
#: at the same rate once the driver is free).
HDV_LC_TIME_TO_IMPATIENCE_S = 10.0


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


#: Origins and destinations of an OD matrix (``demand.od_vph``), as named in errors.
OD_ORIGINS = ("main", "ramp", "ramp2", "...")
OD_DESTINATIONS = ("main", "off", "off2", "...")


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
        od_vph: an origin-destination matrix, ``(origin, destination, flow veh/h)`` rows,
            for open roads: origins ``"main"`` (the road's start) and ``"ramp"``,
            ``"ramp2"``, ... (the on-ramps), destinations ``"main"`` (the road's end) and
            ``"off"``, ``"off2"``, ... (the off-ramps; :mod:`cosim.demand.od_names`);
            ``cav_share`` applies to every row. Given, it replaces ``inflow_vph`` (the
            rows from ``"main"``) and ``ramp_inflow_vph`` (from ``"ramp"``): each
            origin's arrivals are one stream of its rows' total flow,
            each vehicle drawn a destination in proportion to its origin's rows.
        queue_vpkm: open roads: a standing queue placed at t = 0 over ``queue_span_m``,
            veh/km (0: none). Its vehicles stand still in rows across the road (lanes on
            a lane network), at least RING_MIN_GAP_M apart, kinds, sizes and desired
            speeds drawn as the arrivals' (``cav_share``), ids ``<kind>.queue.<n>`` from
            the queue's head; they drive to the road's end. It makes a bottleneck active
            from the start when the entrance alone cannot queue it (a road-limited
            capacity needs a queue upstream for the whole measured window).
        queue_span_m: where that queue stands, ``(start_m, end_m)`` along the road, m.
        human_model: the human drivers (:mod:`cosim.demand.humans`): ``"sl2015"``
            (SUMO's drivers, calibrated: the ``HDV_*`` constants below) or TUM
            LaneFreeDrive's ``StripBasedHuman`` with the constants of their TRB 2024
            (``"tum_trb2024"``) or TRC 2025 (``"tum_trc2025"``) runs: their Krauss law and
            per-vehicle reaction time N(1.5, 0.5) s, their lateral speed. SUMO world only.
    """

    inflow_vph: float = 1800.0
    cav_share: float = 0.5
    ramp_inflow_vph: float = 0.0
    ring_density_vpkm: float = 30.0
    desired_speed_mps: tuple[float, float] = (25.0, 35.0)
    depart_lateral: str = "random"
    depart_speed: str = "desired"
    ring_initial_speed_mps: float | None = None
    arrivals: str = "poisson"
    ring_placement: str = "even"
    size_classes: tuple[tuple[float, float, float], ...] = DEFAULT_SIZE_CLASSES
    insertion: str = "slots"
    slot_headway_s: float = 1.2
    slot_spacing_m: float = 2.55
    od_vph: tuple[tuple[str, str, float], ...] = ()
    human_model: str = "sl2015"
    queue_vpkm: float = 0.0
    queue_span_m: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "desired_speed_mps", tuple(self.desired_speed_mps))
        object.__setattr__(
            self, "size_classes", tuple(tuple(float(v) for v in c) for c in self.size_classes)
        )
        object.__setattr__(self, "od_vph", tuple(tuple(r) for r in self.od_vph))
        object.__setattr__(self, "queue_span_m", tuple(self.queue_span_m))
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ConfigError` naming the field for impossible values."""
        _finite_nonneg("inflow_vph", self.inflow_vph)
        _finite_nonneg("ramp_inflow_vph", self.ramp_inflow_vph)
        _finite_nonneg("ring_density_vpkm", self.ring_density_vpkm)
        if self.ring_initial_speed_mps is not None:
            _finite_nonneg("ring_initial_speed_mps", self.ring_initial_speed_mps)
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
        self._validate_od()
        _choice("human_model", self.human_model, HUMAN_MODELS)
        self._validate_queue()

    def _validate_queue(self) -> None:
        _finite_nonneg("queue_vpkm", self.queue_vpkm)
        span = self.queue_span_m
        if len(span) != 2 or not all(isinstance(x, int | float) and math.isfinite(x)
                                     for x in span):
            raise ConfigError(f"demand.queue_span_m must be (start_m, end_m) (got {span!r})")
        if self.queue_vpkm > 0 and not 0.0 <= span[0] < span[1]:
            raise ConfigError(f"demand.queue_span_m must satisfy 0 <= start_m < end_m when "
                              f"demand.queue_vpkm > 0 (got {span!r})")

    def _validate_od(self) -> None:
        seen = set()
        for i, row in enumerate(self.od_vph):
            if len(row) != 3:
                raise ConfigError(f"demand.od_vph[{i}] must be (origin, destination, veh/h) "
                                  f"(got {row!r})")
            o, d, q = row
            if origin_number(o) is None or destination_number(d) is None:
                raise ConfigError(
                    f"demand.od_vph[{i}]: origin must be one of {', '.join(OD_ORIGINS)} and "
                    f"destination one of {', '.join(OD_DESTINATIONS)} (got {o!r} -> {d!r})")
            _finite_nonneg(f"od_vph[{i}] flow", q)
            if (o, d) in seen:
                raise ConfigError(f"demand.od_vph lists {o!r} -> {d!r} twice")
            seen.add((o, d))

    def total_vph(self, origin: str | None = None) -> float:
        """Planned flow (veh/h) from ``origin`` (``"main"``, ``"ramp"``, ``"ramp2"``...), or
        from every origin (None)."""
        flows = self.origin_flows()
        keys = flows if origin is None else [origin]
        return float(sum(sum(flows.get(k, {}).values()) for k in keys))

    def origin_flows(self) -> dict[str, dict[str, float]]:
        """Flow (veh/h) per origin and destination: the OD matrix, or without one the main
        road's ``inflow_vph`` and the ramp's ``ramp_inflow_vph``, all to the road's end."""
        if not self.od_vph:
            return {"main": {"main": self.inflow_vph}, "ramp": {"main": self.ramp_inflow_vph}}
        out: dict[str, dict[str, float]] = {}
        for o, d, q in self.od_vph:
            out.setdefault(o, {})[d] = float(q)
        return out

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
