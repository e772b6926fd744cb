"""Cost of the co-simulation against SUMO alone and against the libsumo floor (issue 15).

Case (issue 15, the same as ``bench_floor.py``): straight 2 km x 10.2 m road, 8 000 veh/h,
100 % CAVs, 300 s, step 0.1 s, lateral resolution 0.8 m, SUMO's collision check on
(``--collision.action warn``), seed 3. Five variants, each its own process (libsumo holds
one simulation per process), interleaved over ``--rounds`` rounds in rotating order:

* ``sumo``   the ``sumo`` binary on the same network and routes, SUMO drives everyone
             (``bench_floor.py``'s variant ``a``);
* ``floor``  libsumo driven directly, no cosim code: subscribe 5 variables and read them,
             take every CAV over, ``setSpeed`` + ``setLateralLanePosition`` for every CAV
             every step, holding speed and lateral position (``bench_floor.py``'s variant
             ``e``, imported from it);
* ``floor.1s`` the floor with the take-over ``cosim`` uses on a road without human
             drivers: the CAVs' SUMO action step is 1 s, ``setPreviousSpeed`` before
             ``setSpeed`` (``bench_floor.py``'s ``e.asl``);
* ``cosim.0.1s`` ``cosim`` with the CAVs' SUMO action step of one step
             (``scenario.cav_action_step_s = 0.1``, the path before; SUMO runs its lane
             changer and car-following plan for every CAV every step);
* ``cosim``  ``run_scenario`` of that case (what ``cosim run`` runs, without writing its
             output files): the lane-free flocking law, the safety layer, every recorder.

CPU s: process CPU time in the child from the start of the run (``libsumo.start``, or
``run_scenario``, network and routes loaded) to its end; Python's start and imports are not
in it (``proc s``: the whole child process, imports included; for ``sumo`` the whole
binary). Ratios are medians of per-round ratios (the load of the shared machine cancels as
far as it can); the last two columns give the lowest and highest per-round ratio.
``us/veh-step``: CPU per vehicle on the road per step.

Then the cost split of ``cosim`` by phase (medians over rounds), measured by the loop's own
hooks (:class:`cosim.sim.loop.PhaseTimer`; no monkeypatching): ``advance`` is SUMO's step,
``other`` what is outside the steps (starting SUMO, loading the network, the result tables);
and the first ``control`` step alone (numba loads its compiled kernels from the cache).

Then the cost per vehicle-step with N = 100, 500, 1 000, 2 000 vehicles on a 10 km x 10.2 m
ring (100 % CAVs placed at t = 0: N stays fixed), after ``SCALE_SKIP`` steps, in as many
interleaved rounds as the main case (medians): SUMO's step, the Python side (every other
phase) and each phase, us per vehicle-step, and how flat each is over N (largest /
smallest). Beside it the floor on the same rings (:func:`ring_floor_child`: the world
``cosim`` starts, driven by ``bench_floor.py``'s child instead of the loop, with the CAVs'
SUMO action step of one step, ``floor``, and of 1 s, ``floor.1s``, the take-over ``cosim``
uses here): what the least controller of this kind costs per vehicle-step at each N, an
expectation for how flat a co-simulation can be, and cosim's total against it.

Usage::

    .venv/bin/python benchmarks/bench_cosim.py            # 300 s, 3 rounds; 30 s rings
    .venv/bin/python benchmarks/bench_cosim.py --quick    # 60 s, 1 round; 8 s rings (CI)
    .venv/bin/python benchmarks/bench_cosim.py --rounds 5 --duration 120 --no-scaling
    .venv/bin/python benchmarks/bench_cosim.py --cache-probe   # rings only, ~15 s
    .venv/bin/python benchmarks/bench_cosim.py --long-rings    # 10-50 km rings, ~2.5 min

``--long-rings``: the same table for rings of 100 CAVs per km, 10, 20 and 50 km long (N =
1 000, 2 000, 5 000): what grows with the road's length (the road profile of a long ring
has hundreds of pieces) shows there.

The scaling table ends with the line ``a + b N`` through the Python side's cost per step
at the two smallest N: ``a`` is paid per step whatever N (what makes a small N cost more
per vehicle; at the largest N the cost per vehicle grows again, with SUMO's, as the
vehicles' data outgrow the caches, so a fit over all N would hide ``a``).
``--cache-probe`` asks how much of it is the caches SUMO's step leaves cold: on
the rings of N = 100 and 500, every other step from ``SCALE_SKIP`` on runs without SUMO's
step (the world's ``step`` replaced by a no-op for that step, so the vehicles stand still
and the Python phases run as usual), and it prints the Python side per step after SUMO's
step and without it.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
import bench_floor as bf  # noqa: E402  (the floor variant and the case, not copied)

PHASES = ("advance", "observe", "reference", "control", "constrain", "safety", "integrate",
          "apply", "record")
#: Variants, interleaved in rounds: SUMO alone, the floor of issue 15, the floor with the
#: take-over cosim uses (CAVs' SUMO action step 1 s), cosim with its CAVs' action step of
#: one step (the path before, ``scenario.cav_action_step_s = 0.1``) and cosim as run.
VARIANTS = ("sumo", "floor", "floor.1s", "cosim.0.1s", "cosim")
SCALE_N = (100, 500, 1000, 2000)
SCALE_LENGTH_M = 10000.0
SCALE_SKIP = 20  # steps left out of the per-vehicle-step figures (start, first calls)
PROBE_N = (100, 500)  # the rings of --cache-probe
LONG_N = (1000, 2000, 5000)  # --long-rings: N CAVs on N / 100 km
#: The floor on the rings: name -> bench_floor variant (CAV action step one step / 1 s).
RING_FLOORS = {"floor": "e", "floor.1s": "e.asl"}


# ======================================================================================
# Child: one run_scenario with the loop's phase timers
# ======================================================================================


def cosim_overrides(duration_s: float) -> dict:
    """The benchmark case as overrides of the built-in ``default`` scenario."""
    return {
        "network.length_m": bf.LENGTH_M, "network.width_m": bf.WIDTH_M,
        "demand.inflow_vph": bf.INFLOW_VPH, "demand.cav_share": 1.0,
        "scenario.seed": bf.SEED, "scenario.duration_s": duration_s,
        "scenario.warmup_s": min(60.0, 0.5 * duration_s),
        "scenario.interval_s": min(60.0, 0.5 * duration_s),
        "scenario.step_length_s": bf.STEP_S, "scenario.lateral_resolution_m": bf.BASE_RES_M,
        "outputs.sumo_collisions": True,
    }


def ring_overrides(n: int, duration_s: float, length_m: float = SCALE_LENGTH_M) -> dict:
    """N CAVs on a ring of ``length_m`` (default 10 km; placed at t = 0)."""
    return {
        "network.circumference_m": length_m, "network.width_m": bf.WIDTH_M,
        "demand.ring_density_vpkm": n / (length_m / 1000.0), "demand.cav_share": 1.0,
        "scenario.seed": bf.SEED, "scenario.duration_s": duration_s,
        "scenario.warmup_s": 0.0, "scenario.interval_s": min(60.0, duration_s),
        "scenario.step_length_s": bf.STEP_S, "scenario.lateral_resolution_m": bf.BASE_RES_M,
    }


def ring_floor_child(p: dict) -> dict:
    """The floor with cosim's take-over (``bench_floor.py``'s ``e.asl``: every CAV taken
    over with a SUMO action step of 1 s, ``setSpeed`` + ``setLateralLanePosition`` every
    step, holding speed and lateral position) on the network and vehicles of a ring
    scenario: the world ``cosim`` would start (:func:`cosim.sim.runner.build_world`), driven
    by ``bench_floor.child_run`` instead of the loop. CPU s of SUMO's step and of the rest
    from step ``skip`` on."""
    from cosim.config.scenario import load_scenario
    from cosim.sim.runner import build_world

    sc = load_scenario(p["scenario"], p["overrides"])
    with tempfile.TemporaryDirectory(prefix="bench_ring_floor_") as tmp:
        world, net, _, _ = build_world(sc, Path(tmp))
        res = bf.child_run({"mode": "run", **bf.VARIANTS[p.get("variant", "e.asl")][1],
                            "dt": bf.STEP_S,
                            "duration": sc.scenario.duration_s, "cmd": world.cmd,
                            "offsets": {}, "road_length": net.length_m,
                            "from_step": int(p["skip"])})
    after = res["after"]
    return {"veh_steps_after": after["veh_steps"], "sumo_s": after["T"]["step"],
            "cpu_after_s": after["cpu_s"]}


def child(p: dict) -> dict:
    """Run one scenario; CPU (s) in all and per phase, vehicle-steps, from step ``skip`` on
    too."""
    if p.get("floor"):
        return ring_floor_child(p)
    from cosim.config.scenario import load_scenario
    from cosim.sim.loop import PhaseTimer
    from cosim.sim.runner import run_scenario

    sc = load_scenario(p["scenario"], p["overrides"])
    skip = int(p.get("skip", 0))
    out: dict = {"veh_steps": 0, "veh_steps_after": 0, "first_control_s": 0.0}
    timers: list[PhaseTimer] = []
    snap: dict = {}

    def hooks(loop):
        timers.append(PhaseTimer(loop.hooks))

        def count(st):
            n = st.state.n
            out["veh_steps"] += n
            if st.k >= skip:
                out["veh_steps_after"] += n

        def first_control(when):  # the first step that runs the law
            def fn(st):
                if when == "before" and not out.get("_law_ran"):
                    out["first_control_s"] = -time.process_time()
                elif when == "after" and not out.get("_law_ran"):
                    out["first_control_s"] += time.process_time()
                    out["_law_ran"] = True
            return fn

        def snapshot(st):  # the phase timers when the steady part starts
            if st.k == skip - 1:
                snap.update(timers[0].cpu_s)

        loop.hooks.add("observe", count)
        loop.hooks.add("control", first_control("before"), "before")
        loop.hooks.add("control", first_control("after"), "after")
        loop.hooks.add("record", snapshot)
        if p.get("probe"):
            _probe(loop, timers[0], skip, out)

    c0, w0 = time.process_time(), time.perf_counter()
    res = run_scenario(sc, hooks=hooks)
    out["cpu_s"] = time.process_time() - c0
    out["wall_s"] = time.perf_counter() - w0
    cpu = dict(timers[0].cpu_s)
    out["phases"] = {k: cpu.get(k, 0.0) for k in PHASES}
    out["phases_after"] = {k: cpu.get(k, 0.0) - snap.get(k, 0.0) for k in PHASES}
    summary = res.summary.iloc[0]
    out["inserted"] = int(summary["vehicles_inserted"])
    col = summary.get("collisions_sumo_cav")
    out["collisions_sumo_cav"] = None if col is None else int(col)
    return out


def _probe(loop, timer, skip: int, out: dict) -> None:
    """From step ``skip`` on, every other step runs without SUMO's step (the world's
    ``step`` is a no-op then: the vehicles stand where they were, the Python phases run as
    usual); CPU s of the Python phases in the steps after SUMO's step (``cold``: SUMO's
    step has just run through the caches) and in those without it (``warm``)."""
    world, real_step = loop.world, loop.world.step
    out["probe"] = {"cold": [0.0, 0], "warm": [0.0, 0]}
    last = {"py": 0.0}

    def python_s() -> float:
        return sum(v for k, v in timer.cpu_s.items() if k != "advance")

    def before(st):
        warm = st.k >= skip and st.k % 2 == 1
        world.step = (lambda: None) if warm else real_step
        last["py"], last["warm"] = python_s(), warm

    def after(st):
        if st.k >= skip:
            acc = out["probe"]["warm" if last["warm"] else "cold"]
            acc[0] += python_s() - last["py"]
            acc[1] += 1

    loop.hooks.add("advance", before, "before")
    loop.hooks.add("record", after, "after")


# ======================================================================================
# Parent
# ======================================================================================


def run_cosim(scenario: str, overrides: dict, skip: int = 0, probe: bool = False,
              floor: bool = False, **extra) -> dict:
    """One child: ``run_scenario`` with the phase timers, or (``floor``) the floor on the
    scenario's world (:func:`ring_floor_child`)."""
    payload = {"scenario": scenario, "overrides": overrides, "skip": skip, "probe": probe,
               "floor": floor, **extra}
    c0, w0 = bf._children_cpu(), time.perf_counter()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child",
                           json.dumps(payload)], capture_output=True, text=True, check=False,
                          timeout=3600, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"cosim child failed:\n{proc.stderr[-4000:]}")
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    out = json.loads(line[len("RESULT "):])
    out["proc_s"] = bf._children_cpu() - c0
    out["proc_wall_s"] = time.perf_counter() - w0
    return out


