"""Scenario configuration: frozen dataclasses loaded from TOML and validated on load.

A scenario file has the sections below; every key is optional and defaults
to the built-in default scenario. Unknown sections or keys, wrong types and
impossible values raise :class:`~cosim.errors.ConfigError` with one line that
names the offending ``section.key``. See ``experiments/scenarios/*.toml``.

    [scenario]   name, seed, duration_s, warmup_s, step_length_s,
                 lateral_resolution_m, interval_s
    [network]    NetworkSpec fields (cosim.network_build)
    [demand]     DemandSpec fields (cosim.demand)
    [controller] kind, desired_speed_gain, lateral_damping, and
    [controller.params] FlockingParams fields (controllers.params)
    [limits]     acceleration and jerk limits of the CAVs
    [safety]     the safety layer
    [obstacle]   an optional stopped vehicle blocking part of the road
    [outputs]    trajectories, sumo_detectors, measurement zone, cross-sections
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from controllers.params import FlockingParams
from cosim.demand.spec import DemandSpec
from cosim.errors import ConfigError
from cosim.road.spec import NetworkSpec

# "flocking": Olfati-Saber with the road extensions; "boundary_points": seed 003's law
# (others and road edges seen as boundary points); "sumo": SUMO drives the CAVs (baseline).
CONTROLLER_KINDS = ("flocking", "boundary_points", "sumo")


@dataclass(frozen=True)
class RunSpec:
    """[scenario]: time and SUMO options.

    Attributes:
        name: scenario name (used in output folder names).
        description: one line shown by ``cosim list``.
        seed: random seed for demand and SUMO, int.
        duration_s: simulated time, s.
        warmup_s: time excluded from the measurements, s.
        step_length_s: SUMO and control step, s.
        lateral_resolution_m: SUMO sublane width, m (sublane model on).
        interval_s: measurement interval of the interval table, s.
    """

    name: str = "default"
    description: str = ""
    seed: int = 42
    duration_s: float = 240.0
    warmup_s: float = 60.0
    step_length_s: float = 0.1
    lateral_resolution_m: float = 0.8
    interval_s: float = 60.0

    def __post_init__(self) -> None:
        _positive(self, "duration_s", "step_length_s", "lateral_resolution_m", "interval_s")
        if not 0 <= self.warmup_s < self.duration_s:
            raise ConfigError(
                f"scenario.warmup_s must be in [0, duration_s={self.duration_s}), "
                f"got {self.warmup_s}"
            )
        if self.seed < 0:
            raise ConfigError(f"scenario.seed must be >= 0, got {self.seed}")


@dataclass(frozen=True)
class ControllerSpec:
    """[controller]: which law drives the CAVs and its road-specific references.

    Attributes:
        kind: "flocking" (Olfati-Saber with the road extensions) or "sumo"
            (SUMO's own SL2015 model also for CAVs: a baseline).
        params: FlockingParams fields (table [controller.params]).
        lateral_damping: gain pulling the lateral speed to zero, 1/s.
        time_gap_s: time gap T of the reference speed ``min(v_des, (g - s0)/T)``
            (controllers/road_reference.py), s; 0 tracks the desired speed only.
        standstill_gap_m: standstill gap s0 of that policy, m.
        reference_decel_mps2: deceleration b of the closing-speed bound on that
            reference (``v_ref <= sqrt(v_l^2 + 2 b (g - s0))`` with the leader's
            speed ``v_l``), m/s^2; 0 keeps the pure time gap.
        lateral_margin_m: extra lateral width within which a vehicle ahead
            counts as the leader for the time-gap policy, m.
        comm: CommConfig fields (table [controller.comm], controllers/communication.py):
            when given, each CAV acts on received, delayed or lost messages of the
            other CAVs (seed 001) instead of their true states.
    """

    kind: str = "flocking"
    params: dict = field(default_factory=dict)
    lateral_damping: float = 1.0
    time_gap_s: float = 0.8
    standstill_gap_m: float = 2.0
    reference_decel_mps2: float = 3.0
    lateral_margin_m: float = 0.3
    comm: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in CONTROLLER_KINDS:
            raise ConfigError(
                f"controller.kind must be one of {', '.join(CONTROLLER_KINDS)}, got {self.kind!r}"
            )
        for name in ("time_gap_s", "standstill_gap_m", "reference_decel_mps2",
                     "lateral_margin_m"):
            if getattr(self, name) < 0:
                raise ConfigError(f"controller.{name} must be >= 0, got {getattr(self, name)}")
        if self.lateral_damping < 0:
            raise ConfigError(
                f"controller.lateral_damping must be >= 0, got {self.lateral_damping}"
            )
        self.flocking_params()  # validate now
        if self.kind == "boundary_points":
            self.boundary_point_params()
        self.comm_config()

    def comm_config(self):
        """The validated CommConfig, or None when [controller.comm] is empty."""
        if not self.comm:
            return None
        from controllers.communication import CommConfig

        known = {f.name for f in fields(CommConfig)}
        for key in self.comm:
            if key not in known:
                raise ConfigError(
                    f"controller.comm: unknown key {key!r} (known: {', '.join(sorted(known))})"
                )
        try:
            return CommConfig(**self.comm)
        except (ValueError, TypeError) as exc:
            raise ConfigError(f"controller.comm: {exc}") from None

    def boundary_point_params(self):
        """Seed 003 parameters for the road (road defaults overridden by [controller.params])."""
        from controllers.boundary_points import BoundaryPointParams

        return self._params(BoundaryPointParams, ROAD_BOUNDARY_POINT_DEFAULTS)

    def flocking_params(self) -> FlockingParams:
        """The validated FlockingParams (road defaults overridden by [controller.params])."""
        if self.kind == "boundary_points":
            return road_flocking_defaults()
        return self._params(FlockingParams, dataclasses.asdict(road_flocking_defaults()))

    def _params(self, cls: type, defaults: dict):
        """``cls(**(defaults | [controller.params]))``, errors as one ConfigError line."""
        known = {f.name for f in fields(cls)}
        for key in self.params:
            if key not in known:
                raise ConfigError(f"controller.params: unknown key {key!r} for {self.kind}")
        try:
            return cls(**{**defaults, **self.params})
        except (ValueError, TypeError) as exc:
            raise ConfigError(f"controller.params: {exc}") from None


# Seed 003's law scaled to cars (table 3 is for point robots at 5 m/s): sensing radius
# 15 m, spacing 6 m; p_max = 10 m/s is the largest *relative* speed between neighbours
# on a road (so d_e = d_min + 2 p_max dt = 3 m); separation weight tau_s = 10 instead of
# 1e4 because cars side by side sit inside d_e; bounded (sigma_1) pull to the goal.
ROAD_BOUNDARY_POINT_DEFAULTS = {
    "r": 15.0,
    "d": 6.0,
    "epsilon": 0.1,
    "a": 2.0,
    "b": 20.0,
    "c1_alpha": 0.05,
    "c2_alpha": 0.3,
    "c1_beta": 0.05,
    "c2_beta": 0.3,
    "c1_gamma": 0.5,
    "c2_gamma": 0.5,
    "tau_a": 0.1,
    "tau_e": 1.0,
    "tau_s": 10.0,
    "p_max": 10.0,
    "d_min": 1.0,
    "dt": 0.1,
    "gamma_position": "sigma1",
    "beta_potential": "repulsive",
}


def road_flocking_defaults() -> FlockingParams:
    """Flocking gains for cars on a 10.2 m road (rows of 3 across, long headways along).

    Spacing is anisotropic: ``d_lat`` = 3.4 m (a lane's width), ``d_long`` =
    35 m (about 1.2 s at 30 m/s); gains are scaled to car accelerations
    (a few m/s^2) instead of seed 000's point-robot gains.
    """
    return FlockingParams(
        d=3.4,
        r=1.2 * 3.4,
        d_long=35.0,
        d_lat=3.4,
        epsilon=0.1,
        a=5.0,
        b=5.0,
        h_alpha=0.2,
        h_beta=0.9,
        d_beta=5.0,
        r_beta=6.0,
        d_vehicle=2.0,
        r_vehicle=4.0,
        d_wall=0.6,
        r_wall=1.5,
        c1_alpha=0.3,
        c2_alpha=0.3,
        c1_beta=1.0,
        c2_beta=0.5,
        c1_wall=2.0,
        c2_wall=1.0,
        c1_gamma=(0.0, 0.0),
        c2_gamma=(0.5, 0.0),
    )


@dataclass(frozen=True)
class LimitsSpec:
    """[limits]: CAV actuator limits (road frame), m/s^2 and m/s^3.

    Attributes:
        long_min_mps2, long_max_mps2: longitudinal acceleration range.
        lat_max_mps2: lateral acceleration bound (absolute).
        lat_speed_max_mps: lateral speed bound, m/s.
        jerk_max_mps3: jerk bound, or 0 for none.
        emergency_decel_mps2: deceleration the safety layer may use, >= -long_min.
    """

    long_min_mps2: float = -4.5
    long_max_mps2: float = 2.6
    lat_max_mps2: float = 1.5
    lat_speed_max_mps: float = 1.5
    jerk_max_mps3: float = 0.0
    emergency_decel_mps2: float = 9.0

    def __post_init__(self) -> None:
        if not self.long_min_mps2 < 0:
            raise ConfigError(f"limits.long_min_mps2 must be < 0, got {self.long_min_mps2}")
        _positive(self, "long_max_mps2", "lat_max_mps2", "lat_speed_max_mps")
        if self.jerk_max_mps3 < 0:
            raise ConfigError(f"limits.jerk_max_mps3 must be >= 0, got {self.jerk_max_mps3}")
        if self.emergency_decel_mps2 < -self.long_min_mps2:
            raise ConfigError("limits.emergency_decel_mps2 must be >= -long_min_mps2")


@dataclass(frozen=True)
class SafetySpec:
    """[safety]: the CAV safety layer (clips the flocking command only when needed).

    Attributes:
        enabled: turn the layer on (default) or off (to study raw flocking).
        reaction_steps: command delay assumed in the safe-speed rule, steps.
        min_gap_m: bumper-to-bumper standstill gap kept to the vehicle ahead, m.
        lateral_clearance_m: side-to-side clearance kept to vehicles beside, m.
        edge_margin_m: distance kept between the vehicle's side and the road edge, m.
        assumed_leader_decel_mps2: deceleration assumed for the vehicle ahead, m/s^2.
    """

    enabled: bool = True
    reaction_steps: int = 1
    min_gap_m: float = 2.0
    lateral_clearance_m: float = 0.3
    edge_margin_m: float = 0.1
    assumed_leader_decel_mps2: float = 9.0

    def __post_init__(self) -> None:
        if self.reaction_steps < 0:
            raise ConfigError(f"safety.reaction_steps must be >= 0, got {self.reaction_steps}")
        _nonneg(self, "min_gap_m", "lateral_clearance_m", "edge_margin_m")
        _positive(self, "assumed_leader_decel_mps2")


@dataclass(frozen=True)
class ObstacleSpec:
    """[obstacle]: a stopped vehicle blocking part of the road (none if length_m = 0).

    Attributes:
        s_m: longitudinal position of its centre along the main route, m.
        d_m: lateral offset of its centre from the road centre line, m.
        length_m, width_m: its size, m.
        appear_s: time it is placed, s.
    """

    s_m: float = 0.0
    d_m: float = 0.0
    length_m: float = 0.0
    width_m: float = 0.0
    appear_s: float = 0.0

    def __post_init__(self) -> None:
        _nonneg(self, "length_m", "width_m", "appear_s", "s_m")

    @property
    def present(self) -> bool:
        return self.length_m > 0 and self.width_m > 0


@dataclass(frozen=True)
class OutputSpec:
    """[outputs]: what a run writes.

    Attributes:
        trajectories: write one row per vehicle and step (large).
        trajectory_every: keep every k-th step in the trajectories.
        sumo_detectors: also write SUMO's E1 loops and edgeData for comparison.
        sumo_collisions: also let SUMO detect collisions (``--collision.action
            warn``; counted as ``collisions_sumo_*``). Our geometric check
            (``collisions_geometric_*``) always runs. SUMO's check costs a third
            of its step on one long sublane lane, nothing measurable on 100 m
            edges (benchmarks/bench_sumo_options.py); the sweeps turn it off.
        zone_start_m, zone_end_m: Edie measurement zone along the main route, m
            (zone_end_m = 0: up to 100 m before the road's end).
        cross_sections_m: positions of the flow cross-sections, m (empty: zone
            start, middle and end).
        ttc_threshold_s: ``TTC*`` of the time-to-collision exposure measures (TET,
            TIT; :mod:`cosim.metrics.traffic`), s; 1.5 s as in FHWA's SSAM.
    """

    trajectories: bool = False
    trajectory_every: int = 1
    sumo_detectors: bool = False
    sumo_collisions: bool = True
    zone_start_m: float = 100.0
    zone_end_m: float = 0.0
    cross_sections_m: tuple[float, ...] = ()
    ttc_threshold_s: float = 1.5

    def __post_init__(self) -> None:
        object.__setattr__(self, "cross_sections_m", tuple(float(x) for x in self.cross_sections_m))
        _nonneg(self, "zone_start_m", "zone_end_m")
        _positive(self, "ttc_threshold_s")
        if self.trajectory_every < 1:
            raise ConfigError("outputs.trajectory_every must be >= 1")
        if self.zone_end_m and self.zone_end_m <= self.zone_start_m:
            raise ConfigError("outputs.zone_end_m must be > zone_start_m")


@dataclass(frozen=True)
class Scenario:
    """A whole scenario: the unit a run is determined by (with its seed)."""

    scenario: RunSpec = field(default_factory=RunSpec)
    network: NetworkSpec = field(
        default_factory=lambda: NetworkSpec(kind="straight", length_m=1000.0)
    )
    demand: DemandSpec = field(default_factory=DemandSpec)
    controller: ControllerSpec = field(default_factory=ControllerSpec)
    limits: LimitsSpec = field(default_factory=LimitsSpec)
    safety: SafetySpec = field(default_factory=SafetySpec)
    obstacle: ObstacleSpec = field(default_factory=ObstacleSpec)
    outputs: OutputSpec = field(default_factory=OutputSpec)

    def __post_init__(self) -> None:
        ob = self.obstacle
        if ob.present:
            back, front = ob.s_m - 0.5 * ob.length_m, ob.s_m + 0.5 * ob.length_m
            for x in self.network.joints_m():
                if back - 0.5 <= x <= front + 0.5:
                    # SUMO keeps the back of a vehicle that never moves at the centre of
                    # the previous edge's lane and reports phantom collisions there.
                    raise ConfigError(
                        f"obstacle ({back:g}..{front:g} m) lies on the joint of two road "
                        f"edges at s = {x:g} m: move obstacle.s_m or set "
                        "network.max_edge_length_m (0: one edge)"
                    )

    def with_seed(self, seed: int) -> Scenario:
        return dataclasses.replace(self, scenario=dataclasses.replace(self.scenario, seed=seed))

    def to_dict(self) -> dict:
        """Plain nested dict (TOML-serialisable) of the resolved scenario."""
        return {f.name: _plain(dataclasses.asdict(getattr(self, f.name))) for f in fields(self)}


SECTIONS: dict[str, type] = {f.name: f.type for f in fields(Scenario)}
_SECTION_TYPES = {
    "scenario": RunSpec,
    "network": NetworkSpec,
    "demand": DemandSpec,
    "controller": ControllerSpec,
    "limits": LimitsSpec,
    "safety": SafetySpec,
    "obstacle": ObstacleSpec,
    "outputs": OutputSpec,
}


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value


def _positive(obj, *names: str) -> None:
    section = _section_name(obj)
    for name in names:
        v = getattr(obj, name)
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ConfigError(f"{section}.{name} must be a number > 0, got {v!r}")


def _nonneg(obj, *names: str) -> None:
    section = _section_name(obj)
    for name in names:
        v = getattr(obj, name)
        if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
            raise ConfigError(f"{section}.{name} must be a number >= 0, got {v!r}")


def _section_name(obj) -> str:
    for name, cls in _SECTION_TYPES.items():
        if type(obj) is cls:
            return name
    return type(obj).__name__


def _check_type(section: str, key: str, value: Any, hint: Any) -> Any:
    """Check a TOML value against a dataclass field's type hint; return it converted."""
    where = f"{section}.{key}"
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _check_type(section, key, value, arg)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{where}: bad value {value!r}")
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where} must be true or false, got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where} must be an integer, got {value!r}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where} must be a number, got {value!r}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where} must be a string, got {value!r}")
        return value
    if origin is tuple or hint is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where} must be a list, got {value!r}")
        if args and args[-1] is Ellipsis:
            return tuple(_check_type(section, key, v, args[0]) for v in value)
        if args and len(args) != len(value):
            raise ConfigError(f"{where} must have {len(args)} entries, got {len(value)}")
        kinds = args or [Any] * len(value)
        return tuple(
            _check_type(section, key, v, a) for v, a in zip(value, kinds, strict=True)
        )
    if hint is dict or origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{where} must be a table, got {value!r}")
        return dict(value)
    return value


