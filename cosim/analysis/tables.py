"""A sweep's results as tables: fundamental diagrams, capacity, safety, boundary, flock.

Input: a sweep output directory (``results.csv``, ``sweep.json``, ``runs/<run_id>/``; see
:mod:`cosim.sweeps.results`). Only ``ok`` runs enter the statistics; failed runs are listed.

A **series** is one curve of the fundamental diagram: a CAV share and a controller
(``demand.cav_share``, ``controller.kind``), plus the variant and any other swept
parameter except the demand level and the seed. The **demand level** is the swept
``demand.inflow_vph`` (open roads, veh/h) or ``demand.ring_density_vpkm`` (rings, veh/km).

*Arms*: a sweep whose variants are all named ``ARM#RUN`` (one variant per run, e.g. the
headline's ``bottleneck/lanefree#2``) is grouped by ``arm`` (the name before ``#``)
instead of by variant, and its demand level is ``demand_level``: the ring density
(veh/km) of ring runs, the inflow (veh/h) of the others.

*Rejected points*: every run row carries ``stationary`` (its interval flows drifted by
less than 2 %, :mod:`cosim.metrics.capacity`) and ``entrance_limited`` (the entrance, not
the road, set its flow); ``fd_runs`` shows both, ``capacity`` counts them and says
whether the maximum is such a point, and the figures draw non-stationary points hollow.

Tables (each a DataFrame; :mod:`cosim.analysis.report` writes them as CSV and Markdown):

* ``fd_runs``: one point per run: Edie flow (veh/h), density (veh/km), space-mean speed
  (m/s) over the measurement period (the run's summary row);
* ``fd_intervals``: one point per measurement interval of every run (its intervals.csv);
* ``fd_summary``: per series and demand level, the mean over seeds with a t-based
  confidence interval (``*_ci``: half-width);
* ``capacity``: per series, the maximum sustained flow: for each seed the maximum over
  demand levels of the run's mean Edie flow (mean over the measurement intervals after
  warm-up), then the mean over seeds with a t-based confidence interval
  (``capacity_ci_low/high_vph``); ``at_grid_edge`` is true when that maximum is reached
  at the highest demand tested (the capacity may be higher); ``n_entrance_limited_max``
  and ``n_not_stationary_max`` count the seeds whose maximum is an entrance-limited
  (a lower bound of the road's capacity: an entrance service rate) or non-stationary
  point;
* ``discharge``: per series with a bottleneck, the queue-discharge flow (road-limited
  capacity, :mod:`cosim.metrics.capacity`) over the runs whose bottleneck was active and
  not entrance-limited (``n_valid`` of ``n_runs``), mean with a t-based CI, and how many
  of them were stationary;
* ``safety``: collisions (sum over seeds), minimum gaps and side clearances (minimum),
  time headways, safety-layer activations, per series and demand level;
* ``boundary``: boundary violations (vehicle-steps, vehicles, worst excursion, share);
* ``flock``: flock metrics (minimum CAV distance, velocity alignment, connectivity) and
  controller clip rates;
* ``failed``: failed runs and their reasons.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # numpy and pandas are imported where used: `cosim --help` stays fast
    import pandas as pd

from cosim.errors import ConfigError

DEMAND_COLUMNS = ("demand.inflow_vph", "demand.ring_density_vpkm")
#: Always part of a series (the brief: one curve per CAV share and controller).
CORE_SERIES = ("demand.cav_share", "controller.kind")
FD_COLUMNS = ("edie_density_vpkm", "edie_flow_vph", "space_mean_speed_mps")
#: Flags of a run that reject it as a point of a fundamental diagram or capacity.
FLAG_COLUMNS = ("stationary", "flow_drift", "entrance_limited")
#: Separates an arm from the rest of a variant's name (``bottleneck/lanefree#2``).
ARM_SEPARATOR = "#"

SAFETY_AGG = (
    ("collisions_sumo_cav", "sum"),
    ("collisions_geometric_cav", "sum"),
    ("collisions_sumo_hdv_only", "sum"),
    ("collisions_geometric_hdv_only", "sum"),
    ("teleports", "sum"),
    ("min_gap_m", "min"),
    ("min_cav_gap_m", "min"),
    ("min_side_clearance_m", "min"),
    ("median_time_headway_s", "mean"),
    ("p05_time_headway_s", "min"),
    ("min_ttc_s", "min"),
    ("min_cav_ttc_s", "min"),
    ("tet_veh_s", "sum"),
    ("tit_veh_s2", "sum"),
    ("measured_vehicle_s", "sum"),
    ("safety_speed_activations", "sum"),
    ("safety_side_activations", "sum"),
    ("safety_edge_activations", "sum"),
    ("vehicle_steps", "sum"),
    ("harsh_accel_share_cav", "mean"),
    ("harsh_accel_share_hdv", "mean"),
    ("safety_activations_per_cav_km", "mean"),
)
BOUNDARY_AGG = (
    ("boundary_vehicle_steps", "sum"),
    ("boundary_vehicle_steps_cav", "sum"),
    ("boundary_vehicles", "sum"),
    ("worst_boundary_excursion_m", "max"),
    ("vehicle_steps", "sum"),
)
FLOCK_AGG = (
    ("flock_min_agent_distance_m", "min"),
    ("flock_velocity_alignment", "mean"),
    ("flock_largest_component_share", "mean"),
)


# --------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------


@dataclass
class SweepResults:
    """A sweep's results table with what the analysis needs to group it."""
    root: Path
    table: pd.DataFrame
    plan: dict = field(default_factory=dict)
    demand_col: str | None = None
    series_cols: list[str] = field(default_factory=list)

    @property
    def ok(self) -> pd.DataFrame:
        return self.table[self.table["status"] == "ok"].copy()

    @property
    def failed(self) -> pd.DataFrame:
        return self.table[self.table["status"] != "ok"].copy()

    def run_dir(self, run_id: str) -> Path:
        return self.root / "runs" / str(run_id)


