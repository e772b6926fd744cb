"""The SUMO-free road world: the same road frame, double integrators, no SUMO.

A :class:`~cosim.sim.world.World` for unit tests of the whole loop (milliseconds per
run) and fast law studies. It is not a traffic simulator of human drivers:

* controlled CAVs move exactly as commanded: ``v = v_next``, ``s += v_next dt``,
  ``d = d_next`` (what SUMO does with ``setSpeed`` in speed mode 0 and
  ``setLateralLanePosition``);
* every other vehicle (human drivers, CAVs before they are taken over) follows the
  IDM (Treiber, Hennecke & Helbing, Phys. Rev. E 62, 1805, 2000) along the road
  behind the nearest laterally overlapping vehicle ahead, and never moves sideways:
  ``a = a_max [1 - (v/v0)^4 - (s*(v, dv)/g)^2]``, ``s* = s0 + v T + v dv / (2 sqrt(a_max b))``,
  with the vehicle types' acceleration, standstill gap and reaction time
  (:mod:`cosim.demand.spec`), braking at most at the emergency deceleration;
* vehicles enter at the road's start as planned (:func:`cosim.demand.plan.plan_vehicles`)
  once the gap ahead in their lateral band is at least ``s0 + v0 T`` (else they wait:
  :meth:`pending`), and leave when their front reaches the road's end; on a ring
  they are placed at t = 0;
* a stopped obstacle never moves.

The world detects no collisions itself (:meth:`collisions` is empty): the loop's
geometric check (:mod:`cosim.metrics.traffic`) sees every overlap.
"""

from __future__ import annotations

import numpy as np

from controllers.road.reference import leader_gaps
from cosim.demand.plan import DemandPlan
from cosim.demand.spec import (
    ACCEL_MPS2,
    CAV_TAU_S,
    DECEL_MPS2,
    EMERGENCY_DECEL_MPS2,
    HDV_TAU_S,
    MIN_GAP_M,
)
from cosim.road.geometry import RoadGeometry
from cosim.sim.world import RoadSnapshot

IDM_COMFORT_DECEL_MPS2 = 2.0  # b of the IDM, m/s^2
IDM_DELTA = 4.0
#: Largest distance ahead (m) at which an IDM driver reacts to a leader.
IDM_REACH_M = 200.0


