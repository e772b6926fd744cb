"""Olfati-Saber controller and plane-world speed and memory versus N (one core).

Prints, for N = 100, 1 000, 10 000 and 100 000 agents at a fixed density, the
controller's time per step, agent-steps per second and the tracemalloc peak of
one step, for the dense reference neighbour search and the KD-tree, plus a
PlaneWorld end-to-end figure (observation + controller + Euler step + leader,
metrics and trajectory recording off). Then a profile of one step at
N = 10 000 split into neighbour search, alpha pair math, scatter, walls, gamma.

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
    ... --proposed         # run with the patches proposed in benchmarks/README.md
    ... --ab               # interleaved current-vs-proposed speed-ups at the profile N

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
import math  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Callable  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from dataclasses import dataclass  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

import controllers.flocking as fl  # noqa: E402
import controllers.neighbours as nb  # noqa: E402
import controllers.olfati_saber as osb  # noqa: E402
from controllers.flocking import OlfatiSaberController  # noqa: E402
from controllers.observation import Observation  # noqa: E402
from controllers.params import FlockingParams  # noqa: E402
from controllers.references import VirtualLeader  # noqa: E402
from cosim.plane import PlaneWorld  # noqa: E402

MIB = 2.0**20
SPACING_M = 5.7  # lattice spacing (d = 6 m, r = 7.2 m: 4 neighbours each)
JITTER_M = 0.3
EDGE_GAP_M = 2.0  # outer rows' side to road edge (< r_wall = 3.6 m)
SIZES_M = (4.5, 1.8)  # length, width
DT_S = 0.01  # s, as the seed scenarios (dt = 0.1 s is unstable with these gains)
DENSE_BYTES_PER_N2 = 46.0  # measured tracemalloc peak of the dense search / N^2 (m = 2)


# --------------------------------------------------------------------------- scenario
def bench_params(method: str) -> FlockingParams:
    """Default gains; bounded (sigma_1) gamma so the flock keeps its density while timed."""
    return FlockingParams(neighbour_search=method, gamma_position="sigma1")


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

    def observation(self) -> Observation:
        n = self.n
        return Observation(
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


# --------------------------------------------------------------------------- proposed patches
def proposed_neighbour_pairs_tree(x, radius, period=None):
    """neighbours.neighbour_pairs_tree with ``balanced_tree=False`` (faster build)."""
    n = len(x)
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    pts, boxsize = nb.tree_points(x, radius, period)
    tree = cKDTree(pts, boxsize=boxsize, balanced_tree=False)
    pairs = tree.query_pairs(np.nextafter(radius, 0.0), output_type="ndarray")
    return pairs.astype(np.int64, copy=False)


def proposed_neighbour_pairs(x, radius, period=None, method="auto"):
    """neighbours.neighbour_pairs with one int64 key sort instead of np.lexsort (same result)."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    if method == "dense" or (method == "auto" and n <= nb.DENSE_MAX_N):
        pairs = nb.neighbour_pairs_dense(x, radius, period)
    elif method in ("kdtree", "auto"):
        pairs = nb.neighbour_pairs_tree(x, radius, period)
    else:
        raise ValueError(f"neighbour search method must be dense, kdtree or auto, not {method!r}")
    if len(pairs):
        key = pairs[:, 0] * n + pairs[:, 1]  # i < j < n, so the key orders (i, j) lexicographically
        key.sort()
        pairs = np.empty((len(key), 2), dtype=np.int64)
        np.divmod(key, n, out=(pairs[:, 0], pairs[:, 1]))
    return pairs


def proposed_alpha_term(self, obs, s):
    """flocking.OlfatiSaberController.alpha_term, same law, fewer passes over the pairs."""
    p = self.params
    x = obs.q * s
    period = None if obs.period_s is None else obs.period_s * s[0]
    pairs = fl.neighbour_pairs(x, p.r, period, p.neighbour_search)
    u, _ = alpha_pair_forces(self, obs, s, pairs)
    return u, len(pairs)