def load_results(path: str | Path) -> SweepResults:
    """Load ``results.csv`` (a sweep directory or the CSV itself) and ``sweep.json``."""
    import pandas as pd

    path = Path(path)
    csv = path if path.suffix == ".csv" else path / "results.csv"
    if not csv.is_file():
        raise ConfigError(f"no results table at {csv} (run 'cosim sweep' first)")
    try:
        table = pd.read_csv(csv)
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError,
            OSError) as exc:
        raise ConfigError(f"{csv}: unreadable results table: {exc}") from None
    for col in ("run_id", "status"):
        if col not in table:
            raise ConfigError(f"{csv}: not a sweep results table (no column {col!r})")
    root = csv.parent
    plan = {}
    if (root / "sweep.json").is_file():
        try:
            plan = json.loads((root / "sweep.json").read_text())
        except ValueError:
            plan = {}
    table = _normalise_flags(table)
    if _has_arms(table):
        table = add_arms(table)
        return SweepResults(root, table, plan, "demand_level", ["arm"])
    demand = demand_column(table, plan)
    return SweepResults(root, table, plan, demand, series_columns(table, plan, demand))


def _normalise_flags(table: pd.DataFrame) -> pd.DataFrame:
    """Boolean flag columns as booleans (CSV may hold True/False strings or blanks)."""
    for col in ("stationary", "entrance_limited", "bottleneck_active", "queue_at_entrance",
                "discharge_stationary"):
        if col in table:
            table[col] = table[col].map(_as_bool).astype("boolean")
    return table


def _as_bool(v):
    if isinstance(v, str):
        return {"true": True, "false": False}.get(v.strip().lower())
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return None
    return bool(v)


def _has_arms(table: pd.DataFrame) -> bool:
    if "variant" not in table:
        return False
    names = table["variant"].dropna().astype(str)
    return len(names) > 0 and bool(names.str.contains(ARM_SEPARATOR, regex=False).all())


def add_arms(table: pd.DataFrame) -> pd.DataFrame:
    """Columns ``arm`` (variant name before ``#``), ``part`` (arm before ``/``, or "") and
    ``demand_level`` (ring density on rings, veh/km; else inflow, veh/h)."""
    import numpy as np

    table = table.copy()
    names = table["variant"].astype(str)
    table["arm"] = names.str.split(ARM_SEPARATOR, n=1).str[0]
    table["part"] = [a.split("/", 1)[0] if "/" in a else "" for a in table["arm"]]
    dens = pd_numeric(table, "demand.ring_density_vpkm")
    inflow = pd_numeric(table, "demand.inflow_vph")
    ring = (table["network.kind"] == "ring") if "network.kind" in table else np.isfinite(dens)
    table["demand_level"] = np.where(ring, dens, inflow)
    return table


def pd_numeric(table: pd.DataFrame, col: str):
    """``table[col]`` as floats (NaN where missing or not a number)."""
    import numpy as np
    import pandas as pd

    if col not in table:
        return np.full(len(table), np.nan)
    return pd.to_numeric(table[col], errors="coerce").to_numpy(float)


