"""PNG figures (matplotlib, Agg backend): fundamental diagrams, capacity, time-space, top view.

* :func:`plot_fundamental_diagram`: flow vs density and speed vs density, one curve per
  series (CAV share x controller, ...): the seed-mean per demand level, with every run
  and (faint) every measurement interval as points.
* :func:`plot_capacity`: capacity vs CAV share, one line per controller/variant, with
  the confidence interval as error bars.
* :func:`plot_time_space`: trajectories ``s(t)`` coloured by speed (from a run's
  ``trajectories.csv``: columns ``t_s, id, s_m, d_m, v_mps, is_cav``).
* :func:`plot_top_view`: the road seen from above at chosen times: vehicles as
  rectangles (``length_m x width_m`` at ``(s_m, d_m)``), CAVs and HDVs coloured, road
  edges (and lane lines of the three-lane baseline) drawn.
* :func:`plot_run`: both run figures for a run folder (road geometry from config.toml).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.collections import LineCollection, PatchCollection  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch, Rectangle  # noqa: E402

CAV_COLOUR = "tab:blue"
HDV_COLOUR = "tab:orange"
LINESTYLES = ("-", "--", ":", "-.")
MARKERS = ("o", "s", "^", "D", "v", "P", "X")
#: Segments beyond this many are thinned in time for the time-space diagram.
MAX_SEGMENTS = 400_000

Edges = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

_LABELS = {
    "demand.cav_share": "CAV",
    "controller.kind": "",
    "variant": "",
    "network.kind": "",
}


def series_label(keys: Sequence[str], values: Sequence) -> str:
    """'CAV 50% flocking' style label of a series."""
    parts = []
    for k, v in zip(keys, values, strict=True):
        if v is None or (isinstance(v, float) and math.isnan(v)):
            continue
        if k == "demand.cav_share":
            parts.append(f"CAV {float(v):.0%}")
        elif k in _LABELS:
            parts.append(str(v))
        else:
            short = k.split(".")[-1]
            parts.append(f"{short}={v:g}" if isinstance(v, float) else f"{short}={v}")
    return " ".join(parts) or "all runs"


def _styles(frame: pd.DataFrame, series_cols: list[str]):
    """Colour by CAV share (viridis), line style and marker by the rest of the series."""
    cmap = plt.get_cmap("viridis")
    rest = [c for c in series_cols if c != "demand.cav_share"]
    rest_keys = (
        list(dict.fromkeys(map(tuple, frame[rest].astype(str).to_numpy()))) if rest else [()]
    )
    shares = (sorted(frame["demand.cav_share"].dropna().unique())
              if "demand.cav_share" in series_cols else [])

    def style(row_keys: dict) -> dict:
        if "demand.cav_share" in row_keys and len(shares) > 0:
            share = float(row_keys["demand.cav_share"])
            colour = cmap(0.85 * share) if len(shares) > 1 else cmap(0.3)
        else:
            colour = None
        k = rest_keys.index(tuple(str(row_keys[c]) for c in rest)) if rest else 0
        if colour is None:
            colour = plt.get_cmap("tab10")(k % 10)
        return {"color": colour, "linestyle": LINESTYLES[k % len(LINESTYLES)],
                "marker": MARKERS[k % len(MARKERS)]}

    return style


def _groups(frame: pd.DataFrame, cols: list[str]):
    if not cols:
        yield {}, frame
        return
    for key, g in frame.groupby(cols, dropna=False, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        yield dict(zip(cols, key, strict=True)), g


def plot_fundamental_diagram(
    runs: pd.DataFrame,
    out_path: str | Path,
    series_cols: Sequence[str] = ("demand.cav_share", "controller.kind"),
    demand_col: str | None = None,
    intervals: pd.DataFrame | None = None,
    title: str | None = None,
) -> Path:
    """Flow-density and speed-density diagrams, one curve per series.

    Args:
        runs: one row per run with ``edie_density_vpkm``, ``edie_flow_vph``,
            ``space_mean_speed_mps``, the series columns and the demand column
            (:func:`cosim.analysis.analysis.fd_runs`).
        out_path: PNG file to write.
        series_cols: columns that define a curve.
        demand_col: the demand level; curves join the seed-means per level (in order of
            demand). Without it, the curve joins the runs sorted by density.
        intervals: per-interval points (:func:`cosim.analysis.analysis.fd_intervals`), drawn faint.
    """
    series_cols = [c for c in series_cols if c in runs]
    style = _styles(runs, series_cols)
    fig, (ax_q, ax_v) = plt.subplots(1, 2, figsize=(12, 4.8))
    for keys, g in _groups(runs, series_cols):
        st = style(keys)
        label = series_label(list(keys), list(keys.values()))
        if intervals is not None and len(intervals):
            sel = intervals
            for c, v in keys.items():
                sel = sel[(sel[c] == v) | (sel[c].isna() & pd.isna(v))]
            ax_q.scatter(sel["edie_density_vpkm"], sel["edie_flow_vph"], s=6, alpha=0.15,
                         color=st["color"], linewidths=0)
            ax_v.scatter(sel["edie_density_vpkm"], sel["space_mean_speed_mps"], s=6,
                         alpha=0.15, color=st["color"], linewidths=0)
        ax_q.scatter(g["edie_density_vpkm"], g["edie_flow_vph"], s=14, alpha=0.5,
                     color=st["color"], marker=st["marker"], linewidths=0)
        ax_v.scatter(g["edie_density_vpkm"], g["space_mean_speed_mps"], s=14, alpha=0.5,
                     color=st["color"], marker=st["marker"], linewidths=0)
        if demand_col and demand_col in g:
            curve = g.groupby(demand_col)[
                ["edie_density_vpkm", "edie_flow_vph", "space_mean_speed_mps"]].mean()
        else:
            curve = g.sort_values("edie_density_vpkm")
        ax_q.plot(curve["edie_density_vpkm"], curve["edie_flow_vph"], color=st["color"],
                  linestyle=st["linestyle"], marker=st["marker"], markersize=4, label=label)
        ax_v.plot(curve["edie_density_vpkm"], curve["space_mean_speed_mps"],
                  color=st["color"], linestyle=st["linestyle"], marker=st["marker"],
                  markersize=4, label=label)
    ax_q.set_xlabel("density (Edie), veh/km")
    ax_q.set_ylabel("flow (Edie), veh/h")
    ax_v.set_xlabel("density (Edie), veh/km")
    ax_v.set_ylabel("space-mean speed, m/s")
    for ax in (ax_q, ax_v):
        ax.grid(alpha=0.3)
        ax.set_xlim(left=0)
        ax.set_ylim(bottom=0)
    ax_q.legend(fontsize=8, loc="best")
    fig.suptitle(f"Fundamental diagram{': ' + title if title else ''}")
    return _save(fig, out_path)


def plot_capacity(
    capacity: pd.DataFrame,
    out_path: str | Path,
    series_cols: Sequence[str] = ("demand.cav_share", "controller.kind"),
    title: str | None = None,
) -> Path:
    """Capacity (veh/h) vs CAV share, one line per remaining series key, CI error bars."""
    rest = [c for c in series_cols if c in capacity and c != "demand.cav_share"]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, (keys, g) in enumerate(_groups(capacity, rest)):
        g = g.sort_values("demand.cav_share")
        y = g["capacity_vph"].to_numpy(float)
        lo = g.get("capacity_ci_low_vph", pd.Series(np.nan, index=g.index)).to_numpy(float)
        err = np.where(np.isfinite(lo), y - lo, 0.0)
        ax.errorbar(100 * g["demand.cav_share"].to_numpy(float), y, yerr=err, capsize=3,
                    marker=MARKERS[k % len(MARKERS)], linestyle=LINESTYLES[k % 4],
                    label=series_label(list(keys), list(keys.values())) if keys else None)
    ax.set_xlabel("CAV share, %")
    ax.set_ylabel("capacity (max mean flow), veh/h")
    ax.grid(alpha=0.3)
    ax.set_ylim(bottom=0)
    if rest:
        ax.legend(fontsize=8)
    ax.set_title(f"Capacity{': ' + title if title else ''} (error bars: CI over seeds)",
                 fontsize=10)
    return _save(fig, out_path)


def plot_time_space(
    traj: pd.DataFrame | str | Path,
    out_path: str | Path,
    period: float | None = None,
    title: str | None = None,
    vmax: float | None = None,
) -> Path:
    """Time-space diagram: every vehicle's ``s(t)`` as a line coloured by its speed.

    Args:
        traj: trajectories (``t_s, id, s_m, v_mps``) or the path of trajectories.csv.
        period: ring circumference, m: lines break where ``s`` wraps (detected anyway
            as a backward jump of more than half the span).
    """
    tr = _read_traj(traj)
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
    fig, ax = plt.subplots(figsize=(10, 6))
    lc = LineCollection(segs, cmap="RdYlGn", linewidths=0.6, rasterized=True)
    lc.set_array(0.5 * (v[idx] + v[idx + 1]))
    lc.set_clim(0.0, vmax or (float(np.nanmax(v)) if len(v) else 1.0))
    ax.add_collection(lc)
    if len(t):
        ax.set_xlim(t.min(), t.max())
        ax.set_ylim(s.min(), s.max())
    ax.set_xlabel("time, s")
    ax.set_ylabel("position along the road s, m")
    fig.colorbar(lc, ax=ax, label="speed, m/s")
    ax.set_title(title or "Time-space diagram")
    return _save(fig, out_path)


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
    """
    tr = _read_traj(traj)
    steps = np.unique(tr["t_s"].to_numpy(float))
    if len(steps) == 0:
        raise ValueError("trajectories are empty")
    if times is None:
        times = [steps[int(q * (len(steps) - 1))] for q in (0.25, 0.5, 0.75)]
    picks = [float(steps[np.abs(steps - tq).argmin()]) for tq in times]
    s_range, s_grid, (y_lo, y_hi) = _view_window(tr, picks[len(picks) // 2], s_range, edges,
                                                 window_m)
    fig, axes = plt.subplots(len(picks), 1, figsize=(12, 0.9 + 1.5 * len(picks)),
                             squeeze=False)
    for ax, tq in zip(axes[:, 0], picks, strict=True):
        _draw_road(ax, s_grid, edges, lane_lines, s_range, (y_lo, y_hi))
        _draw_vehicles(ax, tr[tr["t_s"] == tq], s_range)
        ax.text(0.005, 0.95, f"t = {tq:.1f} s", transform=ax.transAxes, va="top",
                fontsize=8, bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0})
    axes[-1, 0].set_xlabel("s, m (lateral axis stretched)")
    handles = [Patch(color=CAV_COLOUR, label="CAV"), Patch(color=HDV_COLOUR, label="HDV")]
    if edges is not None:
        handles.append(Line2D([], [], color="k", label="road edge"))
    axes[0, 0].legend(handles=handles, loc="upper right", fontsize=7, ncol=3)
    fig.suptitle(title or "Top view")
    return _save(fig, out_path)


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
    ax.set_ylabel("d, m")


