"""Time-gap reference speed and leader search (controllers/road/reference.py)."""

import math

import numpy as np
import pytest

from controllers.road.reference import leader_gaps, reference_reach_m, time_gap_speed


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


def test_leader_speed_is_that_of_the_nearest_overlapping_leader():
    # vehicle 0 at s=0 with two leaders in its band (30 m and 60 m) and one beside at 10 m
    s = np.array([0.0, 60.0, 30.0, 10.0])
    d = np.array([0.0, 0.0, 0.5, 3.0])
    v = np.array([20.0, 5.0, 12.0, 30.0])
    gap, v_leader = leader_gaps(s, d, np.full(4, 4.0), np.full(4, 1.8), np.array([0, 1]),
                                reach_m=100.0, v=v)
    assert gap[0] == pytest.approx(26.0)
    assert v_leader[0] == 12.0
    assert np.isinf(gap[1]) and np.isnan(v_leader[1])


def test_closing_speed_bound_slows_the_approach_to_a_stopped_car():
    """40 m behind a stopped car the time gap alone asks for 47.5 m/s (capped at 30);
    with b = 3 m/s^2 the reference is sqrt(2 b (g - s0)) = sqrt(228) ~ 15.1 m/s, so the
    CAV could brake to a stop s0 behind it at b."""
    v_des = np.array([30.0])
    gap = np.array([40.0])
    assert time_gap_speed(v_des, gap, 0.8, 2.0) == pytest.approx([30.0])
    v = time_gap_speed(v_des, gap, 0.8, 2.0, np.array([0.0]), decel_mps2=3.0)
    assert v == pytest.approx([math.sqrt(2 * 3.0 * 38.0)])
    # a stop from v at b takes v^2 / (2 b) = g - s0 exactly
    assert v[0] ** 2 / (2 * 3.0) == pytest.approx(40.0 - 2.0)


def test_closing_speed_bound_never_binds_in_time_gap_equilibrium():
    """Following a leader at its own speed with g = s0 + T v: the reference stays v (the
    equilibrium, hence the fundamental diagram, is unchanged); below s0 it is 0; no
    leader (nan) leaves the time-gap reference."""
    v_eq = np.array([5.0, 15.0, 25.0, 30.0])
    gap = 2.0 + 0.8 * v_eq
    v = time_gap_speed(np.full(4, 35.0), gap, 0.8, 2.0, v_eq, decel_mps2=3.0)
    assert v == pytest.approx(v_eq)
    v = time_gap_speed(np.array([30.0, 30.0]), np.array([1.5, np.inf]), 0.8, 2.0,
                       np.array([10.0, np.nan]), decel_mps2=3.0)
    assert v == pytest.approx([0.0, 30.0])


def test_reference_reach_covers_both_policies():
    # time gap binds to s0 + T v, the closing bound to s0 + v^2 / (2 b)
    assert reference_reach_m(30.0, 0.8, 2.0, 0.0) == pytest.approx(2.0 + 24.0 + 10.0)
    assert reference_reach_m(30.0, 0.8, 2.0, 3.0) == pytest.approx(2.0 + 150.0 + 10.0)
    # beyond the reach a stopped leader no longer lowers a 30 m/s reference
    far = reference_reach_m(30.0, 0.8, 2.0, 3.0) - 10.0
    v = time_gap_speed(np.array([30.0]), np.array([far]), 0.8, 2.0, np.array([0.0]), 3.0)
    assert v == pytest.approx([30.0])


def _brute_force_leaders(s, d, length, width, rows, reach, period, margin, v):
    gap = np.full(len(rows), np.inf)
    v_leader = np.full(len(rows), np.nan)
    for a, me in enumerate(rows):
        for j in range(len(s)):
            ds = s[j] - s[me]
            if period is not None:
                ds = ds % period
            if j == me or not 0 < ds <= (reach if period is None else min(reach, period / 2)):
                continue
            if abs(d[j] - d[me]) >= 0.5 * (width[me] + width[j]) + margin:
                continue
            g = ds - 0.5 * (length[me] + length[j])
            if g < gap[a]:
                gap[a], v_leader[a] = g, v[j]
    return gap, v_leader


@pytest.mark.parametrize("period", [None, 600.0], ids=["open", "ring"])
@pytest.mark.parametrize("seed", range(4))
def test_sorted_scan_matches_brute_force(period, seed):
    """Random traffic on 600 m, mixed lengths 3.2-12 m (trucks make the nearest centre
    differ from the nearest bumper), reach 30 m: same gaps and leader speeds as
    checking every pair."""
    rng = np.random.default_rng(seed)
    m = 60
    s = rng.uniform(0.0, 600.0, m)
    s[:5] = s[5]  # ties along the road
    d = rng.uniform(-4.0, 4.0, m)
    length = rng.choice([3.2, 4.5, 5.15, 12.0], m)
    width = rng.choice([1.6, 1.8, 2.5], m)
    v = rng.uniform(0.0, 35.0, m)
    rows = rng.choice(m, 50, replace=False)
    got_gap, got_v = leader_gaps(s, d, length, width, rows, 30.0, period, 0.3, v=v)
    want_gap, want_v = _brute_force_leaders(s, d, length, width, rows, 30.0, period, 0.3, v)
    assert np.isfinite(want_gap).sum() > 15 and np.isinf(want_gap).sum() > 0
    assert got_gap == pytest.approx(want_gap)
    np.testing.assert_array_equal(np.isnan(got_v), np.isnan(want_v))
    assert got_v[~np.isnan(want_v)] == pytest.approx(want_v[~np.isnan(want_v)])
