"""PNG figures (matplotlib, Agg backend): fundamental diagrams, capacity, time-space, top view.

Modules, by job:

* :mod:`cosim.analysis.figures.style`: the one style of all figures: colours
  (:data:`CAV_COLOUR`, :data:`HDV_COLOUR`, :data:`PALETTE`), markers and line styles
  (:func:`series_style`), readable series labels with units (:func:`series_label`,
  :func:`series_labels`), the speed colour map (:func:`speed_cmap`), the legend entry of
  a non-stationary point (:func:`REJECTED_HANDLE`) and the axis-limit and title helpers;
* :mod:`cosim.analysis.figures.output`: :func:`save`, the one way a figure is written
  (PNG, closed after);
* :mod:`cosim.analysis.figures.sweep`: figures of a whole sweep:
  :func:`fundamental_diagram_figure` (flow vs density and speed vs density, one curve per
  series: the seed-mean per demand level, every run as a faint marker of its series and
  every measurement interval as a grey dot), :func:`capacity_figure` (capacity vs CAV
  share, one line per controller/variant, confidence intervals as error bars) and
  :func:`stationary_mask`;
* :mod:`cosim.analysis.figures.runs`: figures of one run (from ``trajectories.csv``:
  ``t_s, id, s_m, d_m, v_mps, is_cav``): :func:`time_space_figure` (``s(t)`` coloured by
  speed, CAVs and HDVs in two panels), :func:`top_view_figure` (the road from above at
  chosen times: vehicles as rectangles ``length_m x width_m`` at ``(s_m, d_m)``, road
  edges and the lane lines of the three-lane baseline), :func:`top_view_animation` and
  :func:`animate_top_view` (the same as a GIF), :func:`road_geometry` and
  :func:`plot_run` (the run figures of a run folder, road geometry and scenario name from
  config.toml);
* :mod:`cosim.analysis.figures.headline`: the headline experiment
  (:mod:`cosim.analysis.headline`): :func:`headline_capacity_figure` (queue discharge per
  arm with confidence intervals), :func:`headline_mixed_figure` (flow on TUM's ring
  against the CAV share, beside TUM's), :func:`headline_fd_figure` (the ring fundamental
  diagram per time gap and mode) and :func:`headline_gain_figure` (lane-free against
  fixed rows at equal time gap);
* :mod:`cosim.analysis.figures.tum_protocol`: :func:`tum_protocol_fd_figure` (TUM's ring
  protocol: flow at their detector against the density per CAV share, beside theirs).

Points that are not stationary (flow drift of 2 % or more) are drawn hollow everywhere.

One style for all: every series has its own colour (Okabe-Ito, colour-blind safe) and
marker (:func:`series_style`) and a readable label (:func:`series_label`, e.g.
"CAV 95 %, flocking"); CAVs are blue and HDVs orange everywhere; every axis names its
unit; every title names the sweep or scenario. Every ``*_figure`` builder returns the
matplotlib Figure unsaved (the tests inspect those); write it with
``save(builder(...), out_path)``, which returns the PNG path.

The names below are re-exported here, so ``from cosim.analysis import figures as fg;
fg.fundamental_diagram_figure(...)`` works. Importing this package selects matplotlib's
Agg backend before any of its modules loads pyplot.
"""

import matplotlib

matplotlib.use("Agg")

from cosim.analysis.figures.headline import (  # noqa: E402
    RING_MODES,
    headline_capacity_figure,
    headline_fd_figure,
    headline_gain_figure,
    headline_mixed_figure,
)
from cosim.analysis.figures.output import save  # noqa: E402
from cosim.analysis.figures.runs import (  # noqa: E402
    ANIMATION_DPI,
    MAX_SEGMENTS,
    Edges,
    animate_top_view,
    plot_run,
    road_geometry,
    time_space_figure,
    top_view_animation,
    top_view_figure,
)
from cosim.analysis.figures.style import (  # noqa: E402
    CAV_COLOUR,
    HDV_COLOUR,
    INTERVAL_COLOUR,
    LINESTYLES,
    MARKERS,
    PALETTE,
    REJECTED_HANDLE,
    SPEED_CMAP,
    series_label,
    series_labels,
    series_style,
    speed_cmap,
)
from cosim.analysis.figures.sweep import (  # noqa: E402
    FREE_FLOW_SHARE,
    capacity_figure,
    free_flow_only,
    fundamental_diagram_figure,
    stationary_mask,
)
from cosim.analysis.figures.tum_protocol import tum_protocol_fd_figure  # noqa: E402

__all__ = [
    "ANIMATION_DPI",
    "CAV_COLOUR",
    "FREE_FLOW_SHARE",
    "HDV_COLOUR",
    "INTERVAL_COLOUR",
    "LINESTYLES",
    "MARKERS",
    "MAX_SEGMENTS",
    "PALETTE",
    "REJECTED_HANDLE",
    "RING_MODES",
    "SPEED_CMAP",
    "Edges",
    "animate_top_view",
    "capacity_figure",
    "free_flow_only",
    "fundamental_diagram_figure",
    "headline_capacity_figure",
    "headline_fd_figure",
    "headline_gain_figure",
    "headline_mixed_figure",
    "tum_protocol_fd_figure",
    "plot_run",
    "road_geometry",
    "save",
    "series_label",
    "series_labels",
    "series_style",
    "speed_cmap",
    "stationary_mask",
    "time_space_figure",
    "top_view_animation",
    "top_view_figure",
]
