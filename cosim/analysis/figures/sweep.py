"""Figures of a whole sweep: the fundamental diagram and capacity against the CAV share.

* :func:`fundamental_diagram_figure`: flow vs density and speed vs density, one curve per
  series (CAV share x controller, ...): the seed-mean per demand level, every run as a
  faint marker of its series and every measurement interval as a grey dot.
* :func:`capacity_figure`: capacity vs CAV share, one line per controller/variant, with
  the confidence interval as error bars.
* :func:`stationary_mask`: which runs are stationary; the others are drawn hollow in
  every figure (also the headline ones).

Each builder returns the matplotlib Figure unsaved; write it with
:func:`cosim.analysis.figures.output.save`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

from cosim.analysis.figures.style import (
    INTERVAL_COLOUR,
    REJECTED_HANDLE,
    axis_top,
    series_labels,
    series_style,
    titled,
)
from cosim.analysis.tables import FD_COLUMNS

#: A fundamental diagram whose every speed is at least this share of the free speed (the
#: highest run speed) holds only its free-flow branch, and says so on the figure.
FREE_FLOW_SHARE = 0.8


def _groups(frame: pd.DataFrame, cols: list[str]):
    if not cols:
        yield {}, frame
        return
    for key, g in frame.groupby(cols, dropna=False, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        yield dict(zip(cols, key, strict=True)), g


def free_flow_only(speeds: Sequence[float] | np.ndarray,
                   share: float = FREE_FLOW_SHARE) -> tuple[bool, float]:
    """(True if no speed falls below ``share`` x the free speed, the free speed in m/s).

    The free speed is the highest finite speed; with no finite speed: (False, NaN).
    """
    v = np.asarray(speeds, dtype=float)
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return False, math.nan
    free = float(v.max())
    return bool(free > 0 and v.min() >= share * free), free


def stationary_mask(runs: pd.DataFrame) -> np.ndarray:
    """(R,) bool: runs accepted as stationary (column ``stationary``; all when absent).
    Non-stationary runs are drawn as hollow markers in every figure."""
    if "stationary" not in runs:
        return np.ones(len(runs), dtype=bool)
    return runs["stationary"].astype("boolean").fillna(False).to_numpy(bool)


def fundamental_diagram_figure(
    runs: pd.DataFrame,
    series_cols: Sequence[str] = ("demand.cav_share", "controller.kind"),
    demand_col: str | None = None,
    intervals: pd.DataFrame | None = None,
    title: str | None = None,
):
    """Flow-density and speed-density diagrams, one curve per series (a matplotlib
    Figure, not saved).

    Args:
        runs: one row per run with ``edie_density_vpkm`` (veh/km), ``edie_flow_vph``
            (veh/h), ``space_mean_speed_mps`` (m/s), the series columns and the demand
            column (:func:`cosim.analysis.tables.fd_runs`).
        series_cols: columns that define a curve (one colour and marker each).
        demand_col: the demand level; curves join the seed-means per level (in order of
            demand). Without it, the curve joins the runs sorted by density.
        intervals: per-interval points (:func:`cosim.analysis.tables.fd_intervals`), drawn
            as grey dots ("per interval" in the legend).
        title: the sweep's or scenario's name, in the figure title.

    A diagram whose speeds all stay above :data:`FREE_FLOW_SHARE` of the free speed says
    on the figure that it holds only the free-flow branch.
    """
    series_cols = [c for c in series_cols if c in runs]
    groups = list(_groups(runs, series_cols))
    labels = series_labels(series_cols, [list(k.values()) for k, _ in groups])
    fig, (ax_q, ax_v) = plt.subplots(1, 2, figsize=(12, 5))
    speeds = [runs["space_mean_speed_mps"].to_numpy(float)]
    handles = []
    if intervals is not None and len(intervals):
        for ax, y in ((ax_q, "edie_flow_vph"), (ax_v, "space_mean_speed_mps")):
            ax.scatter(intervals["edie_density_vpkm"], intervals[y], s=7, alpha=0.5,
                       color=INTERVAL_COLOUR, linewidths=0, zorder=1)
        speeds.append(intervals["space_mean_speed_mps"].to_numpy(float))
        handles.append(Line2D([], [], linestyle="", marker="o", markersize=4, alpha=0.6,
                              color=INTERVAL_COLOUR, label="per interval"))
    any_rejected = False
    for k, ((_keys, g), label) in enumerate(zip(groups, labels, strict=True)):
        st = series_style(k)
        ok = stationary_mask(g)
        any_rejected |= bool((~ok).any())
        for ax, y in ((ax_q, "edie_flow_vph"), (ax_v, "space_mean_speed_mps")):
            ax.scatter(g.loc[ok, "edie_density_vpkm"], g.loc[ok, y], s=18, alpha=0.45,
                       color=st["color"], marker=st["marker"], linewidths=0, zorder=2)
            ax.scatter(g.loc[~ok, "edie_density_vpkm"], g.loc[~ok, y], s=22, alpha=0.8,
                       facecolors="none", edgecolors=st["color"], marker=st["marker"],
                       linewidths=1.0, zorder=2)
        if demand_col and demand_col in g:
            curve = g.groupby(demand_col)[list(FD_COLUMNS)].mean()
        else:
            curve = g.sort_values("edie_density_vpkm")
        for ax, y in ((ax_q, "edie_flow_vph"), (ax_v, "space_mean_speed_mps")):
            (line,) = ax.plot(curve["edie_density_vpkm"], curve[y], markersize=5, label=label,
                              zorder=3, **st)
        handles.insert(k, line)
    handles.append(Line2D([], [], linestyle="", marker="o", markersize=5, color="0.3",
                          alpha=0.45, label="per run (marker of its series)"))
    if any_rejected:
        handles.append(REJECTED_HANDLE())
    ax_q.set_xlabel("density (Edie), veh/km")
    ax_q.set_ylabel("flow (Edie), veh/h")
    ax_v.set_xlabel("density (Edie), veh/km")
    ax_v.set_ylabel("space-mean speed, m/s")
    frames = [runs] + ([intervals] if intervals is not None and len(intervals) else [])
    for ax, y in ((ax_q, "edie_flow_vph"), (ax_v, "space_mean_speed_mps")):
        ax.grid(alpha=0.3)
        ax.set_xlim(0, axis_top(frames, "edie_density_vpkm"))
        ax.set_ylim(0, axis_top(frames, y))
    ax_q.legend(handles=handles, fontsize=8, loc="best", title="lines: mean over seeds",
                title_fontsize=8)
    only_free, v_free = free_flow_only(np.concatenate(speeds))
    if only_free:
        ax_q.text(0.98, 0.03,
                  "free-flow branch only: no congested point\n"
                  f"(every speed ≥ {FREE_FLOW_SHARE:.0%} of the free speed, {v_free:.1f} m/s)",
                  transform=ax_q.transAxes, ha="right", va="bottom", fontsize=8,
                  bbox={"facecolor": "white", "edgecolor": "0.6", "alpha": 0.9})
    fig.suptitle(titled("Fundamental diagram", title))
    fig.tight_layout()
    return fig


def capacity_figure(
    capacity: pd.DataFrame,
    series_cols: Sequence[str] = ("demand.cav_share", "controller.kind"),
    title: str | None = None,
):
    """Capacity (veh/h) vs CAV share (%), one line per remaining series key (colour and
    marker each), confidence-interval error bars (a matplotlib Figure, not saved)."""
    rest = [c for c in series_cols if c in capacity and c != "demand.cav_share"]
    groups = list(_groups(capacity, rest))

    def only_share(g):  # a series at one CAV share is labelled with it ("HDV only", ...)
        shares = g["demand.cav_share"].dropna().unique()
        return float(shares[0]) if len(shares) == 1 else None

    at = 1 if rest[:1] == ["variant"] else 0  # the label reads variant, share, controller
    labels = series_labels(rest[:at] + ["demand.cav_share"] + rest[at:],
                           [[*list(k.values())[:at], only_share(g), *list(k.values())[at:]]
                            for k, g in groups])
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, ((_keys, g), label) in enumerate(zip(groups, labels, strict=True)):
        g = g.sort_values("demand.cav_share")
        y = g["capacity_vph"].to_numpy(float)
        lo = g.get("capacity_ci_low_vph", pd.Series(np.nan, index=g.index)).to_numpy(float)
        err = np.where(np.isfinite(lo), y - lo, 0.0)
        ax.errorbar(100 * g["demand.cav_share"].to_numpy(float), y, yerr=err, capsize=3,
                    label=label if rest else "mean over seeds", **series_style(k))
    ax.set_xlabel("CAV share, %")
    ax.set_ylabel("capacity (max mean flow), veh/h")
    ax.grid(alpha=0.3)
    ax.set_xlim(-5, 105)
    ax.set_ylim(0, axis_top([capacity], "capacity_vph", "capacity_ci_high_vph"))
    ax.legend(fontsize=8)
    ax.set_title(f"{titled('Capacity', title)} (error bars: CI over seeds)", fontsize=10)
    fig.tight_layout()
    return fig
