"""The road profile's compiled look-ups (``RoadProfile.edges`` and ``narrowest``,
:mod:`controllers.road.profile_kernels`) give exactly what the numpy code before them gave
(issue 15). ``ref_edges`` and ``ref_narrowest`` are verbatim copies of the methods before
the change (only the names changed); states: straight and periodic profiles of 2 to 40
pieces, positions exactly on piece starts, before the first and past the road's end, NaN,
zero and long look-aheads."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.observation import RoadProfile


def ref_edges(self, s: np.ndarray) -> np.ndarray:
    """Edges (N, 2) m ``[right, left]`` at positions ``s`` (N,) m (clamped at the ends)."""
    s = np.asarray(s, dtype=float)
    if self.is_constant:  # one piece: its edges everywhere
        out = np.empty((len(s), 2))
        out[:, 0] = self.right[0]
        out[:, 1] = self.left[0]
        return out
    if self.periodic:
        s = np.mod(s, self.length_m)
    k = np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, len(self.s0) - 1)
    out = np.empty((len(s), 2))
    out[:, 0] = self.right[k]
    out[:, 1] = self.left[k]
    return out


def ref_narrowest(self, s: np.ndarray, ahead_m: np.ndarray | float) -> np.ndarray:
    s = np.asarray(s, dtype=float)
    out = ref_edges(self, s)
    if self.is_constant:
        return out
    ahead = np.broadcast_to(np.asarray(ahead_m, dtype=float), s.shape)
    end = (s + ahead)[:, None]
    start = self.s0[None, :]
    stop = np.append(self.s0[1:], np.inf)[None, :]
    col = s[:, None]
    hits = (stop > col) & (start <= end)
    if self.periodic:  # the piece one lap on, seen across the seam
        hits |= (stop + self.length_m > col) & (start + self.length_m <= end)
    right = np.max(np.where(hits, self.right[None, :], -np.inf), axis=1)
    left = np.min(np.where(hits, self.left[None, :], np.inf), axis=1)
    out[:, 0] = np.maximum(out[:, 0], right)
    out[:, 1] = np.minimum(out[:, 1], left)
    return out


def _profile(rng, k: int, periodic: bool) -> RoadProfile:
    length = float(rng.choice([300.0, 1000.0, 1234.5]))
    inner = np.sort(rng.choice(np.arange(1, int(length)), k - 1, replace=False)).astype(float)
    s0 = np.concatenate([[float(rng.choice([0.0, -20.0]))], inner])
    width = rng.choice([10.2, 6.8, 3.4, 8.0], k)
    off = rng.choice([0.0, 0.5, -1.0], k)
    return RoadProfile(s0, off - 0.5 * width, off + 0.5 * width, length, periodic)


@pytest.mark.parametrize("periodic", [False, True])
def test_compiled_profile_look_ups_match_the_numpy_ones(periodic):
    rng = np.random.default_rng(4 + periodic)
    for _ in range(60):
        prof = _profile(rng, int(rng.choice([2, 3, 10, 40])), periodic)
        n = int(rng.integers(0, 60))
        s = rng.uniform(-50.0, prof.length_m + 50.0, n)
        if n > 4:  # on piece starts, on the road's ends, unknown
            s[:3] = rng.choice(prof.s0, 3)
            s[3] = prof.length_m
            s[4] = np.nan
        ahead = rng.choice([0.0, 5.0, 80.0, 400.0, 2000.0], n)
        if n > 5:
            ahead[5] = np.nan
        np.testing.assert_array_equal(prof.edges(s), ref_edges(prof, s))
        np.testing.assert_array_equal(prof.narrowest(s, ahead), ref_narrowest(prof, s, ahead))
        np.testing.assert_array_equal(prof.narrowest(s, 30.0), ref_narrowest(prof, s, 30.0))


def ref_wall_gap(road, q, width, length, reach_m):
    """``Loop._wall_gap`` before it was compiled (verbatim but for the arguments)."""
    ds = road.s0[None, :] - q[:, 0:1]
    if road.periodic:
        ds = np.mod(ds, road.length_m)
    half = 0.5 * width[:, None]
    out = (q[:, 1:2] - half < road.right[None, :]) | (
        q[:, 1:2] + half > road.left[None, :])
    wall = (ds > 0) & (ds < reach_m) & out
    gap = np.min(np.where(wall, ds, np.inf), axis=1) - 0.5 * length
    return gap


@pytest.mark.parametrize("periodic", [False, True])
def test_compiled_wall_gap_matches_the_numpy_one(periodic):
    from controllers.road.profile_kernels import first_wall_ahead
    from cosim.sim.loop import WALL_REACH_M

    rng = np.random.default_rng(9 + periodic)
    found = 0
    for _ in range(80):
        prof = _profile(rng, int(rng.choice([2, 3, 10, 40])), periodic)
        n = int(rng.integers(0, 60))
        q = np.column_stack([rng.uniform(-50.0, prof.length_m + 50.0, n),
                             rng.uniform(-4.0, 4.0, n)])
        width, length = rng.choice([1.8, 2.5], n), rng.choice([4.5, 12.0], n)
        want = ref_wall_gap(prof, q, width, length, WALL_REACH_M)
        got = first_wall_ahead(q[:, 0].copy(), q[:, 1].copy(), width, length, prof.s0,
                               prof.right, prof.left, periodic, prof.length_m, WALL_REACH_M)
        np.testing.assert_array_equal(got, want)
        found += int(np.isfinite(want).sum())
    assert found > 100