def run_variant(case, name: str, duration_s: float) -> dict:
    if name == "sumo":
        return bf.run_variant(case, "a")
    if name == "floor":
        return bf.run_variant(case, "e")
    if name == "floor.1s":
        return bf.run_variant(case, "e.asl")
    if name == "cosim.0.1s":
        return run_cosim("default", {**cosim_overrides(duration_s),
                                     "scenario.cav_action_step_s": bf.STEP_S})
    return run_cosim("default", cosim_overrides(duration_s))


def _ratio(res: dict, num: str, den: str) -> float:
    return bf._med([a["cpu_s"] / b["cpu_s"] for a, b in zip(res[num], res[den], strict=True)])


def _spread(res: dict, num: str, den: str) -> str:
    """Lowest and highest per-round ratio ``num / den`` (how much the load moved it)."""
    r = [a["cpu_s"] / b["cpu_s"] for a, b in zip(res[num], res[den], strict=True)]
    return f"{min(r):.2f}-{max(r):.2f}"


def print_main(res: dict) -> None:
    what = {"sumo": "sumo binary, SUMO drives everyone",
            "floor": "libsumo floor (bench_floor e)",
            "floor.1s": "floor, CAV action step 1 s (bench_floor e.asl)",
            "cosim.0.1s": "cosim, CAV action step 0.1 s (the path before)",
            "cosim": "cosim: run_scenario, flocking + safety + metrics"}
    print(f"\n{'variant':<11}{'what':<50}{'CPU s':>7}{'/ sumo':>8}{'/ floor':>8}"
          f"{'/ f.1s':>8}{'proc s':>8}{'veh-steps':>10}{'us/veh-step':>12}"
          f"{'rounds: / sumo':>16}{'/ floor':>11}")
    print("-" * 149)
    for n in VARIANTS:
        rows = res[n]
        cpu = bf._med([r["cpu_s"] for r in rows])
        src = rows if n != "sumo" else res["floor"]  # the binary carries the same traffic
        vs = bf._med([r.get("veh_steps") for r in src])
        us = 1e6 * cpu / vs if vs and math.isfinite(vs) else float("nan")
        print(f"{n:<11}{what[n]:<50}{cpu:7.2f}{_ratio(res, n, 'sumo'):8.2f}"
              f"{_ratio(res, n, 'floor'):8.2f}{_ratio(res, n, 'floor.1s'):8.2f}"
              f"{bf._med([r['proc_s'] for r in rows]):8.2f}{vs:10.0f}{us:12.2f}"
              f"{_spread(res, n, 'sumo'):>16}{_spread(res, n, 'floor'):>11}")


