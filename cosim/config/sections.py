"""The scenario sections owned by the co-simulation itself.

The other sections are their components' own parameter classes (one source of truth):
``[network]`` :class:`cosim.road.spec.NetworkSpec`, ``[demand]``
:class:`cosim.demand.spec.DemandSpec`, ``[limits]``
:class:`controllers.layers.constraints.ActuatorLimits`, ``[safety]``
:class:`controllers.layers.safety.SafetyParams`, ``[controller.params]`` the law's own
parameter class (:mod:`controllers.registry`), ``[controller.comm]``
:class:`controllers.comm.CommConfig`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, fields
from typing import Any

from controllers import registry
from cosim.config.schema import check_table
from cosim.errors import ConfigError

WORLDS = ("sumo", "road")
#: Largest seed SUMO accepts (a C int).
MAX_SEED = 2**31 - 1
#: SUMO's time resolution: steps are whole multiples of it, s.
STEP_RESOLUTION_S = 0.001
#: Most steps of one run (10^7: 11.6 simulated days at 0.1 s).
MAX_STEPS = 10_000_000
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


def _finite(section: str, obj, *names: str, low: float | None = None, strict: bool = False):
    for name in names:
        v = getattr(obj, name)
        ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        if ok and low is not None:
            ok = v > low if strict else v >= low
        if not ok:
            rel = "" if low is None else (f" > {low:g}" if strict else f" >= {low:g}")
            raise ConfigError(f"{section}.{name} must be a finite number{rel}, got {v!r}")


#: Longest SUMO action step for CAVs, s. SUMO plans a vehicle's way over the next lanes
#: (its links at joints and junctions) in its action steps; with 10 s the plan ran out
#: before the next one and SUMO stopped CAVs at a lane's end (bench_floor.py exactness,
#: 2026-12-01), with 1 s every commanded move landed exactly.
MAX_CAV_ACTION_STEP_S = 1.0


@dataclass(frozen=True)
class RunSpec:
    """[scenario]: time, seed and world.

    Attributes:
        name: scenario name (letters, digits, ``_ . -``; used in output folder names).
        description: one line shown by ``cosim list``.
        seed: random seed for demand and SUMO, 0 .. 2^31 - 1.
        duration_s: simulated time, s.
        warmup_s: time excluded from the measurements, s.
        step_length_s: SUMO and control step, s.
        lateral_resolution_m: SUMO sublane width, m (sublane model on), or ``"auto"``
            (the default): chosen from the road and the obstacle by
            :mod:`cosim.sumo.sublanes` (0.8 m where nothing narrows, 0.2 m where SUMO's
            drivers must pass a narrowing or a stopped car); ``meta.json`` and the
            summary (``sumo_lateral_resolution_m``) record the width used.
        interval_s: measurement interval of the interval table, s. The warm-up plus one
            interval must fit in the duration (else nothing would be measured: refused).
        world: "sumo" (SUMO's road and drivers, the default) or "road" (the SUMO-free
            road world of :mod:`cosim.sim.road_world`: the same road frame, double
            integrators, non-CAVs driven by a plain IDM: for law studies and tests).
        cav_action_step_s: SUMO's action step for the CAVs it no longer steers, s, from
            ``step_length_s`` to :data:`MAX_CAV_ACTION_STEP_S`, in runs whose demand has
            no human drivers (with humans the CAVs act every step). SUMO runs a vehicle's
            own decisions (lane changer, car-following plan) once per action step; our
            law overrules them every step, so a longer one only saves SUMO's work (its
            step costs about a third at 1 s: benchmarks/bench_floor.py); every command
            lands as before and runs are bit-identical to those with one step
            (tests/test_exactness.py), insertions included, because the runner keeps
            SUMO's Euler update explicitly (``--step-method.ballistic false``; unset, SUMO
            switches every vehicle to the ballistic update when one gets a longer action
            step). With SUMO's drivers on the road it is not used: their lane changer
            informs and is informed by the CAVs' only in the CAVs' action steps, and the
            runs are no longer the same (benchmarks/action_step_humans.py).
            ``meta.json`` records the action step used (``sumo_cav_action_step_s``).
    """

    name: str = "default"
    description: str = ""
    seed: int = 42
    duration_s: float = 240.0
    warmup_s: float = 60.0
    step_length_s: float = 0.1
    lateral_resolution_m: float | str = "auto"
    interval_s: float = 60.0
    world: str = "sumo"
    cav_action_step_s: float = 1.0

    def __post_init__(self) -> None:
        if not _NAME.match(self.name):
            raise ConfigError(
                f"scenario.name {self.name!r} must start with a letter or digit and hold only "
                "letters, digits, '_', '.' and '-' (it names output folders)"
            )
        _finite("scenario", self, "duration_s", "step_length_s", "interval_s", low=0.0,
                strict=True)
        if isinstance(self.lateral_resolution_m, str):
            if self.lateral_resolution_m != "auto":
                raise ConfigError("scenario.lateral_resolution_m must be a number of metres "
                                  f"or \"auto\", got {self.lateral_resolution_m!r}")
        else:
            _finite("scenario", self, "lateral_resolution_m", low=0.0, strict=True)
        _finite("scenario", self, "warmup_s", low=0.0)
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise ConfigError(f"scenario.seed must be an integer, got {self.seed!r}")
        if not 0 <= self.seed <= MAX_SEED:
            raise ConfigError(f"scenario.seed must be in [0, {MAX_SEED}], got {self.seed}")
        ticks = self.step_length_s / STEP_RESOLUTION_S
        if ticks < 1.0 - 1e-9 or abs(ticks - round(ticks)) > 1e-6:
            raise ConfigError(
                f"scenario.step_length_s = {self.step_length_s:g} s must be a whole number of "
                f"milliseconds, at least {STEP_RESOLUTION_S:g} s (SUMO's time resolution)"
            )
        if self.duration_s / self.step_length_s > MAX_STEPS:
            raise ConfigError(
                f"scenario.duration_s = {self.duration_s:g} s is "
                f"{self.duration_s / self.step_length_s:.3g} steps of {self.step_length_s:g} s: "
                f"more than the {MAX_STEPS:.0e} a run may take"
            )
        if self.step_length_s > self.duration_s:
            raise ConfigError(
                f"scenario.step_length_s = {self.step_length_s:g} s is longer than the run "
                f"(duration_s = {self.duration_s:g} s)"
            )
        if self.interval_s < self.step_length_s:
            raise ConfigError("scenario.interval_s must be at least one step_length_s")
        if self.warmup_s >= self.duration_s:
            raise ConfigError(
                f"scenario.warmup_s = {self.warmup_s:g} s is not shorter than the run "
                f"(duration_s = {self.duration_s:g} s): nothing would be measured (shorten "
                "the warm-up, e.g. --warmup, or lengthen the run)")
        if self.warmup_s + self.interval_s > self.duration_s + 1e-9:
            raise ConfigError(
                f"the {self.warmup_s:g} s warm-up plus one {self.interval_s:g} s measurement "
                f"interval do not fit in the {self.duration_s:g} s run: nothing would be "
                "measured (shorten scenario.warmup_s or scenario.interval_s, or lengthen the "
                "run)")
        _finite("scenario", self, "cav_action_step_s", low=0.0, strict=True)
        if not (self.step_length_s - 1e-9 <= self.cav_action_step_s
                <= MAX_CAV_ACTION_STEP_S + 1e-9):
            raise ConfigError(
                f"scenario.cav_action_step_s = {self.cav_action_step_s:g} s must lie between "
                f"scenario.step_length_s ({self.step_length_s:g} s) and "
                f"{MAX_CAV_ACTION_STEP_S:g} s"
            )
        if self.world not in WORLDS:
            raise ConfigError(f"scenario.world must be one of {', '.join(WORLDS)}, "
                              f"got {self.world!r}")

    @property
    def n_steps(self) -> int:
        """Number of steps of the run."""
        return int(round(self.duration_s / self.step_length_s))


@dataclass(frozen=True)
class ControllerSpec:
    """[controller]: which law drives the CAVs, its parameters and its communication.

    Attributes:
        kind: a registered law (``cosim list`` shows them: flocking, flocking_timegap,
            boundary_points, formation, vicsek, sumo) or a class of yours as
            ``"module.path:ClassName"`` (imported from the Python path).
        params: [controller.params]: the law's parameters (its own dataclass; unknown keys
            are refused with the valid ones listed). Written out fully resolved.
        comm: [controller.comm]: seed 001's communication layer
            (:class:`controllers.comm.CommConfig`): each CAV acts on received,
            delayed or lost messages of the others. Empty: ideal.
    """

    kind: str = "flocking"
    params: dict = field(default_factory=dict)
    comm: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        e = self._entry()
        if e.params_type is not None:
            typed = check_table(e.params_type, "controller.params", self.params,
                                exclude=frozenset(e.run_fields))
            object.__setattr__(self, "params", typed)
        # Keep every parameter as used (the law's road defaults filled in): one value per
        # parameter, written out in full and equal after a round trip through TOML.
        resolved = registry.params_dict(self.law_params())
        for key in e.run_fields:
            resolved.pop(key, None)
        object.__setattr__(self, "params", resolved)
        self.comm_config()

    def _entry(self) -> registry.LawEntry:
        try:
            return registry.entry(self.kind)
        except registry.LawError as exc:
            raise ConfigError(str(exc)) from None

    @property
    def drives(self) -> bool:
        """False when SUMO drives the CAVs (kind "sumo")."""
        return self._entry().drives

    def law_params(self) -> Any:
        """The law's validated parameters (road defaults overridden by [controller.params])."""
        try:
            return registry.make_params(self.kind, self.params)
        except registry.LawError as exc:
            raise ConfigError(str(exc)) from None

    def resolved_params(self) -> dict:
        """Every parameter of the law, as used (for config.toml and meta.json)."""
        return dict(self.params)

    def comm_config(self):
        """The validated CommConfig, or None when [controller.comm] is empty."""
        if not self.comm:
            return None
        from controllers.comm import CommConfig

        known = {f.name for f in fields(CommConfig)}
        for key in self.comm:
            if key not in known:
                raise ConfigError(
                    f"controller.comm: unknown key {key!r} (known: {', '.join(sorted(known))})"
                )
        typed = check_table(CommConfig, "controller.comm", self.comm)
        try:
            return CommConfig(**typed)
        except (ValueError, TypeError) as exc:
            raise ConfigError(f"controller.comm: {exc}") from None


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
        _finite("obstacle", self, "length_m", "width_m", "appear_s", "s_m", low=0.0)
        _finite("obstacle", self, "d_m")

    @property
    def present(self) -> bool:
        return self.length_m > 0 and self.width_m > 0


