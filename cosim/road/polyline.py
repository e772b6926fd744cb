"""The reference line as a polyline: arc length, the point at ``(s, d)``, the nearest point
and the projection of points onto it, and lines moved sideways.

:class:`Line` is a polyline of ``M`` segments (points ``(M+1, 2)``, m) with its cumulative
arc length, unit tangents and left normals; ``periodic`` closes it into a loop (the ring),
whose arc length wraps at :attr:`Line.length`. Distances are m, ``d`` is signed and
positive to the left of the line's direction. Plain numpy; the compiled road frame
(:mod:`cosim.road.frame_kernels`) repeats :meth:`Line.segment_of` and :meth:`Line.holding`
element by element with :data:`MAX_WALK` and :data:`FOOT_EPS`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from cosim.errors import NetworkError

#: Most segments a projection walks from its first guess (:meth:`Line.holding`).
MAX_WALK = 64
#: Slack (m) when deciding whether a projection's foot lies inside a segment.
FOOT_EPS = 1e-6
#: Up to this many segments :meth:`Line.nearest` measures every point against all.
_NEAREST_ALL_MAX = 64


@dataclass(frozen=True)
class Line:
    """A polyline of M segments (build it with :meth:`of`).

    Attributes:
        pts: points (M+1, 2), m.
        cum: arc length at each point (M+1,), m (``cum[0] = 0``).
        tan: unit tangent of each segment (M, 2).
        nrm: unit left normal of each segment (M, 2).
        seg: length of each segment (M,), m.
        periodic: a closed loop: the last point is the first, arc length wraps at
            :attr:`length`.
    """

    pts: np.ndarray
    cum: np.ndarray
    tan: np.ndarray
    nrm: np.ndarray
    seg: np.ndarray
    periodic: bool

    @classmethod
    def of(cls, pts: np.ndarray, periodic: bool) -> Line:
        """The line through points ``pts`` (M+1, 2) m, no two consecutive ones equal
        (:func:`dedupe`); ``periodic``: the last point repeats the first."""
        pts = np.asarray(pts, dtype=float)
        d = np.diff(pts, axis=0)
        seg = np.hypot(d[:, 0], d[:, 1])
        tan = d / seg[:, None]
        nrm = np.column_stack([-tan[:, 1], tan[:, 0]])
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        return cls(pts, cum, tan, nrm, seg, periodic)

    @property
    def length(self) -> float:
        """Total arc length, m."""
        return float(self.cum[-1])

    @property
    def n_seg(self) -> int:
        """Number of segments M."""
        return len(self.seg)

    def segment_of(self, s: np.ndarray) -> np.ndarray:
        """Index of the segment that holds each ``s`` (m; clamped at the ends)."""
        if self.periodic:
            s = np.mod(s, self.length)
        j = np.searchsorted(self.cum, s, side="right") - 1
        return np.clip(j, 0, self.n_seg - 1)

    def project_on(self, xy: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(along, d): foot of each point on the infinite line of segment ``j`` (m from the
        segment's start) and the signed distance (m, left positive)."""
        v = xy - self.pts[j]
        t = self.tan[j]
        along = v[:, 0] * t[:, 0] + v[:, 1] * t[:, 1]
        d = t[:, 0] * v[:, 1] - t[:, 1] * v[:, 0]
        return along, d

    def holding(self, xy: np.ndarray, j: np.ndarray) -> np.ndarray:
        """The segment on which each point's foot lies, walking from ``j`` (a guess)
        segment by segment; where no segment holds it (the outside of a bend) the last
        one the walk reached."""
        j = j.copy()
        n = self.n_seg
        last = np.zeros(len(j), dtype=int)
        active = np.ones(len(j), dtype=bool)
        for _ in range(MAX_WALK):
            a, _ = self.project_on(xy, j)
            step = np.where(a > self.seg[j] + FOOT_EPS, 1, np.where(a < -FOOT_EPS, -1, 0))
            if not self.periodic:  # an open line is extended beyond its ends
                step[(j == 0) & (step < 0)] = 0
                step[(j == n - 1) & (step > 0)] = 0
            step[~active | (step == -last)] = 0  # a reversal: the outside of a bend
            if not step.any():
                break
            active &= step != 0
            j = np.mod(j + step, n) if self.periodic else j + step
            last = np.where(step != 0, step, last)
        return j

    def project(self, xy: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(s, d)`` of points ``xy`` (K, 2), m: the foot on segment ``j`` (a guess) or on a
        neighbour that holds it (:meth:`holding`); an open line is extended beyond its ends."""
        j = self.holding(xy, j)
        a, d = self.project_on(xy, j)
        s = self.cum[j] + a
        if self.periodic:
            s = np.mod(s, self.length)
        return s, d

    def _inside(self, along: np.ndarray, j: np.ndarray) -> np.ndarray:
        lo = along >= -FOOT_EPS
        hi = along <= self.seg[j] + FOOT_EPS
        if not self.periodic:
            lo |= j == 0
            hi |= j == self.n_seg - 1
        return lo & hi

    def nearest(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(s, d, j)`` (K,) each of the nearest point of the line to each point ``xy``
        (K, 2) m (open lines are extended beyond their ends). Build-time only.

        Each point is measured against the segments that can hold its nearest point
        (:meth:`_candidates`: O(K log M) with a tree of the segments' middles, not K x M);
        :meth:`_nearest_among` measures them as the full search would, so the answer is
        the same to the bit (tests/test_road_frame.py)."""
        if self.n_seg <= _NEAREST_ALL_MAX or len(xy) == 0:
            return self._nearest_among(xy, None)
        return self._nearest_among(xy, self._candidates(xy))

    @cached_property
    def _middles(self):
        """A tree of the segments' middles and the longest half segment, m."""
        from scipy.spatial import cKDTree  # scipy: imported when first used

        return cKDTree(0.5 * (self.pts[:-1] + self.pts[1:])), 0.5 * float(self.seg.max())

    def _candidates(self, xy: np.ndarray) -> np.ndarray:
        """Segment indices (K, C), ascending in each row (a row's last repeated as padding),
        that include every segment nearest to each point.

        A segment's distance is at most that of its middle and at least the middle's less
        half its length, so the nearest lie within (distance to the nearest middle) + (the
        longest half segment) of their middles; an open line's end segments, extended
        without end, are always candidates."""
        tree, half_max = self._middles
        r0, _ = tree.query(xy)
        reach = r0 + half_max + 1e-6 + 1e-9 * r0  # rounding's slack
        lists = tree.query_ball_point(xy, reach)
        if not self.periodic:
            ends = [0, self.n_seg - 1]
            lists = [lst + ends for lst in lists]
        size = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
        cand = np.full((len(lists), int(size.max())), self.n_seg, dtype=np.int64)
        rows = np.repeat(np.arange(len(lists)), size)
        cols = np.arange(len(rows)) - np.repeat(np.cumsum(size) - size, size)
        cand[rows, cols] = np.concatenate([np.asarray(lst, dtype=np.int64) for lst in lists])
        cand.sort(axis=1)
        last = cand[np.arange(len(cand)), size - 1]
        return np.where(cand == self.n_seg, last[:, None], cand)

    def _nearest_among(self, xy: np.ndarray, cand: np.ndarray | None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`nearest` over the segments ``cand`` (K, C) of each point (ascending; a
        repeat only after its first place), or over all of them (None), in chunks."""
        k = len(xy)
        s_out, d_out, j_out = np.empty(k), np.empty(k), np.empty(k, dtype=int)
        width = self.n_seg if cand is None else cand.shape[1]
        chunk = max(1, 2_000_000 // max(width, 1))
        lo_all = np.zeros(self.n_seg)
        hi_all = self.seg.copy()
        if not self.periodic:
            lo_all[0], hi_all[-1] = -np.inf, np.inf
        for a in range(0, k, chunk):
            p = xy[a:a + chunk]
            r = np.arange(len(p))
            c = (np.broadcast_to(np.arange(self.n_seg), (len(p), self.n_seg)) if cand is None
                 else cand[a:a + chunk])
            start, tan = self.pts[c], self.tan[c]  # (k, C, 2)
            v = p[:, None, :] - start
            along = v[:, :, 0] * tan[:, :, 0] + v[:, :, 1] * tan[:, :, 1]
            t = np.clip(along, lo_all[c], hi_all[c])
            foot = start + t[:, :, None] * tan
            dist = np.hypot(p[:, None, 0] - foot[:, :, 0], p[:, None, 1] - foot[:, :, 1])
            col = np.argmin(dist, axis=1)
            j = c[r, col]
            s_out[a:a + chunk] = self.cum[j] + t[r, col]
            vv = v[r, col]
            tt = self.tan[j]
            d_out[a:a + chunk] = tt[:, 0] * vv[:, 1] - tt[:, 1] * vv[:, 0]
            j_out[a:a + chunk] = j
        if self.periodic:
            s_out = np.mod(s_out, self.length)
        return s_out, d_out, j_out

    def point(self, s: np.ndarray, d: np.ndarray) -> np.ndarray:
        """``(x, y)`` (K, 2) of road-frame positions: the point at ``s`` plus ``d`` times
        the left normal of the segment that holds ``s`` (the inverse of :meth:`project`)."""
        s = np.asarray(s, dtype=float)
        j = self.segment_of(s)
        if self.periodic:
            s = np.mod(s, self.length)
        a = s - self.cum[j]
        return self.pts[j] + a[:, None] * self.tan[j] + np.asarray(d, float)[:, None] * self.nrm[j]


def dedupe(pts: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """``pts`` (V, 2) m without consecutive repeats (points closer than ``eps`` m to the one
    before them)."""
    if len(pts) < 2:
        return pts
    keep = np.concatenate([[True], np.hypot(*np.diff(pts, axis=0).T) > eps])
    return pts[keep]


def offset_polyline(pts: np.ndarray, c: float, periodic: bool) -> np.ndarray:
    """``pts`` (V, 2) m moved sideways by ``c`` (m, left positive), vertices on the mitre
    (as SUMO's ``PositionVector::move2side`` builds lane shapes from an edge's line);
    ``periodic``: a closed loop (the last point is the first). Raises NetworkError where
    two segments turn by more than about 150 degrees (their cosine below -0.9)."""
    if c == 0.0:
        return pts.copy()
    d = np.diff(pts, axis=0)
    t = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    n = np.column_stack([-t[:, 1], t[:, 0]])
    out = np.empty_like(pts)
    m = len(t)
    for i in range(len(pts)):
        if periodic:
            a, b = n[(i - 1) % m], n[i % m]
        elif i == 0:
            a = b = n[0]
        elif i == len(pts) - 1:
            a = b = n[-1]
        else:
            a, b = n[i - 1], n[i]
        cos = float(a @ b)
        if cos < -0.9:
            raise NetworkError("the main route turns back on itself (a turn of more than "
                               "150 degrees between two edges): the road frame cannot follow it")
        out[i] = pts[i] + c * (a + b) / (1.0 + cos)
    if periodic:
        out[-1] = out[0]
    return out
