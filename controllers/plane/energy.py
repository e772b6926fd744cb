"""The flock's total energy H (OS06 eq. 61; seed 003 eq. 20), for stability checks.

``H = sum_(i<j) c1_alpha psi_alpha(||S q_ij||_sigma)``
``    + sum_i [U_gamma(q_i - q_r) + ||p_i - p_r||^2 / 2]``

with ``U_gamma(e) = sum_k c1_gamma_k e_k^2 / 2`` for the linear gamma term and
``c1_gamma (sqrt(1 + ||e||^2) - 1)`` for the sigma_1 term (a scalar gain).
Units: m^2/s^2 (energy per unit mass). With a static leader, no obstacles and
c2 > 0 the law makes H non-increasing (seed 003 Theorem 1 (i)), so every agent
stays within ``sqrt(2 H_0 / c1_gamma)`` of the leader.
"""

from __future__ import annotations

import numpy as np

from controllers.neighbours import neighbour_pairs
from controllers.plane.olfati_saber import OlfatiSaberController
from controllers.plane.potentials import psi_alpha, sigma_norm


def flock_energy(
    law: OlfatiSaberController,
    q: np.ndarray,
    p: np.ndarray,
    q_r: np.ndarray | None,
    p_r: np.ndarray | None,
    period: float | None = None,
) -> float:
    """Total energy H (m^2/s^2) of positions ``q`` (N, m) and velocities ``p`` (N, m)."""
    prm = law.params
    n, m = q.shape
    s = prm.scale(m)
    pairs = neighbour_pairs(q * s, prm.r, None if period is None else period * s[0], "auto")
    h = 0.0
    if len(pairs):
        z = q[pairs[:, 1]] - q[pairs[:, 0]]
        if period is not None:
            z[:, 0] = (z[:, 0] + 0.5 * period) % period - 0.5 * period
        zs = sigma_norm(z * s, prm.epsilon)
        h += prm.c1_alpha * float(
            np.sum(psi_alpha(zs, law.r_alpha, law.d_alpha, prm.h_alpha, prm.a, prm.b))
        )
    # Pairs beyond r contribute psi_alpha(r_alpha), a constant: count them so H is continuous.
    n_pairs_total = n * (n - 1) // 2
    far = n_pairs_total - len(pairs)
    if far:
        h += (
            prm.c1_alpha
            * far
            * float(
                psi_alpha(
                    np.array(law.r_alpha), law.r_alpha, law.d_alpha, prm.h_alpha, prm.a, prm.b
                )
            )
        )
    if q_r is not None:
        e = q - q_r
        if period is not None:
            e[:, 0] = (e[:, 0] + 0.5 * period) % period - 0.5 * period
        c1 = prm.gains("c1_gamma", m)
        if prm.gamma_position == "linear":
            h += 0.5 * float(np.sum(c1 * e * e))
        else:
            h += float(c1[0] * np.sum(np.sqrt(1.0 + np.sum(e * e, axis=1)) - 1.0))
    dv = p if p_r is None else p - p_r
    h += 0.5 * float(np.sum(dv * dv))
    return h
