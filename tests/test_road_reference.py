"""Time-gap reference speed and leader search (controllers/road_reference.py)."""

import numpy as np
import pytest

from controllers.road_reference import leader_gaps, time_gap_speed


def test_time_gap_speed_is_gap_minus_standstill_over_time_gap_capped_by_desire():
    v_des = np.array([30.0, 30.0, 30.0, 30.0])
    gap = np.array([np.inf, 26.0, 2.0, 1.0])  # m
    v = time_gap_speed(v_des, gap, time_gap_s=0.8, standstill_gap_m=2.0)
    assert v == pytest.approx([30.0, 30.0, 0.0, 0.0])
    assert time_gap_speed(v_des, np.array([10.0] * 4), 0.8, 2.0) == pytest.approx([10.0] * 4)
    assert time_gap_speed(v_des, gap, 0.0, 2.0) == pytest.approx(v_des)


def test_leader_gap_is_bumper_to_bumper_to_the_laterally_overlapping_vehicle_ahead():
    # vehicle 0 at s=0; vehicle 1 ahead in the same band, vehicle 2 closer but beside.
    s = np.array([0.0, 30.0, 10.0])
    d = np.array([0.0, 0.5, 3.0])
    length = np.full(3, 4.0)
    width = np.full(3, 1.8)
    gap = leader_gaps(s, d, length, width, np.array([0, 1]), reach_m=100.0)
    assert gap[0] == pytest.approx(26.0)  # 30 - 4 (two half lengths)
    assert np.isinf(gap[1])


def test_leader_gap_wraps_on_a_ring():
    s = np.array([995.0, 5.0])
    gap = leader_gaps(s, np.zeros(2), np.full(2, 4.0), np.full(2, 1.8), np.array([0]),
                      reach_m=50.0, period=1000.0)
    assert gap[0] == pytest.approx(6.0)
