"""Flock metrics from positions (N, m) in m and velocities (N, m) in m/s.

Pure numpy/scipy; neighbour queries use a KD-tree, never N x N arrays.
Sources:
* OS06: R. Olfati-Saber, IEEE TAC 51(3), 2006 — deviation energy (eq. 7),
  velocity mismatch (kinetic energy of relative velocities, Sec. VIII),
  connectivity of the proximity net (Sec. II).
* Seed 003 (Sec. 4): minimum distance between agents and to obstacle points.
* Seed 004 (MATLAB "Calculate metrics"): average nearest-neighbour distance,
  velocity alignment and group dispersion ``sqrt(var(x) + var(y))``. The seed's
  alignment line compares each unit velocity with itself (always 1); we use
  the intended order parameter ``||mean(p_i / ||p_i||)||`` (Vicsek et al. 1995).
"""

from __future__ import annotations

import numpy as np

from controllers.neighbours import DENSE_MAX_N, neighbour_pairs, tree_points
from controllers.observation import Circles, Walls


def nearest_neighbour_distances(q: np.ndarray, period: float | None = None) -> np.ndarray:
    """Distance from each agent to its nearest other agent, (N,) m (inf if N < 2)."""
    if len(q) < 2:
        return np.full(len(q), np.inf)
    q = np.asarray(q, dtype=float)
    # The lateral box must exceed the lateral span so that only axis 0 wraps.
    span = float(np.ptp(q[:, 1:])) if q.shape[1] > 1 else 0.0
    from scipy.spatial import cKDTree  # here, not at import: `cosim list` needs none of it

    pts, box = tree_points(q, max(1.0, span), period)
    dist, _ = cKDTree(pts, boxsize=box).query(pts, k=2)
    return dist[:, 1]


def min_pair_distance(q: np.ndarray, period: float | None = None) -> float:
    """Minimum centre distance between any two agents, m (seed 003 Fig. "minimum distance")."""
    return float(np.min(nearest_neighbour_distances(q, period))) if len(q) > 1 else np.inf


def average_nn_distance(q: np.ndarray, period: float | None = None) -> float:
    """Mean over agents of the nearest-neighbour distance, m (seed 004 avg_neighbor_distance)."""
    return float(np.mean(nearest_neighbour_distances(q, period))) if len(q) > 1 else np.nan


def min_obstacle_distance(
    q: np.ndarray, circles: Circles | None = None, walls: Walls | None = None
) -> float:
    """Minimum distance from any agent to a circle's surface or a wall, m (negative: inside)."""
    best = np.inf
    if circles is not None and len(circles.radii):
        for y, r in zip(circles.centres, circles.radii, strict=True):
            best = min(best, float(np.min(np.linalg.norm(q - y, axis=1) - r)))
    if walls is not None and len(walls.points):
        for y, a in zip(walls.points, walls.normals, strict=True):
            best = min(best, float(np.min((q - y) @ a)))
    return best


def velocity_mismatch(p: np.ndarray, p_ref: np.ndarray | None = None) -> float:
    """Mean squared velocity deviation ``(1/N) sum ||p_i - p_c||^2``, m^2/s^2.

    ``p_c`` is the flock's mean velocity, or ``p_ref`` (the leader's) when given:
    twice the kinetic energy of relative motion per agent (OS06 Sec. VIII).
    """
    if len(p) == 0:
        return np.nan
    c = p.mean(axis=0) if p_ref is None else np.asarray(p_ref)
    return float(np.mean(np.sum((p - c) ** 2, axis=1)))


