"""The SUMO world: libsumo loop, road frame, CAV take-over, applying commands.

This adapter owns every SUMO side effect; controllers never see SUMO. Each
step: ``simulationStep`` -> read all vehicles in bulk (subscriptions) ->
road frame ``(s, d)`` -> observation -> controller -> constraint layers ->
safety layer -> ``setSpeed`` (longitudinal) and ``setLateralLanePosition``
(lateral, integrated by us) for the CAVs.

With speed mode 0, ``setSpeed(v + a dt)`` gives ``x += v_new dt`` (SUMO's
default Euler update); the lateral double integrator is integrated here as
``v_lat += u_lat dt; d += v_lat dt`` (the same semi-implicit Euler).
"""

from __future__ import annotations

import contextlib
import operator
import os
import sys
import tempfile
from collections import deque
from itertools import compress

import numpy as np

from cosim.errors import SumoStartError
from cosim.road.frame import RoadNetwork
from cosim.sim.world import RoadSnapshot
from cosim.sumo.binaries import sumo_binary

_VARS = None
_GETTER = None

#: Run an iterator to its end without keeping its items (a C-level loop).
_consume = deque(maxlen=0).extend


def _row_getter():
    """``operator.itemgetter`` of the subscribed variables, in :func:`_vars` order."""
    global _GETTER
    if _GETTER is None:
        _GETTER = operator.itemgetter(*_vars())
    return _GETTER


def _vars():
    """Dynamic variables subscribed per vehicle (static ones are read once at departure)."""
    global _VARS
    if _VARS is None:
        import libsumo as ls

        _VARS = (
            ls.VAR_LANE_ID,
            ls.VAR_LANEPOSITION,
            ls.VAR_LANEPOSITION_LAT,
            ls.VAR_SPEED,
            ls.VAR_SPEED_LAT,
        )
    return _VARS


def _side_lanes(net: RoadNetwork) -> dict[str, list[tuple[str, float, float, float]]]:
    """Lane id -> spans ``(lane, d_right, d_left, length)`` (m) of every lane of its edge,
    for the main route's edges that have more than one lane (see ``_cross_lanes``)."""
    by_edge: dict[str, list[str]] = {}
    for lane in net.lane_width:
        edge = lane.rsplit("_", 1)[0]
        if not lane.startswith(":") and edge in net.main_route:
            by_edge.setdefault(edge, []).append(lane)
    tb = net.tables
    out = {}
    for lanes in by_edge.values():
        if len(lanes) < 2:
            continue
        spans = []
        for lane in lanes:
            d, half = net.lane_d[lane], 0.5 * net.lane_width[lane]
            spans.append((lane, d - half, d + half, float(tb.lane_len[tb.index[lane]])))
        out.update({lane: spans for lane in lanes})
    return out


#: Lateral speed (m/s) and acceleration (m/s^2) bounds given to controlled CAVs' SL2015
#: model, far beyond any command, so that ``changeSublane`` moves them as asked in one step.
SUBLANE_MOVE_MAX_MPS = 1000.0
SUBLANE_MOVE_MAX_MPS2 = 1.0e6


#: SUMO's default lane-change mode (all its lane-change motivations on).
SUMO_DEFAULT_LANE_CHANGE_MODE = 1621

_CAPTURED: list[str] = []


def captured_lines() -> list[str]:
    """Lines SUMO wrote to stderr during the last :func:`_captured_stderr` block."""
    return list(_CAPTURED)


@contextlib.contextmanager
def _captured_stderr():
    """Redirect file descriptor 2 (where libsumo's C++ code writes) into a buffer.

    SUMO prints its own ``Error: ...`` lines there when it refuses its input; we
    fold them into one error line instead of letting them reach the terminal.
    """
    _CAPTURED.clear()
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield _CAPTURED
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            _CAPTURED.extend(
                x.strip() for x in tmp.read().decode(errors="replace").splitlines() if x.strip()
            )


class _LaneCodes(dict):
    """Lane id -> a small code (int), assigned on first sight; the world's arrays by code
    say the lane's road-frame table key, whether it is on the main route and whether its
    edge has several lanes, so that a step looks every lane id up once."""

    def __init__(self, world: SumoWorld) -> None:
        super().__init__()
        self.world = world

    def __missing__(self, lane: str) -> int:
        w = self.world
        code = len(self)
        self[lane] = code
        w._code_key = np.append(w._code_key, w.net.lane_keys([lane]))
        w._code_main = np.append(w._code_main, lane in w.main_lanes)
        w._code_side = np.append(w._code_side, lane in w._side_lanes)
        return code


