"""The reference line's nearest-point search (``cosim.road.polyline.Line.nearest``, used
when a network's road frame is built) prunes the segments it measures each point
against; it must give the bits of the full K x M search it replaced (copied below
verbatim from commit 7f4978f) on rings, open lines, points far off and exactly between
segments. No SUMO."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.road.polyline import Line


def _nearest_full(line, xy):  # commit 7f4978f's _Line.nearest, verbatim
    k = len(xy)
    s_out, d_out, j_out = np.empty(k), np.empty(k), np.empty(k, dtype=int)
    chunk = max(1, 2_000_000 // max(line.n_seg, 1))
    for a in range(0, k, chunk):
        p = xy[a:a + chunk]
        v = p[:, None, :] - line.pts[None, :-1, :]
        along = np.einsum("kmi,mi->km", v, line.tan)
        lo = np.zeros(line.n_seg)
        hi = line.seg.copy()
        if not line.periodic:
            lo[0], hi[-1] = -np.inf, np.inf
        t = np.clip(along, lo, hi)
        foot = line.pts[None, :-1, :] + t[:, :, None] * line.tan[None, :, :]
        dist = np.hypot(p[:, None, 0] - foot[:, :, 0], p[:, None, 1] - foot[:, :, 1])
        j = np.argmin(dist, axis=1)
        r = np.arange(len(p))
        s_out[a:a + chunk] = line.cum[j] + t[r, j]
        vv = v[r, j]
        tt = line.tan[j]
        d_out[a:a + chunk] = tt[:, 0] * vv[:, 1] - tt[:, 1] * vv[:, 0]
        j_out[a:a + chunk] = j
    if line.periodic:
        s_out = np.mod(s_out, line.length)
    return s_out, d_out, j_out


def _ring(n_seg: int, radius_m: float) -> Line:
    a = np.linspace(0.0, 2 * np.pi, n_seg + 1)
    pts = np.column_stack([radius_m * np.cos(a), radius_m * np.sin(a)])
    pts[-1] = pts[0]
    return Line.of(pts, True)


def _wiggle(n_seg: int, rng) -> Line:
    """An open line with kinks, short and long segments and a hairpin."""
    steps = rng.uniform(0.2, 40.0, n_seg)
    heading = np.cumsum(rng.normal(0.0, 0.3, n_seg))
    heading[n_seg // 2:] += np.pi * 0.9  # a hairpin: far parts of the line come close
    pts = np.vstack([[0.0, 0.0], np.cumsum(np.column_stack(
        [steps * np.cos(heading), steps * np.sin(heading)]), axis=0)])
    return Line.of(pts, False)


def _points(line: Line, rng, k: int) -> np.ndarray:
    """Points near the line, far off it, beyond an open line's ends, on its vertices and
    on the bisectors between segments (ties)."""
    lo, hi = line.pts.min(axis=0), line.pts.max(axis=0)
    span = hi - lo
    near = line.pts[rng.integers(0, len(line.pts), k)] + rng.normal(0.0, 3.0, (k, 2))
    far = rng.uniform(lo - span, hi + span, (k // 4, 2))
    ends = np.vstack([line.pts[0] - 50 * line.tan[0], line.pts[-1] + 50 * line.tan[-1]])
    mids = 0.5 * (line.pts[:-1] + line.pts[1:])
    return np.vstack([near, far, ends, line.pts, mids, (line.pts[:-2] + line.pts[2:]) / 2])


@pytest.mark.parametrize("make", [
    lambda rng: _ring(2000, 1591.5),  # a 10 km ring of 5 m chords
    lambda rng: _ring(100, 40.0),
    lambda rng: _wiggle(400, rng),
    lambda rng: _wiggle(70, rng),
    lambda rng: _wiggle(30, rng),  # few segments: the full search itself
])
def test_pruned_search_gives_the_full_searchs_bits(make):
    rng = np.random.default_rng(15)
    line = make(rng)
    xy = _points(line, rng, 3000)
    got = line.nearest(xy)
    want = _nearest_full(line, xy)
    for g, w, name in zip(got, want, ("s", "d", "j"), strict=True):
        assert g.dtype == w.dtype, name
        assert np.array_equal(g, w), f"{name}: {np.flatnonzero(g != w)[:5]}"


def test_candidates_are_few_on_a_long_ring():
    """What makes the build linear: each point is measured against a handful of the 2000
    segments, not all of them."""
    line = _ring(2000, 1591.5)
    rng = np.random.default_rng(3)
    xy = _points(line, rng, 500)[:500]
    assert line._candidates(xy).shape[1] <= 8
