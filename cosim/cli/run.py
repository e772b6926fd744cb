"""``cosim run``: one scenario, a summary table on the console, CSV outputs in a folder."""

from __future__ import annotations

import math
import sys
from datetime import datetime
from pathlib import Path

from cosim.config.overrides import parse_assignments
from cosim.errors import ConfigError

#: Where :data:`SUMMARY_KEYS` lists the travel times of every origin -> destination pair.
TRAVEL_TIMES = "travel_time_<origin>_<destination>_s"

#: (summary key, label, unit, format) of the console summary, in order.
SUMMARY_KEYS = [
    ("edie_flow_vph", "flow (Edie, zone)", "veh/h", "{:.0f}"),
    ("edie_density_vpkm", "density (Edie, zone)", "veh/km", "{:.1f}"),
    ("space_mean_speed_mps", "space-mean speed", "m/s", "{:.2f}"),
    ("vehicles_inserted", "vehicles inserted", "veh", "{:.0f}"),
    ("vehicles_not_inserted", "vehicles never inserted (entrance)", "veh", "{:.0f}"),
    ("collisions_sumo_cav", "collision events with a CAV (SUMO)", "events", "{:.0f}"),
    ("collisions_geometric_cav", "collision events with a CAV (ours)", "events", "{:.0f}"),
    ("collisions_sumo_hdv_only", "collision events HDV-only (SUMO)", "events", "{:.0f}"),
    ("collisions_geometric_hdv_only", "collision events HDV-only (ours)", "events", "{:.0f}"),
    ("boundary_vehicle_steps", "boundary violations (all)", "veh-steps", "{:.0f}"),
    ("boundary_vehicle_steps_cav", "boundary violations (CAVs)", "veh-steps", "{:.0f}"),
    ("max_standstill_s", "longest standstill", "s", "{:.1f}"),
    ("vehicles_stopped_long", "vehicles stopped > 30 s", "veh", "{:.0f}"),
    ("blocked_windows", "blocked windows (zero flow, queue)", "windows", "{:.0f}"),
    ("min_gap_m", "min bumper-to-bumper gap", "m", "{:.2f}"),
    ("min_side_clearance_m", "min side clearance", "m", "{:.2f}"),
    ("median_time_headway_s", "median time headway", "s", "{:.2f}"),
    ("min_ttc_s", "min time to collision", "s", "{:.2f}"),
    ("tet_share", "time with TTC <= TTC* (TET share)", "", "{:.2e}"),
    ("safety_speed_activations", "safety: speed clips", "CAV-steps", "{:.0f}"),
    ("safety_side_activations", "safety: side clips", "CAV-steps", "{:.0f}"),
    ("safety_edge_activations", "safety: edge clips", "CAV-steps", "{:.0f}"),
    ("missed_exits_cav", "missed exits (CAVs)", "veh", "{:.0f}"),
    ("missed_exits_hdv", "missed exits (HDVs)", "veh", "{:.0f}"),
    (TRAVEL_TIMES, "travel time", "s", "{:.1f}"),
    ("teleports", "teleports", "veh", "{:.0f}"),
    ("wall_time_s", "wall time", "s", "{:.1f}"),
]

#: Why a figure can be missing from a summary (shown instead of a bare "n/a").
MISSING = {
    "collisions_sumo_cav": "SUMO's check off",
    "collisions_sumo_hdv_only": "SUMO's check off",
    "min_gap_m": "no leader seen",
    "min_side_clearance_m": "nobody side by side",
    "median_time_headway_s": "no moving follower",
    "min_ttc_s": "nobody closing in",
    "space_mean_speed_mps": "zone empty",
}


def _expanded(row: dict) -> list[tuple[str, str, str, str]]:
    """:data:`SUMMARY_KEYS` with the travel-time entry expanded into one line per
    origin -> destination pair in ``row`` (``travel_time_<origin>_<destination>_s``)."""
    out = []
    for key, label, unit, fmt in SUMMARY_KEYS:
        if key != TRAVEL_TIMES:
            out.append((key, label, unit, fmt))
            continue
        for k in row:
            if k.startswith("travel_time_") and k.endswith("_s") and k.count("_") == 4:
                o, d = k[len("travel_time_"):-2].split("_")
                out.append((k, f"{label} {o} -> {d}", unit, fmt))
    return out


def format_summary(row: dict) -> str:
    """The run summary as an aligned table; a missing figure says why."""
    lines = []
    for key, label, unit, fmt in _expanded(row):
        if key not in row:
            continue
        val = row[key]
        if val is None or (isinstance(val, float) and not math.isfinite(val)):
            if isinstance(val, float) and val == math.inf:
                lines.append(f"  {label:<38} {'none':>10}   ({MISSING.get(key, 'never seen')})")
            else:
                why = "no trip arrived" if key.startswith("travel_time_") else "not measured"
                lines.append(f"  {label:<38} {'n/a':>10}   ({MISSING.get(key, why)})")
            continue
        if unit == "s" and isinstance(val, int | float) and val > 1e4:
            lines.append(f"  {label:<38} {'> 10 000':>10} {unit}")
            continue
        try:
            text = fmt.format(val)
        except (TypeError, ValueError):
            text = str(val)
        lines.append(f"  {label:<38} {text:>10} {unit}")
    return "\n".join(lines)


