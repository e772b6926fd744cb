"""Lane-free driving on roads a user draws: generated user-style roads, checked.

Usage::

    python -m experiments.user_road_checks                 # full: 3 seeds per arm
    python -m experiments.user_road_checks --smoke         # 1 seed, short runs
    python -m experiments.user_road_checks --evaluate-only # judge an existing folder again
    options: --out DIR (default outputs/user_road_checks[_smoke]), --workers N,
             --set KEY=VALUE (every run; repeatable, as cosim run --set)

Every road is drawn by :mod:`cosim.road.user_roads` from its seed (seeds 101-103: not
the ones the law or the adapter were tuned on) and built with netconvert's defaults from
plain ``.nod.xml`` / ``.edg.xml``, as a user builds one (``network.kind = "file"``). The
runs go through the sweep machinery (one process per run, resumable). Arms:

=============================  ==========================================================
``CLASS/cavNN``                every road class (``step-left``, ``step-right``,
                               ``step-centre``, ``taper``, ``s_curve``, ``bend``,
                               ``long_junction``, ``lane_drop``) at 100, 60 and 40 % CAVs
                               (the rest SUMO's calibrated SL2015 drivers); 5 000 veh/h at
                               100 % (more than a 6.2-7.6 m neck carries: a queue and a
                               zipper in front of it), 4 000 veh/h in mixed traffic
``step-left-sublaneW/cav0``    SUMO's drivers alone on ``step-left`` at a fixed sublane
                               width W of 0.8, 0.4 and 0.2 m (4 000 veh/h): what the
                               automatic choice chooses from (reported, not judged)
``CLASS-obstacle/cavNN``       a stopped car (5 m x 2 m) in the narrow section of
                               ``step-left`` and ``s_curve``, on the right or left half
                               (drawn): 2 000 veh/h at 100, 60 and 0 % CAVs (0 %: SUMO's
                               drivers alone on the same road and seed: where they
                               deadlock without CAVs the table shows it). 2 000 veh/h is
                               below what the one file beside the car carries, so that a
                               standstill there is a deadlock, not the tail of a queue
                               that grows with the demand (at 3 000 veh/h it does)
=============================  ==========================================================

360 s per run (180 s in the smoke form), measured after 60 s in 30 s intervals; SUMO's
sublane width is chosen from the road and the obstacle (``scenario.lateral_resolution_m =
"auto"``). Checks (every seed):

* arms with CAVs: no collision involving a CAV, SUMO's check and ours; no CAV-step outside
  the road;
* arms with at least 50 % CAVs: no vehicle stands still longer than 30 s, no 30 s window
  without flow while traffic waits (``blocked_windows``); on the obstacle arms no CAV
  stands still longer than 30 s and no window is blocked, and the longest standstill of
  SUMO's drivers is reported beside that of the same road and seed without CAVs (there a
  SUMO driver alone behind the stopped car stood up to 35 s before it moved out).

Reported beside them: flow (veh/h), the safety layer's edge interventions per CAV-km (the
law should not lean on it), the share of CAV-steps with |acceleration| > 3 m/s² (comfort),
the sublane width used. Outputs in ``--out``: the sweep (``results.csv``, ``runs/``),
``checks.csv``, ``arms.csv``, ``checks.md``; the drawn sources and nets in ``--out`` +
``_nets``. Exit status 0 when every check passes, 1 when one fails, 2 on a usage error.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from cosim.errors import ConfigError
from experiments import check_cli
from experiments.check_cli import numbers
from experiments.lanefree_checks import _markdown

SEEDS = (101, 102, 103)
#: road arms: name -> (user_roads class, alignment)
ROADS = {"step-left": ("step", "left"), "step-right": ("step", "right"),
         "step-centre": ("step", "centre"), "taper": ("taper", None),
         "s_curve": ("s_curve", None), "bend": ("bend", None),
         "long_junction": ("long_junction", None), "lane_drop": ("lane_drop", None)}
SHARES_PCT = (100, 60, 40)
OBSTACLE_ROADS = ("step-left", "s_curve")
OBSTACLE_SHARES_PCT = (100, 60, 0)
OBSTACLE_LENGTH_M, OBSTACLE_WIDTH_M = 5.0, 2.0
#: SUMO's drivers alone on ``step-left`` at fixed sublane widths (m): what "auto" chooses
#: from (reported, not judged)
SUBLANE_WIDTHS_M = (0.8, 0.4, 0.2)
#: demand, veh/h: at 100 % CAVs more than the neck carries; mixed traffic; obstacle arms
INFLOW_ALL_CAV_VPH, INFLOW_MIXED_VPH, INFLOW_OBSTACLE_VPH = 5000.0, 4000.0, 2000.0
DURATION_S, SMOKE_DURATION_S, WARMUP_S, INTERVAL_S = 360.0, 180.0, 60.0, 30.0
STANDSTILL_MAX_S = 30.0


def _road(name: str, seed: int, obstacle: bool):
    from cosim.road.user_roads import draw

    kind, align = ROADS[name]
    return draw(kind, seed, align, obstacle)


def _obstacle_place(road, net_file: Path) -> tuple[float, float]:
    """The stopped car's centre (s, d), m: at the drawn fraction of the narrow edge, its
    side 0.3 m from the road's edge."""
    from cosim.road.frame import load_road_network

    net = load_road_network(net_file, kind="file", main_route=road.route)
    edge, frac, side = road.obstacle
    span = next(sp for sp in net.edge_spans if sp[0] == edge)
    s = span[1] + frac * (span[2] - span[1])
    right, left = net.edges_at(np.array([s - 3.0, s, s + 3.0]))
    margin = 0.3 + 0.5 * OBSTACLE_WIDTH_M
    d = float(right.max()) + margin if side == "right" else float(left.min()) - margin
    return float(s), d


