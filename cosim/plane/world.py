"""The plane world: a SUMO-free double integrator for controller studies.

Agents obey ``q' = p``, ``p' = u`` (seed 000 "Agents' Dynamics"), integrated
with forward Euler (``q += p dt; p += u dt``, as the seeds' scripts do) or
semi-implicit Euler (``p += u dt; q += p dt``, symplectic, better energy
behaviour). Walls, circular obstacles, road edges and a gamma-agent reference
are optional. Results come back as pandas DataFrames and can be written as CSV.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from controllers.observation import Circles, Observation, Walls
from cosim.metrics.flock import flock_metrics

if TYPE_CHECKING:  # imported where the tables are built, not at start-up (cosim list)
    import pandas as pd

INTEGRATORS = ("euler", "semi_implicit")


@dataclass
class PlaneResult:
    """Outputs of a plane-world run.

    ``metrics``: one row per recorded step (t in s, metric columns with units).
    ``trajectories``: one row per agent and recorded step: t_s, agent, x_m,
    y_m, vx_mps, vy_mps, ux_mps2, uy_mps2 (z columns for m = 3).
    ``leader``: t_s and the reference position/velocity.
    ``meta``: scenario name, seed, parameters.
    """

    metrics: pd.DataFrame
    trajectories: pd.DataFrame
    leader: pd.DataFrame
    meta: dict = field(default_factory=dict)

    def write(self, out_dir: str | Path) -> Path:
        """Write metrics.csv, trajectories.csv, leader.csv and meta.json into ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        self.metrics.to_csv(out / "metrics.csv", index=False)
        self.trajectories.to_csv(out / "trajectories.csv", index=False)
        self.leader.to_csv(out / "leader.csv", index=False)
        (out / "meta.json").write_text(json.dumps(self.meta, indent=2, default=str))
        return out


_AX = ("x", "y", "z")


