"""Cost of the co-simulation against SUMO alone on the same demand and network.

Three ways to run the same route file on the same network with the same SUMO
options (step 0.1 s, lateral resolution 0.8 m, collision warn, seed):

* ``sumo``      : the plain ``sumo`` binary (no Python), SUMO's SL2015 drives everyone;
* ``loop/sumo`` : ``run_scenario`` with ``controller.kind = "sumo"``: our libsumo loop,
                  subscriptions and metrics, SUMO still drives everyone;
* ``cosim``     : ``run_scenario`` with ``controller.kind = "flocking"``: the CAVs are
                  taken over and driven by the flocking controller + safety layer.

Scenario (full): straight 2 km x 10.2 m road, 4000 veh/h, 100 % CAVs, 300 s,
seed 3 (``--quick``: 1 km, 120 s). Each run is its own process (libsumo holds
one simulation per process); variants are interleaved over ``--rounds`` rounds
and the ratios are medians of per-round ratios. The machine is shared, so the
ratios use process CPU time (user + system; the ``sumo`` binary's from
``getrusage`` of the child, ours from ``time.process_time`` around
``run_scenario``, which includes starting libsumo and loading the network and
routes but not Python's imports); wall times are printed too.

Then one instrumented run each of co-sim and loop/sumo: exclusive CPU time per
part of the loop (SUMO's step, subscription fetch, read(), controller, safety,
metrics, apply, ...), measured by wrapping those functions with
``time.process_time`` timers. ``--cprofile`` adds a cProfile listing of a
separate run (it inflates Python-heavy parts).

Patch prototypes (at the end of this file, monkeypatched into the child process):
P1 subscribe only the 5 changing variables and read sizes and type once (sumo_world),
P2 constant-width fast path for the road edges (network_build, runner), P3 all-pairs
neighbour search for small sets (controllers.neighbours.cross_pairs). P1 and P2 are
now in the library (the patches then change nothing); P3 is superseded by the strip
search of ``cross_pairs`` (``strip_cross_pairs``). They stay as the template for the
next prototype: their gains are measured two ways: a *shadow* run, where every patched
function runs in both versions on the same input at every call (alternating order,
CPU time each, results compared exactly), plus a libsumo run that cycles the
subscribed variables 8 -> 5 -> 0 every 20 steps (P1's SUMO-side part); and ``--ab``:
whole runs, current vs patched, interleaved, summaries compared. ``--proposed`` runs
the three variants with the patches in.

Since then: roads are built of 100 m edges (SUMO's sublane step on one 2 km lane
costs about 3.8 times as much) and the sweeps turn SUMO's collision check off; see
``bench_sumo_options.py``. This benchmark keeps SUMO's check on in all three variants
(``outputs.sumo_collisions = true``, the default), so the ratios compare like with like.

Usage::

    .venv/bin/python benchmarks/bench_cosim.py            # full, 2.5-4.5 min (load)
    .venv/bin/python benchmarks/bench_cosim.py --quick    # about 1 min
    .venv/bin/python benchmarks/bench_cosim.py --quick --ab --rounds 3 [--cav-share 0.5]
    .venv/bin/python benchmarks/bench_cosim.py --proposed --no-profile
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FULL = {"length_m": 2000.0, "duration_s": 300.0, "inflow_vph": 4000.0, "cav_share": 1.0}
QUICK = {"length_m": 1000.0, "duration_s": 120.0, "inflow_vph": 4000.0, "cav_share": 1.0}
SEED = 3


def scenario_spec(case: dict, kind: str, lateral_resolution_m: float = 0.8) -> dict:
    return {
        "scenario": {"name": f"bench_{kind}", "seed": SEED, "duration_s": case["duration_s"],
                     "warmup_s": 60.0, "interval_s": 60.0,
                     "lateral_resolution_m": lateral_resolution_m},
        "network": {"kind": "straight", "length_m": case["length_m"], "width_m": 10.2},
        "demand": {"inflow_vph": case["inflow_vph"], "cav_share": case["cav_share"]},
        "controller": {"kind": kind},
    }


# ======================================================================================
# Child process: one run_scenario, optionally instrumented and/or patched
# ======================================================================================


class Timers:
    """Exclusive and inclusive process CPU time per wrapped function (nesting aware)."""

    def __init__(self) -> None:
        self.incl: dict[str, float] = defaultdict(float)
        self.excl: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self._stack: list[float] = []

    def wrap(self, name: str, fn):
        clock = time.process_time

        def timed(*args, **kwargs):
            t0 = clock()
            self._stack.append(0.0)
            try:
                return fn(*args, **kwargs)
            finally:
                el = clock() - t0
                child = self._stack.pop()
                self.incl[name] += el
                self.excl[name] += el - child
                self.calls[name] += 1
                if self._stack:
                    self._stack[-1] += el

        timed.__wrapped__ = fn
        return timed


#: (label, module path, attribute path) of the functions timed in the profile run.
TIMED = (
    ("loop body (runner._loop itself)", "cosim.sim.runner", "_loop"),
    ("SUMO step (libsumo.simulationStep)", "libsumo", "simulationStep"),
    ("world.step(): departures, subscribe", "cosim.sumo.world", "SumoWorld.step"),
    ("subscription fetch (getAllSubscriptionResults)", "libsumo",
     "vehicle.getAllSubscriptionResults"),
    ("world.read(): arrays, road frame", "cosim.sumo.world", "SumoWorld.read"),
    ("world.take_over()", "cosim.sumo.world", "SumoWorld.take_over"),
    ("control step glue (observation, refs)", "cosim.sim.runner", "_control_step"),
    ("edges ahead (_edges_ahead)", "cosim.sim.runner", "_edges_ahead"),
    ("time-gap leader search (leader_gaps)", "cosim.sim.runner", "leader_gaps"),
    ("controller (flocking + layers)", "controllers.constraints", "ConstrainedController.compute"),
    ("safety layer (SafetyLayer.apply)", "controllers.safety", "SafetyLayer.apply"),
    ("world.apply(): setSpeed, setLateralLanePosition", "cosim.sumo.world", "SumoWorld.apply"),
    ("metrics: recorder.record (rest)", "cosim.metrics.traffic", "TrafficRecorder.record"),
    ("metrics: gaps and leaders, TTC", "cosim.metrics.traffic", "gaps_and_leaders"),
    ("metrics: overlapping_pairs()", "cosim.metrics.traffic", "overlapping_pairs"),
    ("metrics: flock_metrics (1/s)", "cosim.sim.runner", "flock_metrics"),
    ("world.collisions()", "cosim.sumo.world", "SumoWorld.collisions"),
    ("StepState subset/other", "cosim.sim.runner", "_subset"),
)


def _install_timers(timers: Timers) -> None:
    import importlib

    for label, mod_name, attr in TIMED:
        mod = importlib.import_module(mod_name)
        owner = mod
        parts = attr.split(".")
        for p in parts[:-1]:
            owner = getattr(owner, p)
        fn = getattr(owner, parts[-1], None)
        if fn is None:
            continue
        wrapped = timers.wrap(label, fn)
        if isinstance(owner, type) and mod_name == "libsumo":
            wrapped = staticmethod(wrapped)
        setattr(owner, parts[-1], wrapped)


def child_main(payload: dict) -> dict:
    import numpy as np

    from cosim.config.scenario import scenario_from_dict
    from cosim.sim.runner import run_scenario
    from cosim.sumo.world import SumoWorld

    if payload.get("mode") == "subs":
        return subscription_cost(payload["cmd"])
    if payload.get("patches"):
        apply_patches(payload["patches"])
    shadow = None
    if payload.get("shadow"):
        shadow = Shadow()
        install_shadows(payload["shadow"], shadow)
    timers = Timers() if payload.get("timers") else None
    if timers is not None:
        _install_timers(timers)
    captured = {}
    start = SumoWorld.start

    def capture_start(self):
        captured["cmd"] = list(self.cmd)
        return start(self)

    SumoWorld.start = capture_start
    sc = scenario_from_dict(payload["spec"])
    prof = None
    if payload.get("cprofile"):
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    w0, c0 = time.perf_counter(), time.process_time()
    res = run_scenario(sc, out_dir=payload["out"])
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    out = {"wall_s": wall, "cpu_s": cpu, "cmd": captured.get("cmd")}
    s = res.summary.iloc[0].to_dict()
    out["summary"] = {k: (None if isinstance(v, float) and not np.isfinite(v) else
                          (v.item() if hasattr(v, "item") else v)) for k, v in s.items()
                      if k not in ("wall_time_s",)}
    if shadow is not None:
        out["shadow"] = shadow.rows
    if timers is not None:
        out["timers"] = {"excl": dict(timers.excl), "incl": dict(timers.incl),
                         "calls": dict(timers.calls)}
    if prof is not None:
        import io
        import pstats

        prof.disable()
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(22)
        out["cprofile"] = buf.getvalue()
    return out


# ======================================================================================
# Parent: run variants in subprocesses
# ======================================================================================


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_child(payload: dict) -> dict:
    c0, w0 = _children_cpu(), time.perf_counter()
    proc = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(payload)],
        capture_output=True, text=True, check=False, timeout=1800,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"child failed:\n{proc.stderr[-4000:]}")
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    out = json.loads(line[len("RESULT "):])
    out["process_cpu_s"] = _children_cpu() - c0
    out["process_wall_s"] = time.perf_counter() - w0
    return out


def plain_sumo_cmd(cmd: list[str]) -> list[str]:
    """The loop's SUMO command with SUMO's own performance report instead of no log."""
    out = list(cmd)
    if "--duration-log.disable" in out:
        k = out.index("--duration-log.disable")
        out[k:k + 2] = ["--duration-log.statistics", "true"]
    return out


def run_plain(cmd: list[str]) -> dict:
    c0, w0 = _children_cpu(), time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=1800)
    wall = time.perf_counter() - w0
    if proc.returncode != 0:
        raise RuntimeError(f"sumo failed:\n{proc.stderr[-3000:]}")
    text = proc.stdout + proc.stderr
    ups = re.search(r"UPS:\s*([\d.]+)", text)
    dur = re.search(r"Duration:\s*([\d.]+)(ms|s)", text)
    ins = re.search(r"Inserted:\s*(\d+)", text)
    dur_s = float(dur.group(1)) / (1000.0 if dur.group(2) == "ms" else 1.0) if dur else None
    return {
        "wall_s": wall, "cpu_s": _children_cpu() - c0,
        "sumo_ups": float(ups.group(1)) if ups else None,
        "sumo_duration_s": dur_s,
        "vehicle_steps": round(float(ups.group(1)) * dur_s) if ups and dur_s else None,
        "inserted": int(ins.group(1)) if ins else None,
    }


def _median(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else float("nan")


def benchmark(case: dict, rounds: int, work: Path, proposed: list[str]) -> dict:
    """Interleaved rounds of the three variants; returns per-variant lists of results.

    Round 0 starts with ``loop/sumo``, whose SUMO command line and route file the
    plain ``sumo`` runs then reuse (same file, same options).
    """
    variants = ["loop/sumo", "cosim", "sumo"]
    res: dict[str, list[dict]] = {v: [] for v in variants}
    cmd = None
    for r in range(rounds):
        for v in variants[r % 3:] + variants[: r % 3]:
            if v == "sumo":
                res[v].append(run_plain(cmd))
                continue
            kind = "sumo" if v == "loop/sumo" else "flocking"
            out = work / f"{kind}_{r}"
            o = run_child({"spec": scenario_spec(case, kind), "out": str(out),
                           "patches": proposed})
            o["vehicle_steps"] = o["summary"]["vehicle_steps"]
            res[v].append(o)
            if cmd is None:
                routes = work / "routes.rou.xml"
                shutil.copy(out / "routes.rou.xml", routes)
                lib_cmd = list(o["cmd"])
                lib_cmd[lib_cmd.index("-r") + 1] = str(routes)
                cmd = plain_sumo_cmd(lib_cmd)
                res["_libsumo_cmd"] = lib_cmd  # type: ignore[assignment]
            shutil.rmtree(out, ignore_errors=True)
    return res


def print_table(res: dict) -> dict:
    print(f"\n{'variant':<11} {'CPU s':>8} {'wall s':>8} {'veh-steps':>10} "
          f"{'vs/s (CPU)':>11} {'vs/s (wall)':>11} {'py start s':>10}  rounds")
    print("-" * 84)
    agg = {}
    for v, rows in res.items():
        if v.startswith("_"):
            continue
        cpu = _median([r["cpu_s"] for r in rows])
        wall = _median([r["wall_s"] for r in rows])
        vs = _median([r["vehicle_steps"] for r in rows])
        startup = _median([r["process_cpu_s"] - r["cpu_s"] for r in rows
                           if "process_cpu_s" in r]) if v != "sumo" else 0.0
        agg[v] = {"cpu_s": cpu, "wall_s": wall, "vehicle_steps": vs}
        print(f"{v:<11} {cpu:8.2f} {wall:8.2f} {vs:10.0f} {vs / cpu:11.0f} {vs / wall:11.0f} "
              f"{startup:10.2f}  {len(rows)}")
    ratios = {}
    n = min(len(r) for k, r in res.items() if not k.startswith("_"))
    for num, den in (("cosim", "sumo"), ("cosim", "loop/sumo"), ("loop/sumo", "sumo")):
        per_cpu = [res[num][k]["cpu_s"] / res[den][k]["cpu_s"] for k in range(n)]
        per_wall = [res[num][k]["wall_s"] / res[den][k]["wall_s"] for k in range(n)]
        per_vs = [(res[num][k]["cpu_s"] / res[num][k]["vehicle_steps"])
                  / (res[den][k]["cpu_s"] / res[den][k]["vehicle_steps"]) for k in range(n)]
        ratios[f"{num} / {den}"] = (statistics.median(per_cpu), statistics.median(per_wall),
                                    statistics.median(per_vs), min(per_cpu), max(per_cpu))
    print(f"\n{'ratio':<20} {'CPU':>7} {'wall':>7} {'per veh-step':>13} {'CPU min':>8} "
          f"{'CPU max':>8}   (target cosim / sumo <= 1.10)")
    print("-" * 84)
    for k, (c, w, p, lo, hi) in ratios.items():
        print(f"{k:<20} {c:7.2f} {w:7.2f} {p:13.2f} {lo:8.2f} {hi:8.2f}")
    return {"agg": agg, "ratios": ratios}


def print_profile(prof: dict, total_cpu: float, name: str = "cosim") -> None:
    t = prof["timers"]
    loop = t["incl"].get("loop body (runner._loop itself)", total_cpu)
    print(f"\nWhere the {name} loop's CPU time goes (exclusive, {loop:.2f} s in _loop of "
          f"{total_cpu:.2f} s in run_scenario)")
    print(f"{'part':<50} {'CPU s':>7} {'share':>7} {'calls':>8} {'us/call':>8}")
    print("-" * 84)
    for label, sec in sorted(t["excl"].items(), key=lambda kv: -kv[1]):
        calls = t["calls"][label]
        print(f"{label:<50} {sec:7.2f} {100 * sec / loop:6.1f}% {calls:8d} "
              f"{1e6 * sec / max(calls, 1):8.1f}")
    rest = total_cpu - loop
    print(f"{'outside the loop (network, routes, start, outputs)':<50} {rest:7.2f}")


def profile_run(case: dict, work: Path, patches: list[str], kind: str = "flocking",
                cprofile: bool = False) -> dict:
    """One instrumented run: section timers, or (``cprofile``) cProfile alone."""
    out = work / "profile"
    o = run_child({"spec": scenario_spec(case, kind), "out": str(out), "timers": not cprofile,
                   "patches": patches, "cprofile": cprofile})
    shutil.rmtree(out, ignore_errors=True)
    return o


def ab(case: dict, rounds: int, work: Path, patches: list[str]) -> None:
    """Current vs patched co-sim, interleaved; summaries must be identical."""
    cur, new = [], []
    for r in range(rounds):
        pair = [("cur", []), ("new", patches)]
        if r % 2:
            pair.reverse()
        for name, p in pair:
            out = work / f"ab_{name}_{r}"
            o = run_child({"spec": scenario_spec(case, "flocking"), "out": str(out),
                           "patches": p})
            shutil.rmtree(out, ignore_errors=True)
            (cur if name == "cur" else new).append(o)
    speed = [c["cpu_s"] / n["cpu_s"] for c, n in zip(cur, new, strict=True)]
    same = all(_same_summary(c["summary"], n["summary"]) for c, n in zip(cur, new, strict=True))
    c_cpu, n_cpu = _median([c["cpu_s"] for c in cur]), _median([n["cpu_s"] for n in new])
    print(f"\nA/B co-sim, current vs patches {patches}: CPU {c_cpu:.2f} s -> {n_cpu:.2f} s, "
          f"speed-up x{statistics.median(speed):.2f} (per round "
          f"{', '.join(f'{x:.2f}' for x in speed)}); summaries identical: {same}")
    if not same:
        c, n = cur[0]["summary"], new[0]["summary"]
        for k in c:
            if c[k] != n.get(k):
                print(f"   {k}: {c[k]} -> {n.get(k)}")


def shadow_run(case: dict, work: Path, patches: list[str]) -> dict:
    out = work / "shadow"
    o = run_child({"spec": scenario_spec(case, "flocking"), "out": str(out),
                   "shadow": patches})
    shutil.rmtree(out, ignore_errors=True)
    return o


def print_shadow(o: dict, cosim_cpu: float, n_steps: int) -> float:
    """Per-function current vs proposed CPU time; returns the total saving, s."""
    print("\nProposed patches, measured call by call on the same inputs (shadow run: both "
          "versions\nrun at every call, alternating order; 'same' = identical results)")
    print(f"{'patch':<5} {'function':<30} {'calls':>7} {'current us':>10} {'proposed us':>11} "
          f"{'saved s':>8} {'same':>5}")
    print("-" * 84)
    total = 0.0
    for label, (patch, calls, t_old, t_new, bad) in sorted(o["shadow"].items()):
        if calls == 0:
            continue
        total += t_old - t_new
        print(f"{patch:<5} {label:<30} {calls:7d} {1e6 * t_old / calls:10.1f} "
              f"{1e6 * t_new / calls:11.1f} {t_old - t_new:8.3f} {'yes' if bad == 0 else bad:>5}")
    print(f"      total saved {total:.2f} s of {cosim_cpu:.2f} s co-sim CPU "
          f"({100 * total / cosim_cpu:.1f} %), {1e6 * total / n_steps:.0f} us per step")
    return total


def subscription_runs(cmd: list[str], end_s: float) -> dict:
    """SUMO-side cost of the subscribed variables (see subscription_cost); per step, s."""
    cmd = list(cmd)
    cmd[cmd.index("--end") + 1] = f"{end_s:g}"
    r = run_child({"mode": "subs", "cmd": cmd})
    print(f"\nlibsumo, SUMO driving, {end_s:g} s; subscribed variables per vehicle cycled "
          "8 -> 5 -> 0 every 20 steps in one run (us per step)")
    print(f"{'variables':<12} {'steps':>6} {'step us':>8} {'fetch us':>9} {'total us':>9}")
    out = {}
    for k, label in (("8", "8 (current)"), ("5", "5 (P1)"), ("0", "0")):
        st, fe, n = r[k]
        out[int(k)] = (st / n, fe / n)
        print(f"{label:<12} {n:6d} {1e6 * st / n:8.1f} {1e6 * fe / n:9.1f} "
              f"{1e6 * (st + fe) / n:9.1f}")
    return out


def _same_summary(a: dict, b: dict) -> bool:
    return all(a[k] == b.get(k) for k in a)


# ======================================================================================
# Proposed patches (prototypes, monkeypatched in the child process)
# ======================================================================================


#: Above this many (agent x vehicle) pairs the dense prototypes fall back to the KD-tree.
DENSE_MAX_PAIRS = 40_000


def patch_subscribe_dynamic() -> list:
    """P1 (sumo_world): subscribe only the 5 variables that change (lane, position,
    lateral position, speed, lateral speed); read length, width and type once at
    departure; build the arrays in read() with list comprehensions and one dict
    lookup per lane (offset, lateral offset, on-main) instead of three."""
    import numpy as np

    from cosim.sumo import world as sw

    def dyn_vars():
        import libsumo as ls

        return (ls.VAR_LANE_ID, ls.VAR_LANEPOSITION, ls.VAR_LANEPOSITION_LAT, ls.VAR_SPEED,
                ls.VAR_SPEED_LAT)

    def step(self) -> None:
        ts = self.ts
        ts.simulationStep()
        static = self.__dict__.setdefault("_static", {})
        keys = (v_lane, v_pos, v_lat, v_speed, v_slat)
        veh = ts.vehicle
        for vid in ts.simulation.getDepartedIDList():
            veh.subscribe(vid, keys)
            tid = veh.getTypeID(vid)
            self.types[vid] = tid
            static[vid] = (veh.getLength(vid), veh.getWidth(vid),
                           1.0 if tid.startswith(self.cav_prefix) else 0.0)
        for vid in ts.simulation.getArrivedIDList():
            self.types.pop(vid, None)
            self.controlled.discard(vid)
            self.v_lat_state.pop(vid, None)
            static.pop(vid, None)

    def lane_info(self, lane):
        off = self.net.lane_offsets.get(lane)
        return (np.nan if off is None else float(off), float(self.net.lane_d.get(lane, 0.0)),
                1.0 if lane in self.main_lanes else 0.0)

    v_lane, v_pos, v_lat, v_speed, v_slat = dyn_vars()

    def read(self):
        res = self.ts.vehicle.getAllSubscriptionResults()
        ids = list(res)
        n = len(ids)
        rows = list(res.values())
        lane = [r[v_lane] for r in rows]
        static = self.__dict__.setdefault("_static", {})
        lanes = self.__dict__.setdefault("_lane_info", {})
        for x in set(lane).difference(lanes):
            lanes[x] = lane_info(self, x)
        # one (n, 10) array: dynamic values, then static per vehicle, then per lane
        a = np.array([(r[v_pos], r[v_lat], r[v_speed], r[v_slat]) + static[v] + lanes[x]
                      for r, v, x in zip(rows, ids, lane, strict=True)],
                     dtype=float).reshape(n, 10)
        s_front = a[:, 7] + a[:, 0]
        if self.period is not None:
            s_front = np.mod(s_front, self.net.length_m)
        length, width = a[:, 4], a[:, 5]
        s = s_front - 0.5 * length
        if self.period is not None:
            s = np.mod(s, self.period)
        d = a[:, 1] + a[:, 8]
        vls = self.v_lat_state
        v_lat_now = a[:, 3].copy()
        for k, vid in enumerate(ids):
            if vid in vls:
                v_lat_now[k] = vls[vid]
        on_main = (a[:, 9] > 0.5) & ~np.isnan(s)
        return sw.VehicleArrays(ids, lane, s_front, s, d, a[:, 2], v_lat_now, length, width,
                                a[:, 6] > 0.5, on_main)

    def step_shadow(self) -> None:
        """The current step (8 variables) plus the static cache the new read() needs."""
        orig_step(self)
        static = self.__dict__.setdefault("_static", {})
        for vid in self.types:
            if vid not in static:
                static[vid] = (self.ts.vehicle.getLength(vid), self.ts.vehicle.getWidth(vid),
                               1.0 if self.types[vid].startswith(self.cav_prefix) else 0.0)

    orig_step = sw.SumoWorld.step
    return [(sw.SumoWorld, "step", step, step_shadow, "world.step()", None),
            (sw.SumoWorld, "read", read, None, "world.read()", _same_arrays)]


def patch_constant_width() -> list:
    """P2 (network_build, runner): numpy copies of the width profile cached on the
    network, a constant-width fast path in width_at, and _edges_ahead computed once
    (not for 5 look-ahead horizons) when the width is constant."""
    import numpy as np

    from cosim.road import frame as nb
    from cosim.sim import runner

    def cache(net):
        c = net.__dict__.get("_width_cache")
        if c is None:
            s0 = np.asarray(net.segment_s0, dtype=float)
            w = np.asarray(net.segment_width, dtype=float)
            const = float(w[0]) if len(w) and np.all(w == w[0]) else None
            c = (s0, w, const)
            object.__setattr__(net, "_width_cache", c)
        return c

    def width_at(self, s):
        s0, w, const = cache(self)
        s = np.asarray(s, dtype=float)
        if const is not None:
            return np.full(s.shape, const)
        if self.periodic:
            s = np.mod(s, self.length_m)
        idx = np.clip(np.searchsorted(s0, s, side="right") - 1, 0, len(w) - 1)
        return w[idx]

    orig_edges_ahead = runner._edges_ahead

    def edges_ahead(net, s, v, period):
        const = cache(net)[2]
        if const is None:
            return orig_edges_ahead(net, s, v, period)
        half = 0.5 * const
        return np.column_stack([np.full(len(s), -half), np.full(len(s), half)])

    return [(nb.RoadNetwork, "width_at", width_at, None, "width_at()", _same_arrays),
            (runner, "_edges_ahead", edges_ahead, None, "_edges_ahead()", _same_arrays)]


def patch_dense_pairs() -> list:
    """P3 (controllers.neighbours.cross_pairs): for the few dozen vehicles of a road
    stretch, all-pairs numpy arithmetic instead of two KD-trees and the flattening of
    query_ball_tree's Python lists, in the safety layer (leader_gaps now scans the
    vehicles sorted along the road and needs no pair search); the
    KD-tree is kept above DENSE_MAX_PAIRS pairs and on rings. Same pair sets (they
    come out sorted instead of in tree order; both callers take per-vehicle minima, so
    results are bit-identical). The flocking vehicle_term could use it too, but it sums
    per pair (bincount), so the new order would change the last bits of its forces.
    The metrics' gaps() and overlapping_pairs() KD-trees were tried the same way and
    gain nothing at 75 vehicles (dense N x N is as slow), so they stay."""
    import numpy as np

    import controllers.neighbours as nbh
    import controllers.safety as sf

    orig_cross = nbh.cross_pairs

    def cross_pairs(x, y, radius, period=None):
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        if period is not None or len(x) * len(y) > DENSE_MAX_PAIRS or x.shape[1] != 2:
            return orig_cross(x, y, radius, period)
        if len(x) == 0 or len(y) == 0:
            return np.empty((0, 2), dtype=np.int64)
        r = np.nextafter(radius, 0.0)
        d0 = x[:, 0][:, None] - y[:, 0][None, :]
        d1 = x[:, 1][:, None] - y[:, 1][None, :]
        i, k = np.nonzero(d0 * d0 + d1 * d1 <= r * r)
        return np.stack([i, k], axis=1).astype(np.int64)

    return [
        (sf, "cross_pairs", cross_pairs, None, "cross_pairs (safety layer)", _same_pairs),
    ]


def _same_arrays(a, b) -> bool:
    """Exact equality of arrays, tuples/lists of arrays, or dataclasses of them."""
    import dataclasses

    import numpy as np

    if dataclasses.is_dataclass(a):
        return all(_same_arrays(getattr(a, f.name), getattr(b, f.name))
                   for f in dataclasses.fields(a))
    if isinstance(a, tuple | list) and not (len(a) and isinstance(a[0], str)):
        return len(a) == len(b) and all(_same_arrays(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray):
        return (a.shape == b.shape and a.dtype.kind == np.asarray(b).dtype.kind
                and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"))
    return a == b


def _same_pairs(a, b) -> bool:
    """Same set of index pairs (row order may differ)."""
    import numpy as np

    if len(a) != len(b):
        return False
    return len(a) == 0 or np.array_equal(np.unique(a, axis=0), np.unique(b, axis=0))


def apply_patches(names: list[str]) -> None:
    for name in names:
        for owner, attr, new, _shadow_repl, _label, _same in PATCHES[name]():
            setattr(owner, attr, new)


class Shadow:
    """Run the current and the proposed version of a function on the same input at
    every call (alternating which goes first), time both with process CPU time,
    check they agree, and return the current result (the run stays on the current path)."""

    def __init__(self) -> None:
        self.rows: dict[str, list] = {}
        self.depth = 0

    def wrap(self, label: str, patch: str, orig, new, same):
        row = self.rows.setdefault(label, [patch, 0, 0.0, 0.0, 0])  # calls, t_old, t_new, bad
        clock = time.process_time

        def shadow(*args, **kwargs):
            if self.depth:  # inside another shadowed call: the current code path only
                return orig(*args, **kwargs)
            self.depth += 1
            try:
                return run(*args, **kwargs)
            finally:
                self.depth -= 1

        def run(*args, **kwargs):
            first_old = row[1] % 2 == 0
            row[1] += 1
            if first_old:
                t0 = clock()
                r_old = orig(*args, **kwargs)
                t1 = clock()
                r_new = new(*args, **kwargs)
                t2 = clock()
                row[2] += t1 - t0
                row[3] += t2 - t1
            else:
                t0 = clock()
                r_new = new(*args, **kwargs)
                t1 = clock()
                r_old = orig(*args, **kwargs)
                t2 = clock()
                row[3] += t1 - t0
                row[2] += t2 - t1
            if not same(r_old, r_new):
                row[4] += 1
            return r_old

        return shadow


def install_shadows(names: list[str], shadow: Shadow) -> None:
    for name in names:
        for owner, attr, new, shadow_repl, label, same in PATCHES[name]():
            if same is None:  # not comparable call by call: install its shadow stand-in
                if shadow_repl is not None:
                    setattr(owner, attr, shadow_repl)
                continue
            orig = getattr(owner, attr)
            setattr(owner, attr, shadow.wrap(label, name, orig, new, same))


def subscription_cost(cmd: list[str], block: int = 20) -> dict:
    """CPU time of libsumo's step and subscription fetch with 8 (current), 5 (P1) and 0
    subscribed variables per vehicle, SUMO driving everyone, no other Python work.

    One simulation; the variable set cycles 8 -> 5 -> 0 every ``block`` steps (all
    vehicles re-subscribed, not timed), so the three share the same traffic and the
    machine's load drift. Returns per set: [step CPU s, fetch CPU s, steps]."""
    import libsumo as ls

    v8 = (ls.VAR_LANE_ID, ls.VAR_LANEPOSITION, ls.VAR_LANEPOSITION_LAT, ls.VAR_SPEED,
          ls.VAR_SPEED_LAT, ls.VAR_LENGTH, ls.VAR_WIDTH, ls.VAR_TYPE)
    sets = {8: v8, 5: v8[:5], 0: ()}
    order = (8, 5, 0)
    ls.start(cmd)
    end = float(cmd[cmd.index("--end") + 1])
    t = {k: [0.0, 0.0, 0] for k in sets}
    clock = time.process_time
    k = 0
    try:
        while ls.simulation.getTime() < end - 1e-9:
            mode = order[(k // block) % 3]
            keys = sets[mode]
            if k % block == 0:
                for vid in ls.vehicle.getIDList():
                    ls.vehicle.unsubscribe(vid)  # subscribe() adds to, not replaces, a set
                    if keys:
                        ls.vehicle.subscribe(vid, keys)
            t0 = clock()
            ls.simulationStep()
            t[mode][0] += clock() - t0
            t[mode][2] += 1
            if keys:
                for vid in ls.simulation.getDepartedIDList():
                    ls.vehicle.subscribe(vid, keys)
                t0 = clock()
                ls.vehicle.getAllSubscriptionResults()
                t[mode][1] += clock() - t0
            k += 1
    finally:
        ls.close()
    return {str(m): v for m, v in t.items()}


PATCHES: dict = {
    "P1": patch_subscribe_dynamic,
    "P2": patch_constant_width,
    "P3": patch_dense_pairs,
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 km, 120 s")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 2)")
    ap.add_argument("--proposed", action="store_true", help="co-sim with the proposed patches")
    ap.add_argument("--ab", action="store_true", help="current vs proposed co-sim, interleaved")
    ap.add_argument("--patches", default=None, help="comma list of patches (default: all)")
    ap.add_argument("--no-profile", action="store_true")
    ap.add_argument("--cprofile", action="store_true", help="also print a cProfile listing")
    ap.add_argument("--cav-share", type=float, default=None, help="CAV share (default 1.0)")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child is not None:
        print("RESULT " + json.dumps(child_main(json.loads(a.child))))
        return 0
    case = dict(QUICK if a.quick else FULL)
    if a.cav_share is not None:
        case["cav_share"] = a.cav_share
    rounds = a.rounds or 2
    patches = list(PATCHES) if a.patches is None else [p for p in a.patches.split(",") if p]
    proposed = patches if a.proposed else []
    import numpy
    import pandas

    from cosim.sumo.binaries import sumo_version

    print(f"bench_cosim: {case['length_m']:g} m x 10.2 m, {case['inflow_vph']:g} veh/h, "
          f"{100 * case['cav_share']:g} % CAVs, {case['duration_s']:g} s, step 0.1 s, "
          f"lateral resolution 0.8 m, seed {SEED}; SUMO {sumo_version()}, numpy "
          f"{numpy.__version__}, pandas {pandas.__version__}; {os.cpu_count()} CPUs, "
          f"load {os.getloadavg()[0]:.1f}; co-sim patches: {proposed or 'none'}")
    work = Path(tempfile.mkdtemp(prefix="bench_cosim_"))
    try:
        if a.ab:
            ab(case, rounds, work, patches)
            return 0
        t0 = time.perf_counter()
        res = benchmark(case, rounds, work, proposed)
        table = print_table(res)
        if not a.no_profile:
            for kind in ("flocking", "sumo"):
                prof = profile_run(case, work, proposed, kind)
                print_profile(prof, prof["cpu_s"], "cosim" if kind == "flocking" else "loop/sumo")
            if a.cprofile:
                prof = profile_run(case, work, proposed, cprofile=True)
                print("\ncProfile (tottime) of a co-sim run (separate run):\n" + prof["cprofile"])
        if not proposed and patches:
            cos = table["agg"]["cosim"]["cpu_s"]
            n_steps = int(round(case["duration_s"] / 0.1))
            saved = print_shadow(shadow_run(case, work, patches), cos, n_steps)
            subs = {}
            if "P1" in patches:
                subs = subscription_runs(res["_libsumo_cmd"], case["duration_s"])
                sub_saved = n_steps * (sum(subs[8]) - sum(subs[5]))
                print(f"P1 on the SUMO side: {sub_saved:.2f} s saved over the run")
                saved += sub_saved
            plain = table["agg"]["sumo"]["cpu_s"]
            print(f"\nProjected co-sim CPU with {', '.join(patches)}: {cos - saved:.2f} s "
                  f"(x{cos / (cos - saved):.2f} faster); cosim / sumo {cos / plain:.2f} -> "
                  f"{(cos - saved) / plain:.2f} (target 1.10)")
        print(f"\n(total benchmark wall time {time.perf_counter() - t0:.0f} s)")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
