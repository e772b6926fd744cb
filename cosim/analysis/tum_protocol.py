"""TUM LaneFreeDrive's ring protocol: our runs measured and averaged as TUM measured theirs.

Input: a sweep like ``experiments/sweeps/tum_protocol.toml``: a 1 km ring, densities
``demand.ring_density_vpkm`` (veh/km) x CAV shares ``demand.cav_share`` x seeds, each run
counting the vehicles that cross ``x = 339.09 m`` (:data:`DETECTOR_COLUMN`, veh/h, the mean
of its 300 s intervals from 2 100 to 3 900 s).

What TUM did (repository TUM-VT/LaneFreeDrive, tag Paper-TRB-2024 = commit 484f37c,
``python_src/results_analysis.ipynb``): one E1 detector on the ring's single 10.2 m lane at
339.09 m, 300 s intervals; a run's flow is the mean of the intervals that begin after
2 000 s and at or before 3 600 s; their table (:data:`TUM_TABLE_VPH`) is the mean of the
runs' flows over the densities 50, 100, ..., 400 veh/km and seeds 1-3 per CAV share. So
their "225 veh/km" is the mean of the densities, not a density they ran; the comparable
number of ours is :func:`share_table`'s ``flow_vph``, not a run at 225 veh/km.

Their per-density flows are not printed in the notebook; :data:`TUM_FIGURE_VPH` holds them
as read off its figure (cell 29, means over their 3 seeds; about +-150 veh/h), for
:func:`density_table` and the fundamental-diagram figure only.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from cosim.analysis.headline import comfort_safety
from cosim.analysis.tables import SweepResults, t_interval

if TYPE_CHECKING:
    import pandas as pd

#: The cross-section of TUM's detector on their 1 000 m ring, m.
DETECTOR_X_M = 339.09
#: Our runs' column for it: vehicles crossing it, veh/h (mean of the measured intervals).
DETECTOR_COLUMN = f"flow_x{DETECTOR_X_M:g}_vph"

#: TUM's table (notebook cell 28): flow, veh/h, mean over 8 densities x 3 seeds, per CAV
#: share; their Potential Lines CAVs among their StripBasedHuman drivers.
TUM_TABLE_VPH = {0.0: 6613.25, 0.1: 6688.25, 0.5: 7554.00, 0.9: 11745.42, 0.95: 13337.25,
                 0.99: 15029.08, 1.0: 15503.75}

#: TUM's flows per density, veh/h, read off their notebook's figure (cell 29; mean over
#: 3 seeds; about +-150 veh/h; NaN where the curve is hidden under others).
TUM_DENSITIES_VPKM = (50.0, 100.0, 150.0, 200.0, 250.0, 300.0, 350.0, 400.0)
TUM_FIGURE_VPH = {
    0.0: (4900, 7930, 7710, 7320, 7030, 6520, 6090, 5620),
    0.1: (4970, 7820, 7780, 7500, 7060, 6630, 6200, 5730),
    0.5: (5230, 9050, 8650, 8290, 8000, 7640, 7140, 6780),
    0.9: (5300, 9550, 13690, 14740, 13800, 13300, 12220, 11680),
    0.95: (math.nan, math.nan, 13510, 17330, 16870, 15530, 14960, 14050),
    0.99: (5400, 9820, 14090, 18600, 19600, 18990, 17730, 16400),
    1.0: (5590, 9950, 14310, 18990, 20700, 19750, 18450, 17010),
}


#: TUM's ring's five car sizes in equal shares: their mean length, m.
TUM_MEAN_LENGTH_M = (3.2 + 3.4 + 3.9 + 4.55 + 5.2) / 5


def rows_equilibrium_flow_vph(density_vpkm: float, rows: int, time_gap_s: float,
                              standstill_gap_m: float, mean_length_m: float = TUM_MEAN_LENGTH_M,
                              free_speed_mps: float = math.inf) -> float:
    """Flow of ``rows`` rows of cars at a constant-time-gap equilibrium, veh/h: each row
    holds ``density_vpkm / rows`` veh/km, so its bumper gap is ``1000 / (k / rows) - L`` m,
    its speed ``(gap - s0) / T`` m/s (at most ``free_speed_mps``, at least 0), and the flow
    ``density x speed``. An independent expectation for a ring's congested branch: with
    TUM's Potential Lines' margins (a Krauss safe speed with a reaction time of 0.5 s and
    no standstill gap, ``python_src/trb_const_config.ini`` at tag Paper-TRB-2024) and 4 rows
    it gives TUM's published flows at 250-400 veh/km within 4 %."""
    spacing_m = 1000.0 / (density_vpkm / rows)
    speed = min(max(spacing_m - mean_length_m - standstill_gap_m, 0.0) / time_gap_s,
                free_speed_mps)
    return density_vpkm * speed * 3.6


