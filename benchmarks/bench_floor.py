"""What reaching SUMO costs: the libsumo floor of a lane-free co-simulation, and its parts.

Case (issue 15): straight 2 km x 10.2 m road, 8 000 veh/h, 100 % CAVs, 300 s, step
0.1 s, lateral resolution 0.8 m, SUMO's collision check on (``--collision.action
warn``), network and routes from the project's own code, seed 3. Every variant is a
separate process (libsumo holds one simulation per process); the variants run in
interleaved rounds (the order rotates every round) and the ratios are medians of
per-round ratios, so the load of the shared machine cancels as far as it can.

Variants (libsumo ones drive it directly, no cosim code in the child):

* ``a``  the ``sumo`` binary, SUMO (SL2015) drives everyone;
* ``b``  libsumo, SUMO drives everyone, no subscriptions;
* ``c``  (b) + subscribe lane id, lane position, lateral lane position, speed, lateral
         speed at departure and read them every step into Python tuples; ``c.4``: the
         same without the lateral speed (a CAV's is integrated by the loop anyway);
* ``d``  (c) + take every CAV over at departure (setSpeedMode 0, setLaneChangeMode 0) and
         hold its departure speed with one ``setSpeed`` (kept by SUMO until the next one),
         so that (d) to (h) carry the same traffic; ``d.free``: no command at all (the
         CAVs then ignore the speed limit and accelerate to their vType's maxSpeed,
         60 m/s: fewer vehicles on the road, so its step is cheaper for that reason);
* ``e``  the floor: (d) + ``setSpeed`` + ``setLateralLanePosition`` for every CAV every
         step, holding speed and lateral position; ``e.v`` / ``e.lat``: one of the two;
* ``f.*`` another longitudinal command instead of ``setSpeed`` (``slowDown(v, dt)``,
         ``setAcceleration(a, dt)``, ``setPreviousSpeed(v)``), ``moveTo`` (a 0 m jump on
         top of (e), its call cost), ``moveToXY`` alone (front position after the step,
         both axes in one call; not in the last 0.5 m of the road, where it would pin the
         vehicle to the lane's end) and ``setSpeed`` + ``moveToXY``;
* ``g.all`` / ``g.skip`` a realistic command pattern (half of the CAVs hold their
         lateral position, half hold their speed, independently; the others change
         both every step), with every setter called every step, or a setter skipped
         when its value did not change (speed equal to the last ``setSpeed`` of that
         vehicle; |d_next - d| <= 1e-6 m);
* ``e.asl`` the floor with the take-over of ``cosim`` (``scenario.cav_action_step_s`` = 1 s):
         the CAVs' SUMO action step is 1 s (SUMO runs their lane changer and car-following
         plan once a second instead of every step), the same ``setSpeed`` +
         ``setLateralLanePosition``; SUMO's Euler update is kept by
         ``--step-method.ballistic false`` (every variant passes it, as the runner does:
         without it SUMO switches every vehicle to the ballistic update, moving one by
         ``(v + v_next) dt / 2``, once any has a longer action step; the exactness runs
         show ``setSpeed`` exact with both action steps);
* ``h.*`` the floor (e) at lateral resolution 0.4 / 0.8 / 1.6 m, on 100 m edges (the
         default, ``network.max_edge_length_m = 100``) and on one 2 km edge (0);
         ``e.nocoll``: (e) with SUMO's collision check off (the sweeps' setting).

CPU s: process CPU time inside the child from ``libsumo.start`` to ``close`` (loading the
network and routes included, Python's start and imports not; ``proc s`` is the whole
child process); for ``a`` the whole ``sumo`` process (getrusage of the child).

Then, once (not timed in rounds):

* per-call costs: every setter called R times on every vehicle of a full road with no
  step in between (interleaved), in microseconds, the call alone; the libsumo Python
  wrapper against ``_libsumo`` directly; a getter and a Python no-op for scale;
* exactness: 300 steps with varying commands (acceleration 1 m/s^2 sine, lateral speed
  0.15 m/s sine, every CAV every step); the lane position, speed and lateral position
  after each step are compared with ``s + v_next dt``, ``v_next``, ``d_next``
  (s from the road frame's lane offsets, so edge joints count too).

Usage::

    .venv/bin/python benchmarks/bench_floor.py              # 300 s, 3 rounds: about 6 min
    .venv/bin/python benchmarks/bench_floor.py --quick      # 60 s, 1 round: < 1 min
    .venv/bin/python benchmarks/bench_floor.py --rounds 5 --duration 120
    .venv/bin/python benchmarks/bench_floor.py --only a,d,e,g.all,g.skip
"""

from __future__ import annotations

