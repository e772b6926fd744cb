"""Rigid formation by artificial potentials plus velocity consensus (seed 002).

Seed 002 ("Flocking with Artificial Potential Fields") gives every agent ``i`` a
neighbourhood ``N_i`` and two potentials (section "Behavior implementation"):

* formation ``V_i = sum_{j in N_i} 1/4 (||q_i - q_j||^2 - delta_ij^2)^2`` (m^4), with
  minima where every constrained pair sits at its desired distance ``delta_ij``;
* speed ``sum_{j in N_i} ||p_i - p_j||^2`` (m^2/s^2), minimal at a common velocity.

The control is the weighted negative gradient (double integrator, ``u`` in m/s^2)::

    u_i = K_for * sum_{j in N_i} (||q_j - q_i||^2 - delta_ij^2) (q_j - q_i)
          - K_vel * sum_{j in N_i} (p_i - p_j)

Note on the sign: the seed prints the formation term as ``-K_for * sum (...)(p_j - p_i)``,
which is ``+K_for * grad V_i`` (gradient *ascent*: a stretched pair would be pushed
further apart), while its speed term ``-K_vel * sum (v_i - v_j)`` is the descent
direction. We implement the descent direction for both, which is what the seed's
own description ("minima in correspondence of the desired distance") requires.

Symbols (SI): ``q`` positions (N, m) in m, ``p`` velocities (N, m) in m/s,
``K_for`` in 1/(m^2 s^2), ``K_vel`` in 1/s. The constraint graph is a list of
*ordered* pairs ``(i, j)`` meaning ``j in N_i``, exactly the terms of the seed's
per-agent sums; an undirected constraint appears twice. With that convention the
seed's hexagon-plus-centre example has 30 constraints (see :func:`hexagon_formation`).

Beyond the seed (for CAVs on a road): optional virtual-leader tracking,
``- K_ref (p_i - p_leader)`` (velocity, 1/s) and ``- K_pos (mean(q) - q_leader)``
(centroid position, 1/s^2, the same for every agent so it never distorts the
shape), and a "rows x columns" grid formation in the road frame.

Distance-only formations are invariant to translation, rotation and reflection:
the controller restores the *shape*, not its orientation. On a road, start the
vehicles near the intended layout (or add per-vehicle lateral references).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.observation import Observation

__all__ = [
    "FormationController",
    "FormationGraph",
    "FormationParams",
    "formation_distance_error",
    "formation_potential",
    "graph_from_reference",
    "grid_formation",
    "hexagon_formation",
    "oscillation_metrics",
    "replicate",
    "rollout",
    "damping_ratios",
    "signed_distance_errors",
    "stiffness_matrix",
]


def _check_gain(name: str, value: float) -> float:
    v = float(value)
    if not np.isfinite(v) or v < 0:
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return v


def _check_positive(name: str, value: float) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


@dataclass(frozen=True)
class FormationParams:
    """Gains of the seed-002 law (all >= 0).

    Attributes:
        K_for: formation gain, 1/(m^2 s^2). Seed values 0.0001, 0.001, 0.01.
        K_vel: velocity-consensus gain, 1/s. Seed value 0.3.
        K_ref: tracking of the virtual leader's velocity ``obs.leader_p``, 1/s
            (0 = off; not in the seed).
        K_pos: tracking of the leader position ``obs.leader_q`` by the formation
            centroid, 1/s^2 (0 = off; not in the seed).
    """

    K_for: float = 0.001
    K_vel: float = 0.3
    K_ref: float = 0.0
    K_pos: float = 0.0

    def __post_init__(self) -> None:
        for name in ("K_for", "K_vel", "K_ref", "K_pos"):
            object.__setattr__(self, name, _check_gain(name, getattr(self, name)))


@dataclass(frozen=True)
class FormationGraph:
    """Distance constraints: ordered pairs ``(i, j)`` (``j in N_i``) and ``delta_ij``.

    Attributes:
        pairs: (E, 2) int agent indices; row ``(i, j)`` adds a term to agent i's sums.
        desired: (E,) desired distances ``delta_ij`` > 0, m.
        reference: optional (N, m) configuration that realises the distances, m
            (used for plots and as a layout hint; never by the control law).
    """

    pairs: np.ndarray
    desired: np.ndarray
    reference: np.ndarray | None = None

    def __post_init__(self) -> None:
        pairs = np.asarray(self.pairs)
        if pairs.ndim != 2 or pairs.shape[1] != 2 or pairs.shape[0] == 0:
            raise ValueError(f"pairs must have shape (E, 2) with E >= 1, got {pairs.shape}")
        if not np.issubdtype(pairs.dtype, np.integer):
            if not np.all(np.equal(np.mod(pairs, 1), 0)):
                raise ValueError("pairs must hold integer agent indices")
        pairs = pairs.astype(np.intp)
        if np.any(pairs < 0):
            raise ValueError("pairs: agent indices must be >= 0")
        if np.any(pairs[:, 0] == pairs[:, 1]):
            raise ValueError("pairs: a constraint joins an agent to itself")
        desired = np.atleast_1d(np.asarray(self.desired, dtype=float))
        if desired.shape != (pairs.shape[0],):
            raise ValueError(f"desired must have shape ({pairs.shape[0]},), got {desired.shape}")
        if not np.all(np.isfinite(desired)) or np.any(desired <= 0):
            raise ValueError("desired distances must be finite and > 0")
        object.__setattr__(self, "pairs", pairs)
        object.__setattr__(self, "desired", desired)
        if self.reference is not None:
            ref = np.asarray(self.reference, dtype=float)
            if ref.ndim != 2 or ref.shape[0] < self.n_agents:
                raise ValueError(f"reference must have shape (N >= {self.n_agents}, m)")
            object.__setattr__(self, "reference", ref)

    @classmethod
    def from_undirected(
        cls, pairs: np.ndarray, desired: np.ndarray, reference: np.ndarray | None = None
    ) -> FormationGraph:
        """Build from undirected pairs (K, 2) and distances (K,) m: each appears both ways."""
        pairs = np.asarray(pairs)
        desired = np.atleast_1d(np.asarray(desired, dtype=float))
        both = np.concatenate([pairs, pairs[:, ::-1]], axis=0)
        return cls(both, np.concatenate([desired, desired]), reference)

    @property
    def n_constraints(self) -> int:
        """Number E of ordered constraints (terms in the per-agent sums)."""
        return int(self.pairs.shape[0])

    @property
    def n_agents(self) -> int:
        """Smallest N the graph fits: largest index + 1."""
        return int(self.pairs.max()) + 1

    def is_symmetric(self) -> bool:
        """True if every (i, j) has a matching (j, i) with the same ``delta``."""
        fwd = {(int(i), int(j)): d for (i, j), d in zip(self.pairs, self.desired, strict=True)}
        return all(fwd.get((j, i)) == d for (i, j), d in fwd.items())

    def degrees(self, n: int | None = None) -> np.ndarray:
        """(N,) number of neighbours |N_i| of each agent."""
        n = self.n_agents if n is None else n
        return np.bincount(self.pairs[:, 0], minlength=n)


def graph_from_reference(reference: np.ndarray, undirected_pairs: np.ndarray) -> FormationGraph:
    """Constraint graph whose distances are those of ``reference`` (N, m) m on the given pairs."""
    ref = np.asarray(reference, dtype=float)
    und = np.asarray(undirected_pairs, dtype=np.intp)
    desired = np.linalg.norm(ref[und[:, 1]] - ref[und[:, 0]], axis=1)
    return FormationGraph.from_undirected(und, desired, reference=ref)


def replicate(graph: FormationGraph, copies: int, n: int | None = None) -> FormationGraph:
    """Disjoint union of ``copies`` independent copies of ``graph`` (for batched runs).

    Copy ``b`` uses agents ``b*n .. b*n + n-1`` (``n`` defaults to ``graph.n_agents``);
    copies never interact, so one rollout integrates many formations at once.
    """
    if int(copies) != copies or copies < 1:
        raise ValueError(f"copies must be an integer >= 1, got {copies!r}")
    n = graph.n_agents if n is None else int(n)
    shift = (np.arange(int(copies)) * n)[:, None, None]
    pairs = (graph.pairs[None, :, :] + shift).reshape(-1, 2)
    ref = None if graph.reference is None else np.tile(graph.reference[:n], (int(copies), 1))
    return FormationGraph(pairs, np.tile(graph.desired, int(copies)), ref)


def hexagon_formation(side: float = 10.0) -> FormationGraph:
    """Seed 002's example: regular hexagon 0..5 plus centre 6, 30 ordered constraints.

    Layout as in the seed's figure: 0 top-left, 1 top-right, 2 right, 3 bottom-right,
    4 bottom-left, 5 left, 6 centre. The figure draws the six rim edges and three
    straight lines through the centre (5-6-2, 0-6-3, 1-6-4). Counting, as the seed's
    sums do, ``j in N_i`` for every agent: each rim agent has its two rim neighbours,
    the centre and the opposite vertex (4 each, 24 in all) and the centre has the six
    rim agents (6): 24 + 6 = 30 ordered constraints, i.e. 15 undirected distances
    (6 rim and 6 spokes of length ``side``, 3 diameters of ``2 * side``). This is the
    only natural reading that gives the seed's 30; without the diameters it would be 24.

    Args:
        side: hexagon side = centre-to-vertex distance, m.

    Returns:
        FormationGraph with pairs (30, 2), desired (30,) m, reference (7, 2) m.
    """
    side = _check_positive("side", side)
    ang = np.deg2rad([120.0, 60.0, 0.0, -60.0, -120.0, 180.0])
    ref = np.vstack([side * np.column_stack([np.cos(ang), np.sin(ang)]), [[0.0, 0.0]]])
    rim = [(k, (k + 1) % 6) for k in range(6)]
    spokes = [(k, 6) for k in range(6)]
    diameters = [(0, 3), (1, 4), (2, 5)]
    return graph_from_reference(ref, np.array(rim + spokes + diameters))


def grid_formation(
    rows: int, cols: int, dx: float, dy: float, diagonals: bool = True
) -> FormationGraph:
    """Rows x columns formation in the road frame (axis 0 longitudinal, axis 1 lateral).

    Agent ``k = r * cols + c`` sits at ``(c * dx, r * dy)`` (centred on the origin),
    i.e. a *row* is a line of vehicles one behind the other (a "lane" of the
    formation) and rows are stacked laterally. Constraints join longitudinal
    neighbours (``dx``), lateral neighbours (``dy``) and, if ``diagonals``, both
    diagonals of every cell (``hypot(dx, dy)``); without diagonals a grid of
    rectangles is not rigid (cells can shear), so keep them for a rigid formation.
    Example: ``grid_formation(2, 3, 12.0, 3.5)`` = two rows of three CAVs.

    Args:
        rows, cols: number of rows (lateral) and columns (longitudinal), >= 1, N = rows*cols >= 2.
        dx: longitudinal spacing (centre to centre), m. dy: lateral spacing, m.
    """
    if int(rows) != rows or rows < 1:
        raise ValueError(f"rows must be an integer >= 1, got {rows!r}")
    if int(cols) != cols or cols < 1:
        raise ValueError(f"cols must be an integer >= 1, got {cols!r}")
    rows, cols = int(rows), int(cols)
    if rows * cols < 2:
        raise ValueError("rows * cols must be >= 2")
    dx = _check_positive("dx", dx)
    dy = _check_positive("dy", dy)
    r, c = np.divmod(np.arange(rows * cols), cols)
    ref = np.column_stack([c * dx, r * dy]).astype(float)
    ref -= ref.mean(axis=0)
    idx = np.arange(rows * cols).reshape(rows, cols)
    und = [np.column_stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()])]
    und.append(np.column_stack([idx[:-1, :].ravel(), idx[1:, :].ravel()]))
    if diagonals:
        und.append(np.column_stack([idx[:-1, :-1].ravel(), idx[1:, 1:].ravel()]))
        und.append(np.column_stack([idx[:-1, 1:].ravel(), idx[1:, :-1].ravel()]))
    return graph_from_reference(ref, np.concatenate(und, axis=0))


def _accumulate(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Sum rows of ``values`` (E, m) into (n, m) by ``index`` (E,) with one bincount."""
    m = values.shape[1]
    flat = (index[:, None] * m + np.arange(m)).ravel()
    return np.bincount(flat, weights=values.ravel(), minlength=n * m).reshape(n, m)


