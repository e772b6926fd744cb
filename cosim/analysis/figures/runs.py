"""Figures of one run, from its ``trajectories.csv`` (``t_s, id, s_m, d_m, v_mps, is_cav``,
``length_m, width_m``): time-space diagram, top view (still and animated), a run folder's set.

* :func:`time_space_figure`: trajectories ``s(t)`` coloured by speed, CAVs and HDVs in
  two panels.
* :func:`top_view_figure`: the road seen from above at chosen times: vehicles as
  rectangles (``length_m x width_m`` at ``(s_m, d_m)``), CAVs and HDVs coloured, road
  edges (and lane lines of the three-lane baseline) drawn; :func:`top_view_animation`
  the same animated, written as a GIF by :func:`animate_top_view`.
* :func:`road_geometry`: road edges, lane lines and ring period from a ``[network]`` table.
* :func:`n_curves_figure`: cumulative counts at an on-ramp's merge and an off-ramp, from
  ``trips.csv``.
* :func:`plot_run`: the run figures of a run folder (road geometry and scenario name
  from config.toml), written with :func:`cosim.analysis.figures.output.save`.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Sequence
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle

from cosim.analysis.figures.output import save
from cosim.analysis.figures.style import CAV_COLOUR, HDV_COLOUR, speed_cmap
from cosim.demand.od_names import destination_number, origin_number
from cosim.errors import ConfigError

#: Resolution of the animated top view (GIF), dots per inch.
ANIMATION_DPI = 80
#: Segments beyond this many are thinned in time for the time-space diagram.
MAX_SEGMENTS = 400_000

Edges = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


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
    """Time-space diagram: every vehicle's ``s(t)`` as a line coloured by its speed, CAVs
    and HDVs in two panels on one speed scale (a matplotlib Figure, not saved).

    Args:
        traj: trajectories (``t_s, id, s_m, v_mps, is_cav``) or the path of trajectories.csv.
        period: ring circumference, m: lines break where ``s`` wraps (detected anyway
            as a backward jump of more than half the span).
        title: the figure title (name the scenario).
        vmax: top of the speed colour scale, m/s (default: the highest speed).
    """
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


def top_view_figure(
    traj: pd.DataFrame | str | Path,
    times: Sequence[float] | None = None,
    s_range: tuple[float, float] | None = None,
    edges: Edges | None = None,
    lane_lines: Sequence[float] = (),
    title: str | None = None,
    window_m: float = 300.0,
):
    """The road from above at chosen times: vehicles as rectangles, road edges as lines
    (a matplotlib Figure, not saved).

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
        traj: trajectories (as for :func:`top_view_figure`) or a path.
        t_range: (start, end) of the animation, s; default the last 30 s recorded.
        every_s: simulated time between frames, s (the nearest recorded steps).
        fps: frames per second of the GIF (real time at ``every_s * fps = 1``).
        s_range, edges, lane_lines, window_m: as for :func:`top_view_figure`.
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
    varying width: piecewise from ``width_profile``; the corridor: with its ramp strips;
    a user's ``file``: unknown (None).
    """
    kind = network.get("kind", "straight")
    width = float(network.get("width_m", 10.2))
    period = float(network.get("circumference_m", 0.0)) if kind == "ring" else None
    if kind == "file":
        return None, [], None
    if kind == "corridor":
        return _corridor_edges(network, width)
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


def _corridor_edges(network: dict, width: float):
    """Edges and lane lines of the corridor (:func:`road_geometry`): the 10.2 m road and its
    ramp strips on the right (their border with the road drawn as a lane line)."""
    strip = float(network.get("ramp_width_m", 3.0))
    merge = float(network.get("merge_position_m", 1000.0))
    acc = float(network.get("acceleration_lane_m", 482.0))
    gore = float(network.get("diverge_position_m", 2500.0))
    dec = float(network.get("deceleration_lane_m", 342.0))
    lanes = int(network.get("lanes", 1))

    def edges(s):
        s = np.asarray(s, float)
        on = ((s >= merge) & (s <= merge + acc)) | ((s >= gore - dec) & (s <= gore))
        return np.where(on, -width / 2 - strip, -width / 2), np.full(s.shape, width / 2)

    lines = [-width / 2 + width * k / lanes for k in range(1, lanes)] + [-width / 2]
    return edges, lines, None


def n_curves_figure(trips: pd.DataFrame | str | Path, title: str | None = None):
    """Cumulative counts (N-curves; Cassidy & Bertini 1999) of a run's trips (``trips.csv``):
    at each on-ramp's merge, its vehicles departing and joining the road; at each off-ramp,
    the vehicles bound for it departing and leaving the road, CAVs and human drivers
    apart (the vertical distance is the number between, the horizontal one the time taken
    by the vehicle of that rank). A matplotlib Figure, not saved."""
    tr = pd.read_csv(trips) if isinstance(trips, str | Path) else trips
    ramps = sorted(set(tr["origin"]) - {"main"}, key=origin_number)
    offs = sorted(set(tr["destination"]) - {"main"}, key=destination_number)
    panels = ([(f"on-ramp merge ({o})", tr["origin"] == o, "merge_s", "joined the road")
               for o in ramps]
              + [(f"off-ramp ({d})", tr["destination"] == d, "exit_s", "left by an off-ramp")
                 for d in offs]) or [("no ramp", tr["origin"] == "", "merge_s", "")]
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 4), squeeze=False)
    axes = axes[0]
    for ax, (name, sel, col, label) in zip(axes, panels, strict=True):
        for kind, colour in (("cav", CAV_COLOUR), ("hdv", HDV_COLOUR)):
            g = tr[sel & (tr["kind"] == kind)]
            for times, style, what in ((g["depart_s"], ":", "departed"), (g[col], "-", label)):
                t = np.sort(pd.to_numeric(times, errors="coerce").dropna().to_numpy(float))
                if len(t):
                    ax.step(t, np.arange(1, len(t) + 1), where="post", color=colour,
                            linestyle=style, label=f"{kind.upper()}s {what}")
        ax.set_title(name)
        ax.set_xlabel("time t, s")
        ax.set_ylabel("cumulative count N, veh")
        ax.legend(fontsize=7)
    fig.suptitle(title or "N-curves")
    fig.tight_layout()
    return fig


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
        save(time_space_figure(tr, period=period, title=f"Time-space diagram: {name}"),
             out / f"{prefix}time_space.png"),
        save(top_view_figure(tr, times=times, edges=edges, lane_lines=lanes,
                             title=f"Top view: {name}"),
             out / f"{prefix}top_view.png"),
    ]
    if (run_dir / "trips.csv").is_file():
        files.append(save(n_curves_figure(run_dir / "trips.csv", title=f"N-curves: {name}"),
                          out / f"{prefix}n_curves.png"))
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
