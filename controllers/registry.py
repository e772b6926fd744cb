"""The registry of road laws: ``controller.kind`` -> the law, its parameters, its needs.

Config validation, the simulation loop and the sweeps all read this table; the loop
never names a law. Registered kinds:

* ``flocking``: the lane-free flocking law (default; :mod:`controllers.road.lanefree`);
* ``flocking_timegap``: Olfati-Saber with a time-gap reference (the previous default);
* ``boundary_points``: seed 003's law, sensed vehicles as boundary points;
* ``formation``: seed 002's rigid formations of CAV groups;
* ``vicsek``: seed 004's alignment with desired-speed tracking;
* ``sumo``: SUMO's own driver model drives the CAVs too (a baseline; no law runs);
* ``"module.path:ClassName"``: a user's class, imported from the Python path and
  constructed with the keyword arguments of ``[controller.params]``; it needs only
  ``compute(obs) -> (N, 2)`` (:mod:`controllers.protocol`).

Each entry names its parameter dataclass and the road defaults that differ from the
dataclass's own (the plane-world seeds use the dataclass defaults), and the fields the
run fills in (such as a law's own step ``dt``), which a scenario may not set.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import os
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from controllers.layers.constraints import ActuatorLimits
from controllers.observation import RoadProfile


class LawError(ValueError):
    """A controller kind or its parameters are invalid; the message says why in one line."""


@dataclass(frozen=True)
class RoadContext:
    """What a law's factory gets from the run.

    Attributes:
        dt: control step, s.
        limits: the run's actuator limits.
        comm: the seed 001 communication layer's config, or None.
        road: the road's edges along its length, or None.
        human_follow_margin_m: the lateral gap within which the run's human drivers take a
            vehicle ahead for their leader, m: SUMO's sublane width (its SL2015 drivers
            follow whatever shares a sublane with them), 0 where they follow only a
            vehicle that overlaps them (the road world's drivers, SUMO's on lanes).
    """

    dt: float
    limits: ActuatorLimits = field(default_factory=ActuatorLimits)
    comm: Any = None
    road: RoadProfile | None = None
    human_follow_margin_m: float = 0.0


@dataclass(frozen=True)
class LawEntry:
    """One registered kind.

    Attributes:
        kind: the name a scenario uses.
        description: one line for ``cosim list`` and the README.
        params_type: the law's parameter dataclass, or None (no parameters).
        defaults: road values of parameters that differ from the dataclass defaults.
        build: ``build(params, ctx) -> law``.
        run_fields: parameter fields taken from the run (``{field: RoadContext attribute}``),
            refused in ``[controller.params]``.
        drives: False when no law runs (SUMO drives the CAVs).
        user: True for a user's ``module:Class``.
    """

    kind: str
    description: str
    params_type: type | None
    defaults: Mapping[str, Any]
    build: Callable[[Any, RoadContext], Any]
    run_fields: Mapping[str, str] = field(default_factory=dict)
    drives: bool = True
    user: bool = False

    def known_params(self) -> list[str]:
        """Parameter names a scenario may set."""
        if self.params_type is None:
            return []
        return sorted(f.name for f in dataclasses.fields(self.params_type)
                      if f.init and f.name not in self.run_fields)


_REGISTRY: dict[str, LawEntry] = {}


def register(entry: LawEntry) -> None:
    """Add (or replace) a kind."""
    _REGISTRY[entry.kind] = entry


def kinds() -> list[str]:
    """Registered kinds, in registration order."""
    _load_builtins()
    return list(_REGISTRY)


def entry(kind: str) -> LawEntry:
    """The entry of a registered kind or of a user's ``module.path:ClassName``."""
    _load_builtins()
    if not isinstance(kind, str) or not kind:
        raise LawError(f"controller.kind must be a non-empty string, got {kind!r}")
    if kind in _REGISTRY:
        return _REGISTRY[kind]
    if ":" in kind:
        return _user_entry(kind)
    raise LawError(
        f"controller.kind {kind!r} is not registered (known: {', '.join(_REGISTRY)}; "
        "or a class of yours as 'module.path:ClassName')"
    )


def make_params(kind: str, values: Mapping[str, Any]) -> Any:
    """The law's parameters: road defaults overridden by ``values``.

    Unknown keys, keys the run sets and invalid values raise :class:`LawError` naming
    the key (and listing the valid keys). For a user class the parameters are the
    keyword arguments, checked against its constructor's signature.
    """
    e = entry(kind)
    if e.user:
        return _user_params(e, values)
    known = e.known_params()
    for key in values:
        if key in e.run_fields:
            raise LawError(
                f"controller.params.{key} is set by the run ({e.run_fields[key]}), not here"
            )
        if key not in known:
            raise LawError(
                f"controller.params: unknown key {key!r} for {kind} "
                f"(known: {', '.join(known) or 'none'})"
            )
    if e.params_type is None:
        return None
    try:
        return e.params_type(**{**e.defaults, **values})
    except (ValueError, TypeError) as exc:
        raise LawError(f"controller.params ({kind}): {exc}") from None


def params_dict(params: Any) -> dict[str, Any]:
    """The parameters as a plain dict (every field: the resolved gains)."""
    if params is None:
        return {}
    if isinstance(params, dict):
        return dict(params)
    return dataclasses.asdict(params)


def build(kind: str, params: Any, ctx: RoadContext) -> Any:
    """The law for ``kind`` with ``params`` in this run (None for ``sumo``)."""
    e = entry(kind)
    if not e.drives:
        return None
    if e.params_type is not None and e.run_fields:
        params = dataclasses.replace(
            params, **{f: getattr(ctx, attr) for f, attr in e.run_fields.items()}
        )
    return e.build(params, ctx)


