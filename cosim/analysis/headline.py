"""The headline experiment's tables: capacity per arm, TUM's ring, the lane-free
gain at equal time gap, the ring fundamental diagram and the 5 %-HDV capacity loss.

Input: a sweep whose runs are variants named ``PART/ARM#RUN`` (``experiments/sweeps/
headline.toml``; :func:`cosim.analysis.tables.add_arms` adds ``arm`` and ``part``):

* ``bottleneck/ARM``: queue discharge at an in-network bottleneck
  (:mod:`cosim.metrics.capacity`): the road-limited capacity of each arm, with a t-based
  confidence interval over its valid runs (bottleneck active, not entrance-limited);
* ``tum_ring/cavNN``: TUM LaneFreeDrive's ring at 225 veh/km, flow (Edie over the ring)
  per CAV share beside TUM's published flows (:data:`TUM_RING_VPH`);
* ``ring_fd/MODE_Tx``: 100 % CAVs on a ring at several densities and time gaps, lane-free
  (``lanefree``) and in fixed rows (``fixed4``: 4 rows on 10.2 m; ``rows3``: 3 rows, three
  lanes' car following): the fundamental diagram and the lane-free gain at equal time gap.

Every table carries the comfort and safety columns: CAV-involved collisions (geometric
check), the smallest time to collision, TET as a share of the vehicle-time
(Minderhoud & Bovy 2001, TTC* = 1.5 s), the share of CAV- and HDV-steps with
``|a| > 3 m/s^2`` and the safety layer's activations per CAV-km. Points that are not
stationary (flow drift >= 2 %) or are entrance-limited are counted, never hidden.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from cosim.analysis.tables import SweepResults, t_interval

if TYPE_CHECKING:
    import pandas as pd

#: TUM LaneFreeDrive's ring results (1 km x 10.2 m, 225 veh/km), veh/h by CAV
#: share: their "Potential Lines" CAVs among their strip-based human model.
TUM_RING_VPH = {0.0: 6613.0, 0.1: 6688.0, 0.5: 7554.0, 0.9: 11745.0, 0.95: 13337.0,
                0.99: 15029.0, 1.0: 15504.0}
PARTS = ("bottleneck", "tum_ring", "ring_fd")
#: Readable names of the arms (the rest of the arm name after the part).
ARM_NAMES = {
    "lanefree": "lane-free flocking CAVs",
    "fixed": "CAVs in fixed rows (same law)",
    "cav95": "95 % CAVs, 5 % SL2015",
    "hdv_sl2015": "SL2015 drivers, lane-free",
    "hdv_lc2013_3lanes": "LC2013 drivers, 3 lanes (lane closed)",
    "fixed4": "CAVs in 4 fixed rows",
    "rows3": "CAVs in 3 fixed rows (lanes)",
}


def is_headline(res: SweepResults) -> bool:
    """True for a sweep of ``PART/ARM#RUN`` variants with at least one known part."""
    return "part" in res.table and bool(res.table["part"].isin(PARTS).any())


def _num(g: pd.DataFrame, col: str):
    import pandas as pd

    return pd.to_numeric(g[col], errors="coerce") if col in g else pd.Series(dtype=float)


def _flag_count(g: pd.DataFrame, col: str, value: bool) -> int:
    if col not in g:
        return 0
    return int((g[col].astype("boolean").fillna(not value) == value).sum())


def comfort_safety(g: pd.DataFrame) -> dict:
    """The comfort and safety columns over the runs ``g`` (see the module docstring)."""
    tet = _num(g, "tet_veh_s").sum()
    meas = _num(g, "measured_vehicle_s").sum()

    def mean(col):
        x = _num(g, col)
        return float(x.mean()) if x.notna().any() else math.nan

    ttc = _num(g, "min_ttc_s")
    return {
        "collisions_cav": int(_num(g, "collisions_geometric_cav").fillna(0).sum()),
        "collisions_hdv_only": int(_num(g, "collisions_geometric_hdv_only").fillna(0).sum()),
        "min_ttc_s": float(ttc.min()) if ttc.notna().any() else math.nan,
        "tet_share": float(tet / meas) if meas > 0 else math.nan,
        "harsh_share_cav": mean("harsh_accel_share_cav"),
        "harsh_share_hdv": mean("harsh_accel_share_hdv"),
        "safety_per_cav_km": mean("safety_activations_per_cav_km"),
        "safety_share_cav_steps": _activation_share(g),
    }


