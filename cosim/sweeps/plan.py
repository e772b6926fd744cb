"""The plan of a sweep: parsing and validating a sweep file, its grid points and run ids.

A sweep file (TOML) names a base scenario, inline overrides and axes::

    seeds = [1, 2, 3]                 # optional; or [sweep] seeds, or an axis scenario.seed

    [sweep]
    name = "open_road_capacity"
    description = "..."
    base = "default"                  # built-in scenario name or a path (relative to
                                      # this file); default: the built-in default

    [overrides]                       # scenario sections applied on top of the base
    scenario.duration_s = 600.0
    network.length_m = 2000.0

    [axes]                            # any scenario parameter by dotted path
    "demand.inflow_vph" = [2000.0, 4000.0]
    "demand.cav_share" = [0.0, 0.5, 1.0]
    "controller.params.c1_alpha" = [0.2, 0.3]

    [[variants]]                      # optional named parameter sets (not a product
    name = "lanefree"                 # among themselves): grid = variants x axes x seeds
    "network.kind" = "straight"

    [smoke]                           # `cosim sweep FILE --smoke`: replaces seeds,
    seeds = [1]                       # the axes it names (others are kept), variants;
    [smoke.overrides]                 # its overrides are applied on top
    scenario.duration_s = 40.0
    [smoke.axes]
    "demand.inflow_vph" = [4000.0]

Dotted keys may be quoted (``"demand.cav_share"``) or TOML-dotted; both mean the same.
Every grid point is validated with :func:`cosim.config.scenario.scenario_from_dict` before
any run starts, so a typo fails with one line.

``run_id`` is a hash of the resolved scenario (every parameter, seed included), so the
same grid point always gets the same directory and ``--resume`` runs only the points
without an ``ok`` row.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cosim.config.builtins import scenario_dir, sweep_dir
from cosim.errors import ConfigError
from cosim.output_dir import safe_name

if TYPE_CHECKING:  # cosim.config.scenario (numpy, ...) is imported where used: the CLI stays fast
    from cosim.config.scenario import Scenario


#: Demand-level parameters (the x of a fundamental diagram), in order of preference.
DEMAND_PATHS = ("demand.inflow_vph", "demand.ring_density_vpkm")
#: Parameters every row carries even when not swept (the analysis groups by them).
DESCRIPTOR_PATHS = (
    "network.kind",
    "network.width_m",
    "demand.cav_share",
    "controller.kind",
    "scenario.duration_s",
)

_TOP_KEYS = {"sweep", "seeds", "overrides", "axes", "variants", "smoke"}
_SWEEP_KEYS = {"name", "description", "base", "seeds"}
_SMOKE_KEYS = {"name", "description", "seeds", "overrides", "axes", "variants"}


@dataclass(frozen=True)
class GridPoint:
    """One run of a sweep: its parameters (dotted path -> value) and resolved scenario."""

    index: int
    run_id: str
    params: dict[str, Any]
    variant: str | None
    scenario: Scenario

    @property
    def seed(self) -> int:
        return self.scenario.scenario.seed

    def label(self) -> str:
        parts = [f"variant={self.variant}"] if self.variant else []
        parts += [f"{k}={_fmt(v)}" for k, v in self.params.items() if k != "scenario.seed"]
        parts.append(f"seed={self.seed}")
        return ", ".join(parts)


@dataclass(frozen=True)
class SweepPlan:
    """A validated sweep: the grid of points and what it was built from."""

    name: str
    description: str
    source: Path | None
    smoke: bool
    base: str
    overrides: dict[str, Any]
    axes: dict[str, list]
    seeds: list[int] | None
    variants: list[dict[str, Any]]
    points: list[GridPoint] = field(repr=False)
    #: A smoke plan: the full sweep's name and description (``None``/"" otherwise).
    full_name: str | None = None
    full_description: str = ""

    @property
    def demand_axis(self) -> str | None:
        """The swept demand parameter (x of the fundamental diagram), if any."""
        for p in DEMAND_PATHS:
            if p in self.axes or any(p in v for v in self.variants):
                return p
        return None

    def param_columns(self) -> list[str]:
        """Parameter columns of the rows: swept ones first, then the descriptors."""
        cols = list(self.axes)
        for v in self.variants:
            cols += [k for k in v if k != "name"]
        cols += list(DESCRIPTOR_PATHS)
        cols += [p for p in DEMAND_PATHS]
        return [c for c in dict.fromkeys(cols) if c != "scenario.seed"]

    def to_json(self) -> dict:
        return {
            "name": self.name,
            "description": self.description,
            "source": str(self.source) if self.source else None,
            "smoke": self.smoke,
            "full_name": self.full_name,
            "full_description": self.full_description,
            "base": self.base,
            "overrides": self.overrides,
            "axes": self.axes,
            "seeds": self.seeds,
            "variants": self.variants,
            "demand_axis": self.demand_axis,
            "param_columns": self.param_columns(),
            "n_points": len(self.points),
            "run_ids": [p.run_id for p in self.points],
        }


def _fmt(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def resolve_sweep_file(arg: str | Path) -> Path:
    """A sweep file by path, or by name from ``experiments/sweeps/``."""
    path = Path(arg)
    if path.is_file():
        return path
    named = sweep_dir() / f"{arg}.toml"
    if path.suffix != ".toml" and named.is_file():
        return named
    known = ", ".join(sorted(p.stem for p in sweep_dir().glob("*.toml")))
    raise ConfigError(f"no sweep file or built-in sweep named {str(arg)!r} (built-in: {known})")


def load_sweep(path: str | Path, smoke: bool = False) -> SweepPlan:
    """Read a sweep file (path or built-in name), validate every grid point, return the plan."""
    from cosim.config.scenario import read_toml

    path = resolve_sweep_file(path)
    data = read_toml(path)  # unreadable, not UTF-8, not TOML: one ConfigError line
    try:
        return sweep_from_dict(data, source=path, smoke=smoke)
    except ConfigError as exc:
        raise ConfigError(f"{path.name}: {exc}") from None


def sweep_from_dict(data: dict, source: Path | None = None, smoke: bool = False) -> SweepPlan:
    """Build and validate a :class:`SweepPlan` from a parsed sweep file."""
    from cosim.config.scenario import scenario_from_dict

    _check_keys(data, _TOP_KEYS, "top level")
    if not data:
        raise ConfigError("nothing to sweep: the file is empty (give [axes], [[variants]] "
                          "or seeds; one run is 'cosim run')")
    head = data.get("sweep", {})
    _check_table(head, "[sweep]")
    _check_keys(head, _SWEEP_KEYS, "[sweep]")
    if "seeds" in head and "seeds" in data:
        raise ConfigError("seeds given both at the top level and in [sweep]")
    default_name = source.stem if source else "sweep"
    full_name, full_description = None, ""
    name = head.get("name", default_name)
    description = head.get("description", "")
    base_arg = head.get("base")
    seeds = data.get("seeds", head.get("seeds"))
    overrides = _flatten(data.get("overrides", {}), "[overrides]")
    axes = _axes(data.get("axes", {}), "[axes]")
    variants = _variants(data.get("variants", []), "[[variants]]")

    if smoke:
        sm = data.get("smoke")
        if sm is None:
            raise ConfigError("--smoke given but the sweep file has no [smoke] table")
        _check_table(sm, "[smoke]")
        _check_keys(sm, _SMOKE_KEYS, "[smoke]")
        full_name, full_description = name, description
        name = sm.get("name", f"{name}_smoke")
        # the full sweep's description names the full grid: a smoke plan has its own
        description = sm.get(
            "description", f"smoke test of the sweep '{full_name}': a reduced grid of short runs"
        )
        if "seeds" in sm:
            seeds = sm["seeds"]
        overrides = {**overrides, **_flatten(sm.get("overrides", {}), "[smoke.overrides]")}
        for path, values in _axes(sm.get("axes", {}), "[smoke.axes]").items():
            axes[path] = values
        if "variants" in sm:
            variants = _variants(sm["variants"], "[smoke.variants]")
    if not isinstance(name, str) or not name:
        raise ConfigError("sweep.name must be a non-empty string")
    if not isinstance(description, str):
        raise ConfigError(f"sweep.description must be a string, got {description!r}")

    if seeds is not None:
        if (
            not isinstance(seeds, list) or not seeds
            or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds)
        ):
            raise ConfigError(f"seeds must be a non-empty list of integers >= 0, got {seeds!r}")
        if len(set(seeds)) != len(seeds):
            raise ConfigError(f"seeds has duplicates: {seeds}")
        if "scenario.seed" in axes:
            raise ConfigError("give either seeds or an axis scenario.seed, not both")
    for path in list(overrides) + list(axes) + [k for v in variants for k in v if k != "name"]:
        _check_path(path)

    base_sc, base_label = _resolve_base(base_arg, source)
    seed_axis = {"scenario.seed": list(seeds)} if seeds is not None else {}
    grid_axes = {**axes, **seed_axis}
    names = list(grid_axes)
    combos = list(itertools.product(*grid_axes.values())) if names else [()]
    points: list[GridPoint] = []
    seen: dict[str, int] = {}
    variant_list = variants or [{}]
    n_total = len(variant_list) * len(combos)
    for variant in variant_list:
        vparams = {k: v for k, v in variant.items() if k != "name"}
        for combo in combos:
            point = dict(zip(names, combo, strict=True))
            flat = {**overrides, **vparams, **point}
            where = ", ".join(
                ([f"variant={variant['name']}"] if variant else [])
                + [f"{'seed' if k == 'scenario.seed' else k}={_fmt(v)}" for k, v in point.items()]
            )
            try:
                sc = scenario_from_dict(_unflatten(flat), base=base_sc)
            except ConfigError as exc:
                raise ConfigError(
                    f"grid point {len(points) + 1}/{n_total} ({where}): {exc}"
                ) from None
            rid = run_id(sc)
            if rid in seen:
                raise ConfigError(
                    f"grid points {seen[rid] + 1} and {len(points) + 1} ({where}) are the "
                    "same scenario (duplicate axis values or variants?)"
                )
            seen[rid] = len(points)
            points.append(
                GridPoint(len(points), rid, {**vparams, **point}, variant.get("name"), sc)
            )
    return SweepPlan(
        name=name, description=description, source=source, smoke=smoke, base=base_label,
        overrides=overrides, axes=axes, seeds=list(seeds) if seeds is not None else None,
        variants=variants, points=points,
        full_name=full_name if smoke else None, full_description=full_description if smoke else "",
    )


def run_id(sc: Scenario) -> str:
    """Stable id of a run: 12 hex digits of the SHA-256 of its resolved settings that differ
    from the built-in defaults (seed included).

    Hashing the difference, not the whole config, keeps ids (and ``--resume``) valid when
    a new option with a default is added to the scenario schema; any real change of the
    scenario (base file, overrides, axes) changes the id.
    """
    from cosim.config.scenario import Scenario

    diff = _diff(sc.to_dict(), Scenario().to_dict())
    blob = json.dumps(diff, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:12]


def _diff(value: Any, default: Any) -> Any:
    if isinstance(value, dict) and isinstance(default, dict):
        out = {}
        for k, v in value.items():
            if k not in default:
                out[k] = v
            elif v != default[k]:
                out[k] = _diff(v, default[k])
        return out
    return value


def _check_table(value: Any, where: str) -> None:
    if not isinstance(value, dict):
        raise ConfigError(f"{where} must be a table")


def _check_keys(data: dict, known: set[str], where: str) -> None:
    for key in data:
        if key not in known:
            raise ConfigError(f"{where}: unknown key {key!r} (known: {', '.join(sorted(known))})")


def _flatten(data: Any, where: str, prefix: str = "") -> dict[str, Any]:
    """Nested or dotted-key tables -> {dotted path: leaf value}."""
    _check_table(data, where)
    out: dict[str, Any] = {}
    for key, value in data.items():
        path = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, dict):
            out.update(_flatten(value, where, path))
        else:
            out[path] = value
    return out


def _axes(data: Any, where: str) -> dict[str, list]:
    axes = _flatten(data, where)
    for path, values in axes.items():
        if not isinstance(values, list) or not values:
            raise ConfigError(f"{where}: axis {path!r} must be a non-empty list of values")
        keys = [json.dumps(v, sort_keys=True) for v in values]
        if len(set(keys)) != len(keys):
            raise ConfigError(f"{where}: axis {path!r} has duplicate values: {values}")
    return axes


def _variants(data: Any, where: str) -> list[dict[str, Any]]:
    if not isinstance(data, list) or not all(isinstance(v, dict) for v in data):
        raise ConfigError(f"{where} must be an array of tables ([[variants]])")
    out = []
    for k, v in enumerate(data):
        flat = _flatten(v, where)
        name = flat.get("name", f"v{k + 1}")
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{where} #{k + 1}: name must be a non-empty string")
        flat["name"] = name
        out.append(flat)
    names = [v["name"] for v in out]
    if len(set(names)) != len(names):
        raise ConfigError(f"{where}: duplicate variant names {names}")
    return out


def _check_path(path: str) -> None:
    """A dotted path must name a scenario parameter (section.key or controller.params.key);
    the rule lives with the scenario schema (:func:`cosim.config.scenario.check_parameter_path`)."""
    from cosim.config.scenario import check_parameter_path

    check_parameter_path(path)


def _unflatten(flat: dict[str, Any]) -> dict:
    out: dict = {}
    for path, value in flat.items():
        node = out
        parts = path.split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return out


def _resolve_base(arg: Any, source: Path | None) -> tuple[Scenario, str]:
    from cosim.config.scenario import default_scenario

    if arg is None:
        return default_scenario(), "default"
    if not isinstance(arg, str) or not arg:
        raise ConfigError(f"sweep.base must be a scenario name or path, got {arg!r}")
    named = scenario_dir() / f"{arg}.toml"
    if not arg.endswith(".toml") and "/" not in arg and named.is_file():
        return _load_base(named), arg
    path = Path(arg).expanduser()
    if not path.is_absolute() and source is not None:
        path = source.parent / path
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in scenario_dir().glob("*.toml")))
        raise ConfigError(
            f"sweep.base: no scenario file {str(path)!r} and no built-in scenario {arg!r} "
            f"(built-in: {known})"
        )
    return _load_base(path), str(path)


def _load_base(path: Path) -> Scenario:
    from cosim.config.scenario import load_scenario

    try:
        return load_scenario(path)
    except ConfigError as exc:
        raise ConfigError(f"base scenario {path}: {exc}") from None


def _value_at(sc: Scenario, path: str) -> Any:
    parts = path.split(".")
    if parts[:2] == ["controller", "params"]:
        return sc.controller.resolved_params().get(parts[2])
    if parts[:2] == ["controller", "comm"]:
        return sc.controller.comm.get(parts[2])
    return getattr(getattr(sc, parts[0]), parts[1])


def _cell(v: Any) -> Any:
    """A parameter value as a CSV cell (lists and tuples as JSON)."""
    if isinstance(v, list | tuple):
        return json.dumps(v)
    return v


def default_out_dir(plan: SweepPlan) -> Path:
    """``outputs/sweeps/<name>``; the name is made a safe single folder name."""
    return Path("outputs") / "sweeps" / safe_name(plan.name)