def deviation_energy(q: np.ndarray, d: float, r: float, period: float | None = None,
                     pairs: np.ndarray | None = None) -> float:
    """Lattice deviation energy ``E = 1/(|E|+1) sum_(i,j in E) (||q_j - q_i|| - d)^2``, m^2.

    OS06 eq. 7 with the proximity net of range ``r`` (directed edges, so each
    undirected pair counts twice in the sum and in ``|E|``). Zero for a perfect
    alpha-lattice. ``pairs``: that net's ``neighbour_pairs(q, r, period)`` (P, 2) if
    already known.
    """
    if pairs is None:
        pairs = neighbour_pairs(q, r, period, "auto")
    if len(pairs) == 0:
        return 0.0
    dq = q[pairs[:, 1]] - q[pairs[:, 0]]
    if period is not None:
        dq[:, 0] = (dq[:, 0] + 0.5 * period) % period - 0.5 * period
    dev = np.linalg.norm(dq, axis=1) - d
    return float(2.0 * np.sum(dev**2) / (2 * len(pairs) + 1))


def velocity_alignment(p: np.ndarray) -> float:
    """Order parameter ``||(1/N) sum p_i / ||p_i||||`` in [0, 1] (1: all headings equal)."""
    speed = np.linalg.norm(p, axis=1)
    moving = speed > 1e-12
    if not moving.any():
        return np.nan
    return float(np.linalg.norm(np.mean(p[moving] / speed[moving, None], axis=0)))


def dispersion(q: np.ndarray) -> float:
    """Group spatial dispersion ``sqrt(sum_k var(q[:, k]))``, m (seed 004; sample variance)."""
    if len(q) < 2:
        return 0.0
    return float(np.sqrt(np.sum(np.var(q, axis=0, ddof=1))))