def print_phases(res: dict) -> None:
    rows = res["cosim"]
    veh_steps = bf._med([r["veh_steps"] for r in rows])
    print("\nSplit of cosim by phase (CPU s, medians over rounds; loop hooks, PhaseTimer)")
    cols = list(PHASES) + ["other", "total"]
    print("".join(f"{c:>10}" for c in cols))
    vals = []
    for c in PHASES:
        vals.append(bf._med([r["phases"][c] for r in rows]))
    other = bf._med([r["cpu_s"] - sum(r["phases"].values()) for r in rows])
    total = bf._med([r["cpu_s"] for r in rows])
    print("".join(f"{x:10.2f}" for x in vals + [other, total]))
    floor = bf._med([r["cpu_s"] for r in res["floor"]])
    python = total - vals[0]
    print(f"Python side (all but SUMO's step): {python:.2f} s, "
          f"{1e6 * python / veh_steps:.2f} us per vehicle-step; floor {floor:.2f} s, SUMO's "
          f"step in cosim {vals[0]:.2f} s")
    first = bf._med([r["first_control_s"] for r in rows])
    print(f"First control step alone (numba loads its compiled kernels from the cache): "
          f"{first:.2f} s of the {vals[3]:.2f} s of control")


def print_scaling(scale: dict, duration_s: float, road: str | None = None,
                  fit: bool = True, floors: dict | None = None) -> None:
    """Per vehicle-step costs of the rings, medians over rounds (us), and how flat they are
    from the smallest to the largest N (largest / smallest of the N)."""
    rounds = len(next(iter(scale.values())))
    road = road or f"a {SCALE_LENGTH_M / 1000:g} km x {bf.WIDTH_M:g} m ring"
    print(f"\nCost per vehicle-step, N CAVs on {road}, {duration_s:g} s, steps "
          f"{SCALE_SKIP}+, medians of {rounds} round(s) (us per vehicle-step; Python = all "
          "phases but SUMO's step)")
    cols = ["N", "veh-steps", "SUMO", "Python", "total"] + [p for p in PHASES if p != "advance"]
    print("".join(f"{c:>10}" for c in cols))
    per_n = {}
    for n, runs in scale.items():
        def us(fn, runs=runs):
            return bf._med([1e6 * fn(r) / r["veh_steps_after"] for r in runs])
        sumo = us(lambda r: r["phases_after"]["advance"])
        py = us(lambda r: sum(v for k, v in r["phases_after"].items() if k != "advance"))
        tot = us(lambda r: sum(r["phases_after"].values()))
        vals = [sumo, py, tot] + [us(lambda r, p=p: r["phases_after"][p])
                                  for p in PHASES if p != "advance"]
        per_n[n] = (sumo, py, tot)
        print(f"{n:>10}{runs[0]['veh_steps_after']:>10}" + "".join(f"{x:10.2f}" for x in vals))
    for k, name in ((1, "Python side"), (2, "total"), (0, "SUMO's step")):
        xs = [v[k] for v in per_n.values()]
        print(f"{name} per vehicle-step: {min(xs):.2f}-{max(xs):.2f} us over N = "
              f"{min(per_n)}..{max(per_n)} (largest / smallest {max(xs) / min(xs):.2f})")
    if not fit:
        return
    small = sorted(per_n)[:2]
    fixed_us, per_veh_us = _fit_fixed({n: per_n[n] for n in small})
    print(f"Python side per step through N = {small[0]} and {small[1]}: {fixed_us:.0f} us + "
          f"{per_veh_us:.2f} us x N (the fixed part: paid per step whatever N)")
    if floors:
        print_ring_floors(floors, per_n)


