"""The compiled gap and overlap searches of the traffic metrics give what the cKDTree code
before them gave (issue 15): identical arrays (``==``, not approx), in the same order.

``ref_overlapping_pairs`` and ``ref_gaps_and_leaders`` are verbatim copies of
``cosim.metrics.traffic.overlapping_pairs`` / ``gaps_and_leaders`` before the change (a
scipy cKDTree per call, ``query_pairs``, numpy post-processing). States: straight roads and
rings (small rings too, shorter than twice the 150 m reach), dense and sparse, positions on
a grid (equal gaps, leaders tied at the same gap, pairs at exactly the reach), vehicles
straddling the ring seam, mixed lengths and widths, empty and single-vehicle states.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from controllers.neighbours import tree_points
from cosim.metrics import kernels as K
from cosim.metrics import traffic
from cosim.metrics.traffic import StepState, gaps_and_leaders, overlapping_pairs


# ------------------------------------------------------------ reference (verbatim copies)
def ref_overlapping_pairs(st: StepState, period: float | None) -> np.ndarray:
    """Pairs (i < j) of vehicles whose rectangles overlap (strictly), (P, 2)."""
    if len(st.s) < 2:
        return np.empty((0, 2), dtype=np.int64)
    reach = float(np.hypot(st.length.max(), st.width.max()))
    pts, box = tree_points(np.column_stack([st.s, st.d]), reach, period)
    pairs = cKDTree(pts, boxsize=box).query_pairs(reach, output_type="ndarray")
    if len(pairs) == 0:
        return pairs
    i, j = pairs[:, 0], pairs[:, 1]
    ds = st.s[j] - st.s[i]
    if period is not None:
        ds = (ds + 0.5 * period) % period - 0.5 * period
    ov = (np.abs(ds) < 0.5 * (st.length[i] + st.length[j])) & (
        np.abs(st.d[j] - st.d[i]) < 0.5 * (st.width[i] + st.width[j])
    )
    return pairs[ov]


def ref_gaps_and_leaders(
    st: StepState, period: float | None, lateral_overlap_margin_m: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`gaps` plus each vehicle's leader: (g_long, g_side, leader), (M,) each.

    ``leader[i]`` is the index of the laterally overlapping vehicle ahead with the
    smallest bumper gap (the one ``g_long[i]`` is measured to), -1 if none within
    the 150 m reach."""
    n = len(st.s)
    g_long = np.full(n, np.inf)
    g_side = np.full(n, np.inf)
    leader = np.full(n, -1, dtype=np.int64)
    if n < 2:
        return g_long, g_side, leader
    reach = 150.0
    pts, box = tree_points(np.column_stack([st.s, st.d]), reach, period)
    pairs = cKDTree(pts, boxsize=box).query_pairs(reach, output_type="ndarray")
    if len(pairs) == 0:
        return g_long, g_side, leader
    i = np.concatenate([pairs[:, 0], pairs[:, 1]])
    j = np.concatenate([pairs[:, 1], pairs[:, 0]])
    ds = st.s[j] - st.s[i]
    if period is not None:
        ds = (ds + 0.5 * period) % period - 0.5 * period
    half_l = 0.5 * (st.length[i] + st.length[j])
    half_w = 0.5 * (st.width[i] + st.width[j])
    dd = np.abs(st.d[j] - st.d[i])
    lat_overlap = dd < half_w + lateral_overlap_margin_m
    ahead = (ds > 0) & lat_overlap
    if ahead.any():
        ia, ja, ga = i[ahead], j[ahead], ds[ahead] - half_l[ahead]
        order = np.lexsort((ga, ia))  # by follower, then gap: the first row of each is its leader
        ia, ja, ga = ia[order], ja[order], ga[order]
        first = np.ones(len(ia), dtype=bool)
        first[1:] = ia[1:] != ia[:-1]
        g_long[ia[first]] = ga[first]
        leader[ia[first]] = ja[first]
    beside = (np.abs(ds) < half_l) & ~lat_overlap
    np.minimum.at(g_side, i[beside], dd[beside] - half_w[beside])
    return g_long, g_side, leader


# ------------------------------------------------------------ states
def make_state(s, d, length, width) -> StepState:
    s, d = np.asarray(s, float), np.asarray(d, float)
    n = len(s)
    return StepState(
        t=0.0, ids=[f"v{k}" for k in range(n)], s=s, s_front=s + 0.5 * np.asarray(length),
        d=d, v=np.full(n, 20.0), v_lat=np.zeros(n), length=np.asarray(length, float),
        width=np.asarray(width, float), is_cav=np.ones(n, bool), edge_right=np.full(n, -5.1),
        edge_left=np.full(n, 5.1),
    )


