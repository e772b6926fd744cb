"""A whole scenario: frozen sections loaded from TOML, validated on load.

A scenario file has the sections below; every key is optional and defaults to the
built-in default scenario (``cosim config default`` prints every resolved value).
Unknown sections or keys, wrong types, non-finite numbers and impossible values raise
:class:`~cosim.errors.ConfigError` with one line naming the offending ``section.key``.

    [scenario]          RunSpec (cosim.config.sections)
    [network]           NetworkSpec (cosim.road.spec)
    [demand]            DemandSpec (cosim.demand.spec)
    [controller]        kind; [controller.params] the law's own parameters;
                        [controller.comm] seed 001's communication layer
    [limits]            ActuatorLimits (controllers.layers.constraints)
    [safety]            SafetyParams (controllers.layers.safety)
    [obstacle]          ObstacleSpec (cosim.config.sections)
    [outputs]           OutputSpec (cosim.config.sections)

Overrides (``cosim run NAME --set KEY=VALUE``, :func:`load_scenario` ``overrides``) are
dotted keys such as ``demand.cav_share`` or ``controller.params.c1_alpha``, applied to
the file's tables before validation.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from controllers import registry
from controllers.layers.constraints import ActuatorLimits
from controllers.layers.safety import SafetyParams
from cosim.config.builtins import builtin_scenarios
from cosim.config.overrides import apply_overrides
from cosim.config.schema import field_names, from_table, plain
from cosim.config.sections import ControllerSpec, ObstacleSpec, OutputSpec, RunSpec
from cosim.demand.spec import DemandSpec
from cosim.errors import ConfigError
from cosim.road.spec import NetworkSpec

#: Section name -> its class (the order of a written config.toml).
SECTIONS: dict[str, type] = {
    "scenario": RunSpec,
    "network": NetworkSpec,
    "demand": DemandSpec,
    "controller": ControllerSpec,
    "limits": ActuatorLimits,
    "safety": SafetyParams,
    "obstacle": ObstacleSpec,
    "outputs": OutputSpec,
}
#: Sub-tables of [controller].
CONTROLLER_TABLES = ("params", "comm")


@dataclass(frozen=True)
class Scenario:
    """A whole scenario: the unit a run is determined by (with its seed)."""

    scenario: RunSpec = field(default_factory=RunSpec)
    network: NetworkSpec = field(
        default_factory=lambda: NetworkSpec(kind="straight", length_m=1000.0)
    )
    demand: DemandSpec = field(default_factory=DemandSpec)
    controller: ControllerSpec = field(default_factory=ControllerSpec)
    limits: ActuatorLimits = field(default_factory=ActuatorLimits)
    safety: SafetyParams = field(default_factory=SafetyParams)
    obstacle: ObstacleSpec = field(default_factory=ObstacleSpec)
    outputs: OutputSpec = field(default_factory=OutputSpec)

    def __post_init__(self) -> None:
        from cosim.config.checks import check_scenario

        check_scenario(self)

    def with_seed(self, seed: int) -> Scenario:
        """A copy with another seed."""
        return self.with_overrides({"scenario.seed": seed})

    def with_overrides(self, overrides: Mapping[str, Any]) -> Scenario:
        """A copy with dotted-key overrides applied (``{"demand.cav_share": 0.5}``)."""
        return scenario_from_dict(apply_overrides(self.to_dict(resolved=False), overrides))

    def to_dict(self, resolved: bool = True) -> dict:
        """Plain nested dict (TOML-serialisable) of the scenario.

        ``resolved=True`` writes every parameter of the law (the gains actually used);
        ``False`` keeps only the ones set, so a changed ``controller.kind`` applies.
        """
        out = {}
        for f in fields(self):
            section = getattr(self, f.name)
            out[f.name] = plain(section)
        if resolved:
            out["controller"]["params"] = plain(self.controller.resolved_params())
        return out

    def law_context(self, road=None, human_follow_margin_m: float = 0.0
                    ) -> registry.RoadContext:
        """What the law's factory gets from this run (``human_follow_margin_m``: the
        world's, m; :class:`controllers.registry.RoadContext`)."""
        return registry.RoadContext(dt=self.scenario.step_length_s, limits=self.limits,
                                    comm=self.controller.comm_config(), road=road,
                                    human_follow_margin_m=human_follow_margin_m)


