"""The fork servers' preload (cosim/sim/preload.py) loads what it says. multiprocessing's
fork server skips a preload module it cannot import without a word, and every forked run
would then pay its own imports and numba cache loads again: these tests would see it."""

from __future__ import annotations

import pytest
from sumo_cases.isolated import run_isolated

pytestmark = pytest.mark.sumo


def loaded_in_child() -> dict:
    """What a freshly forked child has in memory before it does anything."""
    import sys

    mods = ("cosim.sim.preload", "cosim.sumo.world", "libsumo")
    out = {m: m in sys.modules for m in mods}
    from controllers.layers import safety_kernels
    from controllers.road.lanefree import kernels as law_kernels
    from cosim.metrics import kernels as metric_kernels

    out["compiled"] = {f.__name__: len(f.signatures) for f in (
        law_kernels.law_step, safety_kernels.apply_kernel, metric_kernels.traffic_tallies)}
    return out


def test_forked_children_start_with_cosim_libsumo_and_the_compiled_kernels():
    got = run_isolated(loaded_in_child)
    assert got["cosim.sim.preload"] and got["cosim.sumo.world"] and got["libsumo"], got
    assert all(n >= 1 for n in got["compiled"].values()), got