def random_state(rng, n: int, road_m: float, width_m: float, grid: bool, period) -> StepState:
    """``n`` vehicles on ``road_m`` m (a ring of that length if ``period``), lateral offsets
    in +-width/2; ``grid``: positions, offsets and sizes on coarse grids (exact ties)."""
    if grid:
        step = rng.choice([0.5, 1.0, 2.5])
        s = rng.integers(0, max(int(road_m / step), 1), n) * step
        d = rng.integers(-4, 5, n) * (width_m / 8.0)
        length = rng.choice([4.0, 5.0, 12.0], n)
        width = rng.choice([1.8, 2.0, 2.5], n)
    else:
        s = rng.uniform(0.0, road_m, n)
        d = rng.uniform(-0.5 * width_m, 0.5 * width_m, n)
        length = rng.uniform(3.5, 16.0, n)
        width = rng.uniform(1.6, 2.6, n)
    if period is not None and n > 0 and rng.random() < 0.5:
        # positions as SUMO may give them on a ring: some just below/at/above the seam
        k = rng.integers(0, n, max(n // 4, 1))
        s[k] = rng.choice([period, period - 1e-9, 0.0, -0.0, 2 * period - 3.0, -2.0, 1e-12],
                          len(k))
    return make_state(s, d, length, width)


CASES = [
    # (n, road m, width m, period?)  dense and sparse, straight and rings
    (300, 2000.0, 10.2, False), (60, 2000.0, 10.2, False), (3, 500.0, 3.5, False),
    (400, 1000.0, 10.2, True), (40, 5000.0, 10.2, True), (25, 250.0, 10.2, True),
    (12, 80.0, 6.0, True), (30, 299.0, 20.0, True), (150, 300.0, 10.2, True),
    (200, 400.0, 40.0, False),
]


def assert_same_gaps(st, period, margin=0.0):
    want = ref_gaps_and_leaders(st, period, margin)
    pairs, both = traffic.overlaps_and_gaps(st, period, True, margin)  # one sweep for both
    for got in (gaps_and_leaders(st, period, margin), both):
        for g, w, name in zip(got, want, ("g_long", "g_side", "leader"), strict=True):
            assert g.dtype == w.dtype and g.shape == w.shape, name
            assert np.array_equal(g, w), name
    want_pairs = ref_overlapping_pairs(st, period)
    assert pairs.dtype == want_pairs.dtype and np.array_equal(pairs, want_pairs)


def assert_same_overlaps(st, period):
    if period is not None and len(st.s):  # the compiled tree coordinates are the tree's
        px, py, box_y = traffic._points(st, 150.0, period)
        cx, cy, cb = K.tree_points_2d(st.s, st.d, 150.0, period)
        assert np.array_equal(cx, px) and np.array_equal(cy, py) and cb == box_y
    want = ref_overlapping_pairs(st, period)
    got = overlapping_pairs(st, period)
    assert got.dtype == want.dtype and got.shape == want.shape
    assert np.array_equal(got, want)


@pytest.mark.parametrize("grid", [False, True], ids=["continuous", "grid"])
@pytest.mark.parametrize("case", CASES, ids=[f"n{c[0]}_L{c[1]:g}_{'ring' if c[3] else 'road'}"
                                             for c in CASES])
def test_random_states_identical(case, grid):
    n, road, width, ring = case
    rng = np.random.default_rng([n, int(road), int(grid), int(ring)])
    period = road if ring else None
    for _ in range(25):
        st = random_state(rng, int(rng.integers(0, n + 1)), road, width, grid, period)
        assert_same_gaps(st, period)
        assert_same_gaps(st, period, 0.3)
        assert_same_overlaps(st, period)


def test_ties_and_edges_identical():
    # a follower behind two vehicles side by side at the same gap: the tree's order decides
    st = make_state([0.0, 20.0, 20.0, 20.0], [0.0, -1.0, 1.0, 0.0], [5.0] * 4, [4.0] * 4)
    assert_same_gaps(st, None)
    # the follower in the middle of the index range: one leader above, one below
    st = make_state([20.0, 0.0, 20.0], [-1.0, 0.0, 1.0], [5.0] * 3, [4.0] * 3)
    assert_same_gaps(st, None)
    # exactly at the 150 m reach, and just beyond it
    for gap in (150.0, np.nextafter(150.0, 0.0), np.nextafter(150.0, 1e3)):
        st = make_state([0.0, gap], [0.0, 0.0], [5.0, 5.0], [2.0, 2.0])
        assert_same_gaps(st, None)
        assert_same_gaps(st, 1000.0)
    # straddling the seam of a ring, and a ring shorter than twice the reach
    for period in (300.0, 200.0, 1000.0):
        st = make_state([period - 1.0, 1.5, period, 0.0, 0.5 * period], [0.0, 0.3, -0.2, 2.0,
                        0.0], [5.0, 4.0, 12.0, 5.0, 5.0], [2.0, 1.8, 2.5, 2.0, 2.0])
        assert_same_gaps(st, period)
        assert_same_overlaps(st, period)
    # two vehicles exactly half a ring apart
    st = make_state([0.0, 150.0], [0.0, 0.0], [5.0, 5.0], [2.0, 2.0])
    assert_same_gaps(st, 300.0)
    # empty and single-vehicle states
    for n in (0, 1):
        st = make_state(np.zeros(n), np.zeros(n), np.full(n, 5.0), np.full(n, 2.0))
        assert_same_gaps(st, None)
        assert_same_gaps(st, 300.0)
        assert_same_overlaps(st, None)
        assert_same_overlaps(st, 300.0)
    # overlaps: none, one, several (the tree's order kept)
    st = make_state([0.0, 3.0, 3.5, 50.0, 52.0, 300.0], [0.0, 0.5, -0.5, 0.0, 1.0, 0.0],
                    [5.0] * 6, [2.0] * 6)
    assert len(overlapping_pairs(st, None)) == 4
    assert_same_overlaps(st, None)
    assert_same_overlaps(st, 400.0)


def test_compiled_path_taken():
    """The sweep's own candidate pairs are the tree's pairs as a set, each once, and
    random states go through the sweep (not the tree fallback)."""
    rng = np.random.default_rng(7)
    for period in (None, 500.0, 250.0):  # 250 m: shorter than twice the reach
        st = random_state(rng, 200, 500.0 if period is None else period, 10.2, False, period)
        px, py, box_y = traffic._points(st, 150.0, period)
        if period is not None:  # the compiled tree points are the same
            cx, cy, cb = K.tree_points_2d(st.s, st.d, 150.0, period)
            assert np.array_equal(cx, px) and np.array_equal(cy, py) and cb == box_y
        cand = K.pairs_within(px, py, 150.0, period is not None, traffic._period(period),
                              box_y)
        pts, box = tree_points(np.column_stack([st.s, st.d]), 150.0, period)
        tree = cKDTree(pts, boxsize=box).query_pairs(150.0, output_type="ndarray")
        key = np.sort(cand[:, 0] * 200 + cand[:, 1])
        assert len(key) > 1000
        assert np.array_equal(key, np.sort(tree[:, 0] * 200 + tree[:, 1]))
        _, _, _, _, _, tied = K.pair_sweep(px, py, st.s, st.d, st.length, st.width,
                                           period is not None, traffic._period(period),
                                           box_y, True, 150.0, 0.0)
        assert not tied


def test_non_finite_and_other_dtypes_fall_back():
    st = make_state([0.0, 10.0, np.nan], [0.0, 0.0, 0.0], [5.0] * 3, [2.0] * 3)
    for fn in (gaps_and_leaders, ref_gaps_and_leaders):  # the tree refuses NaN positions
        with pytest.raises(ValueError, match="finite"):
            fn(st, None)
    st = make_state([0.0, 10.0, 12.0], [0.0, 0.0, 0.0], [5.0, np.nan, 5.0], [2.0] * 3)
    got = gaps_and_leaders(st, None)
    want = ref_gaps_and_leaders(st, None)
    for g, w in zip(got, want, strict=True):
        assert np.array_equal(g, w, equal_nan=True)
    st32 = make_state([0.0, 10.0], [0.0, 0.0], [5.0] * 2, [2.0] * 2)
    st32.s = st32.s.astype(np.float32)
    for g, w in zip(gaps_and_leaders(st32, None), ref_gaps_and_leaders(st32, None),
                    strict=True):
        assert np.array_equal(g, w)


def test_ring_wrap_matches_numpy():
    """The compiled ``(ds + P/2) % P - P/2`` equals numpy's, bit for bit (signed zeros too)."""
    rng = np.random.default_rng(3)
    for period in (300.0, 1000.0, 2000.0, 10000.0, 123.456):
        ds = np.concatenate([
            rng.uniform(-3 * period, 3 * period, 2000),
            np.array([0.0, -0.0, 0.5 * period, -0.5 * period, period, -period, 1e-300,
                      np.nextafter(0.5 * period, 0.0), np.nextafter(-0.5 * period, 0.0),
                      2.5 * period, -1.5 * period, 1e-17, -1e-17]),
        ])
        want = (ds + 0.5 * period) % period - 0.5 * period
        got = np.array([K.wrap_ds(x, True, period) for x in ds])
        assert np.array_equal(got.view(np.int64), want.view(np.int64))
        assert np.array_equal(np.array([K.wrap_ds(x, False, period) for x in ds]), ds)


def test_strided_arrays_identical():
    """Views with strides (not contiguous) give the same results too."""
    rng = np.random.default_rng(5)
    big = rng.uniform(0.0, 1000.0, (4, 2 * 120))
    s, d = big[0, ::2], big[1, ::2] * 0.01 - 5.0
    st = make_state(s, d, 4.0 + big[2, ::2] * 0.01, 1.6 + big[3, ::2] * 0.001)
    st.s, st.d = s, d  # keep the strided views
    assert not st.s.flags.c_contiguous
    for period in (None, 1000.0):
        assert_same_gaps(st, period)
        assert_same_overlaps(st, period)