import argparse
import inspect
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SEED = 3
STEP_S = 0.1
INFLOW_VPH = 8000.0
LENGTH_M = 2000.0
WIDTH_M = 10.2
BASE_RES_M = 0.8
LAT_TOL_M = 1e-6  # g.skip: setLateralLanePosition only when d moves by more than this
EXACT_HORIZON_S = 40.0  # exactness runs: 40 s, checked over the last 30 s (300 steps)
EXACT_FROM_S = 10.0
CALL_REPS = 40  # per-call micro-benchmark: repetitions over all vehicles, per method
CALL_WARMUP_S = 100.0  # ... after this much SUMO-driven time (the road is full by ~70 s)

# name -> (description, child settings). Settings: sub (subscribe + read), take (take
# CAVs over), lon (longitudinal command), lat (lateral command), xy (moveToXY), jump
# (moveTo by 0 m), pattern (hold | realistic), skip, check (exactness check), res (lateral
# resolution m), edge (max edge length m), coll (--collision.action).
BASE = {"sub": False, "take": False, "lon": None, "lat": False, "xy": False, "jump": False,
        "pattern": "hold", "skip": False, "check": False, "res": BASE_RES_M, "edge": 100.0,
        "coll": "warn"}


def _v(**kw) -> dict:
    return {**BASE, **kw}


FLOOR = {"sub": True, "take": True, "lon": "setSpeed", "lat": True}
VARIANTS: dict[str, tuple[str, dict]] = {
    "a": ("sumo binary, SUMO drives everyone", {}),
    "b": ("libsumo, SUMO drives everyone", _v()),
    "c": ("(b) + subscribe 5 variables, read", _v(sub=True)),
    "c.4": ("(c) without the lateral speed (4 variables)", _v(sub=True, nvars=4)),
    "d.free": ("(c) + take CAVs over, no command at all", _v(sub=True, take=True,
                                                              hold0=False)),
    "d": ("(c) + take over, setSpeed once", _v(sub=True, take=True)),
    "e": ("floor: (d) + setSpeed + setLatLanePos", _v(**FLOOR)),
    "e.v": ("(d) + setSpeed only", _v(sub=True, take=True, lon="setSpeed")),
    "e.lat": ("(d) + setLateralLanePosition only", _v(sub=True, take=True, lat=True)),
    "f.slowDown": ("(d) + slowDown(v, dt) + setLatLanePos",
                   _v(**{**FLOOR, "lon": "slowDown"})),
    "f.setAcceleration": ("(d) + setAcceleration(a, dt) + setLatLanePos",
                          _v(**{**FLOOR, "lon": "setAcceleration"})),
    "f.setPreviousSpeed": ("(d) + setPreviousSpeed(v) + setLatLanePos",
                           _v(**{**FLOOR, "lon": "setPreviousSpeed"})),
    "f.moveTo": ("(e) + moveTo(lane, pos) (0 m jump)", _v(**FLOOR, jump=True)),
    "f.moveToXY": ("(d) + moveToXY alone (both axes)", _v(sub=True, take=True, xy=True)),
    "f.setSpeed+XY": ("(d) + setSpeed + moveToXY",
                      _v(sub=True, take=True, lon="setSpeed", xy=True)),
    "g.all": ("realistic commands, all setters", _v(**FLOOR, pattern="realistic", check=True)),
    "g.skip": ("realistic commands, skip unchanged",
               _v(**FLOOR, pattern="realistic", skip=True, check=True)),
    "h.0.4/100m": ("(e) at 0.4 m, 100 m edges", _v(**FLOOR, res=0.4)),
    "h.1.6/100m": ("(e) at 1.6 m, 100 m edges", _v(**FLOOR, res=1.6)),
    "h.0.4/2km": ("(e) at 0.4 m, one 2 km edge", _v(**FLOOR, res=0.4, edge=0.0)),
    "h.0.8/2km": ("(e) at 0.8 m, one 2 km edge", _v(**FLOOR, res=0.8, edge=0.0)),
    "h.1.6/2km": ("(e) at 1.6 m, one 2 km edge", _v(**FLOOR, res=1.6, edge=0.0)),
    "e.nocoll": ("(e) with --collision.action none", _v(**FLOOR, coll="none")),
    "e.asl": ("(e), CAV action step 1 s", _v(**FLOOR, asl=1.0)),
}

# Exactness runs: name -> child settings (pattern "exact": every CAV varies speed and d).
EXACT: dict[str, dict] = {
    "setSpeed": _v(**FLOOR),
    "setSpeed, action step 1 s": _v(**FLOOR, asl=1.0),
    "setPreviousSpeed + setSpeed, 1 s": _v(**{**FLOOR, "lon": "prev+setSpeed"}, asl=1.0),
    "slowDown(v, dt)": _v(**{**FLOOR, "lon": "slowDown"}),
    "setAcceleration(a, dt)": _v(**{**FLOOR, "lon": "setAcceleration"}),
    "setPreviousSpeed(v)": _v(**{**FLOOR, "lon": "setPreviousSpeed"}),
    "moveTo(s + v dt) + setLat": _v(sub=True, take=True, lat=True, jump=True),
    "moveToXY alone": _v(sub=True, take=True, xy=True),
    "setSpeed + moveToXY": _v(sub=True, take=True, lon="setSpeed", xy=True),
}