def _relative(dq: np.ndarray, period_s: float | None) -> np.ndarray:
    if period_s is None:
        return dq
    out = np.array(dq, dtype=float, copy=True)
    out[..., 0] = (out[..., 0] + 0.5 * period_s) % period_s - 0.5 * period_s
    return out


def signed_distance_errors(
    q: np.ndarray, pairs: np.ndarray, desired: np.ndarray, period_s: float | None = None
) -> np.ndarray:
    """(E,) ``||q_j - q_i|| - delta_ij`` in m for each constraint (positive = stretched)."""
    q = np.asarray(q, dtype=float)
    pairs = np.asarray(pairs, dtype=np.intp)
    dq = _relative(q[..., pairs[:, 1], :] - q[..., pairs[:, 0], :], period_s)
    return np.linalg.norm(dq, axis=-1) - np.asarray(desired, dtype=float)


def formation_distance_error(
    q: np.ndarray,
    pairs: np.ndarray,
    desired: np.ndarray,
    kind: str = "rms",
    period_s: float | None = None,
) -> float:
    """Distance error of a configuration, m.

    ``rms``: ``sqrt(mean_e (||q_j - q_i|| - delta_ij)^2)`` over the E constraints
    (each ordered pair once, so an undirected constraint listed both ways counts twice,
    which does not change the RMS of a symmetric graph). ``max``: largest absolute error.

    Args:
        q: (N, m) positions, m. pairs: (E, 2) ints. desired: (E,) m.
        kind: "rms" or "max".
        period_s: wrap axis 0 with this period (ring road), m, or None.
    """
    err = signed_distance_errors(q, pairs, desired, period_s)
    if kind == "rms":
        return float(np.sqrt(np.mean(err**2)))
    if kind == "max":
        return float(np.max(np.abs(err)))
    raise ValueError(f"kind must be 'rms' or 'max', got {kind!r}")


