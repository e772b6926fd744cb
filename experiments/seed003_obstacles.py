"""Seed 003: boundary-point flocking against Olfati-Saber Algorithm 3 in the paper's scenes.

Usage::

    python experiments/seed003_obstacles.py [--smoke] [--out DIR] [--runs N]
        [--variant-runs M] [--jobs J] [--duration S] [--replot]

Scenes (gamma-agent static; Table 3 parameters; dt = 0.1 s; 300 s; speed
saturation ``sat(p, 5 m/s)`` of eq. 2 and a semi-implicit step for every law):

* ``independent`` (paper Fig. 5/6): 30 agents from [10, 30] x [5, 20] m with
  velocities from [0, 2]^2 m/s, gamma at (75, 80); two circles on the way and
  a straight (infinite) wall alongside, each bypassed on its own.
* ``two_circles`` (Fig. 7): two overlapping circles whose notch faces the
  flock, on the straight line to the gamma-agent.
* ``circle_wall`` (Fig. 8): a circle (R = 11 m) touching a wall that runs
  parallel to the start-goal line 18 m to its left; the line to the goal
  meets the circle on the wall's side of its centre, so agents pulled towards
  the goal slide into the wedge.
* ``multi_N`` (Fig. 9/10), N = 30, 40, 50, 60: from [2, 30] x [5, 30] to
  gamma at (75, 25) past a diamond, a circle and a C shape whose mouth faces
  the flock.

The paper does not give its obstacle geometry; ours follows the figure
descriptions, with the gamma-agent out of a settled flock's sensing range of
the obstacles (agents that sense boundary points near the gamma-agent are
pulled at full speed by the expected velocity and never come to rest).

Laws (``CONTROLLERS``): ``proposed`` (the paper's law, eq. 19 linear gamma)
and ``os`` (``cosim``'s :class:`OlfatiSaberController`, sigma_1 gamma of
eq. 11 as in OS06, Table 3 but obstacle gains 10, see :func:`os_params`) run
on every scene with ``--runs`` random starts (100). The variants run on the
30-agent scenes with ``--variant-runs`` starts (30): ``proposed_sigma1``
(eq. 11 gamma), ``proposed_paper`` (without our side vote and follow
timeout), ``os_table3`` (obstacle gains 1), ``os_linear_dw`` (linear gamma
and seed 000's dynamic weights). Olfati-Saber gets circles and infinite walls
exactly, polygons (diamond, C) as chains of 0.5 m discs along their outline
(OS06 has no other shapes).

Initial positions are drawn uniformly and redrawn until every pair of agents
is at least ``d_min`` = 1 m apart and every agent at least ``d_min`` from the
obstacles (the paper's claim "min distance > d_min" needs a start that
satisfies it; pairs may still start inside each other's separation region
``d_e`` = 2 m, so minima are also reported from t = 1 s on). Runs stop early
once the flock is at rest (see :func:`simulate`); nothing changes after that.

Outputs in ``--out`` (default ``outputs/seed003``):

* ``runs.csv``: one row per (scene, law, seed): minimum distance between
  agents ``min_agent_m`` (and from t = 1 s, ``min_agent_after_1s_m``), to
  boundary points ``min_point_m`` (the paper's beta-agents, 0.5 m spacing),
  to the exact obstacle outline ``min_obstacle_m`` (negative: inside); times
  in s: ``t_pass_s`` (flock centre beyond the far side of the last finite
  obstacle along the start-to-goal axis), ``t_conv_s`` (flock centre within
  3 m of the gamma-agent, staying there), ``t_arrive_s`` (every agent within
  1.5 x the radius of a settled flock of N agents, plus d); NaN: never within
  the run; ``n_not_arrived`` at the end; ``wall_s`` (compute time);
* ``summary.csv``: per scene and law: min / 5 % / median of the run minima,
  the share of runs with a distance <= d_min (whole run and from 1 s), median
  times (inf: most runs never), share of runs converged;
* ``speedup.csv``: median times of a law vs a baseline and the reduction
  ``1 - t / t_baseline`` (the paper claims > 80 %); ``reduction_bound``
  counts runs that never get there as the full duration;
* seed 0 with trajectories: ``<scene>_trajectories.png`` (Fig. 5/7/8/9),
  ``<scene>_centre.png`` (Fig. 5 c/d), ``<scene>_min_distance.png`` (Fig. 6),
  ``timeseries_<scene>_<law>.csv`` (columns ``COLUMNS``, SI units in names);
  over all runs ``min_distance_runs.png`` (Fig. 10) and ``times.png``.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from controllers.layers.constraints import ConstrainedController, SpeedSaturation  # noqa: E402
from controllers.plane.boundary_points import (  # noqa: E402
    BoundaryPointController,
    BoundaryPointParams,
)
from controllers.plane.obstacles import (  # noqa: E402
    Circle,
    ObstacleSet,
    Polygon,
    Wall,
    c_shape,
    diamond,
)
from controllers.plane.olfati_saber import OlfatiSaberController  # noqa: E402
from controllers.plane.params import FlockingParams  # noqa: E402
from controllers.plane.references import VirtualLeader  # noqa: E402
from cosim.plane.world import PlaneWorld

TABLE3 = BoundaryPointParams()
SPACING = 0.5  # m, boundary point spacing
CONV_TOL = 3.0  # m, flock centre to gamma-agent for "converged"
DT = TABLE3.dt


# --------------------------------------------------------------------------- scenes
@dataclass(frozen=True)
class Scene:
    """One experiment: obstacles, start box ((x0, x1), (y0, y1)) in m, goal (m), agents."""

    name: str
    obstacles: ObstacleSet
    start_box: tuple[tuple[float, float], tuple[float, float]]
    goal: tuple[float, float]
    n: int = 30
    title: str = ""

    @property
    def axis(self) -> tuple[np.ndarray, np.ndarray]:
        """Start-box centre (2,) and unit vector towards the goal (2,)."""
        c0 = np.array([np.mean(self.start_box[0]), np.mean(self.start_box[1])])
        u = np.asarray(self.goal) - c0
        return c0, u / np.linalg.norm(u)

    @property
    def s_exit(self) -> float:
        """Progress (m, along the axis) of the far side of the finite obstacles."""
        c0, u = self.axis
        pts = [
            o.boundary(SPACING)
            for o in self.obstacles
            if not (isinstance(o, Wall) and o.normal is not None)
        ]
        return float(np.max((np.vstack(pts) - c0) @ u))

    @property
    def arrive_radius(self) -> float:
        """Radius (m) of a settled flock of ``n`` agents at spacing d, times 1.5."""
        return 1.5 * TABLE3.d * math.sqrt(self.n * math.sqrt(3.0) / (2.0 * math.pi)) + TABLE3.d


def _path_frame(start_box, goal):
    c0 = np.array([np.mean(start_box[0]), np.mean(start_box[1])])
    g = np.asarray(goal, dtype=float)
    u = (g - c0) / np.linalg.norm(g - c0)
    v = np.array([-u[1], u[0]])  # left of the path
    return c0, g, u, v


def scene_independent() -> Scene:
    box, goal = ((10.0, 30.0), (5.0, 20.0)), (75.0, 80.0)
    c0, g, u, v = _path_frame(box, goal)
    L = float(np.linalg.norm(g - c0))
    obst = ObstacleSet(
        (
            Circle(tuple(c0 + 0.30 * L * u + 1.0 * v), 4.0, name="circle A"),
            Circle(tuple(c0 + 0.65 * L * u - 2.0 * v), 5.0, name="circle B"),
            Wall.infinite(tuple(c0 + 14.0 * v), tuple(-v), half_length=250.0),
        )
    )
    return Scene("independent", obst, box, goal, 30, "two circles and a wall, independent")


def scene_two_circles() -> Scene:
    box, goal = ((10.0, 30.0), (5.0, 20.0)), (75.0, 80.0)
    c0, g, u, v = _path_frame(box, goal)
    L = float(np.linalg.norm(g - c0))
    c = c0 + 0.55 * L * u
    obst = ObstacleSet(
        (
            Circle(tuple(c + 4.5 * v), 5.0, name="circle L"),
            Circle(tuple(c - 4.5 * v), 5.0, name="circle R"),
        )
    )
    return Scene("two_circles", obst, box, goal, 30, "two touching circles (notch)")


def scene_circle_wall() -> Scene:
    """A circle (R = 11 m) touching a straight wall that runs 18 m left of the start-goal line.

    The straight line to the goal meets the circle between its centre and
    the wall's side, so agents pulled towards the goal slide into the wedge
    between circle and wall (the goal is 18 m from the wall, out of a settled
    flock's sensing range).
    """
    box, goal = ((10.0, 30.0), (5.0, 20.0)), (75.0, 80.0)
    c0, g, u, v = _path_frame(box, goal)
    L = float(np.linalg.norm(g - c0))
    radius, offset = 11.0, 18.0
    obst = ObstacleSet(
        (
            Wall.infinite(tuple(c0 + offset * v), tuple(-v), half_length=250.0),
            Circle(tuple(c0 + 0.55 * L * u + (offset - radius) * v), radius, name="circle"),
        )
    )
    return Scene("circle_wall", obst, box, goal, 30, "circle touching a wall (wedge)")


def scene_multi(n: int) -> Scene:
    """Paper Fig. 9: start [2, 30] x [5, 30], gamma (75, 25); diamond, circle, C (mouth to -x)."""
    obst = ObstacleSet(
        (
            diamond((36.0, 34.0), 5.0, 5.0),
            Circle((36.0, 12.0), 4.0, name="circle"),
            c_shape((50.0, 22.0), 8.0, 16.0, 2.0, opening=math.pi),
        )
    )
    return Scene(
        f"multi_{n}",
        obst,
        ((2.0, 30.0), (5.0, 30.0)),
        (75.0, 25.0),
        n,
        f"diamond, circle and C shape, N = {n}",
    )


def scenes(smoke: bool = False) -> list[Scene]:
    """The paper's scenes; ``smoke``: the multi-obstacle scene with 30 agents only."""
    ns = (30,) if smoke else (30, 40, 50, 60)
    return [scene_independent(), scene_two_circles(), scene_circle_wall()] + [
        scene_multi(n) for n in ns
    ]


def initial_state(scene: Scene, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Uniform start, redrawn until pairs and obstacles are >= d_min apart; p from [0, 2]^2."""
    rng = np.random.default_rng(seed)
    (x0, x1), (y0, y1) = scene.start_box
    q = np.empty((0, 2))
    for _ in range(100):
        if len(q) == scene.n:
            break
        c = np.column_stack([rng.uniform(x0, x1, 4 * scene.n), rng.uniform(y0, y1, 4 * scene.n)])
        for x in c:
            if len(q) == scene.n:
                break
            if scene.obstacles.signed_distance(x[None])[0] < TABLE3.d_min:
                continue
            if len(q) and np.min(np.linalg.norm(q - x, axis=1)) < TABLE3.d_min:
                continue
            q = np.vstack([q, x])
    if len(q) < scene.n:
        raise RuntimeError(f"{scene.name}: no room for {scene.n} agents in the start box")
    p = rng.uniform(0.0, 2.0, (scene.n, 2))
    return q, p


# --------------------------------------------------------------------------- controllers
CONTROLLERS = {
    "proposed": "boundary points, eq. 19 linear gamma (the paper's law)",
    "proposed_sigma1": "boundary points, eq. 11 sigma_1 gamma",
    "proposed_paper": "boundary points without our two additions (side vote, follow timeout)",
    "os": "Olfati-Saber Alg. 3, sigma_1 gamma, obstacle gains 10 (baseline)",
    "os_table3": "Olfati-Saber Alg. 3, sigma_1 gamma, obstacle gains 1 (Table 3 literally)",
    "os_linear_dw": "Olfati-Saber Alg. 3, linear gamma, dynamic weights, obstacle gains 10",
}
MAIN = ("proposed", "os")


def os_params(gamma: str = "sigma1", dynamic: bool = False, c1_obst: float = 10.0):
    """Table 3 for Olfati-Saber: d = 4, r = 6, eps = 0.5, h = 0.2, a = 2, b = 20, gains 1.

    Not in Table 3: the obstacle distance d' = d = 4 m (what the proposed law
    keeps) and range r' = r = 6 m, walls alike. With Table 3's obstacle gains
    (1) the flock pushes its members into the obstacles (min distance about
    -2 m, see ``os_table3``), unlike the paper's Fig. 6; the baseline raises
    the obstacle gains to ``c1 = 10``, ``c2 = 2 sqrt(10)``.
    """
    p = TABLE3
    c2_obst = 2.0 * math.sqrt(c1_obst) if c1_obst != 1.0 else 1.0
    return FlockingParams(
        d=p.d, r=p.r, epsilon=p.epsilon, h_alpha=p.h, h_beta=p.h, a=p.a, b=p.b,
        d_beta=p.d, r_beta=p.r, d_wall=p.d, r_wall=p.r,
        c1_alpha=1.0, c2_alpha=1.0, c1_beta=c1_obst, c2_beta=c2_obst, c1_wall=c1_obst,
        c2_wall=c2_obst, c1_gamma=1.0, c2_gamma=1.0, gamma_position=gamma,
        dynamic_weights=dynamic, neighbour_search="kdtree",
    )  # fmt: skip


def make_controller(kind: str, scene: Scene):
    """(controller, circles, walls) for the plane world; circles/walls only for OS."""
    if kind not in CONTROLLERS:
        raise ValueError(f"unknown controller {kind!r}; one of {sorted(CONTROLLERS)}")
    sat = [SpeedSaturation(TABLE3.p_max)]
    if kind.startswith("proposed"):
        prm = {
            "proposed": TABLE3,
            "proposed_sigma1": TABLE3.with_(gamma_position="sigma1"),
            "proposed_paper": TABLE3.with_(direction="nearest", follow_timeout=None),
        }[kind]
        law = BoundaryPointController(prm, scene.obstacles, SPACING)
        return ConstrainedController(law, sat), None, None
    prm = {
        "os": os_params("sigma1"),
        "os_table3": os_params("sigma1", c1_obst=1.0),
        "os_linear_dw": os_params("linear", dynamic=True),
    }[kind]
    circles, walls = scene.obstacles.cosim_obstacles(disc_radius=0.5)
    return ConstrainedController(OlfatiSaberController(prm), sat), circles, walls


# --------------------------------------------------------------------------- one run
COLUMNS = ["t_s", "min_agent_m", "min_point_m", "min_obstacle_m", "cx_m", "cy_m",
           "min_progress_m", "max_goal_dist_m", "max_speed_mps"]  # fmt: skip
SETTLE_SPEED = 0.05  # m/s: a converged flock whose agents all move slower than this is at rest
SETTLE_TIME = 10.0  # s at rest (and converged, all arrived) before a run may stop early
STALL_SPEED = 0.005  # m/s: a flock that has not converged is stalled below this speed ...
STALL_TIME = 20.0  # s ... held this long


def _state_row(t: float, q: np.ndarray, p: np.ndarray, scene: Scene) -> tuple:
    """One time-series row (see ``COLUMNS``)."""
    c0, u = scene.axis
    d_agent, _ = cKDTree(q).query(q, k=2)
    return (
        t,
        float(d_agent[:, 1].min()),
        float(scene.obstacles.min_point_distance(q, SPACING).min()),
        float(scene.obstacles.signed_distance(q).min()),
        *q.mean(axis=0),
        float(((q - c0) @ u).min()),
        float(np.linalg.norm(q - np.asarray(scene.goal), axis=1).max()),
        float(np.linalg.norm(p, axis=1).max()),
    )


def simulate(
    scene: Scene,
    kind: str,
    seed: int,
    duration: float = 300.0,
    record: int = 0,
    stop_when_settled: bool = False,
):
    """Run one scene with one controller; returns (summary dict, time series, trajectories).

    ``record`` > 0 keeps positions every ``record`` steps (trajectories (T, N, 2)).
    ``stop_when_settled`` ends the run once the flock has converged, every agent
    has arrived and all speeds stayed below ``SETTLE_SPEED`` for ``SETTLE_TIME``,
    or (not converged) all speeds stayed below ``STALL_SPEED`` for
    ``STALL_TIME`` (stalled): with a static gamma-agent and no noise the state
    no longer changes, so the minimum distances over the full duration are
    those measured and the times stay as they are.
    """
    q0, p0 = initial_state(scene, seed)
    ctrl, circles, walls = make_controller(kind, scene)
    goal = np.asarray(scene.goal)
    rows: list[tuple] = [_state_row(0.0, q0, p0, scene)]
    traj: list[np.ndarray] = [q0.copy()] if record else []

    def hook(world: PlaneWorld) -> None:
        rows.append(_state_row(world.t, world.q, world.p, scene))
        if record and world.k % record == 0:
            traj.append(world.q.copy())

    world = PlaneWorld(
        q0, p0, ctrl, DT, reference=VirtualLeader(goal, np.zeros(2)), circles=circles,
        walls=walls, integrator="semi_implicit", record_every=0, metrics_every=10**9,
        lattice_d=TABLE3.d, lattice_r=TABLE3.r, on_step=hook,
    )  # fmt: skip
    tic = time.perf_counter()
    n_steps = int(round(duration / DT))
    settle_steps = int(round(SETTLE_TIME / DT))
    stall_steps = int(round(STALL_TIME / DT))
    stopped_at = math.nan
    for k in range(n_steps):
        world.step()
        if stop_when_settled and k % 50 == 49 and len(rows) > max(settle_steps, stall_steps):
            tail = np.array(rows[-settle_steps:])
            centre_err = np.hypot(tail[:, 4] - goal[0], tail[:, 5] - goal[1])
            settled = (
                tail[:, 8].max() < SETTLE_SPEED
                and tail[:, 7].max() <= scene.arrive_radius
                and centre_err.max() <= CONV_TOL
            )
            stalled = max(r[8] for r in rows[-stall_steps:]) < STALL_SPEED
            if settled or stalled:
                stopped_at = world.t
                break
    wall_s = time.perf_counter() - tic
    ts = pd.DataFrame(rows, columns=COLUMNS)
    summary = summarise(ts, scene)
    summary["n_not_arrived"] = int(
        np.sum(np.linalg.norm(world.q - goal, axis=1) > scene.arrive_radius)
    )
    summary.update(
        scene=scene.name, controller=kind, seed=seed, n=scene.n, wall_s=wall_s,
        stopped_at_s=stopped_at,
    )  # fmt: skip
    return summary, ts, (np.stack(traj) if record else None)


def _first_time(t: np.ndarray, ok: np.ndarray, staying: bool = False) -> float:
    """First time ``ok`` holds (and, with ``staying``, keeps holding to the end), s; NaN never."""
    if staying:
        bad = np.flatnonzero(~ok)
        if len(bad) == 0:
            return float(t[0])
        k = bad[-1] + 1
        return float(t[k]) if k < len(t) else math.nan
    hit = np.flatnonzero(ok)
    return float(t[hit[0]]) if len(hit) else math.nan


def summarise(ts: pd.DataFrame, scene: Scene) -> dict:
    """Per-run numbers from a time series (see module docstring)."""
    c0, u = scene.axis
    t = ts.t_s.to_numpy()
    centre = ts[["cx_m", "cy_m"]].to_numpy()
    prog = (centre - c0) @ u
    goal_err = np.linalg.norm(centre - np.asarray(scene.goal), axis=1)
    arrived = ts.max_goal_dist_m.to_numpy() <= scene.arrive_radius
    return {
        "min_agent_m": float(ts.min_agent_m.min()),
        "min_point_m": float(ts.min_point_m.min()),
        "min_obstacle_m": float(ts.min_obstacle_m.min()),
        "min_agent_after_1s_m": float(ts.min_agent_m[ts.t_s >= 1.0].min()),
        "min_point_after_1s_m": float(ts.min_point_m[ts.t_s >= 1.0].min()),
        "t_pass_s": _first_time(t, prog >= scene.s_exit),
        "t_conv_s": _first_time(t, goal_err <= CONV_TOL, staying=True),
        "t_arrive_s": _first_time(t, arrived),
        "final_centre_error_m": float(goal_err[-1]),
        "final_max_goal_dist_m": float(ts.max_goal_dist_m.iloc[-1]),
        "converged": bool(goal_err[-1] <= CONV_TOL),
    }


def _job(args):
    scene, kind, seed, duration = args
    summary, _, _ = simulate(scene, kind, seed, duration, stop_when_settled=True)
    return summary


# --------------------------------------------------------------------------- figures
def draw_obstacles(ax, obst: ObstacleSet, box=None) -> None:
    for o in obst:
        if isinstance(o, Circle):
            ax.add_patch(plt.Circle(o.centre, o.radius, color="k", alpha=0.8))
        elif isinstance(o, Polygon):
            ax.add_patch(plt.Polygon(o.vertices, closed=True, color="k", alpha=0.8))
        elif isinstance(o, Wall):
            ax.plot([o.a[0], o.b[0]], [o.a[1], o.b[1]], "k-", lw=3)


def plot_trajectories(out: Path, scene: Scene, trajs: dict[str, np.ndarray]) -> None:
    fig, axes = plt.subplots(1, len(trajs), figsize=(6 * len(trajs), 5.6))
    axes = np.atleast_1d(axes)
    for ax, (kind, tr) in zip(axes, trajs.items(), strict=True):
        draw_obstacles(ax, scene.obstacles)
        for i in range(tr.shape[1]):
            ax.plot(tr[:, i, 0], tr[:, i, 1], "r:", lw=0.6)
        ax.plot(tr[0, :, 0], tr[0, :, 1], "o", ms=3, color="0.5", label="start")
        ax.plot(tr[-1, :, 0], tr[-1, :, 1], "ro", ms=3, label="end")
        ax.plot(*scene.goal, "g^", ms=10, label="gamma-agent")
        xs = np.r_[tr[..., 0].ravel(), scene.goal[0]]
        ys = np.r_[tr[..., 1].ravel(), scene.goal[1]]
        ax.set_xlim(xs.min() - 8, xs.max() + 8)
        ax.set_ylim(ys.min() - 8, ys.max() + 8)
        ax.set_aspect("equal")
        ax.set(title=f"{scene.name}: {kind}", xlabel="x (m)", ylabel="y (m)")
        ax.legend(loc="lower right", fontsize=7)
    fig.tight_layout()
    fig.savefig(out / f"{scene.name}_trajectories.png", dpi=110)
    plt.close(fig)


def plot_centre(out: Path, scene: Scene, series: dict[str, pd.DataFrame]) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    for kind, ts in series.items():
        axes[0].plot(ts.t_s, ts.cx_m, label=kind)
        axes[1].plot(ts.t_s, ts.cy_m, label=kind)
    for ax, k, lab in ((axes[0], 0, "x"), (axes[1], 1, "y")):
        ax.axhline(scene.goal[k], color="g", ls="--", lw=1, label="gamma-agent")
        ax.set(xlabel="t (s)", ylabel=f"flock centre {lab} (m)", title=f"{scene.name}: {lab}(t)")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / f"{scene.name}_centre.png", dpi=110)
    plt.close(fig)


def plot_min_distance(out: Path, scene: Scene, series: dict[str, pd.DataFrame]) -> None:
    fig, ax = plt.subplots(figsize=(7.5, 4))
    for kind, ts in series.items():
        both = np.minimum(ts.min_agent_m, ts.min_point_m)
        ax.plot(ts.t_s, both, lw=0.8, label=f"{kind}: agents or boundary points")
    ax.axhline(TABLE3.d_min, color="k", ls="--", lw=1, label="d_min")
    ax.axhline(TABLE3.d_e, color="grey", ls=":", lw=1, label="d_e")
    ax.set_yscale("log")
    ax.set(xlabel="t (s)", ylabel="minimum distance (m)", title=f"{scene.name}: Fig. 6 analogue")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / f"{scene.name}_min_distance.png", dpi=110)
    plt.close(fig)


def plot_runs(out: Path, runs: pd.DataFrame, duration: float = 300.0) -> None:
    """Fig. 10 analogue (min distance per run) and median times per scene and law."""
    names = list(dict.fromkeys(runs.scene))
    kinds = [k for k in CONTROLLERS if k in set(runs.controller)]
    fig, axes = plt.subplots(1, 2, figsize=(max(10, 2.4 * len(names)), 4.2), sharey=True)
    for ax, col, what in (
        (axes[0], "min_agent_after_1s_m", "between agents (t >= 1 s)"),
        (axes[1], "min_point_m", "agent to boundary point"),
    ):
        for j, kind in enumerate(MAIN):
            sub = runs[runs.controller == kind]
            for k, name in enumerate(names):
                d = sub[sub.scene == name][col].to_numpy()
                x = k + (j - 0.5) * 0.4 + np.linspace(-0.15, 0.15, len(d))
                ax.plot(x, d, ".", ms=3, color=f"C{j}", label=kind if k == 0 else None)
        ax.axhline(TABLE3.d_min, color="k", ls="--", lw=1, label="d_min")
        ax.set_xticks(range(len(names)), names, rotation=25)
        ax.set_yscale("log")
        ax.set(title=f"min distance {what}, per run", ylabel="m")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "min_distance_runs.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(max(11, 2.6 * len(names)), 4.2), sharey=True)
    width = 0.8 / len(kinds)
    for ax, col, title in (
        (axes[0], "t_pass_s", "flock centre past the obstacles"),
        (axes[1], "t_conv_s", "flock centre within 3 m of gamma"),
    ):
        for j, kind in enumerate(kinds):
            sub = runs[runs.controller == kind]
            pos = np.arange(len(names)) + (j - (len(kinds) - 1) / 2) * width
            for x, name in zip(pos, names, strict=True):
                v = sub[sub.scene == name][col]
                if not len(v):
                    continue
                med = float(v.fillna(np.inf).median())
                ax.bar(x, min(med, duration), width, color=f"C{j}",
                       hatch="//" if not np.isfinite(med) else None,
                       label=kind if name == names[0] else None)  # fmt: skip
                ax.text(x, min(med, duration) + 3, f"{v.notna().mean():.0%}", ha="center",
                        fontsize=5, rotation=90)  # fmt: skip
        ax.set_xticks(range(len(names)), names, rotation=25)
        ax.set(title=f"median time: {title}", ylabel=f"s (hatched: > {duration:g} s)")
    axes[0].legend(fontsize=6)
    fig.suptitle("Numbers over the bars: share of runs that reach it", fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "times.png", dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- tables
def summary_table(runs: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for (scene, kind), g in runs.groupby(["scene", "controller"], sort=False):
        both = np.minimum(g.min_agent_m, g.min_point_m)
        rows.append(
            {
                "scene": scene,
                "controller": kind,
                "runs": len(g),
                "min_dist_min_m": both.min(),
                "min_dist_p05_m": both.quantile(0.05),
                "min_dist_median_m": both.median(),
                "min_agent_min_m": g.min_agent_m.min(),
                "min_point_min_m": g.min_point_m.min(),
                "min_obstacle_min_m": g.min_obstacle_m.min(),
                "min_agent_after_1s_min_m": g.min_agent_after_1s_m.min(),
                "collision_after_1s_share": float(
                    np.mean(
                        np.minimum(g.min_agent_after_1s_m, g.min_point_after_1s_m) <= TABLE3.d_min
                    )
                ),
                "collision_share": float(np.mean(both <= TABLE3.d_min)),
                "t_pass_median_s": g.t_pass_s.median(),
                "t_conv_median_s": g.t_conv_s.fillna(np.inf).median(),
                "t_arrive_median_s": g.t_arrive_s.fillna(np.inf).median(),
                "converged_share": g.converged.mean(),
                "n_not_arrived_mean": g.n_not_arrived.mean() if "n_not_arrived" in g else np.nan,
            }
        )
    return pd.DataFrame(rows)


PAIRS = (
    ("proposed", "os"),
    ("proposed", "os_table3"),
    ("proposed", "os_linear_dw"),
    ("proposed_sigma1", "os"),
    ("proposed_paper", "os"),
)


def speedup_table(runs: pd.DataFrame, duration: float = 300.0) -> pd.DataFrame:
    """Median times of a law vs a baseline per scene and the reduction ``1 - t / t_base``.

    Runs that never reach the event count as ``inf`` in the medians;
    ``reduction_bound`` counts them as ``duration`` instead (a lower bound on
    the reduction when the baseline fails).
    """
    rows = []
    for scene, g in runs.groupby("scene", sort=False):
        for law, base in PAIRS:
            a, b = g[g.controller == law], g[g.controller == base]
            if not len(a) or not len(b):
                continue
            for col in ("t_pass_s", "t_conv_s", "t_arrive_s"):
                ta = a[col].fillna(np.inf).median()
                tb = b[col].fillna(np.inf).median()
                tb_cap = b[col].fillna(duration).median()
                ta_cap = a[col].fillna(duration).median()
                rows.append(
                    {
                        "scene": scene,
                        "law": law,
                        "baseline": base,
                        "time": col.removesuffix("_s"),
                        "law_median_s": ta,
                        "baseline_median_s": tb,
                        "law_reached": a[col].notna().mean(),
                        "baseline_reached": b[col].notna().mean(),
                        "reduction": 1.0 - ta / tb if np.isfinite(tb) and tb > 0 else np.nan,
                        "reduction_bound": 1.0 - ta_cap / tb_cap if tb_cap > 0 else np.nan,
                    }
                )
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------- main
def _representative(args):
    scene, kind, duration = args
    summary, ts, tr = simulate(scene, kind, 0, duration, record=5)
    return scene.name, kind, summary, ts, tr


def run_all(fn, jobs: list, workers: int, out: Path | None = None, label: str = "runs"):
    """``[fn(j) for j in jobs]`` in ``workers`` processes, in job order, with progress."""
    if workers <= 1:
        return [fn(j) for j in jobs]
    results: list = [None] * len(jobs)
    tic = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(fn, j): k for k, j in enumerate(jobs)}
        for done, fut in enumerate(as_completed(futures), start=1):
            results[futures[fut]] = fut.result()
            if done % 50 == 0 or done == len(jobs):
                print(f"  {label}: {done}/{len(jobs)} ({time.perf_counter() - tic:.0f} s)",
                      file=sys.stderr, flush=True)  # fmt: skip
                if out is not None and label == "runs":
                    pd.DataFrame([r for r in results if r is not None]).to_csv(
                        out / "runs_partial.csv", index=False
                    )
    return results


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--smoke", action="store_true", help="few runs, short horizon")
    ap.add_argument("--out", type=Path, default=Path("outputs/seed003"), help="output directory")
    ap.add_argument("--runs", type=int, default=None, help="random starts per scene (100)")
    ap.add_argument(
        "--variant-runs", type=int, default=None, help="starts for the variants (min(runs, 30))"
    )
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes")
    ap.add_argument("--duration", type=float, default=None, help="simulated time, s (300)")
    ap.add_argument("--replot", action="store_true", help="tables and run plots from runs.csv")
    args = ap.parse_args(argv)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    if args.replot:
        duration = args.duration if args.duration is not None else 300.0
        runs = pd.read_csv(out / "runs.csv")
        summary_table(runs).to_csv(out / "summary.csv", index=False)
        speedup_table(runs, duration).to_csv(out / "speedup.csv", index=False)
        plot_runs(out, runs, duration)
        return 0
    runs_n = args.runs if args.runs is not None else (1 if args.smoke else 100)
    var_n = args.variant_runs if args.variant_runs is not None else min(runs_n, 30)
    duration = args.duration if args.duration is not None else (120.0 if args.smoke else 300.0)
    all_scenes = scenes(args.smoke)
    variants = [] if args.smoke else [k for k in CONTROLLERS if k not in MAIN]
    tic = time.perf_counter()

    # Representative runs (seed 0, full duration) with trajectories and time series.
    reps = run_all(
        _representative,
        [(scene, kind, duration) for scene in all_scenes for kind in MAIN],
        args.jobs,
        label="figures",
    )
    for scene in all_scenes:
        got = [r for r in reps if r[0] == scene.name]
        trajs = {kind: tr for _, kind, _, _, tr in got}
        series = {kind: ts for _, kind, _, ts, _ in got}
        for kind, ts in series.items():
            ts.assign(controller=kind).to_csv(
                out / f"timeseries_{scene.name}_{kind}.csv", index=False
            )
        plot_trajectories(out, scene, trajs)
        plot_centre(out, scene, series)
        plot_min_distance(out, scene, series)

    # Random starts: both main laws everywhere, the variants on the 30-agent scenes.
    jobs = [(scene, kind, seed, duration) for scene in all_scenes for kind in MAIN
            for seed in range(runs_n)]  # fmt: skip
    jobs += [(scene, kind, seed, duration) for scene in all_scenes if scene.n == 30
             for kind in variants for seed in range(var_n)]  # fmt: skip
    runs = pd.DataFrame(run_all(_job, jobs, args.jobs, out))
    runs.to_csv(out / "runs.csv", index=False)
    summary = summary_table(runs)
    summary.to_csv(out / "summary.csv", index=False)
    speed = speedup_table(runs, duration)
    speed.to_csv(out / "speedup.csv", index=False)
    plot_runs(out, runs, duration)
    pd.set_option("display.width", 250)
    pd.set_option("display.max_columns", 30)
    print(summary.round(3).to_string(index=False))
    print(speed.round(3).to_string(index=False))
    print(
        f"{len(jobs)} runs + {len(reps)} figure runs in {time.perf_counter() - tic:.0f} s -> {out}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
