"""Lateral resolution (SUMO sublane width): what it costs and what it changes.

For ``--lateral-resolution`` 0.2, 0.4, 0.8 and 1.6 m, on mixed traffic (50 %
CAVs under flocking control, 50 % SL2015 human drivers with
``latAlignment="arbitrary"``), the same route file per seed:

* cost: process CPU time of the co-simulated run (``run_scenario``) and of
  the plain ``sumo`` binary driving every vehicle itself on the same route
  file and options, both as a ratio to 0.8 m (the default, RunSpec in
  cosim/config.py), median over seeds (runs interleaved, one process each);
* results: Edie flow, density and space-mean speed in the zone, minimum
  bumper gap (all / CAV), minimum side clearance, median time headway,
  collisions (SUMO's and geometric), boundary violations, insertions;
* HDV (and CAV) lateral behaviour from trajectories sampled every 0.5 s after
  warm-up: mean |lateral speed|, share of samples moving sideways (> 0.1 m/s),
  lateral travel per km driven, overtakes per 100 vehicle-km, side clearance
  to vehicles beside (median, 5th percentile).

Scenario: straight 1 km x 10.2 m road, 4000 veh/h, desired speeds 25-35 m/s,
180 s with 60 s warm-up, seeds 1-3 (``--quick``: 120 s, seeds 1-2).

Results are means over seeds with the seed-to-seed spread (std), so a change
can be told from noise; the route file (demand) depends only on the seed, so
each seed is a paired comparison across resolutions.

Usage::

    .venv/bin/python benchmarks/bench_lateral_resolution.py           # 3 seeds, ~3-5 min
    .venv/bin/python benchmarks/bench_lateral_resolution.py --quick   # 2 seeds, ~1.5-2 min
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from bench_cosim import _children_cpu, plain_sumo_cmd, run_plain  # noqa: E402

RESOLUTIONS = (0.2, 0.4, 0.8, 1.6)
DEFAULT_RES = 0.8
FULL = {"length_m": 1000.0, "duration_s": 180.0, "warmup_s": 60.0, "interval_s": 30.0,
        "inflow_vph": 4000.0, "cav_share": 0.5, "seeds": (1, 2, 3)}
QUICK = {"length_m": 1000.0, "duration_s": 120.0, "warmup_s": 60.0, "interval_s": 30.0,
         "inflow_vph": 4000.0, "cav_share": 0.5, "seeds": (1, 2)}
SAMPLE_EVERY = 5  # trajectory sample every 5 steps (0.5 s)

SUMMARY_KEYS = (
    "edie_flow_vph", "edie_density_vpkm", "space_mean_speed_mps", "min_gap_m", "min_cav_gap_m",
    "min_side_clearance_m", "median_time_headway_s", "collisions_sumo_cav",
    "collisions_sumo_hdv_only", "collisions_geometric_cav", "collisions_geometric_hdv_only",
    "boundary_vehicle_steps", "vehicles_inserted", "vehicles_not_inserted", "teleports",
    "vehicle_steps",
)


def scenario_spec(case: dict, res: float, seed: int) -> dict:
    return {
        "scenario": {"name": f"latres_{res:g}", "seed": seed, "duration_s": case["duration_s"],
                     "warmup_s": case["warmup_s"], "interval_s": case["interval_s"],
                     "lateral_resolution_m": res},
        "network": {"kind": "straight", "length_m": case["length_m"], "width_m": 10.2},
        "demand": {"inflow_vph": case["inflow_vph"], "cav_share": case["cav_share"]},
        "controller": {"kind": "flocking"},
        "outputs": {"trajectories": True, "trajectory_every": SAMPLE_EVERY},
    }


# --------------------------------------------------------------------------------------
# Child: one run + trajectory analysis
# --------------------------------------------------------------------------------------


def lateral_behaviour(tr, warmup_s: float, dt_sample: float) -> dict:
    """HDV (and CAV) lateral statistics from sampled trajectories after warm-up.

    * mean |lateral speed| (m/s) and share of samples moving sideways (> 0.1 m/s);
    * lateral travel per km driven (sum of |d change| between samples), m/km;
    * overtakes per 100 vehicle-km: vehicles that were ahead at one sample and
      behind at the next (all vehicles present at both samples);
    * side clearance to vehicles beside (longitudinal overlap, no lateral overlap):
      median and 5th percentile over vehicle-samples that have one, m.
    """
    import numpy as np

    tr = tr[tr["t_s"] > warmup_s]
    out: dict = {}
    times = np.sort(tr["t_s"].unique())
    by_t = {t: g for t, g in tr.groupby("t_s")}
    passes = {"hdv": 0, "cav": 0}
    side = {"hdv": [], "cav": []}
    for k, t in enumerate(times):
        g = by_t[t]
        s, d = g["s_m"].to_numpy(), g["d_m"].to_numpy()
        L, W = g["length_m"].to_numpy(), g["width_m"].to_numpy()
        cav = g["is_cav"].to_numpy().astype(bool)
        ds = np.abs(s[None, :] - s[:, None])
        sep = np.abs(d[None, :] - d[:, None]) - 0.5 * (W[:, None] + W[None, :])
        beside = (ds < 0.5 * (L[:, None] + L[None, :])) & (sep > 0)
        clr = np.where(beside, sep, np.inf).min(axis=1)
        for name, mask in (("hdv", ~cav), ("cav", cav)):
            c = clr[mask]
            side[name].append(c[np.isfinite(c)])
        if k + 1 < len(times) and abs(times[k + 1] - t - dt_sample) < 1e-6:
            h = by_t[times[k + 1]]
            common = g[["id", "s_m", "is_cav"]].merge(h[["id", "s_m"]], on="id",
                                                       suffixes=("_0", "_1"))
            s0, s1 = common["s_m_0"].to_numpy(), common["s_m_1"].to_numpy()
            passed = (s0[None, :] > s0[:, None]) & (s1[None, :] < s1[:, None])  # [i, j]
            n_pass = passed.sum(axis=1)
            c_cav = common["is_cav"].to_numpy().astype(bool)
            passes["hdv"] += int(n_pass[~c_cav].sum())
            passes["cav"] += int(n_pass[c_cav].sum())
    tr = tr.sort_values(["id", "t_s"])
    for name, part in (("hdv", tr[~tr["is_cav"].astype(bool)]),
                       ("cav", tr[tr["is_cav"].astype(bool)])):
        if part.empty:
            continue
        g = part.groupby("id", sort=False)
        consecutive = (g["t_s"].diff() - dt_sample).abs() < 1e-6
        km = float(g["s_m"].diff()[consecutive].sum()) / 1000.0
        out[f"{name}_mean_abs_vlat_mps"] = float(part["v_lat_mps"].abs().mean())
        out[f"{name}_share_moving_sideways"] = float((part["v_lat_mps"].abs() > 0.1).mean())
        out[f"{name}_lateral_m_per_km"] = (
            float(g["d_m"].diff().abs()[consecutive].sum()) / km if km else np.nan)
        out[f"{name}_overtakes_per_100km"] = 100.0 * passes[name] / km if km else np.nan
        c = np.concatenate(side[name]) if side[name] else np.empty(0)
        out[f"{name}_side_clearance_median_m"] = float(np.median(c)) if len(c) else np.nan
        out[f"{name}_side_clearance_p05_m"] = float(np.percentile(c, 5)) if len(c) else np.nan
        out[f"{name}_km"] = km
    return out


def child_main(payload: dict) -> dict:
    import numpy as np

    from cosim.config.scenario import scenario_from_dict
    from cosim.sim.runner import run_scenario
    from cosim.sumo.world import SumoWorld

    captured = {}
    start = SumoWorld.start

    def capture_start(self):
        captured["cmd"] = list(self.cmd)
        return start(self)

    SumoWorld.start = capture_start
    sc = scenario_from_dict(payload["spec"])
    w0, c0 = time.perf_counter(), time.process_time()
    res = run_scenario(sc, out_dir=payload["out"])
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    s = res.summary.iloc[0]
    summary = {}
    for k in SUMMARY_KEYS:
        v = s.get(k, np.nan)
        v = v.item() if hasattr(v, "item") else v
        summary[k] = None if isinstance(v, float) and not np.isfinite(v) else v
    lat = lateral_behaviour(res.trajectories, sc.scenario.warmup_s,
                            SAMPLE_EVERY * sc.scenario.step_length_s)
    return {"cpu_s": cpu, "wall_s": wall, "cmd": captured["cmd"], "summary": summary,
            "lateral": lat}


def run_child(payload: dict) -> dict:
    c0 = _children_cpu()
    proc = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(payload)],
        capture_output=True, text=True, check=False, timeout=1800,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"child failed:\n{proc.stderr[-4000:]}")
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    out = json.loads(line[len("RESULT "):])
    out["process_cpu_s"] = _children_cpu() - c0
    return out


# --------------------------------------------------------------------------------------
# Parent
# --------------------------------------------------------------------------------------


def _mean_std(xs):
    xs = [x for x in xs if x is not None]
    if not xs:
        return float("nan"), float("nan")
    return statistics.fmean(xs), (statistics.stdev(xs) if len(xs) > 1 else 0.0)


def run_all(case: dict, work: Path) -> dict:
    """{res: {seed: result}} with result = child output + plain sumo timing."""
    out: dict[float, dict[int, dict]] = {r: {} for r in RESOLUTIONS}
    for n, seed in enumerate(case["seeds"]):
        order = RESOLUTIONS[n % 4:] + RESOLUTIONS[: n % 4]  # rotate: interleave the load
        for res in order:
            d = work / f"r{res:g}_s{seed}"
            o = run_child({"spec": scenario_spec(case, res, seed), "out": str(d)})
            routes = work / f"routes_s{seed}_r{res:g}.rou.xml"
            shutil.copy(d / "routes.rou.xml", routes)
            cmd = plain_sumo_cmd(o["cmd"])
            cmd[cmd.index("-r") + 1] = str(routes)
            o["sumo"] = run_plain(cmd)
            shutil.rmtree(d, ignore_errors=True)
            out[res][seed] = o
            print(f"  seed {seed} res {res:g} m: co-sim CPU {o['cpu_s']:.2f} s, "
                  f"sumo CPU {o['sumo']['cpu_s']:.2f} s", flush=True)
    return out


ROWS = (
    # (label, getter, format)
    ("co-sim CPU s", lambda o: o["cpu_s"], "{:.2f}"),
    ("co-sim CPU / 0.8 m", None, "{:.2f}"),
    ("plain sumo CPU s", lambda o: o["sumo"]["cpu_s"], "{:.2f}"),
    ("plain sumo CPU / 0.8 m", None, "{:.2f}"),
    ("sumo veh-steps/s (CPU)", lambda o: o["sumo"]["vehicle_steps"] / o["sumo"]["cpu_s"]
     if o["sumo"]["vehicle_steps"] else None, "{:.0f}"),
    ("co-sim veh-steps/s (CPU)", lambda o: o["summary"]["vehicle_steps"] / o["cpu_s"], "{:.0f}"),
    ("Edie flow veh/h", lambda o: o["summary"]["edie_flow_vph"], "{:.0f}"),
    ("Edie density veh/km", lambda o: o["summary"]["edie_density_vpkm"], "{:.2f}"),
    ("space-mean speed m/s", lambda o: o["summary"]["space_mean_speed_mps"], "{:.2f}"),
    ("min gap m (all)", lambda o: o["summary"]["min_gap_m"], "{:.2f}"),
    ("min gap m (CAV)", lambda o: o["summary"]["min_cav_gap_m"], "{:.2f}"),
    ("min side clearance m", lambda o: o["summary"]["min_side_clearance_m"], "{:.3f}"),
    ("median time headway s", lambda o: o["summary"]["median_time_headway_s"], "{:.2f}"),
    ("collisions SUMO (cav/hdv)", lambda o: (o["summary"]["collisions_sumo_cav"],
                                             o["summary"]["collisions_sumo_hdv_only"]), None),
    ("collisions geom (cav/hdv)", lambda o: (o["summary"]["collisions_geometric_cav"],
                                             o["summary"]["collisions_geometric_hdv_only"]), None),
    ("boundary veh-steps", lambda o: o["summary"]["boundary_vehicle_steps"], "{:.0f}"),
    ("not inserted", lambda o: o["summary"]["vehicles_not_inserted"], "{:.1f}"),
    ("HDV mean |v_lat| m/s", lambda o: o["lateral"].get("hdv_mean_abs_vlat_mps"), "{:.3f}"),
    ("HDV share moving sideways", lambda o: o["lateral"].get("hdv_share_moving_sideways"),
     "{:.3f}"),
    ("HDV lateral m per km", lambda o: o["lateral"].get("hdv_lateral_m_per_km"), "{:.1f}"),
    ("HDV overtakes per 100 veh-km", lambda o: o["lateral"].get("hdv_overtakes_per_100km"),
     "{:.1f}"),
    ("HDV side clearance median m",
     lambda o: o["lateral"].get("hdv_side_clearance_median_m"), "{:.2f}"),
    ("HDV side clearance p05 m", lambda o: o["lateral"].get("hdv_side_clearance_p05_m"),
     "{:.2f}"),
    ("CAV mean |v_lat| m/s", lambda o: o["lateral"].get("cav_mean_abs_vlat_mps"), "{:.3f}"),
    ("CAV overtakes per 100 veh-km", lambda o: o["lateral"].get("cav_overtakes_per_100km"),
     "{:.1f}"),
    ("CAV side clearance p05 m", lambda o: o["lateral"].get("cav_side_clearance_p05_m"),
     "{:.2f}"),
)


def print_table(results: dict, seeds) -> None:
    col = 17
    head = f"{'lateral resolution':<30}" + "".join(f"{f'{r:g} m':>{col}}" for r in RESOLUTIONS)
    print("\n" + head)
    print("-" * len(head))
    for label, get, fmt in ROWS:
        cells = []
        for r in RESOLUTIONS:
            runs = [results[r][s] for s in seeds]
            if label == "co-sim CPU / 0.8 m":
                ratios = [results[r][s]["cpu_s"] / results[DEFAULT_RES][s]["cpu_s"] for s in seeds]
                cells.append(f"x{statistics.median(ratios):.2f}")
                continue
            if label == "plain sumo CPU / 0.8 m":
                ratios = [results[r][s]["sumo"]["cpu_s"] / results[DEFAULT_RES][s]["sumo"]["cpu_s"]
                          for s in seeds]
                cells.append(f"x{statistics.median(ratios):.2f}")
                continue
            vals = [get(o) for o in runs]
            if fmt is None:  # pairs of counts: totals over seeds
                a = sum(v[0] for v in vals)
                b = sum(v[1] for v in vals)
                cells.append(f"{a}/{b}")
                continue
            m, sd = _mean_std(vals)
            cells.append(fmt.format(m) + (f" ±{fmt.format(sd).strip()}" if len(vals) > 1 else ""))
        print(f"{label:<30}" + "".join(f"{c:>{col}}" for c in cells))
    print(f"(mean ± std over seeds {list(seeds)}; ratios: median of per-seed ratios; "
          "collisions: totals over seeds)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 seeds, 120 s")
    ap.add_argument("--seeds", default=None, help="comma list of seeds")
    ap.add_argument("--inflow", type=float, default=None, help="veh/h")
    ap.add_argument("--duration", type=float, default=None, help="s")
    ap.add_argument("--json", type=Path, default=None, help="also write all results here")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child is not None:
        p = json.loads(a.child)
        print("RESULT " + json.dumps(child_main(p)))
        return 0
    case = dict(QUICK if a.quick else FULL)
    if a.seeds:
        case["seeds"] = tuple(int(x) for x in a.seeds.split(","))
    if a.inflow:
        case["inflow_vph"] = a.inflow
    if a.duration:
        case["duration_s"] = a.duration
    from cosim.sumo.binaries import sumo_version

    print(f"bench_lateral_resolution: {case['length_m']:g} m x 10.2 m, "
          f"{case['inflow_vph']:g} veh/h, {100 * case['cav_share']:g} % CAVs (flocking), "
          f"{case['duration_s']:g} s (warm-up {case['warmup_s']:g} s), seeds "
          f"{list(case['seeds'])}; SUMO {sumo_version()}; load {os.getloadavg()[0]:.1f}")
    work = Path(tempfile.mkdtemp(prefix="bench_latres_"))
    t0 = time.perf_counter()
    try:
        results = run_all(case, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print_table(results, case["seeds"])
    if a.json:
        a.json.write_text(json.dumps({str(r): v for r, v in results.items()}, indent=1))
    print(f"(total benchmark wall time {time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
