"""Vicsek-style alignment with noise and the flock metrics of seed 004.

Seed 004 (Jadhav, Lad, Yedla, "Simulation and Analysis of Multi-Agent Flocking
Behaviors", ASU MAE 598 report) studies a Vicsek-style model (its refs.:
Vicsek et al., PRL 1995; Jadbabaie et al., IEEE TAC 2003). Two update rules are
provided here, both *synchronous* (every agent uses the state at step t):

``rule="vicsek"`` (Vicsek et al. 1995; constant speed ``v0``)::

    theta_i(t+1) = arg( sum_{j : |q_j - q_i| <= r} (cos theta_j, sin theta_j) ) + eta * xi_i
    p_i(t+1) = v0 (cos theta_i(t+1), sin theta_i(t+1)),   q_i(t+1) = q_i(t) + dt p_i(t+1)

with ``xi_i ~ U[-1/2, 1/2]`` (noise amplitude ``eta`` in rad, 0..2 pi); the
neighbourhood includes agent i itself.

``rule="seed004"`` (the report's section II model and its Step 1a MATLAB code)::

    p_i(t+1) = (1 - alpha) p_i(t) + alpha * mean_{j : |q_j - q_i| < r} p_j(t) + sigma * n_i(t)
    q_i(t+1) = q_i(t) + dt p_i(t+1)

with ``alpha`` = velocity_matching, ``sigma`` = noise_factor and ``n_i`` standard
normal per component. The speed is *not* constant here: it is set by the noise
(the report notes "more the noise factor more the speed"). Differences from the
MATLAB script: the script updates agents one after the other in place
(later agents see earlier agents' new velocities); we update all at once. The
script's neighbour search ignores the wrap-around it applies to positions; with
``periodic=True`` we search neighbours across the seam too.

The report's parameters (Step 1a, section IV): N = 100, 100 m x 100 m, r = 10 m,
velocity_matching 0.5, noise_factor 0.1, initial velocities ``rand - 0.5`` per
component, 100 time steps of 1 s, wrap-around boundaries; its claim (section IV):
velocities "reach consensus within 10 simulation time steps" with high gains,
"stabilized flocks within 10 to 50 timesteps" (abstract).

Neighbours come from :class:`scipy.spatial.cKDTree` (``boxsize`` for periodic
domains); no N x N array is ever built.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from controllers.observation import Observation

__all__ = [
    "VicsekAlignmentController",
    "VicsekModel",
    "VicsekParams",
    "avg_nearest_neighbour_distance",
    "dispersion",
    "local_alignment",
    "neighbour_pairs",
    "order_parameter",
    "velocity_alignment",
]


if TYPE_CHECKING:  # imported where used: not at start-up (cosim list, config)
    import pandas as pd
    from scipy.spatial import cKDTree


RULES = ("vicsek", "seed004")


# --------------------------------------------------------------------------- neighbours


def _box_array(boxsize: float | np.ndarray | None, m: int) -> np.ndarray | None:
    """Per-axis periods (m,) with 0 = non-periodic axis, or None if nothing is periodic."""
    if boxsize is None:
        return None
    box = np.broadcast_to(np.asarray(boxsize, dtype=float), (m,)).copy()
    box[~np.isfinite(box)] = 0.0
    if np.any(box < 0):
        raise ValueError(f"boxsize must be >= 0 on every axis, got {boxsize!r}")
    return None if not np.any(box > 0) else box


def _wrap(q: np.ndarray, box: np.ndarray | None) -> np.ndarray:
    """Wrap the periodic axes of ``q`` (N, m) into [0, L_k) (exactly, for cKDTree)."""
    if box is None:
        return q
    out = np.array(q, dtype=float, copy=True)
    for k in np.flatnonzero(box > 0):
        x = np.mod(out[:, k], box[k])
        out[:, k] = np.where(x >= box[k], 0.0, x)  # np.mod may round up to exactly L
    return out


def _tree(q: np.ndarray, box: np.ndarray | None) -> cKDTree:
    from scipy.spatial import cKDTree

    return cKDTree(_wrap(q, box), boxsize=box)


def neighbour_pairs(
    q: np.ndarray, r: float, boxsize: float | np.ndarray | None = None
) -> np.ndarray:
    """All unordered pairs ``(i, j)``, ``i < j``, with ``|q_i - q_j| <= r``; shape (K, 2).

    Args:
        q: (N, m) positions, m.
        r: interaction radius, m (> 0).
        boxsize: period L (scalar) or per-axis periods (m,) for a periodic domain,
            0 or inf on a non-periodic axis; None for open space. Distances on
            periodic axes are minimum-image.
    """
    q = np.asarray(q, dtype=float)
    r = _positive("r", r)
    if len(q) < 2:
        return np.empty((0, 2), dtype=np.intp)
    box = _box_array(boxsize, q.shape[1])
    pairs = _tree(q, box).query_pairs(r, output_type="ndarray")
    return np.asarray(pairs, dtype=np.intp).reshape(-1, 2)


def _neighbour_sum(values: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """(N, k) sum over neighbours j of ``values[j]`` (self excluded) from unordered pairs."""
    n, k = values.shape
    i, j = pairs[:, 0], pairs[:, 1]
    idx = np.concatenate([i, j])
    src = np.concatenate([values[j], values[i]], axis=0)
    flat = (idx[:, None] * k + np.arange(k)).ravel()
    return np.bincount(flat, weights=src.ravel(), minlength=n * k).reshape(n, k)


def _degree(pairs: np.ndarray, n: int) -> np.ndarray:
    return np.bincount(pairs.ravel(), minlength=n)


# --------------------------------------------------------------------------- metrics


def _unit(p: np.ndarray) -> np.ndarray:
    """Unit velocity vectors of agents with non-zero speed, (N', m)."""
    p = np.asarray(p, dtype=float)
    s = np.linalg.norm(p, axis=1)
    keep = s > 0
    return p[keep] / s[keep, None]


def order_parameter(p: np.ndarray) -> float:
    """Vicsek order parameter ``phi = |(1/N) sum_i p_i / |p_i||`` (dimensionless, 0..1).

    Seed 004, Step 2 ("velocity alignment"), in the form of Vicsek et al. (1995), the
    report's ref. 2: 1 when all headings agree, about ``1/sqrt(N)`` for random headings.
    Agents with zero speed have no heading and are left out; nan if none is left.

    Args:
        p: (N, m) velocities, m/s.
    """
    u = _unit(p)
    return float(np.linalg.norm(u.mean(axis=0))) if len(u) else float("nan")


def velocity_alignment(p: np.ndarray) -> float:
    """Mean cosine similarity of the headings over all pairs ``i != j`` (dimensionless).

    Seed 004, Step 2: ``velocity_alignment = mean(cosine_similarity)``. The report's
    MATLAB line ``sum(unit_velocities .* unit_velocities, 2)`` multiplies every unit
    vector with *itself*, so it is identically 1 whatever the flock does; we read the
    intent as the cosine similarity between agents:
    ``(1/(N(N-1))) sum_{i != j} e_i . e_j = (N phi^2 - 1) / (N - 1)``, computed in O(N).
    Range ``[-1/(N-1), 1]``; 0 in expectation for random headings. nan if N' < 2.

    Args:
        p: (N, m) velocities, m/s (zero-speed agents are left out).
    """
    u = _unit(p)
    n = len(u)
    if n < 2:
        return float("nan")
    s = u.sum(axis=0)
    return float((s @ s - n) / (n * (n - 1)))


def local_alignment(
    q: np.ndarray, p: np.ndarray, r: float, boxsize: float | np.ndarray | None = None
) -> float:
    """Mean cosine similarity of headings over neighbour pairs within ``r`` (dimensionless).

    ``mean_{(i, j): |q_i - q_j| <= r, i < j} e_i . e_j`` with ``e = p / |p|``: the
    local counterpart of :func:`velocity_alignment` (seed 004 asks for velocity
    alignment with neighbours; a flock can be locally aligned long before it is
    globally). nan if there is no neighbour pair.

    Args:
        q: (N, m) positions, m. p: (N, m) velocities, m/s. r: radius, m.
        boxsize: as in :func:`neighbour_pairs`.
    """
    pairs = neighbour_pairs(q, r, boxsize)
    if len(pairs) == 0:
        return float("nan")
    e = _unit_or_zero(np.asarray(p, dtype=float))
    return float(np.mean(np.sum(e[pairs[:, 0]] * e[pairs[:, 1]], axis=1)))


def avg_nearest_neighbour_distance(
    q: np.ndarray, boxsize: float | np.ndarray | None = None
) -> float:
    """Average nearest-neighbour distance ``(1/N) sum_i min_{j != i} |q_i - q_j|``, m.

    Seed 004, Step 2 ("Average Neighbor Distance": ``nanmean(min(pdist2))`` with the
    diagonal removed). Uses a k-d tree (k = 2 nearest, the first being the agent
    itself); minimum-image distances if ``boxsize`` is given (the report's script
    uses plain distances). nan for N < 2.

    Args:
        q: (N, m) positions, m. boxsize: as in :func:`neighbour_pairs`.
    """
    q = np.asarray(q, dtype=float)
    if len(q) < 2:
        return float("nan")
    box = _box_array(boxsize, q.shape[1])
    d, _ = _tree(q, box).query(_wrap(q, box), k=2)
    return float(np.mean(d[:, 1]))


def dispersion(q: np.ndarray) -> float:
    """Group spatial dispersion ``sqrt(sum_k var(q[:, k]))``, m (sample variance, N-1).

    Seed 004, Step 2: ``sqrt(var(positions(:,1)) + var(positions(:,2)))`` with MATLAB's
    ``var`` (normalised by N - 1). Computed on the coordinates as given (in a periodic
    domain, on the wrapped coordinates, as the report does; uniformly spread agents
    in an L x L box give about ``L / sqrt(6)``). nan for N < 2.

    Args:
        q: (N, m) positions, m.
    """
    q = np.asarray(q, dtype=float)
    if len(q) < 2:
        return float("nan")
    return float(np.sqrt(np.sum(np.var(q, axis=0, ddof=1))))


# --------------------------------------------------------------------------- model


def _positive(name: str, value: float) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def _nonneg(name: str, value: float) -> float:
    v = float(value)
    if not np.isfinite(v) or v < 0:
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return v


@dataclass(frozen=True)
class VicsekParams:
    """Parameters of :class:`VicsekModel` (defaults: the report's Step 1a values).

    Attributes:
        n: number of agents N (>= 2).
        L: side of the square domain, m (> 0); initial positions are uniform in it.
        r: interaction (sensing) radius, m (> 0).
        v0: speed for ``rule="vicsek"``; half-range of the uniform initial velocity
            components for ``rule="seed004"`` (0.5 reproduces ``rand - 0.5``), m/s.
        eta: angular noise amplitude, rad, in [0, 2 pi] (``rule="vicsek"``).
        alpha: velocity_matching in [0, 1] (``rule="seed004"``).
        sigma: noise_factor, m/s, >= 0 (``rule="seed004"``).
        dt: time step, s (> 0).
        periodic: wrap-around square domain of side L (else open plane).
        rule: "vicsek" or "seed004" (see the module docstring).
    """

    n: int = 100
    L: float = 100.0
    r: float = 10.0
    v0: float = 0.5
    eta: float = 0.1
    alpha: float = 0.5
    sigma: float = 0.1
    dt: float = 1.0
    periodic: bool = True
    rule: str = "vicsek"

    def __post_init__(self) -> None:
        if int(self.n) != self.n or self.n < 2:
            raise ValueError(f"n must be an integer >= 2, got {self.n!r}")
        object.__setattr__(self, "n", int(self.n))
        for name in ("L", "r", "v0", "dt"):
            object.__setattr__(self, name, _positive(name, getattr(self, name)))
        for name in ("eta", "alpha", "sigma"):
            object.__setattr__(self, name, _nonneg(name, getattr(self, name)))
        if self.eta > 2 * np.pi:
            raise ValueError(f"eta must be in [0, 2 pi] rad, got {self.eta!r}")
        if self.alpha > 1:
            raise ValueError(f"alpha must be in [0, 1], got {self.alpha!r}")
        if self.rule not in RULES:
            raise ValueError(f"rule must be one of {RULES}, got {self.rule!r}")

    @property
    def density(self) -> float:
        """Number density ``N / L^2``, 1/m^2."""
        return self.n / self.L**2


class VicsekModel:
    """Self-propelled particles in 2-D; vectorised, k-d tree neighbour search.

    Attributes:
        q: (N, 2) positions, m. p: (N, 2) velocities, m/s. t: time, s. k: step count.
    """

    def __init__(self, params: VicsekParams | None = None, seed: int | None = 0) -> None:
        self.params = VicsekParams() if params is None else params
        self.rng = np.random.default_rng(seed)
        P = self.params
        self.q = self.rng.uniform(0.0, P.L, (P.n, 2))
        if P.rule == "vicsek":
            theta = self.rng.uniform(-np.pi, np.pi, P.n)
            self.p = P.v0 * np.column_stack([np.cos(theta), np.sin(theta)])
        else:
            self.p = self.rng.uniform(-P.v0, P.v0, (P.n, 2))
        self.t = 0.0
        self.k = 0

    @property
    def boxsize(self) -> float | None:
        """Period of the domain, m, or None in open space."""
        return self.params.L if self.params.periodic else None

    def neighbours(self) -> np.ndarray:
        """(K, 2) unordered neighbour pairs ``i < j`` within ``r`` at the current state."""
        return neighbour_pairs(self.q, self.params.r, self.boxsize)

    def _vicsek_velocity(self, pairs: np.ndarray) -> np.ndarray:
        P = self.params
        heading = _unit_or_zero(self.p)
        s = heading + _neighbour_sum(heading, pairs)
        theta = np.arctan2(s[:, 1], s[:, 0]) + P.eta * self.rng.uniform(-0.5, 0.5, P.n)
        return P.v0 * np.column_stack([np.cos(theta), np.sin(theta)])

    def _seed004_velocity(self, pairs: np.ndarray) -> np.ndarray:
        P = self.params
        count = 1.0 + _degree(pairs, P.n)
        v_avg = (self.p + _neighbour_sum(self.p, pairs)) / count[:, None]
        noise = self.rng.standard_normal((P.n, 2))
        return (1.0 - P.alpha) * self.p + P.alpha * v_avg + P.sigma * noise

    def step(self) -> None:
        """Advance one step of ``dt`` (synchronous update, then move, then wrap)."""
        pairs = self.neighbours()
        if self.params.rule == "vicsek":
            self.p = self._vicsek_velocity(pairs)
        else:
            self.p = self._seed004_velocity(pairs)
        self.q = self.q + self.params.dt * self.p
        if self.params.periodic:
            self.q = _wrap(self.q, _box_array(self.params.L, 2))
        self.k += 1
        self.t = self.k * self.params.dt

    def metrics(self) -> dict[str, float]:
        """Seed-004 metrics of the current state (see the metric functions for units)."""
        return {
            "step": self.k,
            "t": self.t,
            "order_parameter": order_parameter(self.p),
            "velocity_alignment": velocity_alignment(self.p),
            "local_alignment": local_alignment(self.q, self.p, self.params.r, self.boxsize),
            "avg_nn_distance": avg_nearest_neighbour_distance(self.q, self.boxsize),
            "dispersion": dispersion(self.q),
            "mean_speed": float(np.mean(np.linalg.norm(self.p, axis=1))),
        }

    def advance(self, n_steps: int) -> None:
        """Run ``n_steps`` steps without recording anything."""
        if int(n_steps) != n_steps or n_steps < 0:
            raise ValueError(f"n_steps must be an integer >= 0, got {n_steps!r}")
        for _ in range(int(n_steps)):
            self.step()

    def run(self, n_steps: int, record_every: int = 1) -> pd.DataFrame:
        """Run ``n_steps`` steps; one row of :meth:`metrics` every ``record_every`` steps.

        The initial state is the first row. Columns: step, t (s), order_parameter (-),
        velocity_alignment (-), local_alignment (-), avg_nn_distance (m),
        dispersion (m), mean_speed (m/s).
        """
        if int(n_steps) != n_steps or n_steps < 0:
            raise ValueError(f"n_steps must be an integer >= 0, got {n_steps!r}")
        if int(record_every) != record_every or record_every < 1:
            raise ValueError(f"record_every must be an integer >= 1, got {record_every!r}")
        rows = [self.metrics()]
        done = 0
        while done < n_steps:
            chunk = min(int(record_every), int(n_steps) - done)
            self.advance(chunk)
            done += chunk
            rows.append(self.metrics())
        import pandas as pd

        return pd.DataFrame(rows)


def _unit_or_zero(p: np.ndarray) -> np.ndarray:
    s = np.linalg.norm(p, axis=1, keepdims=True)
    return np.divide(p, s, out=np.zeros_like(p), where=s > 0)


# --------------------------------------------------------------------------- controller


class VicsekAlignmentController:
    """Velocity alignment for double integrators: ``u_i = gain * (mean_{j in N_i} p_j - p_i)``.

    ``N_i`` = other agents within ``radius`` (m) of agent i (self excluded); an agent
    with no neighbour gets ``u_i = 0``. ``gain`` in 1/s, ``u`` in m/s^2, any m in 1..3.
    A periodic axis 0 (``obs.period_s``, ring road) is searched across the seam.
    Usable as a CAV controller (alignment only: no cohesion, no collision avoidance).
    """

    def __init__(self, radius: float = 10.0, gain: float = 0.5) -> None:
        self.radius = _positive("radius", radius)
        self.gain = _nonneg("gain", gain)

    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations (N, m), m/s^2."""
        obs.check_finite()
        box = None
        if obs.period_s is not None:
            box = np.zeros(obs.m)
            box[0] = obs.period_s
        pairs = neighbour_pairs(obs.q, self.radius, box)
        deg = _degree(pairs, obs.n)
        mean_p = _neighbour_sum(obs.p, pairs) / np.maximum(deg, 1)[:, None]
        u = self.gain * (mean_p - obs.p)
        u[deg == 0] = 0.0
        return u
