"""Figures (matplotlib, Agg backend, PNG)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def plot_plane_result(res, out_dir: str | Path) -> list[Path]:
    """Top view of a plane-world run (trajectories, obstacles) and its minimum distances."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tr = res.trajectories
    paths = []
    fig, ax = plt.subplots(figsize=(10, 4))
    for _, g in tr.groupby("agent"):
        ax.plot(g["x_m"], g["y_m"], lw=0.6)
    last = tr[tr["t_s"] == tr["t_s"].max()]
    ax.scatter(last["x_m"], last["y_m"], marker=">", color="k", s=15, zorder=3, label="agents")
    if len(res.leader):
        ax.plot(res.leader["qx_m"], res.leader["qy_m"], "g--", lw=1, label="virtual leader")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(str(res.meta.get("scenario", "")))
    p = out / "trajectories.png"
    fig.savefig(p, dpi=120, bbox_inches="tight")
    plt.close(fig)
    paths.append(p)
    m = res.metrics
    fig, ax = plt.subplots(figsize=(6, 3))
    ax.plot(m["t_s"], m["min_agent_distance_m"], label="min agent distance")
    if m["min_obstacle_distance_m"].replace([float("inf")], float("nan")).notna().any():
        ax.plot(m["t_s"], m["min_obstacle_distance_m"], label="min obstacle distance")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("distance (m)")
    ax.legend(fontsize=8)
    p = out / "min_distance.png"
    fig.savefig(p, dpi=120, bbox_inches="tight")
    plt.close(fig)
    paths.append(p)
    return paths
