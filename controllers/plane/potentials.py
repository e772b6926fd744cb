"""Olfati-Saber's flocking building blocks, vectorised.

Reference: R. Olfati-Saber, "Flocking for multi-agent dynamic systems:
algorithms and theory", IEEE TAC 51(3), 2006 (below "OS06"), as restated in
seed 000 (sections "sigma-Norms", "Bumper Functions", "Potential Functions")
and seed 003 (eqs. 8-11). Equation numbers refer to OS06.

All functions accept numpy arrays and broadcast. Distances are in metres; the
sigma-norm of a length in metres is in "sigma-metres" (same unit for small
``epsilon * z**2``). Radii enter the law as their sigma-norms (``r_alpha =
||r||_sigma``, ``d_alpha = ||d||_sigma``) as in the paper.
"""

from __future__ import annotations

import numpy as np

# Gauss-Legendre nodes for the bump part of psi_alpha (integrand is smooth).
_GL_X, _GL_W = np.polynomial.legendre.leggauss(48)


def _sum_sq(z: np.ndarray) -> np.ndarray:
    """``np.sum(z * z, axis=-1)``; for 1 <= m <= 3 by column adds (same bits, ~5x faster).

    numpy adds fewer than 8 elements in order, so the column adds round the
    same way; ``np.sum`` over a short last axis has a large per-row overhead.
    """
    m = z.shape[-1]
    if not 1 <= m <= 3:
        return np.sum(z * z, axis=-1)
    out = z[..., 0] * z[..., 0]
    for k in range(1, m):
        out += z[..., k] * z[..., k]
    return out


def sigma_norm(z: np.ndarray, epsilon: float, axis: int = -1) -> np.ndarray:
    """Sigma-norm ``||z||_sigma = (sqrt(1 + eps ||z||^2) - 1) / eps`` (OS06 eq. 8).

    ``z`` has shape (..., m); the result has shape (...). Differentiable
    everywhere, unlike the Euclidean norm.
    """
    z = np.asarray(z, dtype=float)
    if z.ndim and axis in (-1, z.ndim - 1):
        sq = _sum_sq(z)
    else:
        sq = np.sum(z * z, axis=axis)
    return (np.sqrt(1.0 + epsilon * sq) - 1.0) / epsilon


def sigma_norm_scalar(x: np.ndarray | float, epsilon: float) -> np.ndarray:
    """Sigma-norm of a scalar length ``x`` >= 0 (e.g. ``r_alpha = ||r||_sigma``), m."""
    x = np.asarray(x, dtype=float)
    return (np.sqrt(1.0 + epsilon * x * x) - 1.0) / epsilon


def sigma_grad(z: np.ndarray, epsilon: float) -> np.ndarray:
    """Gradient of the sigma-norm, ``sigma_eps(z) = z / sqrt(1 + eps ||z||^2)`` (OS06 eq. 9).

    With ``z = q_j - q_i`` this is the vector ``n_ij`` of OS06 eq. 23 and seed 000.
    Shape (..., m) -> (..., m).
    """
    z = np.asarray(z, dtype=float)
    return z / np.sqrt(1.0 + epsilon * _sum_sq(z))[..., None]


def n_ij(q_i: np.ndarray, q_j: np.ndarray, epsilon: float) -> np.ndarray:
    """``n_ij = (q_j - q_i) / sqrt(1 + eps ||q_j - q_i||^2)`` (OS06 eq. 23)."""
    return sigma_grad(np.asarray(q_j) - np.asarray(q_i), epsilon)


def sigma_1(z: np.ndarray) -> np.ndarray:
    """Scalar uniformly bounded map ``sigma_1(z) = z / sqrt(1 + z^2)`` (OS06, below eq. 15)."""
    z = np.asarray(z, dtype=float)
    return z / np.sqrt(1.0 + z * z)


def sigma_1_vec(z: np.ndarray) -> np.ndarray:
    """Vector version ``z / sqrt(1 + ||z||^2)`` used in the gamma term (seed 003 eq. 11)."""
    z = np.asarray(z, dtype=float)
    return z / np.sqrt(1.0 + _sum_sq(z))[..., None]


