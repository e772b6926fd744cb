"""What traffic a scenario generates: the ``[demand]`` section and the vehicle constants.

Flows in veh/h, densities in veh/km, speeds in m/s, sizes in m. The demand's time
horizon is the run's duration (``[scenario] duration_s``), passed in by the runner.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

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