# ======================================================================================
# Child process (imports libsumo only: no numpy, no cosim)
# ======================================================================================


def _phase(ordinal: int) -> float:
    return 0.7 * ordinal


def child_run(p: dict) -> dict:
    """One libsumo run of a variant; returns CPU times (s), call counts and errors (m)."""
    import libsumo as ls

    clock = time.process_time
    V = (ls.VAR_LANE_ID, ls.VAR_LANEPOSITION, ls.VAR_LANEPOSITION_LAT, ls.VAR_SPEED,
         ls.VAR_SPEED_LAT)
    iL, iP, iD, iV, iVL = V
    if p.get("nvars", 5) == 4:
        V = V[:4]
        iVL = iV
    dt = p["dt"]
    n_steps = int(round(p["duration"] / dt))
    offsets: dict = p["offsets"]
    check_from = int(round(p.get("check_from", 0.0) / dt))
    sub, take, lon, lat = p["sub"], p["take"], p["lon"], p["lat"]
    xy, jump, pattern, skip, check = p["xy"], p["jump"], p["pattern"], p["skip"], p["check"]
    cmd_any = bool(lon or lat or xy or jump)
    two_pi = 2.0 * math.pi
    lat_lim = 0.5 * WIDTH_M - 1.0
    x_end = p["road_length"] - 0.5  # moveToXY onto the last lane's end would keep the
    # vehicle there for ever (it never arrives): leave the last 0.5 m to SUMO
    T = {k: 0.0 for k in ("step", "take", "read", "cmd", "lon", "lat", "xy", "jump", "check")}
    calls = {"lon": 0, "lat": 0, "xy": 0, "jump": 0, "lon_skip": 0, "lat_skip": 0}
    err = {"s": 0.0, "v": 0.0, "d": 0.0, "n": 0}

    c0, w0 = clock(), time.perf_counter()
    ls.start(p["cmd"])
    veh, sim, step = ls.vehicle, ls.simulation, ls.simulationStep
    asl = p.get("asl")  # action step (s) of the CAVs taken over (None: one step)
    if offsets:  # a main edge: check that x = s (front) and y = d on this road
        e0 = next(iter(offsets))
        x0, y0 = sim.convert2D(e0, 10.0, 0)
        if abs(x0 - (offsets[e0] + 10.0)) > 1e-6 or abs(y0) > 1e-6:
            raise RuntimeError(f"road frame is not x = s, y = d: {x0, y0}")
    # from step ``from_step`` on, the times and vehicle-steps are also kept apart (after)
    from_step = int(p.get("from_step", 0))
    after: dict = {}
    setSpeed, setLat = veh.setSpeed, veh.setLateralLanePosition
    slowDown, setAcc, setPrev = veh.slowDown, veh.setAcceleration, veh.setPreviousSpeed
    moveTo, moveToXY = veh.moveTo, veh.moveToXY
    angle = ls.INVALID_DOUBLE_VALUE
    subscribe, setSM, setLCM, getType, getSpeed = (
        veh.subscribe, veh.setSpeedMode, veh.setLaneChangeMode, veh.getTypeID, veh.getSpeed)
    hold0 = pattern == "hold" and p.get("hold0", True)
    ctrl: dict[str, int] = {}  # taken-over CAVs -> departure ordinal
    last_v: dict[str, float] = {}  # last setSpeed per vehicle (g.skip)
    expect: dict[str, tuple] = {}
    n_ord = 0
    veh_steps = 0
    cav_steps = 0
    for k in range(n_steps):
        if k == from_step:
            after = {"T": dict(T), "veh_steps": veh_steps, "cpu_s": clock()}
        t0 = clock()
        step()
        if sub:
            dep = sim.getDepartedIDList()
            for vid in dep:
                subscribe(vid, V)
        t1 = clock()
        T["step"] += t1 - t0
        if not sub:
            veh_steps += veh.getIDCount()
            continue
        if take:
            for vid in dep:
                if getType(vid).startswith("cav"):
                    setSM(vid, 0)
                    setLCM(vid, 0)
                    if asl:
                        veh.setActionStepLength(vid, asl, True)
                    if hold0:  # keep the departure speed (held until the next setSpeed)
                        setSpeed(vid, getSpeed(vid))
                    ctrl[vid] = n_ord
                n_ord += 1
            for vid in sim.getArrivedIDList():
                ctrl.pop(vid, None)
                last_v.pop(vid, None)
            t2 = clock()
            T["take"] += t2 - t1
            t1 = t2
        res = veh.getAllSubscriptionResults()
        rows = [(vid, r[iL], r[iP], r[iD], r[iV], r[iVL]) for vid, r in res.items()]
        t2 = clock()
        T["read"] += t2 - t1
        veh_steps += len(rows)
        if not take:
            continue
        cav = [r for r in rows if r[0] in ctrl]
        cav_steps += len(cav)
        if check:
            t3 = clock()
            if k >= check_from:
                es, ev, ed, n = err["s"], err["v"], err["d"], err["n"]
                for vid, lane, pos, d, v, _ in cav:
                    x = expect.get(vid)
                    off = offsets.get(lane)
                    if x is None or off is None or x[0] is None:
                        continue
                    es = max(es, abs(off + pos - x[0]))
                    ev = max(ev, abs(v - x[1]))
                    ed = max(ed, abs(d - x[2]))
                    n += 1
                err.update(s=es, v=ev, d=ed, n=n)
            expect.clear()
            T["check"] += clock() - t3
        if not cmd_any:
            continue
        # commands (v_next m/s, d_next m) per CAV
        t3 = clock()
        t = (k + 1) * dt
        if pattern == "hold":
            cmds = [(vid, lane, pos, d, v, v, d) for vid, lane, pos, d, v, _ in cav]
        else:
            cmds = []
            exact = pattern == "exact"
            for vid, lane, pos, d, v, _ in cav:
                o = ctrl[vid]
                ph = _phase(o)
                if exact or o % 4 >= 2:  # realistic: half of the CAVs hold their speed
                    a = (1.0 if exact else 0.5) * math.sin(two_pi * t / 6.0 + ph)
                    vn = max(0.0, v + a * dt)
                else:
                    vn = last_v.get(vid, v)
                if exact or o % 2 == 1:  # realistic: half hold their lateral position
                    vl = 0.15 * math.sin(two_pi * t / 8.0 + ph)
                    dn = min(lat_lim, max(-lat_lim, d + vl * dt))
                else:
                    dn = d
                cmds.append((vid, lane, pos, d, v, vn, dn))
        if check:
            for vid, lane, pos, _, _, vn, dn in cmds:
                off = offsets.get(lane)
                expect[vid] = (None if off is None else off + pos + vn * dt, vn, dn)
        t4 = clock()
        T["cmd"] += t4 - t3
        if lon == "setSpeed":
            if skip:
                n0 = len(cmds)
                for vid, _, _, _, _, vn, _ in cmds:
                    if last_v.get(vid) != vn:
                        setSpeed(vid, vn)
                        last_v[vid] = vn
                    else:
                        n0 -= 1
                calls["lon"] += n0
                calls["lon_skip"] += len(cmds) - n0
            else:
                for vid, _, _, _, _, vn, _ in cmds:
                    setSpeed(vid, vn)
                if pattern != "hold":
                    for vid, _, _, _, _, vn, _ in cmds:
                        last_v[vid] = vn
                calls["lon"] += len(cmds)
        elif lon == "prev+setSpeed":  # this step's speed too: (v + v_next) / 2 = v_next
            for vid, _, _, _, _, vn, _ in cmds:
                setPrev(vid, vn)
                setSpeed(vid, vn)
            calls["lon"] += 2 * len(cmds)
        elif lon == "slowDown":
            for vid, _, _, _, _, vn, _ in cmds:
                slowDown(vid, vn, dt)
            calls["lon"] += len(cmds)
        elif lon == "setAcceleration":
            for vid, _, _, _, v, vn, _ in cmds:
                setAcc(vid, (vn - v) / dt, dt)
            calls["lon"] += len(cmds)
        elif lon == "setPreviousSpeed":
            for vid, _, _, _, _, vn, _ in cmds:
                setPrev(vid, vn)
            calls["lon"] += len(cmds)
        t5 = clock()
        T["lon"] += t5 - t4
        if lat:
            if skip:
                n0 = 0
                for vid, _, _, d, _, _, dn in cmds:
                    if abs(dn - d) > LAT_TOL_M:
                        setLat(vid, dn)
                        n0 += 1
                calls["lat"] += n0
                calls["lat_skip"] += len(cmds) - n0
            else:
                for vid, _, _, _, _, _, dn in cmds:
                    setLat(vid, dn)
                calls["lat"] += len(cmds)
        t6 = clock()
        T["lat"] += t6 - t5
        if jump:  # hold: a 0 m jump (cost only); exact: the position after the step
            n0 = 0
            for vid, lane, pos, _, _, vn, _ in cmds:
                if lane[0] == ":":
                    continue
                target = pos if pattern == "hold" else pos + vn * dt
                if target < lane_length(ls, lane):
                    moveTo(vid, lane, target)
                    n0 += 1
                elif check:
                    expect.pop(vid, None)
            calls["jump"] += n0
        t7 = clock()
        T["jump"] += t7 - t6
        if xy:  # front position after the step; y = d on this road (checked above)
            n0 = 0
            for vid, lane, pos, _, _, vn, dn in cmds:
                off = offsets.get(lane)
                if off is None:
                    continue
                x = off + pos + vn * dt
                if x < x_end:
                    moveToXY(vid, "", 0, x, dn, angle, 1)
                    n0 += 1
                elif check:  # beyond the road's end: SUMO moves it off with its own speed
                    expect.pop(vid, None)
            calls["xy"] += n0
        T["xy"] += clock() - t7
    c1 = clock()
    ls.close()
    out = {"cpu_s": clock() - c0, "wall_s": time.perf_counter() - w0, "T": T,
           "calls": calls, "err": err, "veh_steps": veh_steps, "cav_steps": cav_steps}
    if after:  # the steps from from_step on (SUMO's start and close left out)
        out["after"] = {"T": {k: T[k] - after["T"][k] for k in T},
                        "veh_steps": veh_steps - after["veh_steps"],
                        "cpu_s": c1 - after["cpu_s"]}
    return out