def formation_potential(q: np.ndarray, graph: FormationGraph) -> float:
    """Seed-002 formation potential summed over agents, ``sum_i V_i``, m^4.

    ``sum_{(i, j) in E} 1/4 (||q_i - q_j||^2 - delta_ij^2)^2``. For a symmetric graph
    ``grad_{q_i}`` of this sum is twice agent i's own ``grad V_i``, so the formation
    part of :class:`FormationController` equals ``-K_for / 2 * grad``.
    """
    q = np.asarray(q, dtype=float)
    i, j = graph.pairs.T
    sq = np.sum((q[j] - q[i]) ** 2, axis=1)
    return float(0.25 * np.sum((sq - graph.desired**2) ** 2))


class FormationController:
    """Seed-002 law over a constraint graph; vectorised over the E constraints.

    Graph index k is row k of the observation (``obs.q[k]``); the world must hand the
    formation's members in the graph's order (rows beyond the graph get only the
    leader terms).

    ``compute(obs)`` returns ``u`` (N, m) in m/s^2 for any m in {1, 2, 3}.
    Periodic axis 0 (``obs.period_s``) is honoured through :meth:`Observation.relative`.
    """

    def __init__(self, graph: FormationGraph, params: FormationParams | None = None) -> None:
        self.graph = graph
        self.params = FormationParams() if params is None else params

    def formation_term(self, obs: Observation) -> np.ndarray:
        """(N, m) ``K_for * sum_{j in N_i} (||q_j-q_i||^2 - delta_ij^2)(q_j - q_i)``, m/s^2."""
        i, j = self.graph.pairs.T
        dq = obs.relative(obs.q[j] - obs.q[i])
        w = self.params.K_for * (np.sum(dq**2, axis=1) - self.graph.desired**2)
        return _accumulate(i, w[:, None] * dq, obs.n)

    def consensus_term(self, obs: Observation) -> np.ndarray:
        """(N, m) ``-K_vel * sum_{j in N_i} (p_i - p_j)``, m/s^2."""
        i, j = self.graph.pairs.T
        return _accumulate(i, -self.params.K_vel * (obs.p[i] - obs.p[j]), obs.n)

    def leader_term(self, obs: Observation) -> np.ndarray:
        """(N, m) virtual-leader tracking (velocity per agent, position by the centroid)."""
        u = np.zeros_like(obs.q)
        if obs.leader_p is not None and self.params.K_ref > 0:
            u -= self.params.K_ref * (obs.p - obs.leader_p)
        if obs.leader_q is not None and self.params.K_pos > 0:
            lq = np.broadcast_to(obs.leader_q, obs.q.shape)
            offset = np.mean(obs.relative(obs.q - lq), axis=0)
            u -= self.params.K_pos * offset
        return u

    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations ``u`` (N, m), m/s^2, for the observation's agents 0..N-1."""
        obs.check_finite()
        if self.graph.n_agents > obs.n:
            raise ValueError(
                f"graph refers to agent {self.graph.n_agents - 1} but only {obs.n} agents observed"
            )
        i, j = self.graph.pairs.T
        dq = obs.relative(obs.q[j] - obs.q[i])
        w = self.params.K_for * (np.sum(dq**2, axis=1) - self.graph.desired**2)
        per_pair = w[:, None] * dq - self.params.K_vel * (obs.p[i] - obs.p[j])
        return _accumulate(i, per_pair, obs.n) + self.leader_term(obs)


