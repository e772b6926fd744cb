"""Olfati-Saber controller and plane-world speed and memory versus N (one core).

Prints, for N = 100, 1 000, 10 000 and 100 000 agents at a fixed density, the
controller's time per step, agent-steps per second and the tracemalloc peak of
one step, for the dense reference neighbour search and the KD-tree, plus
PlaneWorld end-to-end figures (observation + controller + Euler step + leader,
metrics and trajectory recording off) without and with the controller's
opt-in Verlet neighbour list. Then a profile of one controller step at
N = 10 000 split into neighbour search, alpha pair math, walls, gamma.

Scenario (fixed density): a jittered square lattice, spacing 5.7 m (0.95 d),
on a patch about sqrt(N) x sqrt(N) agents of a road whose edges lie 2 m from
the outer rows' sides (inside r_wall, so the edge term acts); 20 m/s cruise
with noise and a moving virtual leader (gamma term, bounded sigma_1 form so
the flock keeps its density while timed); dt = 0.01 s. About 2 neighbour
pairs per agent (4 neighbours each).

Usage:
    .venv/bin/python benchmarks/bench_plane_controller.py          # full, ~1 min (dense
                                                                   # N = 10 000 needs ~4.5 GiB)
    .venv/bin/python benchmarks/bench_plane_controller.py --quick  # N <= 1000, ~3 s
    ... --dense-max 1000   # skip the slow dense reference at N = 10 000
    ... --ab               # interleaved Verlet list off / on (plane world) at the profile N
    ... --ab --baseline DIR  # also against an older copy of the controllers/ package, e.g.
                             #   git archive <commit> controllers | tar -x -C /tmp/base
                             #   ... --ab --baseline /tmp/base/controllers

BLAS/OpenMP pools are forced to one thread before numpy is imported, so the
numbers are single-core. Time per step is the median process CPU time over
repeated steps (minimum and wall-clock median shown too): on a shared machine
CPU time is much less noisy than wall time; still, compare ratios.
"""

from __future__ import annotations

import os