_LANE_LEN: dict[str, float] = {}


def lane_length(ls, lane: str) -> float:
    x = _LANE_LEN.get(lane)
    if x is None:
        x = _LANE_LEN[lane] = ls.lane.getLength(lane)
    return x


def child_calls(p: dict) -> dict:
    """Cost of one call of each setter (us), on every vehicle of a full road, no step."""
    import libsumo as ls
    from libsumo import _libsumo  # the extension module under libsumo's Python wrappers

    clock = time.process_time
    V = (ls.VAR_LANE_ID, ls.VAR_LANEPOSITION, ls.VAR_LANEPOSITION_LAT, ls.VAR_SPEED)
    ls.start(p["cmd"])
    n_steps = int(round(p["warmup"] / p["dt"]))
    for _ in range(n_steps):
        ls.simulationStep()
        for vid in ls.simulation.getDepartedIDList():
            ls.vehicle.subscribe(vid, V)
    offsets = p["offsets"]
    veh = ls.vehicle
    res = veh.getAllSubscriptionResults()
    rows = [(vid, r[V[0]], r[V[1]], r[V[2]], r[V[3]]) for vid, r in res.items()
            if r[V[0]] in offsets and r[V[0]][0] != ":"]
    for vid, *_ in rows:
        veh.setSpeedMode(vid, 0)
        veh.setLaneChangeMode(vid, 0)
    dt = p["dt"]
    angle = ls.INVALID_DOUBLE_VALUE

    def noop(*args):
        return None

    methods = {
        "setSpeed": lambda: [veh.setSpeed(i, v) for i, _, _, _, v in rows],
        "setSpeed (_libsumo direct)": (
            lambda f=_libsumo.vehicle_setSpeed: [f(i, v) for i, _, _, _, v in rows]),
        "setLateralLanePosition": lambda: [veh.setLateralLanePosition(i, d)
                                           for i, _, _, d, _ in rows],
        "setLateralLanePosition (_libsumo)": (
            lambda f=_libsumo.vehicle_setLateralLanePosition: [f(i, d) for i, _, _, d, _ in rows]),
        "slowDown(v, dt)": lambda: [veh.slowDown(i, v, dt) for i, _, _, _, v in rows],
        "setAcceleration(a, dt)": lambda: [veh.setAcceleration(i, 0.0, dt) for i, *_ in rows],
        "setPreviousSpeed(v)": lambda: [veh.setPreviousSpeed(i, v) for i, _, _, _, v in rows],
        "moveTo(lane, pos)": lambda: [veh.moveTo(i, ln, pos) for i, ln, pos, _, _ in rows],
        "moveToXY (request only)": lambda: [
            veh.moveToXY(i, "", 0, offsets[ln] + pos + v * dt, d, angle, 1)
            for i, ln, pos, d, v in rows],
        "getSpeed (getter, for scale)": lambda: [veh.getSpeed(i) for i, *_ in rows],
        "Python no-op f(id, v)": lambda: [noop(i, v) for i, _, _, _, v in rows],
    }
    names = list(methods)
    tot = {m: 0.0 for m in names}
    for rep in range(p["reps"]):
        order = names[rep % len(names):] + names[:rep % len(names)]
        for m in order:
            t0 = clock()
            methods[m]()
            tot[m] += clock() - t0
    ls.close()
    n = p["reps"] * len(rows)
    return {"us_per_call": {m: 1e6 * tot[m] / n for m in names}, "vehicles": len(rows),
            "calls": n}