def alpha_pair_forces(self, obs, s, pairs):
    """Alpha forces (N, m) of the given pairs and the adjacency a_ij per pair.

    np.take instead of fancy row indexing (~9x faster gathers with numpy 2.x);
    |z|^2 by column adds (np.sum over a length-2 axis is slow); one sqrt shared
    by the sigma-norm and n_ij; rho_h evaluated once (it is both the bump of
    phi_alpha and a_ij); scatter as bincount(i) - bincount(j) per axis
    without concatenating. Pairs beyond r contribute exact zeros.
    """
    p = self.params
    n, m = obs.q.shape
    if len(pairs) == 0:
        return np.zeros((n, m)), np.zeros(0)
    i = np.ascontiguousarray(pairs[:, 0])
    j = np.ascontiguousarray(pairs[:, 1])
    z = obs.relative(np.take(obs.q, j, axis=0) - np.take(obs.q, i, axis=0)) * s
    dp = np.take(obs.p, j, axis=0) - np.take(obs.p, i, axis=0)
    sq = z[:, 0] * z[:, 0]
    for k in range(1, m):
        sq += z[:, k] * z[:, k]
    root = np.sqrt(1.0 + p.epsilon * sq)
    z_sigma = (root - 1.0) / p.epsilon
    rho = osb.rho_h(z_sigma / self.r_alpha, p.h_alpha)  # a_ij and the bump of phi_alpha
    w = (p.c1_alpha * rho * osb.phi(z_sigma - self.d_alpha, p.a, p.b)) / root
    c2 = p.c2_alpha * rho
    u = np.empty((n, m))
    for k in range(m):
        fk = (w * s[k]) * z[:, k] + c2 * dp[:, k]  # f_ij on i, -f_ij on j
        u[:, k] = np.bincount(i, fk, minlength=n) - np.bincount(j, fk, minlength=n)
    return u, rho


def _sum_sq(z):
    """``np.sum(z * z, axis=-1)`` for m <= 3 by column adds: same bits, ~5x faster."""
    out = z[..., 0] * z[..., 0]
    for k in range(1, z.shape[-1]):
        out += z[..., k] * z[..., k]
    return out


def proposed_sigma_norm(z, epsilon, axis=-1):
    z = np.asarray(z, dtype=float)
    sq = _sum_sq(z) if axis in (-1, z.ndim - 1) else np.sum(z * z, axis=axis)
    return (np.sqrt(1.0 + epsilon * sq) - 1.0) / epsilon


def proposed_sigma_grad(z, epsilon):
    z = np.asarray(z, dtype=float)
    return z / np.sqrt(1.0 + epsilon * _sum_sq(z))[..., None]


def proposed_sigma_1_vec(z):
    z = np.asarray(z, dtype=float)
    return z / np.sqrt(1.0 + _sum_sq(z))[..., None]


VERLET_SKIN_M = 0.5  # Verlet-list skin (scaled metres)
VERLET_STATS = {"steps": 0, "rebuilds": 0}


def proposed_alpha_term_verlet(self, obs, s):
    """alpha_term with a Verlet neighbour list (pairs within r + skin, reused).

    The list stays valid while every agent's displacement since the rebuild,
    minus the mean displacement, is below skin / 2: a common translation does
    not change pair distances, so no pair can have come from beyond r + skin.
    Pairs between r and r + skin give exact zeros (rho_h = 0). KD-tree only;
    the dense reference path is untouched.
    """
    p = self.params
    n, m = obs.q.shape
    if p.neighbour_search == "dense" or (p.neighbour_search == "auto" and n <= nb.DENSE_MAX_N):
        return proposed_alpha_term(self, obs, s)
    x = obs.q * s
    period = None if obs.period_s is None else obs.period_s * s[0]
    cache = getattr(self, "_verlet", None)
    valid = (
        cache is not None
        and cache["x"].shape == x.shape
        and cache["period"] == period
        and np.array_equal(cache["ids"], obs.ids)
    )
    if valid:
        dx = x - cache["x"]
        if period is not None:
            dx[:, 0] = (dx[:, 0] + 0.5 * period) % period - 0.5 * period
        dx -= dx.mean(axis=0)
        valid = float(_sum_sq(dx).max()) <= (0.5 * VERLET_SKIN_M) ** 2
    VERLET_STATS["steps"] += 1
    if not valid:
        VERLET_STATS["rebuilds"] += 1
        pairs = fl.neighbour_pairs(x, p.r + VERLET_SKIN_M, period, p.neighbour_search)
        cache = {"x": x.copy(), "period": period, "ids": np.array(obs.ids), "pairs": pairs}
        self._verlet = cache
    u, rho = alpha_pair_forces(self, obs, s, cache["pairs"])
    return u, int(np.count_nonzero(rho))