def mixed_rows_equilibrium_flow_vph(density_vpkm: float, rows: int, cav_share: float,
                                    time_gap_s: float, time_gap_hdv_s: float,
                                    standstill_gap_m: float, human_time_gap_s: float,
                                    human_standstill_gap_m: float = 0.0,
                                    mean_length_m: float = TUM_MEAN_LENGTH_M,
                                    free_speed_mps: float = math.inf) -> float:
    """Flow of ``rows`` rows of mixed traffic at one common speed, veh/h: the
    :func:`rows_equilibrium_flow_vph` equilibrium with humans (share ``1 - cav_share``)
    mixed at random into the rows. Each vehicle's bumper gap is its standstill gap plus its
    time gap times the speed: a CAV keeps ``time_gap_s`` behind a CAV and
    ``time_gap_hdv_s`` behind a human (its leader a human with probability
    ``1 - cav_share``), a human his ``human_time_gap_s`` (Krauss's equilibrium gap is the
    reaction time times the speed) behind ``human_standstill_gap_m``; all in s and m. The
    mean time gap per vehicle is then ``p (p T + (1 - p) T_hdv) + (1 - p) T_h``. An
    expectation for the loss humans cost when every row runs at the same speed; rows that
    run at different speeds (humans gathered in some) can do better or worse."""
    p = cav_share
    per_row_vpkm = density_vpkm / rows
    mean_time_gap_s = p * (p * time_gap_s + (1 - p) * time_gap_hdv_s) + (1 - p) * human_time_gap_s
    fixed_m = mean_length_m + p * standstill_gap_m + (1 - p) * human_standstill_gap_m
    speed = min(max(1000.0 / per_row_vpkm - fixed_m, 0.0) / mean_time_gap_s, free_speed_mps)
    return density_vpkm * speed * 3.6


def is_tum_protocol(res: SweepResults) -> bool:
    """True for a ring sweep whose runs count vehicles at TUM's detector."""
    t = res.table
    return DETECTOR_COLUMN in t and "demand.ring_density_vpkm" in t and "demand.cav_share" in t


def _num(g: pd.DataFrame, col: str):
    import pandas as pd

    return pd.to_numeric(g[col], errors="coerce") if col in g else pd.Series(dtype=float)


def _tum_at(share: float, density: float) -> float:
    row = TUM_FIGURE_VPH.get(round(share, 4))
    if row is None or density not in TUM_DENSITIES_VPKM:
        return math.nan
    return float(row[TUM_DENSITIES_VPKM.index(density)])


def density_table(res: SweepResults) -> pd.DataFrame:
    """Flow at TUM's detector per CAV share and density, mean over the seeds.

    Columns: ``cav_share``, ``density_vpkm``, ``n_runs``, ``flow_vph`` (mean over the
    seeds), ``flow_min_vph`` / ``flow_max_vph``, ``edie_flow_vph`` (the same runs over
    the whole ring: a check on the detector), ``speed_mps`` (space-mean), ``flow_drift``
    (largest over the seeds; second half of the intervals against the first), ``tum_vph``
    (:data:`TUM_FIGURE_VPH`), ``ours_over_tum``, then
    :func:`cosim.analysis.headline.comfort_safety`.
    """
    import pandas as pd

    ok = res.ok
    rows = []
    keys = [_num(ok, "demand.cav_share"), _num(ok, "demand.ring_density_vpkm")]
    for (share, dens), g in ok.groupby(keys, sort=True):
        q = _num(g, DETECTOR_COLUMN)
        tum = _tum_at(float(share), float(dens))
        mean = float(q.mean())
        drift = _num(g, "flow_drift").abs()
        row = {
            "cav_share": float(share), "density_vpkm": float(dens), "n_runs": int(q.notna().sum()),
            "flow_vph": mean, "flow_min_vph": float(q.min()), "flow_max_vph": float(q.max()),
            "edie_flow_vph": float(_num(g, "edie_flow_vph").mean()),
            "speed_mps": float(_num(g, "space_mean_speed_mps").mean()),
            "flow_drift": float(drift.max()) if drift.notna().any() else math.nan,
            "tum_vph": tum,
            "ours_over_tum": mean / tum if math.isfinite(tum) and tum > 0 else math.nan,
        }
        row.update(comfort_safety(g))
        rows.append(row)
    return pd.DataFrame(rows)


