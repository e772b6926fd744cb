"""The lane-free law's narrowing bound, compiled (:func:`controllers.road.lanefree.kernels.
narrowing_bound`), gives exactly what its numpy version gave (issue 15).

``old_narrowing`` is a verbatim copy of ``LaneFreeFlocking._narrowing`` before the change
(only the name changed; it calls the law's numpy ``_approach``, unchanged). States: random
CAVs on profiles that narrow, widen and narrow again, straight and on a ring, with side
bounds from neighbours (finite and infinite), stopped and fast CAVs."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.observation import Observation, RoadProfile
from controllers.road.lanefree import LaneFreeFlocking, LaneFreeParams
from controllers.road.lanefree.law import _Scene


def old_narrowing(self, obs, sc, side) -> np.ndarray:
    """Approach bound (N,) m/s^2 to the start of the first road piece ahead (within the
    look-ahead) whose edges exclude the CAV's body at its lateral position by more than
    it can still move sideways before it gets there; inf if none."""
    p = self.params
    n = sc.n
    road = obs.road
    s, d = sc.s[:n], sc.d[:n]
    half_w = 0.5 * sc.width[:n] + 0.1
    ds = road.s0[None, :] - s[:, None]  # (N, K)
    if road.periodic:
        ds = np.mod(ds, road.length_m)
    look = np.maximum(p.edge_lookahead_min_m, sc.v[:n] * p.lookahead_s)
    # lateral shift the body needs to fit the piece, and what it can still do before
    # reaching it (half the lateral speed limit and half the bound deceleration)
    need = np.maximum(road.right[None, :] - (d[:, None] - half_w[:, None]),
                      (d[:, None] + half_w[:, None]) - road.left[None, :])
    t_avail = np.maximum(ds, 0.0) / np.maximum(sc.v[:n], 1.0)[:, None]
    can = np.minimum(0.5 * self.lat_speed_max * t_avail,
                     0.25 * p.a_lat_bound_mps2 * t_avail**2)
    # a vehicle alongside on the side the CAV must move to blocks it now
    to_left = road.right[None, :] > d[:, None] - half_w[:, None]
    room = np.where(to_left, side["hi"][:, None] - d[:, None],
                    d[:, None] - side["lo"][:, None])
    can = np.minimum(can, np.maximum(room, 0.0) + 0.1)
    wall = (ds > 0) & (ds < look[:, None]) & (need > can)
    if not wall.any():
        return np.full(n, np.inf)
    g = np.min(np.where(wall, ds, np.inf), axis=1) - 0.5 * sc.length[:n]
    return np.where(np.isfinite(g), self._approach(g, np.zeros(n), sc.v[:n]), np.inf)



def _case(rng, periodic: bool):
    length = 2000.0
    k = int(rng.choice([2, 3, 6, 20]))
    s0 = np.concatenate([[0.0], np.sort(rng.choice(np.arange(50, 1950), k - 1, replace=False))])
    w = rng.choice([10.2, 6.8, 3.4, 8.5], k).astype(float)
    road = RoadProfile(s0, -0.5 * w, 0.5 * w, length, periodic)
    n = int(rng.integers(1, 80))
    s = rng.uniform(0.0, length, n)
    d = rng.uniform(-4.5, 4.5, n)
    v = rng.choice([0.0, 0.5, 3.0, 15.0, 30.0], n) + rng.uniform(0, 1, n)
    width = rng.choice([1.8, 2.5], n).astype(float)
    length_v = rng.choice([4.5, 12.0], n).astype(float)
    hi = np.where(rng.random(n) < 0.5, np.inf, d + rng.uniform(-0.5, 3.0, n))
    lo = np.where(rng.random(n) < 0.5, -np.inf, d - rng.uniform(-0.5, 3.0, n))
    obs = Observation(q=np.column_stack([s, d]), p=np.column_stack([v, np.zeros(n)]), dt=0.1,
                      length=length_v, width=width, road=road,
                      period_s=length if periodic else None)
    sc = _Scene(s=s, d=d, v=v, v_lat=np.zeros(n), length=length_v, width=width,
                accel=np.zeros(n), is_cav=np.ones(n, bool), static=np.zeros(n, bool), n=n)
    return obs, sc, {"hi": hi, "lo": lo}


@pytest.mark.parametrize("periodic", [False, True])
def test_compiled_narrowing_bound_matches_the_numpy_one(periodic):
    rng = np.random.default_rng(21 + periodic)
    law = LaneFreeFlocking(LaneFreeParams())
    walls = 0
    for _ in range(300):
        obs, sc, side = _case(rng, periodic)
        want = old_narrowing(law, obs, sc, side)
        got = law._narrowing(obs, sc, side)
        np.testing.assert_array_equal(got, want)
        walls += int(np.isfinite(want).sum())
    assert walls > 200  # the bound acted
