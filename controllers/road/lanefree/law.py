"""The lane-free flocking law (:class:`LaneFreeFlocking`; see :mod:`controllers.road.lanefree`).

Per step: the scene (all vehicles, CAVs first), one sort along the road shared by the
neighbour window and the leader search, the lateral targets of the CAVs whose turn it is
(:func:`kernels.plan`), then every window term at once (:func:`kernels.interact`); the
narrowing bound and the patience rule of the yields, which are rare, stay numpy and Python.
Memory across steps is kept in arrays indexed by a slot per CAV id (one dict look-up per CAV
per step); an entry counts only if its CAV was present in the previous step, as when it was
kept in dicts pruned every step.
"""

from __future__ import annotations

import functools
import zlib
from dataclasses import dataclass
from itertools import compress, repeat

import numpy as np

from controllers.observation import Observation

from .params import LaneFreeParams
from .purpose import RoutePurpose


def _kernels():
    """The compiled kernels (:mod:`.kernels`), imported when a law first computes (not when
    a scenario's configuration imports the law for its parameters: that needs no numba)."""
    from . import kernels

    return kernels


@functools.lru_cache(maxsize=1 << 16)
def _stable_hash(vid) -> int:
    """A hash of a vehicle id that is the same in every process (Python's is salted)."""
    return zlib.crc32(str(vid).encode())


_NO_STATIC = np.zeros(0, dtype=np.intp)  # no static vehicle (no vehicle but CAVs)


def _c_writable(a: np.ndarray) -> np.ndarray:
    """``a`` as a C-contiguous, writable float64 array (itself when it is one already)."""
    if a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable:
        return a
    return np.require(a, dtype=float, requirements=("C", "W"))


@dataclass
class _Scene:
    """All vehicles of a step in one array set: CAVs first (rows 0..N-1), then the others."""

    s: np.ndarray
    d: np.ndarray
    v: np.ndarray
    v_lat: np.ndarray
    length: np.ndarray
    width: np.ndarray
    accel: np.ndarray
    is_cav: np.ndarray
    static: np.ndarray  # a non-CAV never seen moving (a stopped obstacle)
    n: int