def _activation_share(g: pd.DataFrame) -> float:
    """Safety-layer activations (edge, side and speed rules) over the CAV-steps it saw, all
    runs of ``g`` pooled: an upper bound of the share of CAV-steps with an intervention
    (one step can count for several rules). NaN without CAV-steps."""
    acts = sum(_num(g, f"safety_{r}_activations").fillna(0).sum()
               for r in ("edge", "side", "speed"))
    steps = _num(g, "safety_agent_steps").fillna(0).sum()
    return float(acts / steps) if steps > 0 else math.nan


def _arm_label(arm: str, g: pd.DataFrame) -> str:
    name = arm.split("/", 1)[-1]
    base = name.split("_T")[0] if name.startswith(("lanefree_", "fixed4_", "rows3_")) else name
    label = ARM_NAMES.get(base, name.replace("_", " "))
    share = _num(g, "demand.cav_share")
    tg = _num(g, "controller.params.time_gap_s")
    if share.notna().any() and share.max() > 0 and tg.notna().any():
        label += f", T = {tg.iloc[0]:g} s"
    return label


def _part(res: SweepResults, part: str) -> pd.DataFrame:
    ok = res.ok
    return ok[ok["part"] == part] if "part" in ok else ok.iloc[:0]


def bottleneck_table(res: SweepResults, confidence: float = 0.95) -> pd.DataFrame:
    """Road-limited capacity per bottleneck arm: queue discharge over the valid runs.

    Columns: ``arm``, ``label``, ``n_runs``, ``n_valid`` (bottleneck active, not
    entrance-limited), ``n_stationary`` (valid runs with discharge drift < 2 %),
    ``capacity_vph`` and ``ci_low_vph`` / ``ci_high_vph`` (t-based, over the valid runs),
    ``downstream_flow_vph`` (mean Edie flow of all runs in the zone past the bottleneck),
    ``why_rejected``, then :func:`comfort_safety`.
    """
    import pandas as pd

    df = _part(res, "bottleneck")
    rows = []
    for arm, g in df.groupby("arm", sort=False):
        valid = g["bottleneck_active"].astype("boolean").fillna(False).astype(bool)
        valid &= ~g["entrance_limited"].astype("boolean").fillna(False).astype(bool)
        v = g[valid]
        mean, half, n = t_interval(_num(v, "discharge_flow_vph"), confidence)
        notes = g.loc[~valid, "capacity_note"].dropna().astype(str) if "capacity_note" in g \
            else pd.Series(dtype=str)
        row = {
            "arm": arm, "label": _arm_label(arm, g), "n_runs": len(g), "n_valid": n,
            "n_stationary": _flag_count(v, "discharge_stationary", True),
            "capacity_vph": mean,
            "ci_low_vph": mean - half if n > 1 else math.nan,
            "ci_high_vph": mean + half if n > 1 else math.nan,
            "downstream_flow_vph": float(_num(g, "edie_flow_vph").mean()),
            "why_rejected": notes.iloc[0] if len(notes) else "",
        }
        row.update(comfort_safety(g))
        rows.append(row)
    return pd.DataFrame(rows)


