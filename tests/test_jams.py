"""Jam figures (cosim/metrics/jams.py) from hand-made steps: standstill durations,
long standstills, blocked windows at a cross-section, obstacles never counted, the
ring's seam. Steps of 1 s, windows of 10 s, a cross-section at 100 m."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.metrics.jams import UPSTREAM_M, JamRecorder


def _rec(xs=(100.0,), period=None, warmup=0.0, long_s=10.0) -> JamRecorder:
    return JamRecorder(1.0, warmup, xs, period, v_stop=0.5, long_s=long_s)


def _step(rec: JamRecorder, t: float, vehicles: dict) -> None:
    """vehicles: id -> (front position m, speed m/s[, is_static])."""
    ids = list(vehicles)
    front = np.array([vehicles[k][0] for k in ids], dtype=float)
    v = np.array([vehicles[k][1] for k in ids], dtype=float)
    static = np.array([len(vehicles[k]) > 2 and vehicles[k][2] for k in ids], dtype=bool)
    rec.record(t, ids, front, v, static)


def test_free_flow_gives_zero_jam_figures():
    rec = _rec()
    for t in range(0, 41):
        _step(rec, t, {"a": (20.0 * t, 20.0), "b": (20.0 * t - 30.0, 20.0)})
    s = rec.summary()
    assert s == {"max_standstill_s": 0.0, "vehicles_stopped_long": 0, "long_standstill_s": 10.0,
                 "blocked_windows": 0, "gridlock": False}


def test_standstill_duration_is_measured_from_the_first_stopped_step():
    rec = _rec(xs=())
    # "a" stands still (0.4 m/s < 0.5) from t = 2 to t = 6, moves, stops again 3 s
    speeds = [5, 5, 0.4, 0, 0, 0, 0, 5, 0, 0, 0, 5]
    for t, v in enumerate(speeds):
        _step(rec, t, {"a": (10.0, v)})
    assert rec.summary()["max_standstill_s"] == pytest.approx(4.0)
    assert rec.summary()["vehicles_stopped_long"] == 0


def test_long_standstills_count_vehicles_once_and_obstacles_never():
    rec = _rec(xs=())
    for t in range(0, 25):
        vehicles = {"a": (10.0, 0.0), "obstacle": (30.0, 0.0, True)}
        if t < 12:  # "b" stands 11 s, then leaves the road (its timer is dropped)
            vehicles["b"] = (5.0, 0.0)
        if t < 5:  # "c" stands 4 s, then drives
            vehicles["c"] = (0.0, 0.0)
        else:
            vehicles["c"] = (float(t), 1.0)
        _step(rec, t, vehicles)
    s = rec.summary()
    assert s["max_standstill_s"] == pytest.approx(24.0)  # "a", t = 0 .. 24
    assert s["vehicles_stopped_long"] == 2  # a (24 s) and b (11 s); c and the obstacle not
    # "b" comes back later standing again: a new standstill, not the old one continued
    _step(rec, 30, {"b": (5.0, 0.0)})
    _step(rec, 31, {"b": (5.0, 0.0)})
    assert rec._since["b"] == 30


def test_a_queue_waiting_at_a_section_nobody_passes_blocks_the_window():
    rec = _rec()
    for t in range(0, 21):  # two windows: (0, 10] and (10, 20]
        _step(rec, t, {"queue": (100.0 - 40.0, 0.0), "far": (500.0 + 20 * t, 20.0)})
    s = rec.summary()
    assert s["blocked_windows"] == 2 and s["gridlock"] is True
    assert [w["t_end_s"] for w in rec.blocked_log] == [10.0, 20.0]
    assert rec.blocked_log[0]["cross_section_m"] == 100.0


@pytest.mark.parametrize("case", ["someone_passes", "queue_too_far", "queue_leaves",
                                  "queue_is_an_obstacle", "queue_downstream"])
def test_a_window_is_not_blocked_when(case):
    rec = _rec()
    for t in range(0, 11):
        vehicles = {"queue": (60.0, 0.0)}
        if case == "someone_passes":  # front crosses 100 m between t = 5 and t = 6
            vehicles["passer"] = (50.0 + 10.0 * t, 10.0)
        elif case == "queue_too_far":
            vehicles = {"queue": (100.0 - UPSTREAM_M - 1.0, 0.0)}
        elif case == "queue_leaves" and t >= 8:  # waiting for part of the window only
            vehicles = {"queue": (60.0 + 5 * (t - 7), 5.0)}
        elif case == "queue_is_an_obstacle":
            vehicles = {"queue": (60.0, 0.0, True)}
        elif case == "queue_downstream":
            vehicles = {"queue": (101.0, 0.0)}
        _step(rec, t, vehicles)
    assert rec.summary()["blocked_windows"] == 0


def test_windows_start_after_the_warm_up():
    rec = _rec(warmup=15.0)
    for t in range(0, 31):
        _step(rec, t, {"queue": (60.0, 0.0)})
    # only (15, 25] is a whole window after the warm-up
    assert rec.summary()["blocked_windows"] == 1
    assert rec.blocked_log[0]["t_start_s"] == 15.0


def test_ring_seam_upstream_and_crossings():
    # section at 10 m on a 1000 m ring: a car stopped at 950 m is 60 m upstream of it
    blocked = _rec(xs=(10.0,), period=1000.0)
    for t in range(0, 11):
        _step(blocked, t, {"queue": (950.0, 0.0)})
    assert blocked.summary()["blocked_windows"] == 1
    # a car passing the section across the seam (990 m -> 5 m -> 20 m) unblocks it
    passed = _rec(xs=(10.0,), period=1000.0)
    for t in range(0, 11):
        front = (980.0 + 15.0 * t) % 1000.0
        _step(passed, t, {"queue": (950.0, 0.0), "passer": (front, 15.0)})
    assert passed.summary()["blocked_windows"] == 0
