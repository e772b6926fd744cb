"""The compiled road frame (cosim/road/frame_kernels.py) against its numpy reference
(cosim/road/frame_reference.py: ``lane_frame_reference``, ``lateral_reference``): the
same bits, element by element, on every kind of lane the frame meets.

The networks: netconvert's curve and multi-edge roads from networks/examples/ (bends,
kinks, smoothed junction lanes: projected), its width change, the on-ramp cosim builds
(lanes parallel to the line next to lanes that are not) and the ring (every lane parallel,
the wrap at the seam). The inputs mix lanes at
random, positions inside, before and beyond each lane (``s`` continues from the end; a
position past the end is taken on the next lane), vehicles off the routes (key -1), and
subsets where every lane is parallel (numpy's short cuts).
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from cosim.road import frame_kernels as FK
from cosim.road.build import build_network
from cosim.road.frame import load_road_network
from cosim.road.frame_reference import lane_frame_reference, lateral_reference
from cosim.road.spec import NetworkSpec
from tests.test_road_frame import ROUTES, build_example

pytestmark = pytest.mark.sumo  # netconvert builds the networks


@pytest.fixture(scope="module")
def networks(tmp_path_factory):
    folder = tmp_path_factory.mktemp("frame_kernel_nets")
    out = {
        "ring": build_network(NetworkSpec(kind="ring", circumference_m=500.0), folder / "r"),
        "onramp": build_network(NetworkSpec(kind="onramp"), folder / "o"),
    }
    for name in ("curve", "multi_edge", "width_change"):
        out[name] = load_road_network(build_example(name, folder / name), kind="file",
                                      main_route=ROUTES[name])
    return out


def _inputs(net, rng, n, off_route=0.1, beyond=0.2, only=None):
    tb = net.tables
    lanes = np.arange(len(tb.lane_len)) if only is None else np.flatnonzero(only)
    k = rng.choice(lanes, n).astype(np.int64)
    length = tb.lane_len[k]
    pos = rng.uniform(0.0, 1.0, n) * length
    far = rng.random(n) < beyond
    pos[far] = np.where(rng.random(far.sum()) < 0.5, -rng.uniform(0, 5, far.sum()),
                        length[far] + rng.uniform(0, 30, far.sum()))
    k[rng.random(n) < off_route] = -1
    lat = rng.uniform(-4.0, 4.0, n)
    return k, pos, lat


def _same(a, b):
    return np.array_equal(a, b, equal_nan=True) and np.array_equal(
        np.signbit(a), np.signbit(b))


@pytest.mark.parametrize("name", ["ring", "curve", "multi_edge", "width_change", "onramp"])
@pytest.mark.parametrize("case", ["mixed", "none_beyond", "all_on_route", "parallel_only"])
def test_compiled_frame_is_numpys_bit_for_bit(networks, name, case):
    net = networks[name]
    tb = net.tables
    rng = np.random.default_rng(zlib.crc32(f"{name}/{case}".encode()))  # fixed inputs
    only = None
    if case == "parallel_only":
        if not tb.par.any():
            pytest.fail(f"{name}: no lane parallel to the line (the case needs one)")
        only = tb.par
    kw = {"none_beyond": dict(beyond=0.0), "all_on_route": dict(off_route=0.0),
          "parallel_only": dict(only=only), "mixed": {}}[case]
    args = tb.kernel_args()
    for n in (1, 7, 300):
        k, pos, lat = _inputs(net, rng, n, **kw)
        s_ref, d_ref = lane_frame_reference(tb, k, pos, lat)
        s, d = FK.geo_frame(k, pos, lat, args)
        assert _same(s, s_ref) and _same(d, d_ref), (name, case, n)
        # and the inverse, at the frame's own d (the loop's use) and at other offsets
        for dd in (d_ref, rng.uniform(-4.0, 4.0, n)):
            want = lateral_reference(tb, k, pos, dd)
            got = FK.geo_lateral(k, pos, dd, args)
            assert _same(got, want), (name, case, n)


def test_ramp_lanes_take_the_projection_and_round_trip(networks):
    """The main route's lanes are all in SUMO's lane coordinates (the parallel path), the
    on-ramp's lanes are not (so the test above exercises the projection there), and the
    public methods, which run compiled, still invert each other."""
    for name in ("curve", "multi_edge", "width_change", "ring"):
        assert networks[name].tables.par.all(), name
    net = networks["onramp"]
    assert not net.tables.par.all()
    rng = np.random.default_rng(3)
    k, pos, lat = _inputs(net, rng, 500, off_route=0.0, beyond=0.0, only=~net.tables.par)
    s, d = net.lane_frame(None, pos, lat, keys=k)
    back = net.lateral_lane_position(None, pos, d, keys=k)
    np.testing.assert_allclose(back, lat, atol=1e-3)