def stiffness_matrix(graph: FormationGraph, q: np.ndarray, K_for: float) -> np.ndarray:
    """Jacobian ``d u_formation / d q`` at configuration ``q`` (N, m): (N*m, N*m), 1/s^2.

    Dense, for analysing small formations. For ordered pair (i, j) with
    ``r = q_j - q_i``: ``d u_i / d q_j = K_for ((|r|^2 - delta^2) I + 2 r r^T) = -d u_i / d q_i``.
    """
    q = np.asarray(q, dtype=float)
    n, m = q.shape
    i, j = graph.pairs.T
    r = q[j] - q[i]
    w = np.sum(r**2, axis=1) - graph.desired**2
    blocks = K_for * (w[:, None, None] * np.eye(m) + 2.0 * r[:, :, None] * r[:, None, :])
    J = np.zeros((n, m, n, m))
    np.add.at(J, (i, slice(None), j), blocks)
    np.add.at(J, (i, slice(None), i), -blocks)
    return J.reshape(n * m, n * m)


def damping_ratios(
    graph: FormationGraph, params: FormationParams, q: np.ndarray | None = None
) -> np.ndarray:
    """Damping ratios of the linearised closed loop about a formation ``q`` (default: reference).

    Continuous time, no leader: ``d/dt [dq, dp] = [[0, I], [S, -K_vel L (x) I]] [dq, dp]``
    with ``S`` = :func:`stiffness_matrix` and ``L`` the graph Laplacian. Returns the
    ratios ``zeta = -Re(s) / |s|`` (dimensionless) of the eigenvalues ``s`` with
    ``|s| > 1e-6 max|s|`` (rigid-body translation/rotation and common-velocity modes dropped),
    sorted ascending. ``zeta < 1`` for a complex pair = oscillatory mode: the seed's
    "oscillatory trends" appear when ``min(zeta)`` drops; it falls roughly as
    ``K_vel / sqrt(K_for * delta^2)``.
    """
    q = graph.reference if q is None else np.asarray(q, dtype=float)
    if q is None:
        raise ValueError("q is required when the graph has no reference configuration")
    n, m = q.shape
    S = stiffness_matrix(graph, q, params.K_for)
    A = np.zeros((n, n))
    np.add.at(A, (graph.pairs[:, 0], graph.pairs[:, 1]), 1.0)
    lap = np.kron(np.diag(A.sum(axis=1)) - A, np.eye(m))
    top = np.hstack([np.zeros((n * m, n * m)), np.eye(n * m)])
    bottom = np.hstack([S, -params.K_vel * lap])
    s = np.linalg.eigvals(np.vstack([top, bottom]))
    s = s[np.abs(s) > 1e-6 * np.abs(s).max()]
    return np.sort(-s.real / np.abs(s))