class RoadWorld:
    """See the module docstring.

    Args:
        road: the road's frame (:func:`cosim.road.geometry.road_geometry`).
        plan: the vehicles to insert.
        dt: step, s.
    """

    def __init__(self, road: RoadGeometry, plan: DemandPlan, dt: float) -> None:
        self.geometry = road
        self.road = road.profile()
        self.dt = float(dt)
        self.period = road.length_m if road.periodic else None
        self.speed_limit_mps = float(road.speed_limit_mps)
        self._plan = list(plan.vehicles)
        self._next = 0
        self._t = 0.0
        self.departed_now: list = []
        self.arrived_now: list = []
        self.controlled: set = set()
        cap = max(16, len(self._plan) + 1)
        self.ids: list = []
        self.s = np.zeros(cap)
        self.d = np.zeros(cap)
        self.v = np.zeros(cap)
        self.v_lat = np.zeros(cap)
        self.length = np.zeros(cap)
        self.width = np.zeros(cap)
        self.is_cav = np.zeros(cap, dtype=bool)
        self.is_static = np.zeros(cap, dtype=bool)
        self.desired = np.zeros(cap)
        self.tau = np.zeros(cap)
        #: the last commands: rows (into ``ids`` at the time of the call) and (v_next,
        #: d_next, v_lat_next) (K,) each, m/s, m, m/s
        self._cmd: tuple | None = None
        self._waiting = 0

    # --------------------------------------------------------------------------- World
    def start(self) -> None:
        """Nothing to start (SUMO's counterpart opens a simulation)."""

    def close(self) -> None:
        """Nothing to close."""

    @property
    def time(self) -> float:
        return self._t

    @property
    def n(self) -> int:
        return len(self.ids)

    def step(self) -> None:
        """Move every vehicle one step, remove arrivals, insert departures."""
        dt = self.dt
        n = self.n
        self.departed_now = []
        self.arrived_now = []
        if n:
            self._move(n, dt)
        self._t = round(self._t + dt, 9)
        if n and self.period is None:
            front = self.s[:n] + 0.5 * self.length[:n]
            gone = np.flatnonzero(front >= self.geometry.length_m)
            if len(gone):
                self.arrived_now = [self.ids[i] for i in gone]
                self._remove(gone)
        self._insert()

    def observe(self) -> RoadSnapshot:
        n = self.n
        s = self.s[:n].copy()
        s_front = s + 0.5 * self.length[:n]
        if self.period is not None:
            s = np.mod(s, self.period)
            s_front = np.mod(s_front, self.period)
        return RoadSnapshot(
            ids=list(self.ids), s=s, s_front=s_front, d=self.d[:n].copy(), v=self.v[:n].copy(),
            v_lat=self.v_lat[:n].copy(), length=self.length[:n].copy(),
            width=self.width[:n].copy(), is_cav=self.is_cav[:n].copy(),
            on_main=np.ones(n, dtype=bool), is_static=self.is_static[:n].copy(),
            desired=self.desired[:n].copy(),
        )

    def take_over(self, ids: list) -> None:
        self.controlled.update(ids)

    def apply(self, ids: list, v_next: np.ndarray, d_next: np.ndarray,
              v_lat_next: np.ndarray, rows: np.ndarray | None = None) -> None:
        """Commands for the next step; a vehicle not taken over ignores its command."""
        if rows is None:
            row_of = dict(zip(self.ids, range(self.n), strict=True))
            rows = np.fromiter(map(row_of.__getitem__, ids), dtype=np.intp, count=len(ids))
        rows = np.asarray(rows, dtype=np.intp)
        if not self.controlled.issuperset(ids):
            keep = np.fromiter(map(self.controlled.__contains__, ids), dtype=bool,
                               count=len(ids))
            rows = rows[keep]
            v_next, d_next, v_lat_next = (np.asarray(x)[keep]
                                          for x in (v_next, d_next, v_lat_next))
        self._cmd = (rows, np.array(v_next, dtype=float), np.array(d_next, dtype=float),
                     np.array(v_lat_next, dtype=float))

    def collisions(self) -> list[tuple[str, str]]:
        return []

    def teleports(self) -> int:
        return 0

    def pending(self) -> int:
        """Vehicles due to depart that could not enter yet."""
        return self._waiting

    def add_obstacle(self, s_m: float, d_m: float, length_m: float, width_m: float) -> str:
        """A stopped vehicle with its centre at (s, d); returns its id ("obstacle")."""
        self._append("obstacle", s_m, d_m, 0.0, length_m, width_m, False, 0.0, 0.0)
        self.is_static[self.n - 1] = True
        return "obstacle"

    # --------------------------------------------------------------------------- inside
    def _move(self, n: int, dt: float) -> None:
        ctrl = np.zeros(n, dtype=bool)
        if self._cmd is not None:
            ctrl[self._cmd[0]] = True
        free = ~ctrl & ~self.is_static[:n]
        if free.any():
            acc = self._idm(np.flatnonzero(free))
            v_new = np.maximum(self.v[:n][free] + acc * dt, 0.0)
            self.v[:n][free] = v_new
            self.s[:n][free] += v_new * dt
            self.v_lat[:n][free] = 0.0
        if self._cmd is not None:  # the controlled CAVs move as commanded
            rows, v_next, d_next, vl = self._cmd
            self.v[rows] = v_next
            self.s[rows] += v_next * dt
            self.d[rows] = d_next
            self.v_lat[rows] = vl
            self._cmd = None

    def _idm(self, rows: np.ndarray) -> np.ndarray:
        n = self.n
        s = self.s[:n] if self.period is None else np.mod(self.s[:n], self.period)
        gap, v_lead = leader_gaps(s, self.d[:n], self.length[:n], self.width[:n], rows,
                                  reach_m=IDM_REACH_M, period=self.period, v=self.v[:n])
        v = self.v[rows]
        v0 = np.maximum(self.desired[rows], 0.1)
        a, b = ACCEL_MPS2, IDM_COMFORT_DECEL_MPS2
        dv = np.where(np.isfinite(v_lead), v - v_lead, 0.0)
        s_star = MIN_GAP_M + np.maximum(v * self.tau[rows] + v * dv / (2 * np.sqrt(a * b)), 0.0)
        interaction = np.where(np.isfinite(gap), (s_star / np.maximum(gap, 0.01)) ** 2, 0.0)
        acc = a * (1.0 - (v / v0) ** IDM_DELTA - interaction)
        return np.maximum(acc, -EMERGENCY_DECEL_MPS2)

    def _insert(self) -> None:
        self._waiting = 0
        while self._next < len(self._plan) and self._plan[self._next].depart <= self._t + 1e-9:
            pv = self._plan[self._next]
            if pv.centre_s_m is not None:  # ring: placed at t = 0
                s = pv.centre_s_m
            else:
                s = 0.5 * pv.length_m  # rear at the road's start
                if not self._room(s, pv):
                    self._waiting = len([p for p in self._plan[self._next:]
                                         if p.depart <= self._t + 1e-9])
                    return
            v0 = pv.v0_mps if pv.v0_mps is not None else pv.speed
            d = pv.lat_m if pv.lat_m is not None else 0.0
            self._append(pv.vid, s, d, v0, pv.length_m, pv.width_m, pv.is_cav, pv.speed,
                         CAV_TAU_S if pv.is_cav else HDV_TAU_S)
            self.departed_now.append(pv.vid)
            self._next += 1

    def _room(self, s: float, pv) -> bool:
        """True when the new vehicle fits behind the vehicle ahead in its band: a gap of at
        least ``s0 + v0 T`` and a departure speed ``v0`` it could stop from behind that
        vehicle braking (Krauss's safe speed with the vType's deceleration), as SUMO's
        insertion check does for a given departure speed."""
        n = self.n
        if n == 0:
            return True
        d = pv.lat_m if pv.lat_m is not None else 0.0
        overlap = np.abs(self.d[:n] - d) < 0.5 * (self.width[:n] + pv.width_m)
        ds = self.s[:n] - s
        gap = ds - 0.5 * (self.length[:n] + pv.length_m)
        ahead = overlap & (ds > -0.5 * (self.length[:n] + pv.length_m))
        if not ahead.any():
            return True
        v0 = pv.v0_mps if pv.v0_mps is not None else pv.speed
        tau = CAV_TAU_S if pv.is_cav else HDV_TAU_S
        k = int(np.argmin(np.where(ahead, gap, np.inf)))
        g = float(gap[k])
        if g < MIN_GAP_M + v0 * tau:
            return False
        b = DECEL_MPS2
        v_l = float(self.v[k])
        v_safe = -b * tau + np.sqrt((b * tau) ** 2 + v_l * v_l + 2 * b * max(g - MIN_GAP_M, 0.0))
        return v0 <= v_safe + 1e-9

    def _append(self, vid, s, d, v, length, width, is_cav, desired, tau) -> None:
        i = self.n
        if i >= len(self.s):
            for name in ("s", "d", "v", "v_lat", "length", "width", "is_cav", "is_static",
                         "desired", "tau"):
                arr = getattr(self, name)
                setattr(self, name, np.concatenate([arr, np.zeros_like(arr)]))
        self.ids.append(vid)
        self.s[i], self.d[i], self.v[i], self.v_lat[i] = s, d, v, 0.0
        self.length[i], self.width[i] = length, width
        self.is_cav[i], self.is_static[i] = is_cav, False
        self.desired[i], self.tau[i] = desired, tau

    def _remove(self, rows: np.ndarray) -> None:
        keep = np.ones(self.n, dtype=bool)
        keep[rows] = False
        for r in rows:
            self.controlled.discard(self.ids[r])
        self.ids = [v for v, k in zip(self.ids, keep, strict=True) if k]
        m = len(self.ids)
        for name in ("s", "d", "v", "v_lat", "length", "width", "is_cav", "is_static",
                     "desired", "tau"):
            arr = getattr(self, name)
            arr[:m] = arr[: len(keep)][keep]