class PlaneWorld:
    """Double-integrator world running any controller with ``compute(obs) -> u``.

    Args:
        q0, p0: initial positions and velocities (N, m), m and m/s.
        controller: object with ``compute(Observation) -> (N, m)`` m/s^2.
        dt: step, s.
        reference: gamma-agent with ``state()`` and ``advance(dt, q)`` or None.
        circles, walls: obstacles.
        road_edges: constant (right, left) lateral edges in m, or a function of
            the longitudinal positions (N,) returning (N, 2).
        period_s: periodic axis-0 length, m (ring), or None.
        integrator: "euler" or "semi_implicit".
        lattice_d, lattice_r: spacing and range used by the flock metrics, m.
        record_every: keep trajectories every k steps (0: none).
        metrics_every: compute metrics every k steps.
        on_step: optional callback ``f(world)`` after each step (e.g. energy).
    """

    def __init__(
        self,
        q0: np.ndarray,
        p0: np.ndarray,
        controller,
        dt: float,
        *,
        reference=None,
        circles: Circles | None = None,
        walls: Walls | None = None,
        road_edges=None,
        period_s: float | None = None,
        integrator: str = "euler",
        lattice_d: float = 7.0,
        lattice_r: float = 8.4,
        sizes: tuple[float, float] | None = None,
        record_every: int = 1,
        metrics_every: int = 1,
        on_step: Callable | None = None,
    ) -> None:
        self.q = np.array(q0, dtype=float, copy=True)
        self.p = np.array(p0, dtype=float, copy=True)
        if self.q.ndim != 2 or self.q.shape != self.p.shape:
            raise ValueError(f"q0 {self.q.shape} and p0 {self.p.shape} must both be (N, m)")
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt!r}")
        if integrator not in INTEGRATORS:
            raise ValueError(f"integrator must be one of {INTEGRATORS}, got {integrator!r}")
        self.controller = controller
        self.dt = float(dt)
        self.reference = reference
        self.circles = circles
        self.walls = walls
        self.road_edges = road_edges
        self.period_s = period_s
        self.integrator = integrator
        self.lattice_d = lattice_d
        self.lattice_r = lattice_r
        self.sizes = sizes
        self.record_every = record_every
        self.metrics_every = max(1, metrics_every)
        self.on_step = on_step
        self.t = 0.0
        self.k = 0
        self.u = np.zeros_like(self.q)
        self._metrics: list[dict] = []
        self._traj: list[np.ndarray] = []
        self._leader: list[np.ndarray] = []

    @property
    def n(self) -> int:
        return self.q.shape[0]

    def observation(self) -> Observation:
        """The controller's view of the current state."""
        q_r = p_r = None
        if self.reference is not None:
            q_r, p_r = self.reference.state()
        edges = None
        if self.road_edges is not None:
            edges = (
                self.road_edges(self.q[:, 0])
                if callable(self.road_edges)
                else np.broadcast_to(np.asarray(self.road_edges, dtype=float), (self.n, 2))
            )
        length = width = None
        if self.sizes is not None:
            length, width = np.full(self.n, self.sizes[0]), np.full(self.n, self.sizes[1])
        return Observation(
            q=self.q,
            p=self.p,
            t=self.t,
            dt=self.dt,
            length=length,
            width=width,
            circles=self.circles,
            walls=self.walls,
            road_edges=edges,
            leader_q=q_r,
            leader_p=p_r,
            period_s=self.period_s,
        )

    def step(self) -> None:
        """One control step: observe, compute u, integrate, move the reference."""
        obs = self.observation()
        obs.check_finite()
        if self.k % self.metrics_every == 0:
            self._record_metrics(obs)
        u = np.asarray(self.controller.compute(obs), dtype=float)
        if u.shape != self.q.shape:
            raise ValueError(f"controller returned u of shape {u.shape}, expected {self.q.shape}")
        self.u = u
        if self.record_every and self.k % self.record_every == 0:
            self._record_traj()  # the row at t holds the command applied from t
        if self.integrator == "euler":
            self.q = self.q + self.p * self.dt
            self.p = self.p + u * self.dt
        else:
            self.p = self.p + u * self.dt
            self.q = self.q + self.p * self.dt
        if self.period_s is not None:
            self.q[:, 0] = np.mod(self.q[:, 0], self.period_s)
        if self.reference is not None:
            self.reference.advance(self.dt, self.q)
        self.t += self.dt
        self.k += 1
        if self.on_step is not None:
            self.on_step(self)

    def run(self, duration_s: float) -> PlaneResult:
        """Run for ``duration_s`` seconds and return the recorded outputs."""
        n_steps = int(round(duration_s / self.dt))
        for _ in range(n_steps):
            self.step()
        obs = self.observation()
        self._record_metrics(obs)
        if self.record_every:
            self.u = np.full_like(self.q, np.nan)  # no command after the last step
            self._record_traj()
        return self.result()

    def _record_metrics(self, obs: Observation) -> None:
        row = {"t_s": self.t, "step": self.k}
        row.update(
            flock_metrics(
                self.q,
                self.p,
                self.lattice_d,
                self.lattice_r,
                p_ref=obs.leader_p,
                circles=self.circles,
                walls=self.walls,
                period=self.period_s,
            )
        )
        row["max_speed_mps"] = float(np.max(np.linalg.norm(self.p, axis=1)))
        if obs.road_edges is not None:
            half = 0.0 if obs.width is None else 0.5 * obs.width
            out = np.maximum(
                obs.road_edges[:, 0] - (self.q[:, 1] - half),
                (self.q[:, 1] + half) - obs.road_edges[:, 1],
            )
            row["max_edge_excursion_m"] = float(np.max(out))
        if obs.leader_q is not None:
            e = obs.relative(self.q - obs.leader_q)
            row["max_leader_distance_m"] = float(np.max(np.linalg.norm(e, axis=1)))
        self._metrics.append(row)
        if self.reference is not None:
            q_r, p_r = self.reference.state()
            self._leader.append(np.concatenate([[self.t], q_r, p_r]))

    def _record_traj(self) -> None:
        block = np.column_stack(
            [np.full(self.n, self.t), np.arange(self.n), self.q, self.p, self.u]
        )
        self._traj.append(block)

    def result(self, meta: dict | None = None) -> PlaneResult:
        import pandas as pd

        m = self.q.shape[1]
        cols = ["t_s", "agent"]
        cols += [f"{a}_m" for a in _AX[:m]]
        cols += [f"v{a}_mps" for a in _AX[:m]]
        cols += [f"u{a}_mps2" for a in _AX[:m]]
        traj = (
            pd.DataFrame(np.vstack(self._traj), columns=cols)
            if self._traj
            else pd.DataFrame(columns=cols)
        )
        if len(traj):
            traj["agent"] = traj["agent"].astype(int)
        lcols = ["t_s"] + [f"q{a}_m" for a in _AX[:m]] + [f"p{a}_mps" for a in _AX[:m]]
        leader = (
            pd.DataFrame(np.vstack(self._leader), columns=lcols)
            if self._leader
            else pd.DataFrame(columns=lcols)
        )
        return PlaneResult(pd.DataFrame(self._metrics), traj, leader, dict(meta or {}))