# ======================================================================================
# Parent
# ======================================================================================


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_child(payload: dict) -> dict:
    """Run ``payload`` in a fresh Python process; adds its whole-process CPU (s)."""
    c0, w0 = _children_cpu(), time.perf_counter()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(payload)],
        capture_output=True, text=True, check=False, timeout=3600, env=env,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"child failed:\n{proc.stderr[-4000:]}")
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    out = json.loads(line[len("RESULT "):])
    out["proc_s"] = _children_cpu() - c0
    out["proc_wall_s"] = time.perf_counter() - w0
    return out


def run_binary(cmd: list[str]) -> dict:
    c0, w0 = _children_cpu(), time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=3600)
    if proc.returncode != 0:
        raise RuntimeError(f"sumo failed:\n{proc.stderr[-3000:]}")
    cpu = _children_cpu() - c0
    return {"cpu_s": cpu, "proc_s": cpu, "wall_s": time.perf_counter() - w0}


class Case:
    """Networks, route files and SUMO commands of the benchmark case (built once)."""

    def __init__(self, work: Path, duration_s: float) -> None:
        from cosim.demand.routes import write_routes
        from cosim.demand.spec import DemandSpec
        from cosim.road import NetworkSpec, build_network
        from cosim.sumo.binaries import sumo_binary

        self.duration_s = duration_s
        self.sumo = str(sumo_binary())
        self.nets, self.routes = {}, {}
        for edge in (100.0, 0.0):
            net = build_network(NetworkSpec(kind="straight", length_m=LENGTH_M, width_m=WIDTH_M,
                                            max_edge_length_m=edge))
            self.nets[edge] = net
            horizon = max(duration_s, EXACT_HORIZON_S, CALL_WARMUP_S)
            path = work / f"routes_{edge:g}.rou.xml"
            if "horizon_s" in inspect.signature(write_routes).parameters:  # new demand API
                demand = DemandSpec(inflow_vph=INFLOW_VPH, cav_share=1.0)
                info = write_routes(net, demand, SEED, path, horizon_s=horizon)
            else:  # the demand horizon in DemandSpec (up to commit 68b0fc8)
                demand = DemandSpec(inflow_vph=INFLOW_VPH, cav_share=1.0, duration_s=horizon)
                info = write_routes(net, demand, SEED, path)
            self.routes[edge] = info
        self.n_vehicles = self.routes[100.0].n_cav + self.routes[100.0].n_hdv

    def cmd(self, edge: float, res: float, duration_s: float, coll: str = "warn") -> list[str]:
        """The runner's SUMO arguments (cosim/sim/runner.py ``_run_in``), detectors off."""
        net = self.nets[edge]
        return [self.sumo, "-n", str(net.net_file), "-r", str(self.routes[edge].path),
                "--step-length", str(STEP_S), "--collision.action", coll,
                "--collision.mingap-factor", "0", "--seed", str(SEED), "--begin", "0",
                "--end", str(duration_s), "--no-step-log", "true", "--no-warnings", "true",
                "--duration-log.disable", "true", "--lateral-resolution", str(res),
                "--step-method.ballistic", "false"]

    def offsets(self, edge: float) -> dict:
        """Road-frame s of position 0 of every lane on the main route (edges too, first)."""
        net = self.nets[edge]
        first = {e: net.lane_offsets[e] for e in net.main_route}
        return {**first, **{k: float(v) for k, v in net.lane_offsets.items()}}

    def payload(self, settings: dict, duration_s: float, **extra) -> dict:
        return {"mode": "run", **settings, "dt": STEP_S, "duration": duration_s,
                "cmd": self.cmd(settings["edge"], settings["res"], duration_s, settings["coll"]),
                "offsets": self.offsets(settings["edge"]),
                "road_length": self.nets[settings["edge"]].length_m, **extra}


