"""controllers/layers/safety.py without SUMO: the safe-speed, side-clearance and road-edge rules.

Defaults: dt = 0.1 s, one reaction step (tau = 0.1 s), min gap 2 m, lateral clearance
0.3 m, edge margin 0.1 m, own and leader deceleration 9 m/s^2, lateral acceleration and
speed 1.5 m/s^2 and 1.5 m/s. Cars 4.5 m x 1.8 m on a 10.2 m road (edges at +-5.1 m).
Closed loops integrate like SUMO: v += u dt, s += v dt; d += v_lat dt.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.layers.safety import RoadState, SafetyConfig, SafetyCounts, SafetyLayer

DT = 0.1
L, W = 4.5, 1.8
EDGE = 5.1


def road(s, d, v, length=L, width=W) -> RoadState:
    s = np.asarray(s, float)
    n = len(s)
    return RoadState(s, np.asarray(d, float), np.asarray(v, float),
                     np.full(n, length, float), np.full(n, width, float))


def edges(n: int = 1) -> np.ndarray:
    return np.tile([-EDGE, EDGE], (n, 1)).astype(float)


def v_safe(gap_bumper: float, v_leader: float = 0.0, b=9.0, bl=9.0, tau=0.1, min_gap=2.0):
    """Krauss safe speed written out independently."""
    g = gap_bumper - min_gap
    return -b * tau + math.sqrt((b * tau) ** 2 + v_leader**2 * b / bl + 2 * b * g)


def one_cav(layer, u, v_lat, rd, period=None):
    u_s, vl = layer.apply(np.array([u], float), np.array([0]), np.array([v_lat], float),
                          rd, edges(), period)
    return u_s[0], vl[0]


# --------------------------------------------------------------------------------------
# 3. Safe speed
# --------------------------------------------------------------------------------------


def test_closing_on_stopped_vehicle_is_braked_to_exactly_v_safe():
    """20 m/s towards a stopped car; gap chosen so that v_safe = 19.5 m/s (reachable in
    one step): a +2 m/s^2 command becomes the one that lands on v_safe."""
    target = 19.5
    # invert v_safe: (v + b tau)^2 = (b tau)^2 + 2 b g
    g = ((target + 0.9) ** 2 - 0.81) / 18.0 + 2.0
    ds = g + L
    layer = SafetyLayer(SafetyConfig())
    (u_long, u_lat), vl = one_cav(layer, [2.0, 0.0], 0.0, road([0.0, ds], [0.0, 0.0], [20, 0]))
    assert v_safe(g) == pytest.approx(target)
    assert 20.0 + u_long * DT == pytest.approx(target, abs=1e-9)
    assert u_long == pytest.approx((target - 20.0) / DT)
    assert vl == 0.0 and u_lat == 0.0
    assert layer.counts.speed == 1 and layer.counts.seen == 1


def test_unreachable_safe_speed_brakes_at_the_emergency_deceleration():
    """30 m/s with a stopped car 35 m ahead: v_safe ~ 21.8 m/s, 8 m/s below in one step
    is impossible; the layer commands the full -9 m/s^2 (not less, not more)."""
    layer = SafetyLayer(SafetyConfig())
    (u_long, _), _ = one_cav(layer, [1.0, 0.0], 0.0, road([0.0, 35.0], [0, 0], [30, 0]))
    assert v_safe(35.0 - L) < 30.0 - 9.0 * DT
    assert u_long == pytest.approx(-9.0)


def test_closed_loop_stops_min_gap_behind_stopped_vehicle():
    """Full throttle (+2.6 m/s^2) at 30 m/s, stopped car 100 m ahead: the CAV stops
    with a bumper gap of min_gap (2 m) to 1 m more, never below it, braking <= 9 m/s^2."""
    layer = SafetyLayer(SafetyConfig())
    s = np.array([0.0, 100.0])
    v = np.array([30.0, 0.0])
    gaps, decels = [], []
    for _ in range(300):
        (u_long, _), _ = one_cav(layer, [2.6, 0.0], 0.0, road(s, [0, 0], v))
        v_new = v[0] + u_long * DT
        assert v_new >= 0.0
        decels.append((v[0] - v_new) / DT)
        v[0] = v_new
        s[0] += v_new * DT
        gaps.append(s[1] - s[0] - L)
    assert v[0] == pytest.approx(0.0, abs=1e-9)
    assert min(gaps) >= 2.0 - 1e-9
    assert gaps[-1] <= 3.0
    assert max(decels) <= 9.0 + 1e-9
    assert layer.counts.speed > 0


def test_vehicle_beside_does_not_brake_but_one_within_clearance_does():
    """Stopped car 20 m ahead with its side 1.6 m (no overlap) or 0.2 m (< 0.3 m
    clearance) away laterally: only the second is treated as a leader."""
    layer = SafetyLayer(SafetyConfig())
    (u_far, _), _ = one_cav(layer, [2.0, 0.0], 0.0, road([0, 20], [0.0, 3.4], [25, 0]))
    assert u_far == 2.0
    assert layer.counts.speed == 0
    (u_near, _), _ = one_cav(layer, [2.0, 0.0], 0.0, road([0, 20], [0.0, 2.0], [25, 0]))
    assert u_near == pytest.approx(-9.0)
    assert layer.counts.speed == 1



def test_vehicle_alongside_within_clearance_is_no_leader_unless_it_closes_in():
    """A car alongside (its centre 0.1 m ahead, the bodies overlapping along the road) with
    its side 0.2 m away (< 0.3 m clearance): a leader at a negative gap would stop the CAV
    dead (TUM's ring: a human driver behind then ran into the CAV), which cannot avoid a
    car beside; it is no leader while clear sideways, and still one when it moves towards
    the CAV fast enough to close the 0.2 m within 1 s (``ALONGSIDE_S``)."""
    layer = SafetyLayer(SafetyConfig())
    beside = road([0.0, 0.1], [0.0, 2.0], [5.0, 5.0])
    (u_long, _), _ = one_cav(layer, [0.5, 0.0], 0.0, beside)
    assert u_long == 0.5 and layer.counts.speed == 0
    closing = RoadState(beside.s, beside.d, beside.v, beside.length, beside.width,
                        np.array([0.0, -0.3]))
    (u_long, _), _ = one_cav(layer, [0.5, 0.0], 0.0, closing)
    assert u_long < -5.0 and layer.counts.speed == 1

def test_lateral_move_behind_a_vehicle_it_could_not_stop_behind_is_held_off():
    """A car 8 m ahead (centres) at 19 m/s, side gap 0.4 m, CAV at 20 m/s: sharing its
    band would put the CAV above its Krauss safe speed (~18.8 m/s), so the move stops at
    the 0.3 m side clearance and the CAV need not brake."""
    rd = road([0, 8.0], [0.0, 2.2], [20, 19])
    assert v_safe(8.0 - L, v_leader=19.0) < 20.0
    move = SafetyLayer(SafetyConfig())
    (u_move, _), vl = one_cav(move, [1.0, 0.0], 1.5, rd)
    assert vl == pytest.approx(1.0)  # 0.4 m -> 0.3 m in one 0.1 s step
    assert u_move == 1.0
    assert move.counts.side == 1 and move.counts.speed == 0


def test_lateral_move_behind_a_vehicle_far_enough_ahead_is_free_and_bounds_the_speed():
    """The same car 11 m ahead: the CAV (20 m/s) is within its safe speed behind it, so
    the full lateral move goes ahead, and the car becomes a leader that caps the
    acceleration at v_safe (rule 3 along the swept band)."""
    rd = road([0, 11.0], [0.0, 2.2], [20, 19])
    cap = v_safe(11.0 - L, v_leader=19.0)
    assert 20.0 < cap < 20.0 + 5.0 * DT
    move = SafetyLayer(SafetyConfig())
    (u_move, _), vl = one_cav(move, [5.0, 0.0], 1.5, rd)
    assert vl == pytest.approx(1.5)
    assert 20.0 + u_move * DT == pytest.approx(cap, abs=1e-9)
    assert move.counts.side == 0 and move.counts.speed == 1


def test_no_cut_in_front_of_a_follower_that_could_not_stop():
    """Taken from a ring run (1 km, 250 veh/km, seed 2) that collided before this rule:
    a CAV at 16.3 m/s steers towards the band of a car 13.7 m behind (centres) at 21.7
    m/s, side gap 0.4 m. In one band the follower would exceed its safe speed, so the
    CAV keeps the side clearance; with the follower at the CAV's speed it may move."""
    layer = SafetyLayer(SafetyConfig())
    fast = road([13.69, 0.0], [0.0, -2.2], [16.32, 21.72])
    assert 21.72 > v_safe(13.69 - L, v_leader=16.32)
    _, vl = one_cav(layer, [0.0, -1.5], -1.5, fast)
    assert vl == pytest.approx(-1.0)
    assert layer.counts.side == 1
    calm = road([13.69, 0.0], [0.0, -2.2], [16.32, 16.32])
    _, vl = one_cav(layer, [0.0, -1.5], -1.5, calm)
    assert vl == pytest.approx(-1.5)  # lat_speed_max
    assert layer.counts.side == 1


def test_braking_cav_cutting_across_a_braking_cav_never_overlaps_it():
    """Closed loop of the same ring situation: the front CAV brakes at the emergency
    rate and steers right into the band of the rear CAV, which is 5.4 m/s faster and
    already at the right road edge. Both brake at 9 m/s^2 at most; the bodies never
    overlap and the rear CAV stops at least min_gap behind if it ends up behind."""
    layer = SafetyLayer(SafetyConfig())
    s = np.array([199.33, 185.64])
    d = np.array([-2.24, -4.09])
    v = np.array([16.32, 21.72])
    vl = np.array([-0.52, 0.0])
    length = np.array([3.9, 4.5])
    width = np.array([1.7, 1.78])
    u_cmd = np.array([[-9.0, -1.5], [-4.5, 0.0]])
    for _ in range(60):
        rd = RoadState(s.copy(), d.copy(), v.copy(), length, width, vl.copy())
        u, vl = layer.apply(u_cmd, np.array([0, 1]), vl, rd, edges(2))
        v = np.maximum(v + u[:, 0] * DT, 0.0)
        s = s + v * DT
        d = d + vl * DT
        lat_gap = abs(d[0] - d[1]) - 0.5 * width.sum()
        long_gap = s[0] - s[1] - 0.5 * length.sum()
        assert lat_gap > 0.0 or long_gap > 0.0
    assert v[0] == 0.0 and v[1] == 0.0


def test_speed_never_commanded_negative():
    """Already overlapping a stopped car (negative gap) at 0.5 m/s: brake to 0, not < 0."""
    layer = SafetyLayer(SafetyConfig())
    (u_long, _), _ = one_cav(layer, [0.0, 0.0], 0.0, road([0, 3.0], [0, 0], [0.5, 0]))
    assert 0.5 + u_long * DT == pytest.approx(0.0, abs=1e-12)


def test_braking_across_the_ring_wrap_matches_the_straight_case():
    """Period 300 m: a CAV at s = 290 m and a stopped car at s = 25 m (35 m ahead across
    s = 0) gives the same command as 0 m and 35 m on an open road."""
    straight = SafetyLayer(SafetyConfig())
    (u_open, _), _ = one_cav(straight, [2.0, 0.0], 0.0, road([0, 35], [0, 0], [22, 0]))
    ring = SafetyLayer(SafetyConfig())
    (u_ring, _), _ = one_cav(ring, [2.0, 0.0], 0.0, road([290, 25], [0, 0], [22, 0]), 300.0)
    assert 22.0 + u_open * DT == pytest.approx(v_safe(35.0 - L), abs=1e-9)
    assert u_ring == pytest.approx(u_open, abs=1e-12)
    assert ring.counts.speed == 1


def test_leader_speed_raises_the_safe_speed():
    """Same 30 m gap, leader at 20 m/s instead of stopped: v_safe grows as in Krauss."""
    g = 30.0 - L
    expect = v_safe(g, v_leader=20.0)
    assert expect > 25.0  # so a CAV at 25 m/s is not limited at all
    layer = SafetyLayer(SafetyConfig())
    (u_long, _), _ = one_cav(layer, [2.0, 0.0], 0.0, road([0, 30], [0, 0], [25, 20]))
    assert u_long == 2.0
    (u_long, _), _ = one_cav(layer, [2.0, 0.0], 0.0, road([0, 30], [0, 0], [25, 0]))
    assert 25.0 + u_long * DT == pytest.approx(max(v_safe(g), 25.0 - 0.9), abs=1e-9)


# --------------------------------------------------------------------------------------
# 2. Side clearance
# --------------------------------------------------------------------------------------


def test_lateral_motion_into_vehicle_beside_is_blocked():
    """A car right beside (ds = 0) 2.2 m to the left: pushing left at full lateral speed
    ends with exactly 0.3 m side clearance and stays there."""
    layer = SafetyLayer(SafetyConfig())
    d, vl = 0.0, 1.5
    clearances = []
    for _ in range(30):
        (_, u_lat), vl = one_cav(layer, [0.0, 1.5], vl, road([0, 0], [d, 2.2], [20, 20]))
        d += vl * DT
        clearances.append(2.2 - d - W)
    assert min(clearances) >= 0.3 - 1e-9
    assert clearances[-1] == pytest.approx(0.3, abs=1e-9)
    assert layer.counts.side >= 29


def test_no_move_into_a_side_gap_that_is_already_too_small_but_away_is_free():
    rd = road([0, 1.0], [0.0, 2.0], [20, 20])  # side clearance 0.2 m < 0.3 m
    layer = SafetyLayer(SafetyConfig())
    _, vl_in = one_cav(layer, [0.0, 1.5], 0.0, rd)
    assert vl_in == 0.0
    assert layer.counts.side == 1
    _, vl_out = one_cav(layer, [0.0, -1.5], 0.0, rd)
    assert vl_out == pytest.approx(-1.5 * DT)  # v_lat = 0 + u dt, unchanged
    assert layer.counts.side == 1


def test_side_rule_ignores_vehicles_far_ahead():
    """Same lateral offset but 50 m ahead at the same speed: no side constraint."""
    layer = SafetyLayer(SafetyConfig())
    _, vl = one_cav(layer, [0.0, 1.5], 1.5, road([0, 50], [0.0, 2.0], [20, 20]))
    assert vl == pytest.approx(1.5)
    assert layer.counts.side == 0


def test_two_cavs_moving_towards_each_other_keep_the_side_clearance():
    """CAVs side by side, 0.45 m apart, both pushing towards each other at 1.5 m/s."""
    layer = SafetyLayer(SafetyConfig())
    d = np.array([-1.125, 1.125])
    vl = np.array([1.5, -1.5])
    worst = np.inf
    for _ in range(5):
        _, vl = layer.apply(np.array([[0.0, 1.5], [0.0, -1.5]]), np.array([0, 1]), vl,
                            road([0, 0], d, [20, 20]), edges(2))
        d = d + vl * DT
        worst = min(worst, d[1] - d[0] - W)
    assert worst >= 0.3 - 1e-9


# --------------------------------------------------------------------------------------
# 1. Road edges
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("side", [+1.0, -1.0], ids=["left", "right"])
def test_edge_rule_keeps_the_body_inside_the_road(side):
    """Pushing sideways for 10 s from the centre: the body never gets closer than the
    margin (0.1 m) to the edge, the lateral speed never exceeds sqrt(2 a_lat room),
    and the CAV ends at the margin."""
    layer = SafetyLayer(SafetyConfig())
    limit = EDGE - 0.5 * W - 0.1  # furthest allowed centre offset: 4.1 m
    d, vl = 0.0, 0.0
    for _ in range(100):
        room = limit - side * d
        _, vl = one_cav(layer, [0.0, side * 1.5], vl, road([0], [d], [20]))
        assert abs(vl) <= math.sqrt(2 * 1.5 * max(room, 0.0)) + 1e-9
        d += vl * DT
        assert side * d + 0.5 * W <= EDGE - 0.1 + 1e-9
    assert side * d == pytest.approx(limit, abs=0.02)
    assert layer.counts.edge > 0
    assert layer.counts.seen == 100


def test_vehicle_outside_the_margin_is_not_pushed_further_out():
    layer = SafetyLayer(SafetyConfig())
    _, vl = one_cav(layer, [0.0, 1.5], 1.0, road([0], [4.5], [20]))  # 0.4 m beyond 4.1
    assert vl <= 0.0
    _, vl = one_cav(layer, [0.0, -1.5], -1.0, road([0], [4.5], [20]))  # inwards is free
    assert vl == pytest.approx(-1.15)


# --------------------------------------------------------------------------------------
# Counts
# --------------------------------------------------------------------------------------


def test_counts_increase_per_rule_and_per_agent_step():
    layer = SafetyLayer(SafetyConfig())
    assert layer.counts == SafetyCounts()
    # CAV 0 brakes for a stopped car, CAV 1 drives into the left edge, CAV 2 is free
    rd = road([0, 30, 0, 200], [-3.0, -3.0, 4.0, 0.0], [25, 0, 20, 20])
    u = np.array([[2.0, 0.0], [0.0, 1.5], [0.5, 0.0]])
    u_s, _ = layer.apply(u, np.array([0, 2, 3]), np.array([0.0, 1.5, 0.0]), rd, edges(3))
    assert u_s[0, 0] < 2.0 and u_s[2, 0] == 0.5
    c = layer.counts.as_dict()
    assert c == {"safety_edge_activations": 1, "safety_side_activations": 0,
                 "safety_speed_activations": 1, "safety_agent_steps": 3}
    layer.apply(u, np.array([0, 2, 3]), np.array([0.0, 1.5, 0.0]), rd, edges(3))
    assert layer.counts.seen == 6 and layer.counts.speed == 2 and layer.counts.edge == 2


def test_no_cavs_is_a_no_op():
    layer = SafetyLayer(SafetyConfig())
    u, vl = layer.apply(np.zeros((0, 2)), np.zeros(0, int), np.zeros(0),
                        road([0.0], [0.0], [10.0]), np.zeros((0, 2)))
    assert u.shape == (0, 2) and vl.shape == (0,)
    assert layer.counts.seen == 0
