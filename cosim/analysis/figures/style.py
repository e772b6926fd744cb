"""The one style of every figure: colours, palette, markers, series labels, units.

Every series has its own colour (Okabe-Ito, colour-blind safe) and marker
(:func:`series_style`) and a readable label (:func:`series_label`, e.g.
"CAV 95 %, flocking"); CAVs are blue and HDVs orange everywhere (:data:`CAV_COLOUR`,
:data:`HDV_COLOUR`); speeds are coloured by :func:`speed_cmap`; points that are not
stationary are drawn hollow (legend entry :func:`REJECTED_HANDLE`). Also the small
shared axis helpers: :func:`axis_top` (upper limit) and :func:`titled` (figure titles
that name the sweep or scenario).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

#: CAVs and HDVs in every figure (and in sumo-gui: cosim.demand.routes.CAV_RGB/HDV_RGB):
#: tab:blue and tab:orange, a colour-blind-safe pair that also differs in lightness.
CAV_COLOUR = "tab:blue"
HDV_COLOUR = "tab:orange"
#: Series colours: the Okabe & Ito (2008) colour-blind-safe palette (yellow last: it
#: reads poorly on white).
PALETTE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000",
           "#F0E442")
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
LINESTYLES = ("-", "--", "-.", ":")
#: Per-measurement-interval points of the fundamental diagram.
INTERVAL_COLOUR = "0.55"
#: Speed colour map of the time-space diagram: viridis (perceptually uniform, colour-blind
#: safe) without its lightest 15 %, so that free-flow lines stay visible on white.
SPEED_CMAP = "viridis_to_85"

_CONTROLLER_NAMES = {
    "flocking": "flocking",
    "boundary_points": "boundary points",
    "formation": "formation",
    "vicsek": "Vicsek",
    "sumo": "SUMO-driven",
}
_NETWORK_NAMES = {
    "straight": "lane-free road",
    "three_lane": "3 lanes",
    "ring": "ring",
    "varying_width": "varying width",
    "on_ramp": "on-ramp",
    "file": "user network",
}
_UNITS = {"_m": "m", "_s": "s", "_mps": "m/s", "_mps2": "m/s²", "_vph": "veh/h",
          "_vpkm": "veh/km", "_deg": "°"}


def speed_cmap():
    """The :data:`SPEED_CMAP` colour map (viridis from 0 to 0.85)."""
    from matplotlib.colors import LinearSegmentedColormap

    base = plt.get_cmap("viridis")
    return LinearSegmentedColormap.from_list(SPEED_CMAP, base(np.linspace(0.0, 0.85, 256)))


def series_style(k: int) -> dict:
    """Colour, marker and line style of the k-th series (0-based).

    Colours from :data:`PALETTE` and markers from :data:`MARKERS`: the first 8 series
    differ in both; later ones repeat a colour with another marker and line style.
    """
    n = len(PALETTE)
    return {"color": PALETTE[k % n], "marker": MARKERS[(k + k // n) % len(MARKERS)],
            "linestyle": LINESTYLES[(k // n) % len(LINESTYLES)]}


def _param_text(key: str, v) -> str:
    name = key.split(".")[-1]
    for suffix, unit in _UNITS.items():
        if name.endswith(suffix):
            value = f"{v:g}" if isinstance(v, float | int) else str(v)
            return f"{name[: -len(suffix)].replace('_', ' ')} {value} {unit}"
    value = f"{v:g}" if isinstance(v, float) else str(v)
    return f"{name} = {value}"


def series_label(keys: Sequence[str], values: Sequence, short: bool = True) -> str:
    """A readable label of a series, e.g. ``"CAV 95 %, flocking"``,
    ``"three lane lc2013, HDV only"``, ``"CAV 50 %, flocking, width 8 m"``.

    With ``short``, a CAV share of 0 reads "HDV only" and the (idle) controller is left
    out; :func:`series_labels` falls back to the full form where that is ambiguous.
    """
    pairs = [(k, v) for k, v in zip(keys, values, strict=True)
             if not (v is None or (isinstance(v, float) and math.isnan(v)))]
    no_cavs = short and any(k == "demand.cav_share" and float(v) == 0.0 for k, v in pairs)
    parts = []
    for k, v in pairs:
        if k == "demand.cav_share":
            parts.append("HDV only" if no_cavs else f"CAV {100 * float(v):g} %")
        elif k == "controller.kind":
            if not no_cavs:
                parts.append(_CONTROLLER_NAMES.get(str(v), str(v)))
        elif k == "variant":
            parts.append(str(v).replace("_", " "))
        elif k == "network.kind":
            parts.append(_NETWORK_NAMES.get(str(v), str(v).replace("_", " ")))
        else:
            parts.append(_param_text(k, v))
    return ", ".join(parts) or "all runs"


def series_labels(keys: Sequence[str], rows: Sequence[Sequence]) -> list[str]:
    """Labels of several series (one value row each), short where they stay distinct."""
    short = [series_label(keys, r) for r in rows]
    if len(set(short)) == len(short):
        return short
    return [series_label(keys, r, short=False) for r in rows]


def REJECTED_HANDLE() -> Line2D:  # noqa: N802 (a legend entry, built fresh per figure)
    """Legend entry of a rejected (non-stationary) point: a hollow grey marker."""
    return Line2D([], [], linestyle="", marker="o", markersize=5, markerfacecolor="none",
                  markeredgecolor="0.3", label="hollow: not stationary (drift >= 2 %)")


def axis_top(frames: Sequence[pd.DataFrame], *cols: str) -> float:
    """Upper axis limit: 5 % above the largest finite value of ``cols`` (1 if none)."""
    vals = np.concatenate([np.asarray(f[c], dtype=float).ravel()
                           for f in frames for c in cols if c in f] or [np.zeros(0)])
    vals = vals[np.isfinite(vals)]
    return 1.05 * float(vals.max()) if len(vals) and vals.max() > 0 else 1.0


def titled(what: str, name: str | None) -> str:
    """A figure title: ``"what: name"`` (the sweep's or scenario's name), or ``what``."""
    return f"{what}: {name}" if name else what