def run_variant(case: Case, name: str) -> dict:
    if name == "a":
        return run_binary(case.cmd(100.0, BASE_RES_M, case.duration_s))
    return run_child(case.payload(VARIANTS[name][1], case.duration_s))


def _med(xs) -> float:
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return statistics.median(xs) if xs else float("nan")


def _ratio(res: dict, num: str, den: str) -> float:
    if num not in res or den not in res:
        return float("nan")
    return _med([a["cpu_s"] / b["cpu_s"] for a, b in zip(res[num], res[den], strict=False)])


def _diff(res: dict, num: str, den: str) -> float:
    """Median over rounds of the CPU difference num - den (s)."""
    if num not in res or den not in res:
        return float("nan")
    return _med([a["cpu_s"] - b["cpu_s"] for a, b in zip(res[num], res[den], strict=False)])


def print_main(res: dict, names: list[str]) -> None:
    print(f"\n{'variant':<19}{'what':<46}{'CPU s':>7}{'/ a':>7}{'/ e':>7}{'proc s':>8}"
          f"{'veh-steps':>10}{'us/veh-step':>12}")
    print("-" * 116)
    for n in names:
        rows = res[n]
        cpu = _med([r["cpu_s"] for r in rows])
        same = res.get("b") or res.get("c") or []  # (a) carries the traffic of (b) and (c)
        vs = _med([r.get("veh_steps") for r in (rows if n != "a" else same)])
        us = 1e6 * cpu / vs if vs and math.isfinite(vs) else float("nan")
        print(f"{n:<19}{VARIANTS[n][0]:<46}{cpu:7.2f}{_ratio(res, n, 'a'):7.2f}"
              f"{_ratio(res, n, 'e'):7.2f}{_med([r['proc_s'] for r in rows]):8.2f}"
              f"{vs:10.0f}{us:12.2f}")


