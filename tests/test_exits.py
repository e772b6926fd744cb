"""The road seen by vehicles that leave it by an exit or stay on it
(:mod:`controllers.road.exits`), and the lane-free law's exit purpose, without SUMO."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.observation import Observation, RoadProfile
from controllers.road import exits as X
from controllers.road.lanefree import LaneFreeFlocking as LaneFreeLaw
from controllers.road.lanefree import LaneFreeParams  # noqa: I001

# a 10.2 m road (d in [-5.1, 5.1]) with a 3 m strip on its right from 2 160 m to the gore
# at 2 500 m: the corridor's deceleration strip
ROAD = RoadProfile(np.array([0.0, 2160.0, 2500.0]), np.array([-5.1, -8.1, -5.1]),
                   np.array([5.1, 5.1, 5.1]), 3500.0)
EXIT = np.array([2160.0, 2500.0, -8.1, -5.1])


def test_the_through_road_has_no_strip_and_keeps_the_band_beside_it_clear():
    plain = X.through_road(ROAD, EXIT[None, :])
    e = plain.edges(np.array([1000.0, 2300.0, 2499.0, 2600.0]))
    assert np.allclose(e[:, 0], -5.1) and np.allclose(e[:, 1], 5.1)
    kept = X.through_road(ROAD, EXIT[None, :], keep_clear_m=2.2, lead_m=60.0)
    e = kept.edges(np.array([2000.0, 2101.0, 2300.0, 2499.0, 2501.0]))
    assert np.allclose(e[:, 0], [-5.1, -2.9, -2.9, -2.9, -5.1])


def test_the_exit_road_carries_the_strip_on_past_the_gore():
    road = X.exit_road(ROAD, EXIT)
    e = road.edges(np.array([1000.0, 2300.0, 2501.0, 3000.0]))
    assert np.allclose(e, [[-5.1, 5.1], [-8.1, 5.1], [-8.1, -5.1], [-8.1, -5.1]])


def test_the_exit_funnel_narrows_steadily_to_the_strip():
    prepare, commit = 1000.0, 60.0
    slope = (5.1 - (-5.1)) / (prepare - commit)
    road = X.exit_funnel(ROAD, EXIT, prepare, commit, slope)
    s = np.arange(1400.0, 2500.0, 1.0)
    e = road.edges(s)
    assert np.allclose(road.edges(np.array([1000.0]))[0], [-5.1, 5.1])  # before: the road
    assert np.allclose(e[s >= 2440.0], [-8.1, -5.1])  # from the commit point: the strip
    left = e[:, 1]
    assert np.all(np.diff(left) <= 1e-9)  # the left bound only closes in
    # no jump where the strip starts (the road's right edge moves out there by 3 m)
    assert np.max(-np.diff(left)) <= slope * X.FUNNEL_STEP_M + 1e-6
    assert np.all(left - e[:, 0] >= 3.0 - 1e-9)  # room for the strip's width everywhere


def _obs(q, p, exit_index, others=None):
    n = len(q)
    kw = {}
    if others is not None:
        kw = {"others_q": others[0], "others_p": others[1],
              "others_length": np.full(len(others[0]), 4.5),
              "others_width": np.full(len(others[0]), 1.8),
              "others_ids": np.array([f"h{i}" for i in range(len(others[0]))], dtype=object)}
    return Observation(q=np.array(q, float), p=np.array(p, float), dt=0.1,
                       ids=np.array([f"c{i}" for i in range(n)], dtype=object),
                       length=np.full(n, 4.5), width=np.full(n, 1.8),
                       desired_speed=np.full(n, 30.0), road=ROAD,
                       road_edges=X.exit_road(ROAD, EXIT).narrowest(np.asarray(q)[:, 0], 60.0)
                       if exit_index[0] else ROAD.narrowest(np.asarray(q)[:, 0], 60.0),
                       exits=EXIT[None, :], exit_index=np.array(exit_index), **kw)


def _lateral_after(law, obs_fn, steps=60):
    """Drive one CAV (a double integrator) ``steps`` steps; its lateral positions, m."""
    q, p = obs_fn.q0.copy(), obs_fn.p0.copy()
    out = []
    for _ in range(steps):
        u = law.compute(obs_fn(q, p))
        p = p + u * 0.1
        q = q + p * 0.1
        out.append(q[0, 1])
    return np.array(out)


class _Drive:
    def __init__(self, d0, s0, exit_index):
        self.q0 = np.array([[s0, d0]])
        self.p0 = np.array([[28.0, 0.0]])
        self.exit_index = exit_index

    def __call__(self, q, p):
        return _obs(q, p, [self.exit_index])


@pytest.mark.parametrize("s0", [1700.0, 2200.0])
def test_a_cav_bound_for_the_exit_moves_towards_it_and_one_staying_does_not(s0):
    d_exit = _lateral_after(LaneFreeLaw(LaneFreeParams()), _Drive(2.0, s0, 1))
    d_stay = _lateral_after(LaneFreeLaw(LaneFreeParams()), _Drive(2.0, s0, 0))
    assert d_exit[-1] < 2.0 - 1.0  # more than a metre towards the exit in 6 s
    assert d_stay.min() > 2.0 - 0.3


def test_a_cav_staying_on_the_road_leaves_the_strip_and_one_leaving_keeps_it():
    stay = _lateral_after(LaneFreeLaw(LaneFreeParams()), _Drive(-6.6, 2300.0, 0), steps=80)
    leave = _lateral_after(LaneFreeLaw(LaneFreeParams()), _Drive(-6.6, 2300.0, 1), steps=80)
    assert stay[-1] > -5.1 + 0.9  # out of the strip: it leads off the road
    assert np.all(np.abs(leave + 6.6) < 0.6)  # in the strip, near its middle


def test_a_cav_bound_for_a_later_exit_does_not_drive_on_an_earlier_exits_strip():
    """Two exits on the right (strips 1 200-1 500 m and 2 160-2 500 m): the road of a CAV
    bound for the second has no first strip, and its funnel closes on the second."""
    from controllers.road.lanefree.purpose import RoutePurpose

    road = RoadProfile(np.array([0.0, 1200.0, 1500.0, 2160.0, 2500.0]),
                       np.array([-5.1, -8.1, -5.1, -8.1, -5.1]), np.full(5, 5.1), 3500.0)
    exits = np.array([[1200.0, 1500.0, -8.1, -5.1], EXIT])
    q = np.array([[1300.0, -4.0], [1300.0, -4.0], [2300.0, -4.0]])
    obs = Observation(q=q, p=np.tile([28.0, 0.0], (3, 1)), dt=0.1,
                      ids=np.array(["a", "b", "c"], dtype=object), length=np.full(3, 4.5),
                      width=np.full(3, 1.8), desired_speed=np.full(3, 30.0), road=road,
                      road_edges=road.narrowest(q[:, 0], 60.0), exits=exits,
                      exit_index=np.array([1, 2, 2]))
    roads = {k: r for k, _, r, _ in RoutePurpose(LaneFreeParams()).roads(obs)}
    first, second = roads[1].edges(np.array([1300.0, 2300.0])), roads[2].edges(
        np.array([1300.0, 2300.0, 2480.0]))
    assert first[0, 0] == pytest.approx(-8.1)  # its own strip is its road
    assert second[0, 0] == pytest.approx(-5.1)  # the first exit's strip is not
    assert second[1, 0] == pytest.approx(-8.1) and second[2, 1] == pytest.approx(-5.1)
