"""Seed 002: rigid hexagon formation by artificial potentials, and the K_for sweep.

Usage::

    python experiments/seed002_formation.py [--smoke] [--out DIR]

Writes to ``--out`` (default ``outputs/seed002``):

* ``hexagon_error.csv``: t (s), e_rms (m), e_max (m), v_spread (m/s) of one run of
  the 7-agent hexagon (K_for = 0.001, K_vel = 0.3) from a random start;
* ``hexagon_trajectories.png`` (fixed camera and camera on the centroid, as the seed's
  animations) and ``hexagon_error.png`` (distance error vs time);
* ``kfor_sweep.csv``: one row per (K_for, start) with the oscillation measures of
  :func:`controllers.plane.formation.oscillation_metrics` and the linearised damping ratio;
  ``kfor_sweep_summary.csv`` and ``kfor_sweep.png``; the summary is printed;
* ``road_grid.csv`` / ``road_grid.png``: two rows of three CAVs travelling at the
  virtual leader's 25 m/s while restoring their shape.

Scale: the seed works in screen pixels; we use SI with a hexagon side of 10 m
(``--side``). Only ``K_for * side^2 / K_vel^2`` matters for the shape of the transient.
Random starts follow the seed: positions uniform in a square (4 sides wide), velocity
components uniform in [0, 5] m/s. Integration is the seed's explicit Euler update.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from controllers.plane.formation import (  # noqa: E402
    FormationController,
    FormationGraph,
    FormationParams,
    damping_ratios,
    grid_formation,
    hexagon_formation,
    oscillation_metrics,
    replicate,
    rollout,
    signed_distance_errors,
)

K_FOR_SWEEP = (1e-4, 1e-3, 1e-2)  # 1/(m^2 s^2), seed 002's three simulations
K_VEL = 0.3  # 1/s, seed 002


def random_starts(n: int, side: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Seed-like random initial state: q (n, 2) in a 4*side square, m; p (n, 2) in [0, 5] m/s."""
    return rng.uniform(0.0, 4.0 * side, (n, 2)), rng.uniform(0.0, 5.0, (n, 2))


def rms_error_series(Q: np.ndarray, graph: FormationGraph) -> np.ndarray:
    """(T,) RMS distance error of each sample of Q (T, N, m), m."""
    return np.sqrt(np.mean(signed_distance_errors(Q, graph.pairs, graph.desired) ** 2, axis=1))


def run_until_settled(
    ctrl: FormationController,
    q0: np.ndarray,
    p0: np.ndarray,
    dt: float,
    t_max: float,
    copies: list[FormationGraph],
    tol: float,
    chunk: float = 20.0,
    **kw,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Roll out in chunks of ``chunk`` s until every copy's RMS error < ``tol`` m or ``t_max``."""
    ts, Qs, Ps = [np.zeros(1)], [q0[None]], [p0[None]]
    t_now = 0.0
    while t_now < t_max - 1e-9:
        steps = int(round(min(chunk, t_max - t_now) / dt))
        t, Q, P = rollout(ctrl, Qs[-1][-1], Ps[-1][-1], dt, steps, **kw)
        ts.append(t[1:] + t_now)
        Qs.append(Q[1:])
        Ps.append(P[1:])
        t_now = float(ts[-1][-1])
        n = copies[0].n_agents
        last = Qs[-1][-1]
        errs = [rms_error_series(last[None, b * n : (b + 1) * n], g) for b, g in enumerate(copies)]
        if max(float(e[0]) for e in errs) < tol:
            break
    return np.concatenate(ts), np.concatenate(Qs), np.concatenate(Ps)


def hexagon_demo(out: Path, side: float, dt: float, horizon: float, seed: int) -> pd.DataFrame:
    """One hexagon from a random start; CSV + two figures. Returns the error table."""
    g = hexagon_formation(side)
    q0, p0 = random_starts(7, side, np.random.default_rng(seed))
    ctrl = FormationController(g, FormationParams(K_for=1e-3, K_vel=K_VEL))
    t, Q, P = rollout(ctrl, q0, p0, dt, int(round(horizon / dt)))
    eps = signed_distance_errors(Q, g.pairs, g.desired)
    df = pd.DataFrame(
        {
            "t": t,
            "e_rms": np.sqrt(np.mean(eps**2, axis=1)),
            "e_max": np.abs(eps).max(axis=1),
            "v_spread": np.linalg.norm(P - P.mean(axis=1, keepdims=True), axis=2).max(axis=1),
        }
    )
    df.to_csv(out / "hexagon_error.csv", index=False)
    plot_trajectories(out / "hexagon_trajectories.png", Q, g)
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.semilogy(df.t, df.e_rms, label="RMS")
    ax.semilogy(df.t, df.e_max, label="max", alpha=0.7)
    ax.set(xlabel="t (s)", ylabel="distance error (m)", title="Hexagon, K_for=1e-3, K_vel=0.3")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "hexagon_error.png", dpi=120)
    plt.close(fig)
    return df


