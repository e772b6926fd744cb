"""SUMO's sublane width chosen from the road and the obstacle
(``scenario.lateral_resolution_m = "auto"``).

SUMO's sublane model sees the road in strips of ``--lateral-resolution`` (a lane's last
strip is what is left over); its drivers (SL2015) decide where to go strip by strip and
treat a strip that a body touches as taken. Where nothing narrows, a coarse grid costs
them nothing; where they must pass a stopped car or fit into a neck, the part of a strip
that a body or an edge cuts off is lost to them, and two drivers side by side at the neck
can wait for each other for minutes. Measured on a user-drawn abrupt step (10.2 m to a
6.2-7.6 m neck aligned left, netconvert's defaults, 4 000 veh/h, SUMO's drivers alone,
seeds 101-103, 360 s: ``python -m experiments.user_road_checks``, arms
``step-left-sublaneW/cav0``): the longest standstill was 7.8 / 247 / 241 s at 0.8 m,
1.7 / 300 / 24 s at 0.4 m and 2.3 / 16 / 28 s at 0.2 m.

The rule: :data:`COARSE_M` on a road of constant width with nothing standing on it,
:data:`NARROW_M` where the width changes (by more than :data:`WIDTH_TOL_M`) or a stopped
car stands. Lengths in m.
"""

from __future__ import annotations

import numpy as np

#: sublane width where nothing narrows, m
COARSE_M = 0.8
#: sublane width where the road narrows or a car stands, m (more strips for SUMO's
#: drivers to look at; on the step above its runs were no slower, the deadlocked ones at
#: 0.8 m slower still)
NARROW_M = 0.2
#: the widths auto chooses from, m, coarsest first
CHOICES_M = (COARSE_M, NARROW_M)
#: width changes smaller than this are no narrowing, m
WIDTH_TOL_M = 0.05


def narrowing(widths_m, obstacle: bool = False) -> bool:
    """Whether SUMO's drivers must pass a narrowing: the road's width changes (``widths_m``:
    the profile's widths, m) or a stopped car stands (``obstacle``)."""
    w = np.asarray(widths_m, dtype=float)
    return bool(obstacle or (w.size and float(w.max() - w.min()) > WIDTH_TOL_M))


def auto_resolution_m(narrows: bool) -> float:
    """The sublane width (m): :data:`NARROW_M` where something narrows, else
    :data:`COARSE_M` (module docstring)."""
    return NARROW_M if narrows else COARSE_M


def scenario_resolution_m(sc, net) -> float:
    """``scenario.lateral_resolution_m`` of ``sc`` resolved on the built network ``net``
    (a :class:`cosim.road.frame.RoadNetwork`): the number itself, or the auto rule's."""
    value = sc.scenario.lateral_resolution_m
    if not isinstance(value, str):
        return float(value)
    return auto_resolution_m(narrowing(net.segment_width, sc.obstacle.present))
