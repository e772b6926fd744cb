"""Neighbour search (controllers/neighbours.py): KD-tree versus dense reference."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.neighbours import (
    cross_pairs,
    neighbour_pairs,
    neighbour_pairs_dense,
    neighbour_pairs_tree,
    scatter_add,
    strip_cross_pairs,
)
from controllers.observation import Observation
from controllers.plane.olfati_saber import OlfatiSaberController
from controllers.plane.params import FlockingParams


def brute_force_pairs(x, radius, period=None):
    """Double loop over i < j: the definition, independent of both implementations."""
    out = []
    for i in range(len(x)):
        for j in range(i + 1, len(x)):
            dq = np.array(x[j], dtype=float) - np.array(x[i], dtype=float)
            if period is not None:
                dq[0] = (dq[0] + 0.5 * period) % period - 0.5 * period
            if np.linalg.norm(dq) < radius:
                out.append((i, j))
    return np.array(out, dtype=np.int64).reshape(-1, 2)


def test_three_agents_on_a_line_hand_pairs():
    # Gaps 5 m and 5.5 m; the outer pair is 10.5 m apart.
    x = np.array([[0.0, 0.0], [5.0, 0.0], [10.5, 0.0]])
    for method in ("dense", "kdtree"):
        np.testing.assert_array_equal(neighbour_pairs(x, 6.0, method=method), [[0, 1], [1, 2]])
        np.testing.assert_array_equal(neighbour_pairs(x, 5.5, method=method), [[0, 1]])
        assert len(neighbour_pairs(x, 10.6, method=method)) == 3


def test_distance_equal_to_the_radius_is_not_a_neighbour_in_both_methods():
    x = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 6.0 - 1e-9]])
    for method in ("dense", "kdtree"):
        np.testing.assert_array_equal(neighbour_pairs(x, 6.0, method=method), [[1, 2]])


@pytest.mark.parametrize("n", [0, 1])
def test_fewer_than_two_agents_give_no_pairs(n):
    x = np.zeros((n, 2))
    for method in ("dense", "kdtree", "auto"):
        pairs = neighbour_pairs(x, 6.0, method=method)
        assert pairs.shape == (0, 2)


def test_unknown_method_raises_value_error_naming_it():
    with pytest.raises(ValueError, match="octree"):
        neighbour_pairs(np.zeros((3, 2)), 1.0, method="octree")


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
@pytest.mark.parametrize("m", [1, 2, 3])
@pytest.mark.parametrize("period", [None, 60.0])
def test_kdtree_and_dense_give_identical_pairs_on_random_flocks(seed, m, period):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 60))
    x = rng.uniform(0.0, 60.0, (n, m))
    if m > 1:
        x[:, 1:] -= 30.0  # negative lateral positions too
    dense = neighbour_pairs(x, 7.2, period, "dense")
    tree = neighbour_pairs(x, 7.2, period, "kdtree")
    assert dense.dtype == tree.dtype == np.int64
    np.testing.assert_array_equal(tree, dense)
    np.testing.assert_array_equal(dense, brute_force_pairs(x, 7.2, period))
    assert len(dense) > 0


def test_kdtree_matches_dense_on_a_few_hundred_agents():
    rng = np.random.default_rng(7)
    x = rng.uniform(0.0, 200.0, (400, 2))
    np.testing.assert_array_equal(
        neighbour_pairs(x, 8.4, method="kdtree"), neighbour_pairs(x, 8.4, method="dense")
    )


def test_raw_tree_and_dense_functions_return_upper_triangle_pairs():
    rng = np.random.default_rng(11)
    x = rng.uniform(0.0, 30.0, (25, 2))
    for fn in (neighbour_pairs_dense, neighbour_pairs_tree):
        pairs = fn(x, 7.0)
        assert np.all(pairs[:, 0] < pairs[:, 1])
        assert {tuple(p) for p in pairs} == {tuple(p) for p in brute_force_pairs(x, 7.0)}


@pytest.mark.parametrize("method", ["dense", "kdtree"])
def test_ring_agents_at_s_1_and_s_l_minus_1_are_neighbours_at_distance_2(method):
    length = 100.0
    x = np.array([[1.0, 0.0], [length - 1.0, 0.0], [50.0, 0.0]])
    np.testing.assert_array_equal(neighbour_pairs(x, 6.0, length, method), [[0, 1]])
    # Without the periodic axis they are 98 m apart.
    assert neighbour_pairs(x, 6.0, None, method).shape == (0, 2)
    # 2 m apart, so a 2.5 m radius still finds them and a 1.9 m one does not.
    assert len(neighbour_pairs(x, 2.5, length, method)) == 1
    assert len(neighbour_pairs(x, 1.9, length, method)) == 0


def test_ring_lateral_axis_does_not_wrap():
    # Same s, 20 m apart laterally: not neighbours for a 6 m radius even with a periodic s axis.
    x = np.array([[10.0, -10.0], [10.0, 10.0]])
    assert neighbour_pairs(x, 6.0, 100.0, "kdtree").shape == (0, 2)


def test_ring_pair_repels_across_the_seam():
    # d = 6 m, agents 2 m apart across s = 0: the one at s = 1 is pushed to +s, the other to -s.
    prm = FlockingParams(c1_gamma=0.0, c2_gamma=0.0)
    q = np.array([[1.0, 0.0], [99.0, 0.0]])
    ring = Observation(q=q, p=np.zeros((2, 2)), period_s=100.0)
    for method in ("dense", "kdtree"):
        u = OlfatiSaberController(prm.with_(neighbour_search=method)).compute(ring)
        assert u[0, 0] > 100.0
        assert u[1, 0] < -100.0
        np.testing.assert_allclose(u[0], -u[1], atol=1e-12)
    flat = Observation(q=q, p=np.zeros((2, 2)))
    np.testing.assert_array_equal(OlfatiSaberController(prm).compute(flat), 0.0)


def random_observation(seed: int, period: float | None):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(8, 40))
    span = 50.0 if period is None else period
    q = np.column_stack([rng.uniform(0.0, span, n), rng.uniform(-10.0, 10.0, n)])
    p = rng.uniform(-5.0, 5.0, (n, 2))
    return Observation(
        q=q, p=p, period_s=period, leader_q=np.array([20.0, 0.0]), leader_p=np.array([10.0, 0.0])
    )


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("period", [None, 80.0])
@pytest.mark.parametrize("aniso", [False, True])
def test_kdtree_and_dense_give_identical_u(seed, period, aniso):
    base = FlockingParams(d_long=9.0, d_lat=3.5) if aniso else FlockingParams()
    obs = random_observation(seed, period)
    law_dense = OlfatiSaberController(base.with_(neighbour_search="dense"))
    law_tree = OlfatiSaberController(base.with_(neighbour_search="kdtree"))
    u_dense = law_dense.compute(obs)
    u_tree = law_tree.compute(obs)
    assert law_dense.last_terms.n_pairs == law_tree.last_terms.n_pairs > 0
    np.testing.assert_array_equal(u_tree, u_dense)


def test_ring_flock_across_the_seam_gives_identical_u_in_both_methods():
    # Agents packed around s = 0 of a 50 m ring: half of them at s ~ 49.
    rng = np.random.default_rng(3)
    s = np.mod(rng.uniform(-8.0, 8.0, 12), 50.0)
    q = np.column_stack([s, rng.uniform(-3.0, 3.0, 12)])
    obs = Observation(q=q, p=rng.uniform(-1.0, 1.0, (12, 2)), period_s=50.0)
    u_dense = OlfatiSaberController(FlockingParams(neighbour_search="dense")).compute(obs)
    u_tree = OlfatiSaberController(FlockingParams(neighbour_search="kdtree")).compute(obs)
    np.testing.assert_array_equal(u_tree, u_dense)
    assert np.abs(u_dense).max() > 1.0


@pytest.mark.parametrize("period", [None, 40.0])
def test_cross_pairs_match_brute_force(period):
    rng = np.random.default_rng(5)
    x = np.column_stack([rng.uniform(0, 40, 15), rng.uniform(-5, 5, 15)])
    y = np.column_stack([rng.uniform(0, 40, 9), rng.uniform(-5, 5, 9)])
    got = {tuple(p) for p in cross_pairs(x, y, 6.0, period)}
    want = set()
    for i in range(len(x)):
        for k in range(len(y)):
            dq = y[k] - x[i]
            if period is not None:
                dq[0] = (dq[0] + 0.5 * period) % period - 0.5 * period
            if np.linalg.norm(dq) < 6.0:
                want.add((i, k))
    assert got == want
    assert len(want) > 0


def _brute_cross(x, y, radius, period):
    dq = y[None, :, :] - x[:, None, :]
    if period is not None:
        dq[..., 0] = (dq[..., 0] + 0.5 * period) % period - 0.5 * period
    i, k = np.nonzero(np.linalg.norm(dq, axis=-1) < radius)
    return {(int(a), int(b)) for a, b in zip(i, k, strict=True)}


@pytest.mark.parametrize("period", [None, 500.0])
def test_strip_search_on_a_road_matches_brute_force_and_the_tree(period):
    """Road-like sets (10 m wide, radius 40 m) take the strip path: exact pairs."""
    rng = np.random.default_rng(11)
    for _ in range(30):
        x = np.column_stack([rng.uniform(0, 500, 40), rng.uniform(-5, 5, 40)])
        y = np.column_stack([rng.uniform(0, 500, 60), rng.uniform(-5, 5, 60)])
        y[0] = x[0] + [40.0, 0.0]  # exactly at the radius: excluded (strict <)
        want = _brute_cross(x, y, 40.0, period)
        strip = strip_cross_pairs(x, y, 40.0, period)
        assert {tuple(p) for p in strip} == want
        assert (0, 0) not in want
        assert np.all(np.diff(strip[:, 0]) >= 0)  # grouped by i
        assert {tuple(p) for p in cross_pairs(x, y, 40.0, period)} == want


def test_cross_pairs_with_an_empty_set_is_empty():
    assert cross_pairs(np.zeros((3, 2)), np.zeros((0, 2)), 5.0).shape == (0, 2)


def test_scatter_add_sums_rows_like_add_at():
    index = np.array([0, 2, 0, 3, 2])
    values = np.arange(10.0).reshape(5, 2)
    want = np.zeros((4, 2))
    np.add.at(want, index, values)
    np.testing.assert_array_equal(scatter_add(4, index, values), want)
    # hand: row 0 = (0,1) + (4,5) = (4, 6); row 1 untouched.
    np.testing.assert_array_equal(scatter_add(4, index, values)[[0, 1]], [[4.0, 6.0], [0.0, 0.0]])
