"""Neighbour search without N x N arrays.

``neighbour_pairs`` returns the undirected pairs (i < j) whose (scaled)
distance is below a radius. The KD-tree path (scipy's cKDTree) costs
O(N log N) time and O(N + pairs) memory; the dense path builds the N x N
distance matrix and exists only as a reference for tests and small N.
A periodic axis 0 (ring road of length ``period``) is handled by the tree's
``boxsize``; the other axes are shifted so that they never wrap.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

DENSE_MAX_N = 64  # "auto" uses the dense reference only up to this many agents


def _wrap(dq: np.ndarray, period: float | None) -> np.ndarray:
    if period is None:
        return dq
    dq = dq.copy()
    dq[..., 0] = (dq[..., 0] + 0.5 * period) % period - 0.5 * period
    return dq


def neighbour_pairs_dense(x: np.ndarray, radius: float, period: float | None = None) -> np.ndarray:
    """Reference implementation: all pairs i < j with ``||x_j - x_i|| < radius``.

    ``x`` (N, m); returns (P, 2) int64. Builds N x N arrays: small N only.
    """
    n = len(x)
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    dq = _wrap(x[None, :, :] - x[:, None, :], period)
    dist = np.linalg.norm(dq, axis=-1)
    i, j = np.nonzero(np.triu(dist < radius, k=1))
    return np.stack([i, j], axis=1).astype(np.int64)


def neighbour_pairs_tree(x: np.ndarray, radius: float, period: float | None = None) -> np.ndarray:
    """All pairs i < j with ``||x_j - x_i|| < radius`` via a KD-tree; (P, 2) int64."""
    n = len(x)
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    pts, boxsize = tree_points(x, radius, period)
    # balanced_tree=False: sliding-midpoint splits instead of medians, a faster build
    # (the query is exact either way, so the pairs are the same).
    tree = cKDTree(pts, boxsize=boxsize, balanced_tree=False)
    # query_pairs uses <= r; shrink by one ulp-ish factor to match the strict "<".
    pairs = tree.query_pairs(np.nextafter(radius, 0.0), output_type="ndarray")
    return pairs.astype(np.int64, copy=False)


def tree_points(x: np.ndarray, radius: float, period: float | None):
    """Points and KD-tree ``boxsize`` for a periodic axis 0 (None: not periodic)."""
    if period is None:
        return x, None
    pts = np.array(x, dtype=float, copy=True)
    pts[:, 0] = np.mod(pts[:, 0], period)
    pts[:, 0][pts[:, 0] >= period] = 0.0
    box = np.empty(pts.shape[1])
    box[0] = period
    for k in range(1, pts.shape[1]):
        lo = pts[:, k].min()
        pts[:, k] -= lo
        box[k] = pts[:, k].max() + 2.0 * radius + 1.0
    return pts, box


def neighbour_pairs(
    x: np.ndarray, radius: float, period: float | None = None, method: str = "auto"
) -> np.ndarray:
    """Undirected neighbour pairs (P, 2), ``i < j``, with distance < ``radius`` (m).

    ``method``: "dense" (reference), "kdtree", or "auto" (dense up to
    ``DENSE_MAX_N`` agents, KD-tree above). Pairs are sorted lexicographically
    so that both methods return identical arrays.
    """
    x = np.asarray(x, dtype=float)
    n = len(x)
    if method == "dense" or (method == "auto" and n <= DENSE_MAX_N):
        pairs = neighbour_pairs_dense(x, radius, period)
    elif method in ("kdtree", "auto"):
        pairs = neighbour_pairs_tree(x, radius, period)
    else:
        raise ValueError(f"neighbour search method must be dense, kdtree or auto, not {method!r}")
    if len(pairs):
        # One int64 key per pair: i < j < n, so i * n + j orders the pairs as
        # np.lexsort((j, i)) does, with one sort of one array (several times faster).
        key = pairs[:, 0] * n + pairs[:, 1]
        key.sort()
        pairs = np.empty((len(key), 2), dtype=np.int64)
        np.divmod(key, n, out=(pairs[:, 0], pairs[:, 1]))
    return pairs


def cross_pairs(
    x: np.ndarray, y: np.ndarray, radius: float, period: float | None = None
) -> np.ndarray:
    """Pairs (i, k) with ``||y_k - x_i|| < radius`` between two point sets; (P, 2) int64.

    Used for agents versus sensed vehicles or obstacle boundary points.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if len(x) == 0 or len(y) == 0:
        return np.empty((0, 2), dtype=np.int64)
    if period is None:
        tree_y = cKDTree(y)
        lists = cKDTree(x).query_ball_tree(tree_y, np.nextafter(radius, 0.0))
    else:
        both, box = tree_points(np.vstack([x, y]), radius, period)
        tree_y = cKDTree(both[len(x) :], boxsize=box)
        lists = cKDTree(both[: len(x)], boxsize=box).query_ball_tree(
            tree_y, np.nextafter(radius, 0.0)
        )
    counts = np.fromiter((len(v) for v in lists), dtype=np.int64, count=len(lists))
    if counts.sum() == 0:
        return np.empty((0, 2), dtype=np.int64)
    i = np.repeat(np.arange(len(x), dtype=np.int64), counts)
    k = np.fromiter((kk for v in lists for kk in v), dtype=np.int64, count=int(counts.sum()))
    return np.stack([i, k], axis=1)


def scatter_add(n: int, index: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Sum rows of ``values`` (P, m) into an (n, m) array at rows ``index`` (P,).

    ``np.bincount`` per axis: several times faster than ``np.add.at``.
    """
    out = np.empty((n, values.shape[1]))
    for k in range(values.shape[1]):
        out[:, k] = np.bincount(index, weights=values[:, k], minlength=n)
    return out
