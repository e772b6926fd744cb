"""Typed, validated construction of frozen dataclasses from TOML tables.

:func:`from_table` builds any dataclass (a scenario section, a law's parameters) from a
dict as parsed from TOML, checking every value against the field's type hint before the
dataclass's own validation runs:

* unknown keys are refused, naming the valid ones;
* ``bool``, ``int``, ``float``, ``str``, ``tuple[...]`` (fixed or ``...``), unions
  (``float | None``, ``tuple | float``) and ``dict`` are checked; an int is accepted
  for a float;
* **every float must be finite** (NaN and +-inf are refused with the key's name);
* the dataclass's own ``ValueError``/``TypeError`` (including
  :class:`controllers.errors.ParameterError`) becomes one :class:`ConfigError` line
  prefixed with the section.

All errors are :class:`~cosim.errors.ConfigError`: one line, naming ``section.key``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from collections.abc import Mapping
from typing import Any

from cosim.errors import ConfigError


def field_names(cls: type) -> list[str]:
    """The init fields of a dataclass, in order."""
    return [f.name for f in dataclasses.fields(cls) if f.init]


def check_value(where: str, value: Any, hint: Any) -> Any:
    """``value`` checked against the type ``hint`` (converted where TOML is looser)."""
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
                return check_value(where, value, arg)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{where}: bad value {value!r}")
    if hint is Any:
        return value
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
        if not math.isfinite(value):
            raise ConfigError(f"{where} must be a finite number, got {value!r}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where} must be a string, got {value!r}")
        return value
    if origin is tuple or hint is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where} must be a list, got {value!r}")
        if args and args[-1] is Ellipsis:
            return tuple(check_value(where, v, args[0]) for v in value)
        if args and len(args) != len(value):
            raise ConfigError(f"{where} must have {len(args)} entries, got {len(value)}")
        kinds = args or [Any] * len(value)
        return tuple(check_value(where, v, a) for v, a in zip(value, kinds, strict=True))
    if hint is dict or origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{where} must be a table, got {value!r}")
        return dict(value)
    return value


@functools.cache
def type_hints(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints(cls)``, evaluated once per class (the annotations are strings:
    evaluating them costs more than checking a table)."""
    return typing.get_type_hints(cls)


def check_table(cls: type, section: str, data: Mapping[str, Any],
                exclude: frozenset[str] = frozenset()) -> dict[str, Any]:
    """The keys of ``data`` checked against ``cls``'s fields (types, finiteness)."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"[{section}] must be a table")
    hints = type_hints(cls)
    known = [n for n in field_names(cls) if n not in exclude]
    out = {}
    for key, value in data.items():
        if key not in known:
            raise ConfigError(f"{section}: unknown key {key!r} (known: {', '.join(sorted(known))})")
        out[key] = check_value(f"{section}.{key}", value, hints[key])
    return out


def from_table(cls: type, section: str, data: Mapping[str, Any]) -> Any:
    """``cls(**data)`` with every key and value checked; errors as one ConfigError line."""
    kwargs = check_table(cls, section, data)
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (ValueError, TypeError) as exc:
        text = str(exc)
        first = text.split(" ", 1)[0]
        if first in field_names(cls):  # "name must be ...": name it as section.name
            raise ConfigError(f"{section}.{text}") from None
        raise ConfigError(f"{section}: {text}") from None


def plain(value: Any) -> Any:
    """A TOML-serialisable copy: dataclasses and tuples to dicts and lists, None dropped."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if hasattr(value, "__fspath__"):
        return str(value)
    return value
