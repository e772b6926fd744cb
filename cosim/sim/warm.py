"""Compile the numba kernels into their cache once, at install (``python -m cosim.sim.warm``).

The compiled kernels (the lane-free law, the safety layer, the recorders, the road frame)
are cached next to their sources (numba's ``cache=True``); compiling them costs about 20 s
of CPU in the first process that calls them, and ``make test`` would otherwise pay it in
several of its processes at once. ``make run`` and ``make test`` call this after installing
the package: it runs every built-in scenario for a few seconds in the SUMO-free road world
(one process), and the SUMO paths of a road without human drivers and of an on-ramp with
them (one process each: libsumo holds one simulation per process), so that later runs load
every kernel from the cache. Nothing is written but numba's cache.
"""

from __future__ import annotations

import subprocess
import sys
import time

#: Simulated seconds of each warm-up run.
WARM_S = 3.0
#: SUMO-world runs (scenario, overrides), each in its own process.
SUMO_RUNS = (("default", {}), ("onramp", {}))


def _run(name: str, overrides: dict) -> None:
    from cosim.config.scenario import load_scenario
    from cosim.sim.runner import run_scenario

    over = {"scenario.duration_s": WARM_S, "scenario.warmup_s": 1.0,
            "scenario.interval_s": WARM_S - 1.0, **overrides}
    run_scenario(load_scenario(name, over))


def warm_road_world() -> list[str]:
    """Every built-in scenario the road world can run, a few seconds each; their names."""
    from cosim.config.builtins import builtin_scenarios
    from cosim.errors import ConfigError

    done = []
    for name in builtin_scenarios():
        try:
            _run(name, {"scenario.world": "road"})
        except ConfigError:  # a network kind the road world has not (the on-ramp)
            continue
        done.append(name)
    return done


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args[:1] == ["--sumo"]:  # one SUMO run (a child of main)
        _run(args[1], {})
        return 0
    t0 = time.perf_counter()
    names = warm_road_world()
    for name, _ in SUMO_RUNS:
        subprocess.run([sys.executable, "-m", "cosim.sim.warm", "--sumo", name], check=True)
    print(f"numba kernels compiled and cached ({len(names)} road-world and {len(SUMO_RUNS)} "
          f"SUMO warm-up runs, {time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
