"""The names of a road's origins and destinations in the demand (``demand.od_vph``).

Origins: ``main`` (the main road's start) and the on-ramps ``ramp``, ``ramp2``, ``ramp3``,
...; destinations: ``main`` (the main road's end) and the off-ramps ``off``, ``off2``, ...;
numbered in the order the network gives them (:mod:`cosim.road.ramps`).
"""

from __future__ import annotations


def ramp_name(k: int) -> str:
    """The demand name of the ``k``-th (0-based) on-ramp: ``ramp``, ``ramp2``, ..."""
    return "ramp" if k == 0 else f"ramp{k + 1}"


def offramp_name(k: int) -> str:
    """The demand name of the ``k``-th (0-based) off-ramp: ``off``, ``off2``, ..."""
    return "off" if k == 0 else f"off{k + 1}"


def origin_number(name: str) -> int | None:
    """0 for ``main``, k for the k-th on-ramp's name (``ramp`` = 1, ``ramp2`` = 2, ...);
    None for a name that is neither."""
    return _number(name, "ramp")


def destination_number(name: str) -> int | None:
    """0 for ``main``, k for the k-th off-ramp's name (``off`` = 1, ``off2`` = 2, ...);
    None for a name that is neither."""
    return _number(name, "off")


def _number(name: str, stem: str) -> int | None:
    if name == "main":
        return 0
    if name == stem:
        return 1
    tail = name[len(stem):] if isinstance(name, str) and name.startswith(stem) else ""
    if tail.isdigit() and not tail.startswith("0") and int(tail) >= 2:
        return int(tail)
    return None