def demand_column(table: pd.DataFrame, plan: dict | None = None) -> str | None:
    """The demand level column: the sweep's demand axis, else the one that varies."""
    plan = plan or {}
    if plan.get("demand_axis") in table:
        return plan["demand_axis"]
    for col in DEMAND_COLUMNS:
        if col in table and table[col].nunique(dropna=True) > 1:
            return col
    for col in DEMAND_COLUMNS:
        if col in table and table[col].notna().any():
            return col
    return None


def is_parameter_column(name: str) -> bool:
    """Whether a results column is a scenario parameter (``section.key``, e.g.
    ``demand.cav_share``), not a measured value whose name holds a decimal point (a
    cross-section's flow, ``flow_x339.09_vph``)."""
    return re.fullmatch(r"[a-z_]+(\.[a-z_][a-z0-9_]*)+", str(name)) is not None


def series_columns(
    table: pd.DataFrame, plan: dict | None = None, demand: str | None = None
) -> list[str]:
    """Columns that tell the curves apart: variant, CAV share, controller, other axes
    (those that vary; with variants, not those a variant fixes)."""

    plan = plan or {}
    candidates = ["variant"] + list(CORE_SERIES)
    candidates += list(plan.get("axes", {}))
    candidates += [c for v in plan.get("variants", []) for c in v if c != "name"]
    candidates += [c for c in table.columns if is_parameter_column(c)]
    out = []
    for c in dict.fromkeys(candidates):
        if c not in table or c == demand or c in DEMAND_COLUMNS or c == "scenario.seed":
            continue
        varies = table[c].nunique(dropna=False) > 1
        if c in CORE_SERIES or varies:
            out.append(c)
    if "variant" in out:  # drop parameters a variant fixes (e.g. its network.kind)
        by_variant = table.groupby("variant", dropna=False)
        out = [c for c in out if c == "variant" or c in CORE_SERIES
               or by_variant[c].nunique(dropna=False).max() > 1]
    return out


# --------------------------------------------------------------------------------------
# Statistics
# --------------------------------------------------------------------------------------


def t_interval(values: Sequence[float], confidence: float = 0.95) -> tuple[float, float, int]:
    """Mean, t-based confidence half-width (NaN for fewer than 2 values) and count."""
    import numpy as np
    from scipy import stats

    x = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=float)
    n = len(x)
    if n == 0:
        return math.nan, math.nan, 0
    mean = float(x.mean())
    if n < 2:
        return mean, math.nan, n
    sd = float(x.std(ddof=1))
    half = float(stats.t.ppf(0.5 + confidence / 2.0, n - 1) * sd / math.sqrt(n))
    return mean, half, n


def _group(df: pd.DataFrame, keys: list[str]):
    return df.groupby(keys, dropna=False, sort=True) if keys else [((), df)]


def _key_dict(keys: list[str], key) -> dict:
    if not isinstance(key, tuple):
        key = (key,)
    return dict(zip(keys, key, strict=True))


def fd_runs(res: SweepResults) -> pd.DataFrame:
    """One fundamental-diagram point per ok run (its summary row)."""
    ok = res.ok
    cols = ["run_id", *res.series_cols]
    if res.demand_col:
        cols.append(res.demand_col)
    cols += [c for c in ("seed", *FD_COLUMNS, *FLAG_COLUMNS) if c in ok]
    return ok[cols].reset_index(drop=True)


def fd_intervals(res: SweepResults) -> pd.DataFrame:
    """Every measurement interval of every ok run (its intervals.csv), with the run's keys."""
    import pandas as pd

    frames = []
    keys = ["run_id", *res.series_cols] + ([res.demand_col] if res.demand_col else [])
    keys += ["seed"] if "seed" in res.table else []
    for _, row in res.ok.iterrows():
        path = res.run_dir(row["run_id"]) / "intervals.csv"
        if not path.is_file():
            continue
        try:
            iv = pd.read_csv(path)
        except pd.errors.EmptyDataError:
            continue
        if iv.empty:
            continue
        for k in reversed(keys):
            iv.insert(0, k, row[k])
        frames.append(iv)
    if not frames:
        return pd.DataFrame(columns=keys + ["t_start_s", "t_end_s", *FD_COLUMNS])
    return pd.concat(frames, ignore_index=True)


def fd_summary(res: SweepResults, confidence: float = 0.95) -> pd.DataFrame:
    """Per series and demand level: mean density, flow and speed over seeds, with CIs."""
    import pandas as pd

    keys = res.series_cols + ([res.demand_col] if res.demand_col else [])
    rows = []
    for key, g in _group(res.ok, keys):
        row = _key_dict(keys, key)
        row["n_runs"] = len(g)
        for col in FD_COLUMNS:
            if col in g:
                mean, half, _ = t_interval(g[col], confidence)
                row[col] = mean
                row[f"{col}_ci"] = half
        rows.append(row)
    return pd.DataFrame(rows)


