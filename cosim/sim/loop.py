"""The simulation loop: one step in named phases, with hooks where recorders and timers attach.

Each step runs these phases in order (:data:`PHASES`):

``advance``    the world moves one step (SUMO's ``simulationStep``, or the road world's);
``observe``    every vehicle in the road frame (:class:`~cosim.sim.world.RoadSnapshot`);
               new CAVs on the main route are taken over;
``reference``  the CAVs' observation: desired speeds, the road edges (the narrowest
               within the stopping distance), the road profile, the vehicles they sense;
``control``    the law: ``u = law.compute(obs)``, (N, 2) m/s^2;
``constrain``  the actuator box and jerk limit (each counts its clips);
``safety``     the safety layer (a backstop: it counts every intervention);
``integrate``  next speed ``v + u_long dt`` (>= 0, <= the speed limit) and lateral
               position ``d + v_lat' dt`` (semi-implicit Euler, as SUMO moves vehicles);
``apply``      the world applies them;
``record``     recorders read the state after the step (the snapshot of ``observe``).

Hooks: ``loop.hooks.add(phase, fn, when="after")`` calls ``fn(step)`` with the
:class:`StepData` before or after a phase; :class:`PhaseTimer` uses them to split the
cost of a run by phase (benchmarks/bench_cosim.py). With ``law = None`` (SUMO drives
the CAVs) the phases from ``reference`` to ``apply`` are skipped.
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controllers import protocol
from controllers.layers.constraints import ActuatorLimits, Layer
from controllers.layers.safety import RoadState, SafetyLayer
from controllers.observation import Observation
from controllers.road.profile_kernels import first_wall_ahead
from cosim.errors import CosimError
from cosim.sim.kernels import cav_columns, integrate
from cosim.sim.world import RoadSnapshot, World

PHASES = ("advance", "observe", "reference", "control", "constrain", "safety", "integrate",
          "apply", "record")

#: Road edges ahead that bound a CAV's lateral position: over its stopping distance at the
#: emergency deceleration plus this margin, m.
EDGE_MARGIN_AHEAD_M = 5.0
#: How far ahead a narrowing is a wall for the safety layer's speed rule, m.
WALL_REACH_M = 250.0


@dataclass
class StepData:
    """What one step computed so far (filled phase by phase).

    Attributes:
        k: step number (0 is the first step); t: time after the step, s.
        state: all vehicles after the step.
        cav_rows: (N,) rows of the controlled CAVs in ``state``; cav_ids: their ids;
            controlled: (M,) bool, the same as a mask.
        obs: the CAVs' observation.
        u_law: (N, 2) the law's command, m/s^2; u: after constraints and safety.
        v_next, d_next, v_lat_next: (N,) the commands applied, m/s, m, m/s.
    """

    k: int = 0
    t: float = 0.0
    state: RoadSnapshot | None = None
    cav_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    controlled: np.ndarray | None = None
    cav_ids: list = field(default_factory=list)
    obs: Observation | None = None
    u_law: np.ndarray | None = None
    u: np.ndarray | None = None
    v_next: np.ndarray | None = None
    d_next: np.ndarray | None = None
    v_lat_next: np.ndarray | None = None


class Hooks:
    """Callbacks around the phases: ``add(phase, fn, when)`` with ``when`` "before"/"after"."""

    def __init__(self) -> None:
        self.before: dict[str, list[Callable[[StepData], Any]]] = defaultdict(list)
        self.after: dict[str, list[Callable[[StepData], Any]]] = defaultdict(list)

    def add(self, phase: str, fn: Callable[[StepData], Any], when: str = "after") -> None:
        if phase not in PHASES:
            raise ValueError(f"unknown phase {phase!r} (phases: {', '.join(PHASES)})")
        if when not in ("before", "after"):
            raise ValueError(f"when must be 'before' or 'after', got {when!r}")
        (self.before if when == "before" else self.after)[phase].append(fn)


class PhaseTimer:
    """CPU and wall time per phase, attached through the loop's hooks.

    ``cpu_s[phase]`` and ``wall_s[phase]`` accumulate ``time.process_time`` and
    ``time.perf_counter`` differences, s.
    """

    def __init__(self, hooks: Hooks) -> None:
        self.cpu_s: dict[str, float] = defaultdict(float)
        self.wall_s: dict[str, float] = defaultdict(float)
        self._t0: dict[str, tuple[float, float]] = {}
        for phase in PHASES:
            hooks.add(phase, self._start(phase), "before")
            hooks.add(phase, self._stop(phase), "after")

    def _start(self, phase):
        def fn(_step):
            self._t0[phase] = (time.process_time(), time.perf_counter())
        return fn

    def _stop(self, phase):
        def fn(_step):
            c0, w0 = self._t0.pop(phase)
            self.cpu_s[phase] += time.process_time() - c0
            self.wall_s[phase] += time.perf_counter() - w0
        return fn


class Loop:
    """Drive ``world`` with ``law`` (None: the world drives every vehicle).

    Args:
        world: a :class:`~cosim.sim.world.World`.
        law: a controller (:mod:`controllers.protocol`) or None.
        limits: the CAVs' actuator limits.
        safety: the safety layer, or None (off).
        layers: constraint layers after the law (default: ``limits.layers()``).
        obstacle: (appear_s, s_m, d_m, length_m, width_m) of a stopped vehicle, or None.
    """

    def __init__(self, world: World, law: Any, limits: ActuatorLimits,
                 safety: SafetyLayer | None = None, layers: list[Layer] | None = None,
                 obstacle: tuple[float, float, float, float, float] | None = None) -> None:
        self.world = world
        self.law = law
        self.limits = limits
        self.safety = safety
        self.layers = limits.layers() if layers is None else list(layers)
        self.obstacle = obstacle
        self.obstacle_id: str | None = None
        self.hooks = Hooks()
        self.dt = float(world.dt)
        self.k = 0
        self.last = StepData()
        self._exit_profiles: list | None = None  # see _exit_roads

    # ------------------------------------------------------------------------------
    def run(self, n_steps: int, progress: Callable[[int], Any] | None = None) -> None:
        """Run ``n_steps`` steps; ``progress(k)`` after each (for a progress display)."""
        protocol.reset(self.law)
        for _ in range(n_steps):
            self.step()
            if progress is not None:
                progress(self.k)

    def step(self) -> StepData:
        """One step through all phases; returns what it computed."""
        st = StepData(k=self.k)
        self._phase("advance", st, self._advance)
        self._phase("observe", st, self._observe)
        if self.law is not None and len(st.cav_rows):
            self._phase("reference", st, self._reference)
            self._phase("control", st, self._control)
            self._phase("constrain", st, self._constrain)
            self._phase("safety", st, self._safety)
            self._phase("integrate", st, self._integrate)
            self._phase("apply", st, self._apply)
        self._phase("record", st, lambda s: None)
        self.k += 1
        self.last = st
        return st

    def _phase(self, name: str, st: StepData, fn: Callable[[StepData], None]) -> None:
        for h in self.hooks.before.get(name, ()):
            h(st)
        fn(st)
        for h in self.hooks.after.get(name, ()):
            h(st)

    # ------------------------------------------------------------------------------
    def _advance(self, st: StepData) -> None:
        ob = self.obstacle
        if ob is not None and self.obstacle_id is None and self.k * self.dt >= ob[0] - 1e-9:
            self.obstacle_id = self.world.add_obstacle(*ob[1:])
        self.world.step()
        st.t = self.world.time

    def _observe(self, st: StepData) -> None:
        state = self.world.observe()
        st.state = state
        if self.law is None:
            return
        controlled = state.is_cav & state.on_main & ~state.is_static
        rows = np.flatnonzero(controlled)
        st.cav_rows = rows
        st.controlled = controlled
        if len(rows):
            all_ids = state.ids
            st.cav_ids = (list(all_ids) if len(rows) == len(all_ids)  # every vehicle
                          else list(map(all_ids.__getitem__, rows.tolist())))
            self.world.take_over(st.cav_ids)

    def _reference(self, st: StepData) -> None:
        state, rows = st.state, st.cav_rows
        others = (_NO_ROWS if len(rows) == state.n  # every vehicle is a controlled CAV
                  else np.flatnonzero(~st.controlled & np.isfinite(state.s)))
        b = self.limits.emergency_decel_mps2
        q, p, desired, stop, length, width, finite = cav_columns(
            np.asarray(rows, dtype=np.int64), *_f64(state.s, state.d, state.v, state.v_lat,
                                                      state.length, state.width, state.desired),
            float(self.world.speed_limit_mps), self.dt, 2 * b, EDGE_MARGIN_AHEAD_M)
        edges = self.world.road.narrowest(q[:, 0], stop)
        for k, road in self._exit_roads(state, rows):  # leaving CAVs: the strip goes on
            edges[k] = road.narrowest(q[k, 0], stop[k])
        on_strip = self._on_entry_strip(q, width)
        if on_strip is not None:  # merging CAVs: the edges where they are (see there)
            edges[on_strip] = self.world.road.edges(q[on_strip, 0])
        all_ids = state.ids
        # the observation's arrays are built here in their final form (float64, the
        # documented shapes): the constructor's checks and conversions are skipped
        if len(others):
            oq, op = _pair(state.s, state.d, others), _pair(state.v, state.v_lat, others)
            ol = np.asarray(state.length[others], dtype=float)
            ow = np.asarray(state.width[others], dtype=float)
            oids = _objects(list(map(all_ids.__getitem__, others.tolist())))
        else:  # nobody else: the same empty arrays every step (they hold nothing to change)
            oq = op = _NO_PAIRS
            ol = ow = _NO_VALUES
            oids = _NO_IDS
        st.obs = Observation.trusted(
            state_finite=bool(finite),
            q=q, p=p, t=st.t, dt=self.dt, ids=_objects(st.cav_ids), length=length,
            width=width, others_q=oq, others_p=op, others_length=ol, others_width=ow,
            others_ids=oids, road_edges=edges, period_s=self.world.period,
            desired_speed=desired, road=self.world.road, **self._exits(state, rows),
        )

    def _on_entry_strip(self, q: np.ndarray, width: np.ndarray) -> np.ndarray | None:
        """(N,) bool: the CAV's body is on an entry strip (an on-ramp's acceleration lane
        beside the road), or None (no strip, or nobody on one). Such a CAV is bounded by
        the road's edges where it is, not by the narrowest over its stopping distance: the
        strip ends ahead, and a CAV that cannot merge yet stops before its end (the
        safety layer's wall rule) rather than be pushed over the border into the road in
        front of traffic that has not made room for it."""
        entries = getattr(self.world, "entries", None)
        if entries is None or not len(q):
            return None
        s, d, half = q[:, 0], q[:, 1], 0.5 * width
        on = np.zeros(len(q), bool)
        for s0, s1, d_r, d_l in entries:
            on |= (s >= s0) & (s <= s1) & (d - half < d_l - 0.05) & (d + half > d_r + 0.05)
        return on if on.any() else None

    def _exit_roads(self, state: RoadSnapshot, rows: np.ndarray) -> list:
        """``(CAV indices, road)`` for the CAVs leaving by an exit: the road with the exit's
        strip going on past the gore (:func:`controllers.road.exits.exit_road`), for the
        edges that bound them and the safety layer's walls; empty without exits."""
        exits = getattr(self.world, "exits", None)
        if exits is None or state.purpose is None:
            return []
        idx = state.purpose[rows]
        if not idx.any():
            return []
        if self._exit_profiles is None:
            from controllers.road.exits import exit_road

            self._exit_profiles = [exit_road(self.world.road, row) for row in exits]
        return [(np.flatnonzero(idx == k + 1), road)
                for k, road in enumerate(self._exit_profiles) if (idx == k + 1).any()]

    def _exits(self, state: RoadSnapshot, rows: np.ndarray) -> dict:
        """The road's exits and each CAV's, and its entry strips (observation fields; none
        without them)."""
        out = {}
        entries = getattr(self.world, "entries", None)
        if entries is not None:
            out["entries"] = entries
        exits = getattr(self.world, "exits", None)
        if exits is not None and state.purpose is not None:
            out.update(exits=exits, exit_index=state.purpose[rows])
        return out

    def _control(self, st: StepData) -> None:
        u = self.law.compute(st.obs)
        name = getattr(self.law, "name", None) or type(self.law).__name__
        try:
            st.u_law = protocol.checked_command(u, st.obs.n, name)
        except (TypeError, ValueError) as exc:  # a law breaking the protocol: one line
            msg = str(exc) if name in str(exc) else f"{name}.compute returned {exc}"
            raise CosimError(f"{msg} (step {st.k}, t = {st.t:g} s)") from None

    def _constrain(self, st: StepData) -> None:
        u = st.u_law
        for layer in self.layers:
            u = layer.apply(u, st.obs)
        st.u = u

    def _safety(self, st: StepData) -> None:
        obs = st.obs
        if self.safety is None:
            lim = self.limits.lat_speed_max_mps
            st.v_lat_next = np.clip(obs.p[:, 1] + st.u[:, 1] * self.dt, -lim, lim)
            return
        state = st.state
        finite = np.isfinite(state.s)
        if finite.all():  # everyone on the road (the usual case): no copies
            pos = st.cav_rows
            road = RoadState(state.s, state.d, state.v, state.length, state.width,
                             state.v_lat)
        else:
            on_road = np.flatnonzero(finite)
            pos = np.searchsorted(on_road, st.cav_rows)
            road = RoadState(state.s[on_road], state.d[on_road], state.v[on_road],
                             state.length[on_road], state.width[on_road],
                             state.v_lat[on_road])
        st.u, st.v_lat_next = self.safety.apply(st.u, pos, obs.p[:, 1], road, obs.road_edges,
                                                self.world.period, self._wall_gap(obs, st))

    def _wall_gap(self, obs: Observation, st: StepData | None = None) -> np.ndarray | None:
        """Distance (N,) m from each CAV's front to the first road piece within
        ``WALL_REACH_M`` whose edges its body does not fit into at its lateral position
        (a CAV leaving by an exit: on its road, :meth:`_exit_roads`)."""
        road = self.world.road
        if road.is_constant:
            return None
        args = (np.ascontiguousarray(obs.q[:, 0]), np.ascontiguousarray(obs.q[:, 1]),
                np.ascontiguousarray(obs.width, dtype=float),
                np.ascontiguousarray(obs.length, dtype=float))
        out = first_wall_ahead(*args, road.s0, road.right, road.left, bool(road.periodic),
                               float(road.length_m), WALL_REACH_M)
        if st is not None:
            for k, ex in self._exit_roads(st.state, st.cav_rows):
                out[k] = first_wall_ahead(*(np.ascontiguousarray(a[k]) for a in args), ex.s0,
                                          ex.right, ex.left, bool(ex.periodic),
                                          float(ex.length_m), WALL_REACH_M)
        return out

    def _integrate(self, st: StepData) -> None:
        obs = st.obs
        st.v_next, st.d_next = integrate(
            obs.q, obs.p, np.ascontiguousarray(st.u, dtype=float),
            np.ascontiguousarray(st.v_lat_next, dtype=float), self.dt,
            float(self.world.speed_limit_mps))

    def _apply(self, st: StepData) -> None:
        self.world.apply(st.cav_ids, st.v_next, st.d_next, st.v_lat_next, rows=st.cav_rows)


_NO_ROWS = np.zeros(0, dtype=np.intp)
_NO_PAIRS = np.zeros((0, 2))
_NO_VALUES = np.zeros(0)
_NO_IDS = np.zeros(0, dtype=object)


def _pair(a: np.ndarray, b: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``np.column_stack([a[rows], b[rows]])`` (len(rows), 2), without the temporaries."""
    out = np.empty((len(rows), 2))
    out[:, 0] = a[rows]
    out[:, 1] = b[rows]
    return out


def _f64(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The arrays as float64 (no copy when they are already)."""
    return tuple(np.asarray(a, dtype=float) for a in arrays)


def _objects(items: list) -> np.ndarray:
    """A 1-d object array of ``items`` (ids)."""
    return np.fromiter(items, dtype=object, count=len(items))
