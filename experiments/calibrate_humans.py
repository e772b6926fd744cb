"""Calibrate and check SUMO's human drivers (HDVs): lane-free SL2015 and three-lane LC2013.

The HDV vTypes are written by ``cosim.demand.routes.vtype_lines`` from the ``HDV_*``
constants of ``cosim.demand.spec``; this script measures what they do and prints one table.

Measurements (SUMO 1.28, step 0.1 s; every SUMO run in its own process, one at a time):

1. **Lane capacity (LC2013)**: a 1 km ring of three 3.4 m lanes built here with netconvert,
   HDVs only (the scenario's size classes and desired speeds U(25, 35) m/s), placed evenly
   at t = 0. There is no entrance, so the road alone sets the flow: Edie's flow per lane
   (total distance travelled / (ring length x time x 3)) after the warm-up, for several
   densities; the capacity is the maximum over densities of the mean over seeds.
2. **Stopped obstacle (SL2015)**: a 1 km x 10.2 m road, a stopped vehicle 5 m x 3.4 m at
   s = 550 m, d = -3.4 m (the right third), 4 000 veh/h of HDVs; the
   longest standstill, vehicles stopped > 30 s, the smallest 30 s flow past the obstacle
   (cross-section 562.5 m), collisions and boundary violations.
3. **TUM LaneFreeDrive's ring (SL2015)**: ``cosim run tum_ring`` with HDVs only and SUMO
   driving (1 km x 10.2 m, TUM's five car sizes): Edie's flow at 225 veh/km (TUM's
   strip-based human model: 6 613 veh/h) and at two lower densities.
4. **Lateral gaps at speed**: from the trajectories of runs 2 and 3 and (full run only) of
   an open road at 8 000 veh/h, sampled every 1 s after the warm-up (open roads: in the
   measurement zone): for every vehicle the nearest vehicle alongside (bodies overlap
   longitudinally, not laterally) on each side, the lateral clearance by the vehicle's
   speed; and the share of vehicle-samples with 3 or more vehicles abreast (driving four
   abreast). On open roads the entrance's insertion slots (2.55 m apart) set the rows at
   high flow: SL2015 has no way to fall back behind a neighbour to open a lateral gap.

Measurement noise: the seeds' spread is in the table; flows on the TUM ring are one seed
of 300 s after a 300 s warm-up (their drift, last / first interval - 1, is printed).

SUMO 1.28 limitations found while calibrating (see cosim/demand/spec.py): minGapLat cannot
grow with speed; lcMaxSpeedLatStanding / lcMaxSpeedLatFactor have no effect on SL2015
lateral speeds; lcImpatience < 0 is refused; SL2015 does not anticipate a width drop
(lcStrategic 1, 5 and 20 give identical runs) and HDV-only traffic at 8 000 veh/h jams
for good at a 10.2 -> 6.8 m narrowing, before and after this calibration.

Usage::

    python experiments/calibrate_humans.py               # the full table, about 2 min
    python experiments/calibrate_humans.py --smoke       # one seed, short runs, about 20 s
    python experiments/calibrate_humans.py --sumo-defaults   # SUMO's drivers before calibration
    python experiments/calibrate_humans.py --hdv-attrs '{"minGapLat": 1.2}'   # try a change
    python experiments/calibrate_humans.py --out DIR     # also write DIR/calibrate_humans.csv

``--hdv-attrs`` overrides attributes of every ``hdv_<k>`` vType (a JSON object; null
removes an attribute), for exploring; the shipped values are those of ``cosim.demand.spec``.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: The human drivers before calibration (``--sumo-defaults``): SUMO's default tau (1 s),
#: the project's former minGapLat (0.5 m; SUMO's default is 0.6 m) and SUMO's defaults for
#: pushiness (0), assertiveness (1) and impatience (none).
SUMO_DEFAULT_HDV = {"tau": "1.0", "minGapLat": "0.5", "lcPushy": None, "lcAssertive": None,
                    "lcTimeToImpatience": None}

#: The obstacle case (HDVs only).
OBSTACLE_CASE = {
    "demand.cav_share": 0.0, "demand.inflow_vph": 4000.0,
    "obstacle.s_m": 550.0, "obstacle.d_m": -3.4, "obstacle.length_m": 5.0,
    "obstacle.width_m": 3.4, "outputs.zone_start_m": 100.0, "outputs.zone_end_m": 900.0,
    "scenario.interval_s": 30.0,
}
#: Cross-section just past the obstacle's front (the runner adds it: s + length / 2 + 10 m).
OBSTACLE_SECTION = "flow_x562.5_vph"

#: Lateral gap summary speed bands, m/s.
SPEED_BANDS = ((0.0, 5.0), (5.0, 15.0), (15.0, 22.0), (22.0, 60.0))

TUM_HUMAN_VPH = 6613.0  # TUM's strip-based human model on their 225 veh/km ring, veh/h


# --------------------------------------------------------------------------------------
# vType overrides (exploration)
# --------------------------------------------------------------------------------------


def patch_hdv_vtypes(attrs: dict | None) -> None:
    """Make ``vtype_lines`` set (or, for None, remove) ``attrs`` on every ``hdv_`` vType."""
    if not attrs:
        return
    import cosim.demand.routes as routes

    original = routes.vtype_lines

    def patched(demand, lanes):
        out = []
        for line in original(demand, lanes):
            if 'id="hdv_' in line:
                head, tail = line.split(">", 1)
                for key, value in attrs.items():
                    head = re.sub(rf' {key}="[^"]*"', "", head)
                    if value is not None:
                        head += f' {key}="{value}"'
                line = head + ">" + tail
            out.append(line)
        return out

    routes.vtype_lines = patched


# --------------------------------------------------------------------------------------
# Lateral gaps
# --------------------------------------------------------------------------------------


def side_gaps(traj: pd.DataFrame, t0_s: float, every_s: float = 1.0,
              period_m: float | None = None, exclude: tuple[str, ...] = ("obstacle",)):
    """Lateral clearance to the nearest vehicle alongside on each side, per vehicle-sample.

    A vehicle is alongside the ego when their bodies overlap longitudinally but not
    laterally (SUMO tolerates 1 mm overlaps, its NUMERICAL_EPS); it is abreast when its body
    also covers the ego's mid-length.

    Args:
        traj: trajectories (t_s, id, s_m front, d_m centre, v_mps, length_m, width_m).
        t0_s: first time used, s; every_s: sampling interval, s.
        period_m: ring circumference (s wraps), m; None on open roads.

    Returns:
        gap_m (G,) and gap_speed_mps (G,): the clearance to the nearest vehicle alongside on
        a side and the ego's speed, one entry per side that has one; speed_mps (M,) and
        n_abreast (M,): per vehicle-sample, its speed and the vehicles abreast of it.
    """
    t = traj[(traj["t_s"] >= t0_s) & ~traj["id"].isin(exclude)]
    times = np.unique(t["t_s"].to_numpy())
    gaps, gap_speeds, speeds, abreast = [], [], [], []
    if len(times) == 0:
        return (np.empty(0),) * 3 + (np.empty(0, dtype=int),)
    step = float(np.median(np.diff(times))) if len(times) > 1 else every_s
    keep = np.round(times[:: max(1, round(every_s / step))], 6)
    t = t[np.isin(np.round(t["t_s"].to_numpy(), 6), keep)]
    for _, g in t.groupby("t_s"):
        c = (g["s_m"] - 0.5 * g["length_m"]).to_numpy()
        o = np.argsort(c)
        c = c[o]
        d, w = g["d_m"].to_numpy()[o], g["width_m"].to_numpy()[o]
        length, v = g["length_m"].to_numpy()[o], g["v_mps"].to_numpy()[o]
        n = len(c)
        if period_m:
            cc, ix = np.concatenate([c - period_m, c, c + period_m]), np.tile(np.arange(n), 3)
        else:
            cc, ix = c, np.arange(n)
        lo = np.searchsorted(cc, c - length.max(), side="left")
        hi = np.searchsorted(cc, c + length.max(), side="right")
        for i in range(n):
            js, ds = ix[lo[i]:hi[i]], cc[lo[i]:hi[i]] - c[i]
            m = (js != i) & (np.abs(ds) < 0.5 * (length[i] + length[js]))
            js, ds = js[m], ds[m]
            gap = np.abs(d[js] - d[i]) - 0.5 * (w[i] + w[js])
            beside = gap > -1e-3
            speeds.append(float(v[i]))
            abreast.append(int(np.sum(beside & (np.abs(ds) < 0.5 * length[js]))))
            for sign in (1.0, -1.0):
                side = beside & (np.sign(d[js] - d[i]) == sign)
                if side.any():
                    gaps.append(float(gap[side].min()))
                    gap_speeds.append(float(v[i]))
    return np.array(gaps), np.array(gap_speeds), np.array(speeds), np.array(abreast)


def gap_rows(case: str, gaps: np.ndarray, gap_speeds: np.ndarray, speeds: np.ndarray,
             abreast: np.ndarray) -> list[dict]:
    """One row per speed band with at least 20 clearances: clearance percentiles (m), the
    share of clearances under 0.5 m and the share of vehicle-samples driving four (or
    more) abreast."""
    rows = []
    for lo, hi in SPEED_BANDS:
        m = (gap_speeds >= lo) & (gap_speeds < hi)
        if m.sum() < 20:
            continue
        p5, p25, p50 = np.percentile(gaps[m], [5, 25, 50])
        mv = (speeds >= lo) & (speeds < hi)
        rows.append({"case": case, "speed_band_mps": f"{lo:g}-{hi:g}", "n": int(m.sum()),
                     "gap_p5_m": p5, "gap_p25_m": p25, "gap_p50_m": p50,
                     "share_below_0.5m": float(np.mean(gaps[m] < 0.5)),
                     "share_four_abreast": float(np.mean(abreast[mv] >= 3))})
    return rows


# --------------------------------------------------------------------------------------
# Child tasks (one SUMO per process)
# --------------------------------------------------------------------------------------


def _cosim_task(task: dict) -> dict:
    from cosim.config.scenario import load_scenario
    from cosim.sim.runner import run_scenario

    sc = load_scenario(task.get("scenario"), task["overrides"])
    res = run_scenario(sc)
    s = res.summary.iloc[0].to_dict()
    out = {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in s.items()
           if isinstance(v, (int, float, str, bool, np.integer, np.floating))}
    out = {k: (v.item() if hasattr(v, "item") else v) for k, v in out.items()}
    iv = res.intervals
    out["interval_flows_vph"] = iv["edie_flow_vph"].round(0).tolist()
    section = task.get("section")
    if section and section in iv:
        out["section_flows_vph"] = iv[section].round(0).tolist()
    if task.get("gaps") and res.trajectories is not None:
        period, traj = task.get("period_m"), res.trajectories
        if period is None:  # open road: the measurement zone only (not the entrance)
            traj = traj[(traj["s_m"] >= sc.outputs.zone_start_m)
                        & (traj["s_m"] <= (sc.outputs.zone_end_m or math.inf))]
        arrays = side_gaps(traj, sc.scenario.warmup_s, 1.0, period)
        out["gap_rows"] = gap_rows(task["gaps"], *arrays)
    return out


def _lane_ring_task(task: dict) -> dict:
    """Three-lane LC2013 ring: Edie flow per lane after the warm-up (no entrance)."""
    import libsumo

    from cosim.demand.routes import vtype_lines
    from cosim.demand.spec import DemandSpec
    from cosim.sumo.binaries import netconvert_binary

    length, lanes, lane_w = task["length_m"], task["lanes"], task["lane_width_m"]
    duration, warm, seed = task["duration_s"], task["warmup_s"], task["seed"]
    n_edges, arc = 10, 8
    work = Path(tempfile.mkdtemp(prefix="lanering_"))
    half = math.pi / (n_edges * arc)  # chord polygon: SUMO measures the polygon
    radius = length / (2 * math.pi) * half / math.sin(half)
    nodes, edges = [], []
    for i in range(n_edges):
        a = 2 * math.pi * i / n_edges
        nodes.append(f'<node id="r{i}" x="{radius * math.cos(a):.4f}" '
                     f'y="{radius * math.sin(a):.4f}" type="priority"/>')
        ang = np.linspace(a, 2 * math.pi * (i + 1) / n_edges, arc + 1)
        shape = " ".join(f"{radius * math.cos(x):.4f},{radius * math.sin(x):.4f}" for x in ang)
        edges.append(f'<edge id="e{i}" from="r{i}" to="r{(i + 1) % n_edges}" '
                     f'numLanes="{lanes}" width="{lane_w}" speed="40" shape="{shape}"/>')
    (work / "r.nod.xml").write_text("<nodes>\n" + "\n".join(nodes) + "\n</nodes>\n")
    (work / "r.edg.xml").write_text("<edges>\n" + "\n".join(edges) + "\n</edges>\n")
    subprocess.run([str(netconvert_binary()), "-n", str(work / "r.nod.xml"),
                    "-e", str(work / "r.edg.xml"), "-o", str(work / "r.net.xml"),
                    "--no-turnarounds", "true", "--no-internal-links", "true"],
                   check=True, capture_output=True)
    demand = DemandSpec()
    rng = np.random.default_rng(seed)
    n_lane = round(task["k_lane_vpkm"] * length / 1000.0)
    edge_len = length / n_edges
    lines = ["<routes>", *vtype_lines(demand, lanes=True)]
    for i in range(n_edges):
        route = " ".join(f"e{(i + j) % n_edges}" for j in range(n_edges))
        lines.append(f'<route id="r{i}" edges="{route}" '
                     f'repeat="{int(duration * 40 / length) + 2}"/>')
    vid = 0
    for lane in range(lanes):
        offset = rng.uniform(0, length / n_lane)
        for j in range(n_lane):
            s = (offset + (j + lane / lanes) * length / n_lane) % length
            e = int(s // edge_len)
            pos = min(s - e * edge_len + 0.1, edge_len - 0.1)
            cls = rng.choice(len(demand.size_classes), p=demand.class_probabilities)
            v0 = rng.uniform(*demand.desired_speed_mps)
            lines.append(f'<vehicle id="v{vid}" type="hdv_{cls}" route="r{e}" depart="0" '
                         f'departLane="{lane}" departPos="{pos:.2f}" departSpeed="0" '
                         f'speedFactor="{v0 / 40:.5f}" insertionChecks="none"/>')
            vid += 1
    lines.append("</routes>")
    (work / "r.rou.xml").write_text("\n".join(lines) + "\n")
    libsumo.start(["sumo", "-n", str(work / "r.net.xml"), "-r", str(work / "r.rou.xml"),
                   "--step-length", "0.1", "--seed", str(seed), "--no-step-log", "true",
                   "--no-warnings", "true", "--collision.action", "warn",
                   "--collision.mingap-factor", "0", "--time-to-teleport", "-1",
                   "--end", str(duration)])
    dt, dist, collisions = 0.1, 0.0, 0
    for step in range(round(duration / dt)):
        libsumo.simulationStep()
        collisions += libsumo.simulation.getCollidingVehiclesNumber()
        if (step + 1) * dt > warm + 1e-9:
            dist += dt * sum(libsumo.vehicle.getSpeed(x) for x in libsumo.vehicle.getIDList())
    n = libsumo.vehicle.getIDCount()
    libsumo.close()
    hours = (duration - warm) / 3600.0
    return {"k_lane_vpkm": n / lanes / (length / 1000.0),
            "q_lane_vph": dist / 1000.0 / (length / 1000.0) / hours / lanes,
            "v_mps": dist / (n * (duration - warm)), "collision_vehicles": collisions}


def child_main(task: dict) -> None:
    patch_hdv_vtypes(task.get("hdv_attrs"))
    fn = {"cosim": _cosim_task, "lane_ring": _lane_ring_task}[task["kind"]]
    print("RESULT " + json.dumps(fn(task), default=str))


def run_child(task: dict, timeout_s: float = 1800.0) -> dict:
    """Run ``task`` in a fresh interpreter (libsumo holds one simulation per process)."""
    proc = subprocess.run([sys.executable, __file__, "--child", json.dumps(task)],
                          capture_output=True, text=True, timeout=timeout_s, cwd=ROOT)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        raise SystemExit(f"error: child run failed ({task['kind']}): "
                         f"{(proc.stderr.strip().splitlines() or ['?'])[-1]}")
    return json.loads(lines[-1][len("RESULT "):])


# --------------------------------------------------------------------------------------
# The measurements
# --------------------------------------------------------------------------------------


def measure(smoke: bool, seeds: int, attrs: dict | None, log) -> dict[str, pd.DataFrame]:
    """Run every measurement; returns the tables (lane, obstacle, ring, gaps)."""
    dur = {"lane": (180.0, 90.0) if smoke else (600.0, 300.0),
           "obstacle": (180.0, 90.0) if smoke else (300.0, 120.0),
           "ring": (150.0, 90.0) if smoke else (600.0, 300.0)}
    seed_list = list(range(1, 1 + (1 if smoke else seeds)))
    gap_tables = []

    # 1. Lane capacity on a three-lane ring (LC2013).
    lane_rows = []
    for k in ([24.0, 30.0] if smoke else [18.0, 21.0, 24.0, 27.0, 30.0, 34.0]):
        for seed in seed_list:
            r = run_child({"kind": "lane_ring", "k_lane_vpkm": k, "seed": seed,
                           "length_m": 1000.0, "lanes": 3, "lane_width_m": 3.4,
                           "duration_s": dur["lane"][0], "warmup_s": dur["lane"][1],
                           "hdv_attrs": attrs})
            lane_rows.append({"k_lane_vpkm": k, "seed": seed, **r})
            log(f"lane ring k={k:g} veh/km/lane seed {seed}: {r['q_lane_vph']:.0f} veh/h/lane")
    lane = pd.DataFrame(lane_rows)

    # 2. Stopped obstacle (HDVs only).
    obs_rows = []
    for seed in seed_list:
        ov = {**OBSTACLE_CASE, "scenario.seed": seed, "scenario.duration_s": dur["obstacle"][0],
              "scenario.warmup_s": dur["obstacle"][1],
              "outputs.trajectories": seed == seed_list[0], "outputs.trajectory_every": 10}
        r = run_child({"kind": "cosim", "scenario": None, "overrides": ov,
                       "section": OBSTACLE_SECTION, "hdv_attrs": attrs,
                       "gaps": "obstacle" if seed == seed_list[0] else None})
        gap_tables += r.pop("gap_rows", [])
        sec = r.get("section_flows_vph") or [float("nan")]
        obs_rows.append({
            "seed": seed, "max_standstill_s": r["max_standstill_s"],
            "stopped_over_30s": r["vehicles_stopped_long"], "min_flow_past_30s_vph": min(sec),
            "mean_flow_past_vph": float(np.mean(sec)),
            "collisions_sumo/ours": _collisions(r),
            "boundary_veh_steps": r["boundary_vehicle_steps"],
            "not_inserted": r["vehicles_not_inserted"]})
        log(f"obstacle seed {seed}: longest standstill {r['max_standstill_s']:.1f} s")
    obstacle = pd.DataFrame(obs_rows)

    # 3. TUM's ring at 225 veh/km and two lower densities (HDVs only, SUMO drives).
    ring_rows = []
    for k in ([225.0] if smoke else [225.0, 120.0, 50.0]):
        ov = {"demand.cav_share": 0.0, "controller.kind": "sumo",
              "demand.ring_density_vpkm": k, "scenario.seed": seed_list[0],
              "scenario.duration_s": dur["ring"][0], "scenario.warmup_s": dur["ring"][1],
              "scenario.interval_s": 30.0 if smoke else 60.0,
              "outputs.sumo_collisions": True,
              "outputs.trajectories": True, "outputs.trajectory_every": 10}
        r = run_child({"kind": "cosim", "scenario": "tum_ring", "overrides": ov,
                       "period_m": 1000.0, "hdv_attrs": attrs, "gaps": f"ring {k:g}"})
        gap_tables += r.pop("gap_rows", [])
        flows = r["interval_flows_vph"]
        ring_rows.append({"k_vpkm": k, "flow_vph": r["edie_flow_vph"],
                          "speed_mps": r["space_mean_speed_mps"],
                          "drift": flows[-1] / flows[0] - 1.0 if flows and flows[0] else None,
                          "collisions_sumo/ours": _collisions(r),
                          "boundary_veh_steps": r["boundary_vehicle_steps"]})
        log(f"TUM ring {k:g} veh/km: {r['edie_flow_vph']:.0f} veh/h")
    ring = pd.DataFrame(ring_rows)

    # 4. Lateral gaps on the open road at 8 000 veh/h (the entrance's slots set the rows).
    if not smoke:
        ov = {"demand.cav_share": 0.0, "demand.inflow_vph": 8000.0, "scenario.seed": 1,
              "scenario.duration_s": 240.0, "scenario.warmup_s": 90.0,
              "outputs.zone_start_m": 100.0, "outputs.zone_end_m": 900.0,
              "outputs.trajectories": True, "outputs.trajectory_every": 10}
        r = run_child({"kind": "cosim", "scenario": None, "overrides": ov, "hdv_attrs": attrs,
                       "gaps": "open road 8000 veh/h"})
        gap_tables += r.pop("gap_rows", [])
        log(f"open road 8000 veh/h: {r['edie_flow_vph']:.0f} veh/h, collisions {_collisions(r)}")
    return {"lane": lane, "obstacle": obstacle, "ring": ring, "gaps": pd.DataFrame(gap_tables)}


def _collisions(r: dict) -> str:
    """Collision events as "SUMO's / ours (geometric overlap)", all vehicle kinds."""
    sumo = sum(r.get(k) or 0 for k in ("collisions_sumo_cav", "collisions_sumo_hdv_only"))
    ours = sum(r.get(k) or 0 for k in ("collisions_geometric_cav",
                                       "collisions_geometric_hdv_only"))
    return f"{int(sumo)}/{int(ours)}"


def print_tables(t: dict[str, pd.DataFrame]) -> None:
    lane = t["lane"].groupby("k_lane_vpkm")[["q_lane_vph", "v_mps", "collision_vehicles"]]
    lane = lane.agg({"q_lane_vph": ["mean", "min", "max"], "v_mps": "mean",
                     "collision_vehicles": "sum"})
    lane.columns = ["q_lane_mean_vph", "q_lane_min_vph", "q_lane_max_vph", "v_mps",
                    "collision_vehicles"]
    best = lane["q_lane_mean_vph"].idxmax()
    print("\n1. Lane capacity: 1 km ring of three 3.4 m lanes, LC2013 (no entrance; Edie flow"
          " per lane after the warm-up; seeds' mean, min, max)")
    print(lane.round(1).to_string())
    print(f"   capacity per lane: {lane.loc[best, 'q_lane_mean_vph']:.0f} veh/h at "
          f"{best:g} veh/km/lane (target 2 000-2 400 veh/h)")
    print("\n2. Stopped obstacle 5 m x 3.4 m on a 10.2 m road, 4 000 veh/h of HDVs "
          "(targets: standstill <= 30 s, flow past > 0 in every 30 s, no collisions)")
    print(t["obstacle"].round(1).to_string(index=False))
    print(f"\n3. TUM's ring (1 km x 10.2 m), HDVs only; TUM's humans: {TUM_HUMAN_VPH:.0f} veh/h "
          "at 225 veh/km")
    print(t["ring"].round(3).to_string(index=False))
    print("\n4. Lateral clearance to the nearest vehicle alongside on each side, by own speed, "
          "after the warm-up (share_four_abreast: vehicle-samples with >= 3 vehicles abreast)")
    print(t["gaps"].round(3).to_string(index=False))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--smoke", action="store_true", help="one seed, short runs (about 20 s)")
    ap.add_argument("--seeds", type=int, default=3, help="seeds of the lane and obstacle runs")
    ap.add_argument("--sumo-defaults", action="store_true",
                    help="measure the drivers before calibration (tau 1 s, minGapLat 0.5 m, "
                         "no lcPushy/lcAssertive/lcTimeToImpatience)")
    ap.add_argument("--hdv-attrs", default=None, help="JSON object of hdv vType attributes")
    ap.add_argument("--out", default=None, help="folder for calibrate_humans.csv")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ns = ap.parse_args(argv)
    if ns.child is not None:
        child_main(json.loads(ns.child))
        return 0
    if ns.seeds < 1:
        print("error: --seeds must be >= 1", file=sys.stderr)
        return 2
    attrs = dict(SUMO_DEFAULT_HDV) if ns.sumo_defaults else {}
    if ns.hdv_attrs:
        try:
            extra = json.loads(ns.hdv_attrs)
        except json.JSONDecodeError as exc:
            print(f"error: --hdv-attrs is not JSON: {exc}", file=sys.stderr)
            return 2
        if not isinstance(extra, dict):
            print("error: --hdv-attrs must be a JSON object", file=sys.stderr)
            return 2
        attrs.update(extra)
    t0 = time.perf_counter()
    tables = measure(ns.smoke, ns.seeds, attrs or None,
                     lambda msg: print(f"  [{time.perf_counter() - t0:5.0f} s] {msg}",
                                       flush=True))
    print_tables(tables)
    print(f"\n(wall time {time.perf_counter() - t0:.0f} s; HDV overrides: {attrs or 'none'})")
    if ns.out:
        out = Path(ns.out)
        out.mkdir(parents=True, exist_ok=True)
        rows = pd.concat([df.assign(table=name) for name, df in tables.items()],
                         ignore_index=True)
        rows.to_csv(out / "calibrate_humans.csv", index=False)
        print(f"written {out / 'calibrate_humans.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
