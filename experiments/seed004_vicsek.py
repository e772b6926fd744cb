"""Seed 004: Vicsek-style alignment with noise; metric time series, noise dependence, heatmaps.

Usage::

    python experiments/seed004_vicsek.py [--smoke] [--out DIR] [--jobs J]

Writes to ``--out`` (default ``outputs/seed004``), all CSV tables in long ("tidy") form:

* ``timeseries.csv`` / ``timeseries.png``: the report's parameters (N = 100,
  100 m x 100 m wrap-around, r = 10 m, 1 s steps) for both update rules
  (``vicsek``: v0 = 0.5 m/s, eta = 0.1 rad; ``seed004``: velocity_matching 0.5,
  noise_factor 0.1 m/s), several seeds; columns: rule, seed, step, t (s),
  order_parameter, velocity_alignment, local_alignment (-), avg_nn_distance (m),
  dispersion (m), mean_speed (m/s);
* ``noise.csv`` / ``noise.png``: stationary metrics against the noise (eta for
  ``vicsek``, noise_factor sigma for ``seed004``);
* ``heatmap_noise_density.*``, ``heatmap_noise_radius.*`` (``vicsek`` rule; density
  varied through the domain side at N = 100, as the report varies the space width) and
  ``heatmap_seed004_noise_matching.*`` (the report's own parameters sigma x alpha).

"Stationary" = mean over the last quarter of the run (samples every 10 steps).
"""

from __future__ import annotations

import argparse
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from controllers.plane.vicsek import VicsekModel, VicsekParams  # noqa: E402

METRICS = (
    "order_parameter",
    "velocity_alignment",
    "local_alignment",
    "avg_nn_distance",
    "dispersion",
    "mean_speed",
)
LABELS = {
    "eta": "eta (rad)",
    "density": "density N/L^2 (1/m^2)",
    "r": "radius r (m)",
    "sigma": "noise_factor sigma (m/s)",
    "alpha": "velocity_matching alpha (-)",
}
REPORT = VicsekParams(n=100, L=100.0, r=10.0, v0=0.5, dt=1.0, periodic=True)  # Step 1a


def rule_params(rule: str) -> VicsekParams:
    """The report's setting with the low-noise value of each rule."""
    if rule == "vicsek":
        return replace(REPORT, rule="vicsek", eta=0.1)
    return replace(REPORT, rule="seed004", alpha=0.5, sigma=0.1)


def stationary(params: VicsekParams, seed: int, n_steps: int) -> dict[str, float]:
    """Metrics averaged over the last quarter of an ``n_steps`` run (samples every 10 steps)."""
    df = VicsekModel(params, seed=seed).run(n_steps, record_every=10)
    tail = df[df.step >= 0.75 * n_steps]
    row = {k: v for k, v in asdict(params).items()}
    row.update({"seed": seed, "density": params.density, "n_steps": n_steps})
    row.update({m: float(tail[m].mean()) for m in METRICS})
    return row


def _stationary_job(args: tuple[VicsekParams, int, int]) -> dict[str, float]:
    return stationary(*args)


def run_grid(jobs: list[tuple[VicsekParams, int, int]], workers: int) -> pd.DataFrame:
    """Run ``stationary`` for every job, in parallel processes if ``workers`` > 1."""
    if workers <= 1:
        return pd.DataFrame([stationary(*j) for j in jobs])
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return pd.DataFrame(list(pool.map(_stationary_job, jobs, chunksize=2)))