def scenario_from_dict(data: Mapping[str, Any], base: Scenario | None = None) -> Scenario:
    """A Scenario from a nested dict (as parsed from TOML), on top of ``base`` (its set
    values; default: the built-in defaults)."""
    if not isinstance(data, Mapping):
        raise ConfigError("a scenario must be a table of sections")
    for key in data:
        if key not in SECTIONS:
            raise ConfigError(f"unknown section [{key}] (known: {', '.join(SECTIONS)})")
    base_dict = (base if base is not None else _DEFAULT).to_dict(resolved=False)
    parts = {}
    for name, cls in SECTIONS.items():
        merged = dict(base_dict.get(name, {}))
        given = data.get(name, {})
        if not isinstance(given, Mapping):
            raise ConfigError(f"[{name}] must be a table")
        if name == "controller":
            given = dict(given)
            if "kind" in given and given.get("kind") != merged.get("kind"):
                merged.pop("params", None)  # another law: the old law's parameters do not apply
            for sub in CONTROLLER_TABLES:
                if sub in given:
                    if not isinstance(given[sub], Mapping):
                        raise ConfigError(f"[controller.{sub}] must be a table")
                    merged[sub] = {**merged.get(sub, {}), **given.pop(sub)}
        merged.update(given)
        parts[name] = from_table(cls, name, merged)
    return Scenario(**parts)


_DEFAULT = Scenario()


def read_toml(path: Path) -> dict:
    """A TOML file as a dict; unreadable, non-UTF-8 or invalid files give one ConfigError."""
    if path.is_dir():
        raise ConfigError(f"{path} is a folder, not a TOML file")
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"file not found: {path}") from None
    except OSError as exc:
        raise ConfigError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path} is not UTF-8 text (byte {exc.start}): is it a TOML file?"
        ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None


def resolve_scenario_path(name_or_path: str | Path) -> Path:
    """A scenario file: an existing path, a ``.toml`` path, or a built-in name."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists() or "/" in str(name_or_path):
        if not path.exists():
            raise ConfigError(f"scenario file not found: {path}")
        return path
    named = builtin_scenarios()
    if str(name_or_path) in named:
        return named[str(name_or_path)]
    raise ConfigError(
        f"no scenario file or built-in scenario named {str(name_or_path)!r} "
        f"(built-in: {', '.join(named)}; see 'cosim list')"
    )


def load_scenario(name_or_path: str | Path | None = None,
                  overrides: Mapping[str, Any] | None = None) -> Scenario:
    """Read and validate a scenario: a TOML file or a built-in name (None: the default).

    ``overrides`` are dotted keys applied to the file's tables before validation.
    Relative ``network.net_file`` paths resolve against the file's folder.
    """
    data: dict = {}
    if name_or_path is not None:
        path = resolve_scenario_path(name_or_path)
        data = read_toml(path)
        net = data.get("network")
        if isinstance(net, dict) and isinstance(net.get("net_file"), str):
            p = Path(net["net_file"]).expanduser()
            if not p.is_absolute():
                net["net_file"] = str((path.parent / p).resolve())
    if overrides:
        data = apply_overrides(data, overrides)
    return scenario_from_dict(data)


def default_scenario() -> Scenario:
    """The built-in default: mixed traffic on a 1 km x 10.2 m lane-free road, 4 minutes."""
    return Scenario()


def check_parameter_path(path: str, kind: str | None = None) -> None:
    """A dotted path must name a scenario parameter: ``section.key``,
    ``controller.params.key`` or ``controller.comm.key``; otherwise one ConfigError
    naming the valid keys. A law parameter is checked against ``kind``'s law; without
    ``kind`` only its form is (each scenario built from it checks it against its law)."""
    parts = path.split(".")
    if parts[0] not in SECTIONS:
        raise ConfigError(
            f"unknown parameter {path!r}: no section [{parts[0]}] (known: {', '.join(SECTIONS)})"
        )
    if parts[:2] == ["controller", "params"]:
        if kind is None:
            if len(parts) != 3:
                raise ConfigError(f"unknown parameter {path!r}: write controller.params.KEY")
            return
        try:
            e = registry.entry(kind)
        except registry.LawError as exc:
            raise ConfigError(str(exc)) from None
        if e.user:
            if len(parts) != 3:
                raise ConfigError(f"unknown parameter {path!r}")
            return
        known = e.known_params()
        if len(parts) != 3 or parts[2] not in known:
            raise ConfigError(
                f"unknown parameter {path!r} (controller.params keys of {e.kind}: "
                f"{', '.join(known)})"
            )
        return
    if parts[:2] == ["controller", "comm"]:
        from controllers.comm import CommConfig

        known = field_names(CommConfig)
        if len(parts) != 3 or parts[2] not in known:
            raise ConfigError(f"unknown parameter {path!r} (controller.comm keys: "
                              f"{', '.join(sorted(known))})")
        return
    known = field_names(SECTIONS[parts[0]])
    if len(parts) != 2 or parts[1] not in known:
        raise ConfigError(
            f"unknown parameter {path!r} ([{parts[0]}] keys: {', '.join(sorted(known))})"
        )


def replace_section(sc: Scenario, **sections: Any) -> Scenario:
    """A copy with whole sections replaced (validated again)."""
    return dataclasses.replace(sc, **sections)