def tum_ring_table(res: SweepResults, confidence: float = 0.95) -> pd.DataFrame:
    """Flow on TUM's ring per CAV share beside TUM's published flow.

    Columns: ``cav_share``, ``n_runs``, ``n_stationary``, ``flow_vph`` (mean Edie flow
    over the runs), ``ci_low_vph`` / ``ci_high_vph`` (t-based; one run: none),
    ``speed_mps``, ``density_vpkm``, ``tum_vph``, ``ours_over_tum``, then
    :func:`comfort_safety`.
    """
    import pandas as pd

    df = _part(res, "tum_ring")
    rows = []
    for share, g in df.groupby(_num(df, "demand.cav_share"), sort=True):
        mean, half, n = t_interval(_num(g, "edie_flow_vph"), confidence)
        tum = TUM_RING_VPH.get(round(float(share), 4), math.nan)
        row = {
            "cav_share": float(share), "n_runs": n,
            "n_stationary": _flag_count(g, "stationary", True),
            "flow_vph": mean,
            "ci_low_vph": mean - half if n > 1 else math.nan,
            "ci_high_vph": mean + half if n > 1 else math.nan,
            "speed_mps": float(_num(g, "space_mean_speed_mps").mean()),
            "density_vpkm": float(_num(g, "edie_density_vpkm").mean()),
            "tum_vph": tum,
            "ours_over_tum": mean / tum if math.isfinite(tum) and tum > 0 else math.nan,
        }
        row.update(comfort_safety(g))
        rows.append(row)
    return pd.DataFrame(rows)


def ring_fd_runs(res: SweepResults) -> pd.DataFrame:
    """The ring arms' runs with ``mode`` (lanefree, fixed4, rows3), ``time_gap_s`` and
    ``label`` columns."""
    df = _part(res, "ring_fd").copy()
    if df.empty:
        return df
    names = df["arm"].str.split("/", n=1).str[-1]
    df["mode"] = names.str.split("_T").str[0]
    df["time_gap_s"] = _num(df, "controller.params.time_gap_s")
    df["label"] = [_arm_label(a, df[df["arm"] == a]) for a in df["arm"]]
    return df


def ring_fd_table(res: SweepResults) -> pd.DataFrame:
    """The ring fundamental diagram per arm and density (mean over runs): ``flow_vph``,
    ``speed_mps``, ``density_vpkm`` (Edie), ``flow_drift`` (largest |drift|),
    ``n_runs``, ``n_stationary``, ``time_gap_s``, ``mode``, then :func:`comfort_safety`."""
    import pandas as pd

    df = _part(res, "ring_fd")
    rows = []
    for (arm, level), g in df.groupby(["arm", "demand_level"], sort=True):
        drift = _num(g, "flow_drift")
        name = arm.split("/", 1)[-1]
        row = {
            "arm": arm, "mode": name.split("_T")[0], "label": _arm_label(arm, g),
            "time_gap_s": float(_num(g, "controller.params.time_gap_s").iloc[0]),
            "ring_density_vpkm": float(level), "n_runs": len(g),
            "n_stationary": _flag_count(g, "stationary", True),
            "flow_vph": float(_num(g, "edie_flow_vph").mean()),
            "speed_mps": float(_num(g, "space_mean_speed_mps").mean()),
            "density_vpkm": float(_num(g, "edie_density_vpkm").mean()),
            "flow_drift": float(drift.abs().max()) if drift.notna().any() else math.nan,
        }
        row.update(comfort_safety(g))
        rows.append(row)
    return pd.DataFrame(rows)


