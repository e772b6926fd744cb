"""The command line every check script shares (``--smoke``, ``--out``, ``--workers``,
``--set``, ``--evaluate-only``, ``--quiet``): run its sweep (resumable: a second call runs
only what is missing), then judge the folder. Bad options are one ``error:`` line, exit 2.

``--set KEY=VALUE`` (repeatable, VALUE is TOML, as ``cosim run --set``) overrides a key in
every run of the check, after the check's own overrides (a law option such as
``controller.params.row_approach_gain=3.5`` through the whole family); each run's
``config.toml`` records it."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from cosim.cli.errors import run_command
from cosim.errors import ConfigError


def main(argv: list[str] | None, name: str, doc: str,
         plan_data: Callable[[Path, bool], dict], report: Callable[[Path, bool], int]) -> int:
    """``python -m experiments.NAME``: ``plan_data(out, smoke)`` gives the sweep
    (``cosim.sweeps.plan.sweep_from_dict`` input), ``report(out, smoke)`` judges it and
    returns the exit status (0: every check passed)."""
    ap = argparse.ArgumentParser(prog=f"python -m experiments.{name}",
                                 description=doc.split("\n")[0])
    ap.add_argument("--smoke", action="store_true", help="1 seed, short runs")
    ap.add_argument("--out", help=f"output folder (default outputs/{name}[_smoke])")
    ap.add_argument("--workers", type=int, help="parallel runs (default: every core)")
    ap.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="override a key in every run, e.g. --set "
                         "controller.params.row_approach_gain=3.5 (repeatable; VALUE is TOML)")
    ap.add_argument("--evaluate-only", action="store_true",
                    help="judge the runs already in --out, run nothing")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")

    def cmd(ns: argparse.Namespace) -> int:
        from cosim.config.overrides import parse_assignments
        from cosim.sweeps.execute import run_sweep
        from cosim.sweeps.plan import sweep_from_dict

        if ns.workers is not None and ns.workers < 1:
            raise ConfigError(f"--workers must be >= 1 (got {ns.workers})")
        if ns.out is not None and not ns.out.strip():
            raise ConfigError("--out must not be empty")
        extra = parse_assignments(ns.set or [])
        out = Path(ns.out or (f"outputs/{name}" + ("_smoke" if ns.smoke else "")))
        if not ns.evaluate_only:
            plan = sweep_from_dict(with_overrides(plan_data(out, ns.smoke), extra))
            res = run_sweep(plan, out, resume=out.is_dir() and any(out.iterdir()),
                            workers=ns.workers, progress=not ns.quiet)
            print(f"{res.n_run} runs in {res.wall_time_s:.0f} s: {res.n_ok} ok, "
                  f"{res.n_failed} failed")
        elif not (out / "results.csv").is_file():
            raise ConfigError(f"--evaluate-only: no results.csv in {out}")
        return report(out, ns.smoke)

    return run_command(cmd, ap.parse_args(argv))


def with_overrides(data: dict, extra: dict) -> dict:
    """A check's sweep (``sweep_from_dict`` input) with the dotted-key overrides ``extra``
    set in every run: in the common overrides and in each variant (they win over both).
    A law parameter (``controller.params.*``) goes only to the runs of the check's own
    controller (the common ``controller.kind``): the arms of SUMO's drivers alone have no
    law to set."""
    if not extra:
        return data
    out = dict(data)
    common = data.get("overrides", {})
    if not data.get("variants"):
        out["overrides"] = {**common, **extra}
        return out
    law = {k: v for k, v in extra.items() if k.startswith("controller.params.")}
    rest = {k: v for k, v in extra.items() if k not in law}
    out["overrides"] = {**common, **rest}
    kind = common.get("controller.kind")
    out["variants"] = [{**v, **rest, **(law if v.get("controller.kind", kind) == kind else {})}
                       for v in data["variants"]]
    return out


def arm_of(variant: str) -> str:
    """The arm of a variant named ``ARM#SEED``."""
    return variant.split("#", 1)[0]


def numbers(frame: pd.DataFrame, col: str) -> np.ndarray:
    """Column ``col`` of ``frame`` as floats (NaN where missing or not a number)."""
    if col not in frame:
        return np.full(len(frame), np.nan)
    return pd.to_numeric(frame[col], errors="coerce").to_numpy(float)


def runs_by_arm(results: pd.DataFrame, share_of: Callable[[str], int]):
    """``(arm, CAV share %, the arm's runs that finished, whether one failed, collisions
    with a CAV per finished run (SUMO's check and ours; SUMO's counts 0 when it was off))``
    for each arm of a check sweep (variants named ``ARM#SEED``), in arm order."""
    res = results.assign(arm=results["variant"].map(arm_of))
    for arm, g in res.groupby("arm", sort=True):
        ok = g[g["status"] == "ok"]
        cav_coll = np.nan_to_num(numbers(ok, "collisions_sumo_cav")) + numbers(
            ok, "collisions_geometric_cav")
        yield arm, share_of(arm), ok, len(ok) < len(g), cav_coll


def check_rows(arm: str, criteria: list, n_runs: int, failed: bool) -> list[dict]:
    """One row per ``(name, values (seeds,), limit, unit)`` of ``criteria``: the worst
    seed and whether every one of the ``n_runs`` runs kept ``values <= limit`` (a run
    that failed, or no run, fails the check)."""
    rows = []
    for name, vals, limit, unit in criteria:
        good = np.isfinite(vals) & (vals <= limit)
        worst = float(np.nanmax(vals)) if np.isfinite(vals).any() else math.nan
        rows.append({"arm": arm, "check": name, "worst_seed": worst,
                     "criterion": f"<= {limit:g} {unit}", "n_runs": n_runs,
                     "passed": bool(good.all()) and not failed and n_runs > 0,
                     "note": "runs failed" if failed else ""})
    return rows
