"""What a fork server loads once before it forks runs (``multiprocessing``'s
``forkserver`` preload: ``cosim sweep --start-method forkserver``, the SUMO tests'
``tests/sumo_cases/isolated.py``).

Importing this module loads cosim's modules, libsumo's library (no simulation is
started: the server stays single-threaded and never holds SUMO's global state) and every
numba kernel the runs call, read back from numba's cache by a few seconds of each
built-in scenario in the SUMO-free road world (:func:`cosim.sim.warm.warm_road_world`;
nothing is written). A forked run then starts with all of it in memory. Without it, a
first run in a fresh process costs more than the same run again (the cache files read
back, modules imported where first used): ``benchmarks/bench_startup.py`` times both
(a 60 s ring run: 1.39 s then 0.91 s fresh, 0.92 s both after the preload);
``python -m cosim.sim.preload`` times a short run twice after the preload.
"""

from __future__ import annotations

import sys
import time

import libsumo  # noqa: F401  (the library only)

import cosim.config  # noqa: F401
import cosim.sim.runner  # noqa: F401
import cosim.sumo.world  # noqa: F401
from cosim.sim.warm import warm_road_world

try:
    warm_road_world()
except Exception as exc:  # an optimisation only: the runs then load the kernels themselves
    print(f"cosim.sim.preload: kernels not preloaded ({type(exc).__name__}: {exc})",
          file=sys.stderr)


def check(name: str = "ring") -> None:
    """A short built-in run, twice in this process after the preload, timed (s)."""
    from cosim.config import load_scenario
    from cosim.sim.runner import run_scenario

    over = {"scenario.duration_s": 60.0, "scenario.warmup_s": 20.0,
            "scenario.interval_s": 20.0, "outputs.trajectories": False}
    for i in range(2):
        t0 = time.perf_counter()
        run_scenario(load_scenario(name, over))
        print(f"{name} run {i + 1}: {time.perf_counter() - t0:.2f} s")


if __name__ == "__main__":
    check(*sys.argv[1:2])