def time_series(out: Path, n_steps: int, seeds: int) -> pd.DataFrame:
    """Metric time series at the report's parameters for both rules."""
    frames = []
    for rule in ("vicsek", "seed004"):
        for seed in range(seeds):
            df = VicsekModel(rule_params(rule), seed=seed).run(n_steps)
            df.insert(0, "seed", seed)
            df.insert(0, "rule", rule)
            frames.append(df)
    ts = pd.concat(frames, ignore_index=True)
    ts.to_csv(out / "timeseries.csv", index=False)
    panels = ("order_parameter", "local_alignment", "avg_nn_distance", "dispersion")
    units = ("phi (-)", "local alignment (-)", "avg NN distance (m)", "dispersion (m)")
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 9), sharex=True)
    for ax, col, lab in zip(axes, panels, units, strict=True):
        for rule, grp in ts.groupby("rule"):
            mean = grp.groupby("step")[col].mean()
            ax.plot(mean.index, mean.values, label=rule)
            for _, g in grp.groupby("seed"):
                ax.plot(g.step, g[col], lw=0.4, alpha=0.3, color=ax.lines[-1].get_color())
        ax.axvline(100, color="k", lw=0.5, ls=":")
        ax.set_ylabel(lab)
    axes[0].axhline(0.9, color="grey", lw=0.5, ls="--")
    axes[0].legend()
    axes[-1].set_xlabel("time step (1 s)")
    axes[0].set_title("Report parameters: N=100, 100 m x 100 m, r=10 m (mean and seeds)")
    fig.tight_layout()
    fig.savefig(out / "timeseries.png", dpi=120)
    plt.close(fig)
    return ts


def consensus_table(ts: pd.DataFrame) -> pd.DataFrame:
    """Per rule: first step with phi > 0.9 per seed; phi and local alignment at 10, 50, 100."""
    rows = []
    for rule, grp in ts.groupby("rule"):
        firsts = []
        for _, g in grp.groupby("seed"):
            above = g.step[g.order_parameter > 0.9]
            firsts.append(int(above.iloc[0]) if len(above) else np.nan)
        row = {"rule": rule, "first_phi>0.9": firsts}
        for k in (10, 50, 100):
            at = grp[grp.step == k]
            if len(at):
                row[f"phi@{k}"] = at.order_parameter.mean()
                row[f"local@{k}"] = at.local_alignment.mean()
        rows.append(row)
    return pd.DataFrame(rows)


def noise_dependence(out: Path, n_steps: int, seeds: int, etas, sigmas, workers) -> pd.DataFrame:
    """Stationary metrics against the noise for both rules."""
    params = [replace(rule_params("vicsek"), eta=float(e)) for e in etas]
    params += [replace(rule_params("seed004"), sigma=float(x)) for x in sigmas]
    jobs = [(p, seed, n_steps) for p in params for seed in range(seeds)]
    df = run_grid(jobs, workers)
    df.to_csv(out / "noise.csv", index=False)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    v = df[df.rule == "vicsek"].groupby("eta")[["order_parameter", "local_alignment"]].mean()
    axes[0].plot(v.index, v.order_parameter, "o-", label="phi (global)")
    axes[0].plot(v.index, v.local_alignment, "s--", label="local alignment")
    axes[0].set(xlabel="eta (rad)", ylabel="stationary value (-)", title="rule vicsek")
    axes[0].legend()
    s = df[df.rule == "seed004"].groupby("sigma")[["order_parameter", "mean_speed"]].mean()
    axes[1].semilogx(s.index, s.order_parameter, "o-", label="phi (global)")
    axes[1].set(xlabel="noise_factor sigma (m/s)", ylabel="phi (-)", title="rule seed004")
    axes[1].set_ylim(0.0, 1.0)
    ax2 = axes[1].twinx()
    ax2.loglog(s.index, s.mean_speed, "r^--", label="mean speed")
    ax2.set_ylabel("mean speed (m/s)", color="r")
    fig.tight_layout()
    fig.savefig(out / "noise.png", dpi=120)
    plt.close(fig)
    return df