def lanefree_gain_table(fd: pd.DataFrame) -> pd.DataFrame:
    """Lane-free gain at equal time gap and density, from :func:`ring_fd_table`.

    Columns: ``time_gap_s``, ``ring_density_vpkm``, ``lanefree_vph``, ``fixed4_vph``,
    ``rows3_vph`` (flows, veh/h), ``gain_vs_fixed4`` and ``gain_vs_rows3``
    (lane-free / fixed - 1), ``all_stationary`` (every run of the three stationary).
    """
    import pandas as pd

    if fd.empty:
        return pd.DataFrame()
    rows = []
    for (tg, k), g in fd.groupby(["time_gap_s", "ring_density_vpkm"], sort=True):
        by = {r["mode"]: r for _, r in g.iterrows()}
        row = {"time_gap_s": float(tg), "ring_density_vpkm": float(k)}
        for mode in ("lanefree", "fixed4", "rows3"):
            row[f"{mode}_vph"] = float(by[mode]["flow_vph"]) if mode in by else math.nan
        for mode in ("fixed4", "rows3"):
            base = row[f"{mode}_vph"]
            row[f"gain_vs_{mode}"] = (row["lanefree_vph"] / base - 1.0
                                      if math.isfinite(base) and base > 0 else math.nan)
        row["all_stationary"] = bool((g["n_stationary"] == g["n_runs"]).all())
        rows.append(row)
    return pd.DataFrame(rows)


def capacity_loss(full: list[float], mixed: list[float], confidence: float = 0.95) -> dict:
    """Capacity loss ``1 - mean(mixed) / mean(full)`` with a Welch t-interval.

    Args:
        full: capacities (veh/h) of the runs with 100 % CAVs; mixed: with the HDVs.
    Returns: ``loss``, ``ci_low``, ``ci_high`` (the Welch interval of the difference of
    the means, over the mean of ``full``), ``n_full``, ``n_mixed``, ``separated`` (the
    interval excludes 0) and ``seeds_needed``: the fewest seeds per arm at which the Welch
    interval's half-width would fall below the observed difference, at the observed
    standard deviations (NaN when it cannot be estimated).
    """
    import numpy as np
    from scipy import stats

    a = np.asarray([x for x in full if x is not None and np.isfinite(x)], dtype=float)
    b = np.asarray([x for x in mixed if x is not None and np.isfinite(x)], dtype=float)
    out = {"loss": math.nan, "ci_low": math.nan, "ci_high": math.nan, "n_full": len(a),
           "n_mixed": len(b), "separated": False, "seeds_needed": math.nan}
    if len(a) == 0 or len(b) == 0 or a.mean() <= 0:
        return out
    diff = a.mean() - b.mean()
    out["loss"] = float(diff / a.mean())
    if len(a) < 2 or len(b) < 2:
        return out
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    se = math.sqrt(va + vb)
    if se == 0:
        out.update(ci_low=out["loss"], ci_high=out["loss"], separated=diff != 0,
                   seeds_needed=2.0)
        return out
    dof = (va + vb) ** 2 / (va ** 2 / (len(a) - 1) + vb ** 2 / (len(b) - 1))
    half = float(stats.t.ppf(0.5 + confidence / 2, dof)) * se
    out.update(ci_low=float((diff - half) / a.mean()), ci_high=float((diff + half) / a.mean()))
    out["separated"] = bool(abs(diff) > half)
    if diff != 0:  # n seeds per arm at the observed spreads, Welch's test as above
        sa2, sb2 = a.var(ddof=1), b.var(ddof=1)
        n = 2
        while n < 10_000:
            df_n = (sa2 + sb2) ** 2 / ((sa2 ** 2 + sb2 ** 2) / (n - 1)) if sa2 + sb2 > 0 \
                else 2 * n - 2
            if float(stats.t.ppf(0.5 + confidence / 2, df_n)) * math.sqrt((sa2 + sb2) / n) \
                    < abs(diff):
                break
            n += 1
        out["seeds_needed"] = float(n)
    return out