def rollout(
    controller: FormationController,
    q0: np.ndarray,
    p0: np.ndarray,
    dt: float,
    n_steps: int,
    *,
    leader_q0: np.ndarray | None = None,
    leader_p: np.ndarray | None = None,
    scheme: str = "euler",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integrate the double integrator under ``controller`` (no saturation, no obstacles).

    ``scheme="euler"`` is the seed's update ``q(t+1) = q + T_s p(t)``,
    ``p(t+1) = p + T_s u(t)`` (explicit Euler); ``"semi-implicit"`` updates ``p``
    first and moves with the new velocity. A constant-velocity virtual leader
    ``leader_q(t) = leader_q0 + leader_p t`` is passed in each observation if given.

    Args:
        q0, p0: (N, m) initial positions m and velocities m/s. dt: step T_s, s.

    Returns:
        t (T+1,) s, Q (T+1, N, m) m, P (T+1, N, m) m/s.
    """
    dt = _check_positive("dt", dt)
    if int(n_steps) != n_steps or n_steps < 0:
        raise ValueError(f"n_steps must be an integer >= 0, got {n_steps!r}")
    if scheme not in ("euler", "semi-implicit"):
        raise ValueError(f"scheme must be 'euler' or 'semi-implicit', got {scheme!r}")
    q = np.array(q0, dtype=float)
    p = np.array(p0, dtype=float)
    Q = np.empty((n_steps + 1, *q.shape))
    P = np.empty_like(Q)
    Q[0], P[0] = q, p
    lp = None if leader_p is None else np.asarray(leader_p, dtype=float)
    lq0 = None if leader_q0 is None else np.asarray(leader_q0, dtype=float)
    for k in range(n_steps):
        lq = None if lq0 is None else lq0 + (0.0 if lp is None else lp * k * dt)
        u = controller.compute(Observation(q=q, p=p, t=k * dt, dt=dt, leader_q=lq, leader_p=lp))
        if scheme == "euler":
            q = q + dt * p
            p = p + dt * u
        else:
            p = p + dt * u
            q = q + dt * p
        Q[k + 1], P[k + 1] = q, p
    return np.arange(n_steps + 1) * dt, Q, P


def oscillation_metrics(
    t: np.ndarray,
    Q: np.ndarray,
    graph: FormationGraph,
    settle_frac: float = 0.1,
    tol: float | None = None,
) -> dict[str, float]:
    """How oscillatory a formation transient is (the seed's "oscillatory trends").

    ``e(t)`` is the RMS distance error (m). The transient ends at ``t*``, the first
    time ``e <= settle_frac * max(e)``. After ``t*``:

    * ``max_rebound`` (m): largest rise of ``e`` above its running minimum; 0 for a
      monotone (non-oscillatory) approach;
    * ``rebound`` (m): total rise, ``sum max(e(t+1) - e(t), 0)``;
    * ``overshoots``: mean number of sign changes per constraint of the signed error
      ``||q_j - q_i|| - delta_ij``, counted only when it leaves a band of +-``tol`` m
      (default 1 % of the smallest ``delta``) — each is one overshoot of the target.

    Also ``t_settle`` (s) = ``t*`` and ``e_final`` (m) = ``e`` at the last sample. If the
    run never gets below ``settle_frac * max(e)``, ``t_settle`` and the after-``t*``
    measures are nan (the run was too short to judge).
    """
    tol = 0.01 * float(graph.desired.min()) if tol is None else float(tol)
    eps = signed_distance_errors(Q, graph.pairs, graph.desired)  # (T+1, E)
    e = np.sqrt(np.mean(eps**2, axis=1))
    settled = e <= settle_frac * e.max()
    overshoots_total = float(np.mean(_band_crossings(eps, tol)))
    if not settled.any():
        nan = float("nan")
        return {
            "t_settle": nan,
            "e_final": float(e[-1]),
            "max_rebound": nan,
            "rebound": nan,
            "overshoots": nan,
            "overshoots_total": overshoots_total,
        }
    k0 = int(np.argmax(settled))
    tail = e[k0:]
    rise = tail - np.minimum.accumulate(tail)
    return {
        "t_settle": float(t[k0]),
        "e_final": float(e[-1]),
        "max_rebound": float(rise.max()),
        "rebound": float(np.sum(np.clip(np.diff(tail), 0.0, None))),
        "overshoots": float(np.mean(_band_crossings(eps[k0:], tol))),
        "overshoots_total": overshoots_total,
    }


def _band_crossings(x: np.ndarray, tol: float) -> np.ndarray:
    """(E,) sign changes of each column of ``x`` (T, E) ignoring samples with |x| <= tol."""
    s = np.where(x > tol, 1, np.where(x < -tol, -1, 0))
    rows = np.where(s != 0, np.arange(len(s))[:, None], 0)
    last = np.take_along_axis(s, np.maximum.accumulate(rows, axis=0), axis=0)  # forward fill
    flips = (last[1:] != last[:-1]) & (last[:-1] != 0)
    return np.count_nonzero(flips, axis=0)
