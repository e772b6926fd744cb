"""Figures of plane-world runs (matplotlib, Agg backend, PNG)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

OBSTACLE_COLOUR = "#d55e00"  # vermilion (Okabe-Ito), colour-blind safe against the agents
EDGE_COLOUR = "#000000"
LEADER_COLOUR = "#009e73"  # bluish green (Okabe-Ito)


def _title(res, what: str) -> str:
    """``"<scenario> (seed S, T s): <what>"`` from the result's meta."""
    meta = res.meta
    details = []
    if "seed" in meta:
        details.append(f"seed {meta['seed']}")
    if meta.get("duration_s") is not None:
        details.append(f"{float(meta['duration_s']):g} s")
    name = str(meta.get("scenario", "plane world"))
    return f"{name} ({', '.join(details)}): {what}" if details else f"{name}: {what}"


def _clip_line(point: np.ndarray, direction: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Segment (2, 2) of the line ``point + s direction`` inside the box [lo, hi], or None."""
    s_lo, s_hi = -np.inf, np.inf
    for k in range(2):
        if abs(direction[k]) < 1e-12:
            if not lo[k] <= point[k] <= hi[k]:
                return None
            continue
        a, b = sorted(((lo[k] - point[k]) / direction[k], (hi[k] - point[k]) / direction[k]))
        s_lo, s_hi = max(s_lo, a), min(s_hi, b)
    if not s_lo < s_hi:
        return None
    return np.array([point + s_lo * direction, point + s_hi * direction])


def _draw_obstacles(ax, obstacles: dict, lo: np.ndarray, hi: np.ndarray) -> None:
    """Circles as filled discs; walls and road edges as lines across the box [lo, hi], m."""
    circles = obstacles.get("circles")
    if circles:
        for k, (c, r) in enumerate(zip(circles["centres_m"], circles["radii_m"], strict=True)):
            ax.add_patch(
                Circle(
                    (c[0], c[1]),
                    r,
                    facecolor=OBSTACLE_COLOUR,
                    edgecolor=OBSTACLE_COLOUR,
                    alpha=0.35,
                    hatch="//",
                    label="obstacle" if k == 0 else None,
                )
            )
    lines = []
    walls = obstacles.get("walls")
    if walls:
        for y, a in zip(walls["points_m"], walls["normals"], strict=True):
            lines.append((np.asarray(y[:2], dtype=float), np.array([-a[1], a[0]], dtype=float)))
    edges = obstacles.get("road_edges_m")
    if edges:
        for e in edges:
            lines.append((np.array([0.0, float(e)]), np.array([1.0, 0.0])))
    labelled = False
    for point, direction in lines:
        seg = _clip_line(point, direction, lo, hi)
        if seg is None:
            continue
        ax.plot(
            seg[:, 0],
            seg[:, 1],
            color=EDGE_COLOUR,
            lw=1.5,
            label=None if labelled else "road edge / wall",
        )
        labelled = True


def trajectory_figure(res) -> Figure:
    """Top view: each agent's path, final positions, the virtual leader and the obstacles.

    ``res`` is a :class:`~cosim.plane.world.PlaneResult` with x_m, y_m columns; obstacles
    come from ``res.meta["obstacles"]`` (see ``cosim.plane.scenarios.obstacles_meta``):
    circles as filled discs, walls and constant road edges as lines across the drawn area.
    """
    tr = res.trajectories
    fig, ax = plt.subplots(figsize=(10, 4))
    for _, g in tr.groupby("agent"):
        ax.plot(g["x_m"], g["y_m"], lw=0.6)
    last = tr[tr["t_s"] == tr["t_s"].max()]
    ax.scatter(last["x_m"], last["y_m"], marker=">", color="k", s=15, zorder=3, label="agents")
    xs, ys = [tr["x_m"].to_numpy()], [tr["y_m"].to_numpy()]
    if len(res.leader):
        lq = res.leader
        ax.plot(lq["qx_m"], lq["qy_m"], "--", color=LEADER_COLOUR, lw=1, label="virtual leader")
        xs.append(res.leader["qx_m"].to_numpy())
        ys.append(res.leader["qy_m"].to_numpy())
    obstacles = res.meta.get("obstacles") or {}
    circles = obstacles.get("circles") or {"centres_m": [], "radii_m": []}
    for c, r in zip(circles["centres_m"], circles["radii_m"], strict=True):
        xs.append(np.array([c[0] - r, c[0] + r]))
        ys.append(np.array([c[1] - r, c[1] + r]))
    x, y = np.concatenate(xs), np.concatenate(ys)
    lo, hi = np.array([x.min(), y.min()]), np.array([x.max(), y.max()])
    margin = np.maximum(5.0, 0.1 * (hi - lo))  # m: walls this close to the data are drawn
    _draw_obstacles(ax, obstacles, lo - margin, hi + margin)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="box")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_title(_title(res, "trajectories"))
    return fig


def distance_figure(res) -> Figure:
    """Minimum distance between agents and to the obstacles (m) against time (s)."""
    m = res.metrics
    fig, ax = plt.subplots(figsize=(6, 3))
    ax.plot(m["t_s"], m["min_agent_distance_m"], label="min agent distance")
    if m["min_obstacle_distance_m"].replace([float("inf")], float("nan")).notna().any():
        ax.plot(m["t_s"], m["min_obstacle_distance_m"], "--", label="min obstacle distance")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("distance (m)")
    ax.legend(fontsize=8)
    ax.set_title(_title(res, "minimum distances"))
    return fig


def plot_plane_result(res, out_dir: str | Path) -> list[Path]:
    """Write trajectories.png and min_distance.png into ``out_dir``; return their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    figures = ((trajectory_figure, "trajectories.png"), (distance_figure, "min_distance.png"))
    for make, name in figures:
        fig = make(res)
        p = out / name
        fig.savefig(p, dpi=120, bbox_inches="tight")
        plt.close(fig)
        paths.append(p)
    return paths