def plot_trajectories(path: Path, Q: np.ndarray, g: FormationGraph) -> None:
    """Trajectories with a fixed camera and with the camera on the centroid (as the seed)."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    und = g.pairs[g.pairs[:, 0] < g.pairs[:, 1]]
    for ax, centred in zip(axes, (False, True), strict=True):
        X = Q - Q.mean(axis=1, keepdims=True) if centred else Q
        for i in range(X.shape[1]):
            ax.plot(X[:, i, 0], X[:, i, 1], lw=0.8)
            ax.annotate(str(i), X[-1, i], fontsize=8)
        for i, j in und:
            ax.plot(*X[-1, [i, j]].T, "k-", lw=0.6, alpha=0.6)
        ax.plot(X[0, :, 0], X[0, :, 1], "ko", ms=3, label="start")
        ax.plot(X[-1, :, 0], X[-1, :, 1], "rs", ms=4, label="end")
        ax.set_aspect("equal")
        ax.set(xlabel="x (m)", ylabel="y (m)")
        ax.set_title("camera on centroid" if centred else "fixed camera")
    axes[0].legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def kfor_sweep(
    out: Path, side: float, dt: float, t_max: float, copies: int, seed: int
) -> pd.DataFrame:
    """Seed 002's K_for sweep with K_vel = 0.3, the same random starts for every gain."""
    g = hexagon_formation(side)
    gb = replicate(g, copies)
    q0, p0 = random_starts(7 * copies, side, np.random.default_rng(seed + 1000))
    rows, curves = [], {}
    for K in K_FOR_SWEEP:
        params = FormationParams(K_for=K, K_vel=K_VEL)
        zeta = float(damping_ratios(g, params).min())
        tic = time.perf_counter()
        t, Q, _ = run_until_settled(
            FormationController(gb, params), q0, p0, dt, t_max, [g] * copies, 1e-3 * side
        )
        wall = time.perf_counter() - tic
        for b in range(copies):
            Qb = Q[:, 7 * b : 7 * b + 7]
            m = oscillation_metrics(t, Qb, g)
            rows.append({"K_for": K, "K_vel": K_VEL, "start": b, "zeta_min": zeta, **m})
        curves[K] = (t, rms_error_series(Q[:, :7], g))
        print(f"  K_for={K:g}: simulated {t[-1]:.0f} s in {wall:.1f} s", flush=True)
    df = pd.DataFrame(rows)
    df.to_csv(out / "kfor_sweep.csv", index=False)
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for K, (t, e) in curves.items():
        ax.semilogy(t, np.maximum(e, 1e-6), label=f"K_for={K:g}")
    ax.set(xlabel="t (s)", ylabel="RMS distance error (m)", xlim=(0, min(t_max, 60.0)))
    ax.set_title(f"K_vel={K_VEL}, start 0 (side {side:g} m)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "kfor_sweep.png", dpi=120)
    plt.close(fig)
    return df


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """One row per K_for: settled fraction, median t_settle and mean oscillation measures."""
    agg = df.groupby("K_for").agg(
        zeta_min=("zeta_min", "first"),
        settled=("t_settle", lambda s: float(np.isfinite(s).mean())),
        t_settle_s=("t_settle", "median"),
        overshoots_total=("overshoots_total", "mean"),
        overshoots_after=("overshoots", "mean"),
        max_rebound_m=("max_rebound", "mean"),
        e_final_max_m=("e_final", "max"),
    )
    return agg.reset_index()


def road_grid_demo(out: Path, dt: float, horizon: float, seed: int) -> pd.DataFrame:
    """Two rows of three CAVs (12 m x 3.5 m) following a 25 m/s virtual leader."""
    g = grid_formation(2, 3, 12.0, 3.5)
    rng = np.random.default_rng(seed)
    q0 = g.reference + rng.normal(0.0, [1.5, 0.4], (6, 2))
    p0 = np.column_stack([rng.uniform(18.0, 24.0, 6), rng.normal(0.0, 0.3, 6)])
    ctrl = FormationController(g, FormationParams(K_for=0.01, K_vel=K_VEL, K_ref=0.5))
    leader = np.array([25.0, 0.0])
    t, Q, P = rollout(ctrl, q0, p0, dt, int(round(horizon / dt)), leader_p=leader,
                      scheme="semi-implicit")  # fmt: skip
    eps = signed_distance_errors(Q, g.pairs, g.desired)
    df = pd.DataFrame(
        {
            "t": t,
            "e_max": np.abs(eps).max(axis=1),
            "speed_error_max": np.abs(P[:, :, 0] - leader[0]).max(axis=1),
            "lateral_spread": Q[:, :, 1].max(axis=1) - Q[:, :, 1].min(axis=1),
        }
    )
    df.to_csv(out / "road_grid.csv", index=False)
    fig, axes = plt.subplots(2, 1, figsize=(8, 5))
    s_rel = Q[:, :, 0] - leader[0] * t[:, None]
    for i in range(6):
        axes[0].plot(s_rel[:, i], Q[:, i, 1], lw=0.8)
    axes[0].plot(s_rel[-1], Q[-1, :, 1], "rs", ms=4)
    axes[0].set(xlabel="s - 25 t (m)", ylabel="d (m)", title="2 x 3 formation in the road frame")
    axes[1].semilogy(df.t, np.maximum(df.e_max, 1e-6))
    axes[1].set(xlabel="t (s)", ylabel="max distance error (m)")
    fig.tight_layout()
    fig.savefig(out / "road_grid.png", dpi=120)
    plt.close(fig)
    return df


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--smoke", action="store_true", help="short run (a few seconds)")
    ap.add_argument("--out", type=Path, default=Path("outputs/seed002"), help="output directory")
    ap.add_argument("--seed", type=int, default=0, help="random seed of the starts")
    ap.add_argument("--side", type=float, default=10.0, help="hexagon side, m")
    ap.add_argument("--dt", type=float, default=0.01, help="sampling time T_s, s")
    ap.add_argument("--starts", type=int, default=None, help="random starts in the sweep")
    args = ap.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    horizon, t_max = (20.0, 20.0) if args.smoke else (60.0, 1000.0)
    starts = args.starts or (2 if args.smoke else 10)

    demo = hexagon_demo(out, args.side, args.dt, horizon, args.seed)
    print(
        f"hexagon (K_for=1e-3, K_vel=0.3): RMS error {demo.e_rms.iloc[0]:.2f} m -> "
        f"{demo.e_rms.iloc[-1]:.2e} m after {demo.t.iloc[-1]:.0f} s"
    )
    print(f"K_for sweep, K_vel={K_VEL}, {starts} random starts, up to {t_max:.0f} s:")
    summary = summarise(kfor_sweep(out, args.side, args.dt, t_max, starts, args.seed))
    summary.to_csv(out / "kfor_sweep_summary.csv", index=False)
    with pd.option_context("display.width", 120, "display.float_format", "{:.3g}".format):
        print(summary.to_string(index=False))
    road = road_grid_demo(out, 0.1, 20.0 if args.smoke else 60.0, args.seed)
    print(
        f"road 2x3 grid: max distance error {road.e_max.iloc[0]:.2f} m -> "
        f"{road.e_max.iloc[-1]:.2e} m, speed error {road.speed_error_max.iloc[-1]:.2e} m/s"
    )
    print(f"outputs in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
