"""The world seam: what the simulation loop needs from a world (SUMO or SUMO-free).

A world advances traffic by one step, reports every vehicle in the road frame, and
applies the next speed and lateral position the loop computed for the CAVs it was
asked to hand over. Two worlds implement :class:`World`:

* :class:`cosim.sumo.world.SumoWorld`: SUMO's network and human drivers through libsumo;
* :class:`cosim.sim.road_world.RoadWorld`: the same road frame with double-integrator
  vehicles and no SUMO (fast unit tests of the whole loop, law studies).

Road frame: ``s`` (m) along the main route (periodic on a ring), ``d`` (m) across it,
positive to the left; vehicles are rectangles ``length x width`` (m) centred at (s, d).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from controllers.observation import RoadProfile


@dataclass
class RoadSnapshot:
    """Every vehicle in the world after a step (M of them), SI units.

    Attributes:
        ids: (M,) vehicle ids.
        s: (M,) centre position along the main route, m (NaN off the route).
        s_front: (M,) front bumper position, m.
        d: (M,) lateral centre offset, m.
        v: (M,) speed along the road, m/s.
        v_lat: (M,) lateral speed, m/s.
        length, width: (M,) body size, m.
        is_cav: (M,) bool: a connected automated vehicle.
        on_main: (M,) bool: on the main route (a ramp vehicle is not, until it merges).
        is_static: (M,) bool: a stopped obstacle (not traffic).
        desired: (M,) desired speed, m/s (NaN: unknown).
        purpose: (M,) int: 0 for a vehicle that stays on the main route, 1 for one that
            leaves it by the off-ramp (None: nobody leaves).
    """

    ids: list
    s: np.ndarray
    s_front: np.ndarray
    d: np.ndarray
    v: np.ndarray
    v_lat: np.ndarray
    length: np.ndarray
    width: np.ndarray
    is_cav: np.ndarray
    on_main: np.ndarray
    is_static: np.ndarray
    desired: np.ndarray
    purpose: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.ids)

    def subset(self, rows: np.ndarray) -> RoadSnapshot:
        """The vehicles at ``rows`` (int indices or a boolean mask)."""
        rows = np.asarray(rows)
        if rows.dtype == bool:
            rows = np.flatnonzero(rows)
        return RoadSnapshot(
            ids=[self.ids[r] for r in rows], s=self.s[rows], s_front=self.s_front[rows],
            d=self.d[rows], v=self.v[rows], v_lat=self.v_lat[rows], length=self.length[rows],
            width=self.width[rows], is_cav=self.is_cav[rows], on_main=self.on_main[rows],
            is_static=self.is_static[rows], desired=self.desired[rows],
            purpose=None if self.purpose is None else self.purpose[rows],
        )

    @classmethod
    def empty(cls) -> RoadSnapshot:
        z = np.zeros(0)
        b = np.zeros(0, dtype=bool)
        return cls([], z, z, z, z, z, z, z, b, b, b, z)


class World(Protocol):
    """A world the loop can drive (see the module docstring).

    Attributes:
        dt: step, s.
        road: the road's edges along the main route.
        period: ring length, m, or None.
        speed_limit_mps: the main route's speed limit, m/s.
        departed_now, arrived_now: ids that entered or left in the last step.
        pending: vehicles due to depart that the entrance has not let in yet.
    """

    dt: float
    road: RoadProfile
    period: float | None
    speed_limit_mps: float
    departed_now: list
    arrived_now: list

    def start(self) -> None: ...

    def close(self) -> None: ...

    @property
    def time(self) -> float: ...

    def step(self) -> None:
        """Advance one step (departures, arrivals, uncontrolled vehicles, the applied commands)."""

    def observe(self) -> RoadSnapshot:
        """Every vehicle now, in the road frame."""

    def take_over(self, ids: list) -> None:
        """From now on the loop commands these CAVs (the world stops driving them)."""

    def apply(self, ids: list, v_next: np.ndarray, d_next: np.ndarray,
              v_lat_next: np.ndarray, rows: np.ndarray | None = None) -> None:
        """Next speed (m/s), lateral position (m) and lateral speed (m/s) of CAVs ``ids``;
        ``rows`` (N,): their rows in the last :meth:`observe` snapshot, if the caller has
        them (a world may use them instead of looking the ids up)."""

    def collisions(self) -> list[tuple[str, str]]:
        """Collisions the world itself detected in the last step (pairs of ids)."""

    def teleports(self) -> int: ...

    def pending(self) -> int: ...

    def add_obstacle(self, s_m: float, d_m: float, length_m: float, width_m: float) -> str:
        """Place a stopped vehicle with its centre at (s, d); returns its id."""