def _draw_vehicles(ax, now: pd.DataFrame, s_range) -> PatchCollection:
    """Vehicles of one instant as rectangles (CAVs blue, HDVs orange); the collection."""
    now = now[now["s_m"].between(s_range[0] - 10, s_range[1] + 10)]
    rects = [Rectangle((r.s_m - r.length_m / 2, r.d_m - r.width_m / 2), r.length_m, r.width_m)
             for r in now.itertuples(index=False)]
    colours = np.where(now["is_cav"].to_numpy(bool), CAV_COLOUR, HDV_COLOUR)
    return ax.add_collection(PatchCollection(rects, facecolors=list(colours), edgecolors="k",
                                             linewidths=0.3))


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
    from matplotlib.animation import FuncAnimation, PillowWriter

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
    fig, ax = plt.subplots(figsize=(12, 2.4))
    _draw_road(ax, s_grid, edges, lane_lines, s_range, y_lims)
    ax.set_xlabel("s, m (lateral axis stretched)")
    handles = [Patch(color=CAV_COLOUR, label="CAV"), Patch(color=HDV_COLOUR, label="HDV")]
    ax.legend(handles=handles, loc="upper right", fontsize=7, ncol=2)
    ax.set_title(title or "Top view")
    label = ax.text(0.005, 0.95, "", transform=ax.transAxes, va="top", fontsize=8,
                    bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0})
    drawn: list = []

    def update(t):
        for artist in drawn:
            artist.remove()
        drawn.clear()
        drawn.append(_draw_vehicles(ax, by_t.get(t, tr.iloc[:0]), s_range))
        label.set_text(f"t = {t:.1f} s")
        return [*drawn, label]

    anim = FuncAnimation(fig, update, frames=list(frames), blit=False)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    anim.save(out, writer=PillowWriter(fps=fps), dpi=80)
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
    with ``animate`` also ``top_view.gif`` over ``t_range`` (s; default the last 30 s)."""
    run_dir = Path(run_dir)
    out = Path(out_dir) if out_dir is not None else run_dir / "figures"
    tr = _read_traj(run_dir / "trajectories.csv")
    network = {}
    if (run_dir / "config.toml").is_file():
        network = tomllib.loads((run_dir / "config.toml").read_text()).get("network", {})
    edges, lanes, period = road_geometry(network)
    name = run_dir.name
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
    return pd.read_csv(path)


def _save(fig, out_path: str | Path) -> Path:
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return out