def capacity_table(res: SweepResults, confidence: float = 0.95) -> pd.DataFrame:
    """Maximum sustained flow per series, with a t-based CI across seeds.

    For each seed: the maximum over demand levels of the run's mean Edie flow (veh/h).
    Columns: ``capacity_vph`` (mean over seeds), ``capacity_ci_low_vph``,
    ``capacity_ci_high_vph``, ``capacity_sd_vph``, ``n_seeds``, ``demand_at_max``
    (median over seeds of the demand level giving the maximum),
    ``density_at_max_vpkm``, ``speed_at_max_mps`` (means over seeds),
    ``capacity_of_mean_curve_vph`` (maximum over demand levels of the seed-mean flow),
    ``n_demand_levels``, ``at_grid_edge``.
    """
    import numpy as np
    import pandas as pd

    ok = res.ok
    demand = res.demand_col
    if ok.empty or "edie_flow_vph" not in ok:
        return pd.DataFrame()
    keys = res.series_cols
    rows = []
    for key, g in _group(ok, keys):
        g = g[np.isfinite(g["edie_flow_vph"].astype(float))]
        if g.empty:
            continue
        row = _key_dict(keys, key)
        by_seed = g.groupby("seed") if "seed" in g else [(0, g)]
        peaks = []
        for _, gs in by_seed:
            peaks.append(gs.loc[gs["edie_flow_vph"].idxmax()])
        peaks = pd.DataFrame(peaks)
        mean, half, n = t_interval(peaks["edie_flow_vph"], confidence)
        row.update(
            capacity_vph=mean,
            capacity_ci_low_vph=mean - half if n > 1 else math.nan,
            capacity_ci_high_vph=mean + half if n > 1 else math.nan,
            capacity_sd_vph=float(peaks["edie_flow_vph"].std(ddof=1)) if n > 1 else math.nan,
            n_seeds=n,
        )
        if "edie_density_vpkm" in peaks:
            row["density_at_max_vpkm"] = float(peaks["edie_density_vpkm"].mean())
        if "space_mean_speed_mps" in peaks:
            row["speed_at_max_mps"] = float(peaks["space_mean_speed_mps"].mean())
        for flag, col in (("entrance_limited", "n_entrance_limited_max"),
                          ("stationary", "n_not_stationary_max")):
            if flag in peaks:
                vals = peaks[flag].astype("boolean").fillna(flag == "entrance_limited")
                row[col] = int(vals.sum()) if flag == "entrance_limited" else int((~vals).sum())
        if demand:
            levels = np.sort(g[demand].dropna().unique())
            row["demand_at_max"] = float(peaks[demand].median())
            curve = g.groupby(demand)["edie_flow_vph"].mean()
            row["capacity_of_mean_curve_vph"] = float(curve.max())
            row["n_demand_levels"] = len(levels)
            row["at_grid_edge"] = bool(len(levels) > 1 and curve.idxmax() == levels[-1])
        rows.append(row)
    return pd.DataFrame(rows)


def discharge_table(res: SweepResults, confidence: float = 0.95) -> pd.DataFrame:
    """Queue-discharge flow (road-limited capacity) per series, over its valid runs.

    A run is valid when its bottleneck was active (``bottleneck_active``) and it was not
    entrance-limited. Columns: ``n_runs`` (runs with a bottleneck), ``n_valid``,
    ``n_stationary`` (valid runs whose discharge drifted by less than 2 %),
    ``discharge_vph`` (mean over the valid runs), ``discharge_ci_low_vph`` /
    ``discharge_ci_high_vph`` (t-based), ``discharge_sd_vph``, ``bottleneck`` (kind),
    ``why_rejected`` (the first rejected run's ``capacity_note``). Empty without
    bottleneck runs.
    """
    import pandas as pd

    ok = res.ok
    if ok.empty or "discharge_flow_vph" not in ok or "bottleneck_kind" not in ok:
        return pd.DataFrame()
    kind = ok["bottleneck_kind"]  # NaN (a float column when no run found one) or a name
    ok = ok[kind.notna() & (kind.astype(str) != "")]
    if ok.empty:
        return pd.DataFrame()
    rows = []
    for key, g in _group(ok, res.series_cols):
        row = _key_dict(res.series_cols, key)
        valid = g["bottleneck_active"].fillna(False).astype(bool)
        if "entrance_limited" in g:
            valid &= ~g["entrance_limited"].fillna(False).astype(bool)
        v = g[valid]
        mean, half, n = t_interval(v["discharge_flow_vph"].astype(float), confidence)
        n_stat = 0
        if len(v) and "discharge_stationary" in v:
            n_stat = int(v["discharge_stationary"].fillna(False).astype(bool).sum())
        row.update(
            bottleneck=str(g["bottleneck_kind"].iloc[0]), n_runs=len(g), n_valid=n,
            n_stationary=n_stat,
            discharge_vph=mean,
            discharge_ci_low_vph=mean - half if n > 1 else math.nan,
            discharge_ci_high_vph=mean + half if n > 1 else math.nan,
            discharge_sd_vph=(float(v["discharge_flow_vph"].astype(float).std(ddof=1))
                              if n > 1 else math.nan),
        )
        bad = g[~valid]
        note = ""
        if len(bad) and "capacity_note" in bad:
            notes = bad["capacity_note"].dropna().astype(str)
            note = notes.iloc[0] if len(notes) else ""
        row["why_rejected"] = note
        rows.append(row)
    return pd.DataFrame(rows)