# ----------------------------------------------------------------------------- user laws
def _import_user_module(module_name: str):
    """Import ``module_name`` as ``python -m`` would: from ``sys.path``, or else from the
    current folder (the ``cosim`` script's own folder is on ``sys.path``, not the one it
    runs in)."""
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        cwd = os.getcwd()
        top = module_name.split(".")[0]
        if exc.name not in (top, module_name) or cwd in sys.path:
            raise
        sys.path.append(cwd)
        return importlib.import_module(module_name)


def _user_class(kind: str) -> type:
    module_name, _, class_name = kind.partition(":")
    if not module_name or not class_name:
        raise LawError(f"controller.kind {kind!r}: write a user law as 'module.path:ClassName'")
    try:
        module = _import_user_module(module_name)
    except Exception as exc:  # ImportError, or the user's module failing on import
        raise LawError(
            f"controller.kind {kind!r}: cannot import module {module_name!r} "
            f"({type(exc).__name__}: {exc}); is its folder on PYTHONPATH or the current "
            "folder?"
        ) from None
    cls = getattr(module, class_name, None)
    if cls is None or not callable(cls):
        raise LawError(f"controller.kind {kind!r}: module {module_name!r} has no class "
                       f"{class_name!r}")
    if not callable(getattr(cls, "compute", None)):
        raise LawError(f"controller.kind {kind!r}: {class_name} has no compute(obs) method")
    return cls


def _user_entry(kind: str) -> LawEntry:
    cls = _user_class(kind)

    def build_user(params: dict, ctx: RoadContext) -> Any:
        try:
            law = cls(**params)
        except Exception as exc:  # the user's constructor refused its parameters
            raise LawError(f"controller.kind {kind!r}: {cls.__name__}(**{params!r}) failed: "
                           f"{type(exc).__name__}: {exc}") from None
        return _with_comm(law, ctx)

    return LawEntry(kind=kind, description=f"user law {kind}", params_type=None, defaults={},
                    build=build_user, user=True)


def _user_params(e: LawEntry, values: Mapping[str, Any]) -> dict:
    cls = _user_class(e.kind)
    try:
        sig = inspect.signature(cls)
        bound = sig.bind(**values)
    except TypeError as exc:
        raise LawError(f"controller.params for {e.kind}: {exc}") from None
    except ValueError:  # no signature (builtin): pass the values as they are
        return dict(values)
    bound.apply_defaults()
    return {k: v for k, v in bound.arguments.items()
            if sig.parameters[k].kind not in (inspect.Parameter.VAR_POSITIONAL,
                                              inspect.Parameter.VAR_KEYWORD)} | dict(
        bound.kwargs)


def _with_comm(law: Any, ctx: RoadContext) -> Any:
    if ctx.comm is None:
        return law
    from controllers.comm import CommunicatingController

    return CommunicatingController(law, ctx.comm)


# ----------------------------------------------------------------------------- built-ins
_LOADED = False


def _load_builtins() -> None:
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    from controllers.road import boundary_points, formation, lanefree, timegap_flocking, vicsek

    register(LawEntry(
        kind="flocking",
        description="lane-free flocking: car following, lateral purpose, cooperation "
                    "(controllers/road/lanefree/)",
        params_type=lanefree.LaneFreeParams,
        defaults={},
        build=lambda p, ctx: _with_comm(lanefree.LaneFreeFlocking(p, ctx), ctx),
        run_fields={"human_follow_margin_m": "human_follow_margin_m"},
    ))
    register(LawEntry(
        kind="flocking_timegap",
        description="Olfati-Saber Algorithm 3 tracking a time-gap reference (previous "
                    "default, drives in invisible lanes)",
        params_type=timegap_flocking.TimeGapFlockingParams,
        defaults=timegap_flocking.road_flocking_defaults(),
        build=lambda p, ctx: timegap_flocking.TimeGapFlocking(
            p, ctx.limits.box(), ctx.limits.jerk_max_mps3,
            wrap=(lambda law: _with_comm(law, ctx)) if ctx.comm is not None else None),
    ))
    register(LawEntry(
        kind="boundary_points",
        description="seed 003: obstacle boundary points and expected velocity; sensed "
                    "vehicles as boundary points",
        params_type=boundary_points.RoadBoundaryPointParams,
        defaults=boundary_points.ROAD_DEFAULTS,
        build=lambda p, ctx: boundary_points.RoadBoundaryPoints(
            p, ctx, wrap=(lambda law: _with_comm(law, ctx)) if ctx.comm is not None else None),
        run_fields={"dt": "dt"},
    ))
    register(LawEntry(
        kind="formation",
        description="seed 002: rigid formations (hexagon plus centre or blocks) of CAV "
                    "groups with velocity consensus",
        params_type=formation.RoadFormationParams,
        defaults={},
        build=lambda p, ctx: _with_comm(formation.RoadFormation(p, ctx), ctx),
    ))
    register(LawEntry(
        kind="vicsek",
        description="seed 004: Vicsek-style velocity alignment with desired-speed tracking",
        params_type=vicsek.RoadVicsekParams,
        defaults={},
        build=lambda p, ctx: _with_comm(vicsek.RoadVicsek(p, ctx), ctx),
    ))
    register(LawEntry(
        kind="sumo",
        description="SUMO's own SL2015 driver model drives the CAVs too (a baseline)",
        params_type=None,
        defaults={},
        build=lambda p, ctx: None,
        drives=False,
    ))