def heatmap(out: Path, name: str, df: pd.DataFrame, x: str, y: str, metric: str, title: str):
    """Write ``name``.csv (tidy) and ``name``.png (mean of ``metric`` over seeds)."""
    df.to_csv(out / f"{name}.csv", index=False)
    grid = df.groupby([y, x])[metric].mean().unstack(x)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    im = ax.imshow(grid.values, origin="lower", aspect="auto", vmin=0, vmax=1, cmap="viridis")
    ax.set_xticks(range(grid.shape[1]), [f"{c:.3g}" for c in grid.columns], rotation=45)
    ax.set_yticks(range(grid.shape[0]), [f"{r:.3g}" for r in grid.index])
    for (i, j), val in np.ndenumerate(grid.values):
        ax.text(j, i, f"{val:.2f}", ha="center", va="center", fontsize=7, color="w")
    ax.set(xlabel=LABELS.get(x, x), ylabel=LABELS.get(y, y), title=title)
    fig.colorbar(im, ax=ax, label=metric)
    fig.tight_layout()
    fig.savefig(out / f"{name}.png", dpi=120)
    plt.close(fig)
    return grid


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--smoke", action="store_true", help="short run (a few seconds)")
    ap.add_argument("--out", type=Path, default=Path("outputs/seed004"), help="output directory")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes")
    args = ap.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    smoke = args.smoke
    workers = 1 if smoke else max(1, args.jobs)

    n_ts, seeds = (100, 2) if smoke else (300, 5)
    n_st, st_seeds = (60, 1) if smoke else (300, 3)
    etas = np.linspace(0, 2 * np.pi, 3 if smoke else 9)
    sigmas = [0.1, 5.0] if smoke else [0.01, 0.1, 0.5, 1.0, 5.0]
    sides = [50.0, 100.0, 200.0] if smoke else [50.0, 71.0, 100.0, 141.0, 200.0, 400.0]
    radii = [5.0, 10.0] if smoke else [2.5, 5.0, 10.0, 15.0, 20.0]
    alphas = [0.1, 0.9] if smoke else [0.1, 0.3, 0.5, 0.7, 0.9, 1.0]

    ts = time_series(out, n_ts, seeds)
    print("Report parameters (N=100, L=100 m, r=10 m), metrics by step:")
    with pd.option_context("display.width", 140, "display.float_format", "{:.3f}".format):
        print(consensus_table(ts).to_string(index=False))

    nd = noise_dependence(out, n_st, st_seeds, etas, sigmas, workers)
    print(f"\nStationary order parameter vs noise ({n_st} steps, {st_seeds} seeds):")
    v = nd[nd.rule == "vicsek"].groupby("eta").order_parameter.mean()
    print("  vicsek  eta (rad): " + "  ".join(f"{e:.2f}->{p:.2f}" for e, p in v.items()))
    s = nd[nd.rule == "seed004"].groupby("sigma")[["order_parameter", "mean_speed"]].mean()
    cells = [f"{k:g}->phi {r.order_parameter:.2f}, |v| {r.mean_speed:.2f}" for k, r in s.iterrows()]
    print("  seed004 sigma (m/s): " + "  ".join(cells))

    base = rule_params("vicsek")
    hm_eta = etas[::2] if not smoke else etas
    jobs = [
        (replace(base, eta=float(e), L=L), sd, n_st) for e in hm_eta for L in sides
        for sd in range(st_seeds)
    ]  # fmt: skip
    dens = run_grid(jobs, workers)
    heatmap(out, "heatmap_noise_density", dens, "density", "eta", "order_parameter",
            "vicsek: stationary phi, N=100, r=10 m")  # fmt: skip
    jobs = [
        (replace(base, eta=float(e), r=r), sd, n_st) for e in hm_eta for r in radii
        for sd in range(st_seeds)
    ]  # fmt: skip
    rad = run_grid(jobs, workers)
    heatmap(out, "heatmap_noise_radius", rad, "r", "eta", "order_parameter",
            "vicsek: stationary phi, N=100, L=100 m")  # fmt: skip
    b4 = rule_params("seed004")
    jobs = [
        (replace(b4, sigma=float(x), alpha=float(a)), sd, n_st) for x in sigmas for a in alphas
        for sd in range(st_seeds)
    ]  # fmt: skip
    sm = run_grid(jobs, workers)
    heatmap(out, "heatmap_seed004_noise_matching", sm, "alpha", "sigma", "order_parameter",
            "seed004: stationary phi, N=100, L=100 m, r=10 m")  # fmt: skip
    print(f"\nheatmaps: {len(dens) + len(rad) + len(sm)} runs; outputs in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
