"""Command line: ``cosim run``, ``cosim list``, ``cosim plane``, ``cosim sweep``, ``cosim analyse``.

Every user error (bad config, missing network, SUMO failing) prints one line
``error: ...`` on stderr and exits with status 2; no traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from datetime import datetime
from pathlib import Path

from cosim.analysis.analysis import add_analyse_parser
from cosim.cli.errors import run_command
from cosim.config.builtins import builtin_scenarios
from cosim.errors import CosimError
from cosim.sweeps.sweep import add_sweep_parser

SUMMARY_KEYS = [
    ("edie_flow_vph", "flow (Edie, zone)", "veh/h", "{:.0f}"),
    ("edie_density_vpkm", "density (Edie, zone)", "veh/km", "{:.1f}"),
    ("space_mean_speed_mps", "space-mean speed", "m/s", "{:.2f}"),
    ("vehicles_inserted", "vehicles inserted", "veh", "{:.0f}"),
    ("collisions_sumo_cav", "collisions with a CAV (SUMO)", "", "{:.0f}"),
    ("collisions_geometric_cav", "collisions with a CAV (geometric)", "", "{:.0f}"),
    ("collisions_sumo_hdv_only", "collisions HDV-only (SUMO)", "", "{:.0f}"),
    ("collisions_geometric_hdv_only", "collisions HDV-only (geometric)", "", "{:.0f}"),
    ("boundary_vehicle_steps", "boundary violations (all)", "veh-steps", "{:.0f}"),
    ("boundary_vehicle_steps_cav", "boundary violations (CAVs)", "veh-steps", "{:.0f}"),
    ("min_gap_m", "min bumper-to-bumper gap", "m", "{:.2f}"),
    ("min_side_clearance_m", "min side clearance", "m", "{:.2f}"),
    ("median_time_headway_s", "median time headway", "s", "{:.2f}"),
    ("min_ttc_s", "min time to collision", "s", "{:.2f}"),
    ("tet_share", "time with TTC <= TTC* (TET share)", "", "{:.2e}"),
    ("safety_speed_activations", "safety: speed clips", "CAV-steps", "{:.0f}"),
    ("safety_side_activations", "safety: side clips", "CAV-steps", "{:.0f}"),
    ("teleports", "teleports", "", "{:.0f}"),
    ("wall_time_s", "wall time", "s", "{:.1f}"),
]




def _resolve_scenario(arg: str | None):
    from cosim.config.scenario import default_scenario, load_scenario

    if arg is None:
        return default_scenario()
    path = Path(arg)
    if path.suffix == ".toml" or path.exists():
        return load_scenario(path)
    named = builtin_scenarios()
    if arg in named:
        return load_scenario(named[arg])
    raise CosimError(
        f"no scenario file or built-in scenario named {arg!r} (see 'cosim list')"
    )


def format_summary(row: dict) -> str:
    """The run summary as an aligned two-column table."""
    lines = []
    for key, label, unit, fmt in SUMMARY_KEYS:
        if key in row:
            val = row[key]
            if val is None or (isinstance(val, float) and val != val):
                lines.append(f"  {label:<36} {'n/a':>10}")
                continue
            try:
                text = fmt.format(val)
            except (TypeError, ValueError):
                text = str(val)
            lines.append(f"  {label:<36} {text:>10} {unit}")
    return "\n".join(lines)


def cmd_run(ns) -> int:
    from cosim.sim.runner import run_scenario

    sc = _resolve_scenario(ns.scenario)
    if ns.seed is not None:
        sc = sc.with_seed(ns.seed)
    if ns.duration is not None:
        sc = dataclasses.replace(
            sc, scenario=dataclasses.replace(sc.scenario, duration_s=ns.duration)
        )
    out = Path(ns.out) if ns.out else Path("outputs") / (
        f"{sc.scenario.name}_seed{sc.scenario.seed}_{datetime.now():%Y%m%d-%H%M%S}"
    )
    print(f"running scenario '{sc.scenario.name}' (seed {sc.scenario.seed}, "
          f"{sc.scenario.duration_s:g} s simulated) ...", flush=True)
    res = run_scenario(sc, out_dir=out, gui=ns.gui, progress=not ns.quiet)
    print(format_summary(res.summary.iloc[0].to_dict()))
    print(f"outputs written to {out}/ (summary.csv, intervals.csv, flock.csv, ...)")
    return 0


def cmd_list(ns) -> int:
    import tomllib

    print("built-in scenarios (cosim run NAME):")
    for name, path in builtin_scenarios().items():
        desc = ""
        try:
            desc = tomllib.loads(path.read_text()).get("scenario", {}).get("description", "")
        except Exception:
            desc = "(unreadable)"
        print(f"  {name:<22} {desc}")
    from cosim.plane.scenarios import SCENARIOS

    print("plane-world reproductions (cosim plane NAME):")
    for name in SCENARIOS:
        print(f"  {name}")
    return 0


def cmd_plane(ns) -> int:
    from cosim.plane.scenarios import SCENARIOS, run_plane_scenario

    if ns.name not in SCENARIOS:
        raise CosimError(f"unknown plane scenario {ns.name!r}; choose from {sorted(SCENARIOS)}")
    kwargs = {}
    if ns.saturation is not None:
        if ns.name != "seed001":
            raise CosimError("--saturation applies to seed001 only")
        kwargs["speed_limit_mps"] = ns.saturation
    res = run_plane_scenario(ns.name, seed=ns.seed, duration_s=ns.duration, **kwargs)
    out = Path(ns.out or Path("outputs") / f"plane_{ns.name}")
    res.write(out)
    m = res.metrics
    print(m.iloc[[0, len(m) // 2, -1]].T.to_string())
    if ns.plot:
        from cosim.plane.plots import plot_plane_result

        for p in plot_plane_result(res, out):
            print(f"figure: {p}")
    print(f"outputs written to {out}/")
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="cosim", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run a scenario (default: the built-in default scenario)")
    r.add_argument("scenario", nargs="?", help="scenario TOML file or built-in name")
    r.add_argument("--seed", type=int, help="override the scenario's seed")
    r.add_argument("--duration", type=float, help="override the simulated time, s")
    r.add_argument("--out", help="output folder (default outputs/NAME_seedS_TIME)")
    r.add_argument("--gui", action="store_true", help="watch the run in sumo-gui (TraCI)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=cmd_run)
    ls = sub.add_parser("list", help="list built-in scenarios")
    ls.set_defaults(func=cmd_list)
    pl = sub.add_parser("plane", help="run a seed reproduction in the SUMO-free plane world")
    pl.add_argument("name")
    pl.add_argument("--seed", type=int)
    pl.add_argument("--duration", type=float)
    pl.add_argument("--saturation", type=float, help="seed001: speed limit, m/s")
    pl.add_argument("--out")
    pl.add_argument("--plot", action="store_true", help="write PNG figures")
    pl.set_defaults(func=cmd_plane)
    add_sweep_parser(sub)
    add_analyse_parser(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    ns = build_parser().parse_args(argv)
    return run_command(ns.func, ns)


if __name__ == "__main__":
    sys.exit(main())
