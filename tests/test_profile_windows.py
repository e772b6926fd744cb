"""The road profile's kernels look at each vehicle's stretch ahead only (bisection of the
pieces' starts, :func:`controllers.road.profile_kernels.ahead_windows`) instead of every
piece: on long roads of hundreds of pieces (a 50 km ring's profile has ~500) they must
still give the numpy references' bits (the verbatim copies of the code before the
kernels, in tests/test_observation_profile.py and tests/test_law_narrowing_exactness.py).
Cases the short profiles there do not reach: many pieces, zero-length pieces, a first
piece before 0, positions a lap or more off, just before a piece's start, infinite,
NaN, look-aheads of a lap and more. No SUMO."""

from __future__ import annotations

import numpy as np
import pytest
from test_law_narrowing_exactness import old_narrowing
from test_observation_profile import ref_narrowest, ref_wall_gap

from controllers.observation import Observation, RoadProfile
from controllers.road.lanefree import LaneFreeFlocking, LaneFreeParams
from controllers.road.lanefree.law import _Scene
from controllers.road.profile_kernels import _MAX_WINDOWS, ahead_windows, first_wall_ahead


def _long_profile(rng, k: int, periodic: bool) -> RoadProfile:
    length = float(rng.choice([20000.0, 50000.0, 4321.5]))
    inner = np.sort(rng.uniform(1.0, length - 1.0, k - 1))
    if k > 10:  # a zero-length piece
        inner[k // 2] = inner[k // 2 - 1]
    s0 = np.concatenate([[float(rng.choice([0.0, -20.0]))], inner])
    width = rng.choice([10.2, 10.19, 6.8, 3.4], k)
    off = rng.choice([0.0, 0.004, -1.0], k)
    return RoadProfile(s0, off - 0.5 * width, off + 0.5 * width, length, periodic)


def _positions(rng, prof: RoadProfile, n: int) -> np.ndarray:
    L = prof.length_m
    s = rng.uniform(-100.0, L + 100.0, n)
    pick = rng.choice(prof.s0, 12)
    s[:12] = pick  # on piece starts
    s[12:24] = np.nextafter(pick, -np.inf)  # just before them
    s[24:28] = [L, 0.0, -L + 3.0, 2.5 * L]  # the seam, a lap or more off
    s[28:31] = [np.nan, np.inf, -np.inf]
    return s


@pytest.mark.parametrize("periodic", [False, True])
def test_narrowest_over_many_pieces_matches_numpy(periodic):
    rng = np.random.default_rng(150 + periodic)
    for _ in range(12):
        prof = _long_profile(rng, int(rng.choice([60, 250, 600])), periodic)
        s = _positions(rng, prof, 300)
        ahead = rng.choice([0.0, 3.0, 150.0, 900.0, prof.length_m, 2.0 * prof.length_m], 300)
        ahead[40:42] = [np.nan, np.inf]
        with np.errstate(invalid="ignore"):
            want = ref_narrowest(prof, s, ahead)
        np.testing.assert_array_equal(prof.narrowest(s, ahead), want)


@pytest.mark.parametrize("periodic", [False, True])
def test_wall_gap_many_pieces_matches_numpy(periodic):
    rng = np.random.default_rng(160 + periodic)
    found = 0
    for reach in (60.0, 800.0, 1e9):  # the loop's reach, long, more than a lap
        for _ in range(6):
            prof = _long_profile(rng, int(rng.choice([60, 250, 600])), periodic)
            n = 300
            q = np.column_stack([_positions(rng, prof, n), rng.uniform(-5.0, 5.0, n)])
            width, length = rng.choice([1.8, 2.5], n), rng.choice([4.5, 12.0], n)
            with np.errstate(invalid="ignore"):
                want = ref_wall_gap(prof, q, width, length, reach)
            got = first_wall_ahead(q[:, 0].copy(), q[:, 1].copy(), width, length, prof.s0,
                                   prof.right, prof.left, periodic, prof.length_m, reach)
            np.testing.assert_array_equal(got, want)
            found += int(np.isfinite(want).sum())
    assert found > 500


@pytest.mark.parametrize("periodic", [False, True])
def test_narrowing_bound_many_pieces_matches_numpy(periodic):
    rng = np.random.default_rng(170 + periodic)
    law = LaneFreeFlocking(LaneFreeParams())
    walls = 0
    for _ in range(10):
        prof = _long_profile(rng, int(rng.choice([60, 250, 600])), periodic)
        n = 200
        s = rng.uniform(0.0, prof.length_m, n)
        s[:12] = np.nextafter(rng.choice(prof.s0[1:], 12), -np.inf)
        d = rng.uniform(-4.5, 4.5, n)
        v = rng.choice([0.0, 3.0, 15.0, 30.0, 60.0], n) + rng.uniform(0, 1, n)
        width = rng.choice([1.8, 2.5], n).astype(float)
        length_v = rng.choice([4.5, 12.0], n).astype(float)
        hi = np.where(rng.random(n) < 0.5, np.inf, d + rng.uniform(-0.5, 3.0, n))
        lo = np.where(rng.random(n) < 0.5, -np.inf, d - rng.uniform(-0.5, 3.0, n))
        obs = Observation(q=np.column_stack([s, d]), p=np.column_stack([v, np.zeros(n)]),
                          dt=0.1, length=length_v, width=width, road=prof,
                          period_s=prof.length_m if periodic else None)
        sc = _Scene(s=s, d=d, v=v, v_lat=np.zeros(n), length=length_v, width=width,
                    accel=np.zeros(n), is_cav=np.ones(n, bool), static=np.zeros(n, bool), n=n)
        side = {"hi": hi, "lo": lo}
        want = old_narrowing(law, obs, sc, side)
        np.testing.assert_array_equal(law._narrowing(obs, sc, side), want)
        walls += int(np.isfinite(want).sum())
    assert walls > 100


def test_windows_hold_every_piece_ahead_and_few_others():
    """Every piece whose start lies (0, reach) ahead is in a window, and a window holds
    little else (what makes the kernels O(N log K))."""
    rng = np.random.default_rng(180)
    win = np.empty((_MAX_WINDOWS, 2), dtype=np.int64)
    for periodic in (False, True):
        prof = _long_profile(rng, 600, periodic)
        L = prof.length_m
        for x in _positions(rng, prof, 400)[31:]:
            reach = float(rng.choice([10.0, 200.0, 3000.0]))
            nw = ahead_windows(prof.s0, x, reach, periodic, L, win)
            inside = np.zeros(len(prof.s0), bool)
            for w in range(nw):
                assert win[w, 0] < win[w, 1] and (w == 0 or win[w, 0] >= win[w - 1, 1])
                inside[win[w, 0]:win[w, 1]] = True
            ds = prof.s0 - x
            if periodic:
                ds = np.mod(ds, L)
            ahead = (ds > 0) & (ds < reach)
            assert inside[ahead].all()
            assert inside.sum() <= ahead.sum() + 2 * nw