def rho_h(z: np.ndarray, h: float) -> np.ndarray:
    """Bump function (OS06 eq. 10): 1 on [0, h), cosine fall on [h, 1], 0 elsewhere.

    Continuous (and C^1) on [0, inf). Values of ``z`` below 0 map to 0 as in
    the paper ("0 otherwise").
    """
    z = np.asarray(z, dtype=float)
    out = np.zeros_like(z)
    out[(z >= 0.0) & (z < h)] = 1.0
    mid = (z >= h) & (z <= 1.0)
    out[mid] = 0.5 * (1.0 + np.cos(np.pi * (z[mid] - h) / (1.0 - h)))
    return out


def phi(z: np.ndarray, a: float, b: float) -> np.ndarray:
    """Uneven sigmoid ``phi(z) = ((a+b) sigma_1(z+c) + (a-b)) / 2``, ``c = |a-b|/sqrt(4ab)``.

    OS06 eq. 15; ``0 < a <= b`` guarantees ``phi(0) = 0``.
    """
    c = abs(a - b) / np.sqrt(4.0 * a * b)
    return 0.5 * ((a + b) * sigma_1(np.asarray(z, dtype=float) + c) + (a - b))


def _phi_antiderivative(y: np.ndarray, a: float, b: float) -> np.ndarray:
    """Antiderivative of ``phi``: ``((a+b) sqrt(1 + (y+c)^2) + (a-b) y) / 2``."""
    c = abs(a - b) / np.sqrt(4.0 * a * b)
    return 0.5 * ((a + b) * np.sqrt(1.0 + (y + c) ** 2) + (a - b) * y)


def phi_alpha(z: np.ndarray, r_alpha: float, d_alpha: float, h: float, a: float, b: float):
    """Action function ``phi_alpha(z) = rho_h(z / r_alpha) phi(z - d_alpha)`` (OS06 eq. 15).

    ``z``, ``r_alpha``, ``d_alpha`` are sigma-norms. Zero at ``z = d_alpha``
    and for ``z >= r_alpha``.
    """
    z = np.asarray(z, dtype=float)
    return rho_h(z / r_alpha, h) * phi(z - d_alpha, a, b)


def psi_alpha(z: np.ndarray, r_alpha: float, d_alpha: float, h: float, a: float, b: float):
    """Pairwise potential ``psi_alpha(z) = integral_{d_alpha}^{z} phi_alpha(s) ds`` (OS06 eq. 16).

    Exact on the plateau ``s < h r_alpha`` (closed-form antiderivative of phi),
    48-point Gauss-Legendre on the bump ``[h r_alpha, min(z, r_alpha)]``.
    Constant for ``z >= r_alpha``. Used for the flock's energy H.
    """
    z = np.asarray(z, dtype=float)

    def big_g(x: np.ndarray) -> np.ndarray:
        # integral_0^x phi_alpha(s) ds
        x = np.asarray(x, dtype=float)
        s_h = h * r_alpha
        plateau = _phi_antiderivative(np.minimum(x, s_h) - d_alpha, a, b) - _phi_antiderivative(
            -d_alpha, a, b
        )
        upper = np.clip(x, s_h, r_alpha)
        half = 0.5 * (upper - s_h)
        nodes = s_h + half[..., None] * (_GL_X + 1.0)
        bump = half * np.sum(_GL_W * phi_alpha(nodes, r_alpha, d_alpha, h, a, b), axis=-1)
        return plateau + bump

    return big_g(z) - big_g(np.asarray(d_alpha))


def phi_beta(z: np.ndarray, d_beta: float, h: float) -> np.ndarray:
    """Repulsive action ``phi_beta(z) = rho_h(z / d_beta) (sigma_1(z - d_beta) - 1)`` (OS06 eq. 56).

    Negative (repulsive) for ``z < d_beta``, zero beyond; sigma-norm units.
    """
    z = np.asarray(z, dtype=float)
    return rho_h(z / d_beta, h) * (sigma_1(z - d_beta) - 1.0)


def adjacency(z_sigma: np.ndarray, r_sigma: float, h: float) -> np.ndarray:
    """Smooth adjacency ``a_ij = rho_h(||q_j - q_i||_sigma / r_alpha)`` in [0, 1] (OS06 eq. 11).

    The same form with ``d_beta`` gives ``b_ik`` (OS06 eq. 57).
    """
    return rho_h(np.asarray(z_sigma, dtype=float) / r_sigma, h)