class SumoWorld:
    """A running SUMO simulation seen in the road frame of ``net`` (a :class:`World`).

    Args:
        net: the road network (road frame).
        sumo_args: extra SUMO command-line arguments (routes, options).
        dt: step, s (SUMO's ``--step-length``).
        desired: desired speed (m/s) per vehicle id (from the demand plan).
        cav_prefix: vType id prefix that marks CAVs.
        gui: run ``sumo-gui`` through TraCI instead of libsumo.
        cav_action_step_s: SUMO's action step for controlled CAVs, s (None: one step;
            the runner gives ``scenario.cav_action_step_s`` when no human driver is in the
            demand, else one step). SUMO runs a vehicle's own decisions (its lane changer,
            its car-following plan) once per action step; our law overrules both every
            step, so a longer one only saves SUMO's work. The position update stays SUMO's
            Euler step ``v_next dt`` only because the runner passes
            ``--step-method.ballistic false``: given no value, SUMO switches every vehicle
            to the ballistic update (``(v + v_next) dt / 2``) as soon as one has an action
            step longer than a step, and its insertions change with it.
    """

    def __init__(self, net: RoadNetwork, sumo_args: list[str], dt: float = 0.1,
                 desired: dict | None = None, cav_prefix: str = "cav",
                 gui: bool = False, cav_action_step_s: float | None = None,
                 destinations: dict | None = None) -> None:
        self.net = net
        #: destination per vehicle id ("main" or an off-ramp's name: "off", "off2", ...),
        #: the off-ramp each vehicle left the road by, and the trip log: id -> [depart,
        #: joined the main road (ramp traffic), left it by an off-ramp, arrived] times, s
        self.destination = dict(destinations or {})
        self.exit_taken: dict[str, str] = {}
        self.trips: dict[str, list[float]] = {}
        #: the road's exits (off-ramps): (K, 4) rows (s_start, s_gore, d_right, d_left), m
        self.exits = net.exit_strips
        #: the on-ramps' acceleration strips: (J, 4) rows (s_start, s_end, d_right,
        #: d_left), m
        self.entries = net.entry_strips
        #: vehicles that would have missed their exit (sent on along the road) or taken
        #: an exit not theirs (sent down that off-ramp), by kind "cav" / "hdv"
        self.missed_exits = {"cav": 0, "hdv": 0}
        self.wrong_exits = {"cav": 0, "hdv": 0}
        #: vehicles put back inside an off-ramp lane they stood across (see _exit_check)
        self.offramp_lateral_fixes = 0
        self.strip_lateral_fixes = 0  # human drivers moved fully onto an exit strip
        #: the diverge edge of each off-ramp -> (its index, its exit lanes)
        self._diverge = {o.diverge_edge: (k, frozenset(o.exit_lanes))
                         for k, o in enumerate(net.offramps)}
        #: an off-ramp's edges -> its name (where a vehicle that left the road went)
        self._offramp_of = {e: o.name for o in net.offramps for e in o.route}
        self._teleports = 0  # vehicles SUMO teleported so far (summed over the steps)
        self.dt = float(dt)
        self.cav_action_step_s = max(float(cav_action_step_s or dt), self.dt)
        #: the CAVs act less often than every step (see _act_every_step)
        self._slow_actions = self.cav_action_step_s > self.dt + 1e-9
        self.road = net.profile()
        self.speed_limit_mps = float(net.speed_limit_mps)
        self.desired = dict(desired or {})
        self.cav_prefix = cav_prefix
        self.gui = gui
        binary = str(sumo_binary("sumo-gui" if gui else "sumo"))
        self.cmd = [binary, "-n", str(net.net_file), *sumo_args]
        self.ts = None
        self.types: dict[str, str] = {}
        # length, width, is_cav, desired speed
        self._static: dict[str, tuple[float, float, bool, float]] = {}
        #: lane id -> a small code, and by code: the road frame's table key of the lane,
        #: whether it is on the main route, whether its edge has several lanes
        self._lane_code = _LaneCodes(self)
        self._code_key = np.zeros(0, dtype=np.int64)
        self._code_main = np.zeros(0, dtype=bool)
        self._code_side = np.zeros(0, dtype=bool)
        #: the last observation: ids, lane ids, table keys, lane positions and lateral lane
        #: positions (m), and which vehicles move sideways with changeSublane (see apply)
        self._ids: list = []
        self._row_cache: dict[str, int] | None = None  # id -> row, built when asked
        self._lanes: tuple = ()
        self._keys = np.zeros(0, dtype=np.int64)
        self._pos = np.zeros(0)
        self._lat = np.zeros(0)
        self._sublane = np.zeros(0, dtype=bool)
        self._straddle = np.zeros(0, dtype=bool)
        self._set_fns: tuple | None = None  # (setSpeed, setLateralLanePosition)
        self._static_ids: list | None = None  # the vehicles of _static_cols, in order
        self._static_cols: tuple = ()
        self.departed_now: list[str] = []
        self.arrived_now: list[str] = []
        self.controlled: set[str] = set()
        self.v_lat_state: dict[str, float] = {}
        self.period = net.length_m if net.periodic else None
        self.main_lanes = set(net.main_lanes) or {k for k in net.lane_offsets
                                                  if self._is_main(k)}
        self._obstacle = None
        self.obstacle_id: str | None = None
        #: vehicles still on an on-ramp: SUMO moves them only along it (lane-change mode
        #: 0), so they join the road at the ramp's right side where they departed;
        #: released to their own driver model (or our law) on the main road
        self._on_ramp: set[str] = set()
        #: lanes of the main route's edges with more than one lane (an acceleration lane,
        #: three_lane): lane id -> [(lane id, d of its right border, d of its left
        #: border, length)] of every lane of its edge (m), for crossing between them
        self._side_lanes = _side_lanes(net)
        #: controlled CAVs given an action step of one step, and those of them in the step
        #: after their last changeSublane move (see _act_every_step)
        self._every_step: set[str] = set()
        self._clearing: set[str] = set()

    def _is_main(self, lane: str) -> bool:
        edge = lane.rsplit("_", 1)[0] if not lane.startswith(":") else lane
        return edge in self.net.main_route or lane.startswith(":") or lane in self.net.main_route

    # ------------------------------------------------------------------------------
    def start(self) -> None:
        """Start SUMO; raise SumoStartError with SUMO's message if it fails."""
        if self.gui:  # display checked first; sumo-gui errors come back as one line
            from cosim.sumo.gui import start_gui

            self.ts = start_gui(self.cmd)
            return
        try:
            import libsumo

            with _captured_stderr():
                libsumo.start(self.cmd)
            self.ts = libsumo
        except Exception as exc:  # libsumo raises its own exception types
            lines = [x.strip() for x in str(exc).splitlines() if x.strip()]
            errors = [x for x in captured_lines() if x.startswith("Error:")]
            detail = " ".join(x.removeprefix("Error:").strip() for x in errors) or " ".join(lines)
            raise SumoStartError(
                f"SUMO failed to start: {detail or type(exc).__name__}"
            ) from None

    def close(self) -> None:
        if self.ts is not None:
            try:
                self.ts.close()
            except Exception:
                pass
            self.ts = None

    @property
    def time(self) -> float:
        return float(self.ts.simulation.getTime())

    def step(self) -> None:
        """Advance SUMO one step, register departures and arrivals, hold the obstacle."""
        ts = self.ts
        ts.simulationStep()
        # SUMO reports the teleports that started in this step only: counted here
        self._teleports += int(ts.simulation.getStartingTeleportNumber())
        self.departed_now = list(ts.simulation.getDepartedIDList())
        self.arrived_now = list(ts.simulation.getArrivedIDList())
        veh = ts.vehicle
        t = float(ts.simulation.getTime())
        for vid in self.departed_now:
            self.trips[vid] = [t, np.nan, np.nan, np.nan]
            veh.subscribe(vid, _vars())
            if ".ramp" in vid:  # keeps its lateral place on the ramp (see _release_ramp)
                veh.setLaneChangeMode(vid, 0)
                self._on_ramp.add(vid)
            tid = veh.getTypeID(vid)
            self.types[vid] = tid
            self._static[vid] = (
                veh.getLength(vid), veh.getWidth(vid), tid.startswith(self.cav_prefix),
                self.desired.get(vid, np.nan), float(self._exit_number(vid)),
            )
        for vid in self.arrived_now:
            if vid in self.trips:
                self.trips[vid][3] = t
            self.types.pop(vid, None)
            self._static.pop(vid, None)
            self.controlled.discard(vid)
            self.v_lat_state.pop(vid, None)
        self._hold_obstacle()

    def observe(self) -> RoadSnapshot:
        """All vehicles on the network, in the road frame (centre positions).

        Built column by column from the subscription results (no per-vehicle row tuples);
        the static columns (size, CAV or not, desired speed) are reused while the set of
        vehicles is the same as in the previous step.
        """
        res = self.ts.vehicle.getAllSubscriptionResults()
        ids = list(res)
        n = len(ids)
        if n:
            lane, pos_l, lat, speed, slat = zip(*map(_row_getter(), res.values()), strict=True)
        else:
            lane = pos_l = lat = speed = slat = ()
        pos = np.array(pos_l, dtype=float).reshape(n)
        lat = np.array(lat, dtype=float).reshape(n)
        speed = np.array(speed, dtype=float).reshape(n)
        # a controlled CAV's lateral speed is the one the loop integrated
        v_lat_now = np.fromiter(map(self.v_lat_state.get, ids, slat), dtype=float, count=n)
        if ids != self._static_ids:
            static = self._static
            cols = np.array([static[vid] for vid in ids], dtype=float).reshape(n, 5)
            self._static_cols = (cols[:, 0].copy(), cols[:, 1].copy(), cols[:, 2] > 0,
                                 cols[:, 3].copy(), cols[:, 4].astype(np.int64))
            self._static_ids = ids
        length, width, is_cav, desired, purpose = self._static_cols
        codes = np.fromiter(map(self._lane_code.__getitem__, lane), dtype=np.int64, count=n)
        keys = self._code_key[codes]
        self._ids, self._row_cache = ids, None
        self._lanes, self._keys, self._pos, self._lat = lane, keys, pos, lat
        if self._on_ramp:
            self._release_ramp()
        # vehicles to move sideways with changeSublane (see apply): the back still on the
        # lane before, or on an edge of several lanes
        sublane = pos < length
        self._straddle = sublane.copy()  # the back still on the lane before
        if self._side_lanes:
            sublane |= self._code_side[codes]
        self._sublane = sublane
        # (lane, position, lateral position) -> (s, d): the lanes' real geometry
        s_front, d_front = self.net.lane_frame(None, pos, lat, keys=keys)
        s = s_front - 0.5 * length
        if self.period is not None:
            s = np.mod(s, self.period)
        on_main = self._code_main[codes] & ~np.isnan(s)
        if self.exits is not None:
            if self._exit_check(ids, lane, pos, speed, on_main, is_cav, purpose, lat, width):
                self._static_ids = None  # a purpose changed: rebuild the columns
                return self.observe()
        is_static = np.zeros(n, dtype=bool)
        if self.obstacle_id is not None:
            row = self._row_of().get(self.obstacle_id)
            if row is not None:
                is_static[row] = True
        return RoadSnapshot(ids, s, s_front, d_front, speed, v_lat_now, length.copy(),
                            width.copy(), is_cav.copy(), on_main, is_static, desired.copy(),
                            None if self.exits is None else purpose.copy())

    #: A vehicle on the lane before the gore that is not one leading onto its route's next
    #: edge is re-routed when its front is within this time of travel of the lane's end, s
    #: (plus EXIT_BACKSTOP_MIN_M): SUMO would stop it there.
    EXIT_BACKSTOP_S = 1.0
    EXIT_BACKSTOP_MIN_M = 2.0

    def _exit_check(self, ids, lanes, pos, speed, on_main, is_cav, purpose, lat,
                    width) -> bool:
        """Exits, for a road with an off-ramp: log each vehicle's time of leaving the main
        road by the off-ramp; hand a CAV that left back to SUMO (its speed and lane-change
        checks on again); the backstop: a vehicle still on the wrong lane just before the
        gore gets a new destination (counted: a missed exit, or a wrong one). For a CAV it
        catches a failure of the law. A human driver that has not reached the exit's lane
        by then drives on, as a driver who misses an exit does: SUMO's would stop at the
        lane's end and, standing, never move sideways (SL2015's lcMaxSpeedLatStanding is 0),
        blocking the road for good. And a vehicle standing on the off-ramp (its junction
        lane included) with its body over the lane's side is put back inside it (counted
        in :attr:`offramp_lateral_fixes`): SUMO's driver, which entered it late and askew,
        would otherwise never move again. Returns True when a destination changed."""
        veh = self.ts.vehicle
        t = float(self.ts.simulation.getTime())
        trips, controlled = self.trips, self.controlled
        for i in np.flatnonzero(~on_main).tolist():
            vid = ids[i]
            if vid in self._on_ramp or vid == self.obstacle_id:
                continue
            trip = trips.get(vid)
            if trip is not None and np.isnan(trip[2]):
                trip[2] = t
                self.exit_taken[vid] = self._offramp_of.get(
                    lanes[i].rpartition("_")[0], self.destination.get(vid, ""))
            if speed[i] < 0.1 and vid not in controlled:
                half = 0.5 * (self.net.lane_width.get(lanes[i], np.inf) - width[i])
                if half > 0 and abs(lat[i]) > half + 0.05:
                    veh.setLateralLanePosition(vid, float(np.clip(lat[i], -half, half)))
                    self.offramp_lateral_fixes += 1
            if vid in controlled:  # left the road: SUMO drives it on the off-ramp
                controlled.discard(vid)
                self.v_lat_state.pop(vid, None)
                veh.setSpeedMode(vid, 31)
                veh.setLaneChangeMode(vid, SUMO_DEFAULT_LANE_CHANGE_MODE)
                veh.setSpeed(vid, -1.0)
                veh.setActionStepLength(vid, self.dt, True)
                self._every_step.discard(vid)
                self._clearing.discard(vid)
        changed = False
        tb, main = self.net.tables, self.net.main_route
        for i, lane in enumerate(lanes):
            at = self._diverge.get(lane.rpartition("_")[0])
            if at is None or ids[i] == self.obstacle_id:
                continue
            if (not is_cav[i] and lane in at[1] and purpose[i] == at[0] + 1
                    and ids[i] not in controlled):
                self._onto_strip(ids[i], lane, float(lat[i]), float(width[i]))
            left = float(tb.lane_len[tb.index[lane]]) - float(pos[i])
            if left > self.EXIT_BACKSTOP_MIN_M + self.EXIT_BACKSTOP_S * float(speed[i]):
                continue
            k, exit_lanes = at
            off = self.net.offramps[k]
            kind = "cav" if is_cav[i] else "hdv"
            if purpose[i] == k + 1 and lane not in exit_lanes:
                veh.setRoute(ids[i], main[main.index(off.diverge_edge):])
                self.destination[ids[i]] = "main"
                self.missed_exits[kind] += 1
            elif purpose[i] != k + 1 and lane in exit_lanes:
                if purpose[i] > 0:  # bound for a later exit: it missed that one too
                    self.missed_exits[kind] += 1
                veh.setRoute(ids[i], (off.diverge_edge, *off.route))
                self.destination[ids[i]] = off.name
                self.wrong_exits[kind] += 1
            else:
                continue
            st = self._static[ids[i]]
            self._static[ids[i]] = (*st[:4], float(self._exit_number(ids[i])))
            changed = True
        return changed

    #: A human driver on an exit strip whose body reaches more than this (m) over the
    #: strip's border is moved inside it (:meth:`_onto_strip`).
    STRIP_OVERHANG_M = 0.05

    def _onto_strip(self, vid: str, lane: str, lat: float, width: float) -> None:
        """A human driver bound for the exit whose lane is the exit strip but whose body
        still reaches over the strip's border into the road is moved the rest of the way
        in (``changeSublane``: at his own lateral speed), counted in
        :attr:`strip_lateral_fixes`. SL2015 with ``latAlignment="arbitrary"`` stops moving
        sideways once he is on the strip's lane; SUMO's drivers on the road beside do not
        see a body that reaches over their lane's border from the strip, and ran into him
        from behind: 8-18 collisions per 600 s run of SUMO's drivers alone on the
        corridor, every one on the deceleration strip."""
        half = 0.5 * (self.net.lane_width.get(lane, np.inf) - width)
        if half > 0 and abs(lat) > half + self.STRIP_OVERHANG_M:
            self.ts.vehicle.changeSublane(vid, float(np.sign(lat) * half - lat))
            self.strip_lateral_fixes += 1

    def _exit_number(self, vid: str) -> int:
        """0 for a vehicle bound for the road's end, k for one bound for the k-th off-ramp
        (the observation's ``purpose``)."""
        dest = self.destination.get(vid, "main")
        return self.net.exit_number(dest) if self.net.offramps else 0

    def _row_of(self) -> dict[str, int]:
        """Id -> row in the last observation (built once per observation, when asked)."""
        if self._row_cache is None:
            self._row_cache = dict(zip(self._ids, range(len(self._ids)), strict=True))
        return self._row_cache

    def _release_ramp(self) -> None:
        """Give vehicles that reached the main road back their lane-change model."""
        veh = self.ts.vehicle
        row_of, lanes = self._row_of(), self._lanes
        t = float(self.ts.simulation.getTime())
        for vid in [v for v in self._on_ramp if v not in row_of
                    or lanes[row_of[v]] in self.main_lanes]:
            self._on_ramp.discard(vid)
            if vid in row_of and vid in self.trips:
                self.trips[vid][1] = t
            if vid in row_of and vid not in self.controlled:
                veh.setLaneChangeMode(vid, SUMO_DEFAULT_LANE_CHANGE_MODE)

    def take_over(self, ids: list) -> None:
        """Hand CAVs to our controller: no SUMO speed checks, no SUMO lane changes."""
        controlled = self.controlled
        if controlled.issuperset(ids):
            return
        veh = self.ts.vehicle
        for vid in [v for v in ids if v not in controlled]:
            veh.setSpeedMode(vid, 0)
            veh.setLaneChangeMode(vid, 0)
            # a lateral move requested with changeSublane lands in full in the step
            veh.setMaxSpeedLat(vid, SUBLANE_MOVE_MAX_MPS)
            veh.setParameter(vid, "laneChangeModel.lcAccelLat", str(SUBLANE_MOVE_MAX_MPS2))
            if self._slow_actions:
                veh.setActionStepLength(vid, self.cav_action_step_s, True)
            self.controlled.add(vid)
            self.v_lat_state.setdefault(vid, 0.0)

    def apply(self, ids: list, v_next: np.ndarray, d_next: np.ndarray,
              v_lat_next: np.ndarray, rows: np.ndarray | None = None) -> None:
        """Command next speeds (m/s) and lateral positions (road frame, m) of CAVs ``ids``
        (``rows``: their rows in the last :meth:`observe`, when the caller has them).

        Two kinds of CAV move sideways with ``changeSublane`` instead of
        ``setLateralLanePosition``, because only SUMO's lane changer keeps its bookkeeping
        of where a vehicle's body is (tests/test_sumo_loop.py):

        * a CAV whose back is still on the lane before its front's (it straddles a joint of
          edges or a junction lane): SUMO keeps a lateral position per lane the back
          occupies, set when the front left that lane; ``setLateralLanePosition`` moves the
          front alone, so SUMO's drivers and collision check would see the back where the
          vehicle was when it crossed the joint;
        * a CAV on an edge of several lanes (an on-ramp's acceleration lane): a body that
          reaches over the lane's border is seen by the drivers of the next lane only
          through the "shadow lane" the lane changer sets; moved there by
          ``setLateralLanePosition`` it is invisible to them.

        Both land exactly: the CAVs' lane changer may move them up to
        :data:`SUBLANE_MOVE_MAX_MPS` sideways, with no lateral acceleration bound.

        Longitudinal: ``setSpeed(v_next)``; SUMO's Euler update moves the CAV by exactly
        ``v_next dt``, the semi-implicit Euler step of the loop, with either action step
        (bench_floor.py's exactness check; tests/test_exactness.py: bit-identical runs).

        Every CAV gets every setter every step (``setSpeed`` persists in SUMO, so skipping
        an unchanged one would be exact, but benchmarks/bench_floor.py measured 1 %: not
        worth its bookkeeping); libsumo's functions are called directly, without the
        wrapper layer of its Python module (the same C++ calls).
        """
        veh = self.ts.vehicle
        if rows is None:
            rows = np.fromiter(map(self._row_of().__getitem__, ids), dtype=np.int64,
                               count=len(ids))
        pos = self._pos[rows]
        v_next = np.asarray(v_next, dtype=float)
        # road-frame d -> lateral lane position where the vehicle will be after the step
        lats = self.net.lateral_lane_position(None, pos + v_next * self.dt, d_next,
                                              keys=self._keys[rows])
        moved = self._sublane[rows]  # these CAVs move with changeSublane (a copy)
        crossed: list = []
        if self._side_lanes:
            lanes = self._lanes
            crossed = self._cross_lanes(ids, [lanes[r] for r in rows.tolist()], pos, v_next,
                                        d_next, lats, moved, self._straddle[rows])
        if self._set_fns is None:
            self._set_fns = self._setters(veh)
        set_speed, set_lat = self._set_fns
        if self._slow_actions:
            self._act_every_step(crossed)
        # one C-level pass per setter (each vehicle's commands are independent of the
        # others', so the order of the calls does not matter)
        vs, lats_l = v_next.tolist(), lats.tolist()
        _consume(map(set_speed, ids, vs))
        if moved.any():
            placed = (~moved).tolist()
            _consume(map(set_lat, compress(ids, placed), compress(lats_l, placed)))
            lat_now = self._lat[rows].tolist()
            for i in np.flatnonzero(moved).tolist():
                veh.changeSublane(ids[i], lats_l[i] - lat_now[i])
        else:
            _consume(map(set_lat, ids, lats_l))
        self.v_lat_state.update(zip(ids, np.asarray(v_lat_next, dtype=float).tolist(),
                                    strict=True))

    def _act_every_step(self, crossed: list) -> None:
        """Give the CAVs that move with ``changeSublane`` this step an action step of one
        step, keep it one step more after their last such move, then give them back
        ``cav_action_step_s``.

        SUMO's lane changer carries out a ``changeSublane`` request in full only in a
        vehicle's action step, and it clears the request's remaining distance and lateral
        speed only in the action step after it. Left standing, SUMO would reserve that
        distance beside a vehicle whose action step is longer than a step, in the sublanes
        its drivers see (``MSLeaderInfo::getSubLanes``): SUMO's drivers would see the CAV
        wider than it is. (The position update is the same for both action steps.) The CAVs
        that move this step are
        the controlled ones of the last observation that move sideways with
        ``changeSublane`` but those in ``crossed`` (moved to another lane with ``moveTo``)."""
        at_dt = self._every_step
        ids = self._ids
        sublane = [ids[i] for i in np.flatnonzero(self._sublane).tolist()]
        if not sublane and not at_dt:
            return
        want = self.controlled.intersection(sublane).difference(crossed)
        keep = want | (at_dt - want - self._clearing)
        raw = getattr(self.ts, "_libsumo", None)
        set_asl = getattr(raw, "vehicle_setActionStepLength", None) \
            or self.ts.vehicle.setActionStepLength
        for vid in at_dt - keep:
            if vid in self.controlled:
                set_asl(vid, self.cav_action_step_s, True)
        for vid in keep - at_dt:
            set_asl(vid, self.dt, True)
        self._clearing = keep - want
        self._every_step = keep

    def _cross_lanes(self, ids: list, lanes: list, pos: np.ndarray, v_next: np.ndarray,
                     d_next: np.ndarray, lats: np.ndarray, moved: np.ndarray,
                     straddle: np.ndarray) -> list:
        """Move CAVs whose commanded centre ``d_next`` (m) lies on another lane of their
        edge onto that lane (``moveTo`` at their position now; SUMO keeps the speed and
        advances them in the step), and rewrite their lateral lane positions ``lats`` (m)
        in place, and take them out of ``moved`` (N,) (placed, not moved with changeSublane, in
        this step); returns their ids. A lateral lane position beyond the lane's border
        would leave the vehicle on its old lane in SUMO's eyes: drawn across the border,
        unseen by the drivers on the neighbouring lane, and stopped at the old lane's end.

        A CAV whose back is still on the lane before (``straddle`` (N,) bool: it has just
        crossed a joint) is not moved: ``moveTo`` would put its back on that lane at the new
        lane's lateral position (SUMO keeps one per lane the back occupies), metres away from
        where it is, and SUMO's junction collision check would see a body turned across the
        road (a user's 3 -> 2 lane drop: 20 degrees, a collision with the vehicle beside);
        it moves with ``changeSublane`` until its back has left the joint."""
        side = self._side_lanes
        crossed = []
        for i, lane in enumerate(lanes):
            spans = side.get(lane)
            if spans is None or straddle[i]:
                continue
            d = float(d_next[i])
            here = next(sp for sp in spans if sp[0] == lane)
            if here[1] <= d <= here[2]:
                continue
            target = min(spans, key=lambda sp: max(sp[1] - d, d - sp[2], 0.0))
            if target[0] == lane:
                continue
            p = min(float(pos[i]) * target[3] / here[3], target[3] - 1e-3)
            self.ts.vehicle.moveTo(ids[i], target[0], p)
            # placed with setLateralLanePosition in this step (changeSublane right after
            # moveTo does not land); from the next step on it moves with changeSublane
            moved[i] = False
            crossed.append(ids[i])
            lats[i] = self.net.lateral_lane_position(
                [target[0]], np.array([p + float(v_next[i]) * self.dt]), np.array([d]))[0]
        return crossed

    def _setters(self, veh):
        """``(setSpeed, setLateralLanePosition)``: libsumo's C functions when running
        libsumo, else the TraCI client's methods (sumo-gui)."""
        raw = getattr(self.ts, "_libsumo", None)
        fast = (getattr(raw, "vehicle_setSpeed", None),
                getattr(raw, "vehicle_setLateralLanePosition", None))
        if None in fast:
            return veh.setSpeed, veh.setLateralLanePosition
        return fast

    def collisions(self) -> list[tuple[str, str]]:
        """(collider, victim) pairs SUMO detected in the last step."""
        return [(c.collider, c.victim) for c in self.ts.simulation.getCollisions()]

    def teleports(self) -> int:
        """Vehicles SUMO teleported so far (``getStartingTeleportNumber`` counts one step's
        only: the world sums it every step)."""
        return self._teleports

    def pending(self) -> int:
        """Vehicles due to depart that SUMO could not insert yet."""
        return len(self.ts.simulation.getPendingVehicles())

    def add_obstacle(self, s_m: float, d_m: float, length_m: float, width_m: float) -> str:
        """Place a stopped vehicle (id "obstacle") with its centre at (s, d); returns its id."""
        ts = self.ts
        edge, pos = self.net.locate(s_m + 0.5 * length_m)
        type_id = "obstacle_t"
        ts.vehicletype.copy("DEFAULT_VEHTYPE", type_id)
        ts.vehicletype.setLength(type_id, length_m)
        ts.vehicletype.setWidth(type_id, width_m)
        ts.vehicletype.setMinGap(type_id, 0.0)
        lane = self._obstacle_lane(edge, d_m)
        ts.route.add("obstacle_route", [edge])
        ts.vehicle.add("obstacle", "obstacle_route", typeID=type_id, departPos=str(pos),
                       departSpeed="0", departLane=lane.rsplit("_", 1)[1])
        ts.vehicle.setSpeedMode("obstacle", 0)
        ts.vehicle.setLaneChangeMode("obstacle", 0)
        ts.vehicle.setSpeed("obstacle", 0.0)
        self._obstacle = (lane, pos, d_m)
        self.obstacle_id = "obstacle"
        return "obstacle"

    def _obstacle_lane(self, edge: str, d_m: float) -> str:
        """The lane of ``edge`` whose centre is nearest to ``d_m`` (the road frame's d, m):
        lane 0 of a one-lane road; on three lanes, the lane the obstacle stands in."""
        lanes = [x for x in self.net.lane_d if x.rsplit("_", 1)[0] == edge]
        if not lanes:
            return f"{edge}_0"
        return min(lanes, key=lambda x: abs(self.net.lane_d[x] - d_m))

    def _hold_obstacle(self) -> None:
        """Keep the obstacle vehicle in place (every step after it departed)."""
        if self._obstacle is None:
            return
        if "obstacle" in self.types:
            lane, pos, d_m = self._obstacle
            self.ts.vehicle.setSpeed("obstacle", 0.0)
            self.ts.vehicle.setLateralLanePosition("obstacle", d_m - self.net.lane_d.get(lane, 0))
