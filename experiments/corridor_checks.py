"""The freeway corridor, checked: CAVs reach their exit, weave, merge, in mixed traffic.

Usage::

    python -m experiments.corridor_checks                 # full: 3 seeds per arm
    python -m experiments.corridor_checks --smoke         # 1 seed, short runs
    python -m experiments.corridor_checks --evaluate-only # judge an existing folder again
    options: --out DIR (default outputs/corridor_checks[_smoke]), --workers N,
             --set KEY=VALUE (every run; repeatable, as cosim run --set)

The built-in ``corridor`` scenario (``experiments/scenarios/corridor.toml``: a 3.5 km,
10.2 m lane-free mainline; a 3 m on-ramp strip of 482 m from 1 000 m; a 676 m weaving
section; a 3 m off-ramp strip of 342 m to the gore at 2 500 m) with an origin-destination
demand of 6 000 veh/h (:data:`OD_VPH`: 4 300 main -> main, 700 main -> off-ramp, 750
on-ramp -> main, 250 on-ramp -> off-ramp). Arms (seeds 1-3, not the scenario's default 42
on which the law's exit parameters were chosen):

==========================  ============================================================
``corridor/cavNN``          100, 70 and 40 % CAVs (the flocking law), the rest SUMO's
                            calibrated SL2015 drivers
``corridor/sl2015``         SUMO's SL2015 drivers alone on the same lane-free corridor
``corridor-3lane/lc2013``   SUMO's LC2013 drivers alone on the corridor with three
                            3.4 m lanes (``network.lanes = 3``)
``freeway-K/cavNN``         a user's freeway with two on-ramps and two off-ramps drawn
                            from seed K (1-4; :func:`cosim.road.user_roads.draw_freeway`:
                            netconvert's defaults, 9.6 m, strips of 120-300 m, weaving
                            sections of 150-600 m; none of them the one the weaving rules
                            were found on) at 100, 70 and 40 % CAVs, with the OD demand
                            :data:`FREEWAY_OD_VPH` (4 400 veh/h), demand seed K
==========================  ============================================================

600 s per run (240 s in the smoke form), measured after 120 s in 60 s intervals; the
measurement zone is the weaving section (1 490-2 150 m; on a freeway its first one).
Checks (every seed):

* arms with CAVs: no collision involving a CAV (SUMO's check and ours), no CAV-step off
  the road, no CAV that missed its exit or took one not its own, and the SUMO world's
  exit backstop (it re-routes a CAV still on the wrong lane at the gore) never acted;
* arms with at least 50 % CAVs: no vehicle stands still longer than 30 s, no 60 s window
  without flow while traffic waits.

Reported beside them (means over seeds): the weaving section's flow (Edie, veh/h) and
space-mean speed (m/s), the mean travel time per origin -> destination (s), human drivers'
missed exits (SUMO's drivers: re-routed at the gore when they have not reached the exit's
lane, as a driver who misses an exit drives on), harsh accelerations, the safety layer's
interventions per CAV-km. Outputs in ``--out``: the sweep (``results.csv``, ``runs/``),
``checks.csv``, ``arms.csv``, ``checks.md``. Exit status 0 when every check passes, 1 when
one fails, 2 on a usage error.
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

SEEDS = (1, 2, 3)
SHARES_PCT = (100, 70, 40)
#: origin -> destination demand, veh/h (6 000 in all)
OD_VPH = (("main", "main", 4300.0), ("main", "off", 700.0), ("ramp", "main", 750.0),
          ("ramp", "off", 250.0))
DURATION_S, SMOKE_DURATION_S, WARMUP_S, INTERVAL_S = 600.0, 240.0, 120.0, 60.0
STANDSTILL_MAX_S = 30.0
OD_PAIRS = ("main_main", "main_off", "ramp_main", "ramp_off")
#: the user freeways' seeds (each its own drawing and demand seed) and their OD demand,
#: veh/h (4 400 in all; every pair the road connects: the second on-ramp joins after the
#: first off-ramp)
FREEWAY_SEEDS = (1, 2, 3, 4)
FREEWAY_OD_VPH = (("main", "main", 2200.0), ("main", "off", 400.0), ("main", "off2", 400.0),
                  ("ramp", "main", 400.0), ("ramp", "off", 200.0), ("ramp", "off2", 200.0),
                  ("ramp2", "main", 400.0), ("ramp2", "off2", 200.0))


def variants(smoke: bool) -> dict[str, dict]:
    """Variant name (``ARM#SEED``) -> overrides of the ``corridor`` scenario."""
    seeds = SEEDS[:1] if smoke else SEEDS
    arms: dict[str, dict] = {f"corridor/cav{p}": {"demand.cav_share": p / 100.0}
                             for p in SHARES_PCT}
    arms["corridor/sl2015"] = {"demand.cav_share": 0.0, "controller.kind": "sumo"}
    arms["corridor-3lane/lc2013"] = {"demand.cav_share": 0.0, "controller.kind": "sumo",
                                     "network.lanes": 3}
    return {f"{arm}#{seed}": {**ov, "scenario.seed": seed}
            for arm, ov in arms.items() for seed in seeds}


def freeway_variants(out: Path, smoke: bool) -> dict[str, dict]:
    """Variant name -> overrides of the user freeways (drawn and built with netconvert's
    defaults into ``out`` + ``_nets``)."""
    from cosim.road.user_roads import build, draw_freeway

    nets = out.parent / f"{out.name}_nets"
    found = {}
    for seed in FREEWAY_SEEDS[:1] if smoke else FREEWAY_SEEDS:
        road = draw_freeway(seed)
        net_file = (nets / f"{road.name}.net.xml").resolve()
        if not net_file.is_file():
            build(road, nets)
        for pct in SHARES_PCT:
            found[f"freeway-{seed}/cav{pct}#{seed}"] = {
                "network.kind": "file", "network.net_file": str(net_file),
                "network.route_edges": list(road.route),
                "network.ramp_edges": [list(r) for r in road.ramps],
                "network.offramp_edges": [list(r) for r in road.offramps],
                "demand.od_vph": [list(r) for r in FREEWAY_OD_VPH],
                "demand.cav_share": pct / 100.0, "scenario.seed": seed,
                "outputs.zone_start_m": road.narrow_from_m,
                "outputs.zone_end_m": road.narrow_to_m,
                "outputs.cross_sections_m": [0.5 * (road.narrow_from_m + road.narrow_to_m)]}
    return found


def plan_data(out: Path, smoke: bool) -> dict:
    duration = SMOKE_DURATION_S if smoke else DURATION_S
    return {
        "sweep": {"name": "corridor_checks" + ("_smoke" if smoke else ""),
                  "base": "corridor", "description": "freeway corridor checks"},
        "overrides": {"demand.od_vph": [list(r) for r in OD_VPH],
                      "outputs.sumo_collisions": True, "scenario.duration_s": duration,
                      "scenario.warmup_s": WARMUP_S, "scenario.interval_s": INTERVAL_S},
        "variants": [{"name": k, **v} for k, v in {**variants(smoke),
                                                     **freeway_variants(out, smoke)}.items()],
    }


def share_of(arm: str) -> int:
    return int(arm.rsplit("/cav", 1)[1]) if "/cav" in arm else 0


def _mean(vals: np.ndarray) -> float:
    return float(np.nanmean(vals)) if np.isfinite(vals).any() else math.nan


def evaluate(results: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(checks, arms): one row per (arm, check) with the worst seed and whether every seed
    passed; one row per arm with the reported figures (means over seeds)."""
    checks, arms = [], []
    for arm, pct, ok, failed, cav_coll in check_cli.runs_by_arm(results, share_of):
        crit = []
        if pct > 0:
            exits = (numbers(ok, "missed_exits_cav") + numbers(ok, "wrong_exits_cav")
                     + numbers(ok, "exit_backstop_cav"))
            crit += [("CAV collisions (SUMO + ours)", cav_coll, 0.0, "events"),
                     ("CAV steps outside the road", numbers(ok, "boundary_vehicle_steps_cav"),
                      0.0, "CAV-steps"),
                     ("CAV exits missed, wrong or by the backstop", exits, 0.0, "CAVs")]
        if pct >= 50:
            crit += [("longest standstill", numbers(ok, "max_standstill_s"), STANDSTILL_MAX_S,
                      "s"),
                     ("blocked windows", numbers(ok, "blocked_windows"), 0.0, "windows")]
        checks += check_cli.check_rows(arm, crit, len(ok), failed)
        cav_km = numbers(ok, "cav_vehicle_km")
        activations = sum(numbers(ok, f"safety_{rule}_activations")
                          for rule in ("edge", "side", "speed"))
        row = {"arm": arm, "n_runs": len(ok),
               "weaving_flow_vph": _mean(numbers(ok, "edie_flow_vph")),
               "weaving_speed_mps": _mean(numbers(ok, "space_mean_speed_mps")),
               "cav_collisions_max": np.nanmax(cav_coll) if pct > 0 and len(ok) else math.nan,
               "hdv_missed_exits": _mean(numbers(ok, "missed_exits_hdv")) if pct < 100
               else math.nan,
               "longest_standstill_s_max": np.nanmax(numbers(ok, "max_standstill_s"))
               if len(ok) else math.nan}
        for od in OD_PAIRS:
            row[f"travel_time_{od}_s"] = _mean(numbers(ok, f"travel_time_{od}_s"))
        row["harsh_accel_share_cav"] = _mean(numbers(ok, "harsh_accel_share_cav")) if pct else \
            math.nan
        row["safety_per_cav_km"] = (float(np.nansum(activations) / np.nansum(cav_km))
                                    if pct > 0 and np.nansum(cav_km) > 0 else math.nan)
        arms.append(row)
    return pd.DataFrame(checks), pd.DataFrame(arms)


def report(sweep_dir: Path, smoke: bool) -> int:
    from cosim.analysis.tables import load_results

    results = load_results(sweep_dir).table
    if "variant" not in results:
        raise ConfigError(f"{sweep_dir}: not a corridor_checks folder (no variant column)")
    checks, arms = evaluate(results)
    checks.to_csv(sweep_dir / "checks.csv", index=False)
    arms.to_csv(sweep_dir / "arms.csv", index=False)
    cmd = "python -m experiments.corridor_checks" + (" --smoke" if smoke else "")
    text = [f"# Freeway corridor{' (smoke)' if smoke else ''}", "",
            f"Runs: `{sweep_dir}/results.csv`. Command: `{cmd}`.", "", "## Arms", "",
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
    return check_cli.main(argv, "corridor_checks", __doc__, plan_data, report)


if __name__ == "__main__":
    sys.exit(main())
