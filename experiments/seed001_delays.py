"""Seed 001: multi-waypoint flocking with bounded delays, asynchrony and saturation.

Usage::

    python experiments/seed001_delays.py [--smoke] [--out DIR]

Seed 001's 50 agents (``cosim.plane.scenarios.seed001_world``: positions in
[0, 100]^2, OS06 Algorithm 2 with c1 = c2 = 0.1 towards the goal, dt = 0.01 s)
fly a mission of several static waypoints (:class:`WaypointSequence`: the
reference jumps to the next waypoint when the flock's centroid is within 5 m)
with speed saturation (10 m/s, seed 001's low value) and actuator saturation
(||u|| <= 5 m/s^2) applied every step to the held command. Seed 001 draws
initial velocities in [-100, 100]^2 m/s; a state constraint must hold at t = 0
too, so they are scaled down to 10 m/s (same directions).

Each agent communicates through :class:`CommunicatingController`: it
broadcasts (q, p) every T seconds to agents closer than r_comm = r = 8.4 m
(seed 001's N_c), each copy delayed uniformly in [0, D] and dropped when older
than D + 5 T. Synchronous: common clock; asynchronous: each agent has its own
phase and a period within +-10 % of T. Control is recomputed at each agent's
instants and held in between. Cases: the ideal law (no communication layer);
T = 0.05 s (20 Hz) with the delay bound D swept, synchronous and asynchronous;
D = 0 with T = 0.1 and 0.2 s (sampling alone); and dead reckoning
(``extrapolate=True``, not in seed 001) for a few D.

Outputs in ``--out`` (default ``outputs/seed001_delays``):

* ``delay_sweep.csv``: one row per case: min inter-agent distance over the run
  and after 10 s, waypoint arrival times, consensus time, residual velocity
  mismatch, connectivity, fragmentation/collision flags, message counts;
* ``metrics_<case>.csv``: each run's metric time series (every 0.1 s);
* ``delay_sweep.png``: min distance, residual mismatch, mission time and
  components vs D; ``trajectories.png``: centroid paths and final positions.

Definitions: consensus time = first time after which the 2 s moving average of
the velocity mismatch ``(1/N) sum ||p_i - mean p||^2`` stays below
0.1 m^2/s^2; residual mismatch = its mean over the last 10 s; connected time =
first time after which the proximity graph (range r = 8.4 m) stays in one
component; "broken" = collision (min distance < 1 m after 10 s, i.e. after the
random start has been sorted out), fragmentation (more than one component at
the end), or the mission not completed. One run per case (world seed 1,
channel seed 1): the break point is that of this realisation.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from controllers.comm import CommConfig, CommunicatingController  # noqa: E402
from controllers.layers.constraints import ConstrainedController  # noqa: E402
from controllers.plane.references import WaypointSequence  # noqa: E402
from cosim.plane.scenarios import seed001_world
from cosim.plane.world import PlaneWorld

WAYPOINTS = np.array([[150.0, 150.0], [300.0, 150.0], [300.0, 300.0], [150.0, 300.0]])  # m
WAYPOINT_TOL_M = 5.0
V_MAX = 10.0  # m/s
A_MAX = 5.0  # m/s^2
PERIOD_S = 0.05  # broadcast / control period T of the delay sweep (20 Hz)
R_COMM_M = 8.4  # = r of seed001_params()
JITTER = 0.1
CONSENSUS_M2PS2 = 0.1
COLLISION_M = 1.0
SETTLE_S = 10.0  # min distance "after the transient" is taken from here on
DELAYS_S = (0.0, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0)
PERIODS_S = (0.1, 0.2)  # extra sampling-only cases at D = 0
EXTRAP_DELAYS_S = (0.3, 1.0)
SMOKE_DELAYS_S = (0.0, 0.3)
MODES = ("synchronous", "asynchronous")


def comm_config(
    mode: str,
    delay_max_s: float,
    seed: int = 1,
    loss: float = 0.0,
    period_s: float = PERIOD_S,
    extrapolate: bool = False,
) -> CommConfig:
    """The sweep's communication model for one case."""
    return CommConfig(
        r_comm_m=R_COMM_M,
        delay_min_s=0.0,
        delay_max_s=delay_max_s,
        loss_prob=loss,
        period_s=period_s,
        expiry_s=delay_max_s + 5 * period_s,
        mode=mode,
        period_jitter=JITTER if mode == "asynchronous" else 0.0,
        seed=seed,
        extrapolate=extrapolate,
    )


