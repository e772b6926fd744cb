"""What a run pays before it simulates: a short built-in run timed twice in one process,
in a fresh interpreter and after the fork servers' preload (``cosim/sim/preload.py``).

Usage::

    .venv/bin/python benchmarks/bench_startup.py            # ring, 60 s; about 20 s
    .venv/bin/python benchmarks/bench_startup.py --scenario default
    .venv/bin/python benchmarks/bench_startup.py --frames 2 10 40   # road frames only

Each variant runs in its own process (libsumo holds one simulation per process), the
variants interleaved over ``--rounds``; per variant the medians of the first and second
run (wall s: imports and numba's cache reads are what differ) and their difference, the
start-up the first run pays.

``--frames KM ...``: the road frame of a ring of each circumference (the network built
once, cached), CPU s of ``build_network`` with the reference line's nearest-point search
as it is and with the full search it replaced (tests/test_line_nearest.py's verbatim copy
of it: every point against every segment), interleaved over ``--rounds``, medians.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OVERRIDES = {"scenario.duration_s": 60.0, "scenario.warmup_s": 20.0,
             "scenario.interval_s": 20.0, "outputs.trajectories": False}


def child(name: str, preload: bool) -> list[float]:
    """Wall s of the same run twice in this process (after the preload, if asked)."""
    if preload:
        import cosim.sim.preload  # noqa: F401
    from cosim.config import load_scenario
    from cosim.sim.runner import run_scenario

    out = []
    for _ in range(2):
        t0 = time.perf_counter()
        run_scenario(load_scenario(name, OVERRIDES))
        out.append(time.perf_counter() - t0)
    return out


def frames(kms: list[float], rounds: int) -> int:
    """Print the road-frame build of rings of ``kms`` km, the search as it is and full."""
    import tempfile

    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "tests"))
    import dataclasses

    from test_line_nearest import _nearest_full

    from cosim.config import load_scenario
    from cosim.road.build import build_network
    from cosim.road.polyline import Line

    pruned = Line.nearest
    cache = Path(tempfile.mkdtemp(prefix="bench_frames_"))
    specs = {km: dataclasses.replace(load_scenario("ring").network,
                                     circumference_m=1000.0 * km) for km in kms}
    for spec in specs.values():  # netconvert once per ring, and the kernels loaded
        build_network(spec, cache)
    cpu: dict[tuple[float, str], list[float]] = {}
    for _ in range(rounds):
        for km, spec in specs.items():
            for variant, fn in (("pruned", pruned), ("full", _nearest_full)):
                Line.nearest = fn
                c0 = time.process_time()
                build_network(spec, cache)
                cpu.setdefault((km, variant), []).append(time.process_time() - c0)
    Line.nearest = pruned
    print(f"bench_startup --frames: a ring's road frame (build_network, network cached), "
          f"CPU s, medians of {rounds} interleaved round(s)")
    print(f"{'ring km':>8}{'search as is':>14}{'full search':>13}{'full / as is':>14}")
    for km in kms:
        a = statistics.median(cpu[(km, "pruned")])
        b = statistics.median(cpu[(km, "full")])
        print(f"{km:8g}{a:14.3f}{b:13.3f}{b / a:14.1f}")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="ring", help="built-in scenario (default ring)")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds (default 3)")
    ap.add_argument("--frames", nargs="+", type=float, metavar="KM",
                    help="time the road frames of rings of these circumferences, km")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    ns = ap.parse_args(argv)
    if ns.child:
        sys.path.insert(0, str(ROOT))
        print("RESULT " + json.dumps(child(ns.child[0], ns.child[1] == "1")))
        return 0
    if ns.rounds < 1:
        print("error: --rounds must be >= 1", file=sys.stderr)
        return 2
    if ns.frames is not None:
        if not all(0.2 <= km <= 200.0 for km in ns.frames):
            print("error: --frames takes circumferences from 0.2 to 200 km", file=sys.stderr)
            return 2
        return frames(ns.frames, ns.rounds)
    times: dict[str, list[list[float]]] = {"fresh": [], "preloaded": []}
    for _ in range(ns.rounds):
        for variant, flag in (("fresh", "0"), ("preloaded", "1")):
            proc = subprocess.run([sys.executable, __file__, "--child", ns.scenario, flag],
                                  capture_output=True, text=True, cwd=ROOT, check=False)
            line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")]
            if proc.returncode or not line:
                print(f"error: the {variant} run failed: {proc.stderr.strip()[-300:]}",
                      file=sys.stderr)
                return 2
            times[variant].append(json.loads(line[0][7:]))
    print(f"bench_startup: built-in {ns.scenario!r}, 60 s, {ns.rounds} interleaved round(s); "
          "wall s, medians")
    print(f"{'variant':<10}{'1st run':>10}{'2nd run':>10}{'start-up':>10}")
    for variant, runs in times.items():
        first = statistics.median(r[0] for r in runs)
        second = statistics.median(r[1] for r in runs)
        print(f"{variant:<10}{first:10.2f}{second:10.2f}{first - second:10.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