def connectivity(q: np.ndarray, r: float, period: float | None = None,
                 pairs: np.ndarray | None = None) -> tuple[int, float]:
    """Proximity-graph connectivity: (number of components, largest component share).

    Graph edges join agents closer than ``r`` (m), OS06's proximity net; ``pairs``: its
    ``neighbour_pairs(q, r, period)`` (P, 2) if already known.
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(q)
    if n == 0:
        return 0, np.nan
    if pairs is None:
        pairs = neighbour_pairs(q, r, period, "auto")
    # CSR straight from the pairs grouped by row (neighbour_pairs sorts them): the graph a
    # COO matrix of the pairs converts to, without the conversion.
    if len(pairs) > 1 and np.any(pairs[1:, 0] < pairs[:-1, 0]):
        pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
    indptr = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(np.bincount(pairs[:, 0], minlength=n), out=indptr[1:])
    graph = csr_matrix((np.ones(len(pairs)), pairs[:, 1].astype(np.int32), indptr),
                       shape=(n, n))
    k, labels = connected_components(graph, directed=False)
    return int(k), float(np.bincount(labels).max() / n)


def flock_metrics(
    q: np.ndarray,
    p: np.ndarray,
    d: float,
    r: float,
    p_ref: np.ndarray | None = None,
    circles: Circles | None = None,
    walls: Walls | None = None,
    period: float | None = None,
) -> dict[str, float]:
    """All flock metrics of one instant, keyed by column name (units in the name).

    The proximity net and the nearest-neighbour distances are computed once and shared;
    in the plane of the road (m = 2, finite float64 positions) by compiled searches that
    give the same pairs, components and distances (:func:`_net_2d`)."""
    if _compiled_ok(q) and _compiled_ok(p, finite=False):
        return _metrics_2d(q, p, d, r, p_ref, circles, walls, period)
    if _compiled_ok(q):
        pairs, n_comp, largest, nn = _net_2d(q, r, period)
    else:
        pairs = neighbour_pairs(q, r, period, "auto") if len(q) else None
        n_comp, largest = connectivity(q, r, period, pairs)
        nn = nearest_neighbour_distances(q, period) if len(q) > 1 else None
    return {
        "min_agent_distance_m": float(np.min(nn)) if nn is not None else np.inf,
        "min_obstacle_distance_m": min_obstacle_distance(q, circles, walls),
        "velocity_mismatch_m2ps2": velocity_mismatch(p),
        "leader_velocity_mismatch_m2ps2": (
            velocity_mismatch(p, p_ref) if p_ref is not None else np.nan
        ),
        "deviation_energy_m2": deviation_energy(q, d, r, period, pairs),
        "avg_nn_distance_m": float(np.mean(nn)) if nn is not None else np.nan,
        "velocity_alignment": velocity_alignment(p),
        "dispersion_m": dispersion(q),
        "n_components": n_comp,
        "largest_component_share": largest,
    }


def _compiled_ok(q, finite: bool = True) -> bool:
    """True when :func:`_net_2d` applies: (N, 2) float64 positions, N >= 2, all finite
    (``finite``: else any values)."""
    return (isinstance(q, np.ndarray) and q.dtype == np.float64 and q.ndim == 2
            and q.shape[1] == 2 and len(q) >= 2
            and (not finite or bool(np.isfinite(q).all())))


def _metrics_2d(q, p, d, r, p_ref, circles, walls, period) -> dict[str, float]:
    """:func:`flock_metrics` of (N, 2) float64 positions (finite) and velocities, N >= 2:
    :func:`_net_2d` and the sums of :func:`cosim.metrics.kernels.flock_moments`, the same
    bits as the numpy functions above (tests/test_metrics_exactness.py)."""
    from cosim.metrics import kernels as K  # numba: imported when first used

    q, p = np.ascontiguousarray(q), np.ascontiguousarray(p)
    pairs, n_comp, largest, nn = _net_2d(q, r, period)
    (mismatch, u0, u1, moving, dispersion_m, energy, nn_min, nn_mean) = K.flock_moments(
        q, p, pairs, float(d), period is not None, 0.0 if period is None else float(period),
        nn)
    return {
        "min_agent_distance_m": float(nn_min),
        "min_obstacle_distance_m": min_obstacle_distance(q, circles, walls),
        "velocity_mismatch_m2ps2": float(mismatch),
        "leader_velocity_mismatch_m2ps2": (
            velocity_mismatch(p, p_ref) if p_ref is not None else np.nan
        ),
        "deviation_energy_m2": float(energy),
        "avg_nn_distance_m": float(nn_mean),
        "velocity_alignment": (float(np.linalg.norm(np.array([u0, u1]))) if moving
                               else np.nan),
        "dispersion_m": float(dispersion_m),
        "n_components": n_comp,
        "largest_component_share": largest,
    }


def _net_2d(q: np.ndarray, r: float, period: float | None):
    """``(pairs, n_components, largest_share, nn)`` of :func:`flock_metrics` for (N, 2)
    positions (N >= 2): :func:`neighbour_pairs` ``"auto"`` (the dense test up to
    ``DENSE_MAX_N`` agents, the tree's above it), :func:`connectivity` and
    :func:`nearest_neighbour_distances`, each computed as those compute it, by the compiled
    kernels of :mod:`cosim.metrics.kernels` (tests/test_recorder_exactness.py)."""
    from cosim.metrics import kernels as K  # numba: imported when first used

    n = len(q)
    periodic = period is not None
    per = float(period) if periodic else 0.0
    if n <= DENSE_MAX_N:
        x = np.ascontiguousarray(q[:, 0])
        y = np.ascontiguousarray(q[:, 1])
        pairs = K.dense_pairs(x, y, float(r), periodic, per)
    else:
        pts, box = tree_points(q, r, period)
        pairs = K.pairs_within(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]),
                               float(np.nextafter(r, 0.0)), periodic, per,
                               float(box[1]) if periodic else 0.0)
        pairs = K.sorted_pairs(pairs, n)
    n_comp, largest = K.components(pairs, n)
    span = float(np.ptp(q[:, 1:]))
    pts, box = tree_points(q, max(1.0, span), period)
    nn = K.nearest_distances(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]),
                             periodic, per, float(box[1]) if periodic else 0.0)
    return pairs, int(n_comp), float(largest / n), nn
