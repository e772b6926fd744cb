"""Seed 003: obstacle boundary points and expected velocity (Wu, Ji, Sun, Liang 2023).

The control law (seed 003 eq. 19), vectorised over agents::

    u_i = u_i^alpha + u_i^beta + u_i^gamma
    u_i^alpha = c1a sum_j eta^a(d_ij) phi_a(||q_ij||_s) n_ij + c2a sum_j a_ij (p_j - p_i)  (13)
    u_i^beta  = c1b sum_k eta^b(d_ik) phi_b(||q_ik||_s) n_ik
                + c2b sum_k b_ik (p_hat_i - p_i)                                       (14, 18)
    u_i^gamma = -c1g f(q_i - q_g) - c2g (p_i - p_g)                                  (11 / 19)

* **Beta-agents are obstacle boundary points** within the sensing radius ``r``
  (eq. 3), not Olfati-Saber's projections. The agent never learns an
  obstacle's shape; it sees a point cloud.
* **Piecewise weights** ``eta`` (eq. 12): ``tau_s`` in the separation region
  ``(0, d_e)``, ``tau_e`` in the early-warning region ``[d_e, d]``, ``tau_a``
  in the attraction region ``(d, r)``, with ``d_e = d_min + 2 p_max dt``: two
  agents closing at ``2 p_max`` cover at most ``2 p_max dt`` in one step, so
  the huge ``tau_s`` acts before ``d_min`` is crossed (this needs the
  velocity saturation of eq. 2 and the step ``dt``; see the last note).
  Note the force ``eta phi_alpha n`` itself is not monotone: ``n = sigma_eps(z)``
  vanishes at contact, so within ``d_e`` a nearer agent pushes *less* than one
  at ``d_e`` (Theorem 1's "V tends to infinity at a collision" does not hold
  for the bounded ``phi_alpha``); crowded agents can get closer than ``d_min``.
* **Expected velocity** ``p_hat_i = (q_hat_i - q_i) / dt`` (eq. 18) replaces
  the beta-agents' velocities, the same for all of agent ``i``'s points. The
  expected position ``q_hat_i`` (Table 2):

  - A1 (at a split point), A2 (between split and rejoin points), A3 (at a
    rejoin point and still blocked): phase comparison (eqs. 15-16). Phases of
    the sensed points are sorted; counterclockwise (ccw) motion scans them
    upwards from the reference direction and takes the point before the first
    gap ``>= delta_theta``; clockwise (cw) scans downwards. The reference
    direction is the split point in A2 and the gamma-agent in A1/A3.
  - A4 (otherwise, while sensing points): ``q_hat_i = q_gamma`` (eq. 17).

  Split point ``S_i``: where the agent, free or at a rejoin point at the
  previous step, first perceives obstacles that prevent it from following the
  gamma-agent. Rejoin point: where ``||q_i - q_g|| <= ||S_i - q_g||`` again.
  Both are kept per vehicle id (``obs.ids``) because vehicles enter and leave.

Choices where the paper is silent or ambiguous (all documented here):

* "obstacles preventing it from following": a sensed boundary point lies in
  the corridor of half-width ``block_width`` (default ``d_min``) along the
  straight segment from the agent towards the gamma-agent, closer than the
  gamma-agent. With boundary spacing <= 2 ``block_width`` every boundary that
  crosses the segment within ``r`` is caught.
* Eq. 15 as printed reads ``theta(m) - theta(m+1) >= delta_theta`` on phases
  sorted ascending (never true); we use the gap ``theta(m+1) - theta(m)``, the
  last gap wrapping round (``theta(1) + 2 pi - theta(M)``). No gap at all
  (surrounded): the last point in scan order.
* In A1/A3 the phase origin is the *nearest blocking point* rather than the
  exact gamma direction. When the blocking obstacle's points cover the gamma
  direction (the paper's Fig. 4) both give the same point; when the blocking
  points lie just to one side of the ray, the paper's rule would skip to an
  unrelated obstacle, ours follows the blocking one.
* cw or ccw (the paper does not say how an agent chooses):
  ``direction="nearest"`` picks, at a fresh split, the side whose chosen point
  deviates least from the gamma direction and keeps it until the agent
  rejoins (A3 keeps it). ``"auto"`` (default) does the same but, at every
  split (A1/A3), takes the side of the boundary-following neighbours (within
  ``r``) that are nearer the gamma-agent when they agree: without it two
  agents going round a concave notch in opposite senses can block each other
  for good (seen in the two-circle scene). ``"ccw"``/``"cw"`` fix the side.
* ``follow_timeout`` (default 20 s; None: the paper's rule): an agent still
  between split and rejoin point after this long gives the split point up
  (treated as rejoined). With the distance rule alone an agent that followed
  one obstacle onto another one whose whole outline is farther from the
  gamma-agent than its split point circles that obstacle for ever (seen with
  the diamond next to the C shape).
* ``psi_beta`` "similar to psi_alpha": ``phi_alpha`` with the same ``d``, ``r``
  (``beta_potential="alpha"``); ``"repulsive"`` drops its attractive part.
  ``b_ik = rho_h(||q_k - q_i||_sigma / r_alpha)``.
* The gamma term: eq. 11 (``sigma_1`` position feedback, Olfati-Saber's) or
  eq. 19's linear ``-c1 (q - q_g)``, which the paper states for the proposed
  algorithm and Theorem 1 uses; ``gamma_position`` selects, default "linear".
* Moving boundary points: when ``boundary_point_velocities`` are given, the
  expected velocity adds the chosen point's velocity (static points: the
  paper's law exactly).
* ``dt`` is the law's ``Delta t`` (Table 3), used in ``d_e`` and ``p_hat``;
  the world should step with the same ``dt``.

Inputs: boundary points come from ``obs.extras["boundary_points"]`` ((K, m)
array, m) with optional ``obs.extras["boundary_point_velocities"]`` ((K, m),
m/s), and/or from an :class:`~controllers.plane.obstacles.ObstacleSet` given to the
constructor (sampled once at ``spacing``); both sets are used when present.
Only points within ``r`` of an agent act on it. The gamma-agent is
``obs.leader_q`` / ``obs.leader_p``; without it the expected-velocity term is
off (``p_hat = p``). Agent pairs and agent-point pairs come from KD-trees;
nothing is N x N.

The law returns raw accelerations (up to ~1e5 m/s^2 in the separation
region); seed 003's model ``q' = sat(p, p_max)`` needs the speed saturation
layer: use :meth:`BoundaryPointController.saturated` (or
``ConstrainedController(law, [SpeedSaturation(p_max)])``) and a semi-implicit
step (``p += u dt; q += p dt``), for which ``d_e`` was designed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import NamedTuple

import numpy as np

from controllers.errors import ParameterError
from controllers.layers.constraints import ConstrainedController, SpeedSaturation
from controllers.neighbours import cross_pairs, neighbour_pairs, scatter_add
from controllers.observation import Observation
from controllers.plane.obstacles import ObstacleSet, sense
from controllers.plane.potentials import phi, rho_h, sigma_1_vec, sigma_norm_scalar

TWO_PI = 2.0 * math.pi

# Scenario codes of Table 2 (0: no boundary point sensed).
NONE, A1, A2, A3, A4 = 0, 1, 2, 3, 4
CCW, CW = 1, -1


@dataclass(frozen=True)
class BoundaryPointParams:
    """Seed 003 parameters; defaults are Table 3.

    Attributes:
        r: sensing radius for agents and boundary points, m (6).
        d: desired distance, m (4).
        epsilon: sigma-norm parameter (0.5).
        h: bump parameter in (0, 1) (0.2).
        a, b: phi parameters, 0 < a <= b (2, 20).
        c1_alpha, c2_alpha, c1_beta, c2_beta, c1_gamma, c2_gamma: gains (1).
        tau_a, tau_e, tau_s: eta weights of the attraction, early-warning and
            separation regions, ``tau_s >= tau_e >= tau_a >= 0`` (0.1, 10, 1e4).
        tau_a_beta, tau_e_beta, tau_s_beta: the same for boundary points
            (None: as for agents).
        delta_theta: phase-discontinuity threshold, rad, in (0, 2 pi) (pi/4).
        p_max: maximum speed, m/s (5).
        d_min: minimum safe distance, m (1).
        dt: step Delta t, s (0.1).
        direction: "auto", "nearest", "ccw" or "cw" (see module notes).
        block_width: half-width of the corridor towards the gamma-agent in
            which a boundary point blocks the agent, m (None: ``d_min``).
        gamma_position: "linear" (eq. 19) or "sigma1" (eq. 11).
        beta_potential: "alpha" (psi_beta = psi_alpha) or "repulsive".
        follow_timeout: s; an agent still between its split and rejoin points
            after this long gives the split point up (as if it rejoined);
            None: the paper's rule only (see module notes).
    """

    r: float = 6.0
    d: float = 4.0
    epsilon: float = 0.5
    h: float = 0.2
    a: float = 2.0
    b: float = 20.0
    c1_alpha: float = 1.0
    c2_alpha: float = 1.0
    c1_beta: float = 1.0
    c2_beta: float = 1.0
    c1_gamma: float = 1.0
    c2_gamma: float = 1.0
    tau_a: float = 0.1
    tau_e: float = 10.0
    tau_s: float = 10000.0
    tau_a_beta: float | None = None
    tau_e_beta: float | None = None
    tau_s_beta: float | None = None
    delta_theta: float = math.pi / 4
    p_max: float = 5.0
    d_min: float = 1.0
    dt: float = 0.1
    direction: str = "auto"
    block_width: float | None = None
    gamma_position: str = "linear"
    beta_potential: str = "alpha"
    follow_timeout: float | None = 20.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool):
                raise ParameterError(f"{f.name} must be a number or string, got {v!r}")
            if isinstance(v, int | float) and not math.isfinite(v):
                raise ParameterError(f"{f.name} must be finite, got {v!r}")
        for name in ("r", "d", "epsilon", "a", "b", "p_max", "d_min", "dt"):
            if not getattr(self, name) > 0:
                raise ParameterError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not 0.0 < self.h < 1.0:
            raise ParameterError(f"h must lie in (0, 1), got {self.h!r}")
        if self.a > self.b:
            raise ParameterError(f"a must be <= b (need 0 < a <= b), got a={self.a}, b={self.b}")
        if self.r <= self.d:
            raise ParameterError(f"r must be > d, got r={self.r}, d={self.d}")
        for name in ("c1_alpha", "c2_alpha", "c1_beta", "c2_beta", "c1_gamma", "c2_gamma"):
            if getattr(self, name) < 0:
                raise ParameterError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        for suffix in ("", "_beta"):
            ta, te, ts = (self._tau(k + suffix) for k in ("tau_a", "tau_e", "tau_s"))
            if ta < 0:
                raise ParameterError(f"tau_a{suffix} must be >= 0, got {ta!r}")
            if te < ta:
                raise ParameterError(f"tau_e{suffix} must be >= tau_a{suffix}, got {te} < {ta}")
            if ts < te:
                raise ParameterError(f"tau_s{suffix} must be >= tau_e{suffix}, got {ts} < {te}")
        if not 0.0 < self.delta_theta < TWO_PI:
            raise ParameterError(f"delta_theta must lie in (0, 2 pi), got {self.delta_theta!r}")
        if self.d_e >= self.d:
            raise ParameterError(
                f"d_min: d_e = d_min + 2 p_max dt = {self.d_e:g} m must be < d = {self.d:g} m "
                f"(d_min={self.d_min}, p_max={self.p_max}, dt={self.dt})"
            )
        if self.follow_timeout is not None and not self.follow_timeout > 0:
            raise ParameterError(
                f"follow_timeout must be > 0 s or None, got {self.follow_timeout!r}"
            )
        if self.block_width is not None and not self.block_width > 0:
            raise ParameterError(f"block_width must be > 0, got {self.block_width!r}")
        if self.direction not in ("auto", "nearest", "ccw", "cw"):
            raise ParameterError(
                f"direction must be auto, nearest, ccw or cw, got {self.direction!r}"
            )
        if self.gamma_position not in ("linear", "sigma1"):
            raise ParameterError(
                f"gamma_position must be 'linear' or 'sigma1', got {self.gamma_position!r}"
            )
        if self.beta_potential not in ("alpha", "repulsive"):
            raise ParameterError(
                f"beta_potential must be 'alpha' or 'repulsive', got {self.beta_potential!r}"
            )

    def _tau(self, name: str) -> float:
        v = getattr(self, name)
        return getattr(self, name[: -len("_beta")]) if v is None else v

    @property
    def d_e(self) -> float:
        """Minimum early-warning distance ``d_e = d_min + 2 p_max dt``, m."""
        return self.d_min + 2.0 * self.p_max * self.dt

    @property
    def tau_alpha(self) -> tuple[float, float, float]:
        """``(tau_a, tau_e, tau_s)`` for agent pairs."""
        return self.tau_a, self.tau_e, self.tau_s

    @property
    def tau_beta(self) -> tuple[float, float, float]:
        """``(tau_a, tau_e, tau_s)`` for agent-boundary point pairs."""
        return self._tau("tau_a_beta"), self._tau("tau_e_beta"), self._tau("tau_s_beta")

    @property
    def corridor(self) -> float:
        """Blocking corridor half-width, m."""
        return self.d_min if self.block_width is None else self.block_width

    def with_(self, **changes) -> BoundaryPointParams:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)


def eta(dist, d_e: float, d: float, r: float, taus: tuple[float, float, float]) -> np.ndarray:
    """Piecewise weight of eq. 12 for distances ``dist`` (m).

    ``tau_s`` on ``(0, d_e)`` (and at 0), ``tau_e`` on ``[d_e, d]``, ``tau_a``
    on ``(d, r)``, 0 from ``r`` on (outside the sensing radius).
    """
    tau_a, tau_e, tau_s = taus
    dist = np.asarray(dist, dtype=float)
    return np.where(
        dist < d_e, tau_s, np.where(dist <= d, tau_e, np.where(dist < r, tau_a, 0.0))
    ).astype(float)


def _same_ids(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.all(a == b))


def _group_starts(owner_sorted: np.ndarray) -> np.ndarray:
    return np.flatnonzero(np.r_[True, owner_sorted[1:] != owner_sorted[:-1]])


def phase_choice(
    rel: np.ndarray,
    owner: np.ndarray,
    n: int,
    ref_dir: np.ndarray,
    mode: np.ndarray,
    delta_theta: float,
) -> np.ndarray:
    """Phase comparison (eqs. 15-16): the chosen boundary point of each agent.

    Args:
        rel: (P, 2) boundary point minus agent position, m.
        owner: (P,) agent index of each row.
        n: number of agents.
        ref_dir: (n, 2) the x-axis of each agent's rotated frame (need not be unit).
        mode: (n,) +1 counterclockwise, -1 clockwise.
        delta_theta: discontinuity threshold, rad.

    Returns (n,) row index into ``rel`` of the expected position, -1 for
    agents without rows. Phases are measured from ``ref_dir`` in the ``mode``
    sense in [0, 2 pi) and sorted; the chosen point is the one before the
    first gap ``>= delta_theta`` (the wrap-around gap last); with no such gap,
    the last point. Clockwise with ascending mirrored phases is eq. 16's
    descending scan.
    """
    out = np.full(n, -1, dtype=np.int64)
    if len(rel) == 0:
        return out
    e = ref_dir[owner]
    ang = np.arctan2(e[:, 0] * rel[:, 1] - e[:, 1] * rel[:, 0], np.sum(e * rel, axis=1))
    th = np.mod(mode[owner] * ang, TWO_PI)
    th[th >= TWO_PI - 1e-12] = 0.0  # a point on the reference ray is phase 0, not 2 pi
    order = np.lexsort((th, owner))
    th_s, own_s = th[order], owner[order]
    starts = _group_starts(own_s)
    ends = np.r_[starts[1:], len(own_s)] - 1
    nxt = np.empty_like(th_s)
    nxt[:-1] = th_s[1:]
    nxt[ends] = th_s[starts] + TWO_PI
    flag = (nxt - th_s) >= delta_theta - 1e-12
    pos = np.arange(len(th_s))
    big = len(th_s) + 1
    first = np.minimum.reduceat(np.where(flag, pos, big), starts)
    first = np.where(first == big, ends, first)
    out[own_s[starts]] = order[first]
    return out


def goal_blocking(
    rel: np.ndarray,
    owner: np.ndarray,
    n: int,
    goal_rel: np.ndarray,
    width: float,
    r: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Which agents perceive obstacles preventing them from following the gamma-agent.

    A sensed point blocks agent ``i`` when it lies in the corridor of
    half-width ``width`` (m) along the segment from ``q_i`` towards the
    gamma-agent, closer than both the gamma-agent and ``r``. ``goal_rel`` (n, 2)
    is ``q_gamma - q_i``. Returns ``(blocked (n,) bool, anchor (n,) row index
    of the nearest blocking point or -1)``.
    """
    blocked = np.zeros(n, dtype=bool)
    anchor = np.full(n, -1, dtype=np.int64)
    if len(rel) == 0:
        return blocked, anchor
    dist = np.linalg.norm(goal_rel, axis=1)
    g = goal_rel / np.maximum(dist, 1e-12)[:, None]
    gi = g[owner]
    x = np.sum(gi * rel, axis=1)
    y = gi[:, 0] * rel[:, 1] - gi[:, 1] * rel[:, 0]
    inside = (x > 0) & (x < np.minimum(dist[owner], r)) & (np.abs(y) < width)
    if not inside.any():
        return blocked, anchor
    rows = np.flatnonzero(inside)
    order = rows[np.lexsort((x[rows], owner[rows]))]
    starts = _group_starts(owner[order])
    agents = owner[order[starts]]
    blocked[agents] = True
    anchor[agents] = order[starts]
    return blocked, anchor