@dataclass(frozen=True)
class OutputSpec:
    """[outputs]: what a run writes and where it measures.

    Attributes:
        trajectories: write one row per vehicle and step (large).
        trajectory_every: keep every k-th step in the trajectories.
        sumo_detectors: also write SUMO's E1 loops and edgeData for comparison.
        sumo_collisions: also let SUMO detect collisions (``--collision.action warn``;
            counted as ``collisions_sumo_*``). Our geometric check always runs. SUMO's
            check costs a third of its step on one long sublane lane, nothing
            measurable on 100 m edges (benchmarks/bench_sumo_options.py).
        zone_start_m, zone_end_m: Edie measurement zone along the main route, m
            (zone_end_m = 0: up to 100 m before the road's end).
        cross_sections_m: positions of the flow cross-sections, m (empty: zone
            start, middle and end).
        ttc_threshold_s: ``TTC*`` of the time-to-collision exposure (TET, TIT), s.
        standstill_speed_mps: a vehicle slower than this stands still (jam figures), m/s.
        long_standstill_s: a standstill longer than this counts in
            ``vehicles_stopped_long`` (jam figures), s.
    """

    trajectories: bool = False
    trajectory_every: int = 1
    sumo_detectors: bool = False
    sumo_collisions: bool = True
    zone_start_m: float = 100.0
    zone_end_m: float = 0.0
    cross_sections_m: tuple[float, ...] = ()
    ttc_threshold_s: float = 1.5
    standstill_speed_mps: float = 0.5
    long_standstill_s: float = 30.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "cross_sections_m", tuple(float(x) for x in self.cross_sections_m))
        _finite("outputs", self, "zone_start_m", "zone_end_m", low=0.0)
        _finite("outputs", self, "ttc_threshold_s", "standstill_speed_mps", "long_standstill_s",
                low=0.0, strict=True)
        for x in self.cross_sections_m:
            if not math.isfinite(x):
                raise ConfigError(f"outputs.cross_sections_m must be finite, got {x!r}")
        if self.trajectory_every < 1:
            raise ConfigError("outputs.trajectory_every must be >= 1")
        if self.zone_end_m and self.zone_end_m <= self.zone_start_m:
            raise ConfigError("outputs.zone_end_m must be > zone_start_m")
