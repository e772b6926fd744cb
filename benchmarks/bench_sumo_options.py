"""What SUMO's own step costs on a lane-free road, and which options change it.

The plain ``sumo`` binary (no Python in the loop) drives every vehicle with SL2015
on a 2 km x 10.2 m road, the same route file (our demand, slot insertion) for all
variants:

* ``one edge``   : the road as one 2 km edge (``network.max_edge_length_m = 0``);
* ``100 m edges``: the road split into 20 edges of 100 m (the default);

each with ``--collision.action warn`` (SUMO checks collisions, ``outputs.sumo_collisions
= true``) and ``none`` (only our geometric check, the sweeps' setting).

Printed: CPU time per variant (median over seeds, runs interleaved) and the ratio to
``one edge / warn``; vehicles arrived and their mean travel time (tripinfo), which
should not depend on the options. Cost only: the co-simulation's other parts are
measured by ``bench_cosim.py``.

Usage::

    .venv/bin/python benchmarks/bench_sumo_options.py           # 12 000 veh/h, 180 s, 2 seeds
    .venv/bin/python benchmarks/bench_sumo_options.py --quick   # 120 s, 1 seed
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from bench_cosim import run_plain  # noqa: E402

from cosim.demand.routes import write_routes  # noqa: E402
from cosim.demand.spec import DemandSpec  # noqa: E402
from cosim.road.build import build_network  # noqa: E402
from cosim.road.spec import NetworkSpec  # noqa: E402
from cosim.sumo.binaries import sumo_binary, sumo_version  # noqa: E402

EDGES = {"one edge": 0.0, "100 m edges": 100.0}
COLLISION = ("warn", "none")


def _trips(path: Path) -> tuple[int, float]:
    """(vehicles arrived, mean travel time s) from a tripinfo file."""
    durations = [float(t.get("duration")) for t in ET.parse(path).getroot().iter("tripinfo")]
    return len(durations), statistics.fmean(durations) if durations else float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="120 s, one seed")
    ap.add_argument("--inflow", type=float, default=12000.0, help="demand, veh/h")
    ns = ap.parse_args()
    duration = 120.0 if ns.quick else 180.0
    seeds = (1,) if ns.quick else (1, 2)
    demand = DemandSpec(inflow_vph=ns.inflow, cav_share=0.0, duration_s=duration)
    print(f"bench_sumo_options: 2000 m x 10.2 m, {ns.inflow:.0f} veh/h, SL2015 drives all, "
          f"{duration:.0f} s, step 0.1 s, lateral resolution 0.8 m, seeds {list(seeds)}; "
          f"SUMO {sumo_version()}")
    nets = {name: build_network(NetworkSpec(kind="straight", length_m=2000.0,
                                            max_edge_length_m=m))
            for name, m in EDGES.items()}
    rows: dict[tuple[str, str], list[dict]] = {}
    with tempfile.TemporaryDirectory(prefix="bench_sumo_") as tmp:
        for seed in seeds:
            for name, net in nets.items():
                tag = f"{seed}_{len(net.main_route)}"
                routes = write_routes(net, demand, seed, Path(tmp) / f"{tag}.rou.xml")
                for coll in COLLISION:
                    trip = Path(tmp) / f"trip_{tag}_{coll}.xml"
                    cmd = [str(sumo_binary()), "-n", str(net.net_file), "-r", str(routes.path),
                           "--step-length", "0.1", "--lateral-resolution", "0.8",
                           "--collision.action", coll, "--collision.mingap-factor", "0",
                           "--seed", str(seed), "--begin", "0", "--end", f"{duration:g}",
                           "--no-step-log", "true", "--no-warnings", "true",
                           "--duration-log.statistics", "true", "--tripinfo-output", str(trip)]
                    r = run_plain(cmd)
                    r["arrived"], r["travel_time_s"] = _trips(trip)
                    rows.setdefault((name, coll), []).append(r)
    base = statistics.median(r["cpu_s"] for r in rows[("one edge", "warn")])
    print(f"\n{'variant':<26}{'CPU s':>8}{'ratio':>8}{'arrived':>9}{'travel time s':>15}")
    print("-" * 66)
    for (name, coll), rs in rows.items():
        cpu = statistics.median(r["cpu_s"] for r in rs)
        arrived = statistics.fmean(r["arrived"] for r in rs)
        tt = statistics.fmean(r["travel_time_s"] for r in rs)
        print(f"{name + ' / ' + coll:<26}{cpu:>8.2f}{cpu / base:>8.2f}{arrived:>9.0f}{tt:>15.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