P_NEIGHBOURS = (
    (nb, "neighbour_pairs_tree", proposed_neighbour_pairs_tree),
    (nb, "neighbour_pairs", proposed_neighbour_pairs),
    (fl, "neighbour_pairs", proposed_neighbour_pairs),
)
P_ALPHA = ((OlfatiSaberController, "alpha_term", proposed_alpha_term),)
P_SUMSQ = tuple(
    (mod, name, func)
    for mod in (osb, fl)
    for name, func in (
        ("sigma_norm", proposed_sigma_norm),
        ("sigma_grad", proposed_sigma_grad),
        ("sigma_1_vec", proposed_sigma_1_vec),
    )
)
PATCHES = P_NEIGHBOURS + P_ALPHA + P_SUMSQ
P_VERLET = (
    P_NEIGHBOURS + P_SUMSQ + ((OlfatiSaberController, "alpha_term", proposed_alpha_term_verlet),)
)


@contextmanager
def patched(targets):
    saved = [(obj, name, getattr(obj, name)) for obj, name, _ in targets]
    try:
        for obj, name, new in targets:
            setattr(obj, name, new)
        yield
    finally:
        for obj, name, old in saved:
            setattr(obj, name, old)


# --------------------------------------------------------------------------- measurement
@dataclass
class Row:
    n: int
    case: str
    pairs_per_agent: float
    med_s: float  # median CPU time per step
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

    def row(self, n: int, case: str, pairs_per_agent: float) -> Row:
        return Row(
            n,
            case,
            pairs_per_agent,
            statistics.median(self.cpu),
            min(self.cpu),
            statistics.median(self.wall),
            len(self.cpu),
            self.peak_bytes,
        )


def measure(step: Callable[[], object], budget_s: float, max_reps: int = 2000) -> Timing:
    """CPU and wall times per call of ``step`` and the tracemalloc peak of one call.

    CPU time (``time.process_time``; one thread) is what the table reports: on
    a shared machine it is far less noisy than wall time. The first call is
    traced (peak of what it allocates); if it is slow (more than half the
    budget) it is also the only timing, else untraced calls are timed until
    the budget (wall seconds) is spent, at least 3.
    """
    gc.collect()
    tracemalloc.start()
    w0, c0 = time.perf_counter(), time.process_time()
    step()
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    if wall > 0.5 * budget_s:
        return Timing([cpu], [wall], peak)
    cpus: list[float] = []
    walls: list[float] = []
    deadline = time.perf_counter() + budget_s
    while len(cpus) < max_reps and (len(cpus) < 3 or time.perf_counter() < deadline):
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


def world_row(sc: Scenario, budget_s: float) -> Row:
    ctrl = OlfatiSaberController(bench_params("kdtree"))
    world = make_world(sc, ctrl)
    world.step()  # step 0 computes the flock metrics once; later steps do not
    timing = measure(world.step, budget_s)
    return timing.row(sc.n, "plane/kdtree", ctrl.last_terms.n_pairs / sc.n)


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


_MODULE_FUNCS = (
    "neighbour_pairs",
    "cross_pairs",
    "scatter_add",
    "sigma_norm",
    "sigma_grad",
    "phi_alpha",
    "phi_beta",
    "adjacency",
    "sigma_1_vec",
)
_METHODS = (
    "compute",
    "alpha_term",
    "circle_term",
    "vehicle_term",
    "wall_term",
    "_one_wall",
    "_beta_pair",
    "gamma_term",
)
_KERNELS = {"sigma_norm", "sigma_grad", "phi_alpha", "adjacency"}


def _category(path: str) -> str:
    parts = path.split("/")
    if "neighbour_pairs" in parts:
        return "neighbour search (KD-tree + pair sort)"
    if "alpha_term" in parts:
        if parts[-1] == "scatter_add":
            return "alpha scatter (concat + bincount)"
        if parts[-1] in _KERNELS:
            return "alpha pair math: sigma/phi/rho kernels"
        return "alpha pair math: gathers, products"
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
        print(f"  {name:<44} {1e3 * t:8.3f} ms  {100 * t / total:5.1f} %")
    print("  by call path (exclusive time):")
    for path, t in sorted(prof.excl.items(), key=lambda kv: -kv[1]):
        if t / steps >= 0.005 * total:
            print(f"    {path:<56} {1e3 * t / steps:8.3f} ms")


# --------------------------------------------------------------------------- A/B
def _world_run(sc: Scenario, steps: int):
    """CPU seconds per step of ``steps`` plane-world steps, and the final positions."""
    world = make_world(sc, OlfatiSaberController(bench_params("kdtree")))
    world.step()  # step 0: flock metrics, not timed
    gc.collect()
    c0 = time.process_time()
    for _ in range(steps):
        world.step()
    return (time.process_time() - c0) / steps, world.q


