"""``cosim sweep``: the argument parser and the command.

Every bad input (sweep file, option, output folder, Dask address) gives one
``error: ...`` line and exit status 2 before anything is written; a sweep with
failed runs exits 1 and says how to run them again.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cosim.cli.errors import run_command
from cosim.errors import ConfigError
from cosim.sweeps.execute import check_options, check_output, run_sweep
from cosim.sweeps.local_backend import START_METHODS
from cosim.sweeps.plan import default_out_dir, load_sweep
from cosim.sweeps.results import read_row


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="sweep TOML file, or a built-in sweep name (experiments/sweeps)")
    p.add_argument("--smoke", action="store_true",
                   help="the file's [smoke] variant: small grid, short runs")
    p.add_argument("--out", help="output folder (default outputs/sweeps/NAME[_smoke]); "
                                 "must be new or empty unless --resume or --replace")
    p.add_argument("--resume", action="store_true",
                   help="complete the sweep in --out: run only the grid points without "
                        "an ok row (the folder must hold the same plan)")
    p.add_argument("--replace", action="store_true",
                   help="delete the contents of --out first, then run the whole grid")
    p.add_argument("--workers", type=int,
                   help="local worker processes, >= 1 (default: the number of CPUs)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on this Dask scheduler (e.g. tcp://host:8786)")
    g.add_argument("--dask-local", type=int, metavar="N",
                   help="run on a local Dask cluster of N >= 1 worker processes")
    p.add_argument("--start-method", choices=START_METHODS, default="spawn",
                   help="local worker processes: fresh interpreters (spawn, default) or "
                        "forked from a preloaded server (forkserver: less start-up time)")
    p.add_argument("--dry-run", action="store_true",
                   help="validate the grid and list it; run nothing")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep)


def add_sweep_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``cosim sweep`` on an argparse subparsers object; returns the subparser."""
    p = subparsers.add_parser(
        "sweep", help="run a grid of scenarios in parallel (resumable; local or Dask)",
        description="Run a sweep file's grid of scenarios; one row per run in results.csv.",
    )
    _add_arguments(p)
    return p


def _runs(n: int) -> str:
    return f"{n} run" if n == 1 else f"{n} runs"


def cmd_sweep(ns: argparse.Namespace) -> int:
    resume, replace = ns.resume, getattr(ns, "replace", False)
    check_options(resume, replace, ns.workers, ns.scheduler, ns.dask_local, ns.start_method)
    if ns.out is not None and not ns.out.strip():
        raise ConfigError("--out must not be empty")
    plan = load_sweep(ns.file, smoke=ns.smoke)
    out = Path(ns.out) if ns.out else default_out_dir(plan)
    if not ns.dry_run:
        check_output(plan, out, resume=resume, replace=replace)
    axes = [f"{k} x{len(v)}" for k, v in plan.axes.items()]
    if plan.seeds is not None:
        axes.append(f"seeds x{len(plan.seeds)}")
    if plan.variants:
        axes.insert(0, f"variants x{len(plan.variants)}")
    print(f"sweep '{plan.name}': {_runs(len(plan.points))} ({', '.join(axes) or 'one point'}) "
          f"-> {out}/", flush=True)
    if ns.dry_run:
        for pt in plan.points:
            row = read_row(out / "runs" / pt.run_id)
            state = row["status"] if row else "todo"
            print(f"  {pt.run_id}  {state:<6}  {pt.label()}")
        return 0
    res = run_sweep(plan, out, resume=resume, workers=ns.workers, scheduler=ns.scheduler,
                    dask_local=ns.dask_local, progress=not ns.quiet,
                    start_method=ns.start_method, replace=replace)
    print(f"{_runs(res.n_run)} in {res.wall_time_s:.1f} s: {res.n_ok} ok, {res.n_failed} failed"
          + (f" ({res.n_skipped} already done)" if res.n_skipped else ""))
    for r in res.failed[:10]:
        print(f"  failed {r['run_id']}: {r.get('error', '')}")
    if len(res.failed) > 10:
        print(f"  ... and {len(res.failed) - 10} more (see results.csv)")
    print(f"results: {res.results_csv}")
    if res.failed:
        print(f"{_runs(len(res.failed))} failed: 'cosim sweep {ns.file}"
              f"{' --smoke' if ns.smoke else ''} --out {out} --resume' runs them again")
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    """``cosim sweep`` without the rest of the CLI: ``main(["FILE", "--smoke", ...])``."""
    ap = argparse.ArgumentParser(prog="cosim sweep",
                                 description="Run a grid of scenarios in parallel.")
    _add_arguments(ap)
    ns = ap.parse_args(argv)
    return run_command(ns.func, ns, "interrupted (finished runs are kept; use --resume)")
