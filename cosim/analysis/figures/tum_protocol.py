"""Figure of TUM LaneFreeDrive's ring protocol (tables from :mod:`cosim.analysis.tum_protocol`).

* :func:`tum_protocol_fd_figure`: flow at TUM's detector against the density, one colour
  per CAV share: ours (mean over the seeds, the seeds' range as error bars) solid, TUM's
  (read off their figure) dashed in the same colour.

The builder returns the matplotlib Figure unsaved; write it with
:func:`cosim.analysis.figures.output.save`.
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from cosim.analysis.figures.style import series_style, titled


def tum_protocol_fd_figure(densities: pd.DataFrame, reference: dict[float, tuple],
                           reference_densities: tuple[float, ...], title: str | None = None):
    """Flow (veh/h) against density (veh/km) per CAV share, ours and TUM's (a matplotlib
    Figure, not saved).

    Args:
        densities: :func:`cosim.analysis.tum_protocol.density_table`.
        reference: TUM's flows (veh/h) by share, one per ``reference_densities`` (veh/km).
    """
    shares = sorted(set(densities["cav_share"]) | set(reference)) if len(densities) \
        else sorted(reference)
    fig, ax = plt.subplots(figsize=(8, 5))
    for k, share in enumerate(shares):
        st = series_style(k)
        d = densities[densities["cav_share"] == share].sort_values("density_vpkm")
        if len(d):
            y = d["flow_vph"].to_numpy(float)
            err = np.vstack([y - d["flow_min_vph"].to_numpy(float),
                             d["flow_max_vph"].to_numpy(float) - y])
            ax.errorbar(d["density_vpkm"], y, yerr=err, capsize=2, color=st["color"],
                        marker=st["marker"], markersize=5, linestyle="-",
                        label=f"ours, {100 * share:g} % CAVs")
        ref = reference.get(share)
        if ref is not None:
            xs = [x for x, q in zip(reference_densities, ref, strict=True) if math.isfinite(q)]
            qs = [q for q in ref if math.isfinite(q)]
            ax.plot(xs, qs, color=st["color"], linestyle="--", linewidth=1.0, alpha=0.8)
    ax.plot([], [], color="0.3", linestyle="--", label="TUM LaneFreeDrive (read off their figure)")
    ax.set_xlabel("density, veh/km")
    ax.set_ylabel("flow at x = 339.09 m, 2 100-3 900 s, veh/h")
    ax.set_xlim(0, 1.05 * max(reference_densities))
    ax.set_ylim(0, None)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper right", ncol=2)
    ax.set_title(titled("TUM's ring protocol: fundamental diagram per CAV share", title),
                 fontsize=10)
    fig.tight_layout()
    return fig
