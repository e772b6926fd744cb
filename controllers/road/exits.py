"""The road as seen by a vehicle that leaves it by an exit, or stays on it (pure numpy).

A road with an off-ramp has lanes that lead only onto the exit (a deceleration strip
beside the road, ending at the gore where the exit leaves). The road's
:class:`~controllers.observation.RoadProfile` holds the strip as part of the road and
ends it at the gore. Three views of it, each a :class:`RoadProfile`:

* :func:`exit_road`: the road of a vehicle leaving by the exit: the road up to the gore,
  then the strip's lateral extent continued (the off-ramp, seen in the road frame). Its
  edges bound a leaving vehicle (the loop's road edges and the safety layer's walls):
  on the road itself the strip ends at the gore.
* :func:`through_road`: the road of a vehicle that stays on it: the strip taken out (its
  lanes lead nowhere it goes).
* :func:`exit_funnel`: the leaving vehicle's strategic purpose: the exit road narrowed,
  from ``prepare_m`` before the gore, towards the strip: a band of the strip's width at
  the road's right edge, widened by ``slope`` (m across per m along) with the distance
  before ``commit_m`` from the gore; from ``commit_m`` on, the strip alone. A law that
  keeps its vehicles inside its road's edges and stops before a narrowing it does not
  fit into (the lane-free law does) then reaches the strip in time or waits for a gap
  before the commit point: it never passes its exit.

``exits`` rows are ``(s_start, s_gore, d_right, d_left)`` (m): where the strip's lanes
start and end along the road, and their right and left border.
"""

from __future__ import annotations

import numpy as np

from controllers.observation import RoadProfile

#: Piece length of the funnel's staircase, m.
FUNNEL_STEP_M = 10.0
#: Room (m) the funnel leaves beside the strip's border where the strip starts (and less
#: in proportion on to the commit point): a vehicle that waited at the road's edge for the
#: strip fits between that edge and the funnel's bound there and moves onto the strip as
#: the bound closes. A lane's width: the widest vehicle with margins each side.
FUNNEL_ROOM_M = 3.0
#: The commit point lies at most this share of the strip's length before the gore (a strip
#: shorter than ``commit_m`` / this share commits earlier than ``commit_m``).
COMMIT_SHARE_MAX = 0.4


def _pieces(road: RoadProfile, extra: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Piece starts (K',) m: the road's and ``extra`` (inside the road's span), with the
    road's edges on each, (K',) m each."""
    s0 = np.unique(np.concatenate([road.s0, extra[(extra > road.s0[0])]]))
    e = road.edges(s0)
    return s0, e[:, 0].copy(), e[:, 1].copy()


def through_road(road: RoadProfile, exits: np.ndarray, keep_clear_m: float = 0.0,
                 lead_m: float = 0.0) -> RoadProfile:
    """``road`` without the exits' strips (see the module docstring), and without a band of
    ``keep_clear_m`` (m) beside each strip from ``lead_m`` (m) before its start to the
    gore: the room a vehicle bound for the exit crosses to reach the strip (beside a
    vehicle waiting for a gap there, a through vehicle would wait for it in turn)."""
    exits = np.asarray(exits, dtype=float).reshape(-1, 4)
    s0, right, left = _pieces(road, np.concatenate([exits[:, :2].ravel(),
                                                    exits[:, 0] - lead_m]))
    for s_start, s_gore, d_right, d_left in exits:
        on = (s0 >= s_start - lead_m - 1e-9) & (s0 < s_gore)
        if d_left <= 1e-9:  # a strip right of the centre line
            right[on] = np.maximum(right[on], d_left + keep_clear_m)
        elif d_right >= -1e-9:  # left of it
            left[on] = np.minimum(left[on], d_right - keep_clear_m)
        # a strip across the middle (a wide lane that splits) is the road: nothing taken
    return RoadProfile(s0, right, np.maximum(left, right + 1e-3), road.length_m, road.periodic)


def exit_road(road: RoadProfile, exit_row: np.ndarray) -> RoadProfile:
    """The road of a vehicle leaving by the exit ``exit_row`` (module docstring)."""
    s_start, s_gore, d_right, d_left = (float(x) for x in exit_row)
    s0, right, left = _pieces(road, np.array([s_gore]))
    beyond = s0 >= s_gore
    right[beyond], left[beyond] = d_right, d_left
    return RoadProfile(s0, right, left, road.length_m, road.periodic)


def exit_funnel(road: RoadProfile, exit_row: np.ndarray, prepare_m: float, commit_m: float,
                slope: float) -> RoadProfile:
    """The leaving vehicle's purpose road (module docstring): ``exit_road`` with its left
    edge (for a strip on the right; mirrored on the left) at most ``slope`` (m across per m
    along) times the distance to the commit point beyond the strip's border, from
    ``prepare_m`` (m) before the gore on, and never narrower than the strip's width: the
    strip alone from ``commit_m`` (m) before the gore on (at most
    :data:`COMMIT_SHARE_MAX` of the strip's length). Measured from the strip's border,
    not from the road's edge, the bound moves steadily across the strip's start (where
    the road's edge jumps outwards by the strip's width), and leaves at least
    :data:`FUNNEL_ROOM_M` beside the border there (on a short strip the bound closes
    more steeply than ``slope``)."""
    s_start, s_gore, d_right, d_left = (float(x) for x in exit_row)
    strip_m = s_gore - s_start
    commit_m = min(commit_m, COMMIT_SHARE_MAX * strip_m)
    base = exit_road(road, exit_row)
    n = int(np.ceil(prepare_m / FUNNEL_STEP_M))
    grid = s_gore - prepare_m + FUNNEL_STEP_M * np.arange(n)
    s0, right, left = _pieces(base, np.append(grid, s_gore - commit_m))
    x = s_gore - s0  # distance to the gore at each piece's start
    band = d_left - d_right
    # each piece holds the bound at its far end (the narrowest it must hold)
    x_end = np.maximum(np.append(s_gore - s0[1:], 0.0), 0.0)
    on = (x <= prepare_m + 1e-9) & (x > 0)
    before_commit = np.maximum(x_end - commit_m, 0.0)
    room = np.minimum(FUNNEL_ROOM_M * before_commit / max(strip_m - commit_m, 1e-9),
                      FUNNEL_ROOM_M)
    reach = np.maximum(before_commit * slope, room)
    if d_left <= 1e-9:  # a strip on the right: bound the left edge
        bound = np.maximum(d_left + reach, right + band)
        left[on] = np.minimum(left[on], bound[on])
    else:  # on the left: bound the right edge
        bound = np.minimum(d_right - reach, left - band)
        right[on] = np.maximum(right[on], bound[on])
    return RoadProfile(s0, right, left, road.length_m, road.periodic)


def strip_only(road: RoadProfile, strips: np.ndarray) -> RoadProfile:
    """``road`` narrowed to the strips along their length (rows ``(s_start, s_end,
    d_right, d_left)``, m): a vehicle on an acceleration strip that must stay on it; past
    the strip's end the road (into which it must have merged) as it is."""
    strips = np.asarray(strips, dtype=float).reshape(-1, 4)
    s0, right, left = _pieces(road, strips[:, :2].ravel())
    for s_start, s_end, d_right, d_left in strips:
        on = (s0 >= s_start - 1e-9) & (s0 < s_end)
        right[on] = np.maximum(right[on], d_right)
        left[on] = np.minimum(left[on], d_left)
    return RoadProfile(s0, right, np.maximum(left, right + 1e-3), road.length_m, road.periodic)