def ab_compare(sc: Scenario, rounds: int, budget_s: float, world_steps: int) -> None:
    """Interleaved current-vs-proposed timing; speed-ups are medians of per-round ratios."""
    obs = sc.observation()
    ctrl = OlfatiSaberController(bench_params("kdtree"))
    u_cur = ctrl.compute(obs).copy()
    with patched(PATCHES):
        u_new = ctrl.compute(obs).copy()
    err = float(np.max(np.abs(u_new - u_cur)) / max(np.max(np.abs(u_cur)), 1e-300))
    variants = {
        "current": (),
        "P1 neighbours": P_NEIGHBOURS,
        "P2 alpha_term": P_ALPHA,
        "P3 sum of sq.": P_SUMSQ,
        "P1+P2+P3": PATCHES,
    }
    worlds = {"current": (), "P1+P2+P3": PATCHES, "P1..P3 + Verlet": P_VERLET}
    ctrl_t: dict[str, list[float]] = defaultdict(list)
    world_t: dict[str, list[float]] = defaultdict(list)
    q_end: dict[str, np.ndarray] = {}
    for _ in range(rounds):
        for name, patches in variants.items():
            with patched(patches):
                cpu = measure(lambda: ctrl.compute(obs), budget_s).cpu
            ctrl_t[name].append(statistics.median(cpu))
        for name, patches in worlds.items():
            with patched(patches):
                t, q_end[name] = _world_run(sc, world_steps)
            world_t[name].append(t)
    print(
        f"\nA/B at N = {sc.n}, CPU time, {rounds} interleaved rounds "
        f"(speed-up = median over rounds of current / variant):"
    )
    print(f"  controller, same observation (P1+P2+P3 max|du|/max|u| = {err:.1e}):")
    for table, label in ((ctrl_t, "ctrl"), (world_t, "world")):
        if label == "world":
            dq = float(np.max(np.abs(q_end["P1..P3 + Verlet"] - q_end["current"])))
            rate = VERLET_STATS["rebuilds"] / max(VERLET_STATS["steps"], 1)
            print(
                f"  plane world, {world_steps} steps after step 0 (Verlet skin {VERLET_SKIN_M} m: "
                f"{100 * rate:.0f} % of steps rebuild; max |dq| vs current {dq:.1e} m):"
            )
        base = table["current"]
        for name, vals in table.items():
            ratio = statistics.median(b / v for b, v in zip(base, vals, strict=True))
            t = statistics.median(vals)
            print(
                f"    {name:<16} {1e3 * t:8.3f} ms/step  {sc.n / t:11.3e} agent-steps/s"
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
    ap.add_argument("--proposed", action="store_true", help="apply the proposed patches")
    ap.add_argument("--ab", action="store_true", help="current vs proposed, interleaved")
    args = ap.parse_args(argv)
    sizes = args.sizes or ([100, 1000] if args.quick else [100, 1000, 10_000, 100_000])
    budget = args.budget or (0.15 if args.quick else 0.6)
    profile_n = args.profile_n or (1000 if args.quick else 10_000)

    print(
        f"numpy {np.__version__}, threads forced to 1 (OMP/OPENBLAS/MKL_NUM_THREADS=1); "
        f"{'PROPOSED patches applied' if args.proposed else 'current code'}"
    )
    print(
        f"fixed density: lattice {SPACING_M} m +- {JITTER_M} m, road edges {EDGE_GAP_M} m from "
        f"outer rows, moving leader; timing budget {budget} s per case\n"
    )
    rows: list[Row] = []
    skipped: list[str] = []
    with patched(PATCHES if args.proposed else ()):
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
            rows.append(world_row(sc, budget))
        print_table(rows, skipped)
        print(
            "(ms/step = median CPU time, min = fastest step; reps 1 = one traced step only;\n"
            " peak = tracemalloc peak of one step (numpy buffers; cKDTree's C++ node arrays,"
            " O(N), are not traced))"
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
        if (10_000, "ctrl/kdtree") in by:
            r = by[10_000, "ctrl/kdtree"]
            best = r.n / r.min_s
            ok = "MET" if r.rate >= 1e6 else ("met by best step only" if best >= 1e6 else "NOT MET")
            print(
                f"target 1e6 agent-steps/s at N = 10000 (controller, one core): {ok} "
                f"(median {r.rate:.3e}, best {best:.3e})"
            )

        if profile_n:
            profile(make_scenario(profile_n), steps=10 if profile_n >= 10_000 else 50)
    if args.ab:
        ab_compare(
            make_scenario(profile_n),
            rounds=5,
            budget_s=0.5 * budget,
            world_steps=40 if profile_n >= 10_000 else 100,
        )


if __name__ == "__main__":
    main()
