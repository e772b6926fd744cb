"""Olfati-Saber Algorithm 3: ``u = u_alpha + u_beta + u_gamma`` (OS06 eq. 59), vectorised.

Algorithms 1 and 2 are special cases (no beta; no beta and no gamma gains on
position). Differences from seed 000's MATLAB script, on purpose:

* the script adds each neighbour's running sum again on every iteration
  (``u_i_a_term01 = u_i_a_term01 + phia_nij`` where ``phia_nij`` is already a
  running sum), counting near neighbours several times; we sum each
  neighbour once, as the paper does;
* the script divides by Euclidean ``r`` and ``d`` (``rho_h(z / r)``,
  ``phi(z - d)``) where ``z`` is a sigma-norm; we use ``r_alpha = ||r||_sigma``
  and ``d_alpha = ||d||_sigma`` as in the paper (same for d', d'');
* the gamma dynamic weight ``C(x, u) = x (tanh(u) + 1)`` uses the obstacle
  beta term per axis, as the script does (the paper's text does not say).

Beyond the paper, for road vehicles:

* anisotropic spacing: the alpha and vehicle terms act in coordinates scaled
  by ``S = diag(d / d_long, d / d_lat)``; the force is the true gradient
  ``S phi n(S z)`` of the scaled potential, so the flock's energy argument
  still holds, and ``d_long = d_lat = d`` gives the isotropic law exactly;
* sensed non-cooperating vehicles are beta-agents at the nearest point of the
  Minkowski sum of the two rectangles (so the gap is bumper to bumper) with the
  vehicle's own velocity;
* road edges and walls are beta-agents at the projection (seed 000; seed 003
  eq. 5) measured from the vehicle's side; with a barrier floor (below) an
  agent already beyond a wall is still pushed back in;
* the repulsion ``phi_beta(z) n_hat(z)`` of the paper vanishes at contact
  (``n_hat`` is proportional to ``z``), and for an agent past a wall or inside
  a circle the beta-agent lies on the other side, so the paper's term pushes
  it further out of the free space. ``FlockingParams.barrier_floor`` chooses:
  "peak" (the default of FlockingParams) floors the gap of every wall, circle
  and vehicle interaction at the gap where that repulsion peaks, so the
  barrier is monotone and at its largest for agents in contact, inside or
  past it (a saturated barrier; for seed 000's constants the floor covers
  2.39 m of the 3 m edge range and 10.19 m of the 12 m obstacle range);
  "none" is the paper's law exactly (``cosim plane seed000`` uses it); a
  number floors every gap at that many m.

With ``barrier_floor="none"``, isotropic spacing and point agents (no sensed
vehicles, which the script lacks), the law equals seed 000's MATLAB appendix
corrected for the first two points above, to rounding: 1e-11 m/s^2 on random
states (tests/test_seed000_matlab.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.neighbours import DENSE_MAX_N, cross_pairs, neighbour_pairs, scatter_add
from controllers.observation import Observation
from controllers.plane.params import FlockingParams
from controllers.plane.potentials import (
    _sum_sq,
    adjacency,
    phi,
    phi_beta,
    rho_h,
    sigma_1_vec,
    sigma_grad,
    sigma_norm,
    sigma_norm_scalar,
)

_MIN_GAP = 1e-3  # m: distance used for a beta-agent when the agent is at or past it


@dataclass
class FlockTerms:
    """The parts of one step's command, each (N, m) in m/s^2."""

    alpha: np.ndarray
    beta: np.ndarray  # circles and sensed vehicles
    wall: np.ndarray  # walls and road edges
    gamma: np.ndarray
    n_pairs: int = 0

    @property
    def total(self) -> np.ndarray:
        return self.alpha + self.beta + self.wall + self.gamma


