"""Three deadlocks of short weaving sections, and the rules that break them.

The road and the vehicles are those of a user's freeway drawn with netconvert's defaults
(``tests/test_several_ramps.py`` with its junctions closer: a 9.6 m road, an acceleration
strip from 270 m to 496 m, a deceleration strip from 704 m to the gore at 922 m; 4 400
veh/h) at two moments, about 200 s into a SUMO run, when CAVs stood there for the rest of
the run before these rules (pure numpy, no SUMO; the law sees the same standing scene for
3 s):

* a merging CAV a few centimetres over the strip's border at its end, held where it stood
  by the side buffers of two CAVs behind it, one on each side: it must move into the road
  ahead, and moves in front of them (the kernels' ``OUTSIDE_TOL_M``);
* a CAV bound for the exit, alongside a merging CAV that stood at the strip's end, slotted
  in behind it (zipper) while the merging CAV waited for it to pass: a mover does not
  slot in behind a standing vehicle it already overlaps; it drives on past it.

And one on the second weaving section of ``draw_freeway(2)`` (``experiments.corridor_checks``,
70 % CAVs, 178 s into the run; it stood 423 s): a CAV bound for the exit, held before its
funnel's wall (the funnel narrows towards the exit strip) by a merging CAV alongside it on
the exit's side at the very end of the acceleration strip, 2.25 m behind it, which waited
for room on the other side: the exit-bound CAV creeps on past its funnel's wall (the law's
``_creep_past``), a purpose and not the road's edge, until the merging CAV can move in
behind it.
"""

from __future__ import annotations

import numpy as np
import pytest

from controllers.observation import Observation, RoadProfile
from controllers.road.exits import exit_road
from controllers.road.lanefree import LaneFreeFlocking, LaneFreeParams

ROAD = RoadProfile(np.array([0.0, 269.97, 496.0, 704.2, 922.08, 1078.32, 1296.2, 1454.4,
                             1622.28]),
                   np.array([-4.8, -8.0, -4.8, -8.0, -4.8, -8.0, -4.8, -8.0, -4.8]),
                   np.full(9, 4.8), 2000.0)
ENTRIES = np.array([[269.97, 496.0, -8.0, -4.8], [1078.32, 1296.2, -8.0, -4.8]])
EXITS = np.array([[704.2, 922.08, -8.0, -4.8], [1454.4, 1622.28, -8.0, -4.8]])

#: id, s (m), d (m), v (m/s), length (m), width (m), exit (0: stays, k: exit k)
BOXED_IN = [  # ramp.41 stands 0.07 m over the strip's border near its end
    ("main.136", 485.51, -2.35, 0.00, 5.15, 1.84, 1),
    ("main.137", 499.71, 0.92, 17.93, 3.90, 1.70, 0),
    ("main.138", 464.04, -2.69, 4.64, 4.50, 1.78, 1),
    ("main.140", 469.68, 1.32, 18.51, 3.20, 1.60, 0),
    ("main.141", 493.29, 3.72, 29.51, 3.20, 1.60, 0),
    ("main.142", 549.57, 3.17, 29.31, 3.90, 1.70, 2),
    ("main.143", 469.80, 3.68, 29.43, 5.15, 1.84, 0),
    ("ramp.41", 492.33, -3.98, 0.00, 4.50, 1.78, 1),
    ("ramp.43", 484.79, -4.83, 0.55, 5.15, 1.84, 0),
    ("ramp.44", 474.94, -3.36, 2.39, 5.15, 1.84, 1),
]
SIDE_BY_SIDE = [  # main.136 (bound for the exit) beside ramp.43 (merging) at the strip's end
    ("main.136", 487.56, -2.35, 0.00, 5.15, 1.84, 1),
    ("main.138", 471.66, -2.69, 0.00, 4.50, 1.78, 1),
    ("main.144", 540.37, 3.07, 27.77, 4.50, 1.78, 2),
    ("main.145", 533.21, 0.63, 28.05, 3.20, 1.60, 0),
    ("main.146", 506.65, 3.76, 28.60, 3.20, 1.60, 0),
    ("main.147", 477.26, 3.41, 28.95, 3.90, 1.70, 2),
    ("ramp.43", 491.66, -4.83, 0.00, 5.15, 1.84, 0),
    ("ramp.44", 479.35, -2.72, 0.00, 5.15, 1.84, 1),
    ("ramp.45", 473.17, -4.90, 0.00, 3.20, 1.60, 1),
]

#: ``draw_freeway(2)`` from its second acceleration strip (1 548-1 774 m) to its second
#: deceleration strip (2 001-2 166 m; the first exit lies behind, left out), 9.6 m.
FREEWAY_2 = (RoadProfile(np.array([0.0, 1548.3, 1773.74, 2000.65, 2166.4]),
                         np.array([-4.8, -8.0, -4.8, -8.0, -4.8]), np.full(5, 4.8), 2539.81),
             np.array([[1548.3, 1773.74, -8.0, -4.8]]),
             np.array([[2000.65, 2166.4, -8.0, -4.8]]))