for _var in (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import gc  # noqa: E402
import importlib  # noqa: E402
import importlib.util  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Callable  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

import numpy as np  # noqa: E402

import controllers.plane.olfati_saber as fl  # noqa: E402
from controllers.observation import Observation  # noqa: E402
from controllers.plane.olfati_saber import OlfatiSaberController  # noqa: E402
from controllers.plane.params import FlockingParams  # noqa: E402
from controllers.plane.references import VirtualLeader  # noqa: E402
from cosim.plane.world import PlaneWorld  # noqa: E402

MIB = 2.0**20
SPACING_M = 5.7  # lattice spacing (d = 6 m, r = 7.2 m: 4 neighbours each)
JITTER_M = 0.3
EDGE_GAP_M = 2.0  # outer rows' side to road edge (< r_wall = 3.6 m)
SIZES_M = (4.5, 1.8)  # length, width
DT_S = 0.01  # s, as the seed scenarios (dt = 0.1 s is unstable with these gains)
DENSE_BYTES_PER_N2 = 46.0  # measured tracemalloc peak of the dense search / N^2 (m = 2)
VERLET_SKIN_M = 0.5  # skin of the plane/verlet rows (OlfatiSaberController(verlet_skin=...))


# --------------------------------------------------------------------------- scenario
def bench_params(method: str, params_cls=FlockingParams):
    """Default gains; bounded (sigma_1) gamma so the flock keeps its density while timed."""
    return params_cls(neighbour_search=method, gamma_position="sigma1")


@dataclass
class Scenario:
    q: np.ndarray  # (N, 2) m
    p: np.ndarray  # (N, 2) m/s
    edges: np.ndarray  # (2,) right/left lateral road edge, m
    leader_q: np.ndarray  # (2,) m
    leader_p: np.ndarray  # (2,) m/s

    @property
    def n(self) -> int:
        return len(self.q)

    def observation(self, obs_cls=Observation) -> Observation:
        n = self.n
        return obs_cls(
            q=self.q,
            p=self.p,
            dt=DT_S,
            length=np.full(n, SIZES_M[0]),
            width=np.full(n, SIZES_M[1]),
            road_edges=self.edges,
            leader_q=self.leader_q,
            leader_p=self.leader_p,
        )


def make_scenario(n: int, seed: int = 0) -> Scenario:
    """Fixed-density layout: jittered square lattice, area proportional to N."""
    rng = np.random.default_rng(seed)
    n_lat = max(2, round(math.sqrt(n)))
    ix, iy = np.divmod(np.arange(n), n_lat)
    y0 = 0.5 * SIZES_M[1] + EDGE_GAP_M
    q = np.column_stack([ix * SPACING_M, y0 + iy * SPACING_M])
    q += rng.normal(0.0, JITTER_M, q.shape)
    p = np.array([20.0, 0.0]) + rng.normal(0.0, 0.5, q.shape)
    edges = np.array([0.0, 2.0 * y0 + (n_lat - 1) * SPACING_M])
    leader_q = q.mean(axis=0) + np.array([10.0, 0.0])
    return Scenario(q, p, edges, leader_q, np.array([21.0, 0.2]))


def make_world(sc: Scenario, controller) -> PlaneWorld:
    return PlaneWorld(
        sc.q,
        sc.p,
        controller,
        DT_S,
        reference=VirtualLeader(sc.leader_q, sc.leader_p),
        road_edges=tuple(sc.edges),
        sizes=SIZES_M,
        record_every=0,
        metrics_every=10**9,  # metrics only at step 0, which is not timed
    )


# --------------------------------------------------------------------------- helpers
@contextmanager
def patched(targets):
    """Temporarily set attributes ``(obj, name, value)`` (profiler wrappers, baseline swaps)."""
    saved = [(obj, name, getattr(obj, name)) for obj, name, _ in targets]
    try:
        for obj, name, new in targets:
            setattr(obj, name, new)
        yield
    finally:
        for obj, name, old in saved:
            setattr(obj, name, old)


def load_baseline(pkg_dir: str) -> SimpleNamespace:
    """Import another copy of the ``controllers`` package (e.g. an older commit) as
    ``controllers_baseline``; returns its flocking, observation and params modules."""
    init = Path(pkg_dir).resolve() / "__init__.py"
    if not init.is_file():
        raise SystemExit(f"--baseline: {init} not found (give the controllers/ directory)")
    name = "controllers_baseline"
    spec = importlib.util.spec_from_file_location(
        name, init, submodule_search_locations=[str(init.parent)]
    )
    pkg = importlib.util.module_from_spec(spec)
    sys.modules[name] = pkg
    spec.loader.exec_module(pkg)
    return SimpleNamespace(
        path=str(init.parent),
        flocking=importlib.import_module(f"{name}.flocking"),
        observation=importlib.import_module(f"{name}.observation"),
        params=importlib.import_module(f"{name}.params"),
    )


# --------------------------------------------------------------------------- measurement
@dataclass
class Row:
    n: int
    case: str
    pairs_per_agent: float
    med_s: float  # median CPU time per step (mean for plane/verlet, see world_row)
    min_s: float  # fastest step (CPU)
    wall_s: float  # median wall time per step
    reps: int
    peak_bytes: int

    @property
    def rate(self) -> float:
        return self.n / self.med_s


@dataclass
class Timing:
    cpu: list[float]
    wall: list[float]
    peak_bytes: int

    def row(self, n: int, case: str, pairs_per_agent: float, mean: bool = False) -> Row:
        return Row(
            n,
            case,
            pairs_per_agent,
            statistics.fmean(self.cpu) if mean else statistics.median(self.cpu),
            min(self.cpu),
            statistics.median(self.wall),
            len(self.cpu),
            self.peak_bytes,
        )


def measure(
    step: Callable[[], object], budget_s: float, max_reps: int = 2000, min_timed: int = 0
) -> Timing:
    """CPU and wall times per call of ``step`` and the tracemalloc peak of one call.

    CPU time (``time.process_time``; one thread) is what the table reports: on
    a shared machine it is far less noisy than wall time. The first call is
    traced (peak of what it allocates); if it is slow (more than half the
    budget) and ``min_timed`` is 0 it is also the only timing, else untraced
    calls are timed until the budget (wall seconds) is spent, at least
    ``max(3, min_timed)``.
    """
    gc.collect()
    tracemalloc.start()
    w0, c0 = time.perf_counter(), time.process_time()
    step()
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    if wall > 0.5 * budget_s and not min_timed:
        return Timing([cpu], [wall], peak)
    cpus: list[float] = []
    walls: list[float] = []
    deadline = time.perf_counter() + budget_s
    least = max(3, min_timed)
    while len(cpus) < max_reps and (len(cpus) < least or time.perf_counter() < deadline):
        w0, c0 = time.perf_counter(), time.process_time()
        step()
        cpus.append(time.process_time() - c0)
        walls.append(time.perf_counter() - w0)
    return Timing(cpus, walls, peak)


def controller_row(sc: Scenario, method: str, budget_s: float) -> Row:
    ctrl = OlfatiSaberController(bench_params(method))
    obs = sc.observation()
    ctrl.compute(obs)  # warm-up (imports, caches)
    pairs = ctrl.last_terms.n_pairs / sc.n
    return measure(lambda: ctrl.compute(obs), budget_s).row(sc.n, f"ctrl/{method}", pairs)


def world_row(sc: Scenario, budget_s: float, verlet_skin: float = 0.0) -> tuple[Row, float]:
    """Plane-world row and the fraction of timed steps that rebuilt the Verlet list.

    With a Verlet list the step times are bimodal (rebuild or reuse), so the
    row's time is the mean over at least 8 timed steps, not the median; the
    traced (memory) step is forced to rebuild and is not timed.
    """
    ctrl = OlfatiSaberController(bench_params("kdtree"), verlet_skin=verlet_skin)
    world = make_world(sc, ctrl)
    world.step()  # step 0 computes the flock metrics once; later steps do not
    if verlet_skin:
        ctrl._verlet = None  # the traced step rebuilds the list: its peak memory
    stats0 = dict(ctrl.verlet_stats)
    timing = measure(world.step, budget_s, min_timed=8 if verlet_skin else 0)
    steps = ctrl.verlet_stats["steps"] - stats0["steps"] - 1  # timed steps
    rebuilds = ctrl.verlet_stats["rebuilds"] - stats0["rebuilds"] - 1
    case = "plane/verlet" if verlet_skin else "plane/kdtree"
    row = timing.row(sc.n, case, ctrl.last_terms.n_pairs / sc.n, mean=bool(verlet_skin))
    return row, (rebuilds / steps if verlet_skin and steps > 0 else float("nan"))


def print_table(rows: list[Row], skipped: list[str]) -> None:
    head = (
        f"{'N':>7} {'case':<13} {'pairs/ag':>8} {'ms/step':>9} {'(min)':>9} {'wall ms':>9} "
        f"{'reps':>5} "
        f"{'agent-steps/s':>13} {'peak MiB':>9} {'MiB/1k ag':>9}"
    )
    print(head)
    print("-" * len(head))
    for r in rows:
        print(
            f"{r.n:>7} {r.case:<13} {r.pairs_per_agent:>8.2f} {1e3 * r.med_s:>9.3f} "
            f"{1e3 * r.min_s:>9.3f} {1e3 * r.wall_s:>9.3f} {r.reps:>5} {r.rate:>13.3e} "
            f"{r.peak_bytes / MIB:>9.2f} "
            f"{r.peak_bytes / MIB / (r.n / 1000):>9.3f}"
        )
    for line in skipped:
        print(line)


# --------------------------------------------------------------------------- profile
class _Profiler:
    """Exclusive CPU time per call path of wrapped functions (nesting-aware)."""

    def __init__(self) -> None:
        self.stack: list[list] = []
        self.excl: dict[str, float] = defaultdict(float)

    def wrap(self, label: str, func: Callable) -> Callable:
        def wrapper(*args, **kwargs):
            path = f"{self.stack[-1][0]}/{label}" if self.stack else label
            frame = [path, 0.0]
            self.stack.append(frame)
            t0 = time.process_time()
            try:
                return func(*args, **kwargs)
            finally:
                dt = time.process_time() - t0
                self.stack.pop()
                self.excl[path] += dt - frame[1]
                if self.stack:
                    self.stack[-1][1] += dt

        return wrapper


_MODULE_FUNCS = (  # names looked up in controllers.plane.olfati_saber's namespace
    "neighbour_pairs",
    "cross_pairs",
    "scatter_add",
    "sigma_norm",
    "sigma_grad",
    "phi_beta",
    "adjacency",
    "sigma_1_vec",
    "rho_h",
    "phi",
)
_METHODS = (
    "compute",
    "alpha_term",
    "_alpha_pair_forces",
    "circle_term",
    "vehicle_term",
    "wall_term",
    "_one_wall",
    "_beta_pair",
    "gamma_term",
)
_KERNELS = {"rho_h", "phi"}


def _category(path: str) -> str:
    parts = path.split("/")
    if "neighbour_pairs" in parts:
        return "neighbour search (KD-tree + pair sort)"
    if "alpha_term" in parts:
        if parts[-1] in _KERNELS:
            return "alpha pair math: rho_h / phi kernels"
        return "alpha pair math: gathers, sqrt, products, scatter"
    if "wall_term" in parts:
        return "walls / road edges"
    if "gamma_term" in parts:
        return "gamma (leader)"
    if "circle_term" in parts or "vehicle_term" in parts:
        return "beta (circles, vehicles)"
    return "other (check_finite, zeros, sum of terms)"


def profile(sc: Scenario, steps: int) -> None:
    ctrl = OlfatiSaberController(bench_params("kdtree"))
    obs = sc.observation()
    ctrl.compute(obs)
    prof = _Profiler()
    targets = [(fl, f, prof.wrap(f, getattr(fl, f))) for f in _MODULE_FUNCS]
    targets += [
        (OlfatiSaberController, f, prof.wrap(f, getattr(OlfatiSaberController, f)))
        for f in _METHODS
    ]
    check = prof.wrap("check_finite", Observation.check_finite)
    targets.append((Observation, "check_finite", check))
    with patched(targets):
        for _ in range(steps):
            ctrl.compute(obs)
    total = sum(prof.excl.values()) / steps
    cats: dict[str, float] = defaultdict(float)
    for path, t in prof.excl.items():
        cats[_category(path)] += t / steps
    print(
        f"\nProfile of one controller step, N = {sc.n}, kdtree, mean of {steps} steps "
        f"(wrapped calls; total {1e3 * total:.2f} ms/step):"
    )
    for name, t in sorted(cats.items(), key=lambda kv: -kv[1]):
        print(f"  {name:<50} {1e3 * t:8.3f} ms  {100 * t / total:5.1f} %")
    print("  by call path (exclusive time):")
    for path, t in sorted(prof.excl.items(), key=lambda kv: -kv[1]):
        if t / steps >= 0.005 * total:
            print(f"    {path:<56} {1e3 * t / steps:8.3f} ms")


# --------------------------------------------------------------------------- A/B
def _world_run(sc: Scenario, controller, steps: int):
    """CPU seconds per step of ``steps`` plane-world steps, and the final positions."""
    world = make_world(sc, controller)
    world.step()  # step 0: flock metrics, not timed
    gc.collect()
    c0 = time.process_time()
    for _ in range(steps):
        world.step()
    return (time.process_time() - c0) / steps, world.q


def ab_compare(sc: Scenario, rounds: int, budget_s: float, world_steps: int, base=None) -> None:
    """Interleaved timings; speed-ups are medians of per-round ratios to the first variant.

    Variants: the library's controller, its Verlet list (plane world), and with
    ``base`` (see :func:`load_baseline`) the baseline package's controller, fed
    its own Observation class (and its ``check_finite`` inside the world).
    """
    obs = sc.observation()
    ctrl = OlfatiSaberController(bench_params("kdtree"))
    u_cur = ctrl.compute(obs).copy()
    ctrl_variants: dict[str, tuple[Callable[[], object], tuple]] = {}
    world_variants: dict[str, tuple[Callable[[], object], tuple]] = {}
    err = None
    if base is not None:
        b_obs = sc.observation(base.observation.Observation)
        b_ctrl = base.flocking.OlfatiSaberController(
            bench_params("kdtree", base.params.FlockingParams)
        )
        u_base = b_ctrl.compute(b_obs).copy()
        err = float(np.max(np.abs(u_cur - u_base)) / max(np.max(np.abs(u_base)), 1e-300))
        ctrl_variants["baseline"] = (lambda: b_ctrl.compute(b_obs), ())
        world_variants["baseline"] = (
            lambda: base.flocking.OlfatiSaberController(
                bench_params("kdtree", base.params.FlockingParams)
            ),
            ((Observation, "check_finite", base.observation.Observation.check_finite),),
        )
    ctrl_variants["library"] = (lambda: ctrl.compute(obs), ())
    world_variants["library kdtree"] = (
        lambda: OlfatiSaberController(bench_params("kdtree")),
        (),
    )
    verlet_ctrls: list[OlfatiSaberController] = []

    def make_verlet():
        verlet_ctrls.append(
            OlfatiSaberController(bench_params("kdtree"), verlet_skin=VERLET_SKIN_M)
        )
        return verlet_ctrls[-1]

    world_variants["library + Verlet"] = (make_verlet, ())
    ctrl_t: dict[str, list[float]] = defaultdict(list)
    world_t: dict[str, list[float]] = defaultdict(list)
    q_end: dict[str, np.ndarray] = {}
    for _ in range(rounds):
        for name, (call, patches) in ctrl_variants.items():
            with patched(patches):
                ctrl_t[name].append(statistics.median(measure(call, budget_s).cpu))
        for name, (factory, patches) in world_variants.items():
            with patched(patches):
                t, q_end[name] = _world_run(sc, factory(), world_steps)
            world_t[name].append(t)
    steps = sum(c.verlet_stats["steps"] for c in verlet_ctrls)
    rebuilds = sum(c.verlet_stats["rebuilds"] for c in verlet_ctrls)
    dq_verlet = float(np.max(np.abs(q_end["library + Verlet"] - q_end["library kdtree"])))
    print(
        f"\nA/B at N = {sc.n}, CPU time, {rounds} interleaved rounds "
        f"(speed-up = median over rounds of first variant / variant):"
    )
    note = "" if err is None else f" (library vs baseline max|du|/max|u| = {err:.1e})"
    print(f"  controller, same observation{note}:")
    _print_ab(sc.n, ctrl_t)
    note = f"max|dq| Verlet vs kdtree {dq_verlet:.1e} m"
    if base is not None:
        dq_base = float(np.max(np.abs(q_end["library kdtree"] - q_end["baseline"])))
        note += f", library vs baseline {dq_base:.1e} m"
    print(
        f"  plane world, {world_steps} steps after step 0 (Verlet skin {VERLET_SKIN_M} m: "
        f"{100 * rebuilds / max(steps, 1):.0f} % of steps rebuild; {note}):"
    )
    _print_ab(sc.n, world_t)
    if base is not None:
        print(f"  (baseline: {base.path})")


def _print_ab(n: int, table: dict[str, list[float]]) -> None:
    ref = next(iter(table.values()))
    for name, vals in table.items():
        ratio = statistics.median(b / v for b, v in zip(ref, vals, strict=True))
        t = statistics.median(vals)
        print(
            f"    {name:<18} {1e3 * t:8.3f} ms/step  {n / t:11.3e} agent-steps/s"
            f"  speed-up x{ratio:4.2f}"
        )


# --------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N = 100 and 1000 only (seconds)")
    ap.add_argument("--sizes", type=int, nargs="+", help="agent counts (default 1e2..1e5)")
    ap.add_argument(
        "--dense-max",
        type=int,
        default=10_000,
        help="largest N for the dense N x N reference (default 10000)",
    )
    ap.add_argument("--budget", type=float, help="seconds of timed steps per case")
    ap.add_argument("--profile-n", type=int, help="N of the profile (default 10000; quick 1000)")
    ap.add_argument("--ab", action="store_true", help="interleaved A/B: Verlet list off/on")
    ap.add_argument(
        "--baseline",
        metavar="DIR",
        help="with --ab: also time the controllers/ package copy in DIR (e.g. an older commit)",
    )
    args = ap.parse_args(argv)
    if args.baseline and not args.ab:
        ap.error("--baseline needs --ab")
    sizes = args.sizes or ([100, 1000] if args.quick else [100, 1000, 10_000, 100_000])
    budget = args.budget or (0.15 if args.quick else 0.6)
    profile_n = args.profile_n or (1000 if args.quick else 10_000)

    print(
        f"numpy {np.__version__}, threads forced to 1 (OMP/OPENBLAS/MKL_NUM_THREADS=1); "
        f"library code from {Path(fl.__file__).parent}"
    )
    print(
        f"fixed density: lattice {SPACING_M} m +- {JITTER_M} m, road edges {EDGE_GAP_M} m from "
        f"outer rows, moving leader; timing budget {budget} s per case\n"
    )
    rows: list[Row] = []
    skipped: list[str] = []
    rebuild: dict[int, float] = {}
    for n in sizes:
        sc = make_scenario(n)
        for method in ("dense", "kdtree"):
            if method == "dense" and n > args.dense_max:
                gib = DENSE_BYTES_PER_N2 * n * n / 2**30
                skipped.append(
                    f"{n:>7} ctrl/dense     skipped: N x N arrays need ~{gib:.0f} GiB "
                    f"(> --dense-max {args.dense_max})"
                )
                continue
            rows.append(controller_row(sc, method, budget))
        rows.append(world_row(sc, budget)[0])
        row, rebuild[n] = world_row(sc, budget, VERLET_SKIN_M)
        rows.append(row)
    print_table(rows, skipped)
    print(
        "(ms/step = median CPU time, min = fastest step; reps 1 = one traced step only;\n"
        " peak = tracemalloc peak of one step (numpy buffers; cKDTree's C++ node arrays,"
        " O(N), are not traced);\n"
        f" plane/verlet: verlet_skin = {VERLET_SKIN_M} m, ms/step is the MEAN over the timed"
        " steps, rebuilds included; its peak is that of a rebuild step)"
    )
    print(
        "plane/verlet steps that rebuilt the list: "
        + ", ".join(f"N={n}: {100 * f:.0f} %" for n, f in rebuild.items())
    )

    by = {(r.n, r.case): r for r in rows}
    for n in sizes:
        if (n, "ctrl/dense") in by:
            ratio = by[n, "ctrl/dense"].med_s / by[n, "ctrl/kdtree"].med_s
            print(f"N = {n:>6}: kdtree is x{ratio:.1f} faster than dense")
    kd = [by[n, "ctrl/kdtree"] for n in sizes]
    if len(kd) > 1:
        per = [r.peak_bytes / r.n for r in kd]
        print(
            "memory per agent (kdtree), bytes: "
            + ", ".join(f"N={r.n}: {b:.0f}" for r, b in zip(kd, per, strict=True))
            + f"  (max/min {max(per) / min(per):.2f}: linear in N)"
        )
    for case in ("ctrl/kdtree", "plane/kdtree", "plane/verlet"):
        if (10_000, case) in by:
            r = by[10_000, case]
            best = r.n / r.min_s
            ok = "MET" if r.rate >= 1e6 else ("met by best step only" if best >= 1e6 else "NOT MET")
            print(
                f"target 1e6 agent-steps/s at N = 10000, {case:<12} (one core): {ok:<7} "
                f"({'mean' if case == 'plane/verlet' else 'median'} {r.rate:.3e}, "
                f"best step {best:.3e})"
            )

    if profile_n:
        profile(make_scenario(profile_n), steps=10 if profile_n >= 10_000 else 50)
    if args.ab:
        ab_compare(
            make_scenario(profile_n),
            rounds=5,
            budget_s=0.5 * budget,
            world_steps=40 if profile_n >= 10_000 else 100,
            base=load_baseline(args.baseline) if args.baseline else None,
        )


if __name__ == "__main__":
    main()
