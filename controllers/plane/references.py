"""Gamma-agents: the references a flock follows.

A reference has ``state() -> (q_r, p_r)`` (each (m,), m and m/s) and
``advance(dt, q)`` which moves it one step given the flock positions (N, m).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass
class VirtualLeader:
    """Double-integrator gamma-agent ``q_r' = p_r``, ``p_r' = f(t)``.

    Seed 000, "Dynamic Virtual Leader".

    ``accel`` maps time (s) to the leader's acceleration (m,), m/s^2; None keeps
    a constant velocity. A lateral component makes the leader move across the road.
    """

    q: np.ndarray
    p: np.ndarray
    accel: Callable[[float], np.ndarray] | None = None
    t: float = 0.0

    def __post_init__(self) -> None:
        self.q = np.asarray(self.q, dtype=float).copy()
        self.p = np.asarray(self.p, dtype=float).copy()
        if self.q.shape != self.p.shape:
            raise ValueError(f"leader q {self.q.shape} and p {self.p.shape} differ")

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        return self.q.copy(), self.p.copy()

    def advance(self, dt: float, flock_q: np.ndarray | None = None) -> None:
        """Forward Euler step of the leader, as in seed 000's main.m."""
        a = np.zeros_like(self.p) if self.accel is None else np.asarray(self.accel(self.t))
        self.q = self.q + self.p * dt
        self.p = self.p + a * dt
        self.t += dt


@dataclass
class WaypointSequence:
    """Multi-waypoint mission (seed 001): go to each waypoint in turn.

    ``waypoints`` (W, m) in m, ``speeds`` (W, m) reference velocities in m/s
    (zero for a static goal). The reference jumps to the next waypoint when the
    flock's centroid is within ``tolerance_m`` of the current one. With
    ``moving=True`` each waypoint moves with its velocity as seed 001's goal
    (``q_r' = p_r``).
    """

    waypoints: np.ndarray
    speeds: np.ndarray | None = None
    tolerance_m: float = 5.0
    moving: bool = False
    index: int = 0
    reached_at: list = field(default_factory=list)
    t: float = 0.0

    def __post_init__(self) -> None:
        self.waypoints = np.atleast_2d(np.asarray(self.waypoints, dtype=float)).copy()
        if self.speeds is None:
            self.speeds = np.zeros_like(self.waypoints)
        self.speeds = np.broadcast_to(
            np.asarray(self.speeds, dtype=float), self.waypoints.shape
        ).copy()
        if not self.tolerance_m > 0:
            raise ValueError(f"tolerance_m must be > 0, got {self.tolerance_m!r}")

    @property
    def done(self) -> bool:
        """True once the last waypoint has been reached."""
        return len(self.reached_at) == len(self.waypoints)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        k = min(self.index, len(self.waypoints) - 1)
        return self.waypoints[k].copy(), self.speeds[k].copy()

    def advance(self, dt: float, flock_q: np.ndarray | None = None) -> None:
        self.t += dt
        k = min(self.index, len(self.waypoints) - 1)
        if self.moving:
            self.waypoints[k] += self.speeds[k] * dt
        if flock_q is None or self.done:
            return
        centroid = np.asarray(flock_q).mean(axis=0)
        if np.linalg.norm(centroid - self.waypoints[k]) <= self.tolerance_m:
            self.reached_at.append(self.t)
            if self.index < len(self.waypoints) - 1:
                self.index += 1