def hdv5_losses(res: SweepResults, confidence: float = 0.95) -> pd.DataFrame:
    """The 5 %-HDV capacity loss on TUM's ring (flow at 225 veh/km) and at the
    bottleneck (queue discharge of the valid runs): :func:`capacity_loss` per place."""
    import pandas as pd

    rows = []
    ring = _part(res, "tum_ring")
    if len(ring):
        share = _num(ring, "demand.cav_share")
        full = _num(ring[share == 1.0], "edie_flow_vph").tolist()
        mixed = _num(ring[share == 0.95], "edie_flow_vph").tolist()
        if full and mixed:
            rows.append({"where": "TUM ring, flow at 225 veh/km",
                         **capacity_loss(full, mixed, confidence)})
    bn = _part(res, "bottleneck")
    if len(bn):
        full = _valid_discharges(bn, "bottleneck/lanefree")
        mixed = _valid_discharges(bn, "bottleneck/cav95")
        if (bn["arm"] == "bottleneck/cav95").any():
            rows.append({"where": "bottleneck, queue discharge",
                         **capacity_loss(full, mixed, confidence)})
    return pd.DataFrame(rows)


def _valid_discharges(bn: pd.DataFrame, arm: str) -> list[float]:
    """Queue discharges (veh/h) of ``arm``'s valid runs (bottleneck active, not
    entrance-limited)."""
    valid = bn["bottleneck_active"].astype("boolean").fillna(False).astype(bool)
    valid &= ~bn["entrance_limited"].astype("boolean").fillna(False).astype(bool)
    return _num(bn[valid & (bn["arm"] == arm)], "discharge_flow_vph").tolist()


def bottleneck_gains(res: SweepResults, confidence: float = 0.95) -> pd.DataFrame:
    """Lane-free CAVs against every other bottleneck arm at the same bottleneck:
    ``gain = mean(lane-free) / mean(arm) - 1`` over the valid runs of each, with the
    Welch interval of :func:`capacity_loss` (of the difference of the means, over the
    arm's mean).

    Columns: ``arm``, ``label``, ``gain``, ``ci_low``, ``ci_high``, ``n_lanefree``,
    ``n_arm``, ``separated`` (the interval excludes 0).
    """
    import pandas as pd

    bn = _part(res, "bottleneck")
    rows = []
    if not len(bn) or not (bn["arm"] == "bottleneck/lanefree").any():
        return pd.DataFrame(rows)
    lanefree = _valid_discharges(bn, "bottleneck/lanefree")
    for arm, g in bn.groupby("arm", sort=False):
        if arm == "bottleneck/lanefree":
            continue
        c = capacity_loss(_valid_discharges(bn, arm), lanefree, confidence)
        rows.append({"arm": arm, "label": _arm_label(arm, g), "gain": -c["loss"],
                     "ci_low": -c["ci_high"], "ci_high": -c["ci_low"],
                     "n_lanefree": c["n_mixed"], "n_arm": c["n_full"],
                     "separated": c["separated"]})
    return pd.DataFrame(rows)


def headline_tables(res: SweepResults, confidence: float = 0.95) -> dict[str, pd.DataFrame]:
    """Every headline table by name (empty frames for parts the sweep lacks)."""
    fd = ring_fd_table(res)
    return {
        "headline_bottleneck": bottleneck_table(res, confidence),
        "headline_bottleneck_gain": bottleneck_gains(res, confidence),
        "headline_tum_ring": tum_ring_table(res, confidence),
        "headline_ring_fd": fd,
        "headline_lanefree_gain": lanefree_gain_table(fd),
        "headline_hdv5_loss": hdv5_losses(res, confidence),
    }


# --------------------------------------------------------------------------------------
# Markdown
# --------------------------------------------------------------------------------------


def _n(v, digits: int = 0) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if digits == 0:
        return f"{v:,.0f}".replace(",", " ")
    return f"{v:.{digits}f}"


def _pct(v, digits: int = 1) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{100 * v:.{digits}f} %"


def _ci(lo, hi) -> str:
    if lo is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return "-"
    return f"{_n(lo)}-{_n(hi)}"


#: A smallest time to collision above this reads "> TTC_SHOWN_S" (nobody closed in).
TTC_SHOWN_S = 100.0


def _ttc(v) -> str:
    if v is not None and math.isfinite(v) and v > TTC_SHOWN_S:
        return f"> {TTC_SHOWN_S:g}"
    return _n(v, 2)