def build_world(
    cfg: CommConfig | None, seed: int = 1, waypoints: np.ndarray = WAYPOINTS
) -> PlaneWorld:
    """Seed 001's world with saturation, a waypoint mission and (optionally) communication."""
    world = seed001_world(seed=seed, speed_limit_mps=V_MAX, accel_limit_mps2=A_MAX)
    speed = np.linalg.norm(world.p, axis=1, keepdims=True)
    world.p = world.p * np.minimum(1.0, V_MAX / np.maximum(speed, 1e-12))
    law = world.controller.law
    inner = law if cfg is None else CommunicatingController(law, cfg)
    world.controller = ConstrainedController(inner, world.controller.layers)
    world.reference = WaypointSequence(waypoints, tolerance_m=WAYPOINT_TOL_M)
    return world


def settle_time(t: np.ndarray, ok: np.ndarray) -> float:
    """First time after which ``ok`` holds to the end (NaN if it fails at the end)."""
    if len(ok) == 0 or not ok[-1]:
        return math.nan
    bad = np.flatnonzero(~ok)
    return float(t[0] if len(bad) == 0 else t[bad[-1] + 1])


def summarise(world: PlaneWorld, metrics: pd.DataFrame) -> dict:
    """One sweep row from a finished run."""
    t = metrics["t_s"].to_numpy()
    dmin = metrics["min_agent_distance_m"].to_numpy()
    comps = metrics["n_components"].to_numpy()
    reached = list(world.reference.reached_at)
    late = t >= SETTLE_S
    mismatch = metrics["velocity_mismatch_m2ps2"]
    smooth = mismatch.rolling(window=20, min_periods=1).mean().to_numpy()  # 2 s at 0.1 s
    mismatch = mismatch.to_numpy()
    row = {
        "min_dist_m": float(dmin.min()),
        "min_dist_after_10s_m": float(dmin[late].min()),
        "t_min_dist_s": float(t[late][np.argmin(dmin[late])]),
        "waypoints_reached": len(reached),
        "mission_time_s": float(reached[-1]) if world.reference.done else math.nan,
        "consensus_time_s": settle_time(t, smooth < CONSENSUS_M2PS2),
        "residual_mismatch_m2ps2": float(mismatch[t >= t[-1] - 10.0].mean()),
        "connected_time_s": settle_time(t, comps == 1),
        "max_components_after_10s": int(comps[late].max()),
        "final_components": int(comps[-1]),
    }
    for k in range(len(world.reference.waypoints)):
        row[f"t_wp{k + 1}_s"] = float(reached[k]) if k < len(reached) else math.nan
    row["collision"] = bool(row["min_dist_after_10s_m"] < COLLISION_M)
    row["fragmented"] = bool(row["final_components"] > 1)
    row["broken"] = bool(row["collision"] or row["fragmented"] or not world.reference.done)
    return row


def case_label(mode: str, delay_max_s: float, period_s: float, extrapolate: bool) -> str:
    if mode == "ideal":
        return "ideal"
    tag = f"{mode[:5]}_T{period_s:g}_D{delay_max_s:g}"
    return tag + ("_extrap" if extrapolate else "")