def section_from_dict(cls: type, section: str, data: dict) -> Any:
    """Build one section's dataclass from a dict, rejecting unknown keys and bad types."""
    if not isinstance(data, dict):
        raise ConfigError(f"[{section}] must be a table")
    hints = typing.get_type_hints(cls)
    known = {f.name for f in fields(cls) if f.init}
    kwargs = {}
    for key, value in data.items():
        if key not in known:
            raise ConfigError(
                f"{section}: unknown key {key!r} (known: {', '.join(sorted(known))})"
            )
        kwargs[key] = _check_type(section, key, value, hints[key])
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"{section}: {exc}") from None


def scenario_from_dict(data: dict, base: Scenario | None = None) -> Scenario:
    """A Scenario from a nested dict (as parsed from TOML), on top of ``base`` defaults."""
    base = base or Scenario()
    for key in data:
        if key not in _SECTION_TYPES:
            raise ConfigError(
                f"unknown section [{key}] (known: {', '.join(_SECTION_TYPES)})"
            )
    parts = {}
    for name, cls in _SECTION_TYPES.items():
        merged = _plain(dataclasses.asdict(getattr(base, name)))
        merged = {k: v for k, v in merged.items() if k in {f.name for f in fields(cls) if f.init}}
        if name in data:
            if not isinstance(data[name], dict):
                raise ConfigError(f"[{name}] must be a table")
            if name == "controller":
                for sub_table in ("params", "comm"):
                    if sub_table in data[name]:
                        if not isinstance(data[name][sub_table], dict):
                            raise ConfigError(f"[controller.{sub_table}] must be a table")
                        merged[sub_table] = {**merged.get(sub_table, {}),
                                             **data[name][sub_table]}
                rest = {k: v for k, v in data[name].items() if k not in ("params", "comm")}
                merged.update(rest)
            else:
                merged.update(data[name])
        parts[name] = section_from_dict(cls, name, merged)
    return Scenario(**parts)


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario TOML file; relative network paths resolve against it."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"scenario file not found: {path}")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    net = data.get("network")
    if isinstance(net, dict) and isinstance(net.get("net_file"), str):
        p = Path(net["net_file"])
        if not p.is_absolute():
            net["net_file"] = str((path.parent / p).resolve())
    return scenario_from_dict(data)


def default_scenario() -> Scenario:
    """The built-in default: mixed traffic on a 1 km x 10.2 m lane-free road, 4 minutes."""
    return Scenario()
