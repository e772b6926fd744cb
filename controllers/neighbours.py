"""Neighbour search without N x N arrays.

``neighbour_pairs`` returns the undirected pairs (i < j) whose (scaled)
distance is below a radius. The KD-tree path (scipy's cKDTree) costs
O(N log N) time and O(N + pairs) memory; the dense path builds the N x N
distance matrix and exists only as a reference for tests and small N. scipy is imported
where the tree is built (not when the package is: ``cosim list`` needs none of it).
A periodic axis 0 (ring road of length ``period``) is handled by the tree's
``boxsize``; the other axes are shifted so that they never wrap.
"""

from __future__ import annotations

import numpy as np

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
    from scipy.spatial import cKDTree

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

    Used for agents versus sensed vehicles or obstacle boundary points. Pairs
    are grouped by ``i`` in increasing order, deterministically. Point sets in
    a strip thinner than the radius along axes 1.. (a road seen from above)
    take a sort-and-window path along axis 0 (``strip_cross_pairs``); others
    a KD-tree.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if len(x) == 0 or len(y) == 0:
        return np.empty((0, 2), dtype=np.int64)
    if _is_strip(x, y, radius, period):
        return strip_cross_pairs(x, y, radius, period)
    from scipy.spatial import cKDTree

    if period is None:
        tree_x, tree_y = cKDTree(x), cKDTree(y)
    else:
        both, box = tree_points(np.vstack([x, y]), radius, period)
        tree_x = cKDTree(both[: len(x)], boxsize=box)
        tree_y = cKDTree(both[len(x) :], boxsize=box)
    # sparse_distance_matrix uses <= r: shrink by one ulp to match the strict "<".
    m = tree_x.sparse_distance_matrix(tree_y, np.nextafter(radius, 0.0), output_type="ndarray")
    return _sorted_pairs(m["i"].astype(np.int64), m["j"].astype(np.int64), len(y))


def _sorted_pairs(i: np.ndarray, k: np.ndarray, n_y: int) -> np.ndarray:
    key = i * n_y + k
    key.sort()
    out = np.empty((len(key), 2), dtype=np.int64)
    np.divmod(key, n_y, out=(out[:, 0], out[:, 1]))
    return out


def _is_strip(x: np.ndarray, y: np.ndarray, radius: float, period: float | None) -> bool:
    """True when every point lies within a band of width < radius across axis 0."""
    if x.shape[1] < 2:
        return False
    lo = np.minimum(x[:, 1:].min(axis=0), y[:, 1:].min(axis=0))
    hi = np.maximum(x[:, 1:].max(axis=0), y[:, 1:].max(axis=0))
    if np.any(hi - lo >= radius):
        return False
    return period is None or period > 2.0 * radius


def strip_cross_pairs(
    x: np.ndarray, y: np.ndarray, radius: float, period: float | None = None
) -> np.ndarray:
    """``cross_pairs`` by sorting ``y`` along axis 0 and windowing ``|dx_0| < radius``.

    Exact for any input (candidates are filtered by the true distance); fast
    when the points are spread along axis 0 and thin across it, since then the
    window holds few more candidates than the ball. Periodic axis 0 needs
    ``period > 2 radius``. (P, 2) int64 grouped by ``i``; within a group ``k``
    follows axis 0.
    """
    key = y[:, 0] if period is None else np.mod(y[:, 0], period)
    order = np.argsort(key, kind="stable")
    s_sorted = key[order]
    if period is not None:  # copies one period below and above close the ring
        s_sorted = np.concatenate([s_sorted - period, s_sorted, s_sorted + period])
        order = np.concatenate([order, order, order])
    s_x = x[:, 0] if period is None else np.mod(x[:, 0], period)
    lo = np.searchsorted(s_sorted, s_x - radius, side="right")
    hi = np.searchsorted(s_sorted, s_x + radius, side="left")
    counts = np.maximum(hi - lo, 0)
    total = int(counts.sum())
    if total == 0:
        return np.empty((0, 2), dtype=np.int64)
    i = np.repeat(np.arange(len(x), dtype=np.int64), counts)
    # position inside each window: global index minus the window's first index
    starts = np.cumsum(counts) - counts
    pos = np.arange(total, dtype=np.int64) - np.repeat(starts, counts) + np.repeat(lo, counts)
    k = order[pos].astype(np.int64, copy=False)
    dq = y[k] - x[i]
    dq = _wrap(dq, period)
    keep = np.einsum("ij,ij->i", dq, dq) < radius * radius
    return np.stack([i[keep], k[keep]], axis=1)


def scatter_add(n: int, index: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Sum rows of ``values`` (P, m) into an (n, m) array at rows ``index`` (P,).

    ``np.bincount`` per axis: several times faster than ``np.add.at``.
    """
    out = np.empty((n, values.shape[1]))
    for k in range(values.shape[1]):
        out[:, k] = np.bincount(index, weights=values[:, k], minlength=n)
    return out