def nets_folder(out: Path) -> Path:
    """Where the drawn roads' sources and nets go: beside ``out`` (the sweep folder holds
    the sweep alone)."""
    return out.parent / f"{out.name}_nets"


def build_nets(out: Path, smoke: bool) -> dict[str, dict]:
    """Draw and build every road of the plan; returns variant name -> overrides."""
    from cosim.road.user_roads import build

    nets = nets_folder(out)
    seeds = SEEDS[:1] if smoke else SEEDS
    variants: dict[str, dict] = {}
    arms = [(n, p, False, None) for n in ROADS for p in SHARES_PCT]
    arms += [(n, p, True, None) for n in OBSTACLE_ROADS for p in OBSTACLE_SHARES_PCT]
    arms += [("step-left", 0, False, r) for r in SUBLANE_WIDTHS_M]
    for name, pct, obstacle, sublane in arms:
        for seed in seeds:
            road = _road(name, seed, obstacle)
            net_file = (nets / f"{road.name}.net.xml").resolve()
            if not net_file.is_file():
                build(road, nets)
            inflow = (INFLOW_OBSTACLE_VPH if obstacle else
                      INFLOW_ALL_CAV_VPH if pct == 100 else INFLOW_MIXED_VPH)
            ov = {"network.kind": "file", "network.net_file": str(net_file),
                  "network.route_edges": list(road.route), "demand.inflow_vph": inflow,
                  "demand.cav_share": pct / 100.0, "scenario.seed": seed,
                  "outputs.zone_start_m": max(0.0, road.narrow_from_m - 300.0),
                  "outputs.zone_end_m": road.narrow_to_m + 100.0,
                  "outputs.cross_sections_m": [max(50.0, road.narrow_from_m - 200.0),
                                               0.5 * (road.narrow_from_m + road.narrow_to_m),
                                               road.narrow_to_m + 50.0]}
            if pct == 0:
                ov["controller.kind"] = "sumo"
            if obstacle:
                s, d = _obstacle_place(road, net_file)
                ov.update({"obstacle.s_m": s, "obstacle.d_m": d,
                           "obstacle.length_m": OBSTACLE_LENGTH_M,
                           "obstacle.width_m": OBSTACLE_WIDTH_M})
            if sublane is not None:
                ov["scenario.lateral_resolution_m"] = sublane
            tag = "-obstacle" if obstacle else f"-sublane{sublane:g}" if sublane else ""
            arm = f"{name}{tag}/cav{pct}"
            variants[f"{arm}#{seed}"] = ov
    return variants


def plan_data(variants: dict[str, dict], smoke: bool) -> dict:
    duration = SMOKE_DURATION_S if smoke else DURATION_S
    return {
        "sweep": {"name": "user_road_checks" + ("_smoke" if smoke else ""), "base": "default",
                  "description": "lane-free driving on user-drawn roads"},
        "overrides": {"scenario.name": "user_road_checks", "controller.kind": "flocking",
                      "outputs.sumo_collisions": True, "scenario.duration_s": duration,
                      "scenario.warmup_s": WARMUP_S, "scenario.interval_s": INTERVAL_S,
                      "scenario.lateral_resolution_m": "auto"},
        "variants": [{"name": k, **v} for k, v in variants.items()],
    }


