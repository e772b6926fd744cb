"""Compiled kernels against their numpy references, and what a call into numba costs.

Usage::

    .venv/bin/python benchmarks/bench_kernels.py           # about 10 s
    .venv/bin/python benchmarks/bench_kernels.py --n 500

* the road frame's projection (``cosim/road/frame_kernels.py``: ``geo_frame``,
  ``geo_lateral``) against ``frame_reference.lane_frame_reference`` / ``lateral_reference``, N
  vehicles at random on the lanes of networks/examples/multi_edge (kinks of +6 and -10
  degrees, netconvert's junction lanes: lanes not parallel to the road's line), built with
  netconvert's defaults; the two give the same bits (tests/test_frame_kernels.py);
* numba's own cost of one call with 21 array arguments and with 3 (a kernel that returns
  at once): what every compiled kernel pays per call before it starts.

Process CPU time per call (median of 5 interleaved rounds of timeit loops), us, and
numpy / compiled as a ratio (the machine is shared: read the ratio).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def per_call_us(fn, number: int) -> float:
    t0 = time.process_time()
    for _ in range(number):
        fn()
    return (time.process_time() - t0) / number * 1e6


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100, help="vehicles (default 100)")
    ns = ap.parse_args(argv)
    if ns.n < 1:
        print("error: --n must be >= 1", file=sys.stderr)
        return 2
    sys.path.insert(0, str(ROOT))
    from numba import njit

    from cosim.road import frame_kernels as FK
    from cosim.road.frame import load_road_network
    from cosim.road.frame_reference import lane_frame_reference, lateral_reference
    from tests.test_road_frame import ROUTES, build_example

    net = load_road_network(build_example("multi_edge", Path(tempfile.mkdtemp())),
                            kind="file", main_route=ROUTES["multi_edge"])
    tb = net.tables
    rng = np.random.default_rng(1)
    k = rng.integers(0, len(tb.lane_len), ns.n).astype(np.int64)
    pos = rng.uniform(0.0, 1.0, ns.n) * tb.lane_len[k]
    lat = rng.uniform(-3.0, 3.0, ns.n)
    args = tb.kernel_args()

    @njit
    def call21(a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15, a16,
               a17, a18, a19, a20):
        return a0[0]

    @njit
    def call3(a0, a1, a2):
        return a0[0]

    x = np.zeros(ns.n)
    many = [x] * 21
    cases = {
        "lane_frame numpy": (lambda: lane_frame_reference(tb, k, pos, lat), 300),
        "lane_frame compiled": (lambda: FK.geo_frame(k, pos, lat, args), 20000),
        "lateral numpy": (lambda: lateral_reference(tb, k, pos, lat), 300),
        "lateral compiled": (lambda: FK.geo_lateral(k, pos, lat, args), 20000),
        "numba call, 21 arrays": (lambda: call21(*many), 100000),
        "numba call, 3 arrays": (lambda: call3(x, x, x), 100000),
    }
    for fn, _ in cases.values():  # compile / load from the cache
        fn()
    got: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(5):
        for name, (fn, number) in cases.items():
            got[name].append(per_call_us(fn, number))
    med = {name: statistics.median(v) for name, v in got.items()}
    print(f"bench_kernels: multi_edge example, N = {ns.n}; process CPU us per call, "
          "medians of 5 interleaved rounds")
    for name, us in med.items():
        print(f"  {name:<24}{us:10.2f}")
    for what in ("lane_frame", "lateral"):
        print(f"  {what}: numpy / compiled = "
              f"{med[what + ' numpy'] / med[what + ' compiled']:.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
