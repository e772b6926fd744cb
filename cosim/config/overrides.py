"""Dotted-key overrides: ``--set KEY=VALUE`` on the command line, a dict in Python.

``demand.cav_share=0.5`` sets ``[demand] cav_share``; ``controller.params.c1_alpha=0.2``
sets a law parameter. VALUE is read as a TOML value (``0.5``, ``true``, ``[25, 35]``,
``"text"``); anything that is not valid TOML is taken as a bare string, so
``controller.kind=mymodule:MyLaw`` needs no quotes.
"""

from __future__ import annotations

import copy
import tomllib
from collections.abc import Iterable, Mapping
from typing import Any

from cosim.errors import ConfigError


def parse_value(text: str) -> Any:
    """A TOML value from text, or the text itself when it is not valid TOML."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_assignments(items: Iterable[str]) -> dict[str, Any]:
    """``["a.b=1", ...]`` -> ``{"a.b": 1, ...}``; a malformed item is one ConfigError."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key or any(not part for part in key.split(".")):
            raise ConfigError(f"--set {item!r}: write KEY=VALUE with a dotted KEY such as "
                              "demand.cav_share=0.5")
        out[key] = parse_value(value.strip())
    return out


def apply_overrides(data: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict:
    """A deep copy of the nested ``data`` with each dotted key set to its value."""
    out = copy.deepcopy(dict(data))
    for path, value in overrides.items():
        parts = path.split(".")
        if len(parts) < 2:
            raise ConfigError(f"override {path!r}: a key needs a section, e.g. "
                              f"scenario.{path}")
        node = out
        for p in parts[:-1]:
            nxt = node.get(p)
            if nxt is None:
                nxt = node[p] = {}
            elif not isinstance(nxt, dict):
                raise ConfigError(f"override {path!r}: {p!r} is a value, not a table")
            node = nxt
        node[parts[-1]] = value
    return out
