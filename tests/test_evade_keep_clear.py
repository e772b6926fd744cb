"""A CAV held at the border of the band it keeps clear beside an exit's strip evades a
human driver who moves onto it, into that band.

On a user's freeway (``experiments.corridor_checks``, ``freeway-3/cav40``) a SUMO driver at
34.7 m/s passing a CAV at 27.3 m/s moved right onto the CAV, which stood at the border of
the band a CAV that stays on the road keeps clear beside the exit's strip while a human
driver is near (``exit_keep_clear_m``): the law bounded its evasion by that band, a
purpose, and not by the road (one collision). The scene here is that one on the road of
``draw_freeway(2)`` (pure numpy, no SUMO): the CAV moves right, out of the driver's way;
with the band as its wall (the rule undone) it is pulled left, into him.
"""

from __future__ import annotations

import numpy as np
from test_weaving_deadlocks import FREEWAY_2, _edges

from controllers.observation import Observation
from controllers.road.lanefree import LaneFreeFlocking, LaneFreeParams, purpose


def _lateral_commands(keep_band_as_wall: bool, monkeypatch) -> np.ndarray:
    """The CAV's lateral commands (m/s^2) over 0.5 s of the scene."""
    if keep_band_as_wall:  # the rule undone: the evasion's road keeps the band too
        roads = purpose.RoutePurpose.roads
        monkeypatch.setattr(purpose.RoutePurpose, "roads",
                            lambda self, obs, keep_clear=True: roads(self, obs))
    law = LaneFreeFlocking(LaneFreeParams())
    road, entries, exits = FREEWAY_2
    # the CAV stays on the road, 30 m before the exit's strip, at the band's border
    q, p = np.array([[1970.0, -1.6]]), np.array([[27.3, 0.0]])
    length, width, exit_index = np.array([4.5]), np.array([1.78]), np.array([0])
    # the driver alongside on its left, bodies touching, moving right at 1 m/s
    oq, op = np.array([[1972.0, 0.25]]), np.array([[34.7, -1.0]])
    out = []
    for k in range(5):
        obs = Observation(
            q=q, p=p, t=k * 0.1, dt=0.1, ids=np.array(["cav.a"], dtype=object),
            length=length, width=width, desired_speed=np.full(1, 30.0), road=road,
            road_edges=_edges(q, width, exit_index, road, entries, exits), exits=exits,
            exit_index=exit_index, entries=entries, others_q=oq, others_p=op,
            others_length=np.array([4.5]), others_width=np.array([1.82]),
            others_ids=np.array(["hdv.x"], dtype=object))
        out.append(law.compute(obs)[0, 1])
    return np.array(out)


def test_a_cav_evades_a_human_driver_into_the_band_it_keeps_clear(monkeypatch):
    assert np.all(_lateral_commands(False, monkeypatch) < -0.5)  # right, away from him


def test_with_the_band_as_its_wall_it_does_not(monkeypatch):
    u = _lateral_commands(True, monkeypatch)
    assert np.all(u >= 0.0), u  # held, or pulled towards him