class LaneFreeFlocking:
    """The lane-free flocking law (see the package docstring).

    Args:
        params: the law's parameters.
        ctx: the run's context (step, actuator limits; :class:`controllers.registry.RoadContext`).
    """

    name = "flocking"
    #: its memory (lateral targets, yields, sensed vehicles' past speeds) is of the CAVs it
    #: computes for: on per-agent views (the communication layer) each CAV gets a copy
    memory_per_agent = True

    def __init__(self, params: LaneFreeParams, ctx=None) -> None:
        self.params = params
        limits = getattr(ctx, "limits", None)
        self.long_min = getattr(limits, "long_min_mps2", -4.5)
        self.long_max = getattr(limits, "long_max_mps2", 2.6)
        self.lat_max = getattr(limits, "lat_max_mps2", 1.5)
        self.lat_speed_max = getattr(limits, "lat_speed_max_mps", 1.5)
        self.emergency_decel = getattr(limits, "emergency_decel_mps2", 9.0)
        self._packed: dict[float, np.ndarray] = {}
        self.reset()

    # ------------------------------------------------------------------ protocol
    def reset(self) -> None:
        # memory of the CAVs, by slot (self._slot: CAV id -> slot)
        self._slot: dict = {}
        self._ids_of_slot: list = []
        self._last_ids: list | None = None  # the CAVs of the last step and their slots
        self._last_slots = np.zeros(0, np.intp)
        self._mem_target = np.empty(0)  # lateral target d*, m
        self._mem_urgent = np.empty(0, bool)  # its move pays in speed (announced)
        self._mem_phase = np.empty(0, np.int64)  # replanning slot
        self._mem_u = np.empty(0)  # last longitudinal command, m/s^2
        self._mem_last = np.empty(0, np.int64)  # call (below) in which it was last present
        self._mem_stood = np.empty(0)  # how long it has stood (slower than 0.1 m/s), s
        self._calls = 0  # steps with CAVs so far
        self._v_prev: dict = {}  # other id -> last speed, m/s
        self._d_prev: dict = {}  # other id -> last lateral position, m
        self._moved: set = set()  # others seen moving (a stopped obstacle never is)
        self._yield_since: dict = {}  # (CAV id, vehicle id) -> time the yield began, s
        self._yield_asked: set = set()  # the pairs of the last call of _patience
        self._urgent_now = np.zeros(0, bool)
        self._edges_plan = None
        self._purpose = RoutePurpose(self.params)  # the road each CAV drives on (purpose.py)
        self._k = 0
        # (N, all True (N,), all False (N,)): the scene's flags when every vehicle is a CAV
        self._flags_n: tuple = (-1, None, None)
        self._none_fresh_n: tuple = (-1, None)  # (N, all False (N,)): see _none_fresh
        self.stats = {"steps": 0, "cav_steps": 0, "target_changes": 0, "yields": 0,
                      "creeps": 0}

    def _kept(self, values: np.ndarray) -> dict:
        """``{id: value}`` of the CAVs present in the last step."""
        last = self._calls - 1
        return {i: values[k].item() for i, k in self._slot.items() if self._mem_last[k] == last}

    @property
    def _target(self) -> dict:
        """CAV id -> lateral target d*, m (the CAVs of the last step)."""
        return self._kept(self._mem_target)

    @property
    def _urgent(self) -> dict:
        """CAV id -> whether its move is announced (the CAVs of the last step)."""
        return self._kept(self._mem_urgent)

    @property
    def _u_prev(self) -> dict:
        """CAV id -> last longitudinal command, m/s^2 (the CAVs of the last step)."""
        return self._kept(self._mem_u)

    @property
    def lattice_m(self) -> tuple[float, float]:
        """Nominal spacing along the road at 25 m/s and twice it as range, m (flock metrics)."""
        p = self.params
        d = p.standstill_gap_m + 4.5 + p.time_gap_s * 25.0
        return d, 2.0 * d

    def extra_metrics(self) -> dict[str, float]:
        """Lateral target changes, yields (cooperation) and creeps past a funnel's wall
        (:meth:`_creep_past`), each per CAV-step."""
        n = max(self.stats["cav_steps"], 1)
        return {"target_change_rate": self.stats["target_changes"] / n,
                "yield_rate": self.stats["yields"] / n,
                "creep_rate": self.stats["creeps"] / n}

    # ------------------------------------------------------------------ the law
    def compute(self, obs: Observation) -> np.ndarray:
        """Accelerations (N, 2), m/s^2."""
        obs.check_finite()
        n = obs.n
        self._k += 1
        self.stats["steps"] += 1
        self.stats["cav_steps"] += n
        if n == 0:
            return np.zeros((0, 2))
        p = self.params
        ids = obs.ids.tolist()
        slots, fresh = self._slots(ids)
        # memory: lateral targets (re-chosen every replan_s, staggered by id), announced
        # moves and the last longitudinal commands
        every = max(1, int(round(p.replan_s / obs.dt)))
        if fresh.any():
            self._mem_phase[slots[fresh]] = [_stable_hash(ids[r]) % every
                                             for r in np.flatnonzero(fresh)]
        target, urgent, due, u_prev = _kernels().recall(
            fresh, slots, self._mem_target, self._mem_urgent, self._mem_phase, self._mem_u,
            self._k % every)
        sc = self._scene(obs, u_prev)
        m = len(sc.s)
        periodic = obs.period_s is not None
        period = float(obs.period_s) if periodic else 0.0
        order = np.argsort(sc.s, kind="stable")
        k_side = min(p.window, max((m - 1) // 2, 1)) if periodic else p.window
        v_des = np.ascontiguousarray(obs.desired_speed, dtype=float) \
            if obs.desired_speed is not None else np.full(n, 30.0)
        edges, loop_edges, evade_edges = self._band_edges(obs, sc)
        held = self._held(obs, sc, order, periodic, period)
        stood = self._stood(obs, sc, slots, fresh)
        # primary leader in the current band, searched as far as braking needs
        reach = float(sc.v[:n].max()) ** 2 / (2 * p.comfort_decel_mps2) + 30.0
        (u, u_long, hi_n, lo_n, j, ask, u_yield, n_asked, target, urgent, n_changes,
         self._edges_plan) = _kernels().law_step(
            self._pack(obs.dt), sc.s, sc.d, sc.v, sc.v_lat, sc.length, sc.width, sc.accel,
            sc.is_cav, n, order, k_side, periodic, period, target, urgent, due,
            p.lateral_mode == "fixed", edges, evade_edges, loop_edges, loop_edges is not None,
            v_des,
            _NO_STATIC if sc.n == len(sc.s) else np.flatnonzero(sc.static), held, stood,
            float(p.candidate_step_m), float(p.hysteresis_mps),
            float(p.queue_hysteresis), float(p.congested_hysteresis_mps), float(p.row_pull),
            float(self.lat_max), reach)
        self.stats["target_changes"] += int(n_changes)
        self._urgent_now = urgent
        # a narrowing ahead that this CAV's body does not fit into where it is: its start
        # is a stopped wall for the approach bound (the CAV merges or waits before it)
        narrowing = obs.road is not None and not obs.road.is_constant
        if narrowing or n_asked:
            if narrowing:
                side = {"hi": hi_n, "lo": lo_n}
                bound = np.full(n, np.inf)
                for k, rows, road, _cap in self._purpose.roads(obs):
                    bound[rows] = self._narrowing(obs, sc, side, road)[rows]
                    if k:  # its funnel is a purpose, not a wall: it may creep past one
                        self._creep_past(obs, sc, side, rows, k, target, urgent, bound)
                u_long = np.minimum(u_long, bound)
            if n_asked:  # cooperation: yield to announced movers and held-up human drivers
                u_long = np.minimum(u_long, self._yield(obs, sc, j, ask, u_yield))
            u[:, 0] = np.clip(u_long, self.long_min, self.long_max)
        self._remember(obs, sc, slots, target, urgent, u)
        return u

    # ------------------------------------------------------------------ inputs
    def _pack(self, dt: float) -> np.ndarray:
        P = self._packed.get(dt)
        if P is None:
            P = _kernels().pack(self.params, self.long_min, self.long_max, self.lat_speed_max,
                       self.emergency_decel, dt)
            self._packed[dt] = P
        return P

    def _slots(self, ids: list) -> tuple[np.ndarray, np.ndarray]:
        """Memory slots (N,) of the CAVs and which of them start afresh (N,) (absent in the
        previous step: no memory, as when it was pruned)."""
        if ids == self._last_ids:  # the same CAVs as in the last step: none afresh
            return self._last_slots, self._none_fresh(len(ids))
        found = list(map(self._slot.get, ids))
        if None in found:
            for r in [r for r, k in enumerate(found) if k is None]:
                k = len(self._ids_of_slot)
                self._slot[ids[r]] = k
                self._ids_of_slot.append(ids[r])
                found[r] = k
            size = len(self._ids_of_slot)
            if size > len(self._mem_last):
                grow = max(size, 2 * len(self._mem_last), 64) - len(self._mem_last)
                self._mem_target = np.concatenate([self._mem_target, np.full(grow, np.nan)])
                self._mem_urgent = np.concatenate([self._mem_urgent, np.zeros(grow, bool)])
                self._mem_phase = np.concatenate([self._mem_phase, np.zeros(grow, np.int64)])
                self._mem_u = np.concatenate([self._mem_u, np.zeros(grow)])
                self._mem_last = np.concatenate([self._mem_last, np.full(grow, -2, np.int64)])
                self._mem_stood = np.concatenate([self._mem_stood, np.zeros(grow)])
        slots = np.array(found, dtype=np.intp)
        fresh = self._mem_last[slots] != self._calls - 1
        self._last_ids, self._last_slots = ids, slots
        return slots, fresh

    def _none_fresh(self, n: int) -> np.ndarray:
        """(n,) all False (read only, kept per n): no CAV starts afresh."""
        if self._none_fresh_n[0] != n:
            flags = np.zeros(n, bool)
            flags.flags.writeable = False
            self._none_fresh_n = (n, flags)
        return self._none_fresh_n[1]

    def _scene(self, obs: Observation, u_prev: np.ndarray) -> _Scene:
        """The vehicles the law sees, CAVs first; ``u_prev``: the CAVs' last longitudinal
        commands (N,), m/s^2."""
        n = obs.n
        has_others = obs.others_q is not None and len(obs.others_q) > 0
        length = obs.length if obs.length is not None else np.full(n, 4.5)
        width = obs.width if obs.width is not None else np.full(n, 1.8)
        if not has_others:
            if self._flags_n[0] != n:  # every vehicle a CAV, none static (read only)
                self._flags_n = (n, np.ones(n, bool), np.zeros(n, bool))
            return _Scene(
                s=np.ascontiguousarray(obs.q[:, 0]), d=np.ascontiguousarray(obs.q[:, 1]),
                v=np.ascontiguousarray(obs.p[:, 0]), v_lat=np.ascontiguousarray(obs.p[:, 1]),
                length=np.ascontiguousarray(length, dtype=float),
                width=np.ascontiguousarray(width, dtype=float), accel=u_prev,
                is_cav=self._flags_n[1], static=self._flags_n[2], n=n)
        oq, op = obs.others_q, obs.others_p
        ol, ow = obs.others_length, obs.others_width
        m_o = len(oq)
        if obs.others_ids is None:  # anonymous: no memory of them
            v_prev = d_prev = np.full(m_o, np.nan)
            self._d_prev = {}
        else:  # by id, C-level passes
            oids = obs.others_ids.tolist()
            self._moved.update(compress(oids, (op[:, 0] > 0.5).tolist()))
            v_prev = np.fromiter(map(self._v_prev.get, oids, repeat(np.nan)), dtype=float,
                                 count=m_o)
            d_prev = np.fromiter(map(self._d_prev.get, oids, repeat(np.nan)), dtype=float,
                                 count=m_o)
            self._d_prev = dict(zip(oids, oq[:, 1].tolist(), strict=True))
        a_other = np.where(np.isfinite(v_prev), (op[:, 0] - v_prev) / obs.dt, 0.0)
        # lateral speed towards the road's frame from the positions (a vehicle on an
        # on-ramp reports 0 across its own lane while it converges on the road)
        v_lat = np.where(np.isfinite(d_prev), (oq[:, 1] - d_prev) / obs.dt, op[:, 1])
        od = self._entering(obs, oq, op, ow, v_lat)
        if obs.others_ids is None:
            static_o = np.zeros(m_o, bool)
        else:  # never seen moving and standing still: a stopped obstacle
            seen = np.fromiter(map(self._moved.__contains__, oids), dtype=bool, count=m_o)
            static_o = ~seen & (np.abs(op[:, 0]) < 0.5)
        return _Scene(
            s=np.concatenate([obs.q[:, 0], oq[:, 0]]),
            d=np.concatenate([obs.q[:, 1], od]),
            v=np.concatenate([obs.p[:, 0], op[:, 0]]),
            v_lat=np.concatenate([obs.p[:, 1], op[:, 1]]),
            length=np.concatenate([length, ol]).astype(float, copy=False),
            width=np.concatenate([width, ow]).astype(float, copy=False),
            accel=np.concatenate([u_prev, a_other]),
            is_cav=np.concatenate([np.ones(n, bool), np.zeros(len(oq), bool)]),
            static=np.concatenate([np.zeros(n, bool), static_o]),
            n=n,
        )

    def _entering(self, obs: Observation, oq: np.ndarray, op: np.ndarray,
                  ow: np.ndarray, v_lat: np.ndarray) -> np.ndarray:
        """Lateral positions (M,) m of the sensed vehicles as the law uses them (a vehicle
        leaving by an exit where SUMO has it): a vehicle still outside the road but about
        to merge (on an on-ramp: within ``entry_reach_m``
        of its edge, or reaching it within ``entry_horizon_s`` at its lateral speed towards
        the road) is taken to be on the road already, at its nearest inside position: CAVs
        behind it there keep their gap to it, CAVs beside it make room.

        Args: ``oq``, ``op`` (M, 2) positions m and velocities m/s (along, across);
        ``ow`` (M,) widths m; ``v_lat`` (M,) lateral speeds in the road frame, m/s."""
        p = self.params
        d = oq[:, 1].copy()
        if obs.road is None:
            return d
        edges = obs.road.edges(oq[:, 0])
        lo = edges[:, 0] + 0.5 * ow + 0.1
        hi = edges[:, 1] - 0.5 * ow - 0.1
        out = np.maximum(lo - d, d - hi)  # > 0: outside by this much
        inward_mps = np.where(d < lo, v_lat, -v_lat)  # lateral speed towards the road
        reach_m = p.entry_reach_m + p.entry_horizon_s * np.maximum(inward_mps, 0.0)
        merging = (out > 0) & (out < reach_m)
        d[merging] = np.clip(d[merging], lo[merging], np.maximum(lo, hi)[merging])
        # a moving vehicle on the road (or merging onto it) that the road narrows on within
        # its squeeze horizon (SUMO's drivers move in only when their lane's edge reaches
        # them) is taken at its nearest inside position there: CAVs beside it make room
        # before it is pushed in, CAVs behind it keep their gap to it. A human driver
        # hugging the edge just before a step is "merging" by a few cm; seen only at the
        # edge it is beside a CAV it is about to cut in front of (a user's abrupt step)
        if not obs.road.is_constant:
            moving = ((out <= 0) | merging) & (np.abs(op[:, 0]) > 0.1)
            if moving.any():
                ahead_m = np.maximum(p.squeeze_min_m, p.squeeze_s * op[moving, 0])
                narrow = obs.road.narrowest(oq[moving, 0], ahead_m)
                w = ow[moving]
                lo_a = narrow[:, 0] + 0.5 * w + 0.1
                hi_a = np.maximum(lo_a, narrow[:, 1] - 0.5 * w - 0.1)
                d[moving] = np.clip(d[moving], lo_a, hi_a)
        if obs.exits is not None and len(obs.exits):
            # a vehicle on an exit's strip or past its gore on the exit's side is leaving:
            # neither merging onto the road nor squeezed by the strip's end
            for s_start, _s_gore, d_right, d_left in obs.exits:
                if d_left <= 1e-9:
                    leaving = (oq[:, 0] >= s_start) & (oq[:, 1] < d_left)
                else:
                    leaving = (oq[:, 0] >= s_start) & (oq[:, 1] > d_right)
                d[leaving] = oq[leaving, 1]
        return d

    # ------------------------------------------------------------------ lateral target
    def _band_edges(self, obs: Observation, sc: _Scene):
        """Road edges (N, 2) m over the target's look-ahead (the road's narrowest ahead, or
        the loop's edges, or none: +-inf), the loop's edges (N, 2) m or None (the kernel
        takes the narrower of the two and the band of lateral centres inside them), and the
        edges (N, 2) m a CAV may evade a human driver within: the first without the band
        kept clear beside an exit's strip (``keep_clear`` of the purpose's roads)."""
        p = self.params
        n = sc.n
        evade = None
        if obs.road is not None and obs.road.is_constant:  # its edges everywhere
            edges = obs.road.edges(sc.s[:n])
        elif obs.road is not None:
            ahead = np.maximum(p.edge_lookahead_min_m, sc.v[:n] * p.edge_lookahead_s)
            edges = np.empty((n, 2))
            for _k, rows, road, cap in self._purpose.roads(obs):
                edges[rows] = road.narrowest(sc.s[:n][rows], np.minimum(ahead[rows], cap))
            if obs.exits is not None and len(obs.exits):
                evade = np.empty((n, 2))
                for _k, rows, road, cap in self._purpose.roads(obs, keep_clear=False):
                    evade[rows] = road.narrowest(sc.s[:n][rows],
                                                 np.minimum(ahead[rows], cap))
        elif obs.road_edges is not None:
            edges = obs.road_edges
        else:
            edges = np.column_stack([np.full(n, -np.inf), np.full(n, np.inf)])
        loop_edges = None
        if obs.road_edges is not None:  # never wider than what the loop enforces
            # writable and contiguous: a read-only copy (delayed messages) would make numba
            # compile law_step once more
            loop_edges = _c_writable(obs.road_edges)
        edges = _c_writable(edges)
        return edges, loop_edges, edges if evade is None else _c_writable(evade)

    # ------------------------------------------------------------------ longitudinal
    def _narrowing(self, obs, sc, side, road=None) -> np.ndarray:
        """Approach bound (N,) m/s^2 to the start of the first road piece ahead (within the
        look-ahead) whose edges exclude the CAV's body at its lateral position by more than
        it can still move sideways before it gets there; inf if none
        (:func:`kernels.narrowing_bound`: one pass over the CAVs, each testing the road's
        pieces that start within its look-ahead; a vehicle alongside on the side the CAV
        must move to blocks it now)."""
        p = self.params
        road = obs.road if road is None else road
        out, _ = _kernels().narrowing_bound(
            self._pack(obs.dt), sc.s, sc.d, sc.v, sc.width, sc.length, sc.n, road.s0,
            road.right, road.left, bool(road.periodic), float(road.length_m),
            np.ascontiguousarray(side["hi"], dtype=float),
            np.ascontiguousarray(side["lo"], dtype=float), float(p.edge_lookahead_min_m),
            float(p.lookahead_s), 0.5 * self.lat_speed_max, 0.25 * p.a_lat_bound_mps2)
        return out

    #: Speed (m/s) to which a CAV creeping past its funnel's wall is held
    #: (:meth:`_creep_past`); it creeps only while slower than this plus 0.5 m/s.
    CREEP_MPS = 2.0
    #: A vehicle alongside within this lateral gap (m) can hold a CAV by its side bound.
    CREEP_SIDE_GAP_M = 1.0

    def _creep_past(self, obs, sc, side, rows, k, target, urgent, bound) -> None:
        """Where a CAV bound for exit ``k`` (``rows`` of the group) stands before its
        funnel's wall (a purpose: it could still leave later) and a CAV alongside it on
        the exit's side, level with it or behind, standing, has announced a move to this
        CAV's side (a merging CAV at the end of its strip), the two wait for each other:
        the first cannot move towards the exit, the second cannot move at all. The one
        ahead creeps on (``bound`` (N,) m/s^2, in place: the road's own narrowing bound
        without the funnel, and at most :data:`CREEP_MPS`) until it is clear of the other,
        which then moves in behind it. A user's freeway at 70 % CAVs stood 423 s so.
        ``target``, ``urgent`` (N,): the CAVs' lateral targets (m) and announced moves."""
        n = sc.n
        cand = rows[np.isfinite(bound[rows]) & (sc.v[rows] < self.CREEP_MPS + 0.5)]
        if not len(cand) or obs.period_s is not None:
            return
        row = np.asarray(obs.exits, dtype=float)[k - 1]
        right = row[3] <= 1e-9  # the exit's strip lies right of the centre line
        movers = np.flatnonzero(urgent[:n] & (sc.v[:n] < 1.0))
        if not len(movers):
            return
        p = self.params
        road = None
        for i in cand.tolist():
            x = sc.s[movers] - sc.s[i]
            dd = sc.d[movers] - sc.d[i]
            half_l = 0.5 * (sc.length[i] + sc.length[movers])
            gap = np.abs(dd) - 0.5 * (sc.width[i] + sc.width[movers])
            towards = np.sign(target[movers] - sc.d[movers]) == -np.sign(dd)
            held = ((x <= 0) & (x > -(half_l + p.side_buffer_m)) & (gap < self.CREEP_SIDE_GAP_M)
                    & ((dd < 0) if right else (dd > 0)) & towards & (movers != i))
            if not held.any():
                continue
            if road is None:
                road = self._purpose.exit_road(obs, k)
            wall = self._narrowing(obs, sc, side, road)[i]
            bound[i] = min(wall, p.approach_gain * (self.CREEP_MPS - sc.v[i]))
            self.stats["creeps"] += 1

    def _approach(self, g, v_j, v) -> np.ndarray:
        """Approach bound ``k_a (v_safe - v)``: come down to the leader's speed at the
        comfortable deceleration before the gap falls to s0, m/s^2 (element-wise)."""
        p = self.params
        b = p.comfort_decel_mps2
        tau = 0.5
        g0 = g - p.standstill_gap_m
        vj = np.maximum(v_j, 0.0)
        root = np.sqrt(np.maximum((b * tau) ** 2 + vj * vj + 2 * b * g0, 0.0))
        v_safe = np.where(g0 > 0, -b * tau + root, 0.0)
        v_safe = np.maximum(v_safe, np.minimum(vj, np.maximum(g0, 0.0)))  # never below 0
        return p.approach_gain * (v_safe - v)

    def _yield(self, obs, sc, j, ask, u_yield) -> np.ndarray:
        """Cooperative gap opening (N,) m/s^2 (inf where nobody asks) from the requests of
        :func:`kernels.interact`, less those a CAV has yielded to too long."""
        ask = ask & self._patience(obs, sc, j, ask)
        out = np.min(np.where(ask, u_yield, np.inf), axis=1)
        self.stats["yields"] += int(np.count_nonzero(np.isfinite(out) & (out < 0)))
        return out

    def _patience(self, obs, sc, j, ask) -> np.ndarray:
        """``ask`` (N, K) without the pairs a CAV has yielded to too long (memory by ids)."""
        p = self.params
        t = float(obs.t)
        ids_all = obs.ids.tolist() + (obs.others_ids.tolist() if obs.others_ids is not None
                                      else [None] * (len(sc.s) - sc.n))
        keep = ask.copy()
        rows, cols = np.nonzero(ask)
        keys = list(zip(map(ids_all.__getitem__, rows.tolist()),
                        map(ids_all.__getitem__, j[rows, cols].tolist()), strict=True))
        seen = set(keys)
        since = self._yield_since
        timeout, renew = p.yield_timeout_s, p.yield_timeout_s + p.yield_cooldown_s
        for k, key in enumerate(keys):
            waited = t - since.setdefault(key, t)
            if waited > timeout:
                keep[rows[k], cols[k]] = False
                if waited > renew:
                    since[key] = t  # patience again
        # a pair that ended before its timeout is forgotten; one kept past it stays (its
        # cooldown). Only the pairs of the last call can have just ended: every other pair
        # in memory was asked in neither call, and at the call where it ended it was either
        # forgotten or past its timeout, which it stays (not a scan of the whole memory,
        # which grew with the run's length)
        for key in self._yield_asked - seen:
            if t - since[key] <= timeout:
                del since[key]
        self._yield_asked = seen
        return keep

    def _held(self, obs, sc, order, periodic, period) -> np.ndarray:
        """Non-CAVs (M,) held up by a stopped obstacle: they have moved, are now slower than
        3 m/s, and the nearest vehicle ahead in their band, within 15 m (bumper to bumper),
        is one that never moved (a stopped obstacle). They want to merge out and must not be
        trapped. A human queued behind moving or merely slow traffic is not held: the CAVs
        beside it owe it nothing (yielding to every human in a queue would stop the free
        bands for them)."""
        n = sc.n
        m = len(sc.s)
        out = np.zeros(m, bool)
        if m == n or obs.others_ids is None:
            return out
        oids = obs.others_ids.tolist()
        rows = np.arange(n, m)
        moved = np.fromiter(map(self._moved.__contains__, oids), dtype=bool, count=len(oids))
        slow = rows[(sc.v[rows] < 3.0) & moved]
        if not len(slow):
            return out
        static = np.zeros(m, bool)
        static[n:] = ~moved
        if not static.any():
            return out
        cand = np.flatnonzero(static)
        for r in slow.tolist():
            ds = sc.s[cand] - sc.s[r]
            if periodic:
                ds = np.mod(ds, period)
            gap = ds - 0.5 * (sc.length[cand] + sc.length[r])
            overlap = np.abs(sc.d[cand] - sc.d[r]) < 0.5 * (sc.width[cand] + sc.width[r])
            ahead = (ds > 0) & overlap & (gap < 15.0)
            if not ahead.any():
                continue
            # nearest vehicle ahead in the band (any kind) must be the static one
            allv = np.arange(m)
            ds_all = sc.s - sc.s[r]
            if periodic:
                ds_all = np.mod(ds_all, period)
            ov_all = np.abs(sc.d - sc.d[r]) < 0.5 * (sc.width + sc.width[r])
            ov_all[r] = False
            near = allv[(ds_all > 0) & ov_all]
            if len(near) and static[near[np.argmin(ds_all[near])]]:
                out[r] = True
        return out

    # ------------------------------------------------------------------ memory
    def _stood(self, obs, sc, slots, fresh) -> np.ndarray:
        """How long (N,) s each CAV has stood, slower than the standoff speed (kernels'
        ``STANDOFF_MPS``), up to and including this step (0 when it moves; a CAV afresh
        starts at one step); kept in the memory."""
        k = _kernels()
        prev = np.where(fresh, 0.0, self._mem_stood[slots])
        stood = np.where(sc.v[:sc.n] < k.STANDOFF_MPS, prev + obs.dt, 0.0)
        self._mem_stood[slots] = stood
        return stood

    def _remember(self, obs, sc, slots, targets, urgent, u) -> None:
        _kernels().remember(slots, targets, urgent, u, self._calls, self._mem_target,
                            self._mem_urgent, self._mem_u, self._mem_last)
        self._calls += 1
        if obs.others_ids is not None and sc.n < len(sc.s):
            oids = obs.others_ids.tolist()
            self._v_prev = dict(zip(oids, sc.v[sc.n:].tolist(), strict=True))
            self._moved.intersection_update(oids)
        else:
            self._v_prev = {}
