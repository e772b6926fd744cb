"""``formation``: seed 002's rigid formations for groups of CAVs on the road.

CAVs are put into groups of ``K`` (7 for the hexagon plus centre, ``rows x cols`` for a
block) as they are first seen, newcomers of one step in their order along the road.
When all members of a group are on the road for the first time, each gets a *slot* of
the shape: members sorted along the road take the slots sorted along the road, and
members level with each other take the slots level with each other from left to right
(so nobody has to overtake a groupmate to reach its slot). A complete group then holds
its shape by seed 002's distance potential with velocity consensus
(:mod:`controllers.plane.formation`) and tracks a reference::

    u_i = sum_j sat(K_for (|q_j - q_i|^2 / delta_ij^2 - 1) (q_j - q_i))  formation (m/s^2)
          + K_vel sum_j (p_j - p_i)                                   velocity consensus
          + K_ref (v_ref - mean_group(v)) e_s - K_ref v_lat,i e_d       group speed, no drift
          + K_lat (d_c + r_d,slot(i) - d_i) e_d                         lateral slot offset
          - K_centre (d_c - d_road) e_d                                 group on the centre

with ``j`` over the members constrained to ``i`` (seed 002's hexagon: 30 ordered
constraints; a block: neighbours and both diagonals of every cell), ``q = (s, d)`` in
metres (``s`` wrapped on a ring), ``delta_ij`` the slots' distance in the shape
(longitudinal unit ``d_long_m``, lateral unit ``d_lat_m``), ``sat`` a bound of
``max_pull_mps2`` on each constraint's pull, ``v_ref`` the smallest desired speed in
the group, ``d_c`` the group's mean lateral position, ``r_d`` a slot's lateral offset
in the shape and ``d_road`` the road's centre line.

Why these choices (measured in the SUMO-free road world and in SUMO, ring of 1 km,
100 % CAVs at 25 m/s):

* each constraint is normalised by its length, the potential being
  ``sum delta^2 / 4 (r^2 / delta^2 - 1)^2`` (m^2): the stiffness along a constraint at
  rest is ``2 K_for`` (1/s^2) for short and long ones alike (seed 002's unnormalised
  potential is 50 times stiffer along the 40 m diameter than across a 5.5 m width);
* the pull of one constraint is bounded (``max_pull_mps2``): the potential is cubic, so
  a group spread over 170 m at the start asked for 1 000 m/s^2; clipped by the
  actuator box (+2.6 / -4.5 m/s^2, not symmetric) the groups braked to 3 m/s and
  merged into one slow platoon. Bounded, the forces stay internal (they sum to zero
  over a group);
* only the group's mean speed tracks ``v_ref`` (tracking each member's speed opposed
  every change of shape);
* the lateral slot term fixes the orientation (distances alone do not) and moves a
  member sideways before it needs to pass a groupmate; it never moves the centroid
  (the offsets sum to zero). With ``K_lat = 0.3`` a 2 x 3 block could lock with a
  member behind a groupmate in its band (4 of 5 random starts); 0.6 converged in all;
* the default shape, 40 m x 5.5 m (hexagon) or 20 m x 3.2 m cells (block), keeps a
  formed group clear of the safety layer: a corner sits 10 m ahead of the centre and
  2.8 m beside it, and members one behind the other are 20 m apart.

From a random start (``ring_placement = "random"``) the worst group's distance error
falls below 0.1 m within 31-44 s in SUMO (seeds 1, 2, 3, 7, 42; hexagons and blocks).
Members of incomplete groups (still entering, or after a member left the road) only
track their own desired speed and damp their lateral speed. Everything is vectorised
over the complete groups ((G, C) arrays: G groups, C constraints of the shape).
:meth:`extra_metrics` gives the formation's distance error. Limits: groups do not
keep distance to each other (a faster group closing on a slower one is held back by
the safety layer, which bends its shape), and a group does not pass human drivers
between its members (with 20 % human drivers on the ring, SUMO-free world, the mean
error stayed at 9-12 m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.errors import ParameterError
from controllers.observation import Observation
from controllers.plane.formation import grid_formation, hexagon_formation

SHAPES = ("hexagon", "block")


@dataclass(frozen=True)
class RoadFormationParams:
    """Attributes:
    shape: "hexagon" (seed 002: hexagon plus centre, 7 CAVs, 30 constraints) or
        "block" (``rows`` x ``cols`` with both diagonals of every cell).
    rows, cols: block size (rows side by side, cols one behind the other).
    d_long_m: longitudinal unit of the shape, m: the hexagon is ``2 d_long_m`` long
        (centre to front vertex ``d_long_m``), a block's columns are ``d_long_m`` apart.
    d_lat_m: lateral unit of the shape, m: the hexagon's corners sit
        ``0.866 d_lat_m`` beside the centre line, a block's rows are ``d_lat_m`` apart.
    K_for: formation gain, 1/s^2 (stiffness ``2 K_for`` per constraint at rest).
    K_vel: velocity consensus gain, 1/s (per constraint).
    K_ref: group speed tracking and lateral speed damping gain, 1/s.
    K_lat: gain pulling each member to its slot's lateral offset from the group's
        mean lateral position, 1/s^2.
    K_centre: gain pulling the group's mean lateral position to the road's centre
        line, 1/s^2.
    """

    shape: str = "hexagon"
    rows: int = 2
    cols: int = 3
    d_long_m: float = 20.0
    d_lat_m: float = 3.2
    K_for: float = 0.1
    K_vel: float = 0.2
    K_ref: float = 0.5
    K_lat: float = 0.6
    K_centre: float = 0.05
    max_pull_mps2: float = 1.0

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
        if not (np.isfinite(self.max_pull_mps2) and self.max_pull_mps2 > 0):
            raise ParameterError(f"max_pull_mps2 must be finite and > 0, got "
                                 f"{self.max_pull_mps2!r}")
        for name in ("K_for", "K_vel", "K_ref", "K_lat", "K_centre"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ParameterError(f"{name} must be finite and >= 0, got {v!r}")

    def shape_m(self) -> tuple[np.ndarray, np.ndarray]:
        """The shape in road metres: slot offsets (K, 2) m from the shape's centre
        (``s`` along the road, ``d`` to the left) and its undirected constraints (C, 2)."""
        if self.shape == "hexagon":
            g = hexagon_formation(1.0)
        else:
            g = grid_formation(self.rows, self.cols, 1.0, 1.0, diagonals=True)
        ref = g.reference * np.array([self.d_long_m, self.d_lat_m])
        ref = ref - ref.mean(axis=0)
        pairs = g.pairs[g.pairs[:, 0] < g.pairs[:, 1]]  # each constraint once
        return ref, pairs


class RoadFormation:
    """Formation groups of CAVs (see the module docstring)."""

    name = "formation"

    def __init__(self, params: RoadFormationParams, ctx=None) -> None:
        self.params = params
        self.ref, self.pairs = params.shape_m()
        self.size = len(self.ref)
        i, j = self.pairs.T
        self.delta = np.linalg.norm(self.ref[j] - self.ref[i], axis=1)  # (C,) m
        self._slot_order = _slot_order(self.ref)
        self.reset()

    def reset(self) -> None:
        self._group: dict = {}  # vehicle id -> group number
        self._slot: dict = {}  # vehicle id -> slot in the shape (once the group is complete)
        self._next = 0
        self._last_error = np.nan
        self._last_error_max = np.nan
        self._n_groups = 0

    @property
    def lattice_m(self) -> tuple[float, float]:
        """The shape's longitudinal unit and twice it as range, m."""
        return self.params.d_long_m, 2.0 * self.params.d_long_m

    # ------------------------------------------------------------------------------
    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations (N, 2), m/s^2."""
        p = self.params
        n = obs.n
        u = np.zeros((n, 2))
        self._last_error = self._last_error_max = np.nan
        self._n_groups = 0
        if n == 0:
            return u
        ids = obs.ids.tolist() if isinstance(obs.ids, np.ndarray) else list(obs.ids)
        new = [r for r, vid in enumerate(ids) if vid not in self._group]
        # newcomers of one step join groups in their order along the road (a world's
        # id order is arbitrary: SUMO lists a ring's vehicles in no spatial order)
        for r in sorted(new, key=lambda r: obs.q[r, 0]):
            self._group[ids[r]] = self._next // self.size
            self._next += 1
        group = np.fromiter((self._group[v] for v in ids), dtype=np.int64, count=n)
        v_des = obs.desired_speed if obs.desired_speed is not None else obs.p[:, 0]

        # group speed: the smallest desired speed among the members present
        g_min = np.full(int(group.max()) + 1, np.inf)
        np.minimum.at(g_min, group, v_des)
        u[:, 0] = p.K_ref * (g_min[group] - obs.p[:, 0])
        u[:, 1] = -p.K_ref * obs.p[:, 1]

        rows = self._complete_groups(obs, ids, group)  # (G, K) rows of obs by slot
        if rows is None:
            return u
        G = len(rows)
        q, v = obs.q[rows], obs.p[rows]  # (G, K, 2)
        i, j = self.pairs.T
        dq = obs.relative(q[:, j] - q[:, i])  # (G, C, 2) m
        r2 = np.sum(dq * dq, axis=2)
        w = p.K_for * (r2 / self.delta**2 - 1.0)  # (G, C) 1/s^2
        pull = np.abs(w) * np.sqrt(r2)  # (G, C) m/s^2
        w *= np.minimum(1.0, p.max_pull_mps2 / np.maximum(pull, 1e-12))
        f = w[:, :, None] * dq + p.K_vel * (v[:, j] - v[:, i])  # force on i, m/s^2
        acc = np.zeros((G, self.size, 2))
        np.add.at(acc, (slice(None), i), f)  # constraint (i, j) pulls i ...
        np.add.at(acc, (slice(None), j), -f)  # ... and j the opposite way
        # the group's mean speed (not each member's) tracks v_ref: shape changes are free
        v_mean = v[:, :, 0].mean(axis=1)  # (G,) m/s
        acc[:, :, 0] += (p.K_ref * (g_min[group[rows[:, 0]]] - v_mean))[:, None]
        d_c = q[:, :, 1].mean(axis=1)  # (G,) m
        acc[:, :, 1] += p.K_lat * (d_c[:, None] + self.ref[None, :, 1] - q[:, :, 1])
        if obs.road_edges is not None:
            d_road = obs.road_edges[rows].mean(axis=(1, 2))
        else:
            d_road = np.zeros(G)
        acc[:, :, 1] -= (p.K_centre * (d_c - d_road))[:, None]
        u[rows.ravel(), 0] = 0.0  # replaced by the group's own speed tracking
        np.add.at(u, rows.ravel(), acc.reshape(-1, 2))

        err = np.abs(np.sqrt(r2) - self.delta).mean(axis=1)  # (G,) m
        self._last_error = float(err.mean())
        self._last_error_max = float(err.max())
        self._n_groups = G
        return u

    def _complete_groups(self, obs: Observation, ids: list, group: np.ndarray):
        """Rows (G, K) of the complete groups' members by slot (slots assigned the first
        time a group is complete), or None."""
        counts = np.bincount(group)
        complete = np.flatnonzero(counts == self.size)
        if not len(complete):
            return None
        members = np.flatnonzero(np.isin(group, complete))
        members = members[np.argsort(group[members], kind="stable")].reshape(-1, self.size)
        slots = np.array([[self._slot.get(ids[r], -1) for r in m] for m in members])
        new = np.flatnonzero((slots < 0).any(axis=1))
        for g in new:
            slots[g] = self._assign_slots(obs, members[g])
            for r, k in zip(members[g], slots[g], strict=True):
                self._slot[ids[r]] = int(k)
        rows = np.empty_like(members)
        np.put_along_axis(rows, slots, members, axis=1)
        return rows

    def _assign_slots(self, obs: Observation, rows: np.ndarray) -> np.ndarray:
        """Slots (K,) for the members ``rows``: the k-th along the road takes the k-th
        slot along the road; level slots are filled from left to right."""
        rel = obs.relative(obs.q[rows] - obs.q[rows[0]])  # wrapped on a ring
        by_s = np.lexsort((-rel[:, 1], rel[:, 0]))  # rear first; ties: left first
        out = np.empty(self.size, dtype=np.int64)
        start = 0
        for level in self._slot_order:  # slots level with each other, left to right
            chunk = by_s[start:start + len(level)]
            out[chunk[np.argsort(-rel[chunk, 1], kind="stable")]] = level
            start += len(level)
        return out

    def extra_metrics(self) -> dict[str, float]:
        """Formation distance error of the last step, m: ``| |q_j - q_i| - delta_ij |``
        averaged over the constraints of each complete group, then the mean and the
        largest over groups (NaN while no group is complete); and the number of
        complete groups."""
        return {"formation_error_m": self._last_error,
                "formation_error_max_m": self._last_error_max,
                "formation_groups": float(self._n_groups)}


def _slot_order(ref: np.ndarray) -> list[np.ndarray]:
    """Slots grouped by their position along the road (rear first), each level sorted
    from left to right (largest ``d`` first)."""
    s = np.round(ref[:, 0], 6)
    levels = []
    for value in np.unique(s):
        level = np.flatnonzero(s == value)
        levels.append(level[np.argsort(-ref[level, 1], kind="stable")])
    return levels