class SplitState(NamedTuple):
    """One vehicle's memory: split point (2,) m, mode (+1 ccw, -1 cw), steps since the split."""

    split: np.ndarray
    mode: int
    steps: int


@dataclass
class BoundaryTerms:
    """One step's parts of the law (each (N, m), m/s^2) and the decision state."""

    alpha: np.ndarray
    beta_gradient: np.ndarray
    beta_consensus: np.ndarray
    gamma: np.ndarray
    scenario: np.ndarray  # (N,) NONE, A1, A2, A3 or A4
    q_hat: np.ndarray  # (N, m) expected position (NaN: no boundary point sensed)
    mode: np.ndarray  # (N,) +1 ccw, -1 cw, 0 not following a boundary
    blocked: np.ndarray  # (N,) bool
    n_alpha_pairs: int = 0
    n_beta_pairs: int = 0

    @property
    def total(self) -> np.ndarray:
        return self.alpha + self.beta_gradient + self.beta_consensus + self.gamma


class BoundaryPointController:
    """Seed 003's obstacle boundary point and expected velocity flocking law.

    ``compute(obs) -> u`` (N, m) m/s^2 for m = 2 (boundary points need a
    plane; without any boundary point other m work too). ``obstacles`` (an
    :class:`~controllers.plane.obstacles.ObstacleSet`) is sampled once at
    ``spacing`` (m); points in ``obs.extras["boundary_points"]`` are added each
    step. ``memory`` maps vehicle id to its split point and motion mode.
    """

    name = "boundary_points"

    def __init__(
        self,
        params: BoundaryPointParams | None = None,
        obstacles: ObstacleSet | None = None,
        spacing: float = 0.5,
    ) -> None:
        self.params = params or BoundaryPointParams()
        p = self.params
        self.r_alpha = float(sigma_norm_scalar(p.r, p.epsilon))
        self.d_alpha = float(sigma_norm_scalar(p.d, p.epsilon))
        self.obstacles = obstacles
        self.spacing = float(spacing)
        self._static = None
        if obstacles is not None and len(obstacles):
            self._static = obstacles.boundary_points(self.spacing)
            self._tree = obstacles.tree(self.spacing)
        self._mem_ids: np.ndarray | None = None  # ids of the last step, in row order
        self._mem_split = np.empty((0, 2))  # (N, 2) split points, NaN: none
        self._mem_mode = np.empty(0, dtype=np.int64)  # (N,) +1 ccw, -1 cw, 0 none
        self._mem_age = np.empty(0, dtype=np.int64)  # (N,) steps since the split
        self.last_terms: BoundaryTerms | None = None

    @property
    def memory(self) -> dict:
        """``{vehicle id: SplitState}`` of the agents between a split and a rejoin point."""
        if self._mem_ids is None:
            return {}
        return {
            vid: SplitState(
                self._mem_split[row].copy(), int(self._mem_mode[row]), int(self._mem_age[row])
            )
            for row, vid in enumerate(self._mem_ids.tolist())
            if not np.isnan(self._mem_split[row, 0])
        }

    def _recall(self, ids: np.ndarray):
        """Split points (N, 2), modes (N,) and ages (N,) for this step's ids (in row order)."""
        n = len(ids)
        if self._mem_ids is not None and _same_ids(ids, self._mem_ids):
            return self._mem_split.copy(), self._mem_mode.copy(), self._mem_age.copy()
        split = np.full((n, 2), np.nan)
        mode = np.zeros(n, dtype=np.int64)
        age = np.zeros(n, dtype=np.int64)
        known = self.memory
        for row, vid in enumerate(ids.tolist()):
            mem = known.get(vid)
            if mem is not None:
                split[row], mode[row], age[row] = mem
        return split, mode, age

    @classmethod
    def saturated(cls, params=None, obstacles=None, spacing=0.5) -> ConstrainedController:
        """The law followed by seed 003's speed saturation ``sat(p, p_max)`` (eq. 2)."""
        law = cls(params, obstacles, spacing)
        return ConstrainedController(law, [SpeedSaturation(law.params.p_max)])

    def reset(self) -> None:
        """Forget all split points."""
        self._mem_ids = None
        self.last_terms = None

    # ------------------------------------------------------------------
    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations (N, m), m/s^2."""
        obs.check_finite()
        terms = self.terms(obs)
        self.last_terms = terms
        return terms.total

    def terms(self, obs: Observation) -> BoundaryTerms:
        n, m = obs.q.shape
        zero = np.zeros((n, m))
        alpha, agent_pairs = self.alpha_term(obs)
        pts, vel = self._points(obs)
        if len(pts) and m != 2:
            raise ValueError(f"boundary points need a plane (m = 2), got m = {m}")
        pairs = self._sense(obs, pts)
        i, k = pairs[:, 0], pairs[:, 1]
        rel = obs.relative(pts[k] - obs.q[i]) if len(pairs) else np.empty((0, m))
        beta_grad, b_sum = self.beta_gradient(obs, rel, i)
        q_hat = np.full((n, m), np.nan)
        scenario = np.zeros(n, dtype=np.int64)
        mode = np.zeros(n, dtype=np.int64)
        blocked = np.zeros(n, dtype=bool)
        beta_cons = zero.copy()
        if obs.leader_q is not None and n:
            goal_rel = obs.relative(np.broadcast_to(obs.leader_q, (n, m)) - obs.q)
            if m == 2:
                q_hat_rel, v_hat, scenario, mode, blocked = self.expected_position(
                    obs,
                    rel,
                    i,
                    goal_rel,
                    vel[k] if vel is not None and len(k) else None,
                    agent_pairs,
                )
            else:  # no boundary points (checked above): only A4 would apply, and b_sum = 0
                q_hat_rel, v_hat = goal_rel, np.zeros((n, m))
            has = b_sum > 0
            q_hat[has] = obs.q[has] + q_hat_rel[has]
            p_hat = q_hat_rel / self.params.dt + v_hat
            beta_cons[has] = self.params.c2_beta * b_sum[has, None] * (p_hat[has] - obs.p[has])
        gamma = self.gamma_term(obs)
        return BoundaryTerms(
            alpha,
            beta_grad,
            beta_cons,
            gamma,
            scenario,
            q_hat,
            mode,
            blocked,
            len(agent_pairs),
            len(pairs),
        )

    # ------------------------------------------------------------------
    def _points(self, obs: Observation) -> tuple[np.ndarray, np.ndarray | None]:
        """Boundary points (K, m) and their velocities (K, m) or None (all static)."""
        m = obs.m
        parts, vels = [], []
        if self._static is not None:
            parts.append(self._static)
            vels.append(np.zeros_like(self._static))
        extra = obs.extras.get("boundary_points") if obs.extras else None
        moving = False
        if extra is not None:
            e = np.asarray(extra, dtype=float)
            e = e.reshape(0, m) if e.size == 0 else e
            if e.ndim != 2 or e.shape[1] != m:
                raise ValueError(
                    f"extras['boundary_points'] must have shape (K, {m}), got {e.shape}"
                )
            if not np.all(np.isfinite(e)):
                raise ValueError("extras['boundary_points'] must be finite")
            ev = obs.extras.get("boundary_point_velocities")
            if ev is None:
                ev = np.zeros_like(e)
            else:
                ev = np.asarray(ev, dtype=float).reshape(e.shape)
                moving = bool(np.any(ev != 0))
            parts.append(e)
            vels.append(ev)
        if not parts:
            return np.empty((0, m)), None
        if len(parts) == 1 and parts[0] is self._static:
            return self._static, None
        return np.vstack(parts), (np.vstack(vels) if moving else None)

    def _sense(self, obs: Observation, pts: np.ndarray) -> np.ndarray:
        """Agent-point pairs within ``r`` (eq. 3), grouped by agent."""
        if len(pts) == 0 or obs.n == 0:
            return np.empty((0, 2), dtype=np.int64)
        if pts is self._static and obs.period_s is None:
            return sense(obs.q, pts, self.params.r, self._tree)
        return cross_pairs(obs.q, pts, self.params.r, obs.period_s)

    def _pair_geometry(self, z: np.ndarray):
        """Distance (P,), sigma-norm (P,), ``n = sigma_eps(z)`` (P, m), ``phi_alpha``, bump.

        One pass for what ``phi_alpha``, ``adjacency``, ``sigma_norm`` and
        ``sigma_grad`` of :mod:`controllers.plane.potentials` would each recompute.
        """
        p = self.params
        sq = z[:, 0] * z[:, 0]
        for k in range(1, z.shape[1]):
            sq = sq + z[:, k] * z[:, k]
        root = np.sqrt(1.0 + p.epsilon * sq)
        z_sigma = (root - 1.0) / p.epsilon
        bump = rho_h(z_sigma / self.r_alpha, p.h)
        phi_a = bump * phi(z_sigma - self.d_alpha, p.a, p.b)
        return np.sqrt(sq), z_sigma, z / root[:, None], phi_a, bump

    def alpha_term(self, obs: Observation) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 13 plus the consensus part of eq. 8; (N, m) and the agent pairs (P, 2)."""
        p = self.params
        n, m = obs.q.shape
        pairs = neighbour_pairs(obs.q, p.r, obs.period_s, "kdtree")
        if len(pairs) == 0:
            return np.zeros((n, m)), pairs
        i, j = pairs[:, 0], pairs[:, 1]
        z = obs.relative(obs.q[j] - obs.q[i])
        dist, _, n_ij, phi_a, a_ij = self._pair_geometry(z)
        w = eta(dist, p.d_e, p.d, p.r, p.tau_alpha)
        f = (p.c1_alpha * w * phi_a)[:, None] * n_ij + (p.c2_alpha * a_ij)[:, None] * (
            obs.p[j] - obs.p[i]
        )
        return scatter_add(n, np.concatenate([i, j]), np.concatenate([f, -f])), pairs

    def beta_gradient(self, obs: Observation, rel: np.ndarray, i: np.ndarray):
        """Eq. 14: ``c1b sum_k eta^b(d_ik) phi_b n_ik``; also ``sum_k b_ik`` (N,)."""
        p = self.params
        n, m = obs.q.shape
        if len(rel) == 0:
            return np.zeros((n, m)), np.zeros(n)
        dist, _, n_ik, phi_b, b_ik = self._pair_geometry(rel)
        if p.beta_potential == "repulsive":
            phi_b = np.minimum(phi_b, 0.0)
        w = eta(dist, p.d_e, p.d, p.r, p.tau_beta)
        f = (p.c1_beta * w * phi_b)[:, None] * n_ik
        b_sum = np.bincount(i, weights=b_ik, minlength=n)
        return scatter_add(n, i, f), b_sum

    def expected_position(self, obs, rel, owner, goal_rel, point_vel, agent_pairs=None):
        """Split/rejoin bookkeeping and Table 2; returns ``q_hat - q`` (N, 2) and more.

        Returns ``(q_hat_rel, v_hat, scenario, mode, blocked)``: expected
        position relative to each agent (m), the chosen point's velocity (m/s,
        zero when static or in A4), scenario codes, modes and blocked flags.
        Updates the memory (split points by vehicle id).
        """
        p = self.params
        n = obs.n
        ids = np.asarray(obs.ids)
        split, mode, age = self._recall(ids)
        blocked, anchor = goal_blocking(rel, owner, n, goal_rel, p.corridor, p.r)
        goal_dist = np.linalg.norm(goal_rel, axis=1)
        in_interval = ~np.isnan(split[:, 0])
        rejoin = np.zeros(n, dtype=bool)
        if in_interval.any():
            s_goal = np.linalg.norm(
                obs.relative(goal_rel[in_interval] + obs.q[in_interval] - split[in_interval]),
                axis=1,
            )
            rejoin[in_interval] = goal_dist[in_interval] <= s_goal
            if p.follow_timeout is not None:
                # Give up a split point followed for too long (e.g. orbiting another obstacle).
                rejoin |= in_interval & (age * p.dt >= p.follow_timeout)
        a3 = rejoin & blocked
        a2 = in_interval & ~rejoin
        a1 = ~in_interval & blocked
        scenario = np.full(n, A4, dtype=np.int64)
        scenario[a1], scenario[a2], scenario[a3] = A1, A2, A3
        # Reference direction: the nearest blocking point (A1/A3), the split point (A2).
        ref = goal_rel.copy()
        both = a1 | a3
        ref[both] = rel[anchor[both]]
        if a2.any():
            to_s = obs.relative(split[a2] - obs.q[a2])
            far = np.linalg.norm(to_s, axis=1) > 1e-9
            ref_a2 = ref[a2]
            ref_a2[far] = to_s[far]
            ref[a2] = ref_a2
        fixed = {"ccw": CCW, "cw": CW}.get(p.direction)
        fresh = a1 | (a3 & (mode == 0))
        if fixed is not None:
            mode[fresh] = fixed
        else:
            if fresh.any():
                mode[fresh] = self._auto_mode(rel, owner, n, ref, goal_rel, fresh, p.delta_theta)
            if p.direction == "auto" and agent_pairs is not None and len(agent_pairs):
                # Flock-consistent side: at a split (A1/A3) take the side of the
                # neighbours nearer the goal that are already going round.
                vote = self._neighbour_vote(agent_pairs, mode, goal_dist, n)
                adopt = (a1 | a3) & (vote != 0)
                mode[adopt] = np.sign(vote[adopt]).astype(np.int64)
        following = a1 | a2 | a3
        sel = following[owner]
        chosen_sel = phase_choice(rel[sel], owner[sel], n, ref, mode, p.delta_theta)
        rows_sel = np.flatnonzero(sel)
        q_hat_rel = goal_rel.copy()  # A4: q_hat = q_gamma
        v_hat = np.zeros((n, 2))
        got = chosen_sel >= 0
        chosen = rows_sel[chosen_sel[got]]
        q_hat_rel[got] = rel[chosen]
        if point_vel is not None:
            v_hat[got] = point_vel[chosen]
        # New split points (Fig. 3): at A1 and A3 the agent's current position.
        split[a1 | a3] = obs.q[a1 | a3]
        split[rejoin & ~blocked] = np.nan
        mode[np.isnan(split[:, 0])] = 0
        age = np.where(a1 | a3, 0, age + 1)
        scenario[np.bincount(owner, minlength=n) == 0] = NONE
        self._mem_ids, self._mem_split = ids.copy(), split
        self._mem_mode, self._mem_age = mode.copy(), age
        return q_hat_rel, v_hat, scenario, mode, blocked

    @staticmethod
    def _neighbour_vote(pairs: np.ndarray, mode: np.ndarray, goal_dist: np.ndarray, n: int):
        """Sum (n,) of the modes of each agent's neighbours that are nearer the goal."""
        i, j = pairs[:, 0], pairs[:, 1]
        j_ahead = goal_dist[j] < goal_dist[i]
        i_ahead = goal_dist[i] < goal_dist[j]
        return np.bincount(i, weights=np.where(j_ahead, mode[j], 0), minlength=n) + np.bincount(
            j, weights=np.where(i_ahead, mode[i], 0), minlength=n
        )

    @staticmethod
    def _auto_mode(rel, owner, n, ref, goal_rel, fresh, delta_theta) -> np.ndarray:
        """For fresh splits: the side (ccw/cw) whose chosen point deviates least from the goal."""
        sel = fresh[owner]
        rows = np.flatnonzero(sel)
        goal_ang = np.arctan2(goal_rel[:, 1], goal_rel[:, 0])
        dev = {}
        for sense_ in (CCW, CW):
            chosen = phase_choice(rel[sel], owner[sel], n, ref, np.full(n, sense_), delta_theta)
            d = np.full(n, np.inf)
            ok = chosen >= 0
            v = rel[rows[chosen[ok]]]
            d[ok] = np.abs(np.angle(np.exp(1j * (np.arctan2(v[:, 1], v[:, 0]) - goal_ang[ok]))))
            dev[sense_] = d
        return np.where(dev[CW] < dev[CCW], CW, CCW)[fresh]

    def gamma_term(self, obs: Observation) -> np.ndarray:
        """``-c1g f(q - q_g) - c2g (p - p_g)``; f linear (eq. 19) or sigma_1 (eq. 11)."""
        p = self.params
        u = np.zeros_like(obs.q)
        if obs.leader_q is not None:
            e = obs.relative(obs.q - obs.leader_q)
            if p.gamma_position == "sigma1":
                e = sigma_1_vec(e)
            u -= p.c1_gamma * e
        if obs.leader_p is not None:
            u -= p.c2_gamma * (obs.p - obs.leader_p)
        elif obs.leader_q is not None:
            u -= p.c2_gamma * obs.p
        return u