class Progress:
    """Progress of a run: a bar on a terminal, a plain line every 10 % otherwise."""

    def __init__(self, name: str, enabled: bool = True) -> None:
        self.name = name
        self.enabled = enabled
        self.tty = sys.stderr.isatty()
        self.bar = None
        self._next = 0.1

    def __call__(self, k: int, n: int) -> None:
        if not self.enabled:
            return
        if self.tty:
            if self.bar is None:
                from tqdm import tqdm

                self.bar = tqdm(total=n, unit="step", desc=self.name, leave=False)
            self.bar.update(1)
        elif k >= self._next * n:
            print(f"  {self.name}: {100 * k / n:.0f} % ({k} of {n} steps)", flush=True)
            self._next += 0.1

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def run_overrides(ns) -> dict:
    """The ``--set`` items and the shortcut options as dotted-key overrides."""
    overrides = parse_assignments(ns.set or [])
    for opt, key in (("seed", "scenario.seed"), ("duration", "scenario.duration_s"),
                     ("warmup", "scenario.warmup_s")):
        value = getattr(ns, opt, None)
        if value is not None:
            overrides[key] = value
    if getattr(ns, "trajectories", False):
        overrides["outputs.trajectories"] = True
    return overrides


def cmd_run(ns) -> int:
    from cosim.config.scenario import load_scenario
    from cosim.output_dir import check_output_dir, prepare_output_dir, safe_name
    from cosim.sim.runner import run_scenario

    check_out_option(ns.out)
    sc = load_scenario(ns.scenario, run_overrides(ns))
    run = sc.scenario
    out = Path(ns.out) if ns.out else Path("outputs") / safe_name(
        f"{run.name}_seed{run.seed}_{datetime.now():%Y%m%d-%H%M%S}"
    )
    check_output_dir(out, replace=ns.replace, what="run output folder")
    if ns.gui:
        from cosim.sumo.gui import check_display

        check_display()
    print(f"running scenario '{run.name}' (seed {run.seed}, {run.duration_s:g} s simulated, "
          f"{sc.controller.kind} CAVs, {run.world} world) ...", flush=True)
    progress = Progress(run.name, enabled=not ns.quiet)
    try:
        res = run_scenario(sc, gui=ns.gui, progress=progress)
    finally:
        progress.close()
    prepare_output_dir(out, replace=ns.replace, what="run output folder")
    res.write(out)
    print(format_summary(res.summary.iloc[0].to_dict()))
    extra = "".join(f"{name}, " for name, table in (("trajectories.csv", res.trajectories),
                                                     ("trips.csv", res.trips))
                    if table is not None)
    print(f"outputs written to {out}/ (summary.csv, intervals.csv, flock.csv, collisions.csv, "
          f"{extra}config.toml, meta.json)")
    return 0


def add_run_parser(sub) -> None:
    r = sub.add_parser(
        "run", help="run a scenario (default: the built-in default scenario)",
        description="Run one scenario and write its outputs. Options override the "
                    "scenario file; --set overrides any key.")
    r.add_argument("scenario", nargs="?",
                   help="a scenario TOML file or a built-in name (cosim list); default: default")
    r.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scenario key, e.g. --set demand.cav_share=0.8 "
                        "--set controller.kind=vicsek (repeatable; VALUE is TOML)")
    r.add_argument("--seed", type=int, help="the scenario's seed (0 .. 2^31-1)")
    r.add_argument("--duration", type=float, help="simulated time, s")
    r.add_argument("--warmup", type=float, help="time before measuring, s")
    r.add_argument("--trajectories", action="store_true",
                   help="also write trajectories.csv (one row per vehicle and step)")
    r.add_argument("--out", help="output folder (default outputs/NAME_seedS_TIME)")
    r.add_argument("--replace", action="store_true",
                   help="clear a non-empty --out folder first (else it is refused)")
    r.add_argument("--gui", action="store_true", help="watch the run in sumo-gui (TraCI)")
    r.add_argument("--quiet", action="store_true", help="no progress display")
    r.set_defaults(func=cmd_run)


def check_out_option(out: str | None) -> None:
    """``--out`` given as an empty or blank string: refused (it would mean the default)."""
    if out is not None and not out.strip():
        raise ConfigError("--out must name a folder, got an empty string")


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise ConfigError(f"{text!r} is not a number") from None
    if not (math.isfinite(v) and v > 0):
        raise ConfigError(f"{text!r} must be a finite number > 0")
    return v
