"""Why mixed runs differed with a long SUMO action step for the CAVs, and what remains
(README, How CAV commands reach SUMO).

The TUM ring (``experiments/scenarios/tum_ring.toml``) with a share of CAVs, run three ways,
each in its own process, the runs of one seed side by side:

* ``every_step``  what ``cosim run`` does with human drivers in the demand: the CAVs' SUMO
                  action step is one step;
* ``long``        the CAVs' action step is ``scenario.cav_action_step_s`` (1 s) although
                  SUMO's drivers share the road (what the runner does not do), SUMO's
                  Euler update kept (``--step-method.ballistic false``, as the runner
                  passes it);
* ``ballistic``   the same without that option: SUMO then switches every vehicle to the
                  ballistic update as soon as one has an action step longer than a step
                  (``MSVehicleType::check``; its warning is hidden by ``--no-warnings``),
                  what every long-action-step run did before the option was passed.

The runner picks the action step inside ``cosim.sim.runner.build_world``; this diagnostic
swaps ``cosim.sumo.world.SumoWorld`` for a subclass that forces the variant (the CAVs' motion
commands are the same in all three).

Usage::

    .venv/bin/python benchmarks/action_step_humans.py                 # 10 % CAVs, seed 1
    .venv/bin/python benchmarks/action_step_humans.py --share 0.5 --seeds 1 2
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODES = ("every_step", "long", "ballistic")


def child(mode: str, share: float, seed: int, duration_s: float, warmup_s: float) -> dict:
    import cosim.sumo.world as sumo_world
    from cosim.config.scenario import load_scenario
    from cosim.sim.runner import run_scenario

    SumoWorld = sumo_world.SumoWorld

    class Forced(SumoWorld):
        def __init__(self, net, sumo_args, *args, cav_action_step_s=None, **kw):
            dt = kw.get("dt", 0.1)
            asl = dt if mode == "every_step" else 1.0
            if mode == "ballistic":  # SUMO's default: it picks the update itself
                i = sumo_args.index("--step-method.ballistic")
                sumo_args = sumo_args[:i] + sumo_args[i + 2:]
            super().__init__(net, sumo_args, *args, cav_action_step_s=asl, **kw)

    sumo_world.SumoWorld = Forced  # build_world imports it from the module at call time
    sc = load_scenario("tum_ring", {"demand.cav_share": share, "scenario.seed": seed,
                                    "scenario.duration_s": duration_s,
                                    "scenario.warmup_s": warmup_s})
    s = run_scenario(sc).summary.iloc[0]
    return {"mode": mode, "seed": seed, "flow_vph": float(s["edie_flow_vph"]),
            "speed_mps": float(s["space_mean_speed_mps"]),
            "collisions_cav": sum(int(s[k]) for k in ("collisions_sumo_cav",
                                                      "collisions_geometric_cav")
                                  if s.get(k) is not None and s[k] == s[k])}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--share", type=float, default=0.1, help="CAV share (default 0.1)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--duration", type=float, default=600.0, help="s (default 600)")
    ap.add_argument("--warmup", type=float, default=300.0, help="s (default 300)")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ns = ap.parse_args(argv)
    if ns.child is not None:
        print("RESULT " + json.dumps(child(**json.loads(ns.child))))
        return 0
    if not 0.0 < ns.share < 1.0:
        print("error: --share must lie strictly between 0 and 1 (humans and CAVs)")
        return 2
    print(f"TUM ring, {100 * ns.share:g} % CAVs, {ns.duration:g} s after {ns.warmup:g} s "
          "warm-up (Edie flow over the measured part)")
    print(f"{'seed':>5}{'mode':>12}{'flow veh/h':>12}{'speed m/s':>11}{'CAV coll.':>11}")
    for seed in ns.seeds:
        procs = [subprocess.Popen(
            [sys.executable, __file__, "--child", json.dumps(
                {"mode": m, "share": ns.share, "seed": seed, "duration_s": ns.duration,
                 "warmup_s": ns.warmup})], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True, cwd=ROOT) for m in MODES]
        for p in procs:
            out, err = p.communicate()
            if p.returncode != 0:
                print(f"error: a run failed: {err.strip().splitlines()[-1:]}")
                return 1
            r = json.loads(out.strip().splitlines()[-1][len("RESULT "):])
            print(f"{seed:>5}{r['mode']:>12}{r['flow_vph']:>12.0f}{r['speed_mps']:>11.2f}"
                  f"{r['collisions_cav']:>11}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