def share_of(arm: str) -> int:
    return int(arm.rsplit("/cav", 1)[1])


def evaluate(results: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(checks, arms): one row per (arm, check) with the worst seed and whether every seed
    passed; one row per arm with the reported figures (means over seeds)."""
    checks, arms = [], []
    for arm, pct, ok, failed, cav_coll in check_cli.runs_by_arm(results, share_of):
        crit = []
        if pct > 0:
            crit += [("CAV collisions (SUMO + ours)", cav_coll, 0.0, "events"),
                     ("CAV steps outside the road", numbers(ok, "boundary_vehicle_steps_cav"),
                      0.0, "CAV-steps")]
        if pct >= 50:
            which = ("CAVs' longest standstill", "max_standstill_cav_s") \
                if "-obstacle" in arm else ("longest standstill", "max_standstill_s")
            crit += [(which[0], numbers(ok, which[1]), STANDSTILL_MAX_S, "s"),
                     ("blocked 30 s windows", numbers(ok, "blocked_windows"), 0.0, "windows")]
        checks += check_cli.check_rows(arm, crit, len(ok), failed)
        cav_km = numbers(ok, "cav_vehicle_km")
        edge = numbers(ok, "safety_edge_activations")
        arms.append({
            "arm": arm, "n_runs": len(ok),
            "flow_vph": np.nanmean(numbers(ok, "edie_flow_vph")) if len(ok) else math.nan,
            "cav_collisions_max": np.nanmax(cav_coll) if pct > 0 and len(ok) else math.nan,
            "longest_standstill_s_max": np.nanmax(numbers(ok, "max_standstill_s"))
            if len(ok) else math.nan,
            "longest_standstill_cav_s_max": np.nanmax(numbers(ok, "max_standstill_cav_s"))
            if len(ok) and pct > 0 else math.nan,
            "longest_standstill_hdv_s_max": np.nanmax(numbers(ok, "max_standstill_hdv_s"))
            if len(ok) and pct < 100 else math.nan,
            "blocked_windows_max": np.nanmax(numbers(ok, "blocked_windows")) if len(ok)
            else math.nan,
            "edge_interventions_per_cav_km": float(np.nansum(edge) / np.nansum(cav_km))
            if pct > 0 and np.nansum(cav_km) > 0 else math.nan,
            "harsh_accel_share_cav": np.nanmean(numbers(ok, "harsh_accel_share_cav"))
            if pct > 0 and len(ok) else math.nan,
            "sublane_m": np.nanmax(numbers(ok, "sumo_lateral_resolution_m")) if len(ok)
            else math.nan,
        })
    return pd.DataFrame(checks), pd.DataFrame(arms)


def report(sweep_dir: Path, smoke: bool) -> int:
    from cosim.analysis.tables import load_results

    results = load_results(sweep_dir).table
    if "variant" not in results:
        raise ConfigError(f"{sweep_dir}: not a user_road_checks folder (no variant column)")
    checks, arms = evaluate(results)
    checks.to_csv(sweep_dir / "checks.csv", index=False)
    arms.to_csv(sweep_dir / "arms.csv", index=False)
    cmd = "python -m experiments.user_road_checks" + (" --smoke" if smoke else "")
    text = [f"# Lane-free driving on user-drawn roads{' (smoke)' if smoke else ''}",
            "", f"Runs: `{sweep_dir}/results.csv`. Command: `{cmd}`.", "", "## Arms", "",
            _markdown(arms), "## Checks", "", _markdown(checks)]
    (sweep_dir / "checks.md").write_text("\n".join(text))
    print(arms.round(3).to_string(index=False))
    failed = checks[~checks["passed"]]
    if not failed.empty:
        print("\nfailed checks:")
        print(failed[["arm", "check", "worst_seed", "criterion", "note"]].to_string(index=False))
    print(f"\n{len(checks) - len(failed)} of {len(checks)} checks passed; "
          f"tables in {sweep_dir}/ (checks.md)")
    return 0 if failed.empty else 1


def main(argv: list[str] | None = None) -> int:
    return check_cli.main(argv, "user_road_checks", __doc__,
                          lambda out, smoke: plan_data(build_nets(out, smoke), smoke), report)


if __name__ == "__main__":
    sys.exit(main())