def share_table(res: SweepResults, confidence: float = 0.95) -> pd.DataFrame:
    """TUM's table computed on our runs: per CAV share the mean flow at the detector over
    the densities, beside TUM's; and the fundamental diagram's peak.

    Columns: ``cav_share``, ``n_runs``, ``densities`` (how many ran), ``seeds`` (fewest
    per density), ``flow_vph`` (mean over the densities of the seed means: TUM's mean over
    all runs when every density has the same seeds), ``ci_low_vph`` / ``ci_high_vph``
    (t-based over the seeds that ran every density of the share: each seed's mean over
    the densities), ``tum_vph`` (:data:`TUM_TABLE_VPH`), ``ours_over_tum``,
    ``max_flow_vph`` and ``max_at_vpkm`` (the highest seed mean over the densities and
    where), ``tum_max_vph`` (the same from :data:`TUM_FIGURE_VPH`), then
    :func:`cosim.analysis.headline.comfort_safety`.
    """
    import pandas as pd

    ok = res.ok
    per_density = density_table(res)
    rows = []
    for share, g in ok.groupby(_num(ok, "demand.cav_share"), sort=True):
        q = _num(g, DETECTOR_COLUMN)
        dens = _num(g, "demand.ring_density_vpkm")
        d = per_density[per_density["cav_share"] == float(share)]
        mean = float(d["flow_vph"].mean()) if len(d) else math.nan
        seed = _num(g, "seed") if "seed" in g else pd.Series(0, index=g.index)
        n_dens = dens.nunique()
        complete = [float(q[seed == k].mean()) for k in sorted(seed.dropna().unique())
                    if dens[seed == k].nunique() == n_dens]
        _, half, n_seeds = t_interval(complete, confidence)
        best = d.loc[d["flow_vph"].idxmax()] if len(d) else None
        tum = TUM_TABLE_VPH.get(round(float(share), 4), math.nan)
        fig = TUM_FIGURE_VPH.get(round(float(share), 4))
        row = {
            "cav_share": float(share), "n_runs": int(q.notna().sum()),
            "densities": int(n_dens),
            "seeds": int(d["n_runs"].min()) if len(d) else 0,
            "flow_vph": mean,
            "ci_low_vph": mean - half if n_seeds > 1 else math.nan,
            "ci_high_vph": mean + half if n_seeds > 1 else math.nan,
            "tum_vph": tum,
            "ours_over_tum": mean / tum if math.isfinite(tum) and tum > 0 else math.nan,
            "max_flow_vph": float(best["flow_vph"]) if best is not None else math.nan,
            "max_at_vpkm": float(best["density_vpkm"]) if best is not None else math.nan,
            "tum_max_vph": float(max(x for x in fig if math.isfinite(x))) if fig else math.nan,
        }
        row.update(comfort_safety(g))
        rows.append(row)
    return pd.DataFrame(rows)


def hdv_loss(shares: pd.DataFrame, column: str = "flow_vph") -> float:
    """Relative flow lost at 5 % human drivers against 100 % CAVs (``1 - q95 / q100``) in
    ``column`` of :func:`share_table` (NaN when either share is missing)."""
    by = dict(zip(shares["cav_share"].round(4), shares[column], strict=True)) \
        if len(shares) else {}
    q95, q100 = by.get(0.95, math.nan), by.get(1.0, math.nan)
    return 1.0 - q95 / q100 if q100 and math.isfinite(q95) and math.isfinite(q100) \
        else math.nan