def run_case(
    mode: str,
    delay_max_s: float = 0.0,
    duration_s: float = 100.0,
    seed: int = 1,
    period_s: float = PERIOD_S,
    extrapolate: bool = False,
    waypoints: np.ndarray = WAYPOINTS,
):
    """Run one case; ``mode="ideal"`` has no communication layer. Returns (row, world, result)."""
    ideal = mode == "ideal"
    cfg = None if ideal else comm_config(mode, delay_max_s, seed, 0.0, period_s, extrapolate)
    world = build_world(cfg, seed, waypoints)
    t0 = time.perf_counter()
    result = world.run(duration_s)
    row = {
        "case": case_label(mode, delay_max_s, period_s, extrapolate),
        "mode": mode,
        "period_s": world.dt if ideal else period_s,
        "delay_max_s": 0.0 if ideal else delay_max_s,
        "extrapolate": bool(extrapolate),
    }
    row.update(summarise(world, result.metrics))
    inner = world.controller.law
    if isinstance(inner, CommunicatingController):
        st = inner.stats
        row.update(
            sent=st.sent,
            delivered=st.delivered,
            expired=st.expired,
            out_of_order=st.out_of_order,
            law_calls=st.law_calls,
        )
    row["clip_speed"] = world.controller.layers[0].clip_rate
    row["clip_accel"] = world.controller.layers[1].clip_rate
    row["wall_s"] = time.perf_counter() - t0
    return row, world, result


def cases(smoke: bool) -> list[dict]:
    """The experiment's cases as keyword arguments of :func:`run_case`."""
    delays = SMOKE_DELAYS_S if smoke else DELAYS_S
    out = [dict(mode="ideal")]
    out += [dict(mode=m, delay_max_s=d) for m in MODES for d in delays]
    if not smoke:
        out += [dict(mode=m, period_s=T) for m in MODES for T in PERIODS_S]
        out += [
            dict(mode=m, delay_max_s=d, extrapolate=True) for m in MODES for d in EXTRAP_DELAYS_S
        ]
    return out