def print_ring_floors(floors: dict, per_n: dict) -> None:
    """The floor variants on the same rings (:func:`ring_floor_child`), us per vehicle-step
    (medians over rounds), against cosim's total (``per_n``: N -> (SUMO, Python, total))."""
    print("\nThe floor on the same rings (the world cosim starts, driven by bench_floor's "
          "child; us per vehicle-step, same steps): floor = SUMO's CAV action step of one step "
          "(the floor of the table above), floor.1s = 1 s (cosim's take-over); SUMO = its "
          "step, calls = reading and the setters")
    cols = ["N"] + [f"{v}:{c}" for v in floors for c in ("SUMO", "calls", "total")] + [
        "cosim"] + [f"/ {v}" for v in floors]
    print("".join(f"{c:>15}" for c in cols))
    for n in per_n:
        vals, totals = [], []
        for runs in floors.values():
            def us(fn, runs=runs[n]):
                return bf._med([1e6 * fn(r) / r["veh_steps_after"] for r in runs])
            sumo = us(lambda r: r["sumo_s"])
            tot = us(lambda r: r["cpu_after_s"])
            vals += [sumo, tot - sumo, tot]
            totals.append(tot)
        cosim = per_n[n][2]
        print(f"{n:>15}" + "".join(f"{x:15.2f}" for x in vals) + f"{cosim:15.2f}"
              + "".join(f"{cosim / t:15.2f}" for t in totals))