def print_split(res: dict, names: list[str]) -> None:
    """Where the CPU of each libsumo variant goes (medians, s) and the setters per call."""
    print("\nSplit of the libsumo variants (CPU s, medians over rounds; us/call = the loop's "
          "own timing of its setter calls)")
    hdr = ("step", "take", "read", "cmd", "lon", "lat", "jump", "xy", "check")
    print(f"{'variant':<19}" + "".join(f"{h:>7}" for h in hdr) + f"{'other':>7}"
          f"{'lon us':>8}{'lat us':>8}{'xy us':>8}{'jump us':>8}")
    for n in names:
        if n == "a":
            continue
        rows = res[n]
        vals = [_med([r["T"][h] for r in rows]) for h in hdr]
        other = _med([r["cpu_s"] - sum(r["T"].values()) for r in rows])

        def per(key: str, col: str, rows: list = rows) -> str:
            c = _med([r["calls"][col] for r in rows])
            return f"{1e6 * _med([r['T'][key] for r in rows]) / c:8.2f}" if c else f"{'':>8}"

        print(f"{n:<19}" + "".join(f"{v:7.2f}" for v in vals) + f"{other:7.2f}"
              + per("lon", "lon") + per("lat", "lat") + per("xy", "xy") + per("jump", "jump"))


def print_calls(res: dict, micro: dict, exact: dict) -> None:
    """Per-call cost (call alone; in the run with SUMO's step effects) and exactness."""
    print(f"\nPer call, microseconds: 'call' = the call alone ({micro['calls']} calls each on "
          f"{micro['vehicles']} vehicles of a full road, no step between)")
    for m, us in micro["us_per_call"].items():
        print(f"  {m:<36}{us:8.2f}")

    def marg(num: str, den: str, key: str) -> float:
        """(CPU num - CPU den) / calls (us): the call with its effect on SUMO's step."""
        c = _med([r["calls"][key] for r in res.get(num, [])])
        return 1e6 * _diff(res, num, den) / c if c else float("nan")

    print("\nIn the run, microseconds per call including what it adds to SUMO's step "
          "(median over rounds of CPU differences / calls):")
    rows = [
        ("setSpeed", marg("e.v", "d", "lon"), "(e.v - d)"),
        ("setLateralLanePosition", marg("e.lat", "d", "lat"), "(e.lat - d)"),
        ("setSpeed + setLatLanePos (per CAV-step)", marg("e", "d", "lon"), "(e - d)"),
        ("slowDown(v, dt) + setLatLanePos", marg("f.slowDown", "d", "lon"), "(f - d)"),
        ("setAcceleration(a, dt) + setLatLanePos", marg("f.setAcceleration", "d", "lon"),
         "(f - d)"),
        ("setPreviousSpeed(v) + setLatLanePos", marg("f.setPreviousSpeed", "d", "lon"),
         "(f - d)"),
        ("moveTo (0 m jump, on top of e)", marg("f.moveTo", "e", "jump"), "(f - e)"),
        ("moveToXY alone (both axes)", marg("f.moveToXY", "d", "xy"), "(f - d)"),
        ("setSpeed + moveToXY", marg("f.setSpeed+XY", "d", "xy"), "(f - d)"),
    ]
    for label, us, how in rows:
        print(f"  {label:<42}{us:8.2f}  {how}")

    print("\nExactness: commanding v_next and d_next, then one step (max over "
          "vehicle-steps; s from lane offsets, so ~1e-13 m is float rounding):")
    print(f"  {'command':<30}{'veh-steps':>10}{'max |ds| m':>13}{'max |dv| m/s':>14}"
          f"{'max |dd| m':>12}  exact?")
    for m, r in exact.items():
        e = r["err"]
        ok = e["s"] < 1e-9 and e["v"] < 1e-9 and e["d"] < 1e-9
        pos_ok = e["s"] < 1e-9 and e["d"] < 1e-9
        verdict = "yes" if ok else ("position yes, speed no" if pos_ok else "no")
        print(f"  {m:<30}{e['n']:>10}{e['s']:13.3g}{e['v']:14.3g}{e['d']:12.3g}  {verdict}")


def print_skip(res: dict) -> None:
    if "g.all" not in res or "g.skip" not in res:
        return
    print("\nSkipping unchanged setters (realistic pattern: half of the CAVs hold d, half "
          "hold v, independently):")
    for n in ("g.all", "g.skip"):
        rows = res[n]
        c = {k: _med([r["calls"][k] for r in rows]) for k in rows[0]["calls"]}
        e = rows[0]["err"]
        print(f"  {n:<8} CPU {_med([r['cpu_s'] for r in rows]):6.2f} s  setSpeed {c['lon']:8.0f} "
              f"calls ({c['lon_skip']:.0f} skipped)  setLat {c['lat']:8.0f} calls "
              f"({c['lat_skip']:.0f} skipped)  setter CPU "
              f"{_med([r['T']['lon'] + r['T']['lat'] for r in rows]):5.2f} s  "
              f"max |ds| {e['s']:.2g} m, |dv| {e['v']:.2g} m/s, |dd| {e['d']:.2g} m "
              f"over {e['n']} CAV-steps")
    print(f"  g.skip / g.all = {_ratio(res, 'g.skip', 'g.all'):.3f} (CPU, median of per-round "
          f"ratios); saved {-_diff(res, 'g.skip', 'g.all'):.2f} s")


