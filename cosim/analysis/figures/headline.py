"""Figures of the headline experiment (tables from :mod:`cosim.analysis.headline`).

* :func:`headline_capacity_figure`: queue discharge per bottleneck arm with confidence
  intervals;
* :func:`headline_mixed_figure`: flow on TUM's ring against the CAV share, beside TUM's;
* :func:`headline_fd_figure`: the ring fundamental diagram per time gap and mode;
* :func:`headline_gain_figure`: lane-free against fixed rows at equal time gap.

Each builder returns the matplotlib Figure unsaved; write it with
:func:`cosim.analysis.figures.output.save`.
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

from cosim.analysis.figures.style import REJECTED_HANDLE, axis_top, series_style, titled
from cosim.analysis.figures.sweep import stationary_mask

#: Modes of the ring arms (cosim.analysis.headline) in a fixed style order.
RING_MODES = (("lanefree", "lane-free flocking"), ("fixed4", "4 fixed rows"),
              ("rows3", "3 fixed rows (lanes)"))


def headline_capacity_figure(bottleneck: pd.DataFrame, title: str | None = None):
    """Queue discharge (veh/h) per bottleneck arm with its confidence interval; arms
    without a valid run say why; hollow when a valid run is not stationary (a matplotlib
    Figure, not saved).

    Args:
        bottleneck: :func:`cosim.analysis.headline.bottleneck_table`.
    """
    fig, ax = plt.subplots(figsize=(8, 0.6 * max(len(bottleneck), 2) + 1.4))
    y = np.arange(len(bottleneck))[::-1]
    for k, (yk, (_, r)) in enumerate(zip(y, bottleneck.iterrows(), strict=True)):
        st = series_style(k)
        cap = float(r["capacity_vph"])
        if not math.isfinite(cap):
            ax.text(0.01, yk, "no valid run: " + str(r.get("why_rejected", ""))[:70],
                    transform=ax.get_yaxis_transform(), va="center", fontsize=7, color="0.35")
            continue
        lo, hi = float(r["ci_low_vph"]), float(r["ci_high_vph"])
        err = [[cap - lo], [hi - cap]] if math.isfinite(lo) else None
        all_stationary = int(r["n_stationary"]) == int(r["n_valid"])
        ax.errorbar([cap], [yk], xerr=err, capsize=4, color=st["color"], marker=st["marker"],
                    markersize=7, linestyle="",
                    markerfacecolor=st["color"] if all_stationary else "none")
        ax.text(cap, yk + 0.25, f"{cap:,.0f}".replace(",", " ")
                + f"  ({int(r['n_valid'])}/{int(r['n_runs'])} valid)", fontsize=7,
                ha="center", color=st["color"])
    ax.set_yticks(y)
    ax.set_yticklabels(list(bottleneck["label"]), fontsize=8)
    ax.set_xlabel("queue-discharge flow (road-limited capacity), veh/h")
    ax.set_xlim(0, axis_top([bottleneck], "capacity_vph", "ci_high_vph") * 1.1)
    ax.set_ylim(-0.7, len(bottleneck) - 0.3)
    ax.grid(alpha=0.3, axis="x")
    ax.legend(handles=[Line2D([], [], linestyle="", marker="o", color="0.3",
                              label="mean of the valid runs, CI over them"),
                       REJECTED_HANDLE()], fontsize=7, loc="lower right")
    ax.set_title(f"{titled('Capacity at a bottleneck', title)} (error bars: CI over seeds)",
                 fontsize=10)
    fig.tight_layout()
    return fig


def headline_mixed_figure(tum: pd.DataFrame, runs: pd.DataFrame,
                          reference: dict[float, float] | None = None,
                          title: str | None = None):
    """Flow (veh/h) on TUM's ring against the CAV share (%): every run (hollow when not
    stationary), the mean with its CI, and TUM's published flows (``reference``,
    veh/h by share) (a matplotlib Figure, not saved).

    Args:
        tum: :func:`cosim.analysis.headline.tum_ring_table`; runs: the ring's run rows
            (``demand.cav_share``, ``edie_flow_vph``, ``stationary``).
    """
    fig, ax = plt.subplots(figsize=(7, 4.5))
    if reference:
        xs = sorted(reference)
        ax.plot([100 * x for x in xs], [reference[x] for x in xs], color="k", marker="s",
                linestyle="--", markersize=5, label="TUM LaneFreeDrive (published)")
    st = series_style(0)
    if len(runs):
        ok = stationary_mask(runs)
        share = 100 * runs["demand.cav_share"].astype(float)
        ax.scatter(share[ok], runs.loc[ok, "edie_flow_vph"], s=18, alpha=0.5,
                   color=st["color"], marker=st["marker"], linewidths=0)
        ax.scatter(share[~ok], runs.loc[~ok, "edie_flow_vph"], s=24, facecolors="none",
                   edgecolors=st["color"], marker=st["marker"], linewidths=1.0)
    if len(tum):
        y = tum["flow_vph"].to_numpy(float)
        lo = tum["ci_low_vph"].to_numpy(float)
        hi = tum["ci_high_vph"].to_numpy(float)
        err = np.vstack([np.where(np.isfinite(lo), y - lo, 0.0),
                         np.where(np.isfinite(hi), hi - y, 0.0)])
        ax.errorbar(100 * tum["cav_share"].to_numpy(float), y, yerr=err, capsize=3,
                    label="ours: mean (CI over seeds where several)", **st)
    ax.scatter([], [], s=18, color=st["color"], marker=st["marker"], label="ours: per run")
    handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=[*handles, REJECTED_HANDLE()], fontsize=8, loc="upper left")
    ax.set_xlabel("CAV share, %")
    ax.set_ylabel("flow (Edie, whole ring), veh/h")
    ax.set_xlim(-5, 105)
    top = axis_top([tum, runs], "flow_vph", "ci_high_vph", "edie_flow_vph")
    ax.set_ylim(0, max(top, 1.05 * max(reference.values())) if reference else top)
    ax.grid(alpha=0.3)
    ax.set_title(titled("Mixed traffic on TUM's ring, 225 veh/km", title), fontsize=10)
    fig.tight_layout()
    return fig


def headline_fd_figure(runs: pd.DataFrame, title: str | None = None,
                       reference: pd.DataFrame | None = None):
    """Flow-density of the ring arms, one panel per time gap, one colour per mode (lane-free,
    4 fixed rows, 3 fixed rows): every run (hollow when not stationary) and the mode's line
    through its density means from the origin (a matplotlib Figure, not saved).

    Args:
        runs: run rows with ``mode``, ``time_gap_s``, ``demand_level``,
            ``edie_density_vpkm``, ``edie_flow_vph``, ``stationary``.
        reference: runs drawn as black crosses in the first panel (e.g. the lane-free
            CAVs of TUM's ring in the SUMO world).
    """
    gaps = sorted(runs["time_gap_s"].dropna().unique()) if len(runs) else []
    fig, axes = plt.subplots(1, max(len(gaps), 1), figsize=(5 * max(len(gaps), 1), 4.4),
                             squeeze=False, sharey=True)
    for ax, tg in zip(axes[0], gaps, strict=False):
        for k, (mode, name) in enumerate(RING_MODES):
            g = runs[(runs["time_gap_s"] == tg) & (runs["mode"] == mode)]
            if g.empty:
                continue
            st = series_style(k)
            ok = stationary_mask(g)
            curve = g.groupby("demand_level")[["edie_density_vpkm", "edie_flow_vph"]].mean(
            ).sort_values("edie_density_vpkm")
            ax.plot(np.r_[0.0, curve["edie_density_vpkm"]], np.r_[0.0, curve["edie_flow_vph"]],
                    color=st["color"], linestyle=st["linestyle"], linewidth=1.2, label=name)
            ax.scatter(g.loc[ok, "edie_density_vpkm"], g.loc[ok, "edie_flow_vph"],
                       color=st["color"], marker=st["marker"], s=34, zorder=3)
            ax.scatter(g.loc[~ok, "edie_density_vpkm"], g.loc[~ok, "edie_flow_vph"],
                       facecolors="none", edgecolors=st["color"], marker=st["marker"], s=38,
                       linewidths=1.2, zorder=3)
        if reference is not None and len(reference) and tg == gaps[0]:
            ax.scatter(reference["edie_density_vpkm"], reference["edie_flow_vph"], color="k",
                       marker="x", s=40, zorder=4,
                       label="lane-free, SUMO world (TUM ring runs)")
        ax.set_title(f"time gap T = {tg:g} s", fontsize=9)
        ax.set_xlabel("density (Edie), veh/km")
        ax.grid(alpha=0.3)
        ax.set_xlim(0, axis_top([runs], "edie_density_vpkm"))
    axes[0, 0].set_ylabel("flow (Edie), veh/h")
    axes[0, 0].set_ylim(0, axis_top([runs] + ([reference] if reference is not None else []),
                                "edie_flow_vph"))
    handles, _ = axes[0, 0].get_legend_handles_labels()
    axes[0, 0].legend(handles=[*handles, REJECTED_HANDLE()], fontsize=7, loc="upper left")
    fig.suptitle(titled("Ring fundamental diagram, 100 % CAVs", title))
    fig.tight_layout()
    return fig


def headline_gain_figure(gain: pd.DataFrame, title: str | None = None):
    """Flow (veh/h) against the time gap (s) of the same law lane-free, in 4 fixed rows
    and in 3 fixed rows, one panel per ring density (a matplotlib Figure, not saved).

    Args:
        gain: :func:`cosim.analysis.headline.lanefree_gain_table`.
    """
    levels = sorted(gain["ring_density_vpkm"].unique()) if len(gain) else []
    fig, axes = plt.subplots(1, max(len(levels), 1), figsize=(5.5 * max(len(levels), 1), 4.2),
                             squeeze=False, sharey=True)
    names = tuple((f"{mode}_vph", name) for mode, name in RING_MODES)
    for ax, k in zip(axes[0], levels, strict=False):
        g = gain[gain["ring_density_vpkm"] == k].sort_values("time_gap_s")
        for j, (col, name) in enumerate(names):
            if col in g and g[col].notna().any():
                ax.plot(g["time_gap_s"], g[col], label=name, markersize=6, **series_style(j))
        ax.set_title(f"{k:g} veh/km", fontsize=9)
        ax.set_xlabel("time gap T, s")
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("flow (Edie), veh/h")
    axes[0, 0].set_ylim(0, axis_top([gain], *(c for c, _ in names)))
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(titled("Lane-free gain at equal time gap (100 % CAVs, ring)", title))
    fig.tight_layout()
    return fig