def _fit_fixed(per_n: dict) -> tuple[float, float]:
    """Least-squares ``a + b N`` of the Python side's cost per step (us) over the N of
    ``per_n`` (N -> (SUMO, Python, total) us per vehicle-step): (a us, b us per vehicle)."""
    ns = list(per_n)
    ys = [per_n[n][1] * n for n in ns]
    mn, my = sum(ns) / len(ns), sum(ys) / len(ys)
    b = sum((n - mn) * (y - my) for n, y in zip(ns, ys, strict=True)) / sum(
        (n - mn) ** 2 for n in ns)
    return my - b * mn, b


def print_probe(probe: dict, duration_s: float) -> None:
    """Python side per step after SUMO's step and without it (``--cache-probe``)."""
    rounds = len(next(iter(probe.values())))
    print(f"\nCache probe, {SCALE_LENGTH_M / 1000:g} km ring, {duration_s:g} s, steps "
          f"{SCALE_SKIP}+: every other step without SUMO's step; Python side, us per step, "
          f"medians of {rounds} round(s)")
    print(f"{'N':>6}{'after SUMO':>12}{'without':>10}{'difference':>12}")
    rows = {}
    for n, runs in probe.items():
        cold = bf._med([1e6 * r["probe"]["cold"][0] / r["probe"]["cold"][1] for r in runs])
        warm = bf._med([1e6 * r["probe"]["warm"][0] / r["probe"]["warm"][1] for r in runs])
        rows[n] = (cold, warm)
        print(f"{n:>6}{cold:12.0f}{warm:10.0f}{cold - warm:12.0f}")
    if len(rows) >= 2:
        for k, name in ((0, "after SUMO's step"), (1, "without it")):
            a, b = _fit_fixed({n: (None, v[k] / n) for n, v in rows.items()})
            print(f"fixed part {name}: {a:.0f} us + {b:.2f} us x N")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="60 s, 1 round, 8 s rings (a smoke test, about 1 min)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 3)")
    ap.add_argument("--duration", type=float, default=None, help="horizon, s (default 300)")
    ap.add_argument("--scale-duration", type=float, default=None,
                    help="horizon of the ring runs, s (default 30)")
    ap.add_argument("--no-scaling", action="store_true", help="skip the N = 100..2000 rings")
    ap.add_argument("--long-rings", action="store_true",
                    help="only rings of 100 CAVs per km, 10, 20 and 50 km long (N = 1 000, "
                         "2 000, 5 000): the cost per vehicle-step as the road grows too")
    ap.add_argument("--cache-probe", action="store_true",
                    help="only the rings at N = 100 and 500, every other step without "
                         "SUMO's step: the Python side with and without SUMO's step between")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ns = ap.parse_args(argv)
    if ns.child is not None:
        sys.path.insert(0, str(ROOT))
        print("RESULT " + json.dumps(child(json.loads(ns.child))))
        return 0
    sys.path.insert(0, str(ROOT))
    from cosim.cli.errors import run_command

    return run_command(bench, ns)