def _aggregate(res: SweepResults, spec, extra_prefix: str | None = None) -> pd.DataFrame:
    import pandas as pd

    ok = res.ok
    keys = res.series_cols + ([res.demand_col] if res.demand_col else [])
    spec = [(c, a) for c, a in spec if c in ok]
    if extra_prefix:
        spec += [(c, "mean") for c in ok.columns if c.startswith(extra_prefix)]
    rows = []
    for key, g in _group(ok, keys):
        row = _key_dict(keys, key)
        row["n_runs"] = len(g)
        for col, agg in spec:
            vals = pd.to_numeric(g[col], errors="coerce")
            row[f"{col}_{agg}"] = getattr(vals, agg)() if vals.notna().any() else math.nan
        rows.append(row)
    return pd.DataFrame(rows)


def safety_table(res: SweepResults) -> pd.DataFrame:
    """Collisions (sums over seeds), minimum gaps and clearances, headways, time to
    collision, per series x demand.

    ``collisions_cav_per_1e6_vehicle_steps`` = collision events involving a CAV (the
    geometric check, which always runs: a pair of rectangles that starts to overlap) per
    million vehicle-steps in the measurement zone. SUMO's own list
    (``collisions_sumo_*``, one entry per step of overlap) is empty when a run set
    ``outputs.sumo_collisions = false``.

    Time to collision (:mod:`cosim.metrics.traffic`): ``min_ttc_s_min`` over all runs;
    ``tet_share`` = Minderhoud & Bovy's time exposed below ``TTC*`` (summed over seeds)
    / the measured vehicle-time, the share of vehicle-time spent closing in on a leader
    with TTC at most ``TTC*``; ``tit_veh_s2_sum`` their time-integrated TTC.
    """
    import numpy as np

    df = _aggregate(res, SAFETY_AGG)
    if {"tet_veh_s_sum", "measured_vehicle_s_sum"} <= set(df.columns):
        df["tet_share"] = df["tet_veh_s_sum"] / df["measured_vehicle_s_sum"].replace(0, np.nan)
    if {"collisions_geometric_cav_sum", "vehicle_steps_sum"} <= set(df.columns):
        steps = df["vehicle_steps_sum"].replace(0, np.nan)
        df["collisions_cav_per_1e6_vehicle_steps"] = (
            df["collisions_geometric_cav_sum"] / steps * 1e6
        )
    return df


def boundary_table(res: SweepResults) -> pd.DataFrame:
    """Boundary violations per series x demand; ``boundary_share`` = violating vehicle-steps
    / vehicle-steps."""
    import numpy as np

    df = _aggregate(res, BOUNDARY_AGG)
    if {"boundary_vehicle_steps_sum", "vehicle_steps_sum"} <= set(df.columns):
        df["boundary_share"] = df["boundary_vehicle_steps_sum"] / df["vehicle_steps_sum"].replace(
            0, np.nan
        )
    return df


def flock_table(res: SweepResults) -> pd.DataFrame:
    """Flock metrics and controller clip rates (mean over seeds) per series x demand."""
    return _aggregate(res, FLOCK_AGG, extra_prefix="clip_rate_")


def failures_table(res: SweepResults) -> pd.DataFrame:
    cols = [c for c in ("run_id", "variant", *res.series_cols, res.demand_col, "seed", "error")
            if c and c in res.table]
    return res.failed[list(dict.fromkeys(cols))].reset_index(drop=True)


