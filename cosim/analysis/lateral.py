"""How CAVs use the road's width: lateral-position histograms, rows and overtaking.

From one run's ``trajectories.csv`` (columns ``t_s, id, s_m, d_m, width_m, is_cav``; a
ring's ``s_m`` wraps at its circumference):

* :func:`lateral_histogram`: the share of CAV-time (after ``t0_s``) spent at each lateral
  position ``d`` (m, positive to the left of the road's centre line), per vehicle width
  class. Rows appear as peaks; rows set by the vehicles' widths appear as peak spacings
  close to a body width plus the lateral clearance.
* :func:`overtakes_per_vehicle_km`: pairwise order changes along the road between
  consecutive samples (Kendall's inversion count between the two orders, one overtake
  per swapped pair), per vehicle-km driven. On a ring positions are unwrapped first.
  Order changes of vehicles side by side count too (they are passes of a kind).
* :func:`lateral_figure`: histograms of several runs (densities) in one figure.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from cosim.analysis.figures.output import plt, save

#: Histogram bin width, m.
BIN_M = 0.1


def unwrapped_positions(tr: pd.DataFrame, period_m: float | None) -> pd.DataFrame:
    """``tr`` sorted by (id, t) with ``s_unwrapped_m`` (s plus laps x period on a ring).

    Assumes a vehicle moves less than half a period between two samples.
    """
    tr = tr.sort_values(["id", "t_s"]).reset_index(drop=True)
    s = tr["s_m"].to_numpy(float)
    if not period_m:
        return tr.assign(s_unwrapped_m=s)
    same = tr["id"].to_numpy() == np.roll(tr["id"].to_numpy(), 1)
    jump = np.diff(s, prepend=s[0])
    jump[~same] = 0.0
    laps = np.where(jump < -0.5 * period_m, 1.0, np.where(jump > 0.5 * period_m, -1.0, 0.0))
    # cumulative laps within each vehicle's series
    lap_sum = pd.Series(laps).groupby(tr["id"]).cumsum().to_numpy()
    return tr.assign(s_unwrapped_m=s + lap_sum * period_m)


def _inversions(order_values: np.ndarray) -> int:
    """Number of pairs out of order in ``order_values`` (merge-sort count, O(n log n))."""
    a = list(order_values)

    def sort(lo: int, hi: int) -> int:
        if hi - lo < 2:
            return 0
        mid = (lo + hi) // 2
        n = sort(lo, mid) + sort(mid, hi)
        left, right = a[lo:mid], a[mid:hi]
        i = j = 0
        k = lo
        while i < len(left) and j < len(right):
            if left[i] <= right[j]:
                a[k] = left[i]
                i += 1
            else:
                a[k] = right[j]
                j += 1
                n += len(left) - i
            k += 1
        a[k:hi] = left[i:] + right[j:]
        return n

    return sort(0, len(a))


def overtakes_per_vehicle_km(tr: pd.DataFrame, period_m: float | None, t0_s: float = 0.0,
                             cav_only: bool = True) -> tuple[float, int, float]:
    """Overtakes per vehicle-km after ``t0_s``.

    Between consecutive sample times, the vehicles present at both are ordered by their
    unwrapped position at the first time; the count of pairs whose order is reversed at
    the second is the number of overtakes in that step.

    Returns:
        (overtakes per vehicle-km, overtakes, vehicle-km driven).
    """
    tr = unwrapped_positions(tr, period_m)
    tr = tr[tr["t_s"] >= t0_s]
    if cav_only and "is_cav" in tr:
        tr = tr[tr["is_cav"].astype(bool)]
    wide = tr.pivot_table(index="t_s", columns="id", values="s_unwrapped_m")
    vals = wide.to_numpy(float)
    n_over, dist_m = 0, 0.0
    for k in range(1, len(vals)):
        a, b = vals[k - 1], vals[k]
        both = np.isfinite(a) & np.isfinite(b)
        if both.sum() < 2:
            continue
        a, b = a[both], b[both]
        dist_m += float(np.sum(np.maximum(b - a, 0.0)))
        n_over += _inversions(b[np.argsort(a, kind="stable")])
    km = dist_m / 1000.0
    return (n_over / km if km > 0 else float("nan")), n_over, km


def lateral_histogram(tr: pd.DataFrame, t0_s: float = 0.0, edges_m: tuple[float, float]
                      | None = None, bin_m: float = BIN_M) -> pd.DataFrame:
    """Share of CAV samples per lateral bin and width class after ``t0_s``.

    Returns:
        a frame with ``d_m`` (bin centres, m), one column per vehicle width (m, rounded to
        cm) with the share of that class's samples (each column sums to 1), and ``all``.
    """
    tr = tr[tr["t_s"] >= t0_s]
    if "is_cav" in tr:
        tr = tr[tr["is_cav"].astype(bool)]
    d = tr["d_m"].to_numpy(float)
    lo, hi = edges_m if edges_m is not None else (float(d.min()), float(d.max()))
    bins = np.arange(lo, hi + bin_m, bin_m)
    out = pd.DataFrame({"d_m": 0.5 * (bins[:-1] + bins[1:])})
    widths = tr["width_m"].round(2) if "width_m" in tr else pd.Series(0.0, index=tr.index)
    for w in sorted(widths.unique()):
        h, _ = np.histogram(d[(widths == w).to_numpy()], bins=bins)
        out[f"{w:g}"] = h / max(h.sum(), 1)
    h, _ = np.histogram(d, bins=bins)
    out["all"] = h / max(h.sum(), 1)
    return out


def row_peaks(hist: pd.DataFrame, min_share: float = 0.06,
              min_separation_m: float = 1.5) -> list[float]:
    """Lateral positions (m) of rows: maxima of the ``all`` histogram smoothed over 0.5 m
    that hold at least ``min_share`` of the samples within +-0.25 m, at least
    ``min_separation_m`` apart (the highest kept; two rows of cars cannot be closer than a
    body width), sorted from right to left."""
    d = hist["d_m"].to_numpy(float)
    bin_m = float(d[1] - d[0]) if len(d) > 1 else BIN_M
    k = max(1, int(round(0.5 / bin_m)))
    y = np.convolve(hist["all"].to_numpy(float), np.ones(k), mode="same")  # share per 0.5 m
    cand = [i for i in range(1, len(y) - 1)
            if y[i] >= y[i - 1] and y[i] > y[i + 1] and y[i] >= min_share]
    kept: list[float] = []
    for i in sorted(cand, key=lambda i: -y[i]):
        if all(abs(d[i] - p) >= min_separation_m for p in kept):
            kept.append(float(d[i]))
    return sorted(kept)


def lateral_figure(hists: Sequence[tuple[str, pd.DataFrame]], road_width_m: float,
                   out_path: str | Path, title: str = "Lateral positions of CAVs") -> Path:
    """One panel per run (label, histogram): the share of CAV-time at each lateral
    position, all CAVs (black) and per width class (colours); road edges dashed."""
    fig, axes = plt.subplots(len(hists), 1, figsize=(7.5, 1.6 + 1.7 * len(hists)),
                             sharex=True, squeeze=False)
    for ax, (label, h) in zip(axes[:, 0], hists, strict=True):
        classes = [c for c in h.columns if c not in ("d_m", "all")]
        for k, c in enumerate(classes):
            ax.plot(h["d_m"], h[c], lw=0.9, alpha=0.8, label=f"width {c} m",
                    color=plt.cm.viridis(k / max(len(classes) - 1, 1)))
        ax.plot(h["d_m"], h["all"], color="k", lw=1.6, label="all CAVs")
        for e in (-0.5 * road_width_m, 0.5 * road_width_m):
            ax.axvline(e, color="0.4", ls="--", lw=0.8)
        ax.set_ylabel("share per 0.1 m")
        ax.set_title(label, fontsize=9, loc="left")
    axes[-1, 0].set_xlabel("lateral position d of the vehicle centre, m (0: centre line, "
                           "+: left)")
    axes[0, 0].legend(fontsize=7, ncol=3, loc="upper right")
    fig.suptitle(title)
    fig.tight_layout()
    return save(fig, out_path)