def plot_sweep(df: pd.DataFrame, path: Path) -> None:
    fig, axes = plt.subplots(1, 4, figsize=(17, 3.9))
    ideal = df[df["mode"] == "ideal"]
    sweep = df[(df["period_s"] == PERIOD_S) & ~df["extrapolate"]]
    extrap = df[df["extrapolate"]]
    series = [(m, sweep[sweep["mode"] == m], s) for m, s in zip(MODES, ("o-", "s--"), strict=True)]
    series += [
        (f"{m}, dead reckoning", extrap[extrap["mode"] == m], s)
        for m, s in zip(MODES, ("^-", "v--"), strict=True)
    ]
    for label, d, style in series:
        if not len(d):
            continue
        d = d.sort_values("delay_max_s")
        axes[0].plot(d.delay_max_s, d.min_dist_after_10s_m, style, label=label)
        axes[1].semilogy(d.delay_max_s, d.residual_mismatch_m2ps2, style, label=label)
        axes[2].plot(d.delay_max_s, d.mission_time_s, style, label=label)
        axes[3].plot(d.delay_max_s, d.final_components, style, label=f"{label}: final")
    if len(ideal):
        axes[0].axhline(ideal.min_dist_after_10s_m.iloc[0], color="k", lw=0.8, label="ideal law")
        axes[1].axhline(ideal.residual_mismatch_m2ps2.iloc[0], color="k", lw=0.8, label="ideal law")
        axes[2].axhline(ideal.mission_time_s.iloc[0], color="k", lw=0.8, label="ideal law")
    axes[0].axhline(COLLISION_M, color="r", lw=0.8, ls=":", label="collision threshold")
    axes[0].set(xlabel="delay bound D (s)", ylabel="min inter-agent distance after 10 s (m)")
    axes[1].set(xlabel="delay bound D (s)", ylabel="velocity mismatch, last 10 s (m^2/s^2)")
    axes[2].set(xlabel="delay bound D (s)", ylabel="time of the last waypoint (s)")
    axes[3].set(xlabel="delay bound D (s)", ylabel="connected components at the end (r = 8.4 m)")
    for ax in axes:
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.suptitle(
        f"Seed 001, 50 agents, waypoint mission, |p| <= {V_MAX:g} m/s, |u| <= {A_MAX:g} m/s^2, "
        f"T = {PERIOD_S:g} s, delays U[0, D]"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_trajectories(runs: list[tuple[str, PlaneWorld, object]], path: Path) -> None:
    fig, axes = plt.subplots(1, len(runs), figsize=(4.2 * len(runs), 4.2), squeeze=False)
    for ax, (label, world, result) in zip(axes[0], runs, strict=True):
        tr = result.trajectories
        cen = tr.groupby("t_s")[["x_m", "y_m"]].mean()
        ax.plot(cen.x_m, cen.y_m, "k-", lw=1, label="centroid")
        wps = world.reference.waypoints
        ax.plot(wps[:, 0], wps[:, 1], "r*", ms=12, label="waypoints")
        ax.plot(world.q[:, 0], world.q[:, 1], "b.", ms=4, label="final positions")
        ax.set(title=label, xlabel="x (m)", ylabel="y (m)", aspect="equal")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--smoke", action="store_true", help="two delays, two waypoints, 40 s: a quick check"
    )
    ap.add_argument("--out", default="outputs/seed001_delays", help="output directory")
    ap.add_argument("--duration", type=float, default=None, help="run length, s (default 100)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    duration = args.duration or (40.0 if args.smoke else 100.0)

    rows, shown = [], []
    worst = max(SMOKE_DELAYS_S if args.smoke else DELAYS_S)
    for kw in cases(args.smoke):
        wps = WAYPOINTS[:2] if args.smoke else WAYPOINTS
        row, world, result = run_case(duration_s=duration, waypoints=wps, **kw)
        rows.append(row)
        result.metrics.to_csv(out / f"metrics_{row['case']}.csv", index=False)
        if row["period_s"] in (PERIOD_S, world.dt) and (
            kw["mode"] == "ideal" or row["delay_max_s"] in (0.2, worst)
        ):
            shown.append((row["case"], world, result))
        print(
            f"{row['case']:>28}: dmin={row['min_dist_after_10s_m']:5.2f} m "
            f"mission={row['mission_time_s']:6.1f} s "
            f"mismatch={row['residual_mismatch_m2ps2']:6.3f} "
            f"comps={row['final_components']} ({row['wall_s']:.1f} s wall)",
            flush=True,
        )
    df = pd.DataFrame(rows)
    df.to_csv(out / "delay_sweep.csv", index=False)
    plot_sweep(df, out / "delay_sweep.png")
    plot_trajectories(shown[:4], out / "trajectories.png")

    cols = [
        "mode",
        "period_s",
        "delay_max_s",
        "extrapolate",
        "min_dist_m",
        "min_dist_after_10s_m",
        "mission_time_s",
        "consensus_time_s",
        "residual_mismatch_m2ps2",
        "connected_time_s",
        "final_components",
        "collision",
        "fragmented",
        "broken",
    ]
    print()
    print(df[cols].to_string(index=False, float_format=lambda v: f"{v:.2f}"))
    print()
    for mode in MODES:
        d = df[(df["mode"] == mode) & (df["period_s"] == PERIOD_S) & ~df["extrapolate"]]
        bad = d[d["broken"]]
        first = f"D = {bad.delay_max_s.min():g} s" if len(bad) else f"none up to D = {worst:g} s"
        frag = d[d["fragmented"]]
        first_frag = f"D = {frag.delay_max_s.min():g} s" if len(frag) else "none"
        print(f"{mode}, T = {PERIOD_S:g} s: first broken {first}; first fragmented {first_frag}")
    print(f"\nwrote {out}/delay_sweep.csv, delay_sweep.png, trajectories.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