def _comfort_cells(r) -> list[str]:
    return [f"{int(r['collisions_cav'])} / {int(r['collisions_hdv_only'])}", _ttc(r["min_ttc_s"]),
            _pct(r["tet_share"], 2),
            _pct(r["harsh_share_cav"], 2), _pct(r["harsh_share_hdv"], 2),
            _n(r["safety_per_cav_km"], 2), _pct(r["safety_share_cav_steps"], 2)]


COMFORT_HEAD = ("collisions CAV / HDV-only", "min TTC (s)", "TET share", "harsh (CAV)",
                "harsh (HDV)", "safety / CAV-km", "safety / CAV-step")


def _table(head, rows) -> list[str]:
    out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out + [""]


def headline_markdown(tables: dict[str, pd.DataFrame], confidence: float = 0.95,
                      figures: list[str] | None = None, title: str = "headline") -> str:
    """The headline report (Markdown): tables with their definitions, then figures."""
    lines = [f"# Headline results: {title}", ""]
    conf = f"{confidence:.0%}"
    bn = tables["headline_bottleneck"]
    if not bn.empty:
        lines += [
            "## Road-limited capacity: queue discharge at a bottleneck", "",
            "Slope of the N-curves at three cross-sections downstream of the bottleneck "
            "while it is active (queue upstream, unqueued flow downstream; Cassidy & Bertini "
            f"1999), mean over the valid runs with the {conf} t-interval. *valid*: "
            "bottleneck active and not entrance-limited; *stationary*: discharge drift "
            "< 2 % between the window's halves.", ""]
        rows = []
        for _, r in bn.iterrows():
            rows.append([r["label"], _n(r["capacity_vph"]), _ci(r["ci_low_vph"], r["ci_high_vph"]),
                         f"{int(r['n_valid'])}/{int(r['n_runs'])}",
                         f"{int(r['n_stationary'])}/{int(r['n_valid'])}",
                         *_comfort_cells(r), r["why_rejected"] or ""])
        lines += _table(("arm", "capacity (veh/h)", f"{conf} CI", "valid", "stationary",
                         *COMFORT_HEAD, "why rejected"), rows)
    gains = tables.get("headline_bottleneck_gain")
    if gains is not None and not gains.empty:
        lines += [
            "## Lane-free CAVs against the other arms at the bottleneck", "",
            "gain = mean discharge of the lane-free CAVs / the arm's - 1 over the valid runs "
            f"of each, Welch {conf} interval (of the difference of the means, over the arm's "
            "mean).", ""]
        rows = []
        for _, r in gains.iterrows():
            rows.append([r["label"], _pct(r["gain"]),
                         (f"{_pct(r['ci_low'])} to {_pct(r['ci_high'])}"
                          if math.isfinite(r["ci_low"]) else "-"),
                         f"{int(r['n_lanefree'])} / {int(r['n_arm'])}",
                         "yes" if r["separated"] else "no"])
        lines += _table(("against", "gain", f"{conf} CI", "valid runs lane-free / arm",
                         "separated from 0"), rows)
    tum = tables["headline_tum_ring"]
    if not tum.empty:
        lines += [
            "## TUM LaneFreeDrive's ring (1 km x 10.2 m, 225 veh/km)", "",
            "Edie flow over the whole ring after the warm-up, mean over runs "
            f"({conf} t-interval where there are several), beside TUM's published flows "
            "(loop detectors). *stationary*: flow drift < 2 % between the halves of the "
            "measured period.", ""]
        rows = []
        for _, r in tum.iterrows():
            rows.append([f"{100 * r['cav_share']:g} %", _n(r["flow_vph"]),
                         _ci(r["ci_low_vph"], r["ci_high_vph"]), _n(r["speed_mps"], 1),
                         f"{int(r['n_stationary'])}/{int(r['n_runs'])}", _n(r["tum_vph"]),
                         _n(r["ours_over_tum"], 2), *_comfort_cells(r)])
        lines += _table(("CAV share", "flow (veh/h)", f"{conf} CI", "speed (m/s)",
                         "stationary", "TUM (veh/h)", "ours / TUM", *COMFORT_HEAD), rows)
    loss = tables["headline_hdv5_loss"]
    if not loss.empty:
        lines += ["## Capacity loss with 5 % human drivers", "",
                  f"1 - mean(95 %) / mean(100 %), Welch {conf} interval; *seeds needed*: "
                  "seeds per arm at which the interval would exclude 0 at the observed "
                  "spread.", ""]
        rows = []
        for _, r in loss.iterrows():
            sep = "yes" if r["separated"] else "no"
            rows.append([r["where"], _pct(r["loss"]),
                         (f"{_pct(r['ci_low'])} to {_pct(r['ci_high'])}"
                          if math.isfinite(r["ci_low"]) else "-"),
                         f"{int(r['n_full'])} / {int(r['n_mixed'])}", sep,
                         _n(r["seeds_needed"]) if not r["separated"] else "-"])
        lines += _table(("where", "loss", f"{conf} CI", "runs 100 % / 95 %", "separated from 0",
                         "seeds needed"), rows)
    gain = tables["headline_lanefree_gain"]
    if not gain.empty:
        lines += ["## Lane-free gain at equal time gap (100 % CAVs, ring)", "",
                  "Edie flow (veh/h) of the same law: lane-free, in 4 fixed rows (10.2 m) and "
                  "in 3 fixed rows (three lanes' car following), at equal time gap and "
                  "density; gain = lane-free / fixed - 1.", ""]
        rows = []
        for _, r in gain.iterrows():
            rows.append([f"{r['time_gap_s']:g}", _n(r["ring_density_vpkm"]),
                         _n(r["lanefree_vph"]), _n(r["fixed4_vph"]), _n(r["rows3_vph"]),
                         _pct(r["gain_vs_fixed4"]), _pct(r["gain_vs_rows3"]),
                         "yes" if r["all_stationary"] else "no"])
        lines += _table(("time gap (s)", "density (veh/km)", "lane-free", "4 fixed rows",
                         "3 fixed rows", "gain vs 4 rows", "gain vs 3 rows",
                         "all stationary"), rows)
    fd = tables["headline_ring_fd"]
    if not fd.empty:
        lines += ["## Ring fundamental diagram (100 % CAVs)", ""]
        rows = []
        for _, r in fd.iterrows():
            rows.append([r["label"], _n(r["ring_density_vpkm"]), _n(r["flow_vph"]),
                         _n(r["speed_mps"], 1), _pct(r["flow_drift"]),
                         f"{int(r['n_stationary'])}/{int(r['n_runs'])}", *_comfort_cells(r)])
        lines += _table(("arm", "density (veh/km)", "flow (veh/h)", "speed (m/s)",
                         "drift (abs)", "stationary", *COMFORT_HEAD), rows)
    lines += [
        "Comfort and safety columns: *collisions*: geometric collision events (a pair of "
        "bodies that starts to overlap) involving a CAV / between human drivers only (all "
        "runs of the row); *min TTC*: smallest time to collision to the "
        "laterally overlapping leader; *TET share*: time spent with TTC <= 1.5 s over the "
        "vehicle-time (Minderhoud & Bovy 2001); *harsh*: share of CAV- / HDV-steps with "
        "|acceleration| > 3 m/s^2 after the warm-up; *safety / CAV-km*: safety-layer "
        "activations (edge, side and speed rules, per CAV-step) per CAV-km driven; "
        "*safety / CAV-step*: the same activations over the CAV-steps (an upper bound of "
        "the share of CAV-steps with an intervention).", ""]
    if figures:
        lines += ["## Figures", ""]
        lines += [f"![{f.rsplit('/', 1)[-1].removesuffix('.png')}]({f})" for f in figures]
        lines.append("")
    return "\n".join(lines)
