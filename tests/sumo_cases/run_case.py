"""Run one scenario with :func:`cosim.sim.runner.run_scenario` (one per process).

Usage: ``python run_case.py OUT_DIR SCENARIO_JSON``; ``SCENARIO_JSON`` is the nested
dict :func:`cosim.config.scenario_from_dict` takes. Prints one line ``RESULT <json>``:
the summary row, the number of ``<vehicle>`` elements in the route file written, and
(when trajectories are on) what the per-step trajectories say about the vehicles.
"""

from __future__ import annotations

import json
import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from cosim.config.scenario import scenario_from_dict
from cosim.sim.runner import run_scenario


def _plain(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if hasattr(v, "item"):
        return _plain(v.item())
    return v


def main(out_dir: str, spec: str) -> dict:
    sc = scenario_from_dict(json.loads(spec))
    res = run_scenario(sc, out_dir=out_dir)
    summary = {k: _plain(v) for k, v in res.summary.iloc[0].to_dict().items()}
    routes = ET.parse(Path(out_dir) / "routes.rou.xml").getroot()
    route_ids = [v.get("id") for v in routes.iter("vehicle")]
    out = {"summary": summary, "n_routes": len(route_ids),
           "road_length_m": res.meta["network"]["length_m"],
           "speed_limit_mps": sc.network.speed_limit_mps,
           "dt": sc.scenario.step_length_s,
           "sumo_cav_action_step_s": res.meta["sumo_cav_action_step_s"]}
    tr = res.trajectories
    if tr is not None:
        t_end = float(tr["t_s"].max())
        last = tr.sort_values("t_s").groupby("id").last()
        left = last[last["t_s"] < t_end - 1e-9]
        out["traj"] = {
            "t_end": t_end,
            "distinct_ids": int(tr["id"].nunique()),
            "ids_not_in_routes": sorted(set(tr["id"]) - set(route_ids)),
            "running_at_end": int((tr["t_s"] > t_end - 1e-9).sum()),
            "left_early": len(left),
            # front bumper of every vehicle that left before the end, at its last step
            "left_min_front_m": float((left["s_m"] + 0.5 * left["length_m"]).min())
            if len(left) else None,
        }
    return out


if __name__ == "__main__":
    print("RESULT " + json.dumps(main(sys.argv[1], sys.argv[2])))
