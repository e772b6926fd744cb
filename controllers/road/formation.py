"""``formation``: seed 002's rigid formations for groups of CAVs on the road.

CAVs are put into groups in the order they are first seen (``group_size`` each: 7 for
the hexagon plus centre, rows x cols for a block). A complete group holds its shape
by seed 002's law in scaled road coordinates ``x = (s / d_long_m, d / d_lat_m)``
(a car needs more room ahead than beside it), with velocity consensus among its
members, and tracks a reference: the smallest desired speed in the group, and the
road's centre line for the group's centroid::

    u_i = S [ K_for sum_j (|x_j - x_i|^2 - delta_ij^2)(x_j - x_i) ]   (gradient of V, m/s^2)
          - K_vel sum_j (p_i - p_j) + K_ref (v_ref - p_i) - K_centre d_centroid e_d

with ``S = diag(1 / d_long_m, 1 / d_lat_m)`` applied to the scaled gradient so that
the force is the true gradient of the formation potential in road coordinates.
Members of incomplete groups (still entering, or after a member left the road) only
track the reference. :meth:`extra_metrics` gives the formation's distance error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.formation import grid_formation, hexagon_formation
from controllers.observation import Observation
from controllers.params import ParameterError

SHAPES = ("hexagon", "block")


@dataclass(frozen=True)
class RoadFormationParams:
    """Attributes:
    shape: "hexagon" (seed 002: hexagon plus centre, 7 CAVs, 30 constraints) or
        "block" (``rows`` x ``cols`` with diagonals).
    rows, cols: block size (rows side by side, cols one behind the other).
    d_long_m: longitudinal unit of the shape (hexagon side along the road, block
        column spacing), m.
    d_lat_m: lateral unit of the shape, m.
    K_for: formation gain, m^2/s^2 (scaled coordinates are unitless).
    K_vel: velocity consensus gain, 1/s.
    K_ref: reference-speed tracking gain, 1/s.
    K_centre: gain pulling the group's centroid to the road centre, 1/s^2.
    """

    shape: str = "hexagon"
    rows: int = 2
    cols: int = 3
    d_long_m: float = 14.0
    d_lat_m: float = 2.9
    K_for: float = 0.4
    K_vel: float = 0.4
    K_ref: float = 0.5
    K_centre: float = 0.05

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ParameterError(f"shape must be one of {SHAPES}, got {self.shape!r}")
        for name in ("rows", "cols"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or v < 1:
                raise ParameterError(f"{name} must be an integer >= 1, got {v!r}")
        if self.shape == "block" and self.rows * self.cols < 2:
            raise ParameterError("a block needs rows * cols >= 2")
        for name in ("d_long_m", "d_lat_m"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ParameterError(f"{name} must be finite and > 0, got {v!r}")
        for name in ("K_for", "K_vel", "K_ref", "K_centre"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ParameterError(f"{name} must be finite and >= 0, got {v!r}")

    def graph(self):
        """The shape's constraint graph in scaled (unitless) coordinates."""
        if self.shape == "hexagon":
            return hexagon_formation(1.0)
        return grid_formation(self.rows, self.cols, 1.0, 1.0, diagonals=True)


class RoadFormation:
    """Formation groups of CAVs (see the module docstring)."""

    name = "formation"

    def __init__(self, params: RoadFormationParams, ctx=None) -> None:
        self.params = params
        self.graph = params.graph()
        self.size = self.graph.n_agents
        self.scale = np.array([1.0 / params.d_long_m, 1.0 / params.d_lat_m])
        self.reset()

    def reset(self) -> None:
        self._group_of: dict = {}  # vehicle id -> (group number, slot in the shape)
        self._next = 0
        self._error_sum = 0.0
        self._error_n = 0
        self._last_error = np.nan

    @property
    def lattice_m(self) -> tuple[float, float]:
        """The shape's longitudinal unit and twice it as range, m."""
        return self.params.d_long_m, 2.0 * self.params.d_long_m

    def _assign(self, ids) -> np.ndarray:
        for vid in ids.tolist():
            if vid not in self._group_of:
                self._group_of[vid] = divmod(self._next, self.size)
                self._next += 1
        return np.array([self._group_of[v] for v in ids.tolist()], dtype=np.int64).reshape(-1, 2)

    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations (N, 2), m/s^2."""
        p = self.params
        n = obs.n
        u = np.zeros((n, 2))
        if n == 0:
            return u
        gs = self._assign(np.asarray(obs.ids, dtype=object))
        group, slot = gs[:, 0], gs[:, 1]
        v_des = obs.desired_speed if obs.desired_speed is not None else obs.p[:, 0]
        # members present per group
        groups, counts = np.unique(group, return_counts=True)
        complete = set(groups[counts == self.size].tolist())
        errors = []
        v_ref = v_des.copy()
        for g in groups.tolist():
            rows = np.flatnonzero(group == g)
            v_ref[rows] = float(np.min(v_des[rows]))
            if g not in complete:
                continue
            rows = rows[np.argsort(slot[rows])]  # row k holds shape slot k
            q = obs.q[rows]
            i, j = self.graph.pairs.T
            dq = obs.relative(q[j] - q[i])
            x = dq * self.scale
            w = p.K_for * (np.sum(x * x, axis=1) - self.graph.desired**2)
            f = (w[:, None] * x) * self.scale - p.K_vel * (obs.p[rows][i] - obs.p[rows][j])
            acc = np.zeros((self.size, 2))
            np.add.at(acc, i, f)
            centre = float(np.mean(q[:, 1]))
            acc[:, 1] -= p.K_centre * centre
            u[rows] += acc
            ref = self.graph.reference / self.scale  # the shape in road metres
            want = np.linalg.norm(ref[j] - ref[i], axis=1)
            errors.append(np.mean(np.abs(np.linalg.norm(dq, axis=1) - want)))
        u[:, 0] += p.K_ref * (v_ref - obs.p[:, 0])
        u[:, 1] -= p.K_ref * obs.p[:, 1]
        self._last_error = float(np.mean(errors)) if errors else np.nan
        if errors:
            self._error_sum += self._last_error
            self._error_n += 1
        return u

    def extra_metrics(self) -> dict[str, float]:
        """Formation distance error, m: the mean over complete groups and constraints of
        ``| |q_j - q_i| - desired |`` (last step, and the mean over all steps so far)."""
        mean = self._error_sum / self._error_n if self._error_n else np.nan
        return {"formation_error_m": self._last_error, "formation_error_mean_m": mean}