MUTUAL = [  # main.87 (bound for the exit) ahead of and beside ramp2.28 at the strip's end
    ("main.87", 1772.15, -2.41, 0.00, 5.15, 1.84, 1),
    ("main.110", 1752.73, -2.65, 3.02, 3.90, 1.70, 1),
    ("main.113", 1755.57, 0.84, 9.55, 3.90, 1.70, 0),
    ("main.114", 1783.09, 3.18, 7.82, 4.50, 1.78, 0),
    ("main.116", 1742.80, -2.86, 4.59, 4.50, 1.78, 1),
    ("ramp2.28", 1769.90, -4.86, 0.00, 4.50, 1.78, 0),
    ("ramp2.30", 1762.75, -3.36, 0.00, 5.15, 1.84, 1),
    ("ramp2.31", 1763.37, -5.77, 0.00, 3.90, 1.70, 1),
    ("ramp2.34", 1748.50, 3.47, 10.68, 3.20, 1.60, 0),
]


def _edges(q, width, exit_index, road, entries, exits):
    """The loop's road edges (N, 2), m (cosim.sim.loop: where it is on an entry strip, the
    exit's road for one leaving, else the narrowest over 30 m)."""
    s, d, half = q[:, 0], q[:, 1], 0.5 * width
    edges = road.narrowest(s, 30.0)
    for k, row in enumerate(exits):
        leaving = exit_index == k + 1
        if leaving.any():
            edges[leaving] = exit_road(road, row).narrowest(s[leaving], 30.0)
    for s0, s1, d_r, d_l in entries:
        on = (s >= s0) & (s <= s1) & (d - half < d_l - 0.05) & (d + half > d_r + 0.05)
        edges[on] = road.edges(s[on])
    return edges


def _commands_after(scene, seconds=3.0, announced=(), road=(ROAD, ENTRIES, EXITS), law=None):
    """The law's commands (N, 2) m/s^2 on the standing scene after ``seconds`` of calls;
    the CAVs ``announced`` had announced their lateral move (the law's memory, as in the
    run: a fresh law replans it in its own time); ``road``: (profile, entry strips, exit
    strips)."""
    law = law or LaneFreeFlocking(LaneFreeParams())
    profile, entries, exits = road
    ids = np.array([f"cav.{r[0]}" for r in scene], dtype=object)
    q = np.array([[r[1], r[2]] for r in scene])
    p = np.array([[r[3], 0.0] for r in scene])
    length = np.array([r[4] for r in scene])
    width = np.array([r[5] for r in scene])
    exit_index = np.array([r[6] for r in scene])
    u = None
    for k in range(int(round(seconds / 0.1))):
        obs = Observation(q=q, p=p, t=k * 0.1, dt=0.1, ids=ids, length=length, width=width,
                          desired_speed=np.full(len(q), 30.0), road=profile,
                          road_edges=_edges(q, width, exit_index, *road), exits=exits,
                          exit_index=exit_index, entries=entries)
        u = law.compute(obs)
        for who in announced:
            law._mem_urgent[law._last_slots[list(ids).index(f"cav.{who}")]] = True
    return dict(zip([r[0] for r in scene], u, strict=True))


@pytest.mark.parametrize("scene, who, axis, what", [
    (BOXED_IN, "ramp.41", 1, "moves into the road ahead"),
    (SIDE_BY_SIDE, "main.136", 0, "drives on past the standing merging CAV"),
])
def test_a_cav_that_would_wait_for_ever_moves(scene, who, axis, what):
    u = _commands_after(scene, announced=(who,))
    assert u[who][axis] > 0.5, (what, u[who])


def test_an_exit_bound_cav_creeps_past_its_funnel_beside_a_merging_cav():
    """MUTUAL: main.87 drives on (at a creep) past its funnel's wall; without the rule it
    stands, and so does ramp2.28 beside it, for good."""
    u = _commands_after(MUTUAL, road=FREEWAY_2)
    assert u["main.87"][0] > 0.5, u["main.87"]
    assert u["ramp2.28"][0] == pytest.approx(0.0, abs=1e-6)  # it waits: the strip ends

    class NoCreep(LaneFreeFlocking):
        def _creep_past(self, *args):
            pass

    u = _commands_after(MUTUAL, road=FREEWAY_2, law=NoCreep(LaneFreeParams()))
    assert abs(u["main.87"][0]) < 1e-6, u["main.87"]


def test_creeping_is_held_to_a_creep_and_only_past_a_cav_behind():
    """The creeping CAV accelerates only towards CREEP_MPS; a merging CAV ahead of it
    (which creeping would not free) makes it creep not at all."""
    scene = [r if r[0] != "main.87" else ("main.87", 1772.15, -2.41, 1.9, 5.15, 1.84, 1)
             for r in MUTUAL]
    u = _commands_after(scene, seconds=0.1, road=FREEWAY_2)
    assert 0.0 < u["main.87"][0] <= LaneFreeParams().approach_gain * (
        LaneFreeFlocking.CREEP_MPS - 1.9) + 1e-9
    behind = [r if r[0] != "main.87" else ("main.87", 1767.65, -2.41, 0.0, 5.15, 1.84, 1)
              for r in MUTUAL]
    law = LaneFreeFlocking(LaneFreeParams())
    _commands_after(behind, road=FREEWAY_2, law=law)
    assert law.stats["creeps"] == 0
    law = LaneFreeFlocking(LaneFreeParams())
    _commands_after(MUTUAL, road=FREEWAY_2, law=law)
    assert law.stats["creeps"] > 0