class OlfatiSaberController:
    """Flocking law of OS06 Algorithm 3 with the seeds' extensions.

    ``compute(obs)`` returns ``u`` (N, m) in m/s^2; ``last_terms`` keeps the
    split into alpha, beta, wall and gamma parts of the last call.

    ``verlet_skin`` (scaled m, default 0 = off) turns on a Verlet neighbour
    list for the KD-tree search of the alpha term: pairs within ``r + skin``
    are kept and reused while no agent has moved more than ``skin / 2``
    relative to the flock's mean displacement. The forces are the same as
    without it (pairs between ``r`` and ``r + skin`` add exact zeros); the
    list is keyed by the agents' ids, N, m, the period and the radius, and
    rebuilt whenever any of them changes, so one controller may serve any
    sequence of observations.
    """

    name = "olfati_saber"

    def __init__(self, params: FlockingParams | None = None, verlet_skin: float = 0.0) -> None:
        if not (np.isfinite(verlet_skin) and verlet_skin >= 0.0):
            raise ValueError(f"verlet_skin must be finite and >= 0, got {verlet_skin!r}")
        self.verlet_skin = float(verlet_skin)
        self.verlet_stats = {"steps": 0, "rebuilds": 0}
        self._verlet: dict | None = None
        self.params = params or FlockingParams()
        p = self.params
        eps = p.epsilon
        self.r_alpha = float(sigma_norm_scalar(p.r, eps))
        self.d_alpha = float(sigma_norm_scalar(p.d, eps))
        self.d_beta = float(sigma_norm_scalar(p.d_beta, eps))
        self.d_vehicle = float(sigma_norm_scalar(p.d_vehicle, eps))
        self.d_wall = float(sigma_norm_scalar(p.d_wall, eps))
        # Floors (m) on the beta gaps (see module docstring and FlockingParams.barrier_floor):
        # "peak": the gap at which |phi_beta(z) n_hat(z)| peaks, so the barrier is monotone;
        # "none": -inf, the paper's law; a number: that gap for every interaction.
        if p.barrier_floor == "peak":
            self.wall_floor = self._repulsion_peak(p.d_wall, self.d_wall)
            self.vehicle_floor = self._repulsion_peak(p.d_vehicle, self.d_vehicle)
            self.circle_floor = self._repulsion_peak(p.d_beta, self.d_beta)
        else:
            floor = -np.inf if p.barrier_floor == "none" else float(p.barrier_floor)
            self.wall_floor = self.vehicle_floor = self.circle_floor = floor
        self.last_terms: FlockTerms | None = None

    def _repulsion_peak(self, d_m: float, d_sigma: float) -> float:
        """Gap in (0, d_m] where ``|phi_beta(||z||_sigma)| ||n_hat(z)||`` is largest, m."""
        p = self.params
        z = np.linspace(1e-4, d_m, 2001)
        zs = sigma_norm_scalar(z, p.epsilon)
        force = -phi_beta(zs, d_sigma, p.h_beta) * z / np.sqrt(1.0 + p.epsilon * z * z)
        return float(z[int(np.argmax(force))])

    # ------------------------------------------------------------------
    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations (N, m), m/s^2, for the observation."""
        obs.check_finite()
        terms = self.terms(obs)
        self.last_terms = terms
        return terms.total

    def terms(self, obs: Observation) -> FlockTerms:
        """All parts of the law for one observation."""
        n, m = obs.q.shape
        zero = np.zeros((n, m))
        if n == 0:
            return FlockTerms(zero, zero.copy(), zero.copy(), zero.copy())
        s = self.params.scale(m)
        alpha, n_pairs = self.alpha_term(obs, s)
        beta = self.circle_term(obs) + self.vehicle_term(obs, s)
        wall = self.wall_term(obs)
        gamma = self.gamma_term(obs, beta)
        return FlockTerms(alpha, beta, wall, gamma, n_pairs)

    # ------------------------------------------------------------------
    def alpha_term(self, obs: Observation, s: np.ndarray) -> tuple[np.ndarray, int]:
        """``c1 sum phi_alpha(||q_ij||_sigma) S n_ij + c2 sum a_ij (p_j - p_i)`` (OS06 eq. 23).

        Returns the term (N, m) and the number of neighbour pairs (scaled
        distance below ``r``).
        """
        p = self.params
        x = obs.q * s
        period = None if obs.period_s is None else obs.period_s * s[0]
        n = len(x)
        tree = p.neighbour_search == "kdtree" or (p.neighbour_search == "auto" and n > DENSE_MAX_N)
        if self.verlet_skin > 0.0 and n > 1 and tree:
            pairs = self._verlet_pairs(obs, x, period)  # within r + skin: a superset
            u, sq = self._alpha_pair_forces(obs, s, pairs)
            return u, int(np.count_nonzero(sq < p.r * p.r))
        pairs = neighbour_pairs(x, p.r, period, p.neighbour_search)
        u, _ = self._alpha_pair_forces(obs, s, pairs)
        return u, len(pairs)

    def _alpha_pair_forces(
        self, obs: Observation, s: np.ndarray, pairs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Alpha term (N, m) of the pairs (P, 2), ``i < j``, and ``||z_ij||^2`` (P,), scaled m^2.

        Per pair, with ``z = S (q_j - q_i)`` (wrapped on a ring) and
        ``root = sqrt(1 + eps ||z||^2)``: ``||z||_sigma = (root - 1) / eps``
        (OS06 eq. 8), ``n_ij = z / root`` (eq. 23, 9), ``a_ij = rho_h(||z||_sigma /
        r_alpha)`` (eq. 11), ``phi_alpha = a_ij phi(||z||_sigma - d_alpha)``
        (eq. 15), and ``f_ij = c1 phi_alpha S n_ij + c2 a_ij (p_j - p_i)`` acts on
        i, ``-f_ij`` on j (antisymmetric pair terms). One sqrt and one rho_h
        serve both uses; pairs at scaled distance >= r add exact zeros.
        """
        p = self.params
        n, m = obs.q.shape
        if len(pairs) == 0:
            return np.zeros((n, m)), np.zeros(0)
        i = np.ascontiguousarray(pairs[:, 0])
        j = np.ascontiguousarray(pairs[:, 1])
        # np.take: row gathers several times faster than fancy indexing q[j].
        z = obs.relative(np.take(obs.q, j, axis=0) - np.take(obs.q, i, axis=0)) * s
        dp = np.take(obs.p, j, axis=0) - np.take(obs.p, i, axis=0)
        sq = _sum_sq(z)
        root = np.sqrt(1.0 + p.epsilon * sq)
        z_sigma = (root - 1.0) / p.epsilon
        a_ij = rho_h(z_sigma / self.r_alpha, p.h_alpha)
        w = (p.c1_alpha * a_ij * phi(z_sigma - self.d_alpha, p.a, p.b)) / root
        c2a = p.c2_alpha * a_ij
        u = np.empty((n, m))
        for k in range(m):
            f_k = (w * s[k]) * z[:, k] + c2a * dp[:, k]
            u[:, k] = np.bincount(i, f_k, minlength=n) - np.bincount(j, f_k, minlength=n)
        return u, sq

    def _verlet_pairs(self, obs: Observation, x: np.ndarray, period: float | None):
        """Pairs within ``r + verlet_skin`` of the last rebuild, rebuilt when they may miss one.

        ``x`` (N, m) scaled positions, ``period`` scaled ring length or None. A
        common translation does not change pair distances, so while every
        agent's displacement since the rebuild minus the mean displacement is
        below ``skin / 2`` (with a 1e-6 relative margin for rounding), no pair
        can have come from beyond ``r + skin`` to within ``r``.
        """
        radius = self.params.r + self.verlet_skin
        c = self._verlet
        self.verlet_stats["steps"] += 1
        if (
            c is not None
            and c["x"].shape == x.shape
            and c["period"] == period
            and c["radius"] == radius
            and np.array_equal(c["ids"], obs.ids)
        ):
            dx = x - c["x"]
            if period is not None:
                dx[:, 0] = (dx[:, 0] + 0.5 * period) % period - 0.5 * period
            dx -= dx.mean(axis=0)
            limit = (0.5 * self.verlet_skin * (1.0 - 1e-6)) ** 2
            if float(_sum_sq(dx).max()) <= limit:
                return c["pairs"]
        self.verlet_stats["rebuilds"] += 1
        pairs = neighbour_pairs(x, radius, period, self.params.neighbour_search)
        self._verlet = {
            "x": x.copy(),
            "period": period,
            "radius": radius,
            "ids": np.array(obs.ids, copy=True),
            "pairs": pairs,
        }
        return pairs

    def _beta_pair(self, dq_hat, dp_hat, d_sigma, c1, c2, s=None):
        """One beta interaction per row: ``c1 phi_beta n_hat + c2 b_ik (p_hat - p_i)``.

        ``dq_hat = q_hat - q_i`` (P, m) m; ``dp_hat = p_hat - p_i`` (P, m) m/s.
        """
        p = self.params
        z = dq_hat if s is None else dq_hat * s
        z_sigma = sigma_norm(z, p.epsilon)
        n_hat = sigma_grad(z, p.epsilon)
        if s is not None:
            n_hat = n_hat * s
        grad = phi_beta(z_sigma, d_sigma, p.h_beta)[:, None] * n_hat
        b_ik = adjacency(z_sigma, d_sigma, p.h_beta)[:, None]
        return c1 * grad + c2 * b_ik * dp_hat

    def circle_term(self, obs: Observation) -> np.ndarray:
        """Circular obstacles: ``q_hat = mu q + (1 - mu) y``, ``p_hat = mu P p`` (OS06 eq. 51)."""
        p = self.params
        n, m = obs.q.shape
        if obs.circles is None or len(obs.circles.radii) == 0:
            return np.zeros((n, m))
        y, radius = obs.circles.centres, obs.circles.radii
        v = obs.relative(obs.q[:, None, :] - y[None, :, :])  # (N, K, m)
        dist = np.linalg.norm(v, axis=-1)
        dist = np.maximum(dist, 1e-9)
        a_k = v / dist[..., None]
        mu = radius[None, :] / dist
        ii, kk = np.nonzero(dist - radius[None, :] < p.r_beta)
        if len(ii) == 0:
            return np.zeros((n, m))
        ak = a_k[ii, kk]
        # q_hat - q = (mu - 1)(q - y) = -a_k (||q - y|| - R); the signed gap is floored
        # (with a floor, agents inside the circle are pushed out along the outward normal a_k;
        # without one, the paper's law pushes them towards the centre).
        signed = dist[ii, kk] - radius[kk]
        q_hat_rel = -ak * np.maximum(signed, self.circle_floor)[:, None]
        p_i = obs.p[ii]
        p_hat = mu[ii, kk][:, None] * (p_i - ak * np.sum(ak * p_i, axis=1, keepdims=True))
        f = self._beta_pair(q_hat_rel, p_hat - p_i, self.d_beta, p.c1_beta, p.c2_beta)
        return scatter_add(n, ii, f)

    def wall_term(self, obs: Observation) -> np.ndarray:
        """Walls (seed 003 eq. 5) and road edges (seed 000).

        ``q_hat = P q + (I - P) y``, ``p_hat = P p`` with ``P = I - a a^T``.
        """
        n, m = obs.q.shape
        u = np.zeros((n, m))
        half_w = np.zeros(n) if obs.width is None else 0.5 * obs.width
        if obs.walls is not None and len(obs.walls.points):
            for y, a in zip(obs.walls.points, obs.walls.normals, strict=True):
                u += self._one_wall(obs, np.broadcast_to(a, (n, m)), obs.q @ a - y @ a)
        if obs.road_edges is not None and m >= 2:
            e_lat = np.zeros((n, m))
            e_lat[:, 1] = 1.0
            # right edge: normal +y; left edge: normal -y; distances from the vehicle's side.
            u += self._one_wall(obs, e_lat, obs.q[:, 1] - obs.road_edges[:, 0] - half_w)
            u += self._one_wall(obs, -e_lat, obs.road_edges[:, 1] - obs.q[:, 1] - half_w)
        return u

    def _one_wall(self, obs: Observation, normal: np.ndarray, signed_gap: np.ndarray):
        """Beta term of one wall per agent: ``normal`` (N, m) into free space, gap (N,) m."""
        p = self.params
        n, m = obs.q.shape
        near = np.flatnonzero(signed_gap < p.r_wall)
        if len(near) == 0:
            return np.zeros((n, m))
        a = normal[near]
        gap = np.maximum(signed_gap[near], self.wall_floor)
        dq_hat = -a * gap[:, None]
        p_i = obs.p[near]
        p_hat = p_i - a * np.sum(a * p_i, axis=1, keepdims=True)
        f = self._beta_pair(dq_hat, p_hat - p_i, self.d_wall, p.c1_wall, p.c2_wall)
        return scatter_add(n, near, f)

    def vehicle_term(self, obs: Observation, s: np.ndarray) -> np.ndarray:
        """Sensed non-cooperating vehicles as rectangles (nearest point, own velocity)."""
        p = self.params
        n, m = obs.q.shape
        if obs.others_q is None or len(obs.others_q) == 0:
            return np.zeros((n, m))
        own_l = np.zeros(n) if obs.length is None else obs.length
        own_w = np.zeros(n) if obs.width is None else obs.width
        reach = p.r_vehicle / float(np.min(s)) + 0.5 * (
            np.hypot(own_l.max(), own_w.max())
            + np.hypot(obs.others_length.max(), obs.others_width.max())
        )
        pairs = cross_pairs(obs.q, obs.others_q, reach, obs.period_s)
        if len(pairs) == 0:
            return np.zeros((n, m))
        i, k = pairs[:, 0], pairs[:, 1]
        half = np.zeros((len(i), m))
        half[:, 0] = 0.5 * (own_l[i] + obs.others_length[k])
        if m > 1:
            half[:, 1] = 0.5 * (own_w[i] + obs.others_width[k])
        rel = obs.relative(obs.q[i] - obs.others_q[k])  # from the other's centre to agent i
        nearest = np.clip(rel, -half, half)
        dq_hat = nearest - rel
        inside = np.all(np.abs(rel) < half, axis=1)
        if inside.any():
            # Overlap: push out through the face of least penetration.
            pen = half[inside] - np.abs(rel[inside])
            axis = np.argmin(pen, axis=1)
            out = np.zeros_like(rel[inside])
            sign = np.where(rel[inside, axis] >= 0, 1.0, -1.0)
            out[np.arange(len(axis)), axis] = sign
            dq_hat[inside] = -out * _MIN_GAP
        gap = np.linalg.norm(dq_hat * s, axis=1)
        floor = self.vehicle_floor
        short = gap < floor
        if short.any():
            dq_hat[short] *= (floor / np.maximum(gap[short], _MIN_GAP))[:, None]
        keep = gap < p.r_vehicle
        if not keep.any():
            return np.zeros((n, m))
        f = self._beta_pair(
            dq_hat[keep],
            obs.others_p[k[keep]] - obs.p[i[keep]],
            self.d_vehicle,
            p.c1_beta,
            p.c2_beta,
            s,
        )
        return scatter_add(n, i[keep], f)

    def gamma_term(self, obs: Observation, u_beta: np.ndarray) -> np.ndarray:
        """Navigational feedback ``-c1 f(q - q_r) - c2 (p - p_r)`` (OS06 eq. 24, seed 003 eq. 11).

        ``f`` is the identity ("linear") or ``sigma_1`` ("sigma1"). With
        ``dynamic_weights`` the gains become ``C(c, u_beta) = c (tanh(u_beta) + 1)``
        per axis (seed 000, "Dynamic Weights").
        """
        p = self.params
        n, m = obs.q.shape
        u = np.zeros((n, m))
        c1 = p.gains("c1_gamma", m)
        c2 = p.gains("c2_gamma", m)
        if p.dynamic_weights:
            w = np.tanh(u_beta) + 1.0
            c1 = c1 * w
            c2 = c2 * w
        if obs.leader_q is not None:
            e = obs.relative(obs.q - obs.leader_q)
            if p.gamma_position == "sigma1":
                e = sigma_1_vec(e)
            u -= c1 * e
        if obs.leader_p is not None:
            u -= c2 * (obs.p - obs.leader_p)
        return u
