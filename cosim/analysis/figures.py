"""PNG figures (matplotlib, Agg backend): fundamental diagrams, capacity, time-space, top view.

* :func:`plot_fundamental_diagram`: flow vs density and speed vs density, one curve per
  series (CAV share x controller, ...): the seed-mean per demand level, every run as a
  faint marker of its series and every measurement interval as a grey dot.
* :func:`plot_capacity`: capacity vs CAV share, one line per controller/variant, with
  the confidence interval as error bars.
* :func:`plot_time_space`: trajectories ``s(t)`` coloured by speed, CAVs and HDVs in
  two panels (from a run's ``trajectories.csv``: ``t_s, id, s_m, d_m, v_mps, is_cav``).
* :func:`plot_top_view`: the road seen from above at chosen times: vehicles as
  rectangles (``length_m x width_m`` at ``(s_m, d_m)``), CAVs and HDVs coloured, road
  edges (and lane lines of the three-lane baseline) drawn; :func:`animate_top_view`
  the same as a GIF.
* :func:`plot_run`: the run figures of a run folder (road geometry and scenario name
  from config.toml).
* Headline (:mod:`cosim.analysis.headline`): :func:`plot_headline_capacity` (queue
  discharge per arm with confidence intervals), :func:`plot_headline_mixed` (flow on
  TUM's ring against the CAV share, beside TUM's), :func:`plot_headline_fd` (the ring
  fundamental diagram per time gap and mode) and :func:`plot_headline_gain` (lane-free against fixed
  rows at equal time gap).

Points that are not stationary (flow drift of 2 % or more) are drawn hollow everywhere.

One style for all: every series has its own colour (Okabe-Ito, colour-blind safe) and
marker (:func:`series_style`) and a readable label (:func:`series_label`, e.g.
"CAV 95 %, flocking"); CAVs are blue and HDVs orange everywhere; every axis names its
unit; every title names the sweep or scenario. Each ``plot_*`` has a ``*_figure``
twin that returns the matplotlib Figure unsaved (the tests inspect those).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Sequence
from pathlib import Path

import matplotlib

from cosim.errors import ConfigError

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.collections import LineCollection, PatchCollection  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch, Rectangle  # noqa: E402

from cosim.analysis.tables import FD_COLUMNS  # noqa: E402

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
#: A fundamental diagram whose every speed is at least this share of the free speed (the
#: highest run speed) holds only its free-flow branch, and says so on the figure.
FREE_FLOW_SHARE = 0.8
#: Resolution of the animated top view (GIF), dots per inch.
ANIMATION_DPI = 80
#: Segments beyond this many are thinned in time for the time-space diagram.
MAX_SEGMENTS = 400_000

Edges = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

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


def _top(frames: Sequence[pd.DataFrame], *cols: str) -> float:
    """Upper axis limit: 5 % above the largest finite value of ``cols`` (1 if none)."""
    vals = np.concatenate([np.asarray(f[c], dtype=float).ravel()
                           for f in frames for c in cols if c in f] or [np.zeros(0)])
    vals = vals[np.isfinite(vals)]
    return 1.05 * float(vals.max()) if len(vals) and vals.max() > 0 else 1.0


def _title(what: str, name: str | None) -> str:
    return f"{what}: {name}" if name else what


def fundamental_diagram_figure(
    runs: pd.DataFrame,
    series_cols: Sequence[str] = ("demand.cav_share", "controller.kind"),
    demand_col: str | None = None,
    intervals: pd.DataFrame | None = None,
    title: str | None = None,
):
    """The figure of :func:`plot_fundamental_diagram` (a matplotlib Figure, not saved)."""
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
        ax.set_xlim(0, _top(frames, "edie_density_vpkm"))
        ax.set_ylim(0, _top(frames, y))
    ax_q.legend(handles=handles, fontsize=8, loc="best", title="lines: mean over seeds",
                title_fontsize=8)
    only_free, v_free = free_flow_only(np.concatenate(speeds))
    if only_free:
        ax_q.text(0.98, 0.03,
                  "free-flow branch only: no congested point\n"
                  f"(every speed ≥ {FREE_FLOW_SHARE:.0%} of the free speed, {v_free:.1f} m/s)",
                  transform=ax_q.transAxes, ha="right", va="bottom", fontsize=8,
                  bbox={"facecolor": "white", "edgecolor": "0.6", "alpha": 0.9})
    fig.suptitle(_title("Fundamental diagram", title))
    fig.tight_layout()
    return fig


def stationary_mask(runs: pd.DataFrame) -> np.ndarray:
    """(R,) bool: runs accepted as stationary (column ``stationary``; all when absent).
    Non-stationary runs are drawn as hollow markers in every figure."""
    if "stationary" not in runs:
        return np.ones(len(runs), dtype=bool)
    return runs["stationary"].astype("boolean").fillna(False).to_numpy(bool)


def REJECTED_HANDLE() -> Line2D:  # noqa: N802 (a legend entry, built fresh per figure)
    """Legend entry of a rejected (non-stationary) point: a hollow grey marker."""
    return Line2D([], [], linestyle="", marker="o", markersize=5, markerfacecolor="none",
                  markeredgecolor="0.3", label="hollow: not stationary (drift >= 2 %)")


def plot_fundamental_diagram(
    runs: pd.DataFrame,
    out_path: str | Path,
    series_cols: Sequence[str] = ("demand.cav_share", "controller.kind"),
    demand_col: str | None = None,
    intervals: pd.DataFrame | None = None,
    title: str | None = None,
) -> Path:
    """Flow-density and speed-density diagrams, one curve per series; the PNG path.

    Args:
        runs: one row per run with ``edie_density_vpkm`` (veh/km), ``edie_flow_vph``
            (veh/h), ``space_mean_speed_mps`` (m/s), the series columns and the demand
            column (:func:`cosim.analysis.tables.fd_runs`).
        out_path: PNG file to write.
        series_cols: columns that define a curve (one colour and marker each).
        demand_col: the demand level; curves join the seed-means per level (in order of
            demand). Without it, the curve joins the runs sorted by density.
        intervals: per-interval points (:func:`cosim.analysis.tables.fd_intervals`), drawn
            as grey dots ("per interval" in the legend).
        title: the sweep's or scenario's name, in the figure title.

    A diagram whose speeds all stay above :data:`FREE_FLOW_SHARE` of the free speed says
    on the figure that it holds only the free-flow branch.
    """
    fig = fundamental_diagram_figure(runs, series_cols, demand_col, intervals, title)
    return _save(fig, out_path)


def capacity_figure(
    capacity: pd.DataFrame,
    series_cols: Sequence[str] = ("demand.cav_share", "controller.kind"),
    title: str | None = None,
):
    """The figure of :func:`plot_capacity` (a matplotlib Figure, not saved)."""
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
    ax.set_ylim(0, _top([capacity], "capacity_vph", "capacity_ci_high_vph"))
    ax.legend(fontsize=8)
    ax.set_title(f"{_title('Capacity', title)} (error bars: CI over seeds)", fontsize=10)
    fig.tight_layout()
    return fig


def plot_capacity(
    capacity: pd.DataFrame,
    out_path: str | Path,
    series_cols: Sequence[str] = ("demand.cav_share", "controller.kind"),
    title: str | None = None,
) -> Path:
    """Capacity (veh/h) vs CAV share (%), one line per remaining series key (colour and
    marker each), confidence-interval error bars; the PNG path."""
    return _save(capacity_figure(capacity, series_cols, title), out_path)


def _time_space_segments(tr: pd.DataFrame, period: float | None):
    """(segments (M, 2, 2) of (t s, s m), speed per segment m/s) of one vehicle class."""
    tr = tr.sort_values(["id", "t_s"], kind="stable")
    t = tr["t_s"].to_numpy(float)
    s = tr["s_m"].to_numpy(float)
    v = tr["v_mps"].to_numpy(float)
    ids = tr["id"].to_numpy()
    steps = np.unique(t)
    dt = float(np.median(np.diff(steps))) if len(steps) > 1 else 1.0
    span = period or (float(s.max() - s.min()) if len(s) else 1.0)
    same = (ids[1:] == ids[:-1]) & (np.diff(t) < 1.5 * dt) & (np.diff(s) > -0.5 * span)
    idx = np.flatnonzero(same)
    if len(idx) > MAX_SEGMENTS:
        idx = idx[:: int(math.ceil(len(idx) / MAX_SEGMENTS))]
    segs = np.stack([np.column_stack([t[idx], s[idx]]),
                     np.column_stack([t[idx + 1], s[idx + 1]])], axis=1)
    return segs, 0.5 * (v[idx] + v[idx + 1])


def time_space_figure(
    traj: pd.DataFrame | str | Path,
    period: float | None = None,
    title: str | None = None,
    vmax: float | None = None,
):
    """The figure of :func:`plot_time_space`: CAVs and HDVs in two panels."""
    tr = _read_traj(traj)
    t_all = tr["t_s"].to_numpy(float)
    s_all = tr["s_m"].to_numpy(float)
    v_all = tr["v_mps"].to_numpy(float)
    vmax = vmax or (float(np.nanmax(v_all)) if len(v_all) else 1.0)
    if "is_cav" in tr:
        cav = tr["is_cav"].astype(bool).to_numpy()
        classes = [("CAVs", CAV_COLOUR, tr[cav]), ("HDVs", HDV_COLOUR, tr[~cav])]
    else:
        classes = [("all vehicles", "k", tr)]
    fig, axes = plt.subplots(len(classes), 1, figsize=(10, 3.2 * len(classes) + 0.8),
                             sharex=True, sharey=True, squeeze=False, layout="constrained")
    lc = None
    for ax, (name, colour, part) in zip(axes[:, 0], classes, strict=True):
        n_veh = part["id"].nunique()
        if n_veh:
            segs, speed = _time_space_segments(part, period)
            lc = LineCollection(segs, cmap=speed_cmap(), linewidths=0.6, rasterized=True)
            lc.set_array(speed)
            lc.set_clim(0.0, vmax)
            ax.add_collection(lc)
        else:
            ax.text(0.5, 0.5, f"no {name} in this run", transform=ax.transAxes,
                    ha="center", va="center", color="0.4")
        ax.set_title(f"{name} ({n_veh} vehicles)", color=colour, fontsize=10, loc="left")
        ax.set_ylabel("position s, m")
        if len(t_all):
            ax.set_xlim(t_all.min(), t_all.max())
            ax.set_ylim(s_all.min(), s_all.max())
    axes[-1, 0].set_xlabel("time, s")
    fig.suptitle(title or "Time-space diagram")
    if lc is not None:
        fig.colorbar(lc, ax=list(axes[:, 0]), label="speed, m/s")
    return fig


def plot_time_space(
    traj: pd.DataFrame | str | Path,
    out_path: str | Path,
    period: float | None = None,
    title: str | None = None,
    vmax: float | None = None,
) -> Path:
    """Time-space diagram: every vehicle's ``s(t)`` as a line coloured by its speed, CAVs
    and HDVs in two panels on one speed scale; the PNG path.

    Args:
        traj: trajectories (``t_s, id, s_m, v_mps, is_cav``) or the path of trajectories.csv.
        period: ring circumference, m: lines break where ``s`` wraps (detected anyway
            as a backward jump of more than half the span).
        title: the figure title (name the scenario).
        vmax: top of the speed colour scale, m/s (default: the highest speed).
    """
    return _save(time_space_figure(traj, period, title, vmax), out_path)


def top_view_figure(
    traj: pd.DataFrame | str | Path,
    times: Sequence[float] | None = None,
    s_range: tuple[float, float] | None = None,
    edges: Edges | None = None,
    lane_lines: Sequence[float] = (),
    title: str | None = None,
    window_m: float = 300.0,
):
    """The figure of :func:`plot_top_view` (a matplotlib Figure, not saved)."""
    tr = _read_traj(traj)
    steps = np.unique(tr["t_s"].to_numpy(float))
    if len(steps) == 0:
        raise ValueError("trajectories are empty")
    if times is None:
        times = [steps[int(q * (len(steps) - 1))] for q in (0.25, 0.5, 0.75)]
    picks = [float(steps[np.abs(steps - tq).argmin()]) for tq in times]
    s_range, s_grid, (y_lo, y_hi) = _view_window(tr, picks[len(picks) // 2], s_range, edges,
                                                 window_m)
    fig, axes = plt.subplots(len(picks), 1, figsize=(12, 1.2 + 1.5 * len(picks)),
                             squeeze=False, sharex=True)
    for ax, tq in zip(axes[:, 0], picks, strict=True):
        _draw_road(ax, s_grid, edges, lane_lines, s_range, (y_lo, y_hi))
        _draw_vehicles(ax, tr[tr["t_s"] == tq], s_range)
        ax.text(0.005, 0.95, f"t = {tq:.1f} s", transform=ax.transAxes, va="top",
                fontsize=8, bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0})
    axes[-1, 0].set_xlabel("position s, m (lateral axis stretched)")
    axes[0, 0].legend(handles=_vehicle_handles(edges, lane_lines), loc="upper right",
                      fontsize=7, ncol=4)
    fig.suptitle(title or "Top view")
    fig.tight_layout()
    return fig


def plot_top_view(
    traj: pd.DataFrame | str | Path,
    out_path: str | Path,
    times: Sequence[float] | None = None,
    s_range: tuple[float, float] | None = None,
    edges: Edges | None = None,
    lane_lines: Sequence[float] = (),
    title: str | None = None,
    window_m: float = 300.0,
) -> Path:
    """The road from above at chosen times: vehicles as rectangles, road edges as lines.

    Args:
        traj: trajectories (``t_s, id, s_m, d_m, length_m, width_m, is_cav``) or a path.
        times: instants, s (the nearest recorded step is drawn); default 3 spread over
            the run.
        s_range: longitudinal window, m; default ``window_m`` around the median position
            of the vehicles at the middle time (or the whole road if shorter).
        edges: ``edges(s) -> (right, left)`` lateral road edges, m (None: not drawn).
        lane_lines: lateral positions of lane markings (three-lane baseline), m.
        title: the figure title (name the scenario).
    """
    fig = top_view_figure(traj, times, s_range, edges, lane_lines, title, window_m)
    return _save(fig, out_path)


def _vehicle_handles(edges: Edges | None, lane_lines: Sequence[float] = ()) -> list:
    handles = [Patch(color=CAV_COLOUR, label="CAV"), Patch(color=HDV_COLOUR, label="HDV")]
    if edges is not None:
        handles.append(Line2D([], [], color="k", label="road edge"))
    if len(lane_lines):
        handles.append(Line2D([], [], color="0.5", linestyle="--", linewidth=0.8,
                              label="lane line"))
    return handles


def _view_window(tr: pd.DataFrame, t_mid: float, s_range, edges: Edges | None,
                 window_m: float):
    """(s_range, s_grid, (y_lo, y_hi)) of a top view: ``window_m`` (m) around the median
    vehicle at ``t_mid`` (s), or the whole road if shorter; lateral limits from the road
    edges (or the vehicles)."""
    if s_range is None:
        mid = tr[tr["t_s"] == t_mid]
        lo_all, hi_all = float(tr["s_m"].min()), float(tr["s_m"].max())
        if hi_all - lo_all <= window_m:
            s_range = (lo_all - 5.0, hi_all + 5.0)
        else:
            c = float(mid["s_m"].median()) if len(mid) else 0.5 * (lo_all + hi_all)
            s_range = (c - window_m / 2, c + window_m / 2)
    s_grid = np.linspace(s_range[0], s_range[1], 400)
    if edges is not None:
        right, left = edges(s_grid)
        y_lims = (float(np.min(right)) - 1.0, float(np.max(left)) + 1.0)
    else:
        y_lims = (float((tr["d_m"] - tr["width_m"] / 2).min()) - 1.0,
                  float((tr["d_m"] + tr["width_m"] / 2).max()) + 1.0)
    return s_range, s_grid, y_lims


def _draw_road(ax, s_grid, edges: Edges | None, lane_lines, s_range, y_lims) -> None:
    if edges is not None:
        right, left = edges(s_grid)
        ax.plot(s_grid, right, color="k", linewidth=1.2)
        ax.plot(s_grid, left, color="k", linewidth=1.2)
    for y in lane_lines:
        ax.axhline(y, color="0.5", linestyle="--", linewidth=0.8)
    ax.set_xlim(*s_range)
    ax.set_ylim(*y_lims)
    ax.set_ylabel("lateral d, m")


def _draw_vehicles(ax, now: pd.DataFrame, s_range) -> PatchCollection:
    """Vehicles of one instant as rectangles (CAVs blue, HDVs orange); the collection."""
    now = now[now["s_m"].between(s_range[0] - 10, s_range[1] + 10)]
    rects = [Rectangle((r.s_m - r.length_m / 2, r.d_m - r.width_m / 2), r.length_m, r.width_m)
             for r in now.itertuples(index=False)]
    colours = np.where(now["is_cav"].to_numpy(bool), CAV_COLOUR, HDV_COLOUR)
    return ax.add_collection(PatchCollection(rects, facecolors=list(colours), edgecolors="k",
                                             linewidths=0.3))


def top_view_animation(
    traj: pd.DataFrame | str | Path,
    t_range: tuple[float, float] | None = None,
    every_s: float = 0.5,
    fps: int = 10,
    s_range: tuple[float, float] | None = None,
    edges: Edges | None = None,
    lane_lines: Sequence[float] = (),
    title: str | None = None,
    window_m: float = 300.0,
):
    """(Figure, FuncAnimation) of :func:`animate_top_view`, not saved."""
    from matplotlib.animation import FuncAnimation

    tr = _read_traj(traj)
    steps = np.unique(tr["t_s"].to_numpy(float))
    if len(steps) == 0:
        raise ValueError("trajectories are empty")
    if every_s <= 0 or fps <= 0:
        raise ValueError("every_s and fps must be > 0")
    if t_range is None:
        t_range = (max(float(steps[0]), float(steps[-1]) - 30.0), float(steps[-1]))
    wanted = np.arange(t_range[0], t_range[1] + 1e-9, every_s)
    k = np.clip(np.searchsorted(steps, wanted), 1, max(len(steps) - 1, 1))
    if len(steps) > 1:  # the nearer of the recorded steps either side
        k = np.where(np.abs(steps[k - 1] - wanted) <= np.abs(steps[k] - wanted), k - 1, k)
    else:
        k = np.zeros(len(wanted), dtype=int)
    frames = np.unique(steps[k])
    frames = frames[(frames >= t_range[0] - every_s) & (frames <= t_range[1] + every_s)]
    if len(frames) == 0:
        raise ValueError(f"no recorded step in t_range {t_range}")
    s_range, s_grid, y_lims = _view_window(tr, float(frames[len(frames) // 2]), s_range,
                                           edges, window_m)
    by_t = dict(tuple(tr.groupby("t_s")))
    fig, ax = plt.subplots(figsize=(12, 3.0))
    _draw_road(ax, s_grid, edges, lane_lines, s_range, y_lims)
    ax.set_xlabel("position s, m (lateral axis stretched)")
    ax.legend(handles=_vehicle_handles(edges, lane_lines), loc="upper right", fontsize=7,
              ncol=4)
    ax.set_title(title or "Top view")
    label = ax.text(0.005, 0.95, "", transform=ax.transAxes, va="top", fontsize=8,
                    bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0})
    fig.tight_layout()  # fixed once: every frame keeps the axis labels inside the picture
    drawn: list = []

    def update(t):
        for artist in drawn:
            artist.remove()
        drawn.clear()
        drawn.append(_draw_vehicles(ax, by_t.get(t, tr.iloc[:0]), s_range))
        label.set_text(f"t = {t:.1f} s")
        return [*drawn, label]

    return fig, FuncAnimation(fig, update, frames=list(frames), blit=False)


def animate_top_view(
    traj: pd.DataFrame | str | Path,
    out_path: str | Path,
    t_range: tuple[float, float] | None = None,
    every_s: float = 0.5,
    fps: int = 10,
    s_range: tuple[float, float] | None = None,
    edges: Edges | None = None,
    lane_lines: Sequence[float] = (),
    title: str | None = None,
    window_m: float = 300.0,
) -> Path:
    """Animated top view (GIF): the road window from above, one frame per ``every_s``.

    Args:
        traj: trajectories (as for :func:`plot_top_view`) or a path.
        t_range: (start, end) of the animation, s; default the last 30 s recorded.
        every_s: simulated time between frames, s (the nearest recorded steps).
        fps: frames per second of the GIF (real time at ``every_s * fps = 1``).
        s_range, edges, lane_lines, window_m: as for :func:`plot_top_view`.
    """
    from matplotlib.animation import PillowWriter

    fig, anim = top_view_animation(traj, t_range, every_s, fps, s_range, edges, lane_lines,
                                   title, window_m)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    anim.save(out, writer=PillowWriter(fps=fps), dpi=ANIMATION_DPI)
    plt.close(fig)
    return out


def road_geometry(network: dict) -> tuple[Edges | None, list[float], float | None]:
    """Road edges function, lane-line offsets and ring period from a ``[network]`` table.

    Straight, ring, on-ramp (main road) and three-lane roads: ``+-width_m/2``;
    varying width: piecewise from ``width_profile``; a user's ``file``: unknown (None).
    """
    kind = network.get("kind", "straight")
    width = float(network.get("width_m", 10.2))
    period = float(network.get("circumference_m", 0.0)) if kind == "ring" else None
    if kind == "file":
        return None, [], None
    if kind == "varying_width" and network.get("width_profile"):
        prof = np.asarray(network["width_profile"], dtype=float)
        ends = np.cumsum(prof[:, 0])
        widths = prof[:, 1]

        def edges(s):
            k = np.clip(np.searchsorted(ends, np.asarray(s, float)), 0, len(widths) - 1)
            return -widths[k] / 2, widths[k] / 2

        return edges, [], None

    def const(s):
        s = np.asarray(s, float)
        return np.full(s.shape, -width / 2), np.full(s.shape, width / 2)

    lanes = [-width / 2 + width / 3, width / 2 - width / 3] if kind == "three_lane" else []
    return const, lanes, period


def plot_run(
    run_dir: str | Path,
    out_dir: str | Path | None = None,
    times: Sequence[float] | None = None,
    prefix: str = "",
    animate: bool = False,
    t_range: tuple[float, float] | None = None,
) -> list[Path]:
    """Time-space diagram and top view of one run folder (needs trajectories.csv);
    with ``animate`` also ``top_view.gif`` over ``t_range`` (s; default the last 30 s).
    Titles name the scenario (config.toml) and the run folder."""
    run_dir = Path(run_dir)
    out = Path(out_dir) if out_dir is not None else run_dir / "figures"
    tr = _read_traj(run_dir / "trajectories.csv")
    _check_times(tr, times, t_range, run_dir)
    cfg = {}
    if (run_dir / "config.toml").is_file():
        cfg = tomllib.loads((run_dir / "config.toml").read_text())
    edges, lanes, period = road_geometry(cfg.get("network", {}))
    scenario = cfg.get("scenario", {}).get("name")
    name = f"{scenario} (run {run_dir.name})" if scenario else f"run {run_dir.name}"
    files = [
        plot_time_space(tr, out / f"{prefix}time_space.png", period=period,
                        title=f"Time-space diagram: {name}"),
        plot_top_view(tr, out / f"{prefix}top_view.png", times=times, edges=edges,
                      lane_lines=lanes, title=f"Top view: {name}"),
    ]
    if animate:
        files.append(animate_top_view(tr, out / f"{prefix}top_view.gif", t_range=t_range,
                                      edges=edges, lane_lines=lanes, title=f"Top view: {name}"))
    return files


def _read_traj(traj) -> pd.DataFrame:
    if isinstance(traj, pd.DataFrame):
        return traj
    path = Path(traj)
    if not path.is_file():
        raise FileNotFoundError(f"no trajectories file {path}")
    try:
        tr = pd.read_csv(path)
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError,
            OSError) as exc:
        raise ConfigError(f"{path}: unreadable trajectories: {exc}") from None
    missing = [c for c in ("t_s", "id", "s_m", "d_m") if c not in tr]
    if missing:
        raise ConfigError(f"{path}: not a trajectories table (no column {missing[0]!r})")
    return tr


def _check_times(tr: pd.DataFrame, times, t_range, run_dir: Path) -> None:
    """Requested instants (s) inside the recorded span, or one ``error:`` line."""
    if tr.empty:
        raise ConfigError(f"{run_dir}: trajectories.csv holds no rows")
    t_min, t_max = float(tr["t_s"].min()), float(tr["t_s"].max())
    asked = list(times or ()) + list(t_range or ())
    outside = [t for t in asked if not t_min - 1e-9 <= t <= t_max + 1e-9]
    if outside:
        raise ConfigError(f"time {outside[0]:g} s is outside the recorded span "
                          f"{t_min:g}-{t_max:g} s of {run_dir}")


def _save(fig, out_path: str | Path) -> Path:
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return out


# --------------------------------------------------------------------------------------
# Headline figures (cosim.analysis.headline)
# --------------------------------------------------------------------------------------


def headline_capacity_figure(bottleneck: pd.DataFrame, title: str | None = None):
    """The figure of :func:`plot_headline_capacity` (a matplotlib Figure, not saved)."""
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
    ax.set_xlim(0, _top([bottleneck], "capacity_vph", "ci_high_vph") * 1.1)
    ax.set_ylim(-0.7, len(bottleneck) - 0.3)
    ax.grid(alpha=0.3, axis="x")
    ax.legend(handles=[Line2D([], [], linestyle="", marker="o", color="0.3",
                              label="mean of the valid runs, CI over them"),
                       REJECTED_HANDLE()], fontsize=7, loc="lower right")
    ax.set_title(f"{_title('Capacity at a bottleneck', title)} (error bars: CI over seeds)",
                 fontsize=10)
    fig.tight_layout()
    return fig


def plot_headline_capacity(bottleneck: pd.DataFrame, out_path: str | Path,
                           title: str | None = None) -> Path:
    """Queue discharge (veh/h) per bottleneck arm with its confidence interval; arms
    without a valid run say why; hollow when a valid run is not stationary; the PNG path.

    Args:
        bottleneck: :func:`cosim.analysis.headline.bottleneck_table`.
    """
    return _save(headline_capacity_figure(bottleneck, title), out_path)


def headline_mixed_figure(tum: pd.DataFrame, runs: pd.DataFrame,
                          reference: dict[float, float] | None = None,
                          title: str | None = None):
    """The figure of :func:`plot_headline_mixed` (a matplotlib Figure, not saved)."""
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
    top = _top([tum, runs], "flow_vph", "ci_high_vph", "edie_flow_vph")
    ax.set_ylim(0, max(top, 1.05 * max(reference.values())) if reference else top)
    ax.grid(alpha=0.3)
    ax.set_title(_title("Mixed traffic on TUM's ring, 225 veh/km", title), fontsize=10)
    fig.tight_layout()
    return fig


def plot_headline_mixed(tum: pd.DataFrame, runs: pd.DataFrame, out_path: str | Path,
                        reference: dict[float, float] | None = None,
                        title: str | None = None) -> Path:
    """Flow (veh/h) on TUM's ring against the CAV share (%): every run (hollow when not
    stationary), the mean with its CI, and TUM's published flows (``reference``,
    veh/h by share); the PNG path.

    Args:
        tum: :func:`cosim.analysis.headline.tum_ring_table`; runs: the ring's run rows
            (``demand.cav_share``, ``edie_flow_vph``, ``stationary``).
    """
    return _save(headline_mixed_figure(tum, runs, reference, title), out_path)


#: Modes of the ring arms (cosim.analysis.headline) in a fixed style order.
RING_MODES = (("lanefree", "lane-free flocking"), ("fixed4", "4 fixed rows"),
              ("rows3", "3 fixed rows (lanes)"))


def headline_fd_figure(runs: pd.DataFrame, title: str | None = None,
                       reference: pd.DataFrame | None = None):
    """The figure of :func:`plot_headline_fd` (a matplotlib Figure, not saved)."""
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
        ax.set_xlim(0, _top([runs], "edie_density_vpkm"))
    axes[0, 0].set_ylabel("flow (Edie), veh/h")
    axes[0, 0].set_ylim(0, _top([runs] + ([reference] if reference is not None else []),
                                "edie_flow_vph"))
    handles, _ = axes[0, 0].get_legend_handles_labels()
    axes[0, 0].legend(handles=[*handles, REJECTED_HANDLE()], fontsize=7, loc="upper left")
    fig.suptitle(_title("Ring fundamental diagram, 100 % CAVs", title))
    fig.tight_layout()
    return fig


def plot_headline_fd(runs: pd.DataFrame, out_path: str | Path, title: str | None = None,
                     reference: pd.DataFrame | None = None) -> Path:
    """Flow-density of the ring arms, one panel per time gap, one colour per mode (lane-free,
    4 fixed rows, 3 fixed rows): every run (hollow when not stationary) and the mode's line
    through its density means from the origin; the PNG path.

    Args:
        runs: run rows with ``mode``, ``time_gap_s``, ``demand_level``,
            ``edie_density_vpkm``, ``edie_flow_vph``, ``stationary``.
        reference: runs drawn as black crosses in the first panel (e.g. the lane-free
            CAVs of TUM's ring in the SUMO world).
    """
    return _save(headline_fd_figure(runs, title, reference), out_path)


def headline_gain_figure(gain: pd.DataFrame, title: str | None = None):
    """The figure of :func:`plot_headline_gain` (a matplotlib Figure, not saved)."""
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
    axes[0, 0].set_ylim(0, _top([gain], *(c for c, _ in names)))
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(_title("Lane-free gain at equal time gap (100 % CAVs, ring)", title))
    fig.tight_layout()
    return fig


def plot_headline_gain(gain: pd.DataFrame, out_path: str | Path, title: str | None = None
                       ) -> Path:
    """Flow (veh/h) against the time gap (s) of the same law lane-free, in 4 fixed rows
    and in 3 fixed rows, one panel per ring density; the PNG path.

    Args:
        gain: :func:`cosim.analysis.headline.lanefree_gain_table`.
    """
    return _save(headline_gain_figure(gain, title), out_path)