def bench(ns) -> int:
    from cosim.errors import ConfigError
    from cosim.sumo.binaries import sumo_version

    rounds = ns.rounds if ns.rounds is not None else (1 if ns.quick else 3)
    duration = ns.duration if ns.duration is not None else (60.0 if ns.quick else 300.0)
    scale_s = ns.scale_duration if ns.scale_duration is not None else (
        8.0 if ns.quick else 30.0)
    if rounds < 1:
        raise ConfigError(f"--rounds must be at least 1, got {rounds}")
    if not math.isfinite(duration) or duration < 10.0:
        raise ConfigError(f"--duration must be at least 10 s, got {duration:g}")
    if not math.isfinite(scale_s) or scale_s < (SCALE_SKIP + 10) * bf.STEP_S:
        raise ConfigError(f"--scale-duration must be at least {(SCALE_SKIP + 10) * bf.STEP_S:g}"
                          f" s, got {scale_s:g}")
    t_start = time.perf_counter()
    if ns.long_rings:
        long: dict[int, list[dict]] = {n: [] for n in LONG_N}
        for r in range(rounds):
            for n in LONG_N[r % 3:] + LONG_N[:r % 3]:
                long[n].append(run_cosim("ring", ring_overrides(n, scale_s, n * 10.0),
                                         skip=SCALE_SKIP))
        print_scaling(long, scale_s, f"a ring of 100 CAVs per km, {LONG_N[0] // 100}-"
                      f"{LONG_N[-1] // 100} km long", fit=False)
        return 0
    if ns.cache_probe:
        probe: dict[int, list[dict]] = {n: [] for n in PROBE_N}
        for r in range(rounds):
            for n in PROBE_N[r % 2:] + PROBE_N[:r % 2]:
                probe[n].append(run_cosim("ring", ring_overrides(n, scale_s), skip=SCALE_SKIP,
                                          probe=True))
        print_probe(probe, scale_s)
        return 0
    print(f"bench_cosim: {bf.LENGTH_M:g} m x {bf.WIDTH_M:g} m straight road, "
          f"{bf.INFLOW_VPH:g} veh/h, 100 % CAVs, {duration:g} s, step {bf.STEP_S:g} s, lateral "
          f"resolution {bf.BASE_RES_M:g} m, collision.action warn, seed {bf.SEED}; {rounds} "
          f"interleaved round(s); SUMO {sumo_version()}, Python {sys.version.split()[0]}; "
          f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}", flush=True)
    names = list(VARIANTS)
    with tempfile.TemporaryDirectory(prefix="bench_cosim_") as tmp:
        os.environ.setdefault("COSIM_NETWORK_CACHE", str(Path(tmp) / "nets"))
        case = bf.Case(Path(tmp), duration)
        res: dict[str, list[dict]] = {n: [] for n in names}
        for r in range(rounds):
            order = names[r % len(names):] + names[:r % len(names)]
            for n in order:
                res[n].append(run_variant(case, n, duration))
            print(f"  round {r + 1}/{rounds} done ({time.perf_counter() - t_start:.0f} s, "
                  f"load {os.getloadavg()[0]:.1f})", flush=True)
    print_main(res)
    print_phases(res)
    col = [r.get("collisions_sumo_cav") for r in res["cosim"]]
    print(f"cosim: vehicles inserted {[r['inserted'] for r in res['cosim']]}, SUMO collisions "
          f"with CAVs {col}")
    if not ns.no_scaling:
        scale: dict[int, list[dict]] = {n: [] for n in SCALE_N}
        floors = {v: {n: [] for n in SCALE_N} for v in RING_FLOORS}
        for r in range(rounds):  # interleaved too, in rotating order
            order = SCALE_N[r % len(SCALE_N):] + SCALE_N[:r % len(SCALE_N)]
            for n in order:
                scale[n].append(run_cosim("ring", ring_overrides(n, scale_s), skip=SCALE_SKIP))
                for v, variant in RING_FLOORS.items():
                    floors[v][n].append(run_cosim("ring", ring_overrides(n, scale_s),
                                                  skip=SCALE_SKIP, floor=True, variant=variant))
        print_scaling(scale, scale_s, floors=floors)
    print(f"\n(total benchmark wall time {time.perf_counter() - t_start:.0f} s, "
          f"load {os.getloadavg()[0]:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