def print_sublane(res: dict) -> None:
    names = [("0.4", "100m", "h.0.4/100m"), ("0.8", "100m", "e"), ("1.6", "100m", "h.1.6/100m"),
             ("0.4", "2km", "h.0.4/2km"), ("0.8", "2km", "h.0.8/2km"),
             ("1.6", "2km", "h.1.6/2km")]
    names = [x for x in names if x[2] in res]
    if len(names) < 2:
        return
    print("\nSublane model in the floor (e): lateral resolution x edge length")
    print(f"  {'res m':>6}{'edges':>7}{'CPU s':>8}{'/ e':>7}{'SUMO step s':>13}")
    for r, e, n in names:
        print(f"  {r:>6}{e:>7}{_med([x['cpu_s'] for x in res[n]]):8.2f}{_ratio(res, n, 'e'):7.2f}"
              f"{_med([x['T']['step'] for x in res[n]]):13.2f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="60 s horizon, 1 round (CI, < 1 min)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 3)")
    ap.add_argument("--duration", type=float, default=None, help="horizon, s (default 300)")
    ap.add_argument("--only", default=None,
                    help="comma list of variants (a, d and e are always run: ratios need them)")
    ap.add_argument("--no-extras", action="store_true",
                    help="skip the per-call micro-benchmark and the exactness runs")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ns = ap.parse_args(argv)
    if ns.child is not None:
        p = json.loads(ns.child)
        out = child_calls(p) if p["mode"] == "calls" else child_run(p)
        print("RESULT " + json.dumps(out))
        return 0
    sys.path.insert(0, str(ROOT))
    from cosim.cli.errors import run_command

    return run_command(bench, ns)


def bench(ns) -> int:
    from cosim.errors import ConfigError

    rounds = ns.rounds if ns.rounds is not None else (1 if ns.quick else 3)
    duration = ns.duration if ns.duration is not None else (60.0 if ns.quick else 300.0)
    if rounds < 1:
        raise ConfigError(f"--rounds must be at least 1, got {rounds}")
    if not math.isfinite(duration) or duration < 10.0 * STEP_S:
        raise ConfigError(f"--duration must be at least {10 * STEP_S:g} s, got {duration:g}")
    names = list(VARIANTS)
    if ns.only:
        want = [x.strip() for x in ns.only.split(",") if x.strip()]
        bad = [x for x in want if x not in VARIANTS]
        if bad:
            raise ConfigError(f"unknown variant(s) {', '.join(bad)}; known: {', '.join(names)}")
        names = [n for n in names if n in set(want) | {"a", "d", "e"}]

    from cosim.sumo.binaries import sumo_version

    t_start = time.perf_counter()
    print(f"bench_floor: {LENGTH_M:g} m x {WIDTH_M:g} m straight road, {INFLOW_VPH:g} veh/h, "
          f"100 % CAVs, {duration:g} s, step {STEP_S:g} s, lateral resolution {BASE_RES_M:g} m "
          f"(h: 0.4-1.6), collision.action warn, seed {SEED}; {rounds} interleaved round(s); "
          f"SUMO {sumo_version()}, Python {sys.version.split()[0]}; {os.cpu_count()} CPUs, "
          f"load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory(prefix="bench_floor_") as tmp:
        case = Case(Path(tmp), duration)
        res: dict[str, list[dict]] = {n: [] for n in names}
        for r in range(rounds):
            order = names[r % len(names):] + names[:r % len(names)]
            for n in order:
                res[n].append(run_variant(case, n))
            print(f"  round {r + 1}/{rounds} done ({time.perf_counter() - t_start:.0f} s, "
                  f"load {os.getloadavg()[0]:.1f})", flush=True)
        print_main(res, names)
        print_split(res, names)
        if not ns.no_extras:
            micro = run_child({"mode": "calls", "dt": STEP_S, "reps": CALL_REPS,
                               "warmup": min(duration, CALL_WARMUP_S),
                               "cmd": case.cmd(100.0, BASE_RES_M, CALL_WARMUP_S + 1.0),
                               "offsets": case.offsets(100.0)})
            exact = {m: run_child(case.payload({**s, "check": True, "pattern": "exact"},
                                               EXACT_HORIZON_S, check_from=EXACT_FROM_S))
                     for m, s in EXACT.items()}
            print_calls(res, micro, exact)
        print_skip(res)
        print_sublane(res)
    print(f"\n(total benchmark wall time {time.perf_counter() - t_start:.0f} s, "
          f"load {os.getloadavg()[0]:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
