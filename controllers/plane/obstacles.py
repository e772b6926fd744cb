"""Obstacles of any shape as sets of boundary points (seed 003, Sec. 2.1 and 3.1).

Seed 003 relaxes Olfati-Saber's assumption that obstacles are spheres or
infinite walls: an agent perceives only the *boundary points* of obstacles
within its sensing radius ``r`` (the set ``N_i^beta`` of eq. 3), each a
beta-agent. This module describes obstacles geometrically and samples their
boundaries:

* :class:`Circle` (the paper's "spherical" obstacle in the plane);
* :class:`Polygon`, with the factories :func:`rectangle`, :func:`diamond` and
  :func:`c_shape` (the non-convex C of the paper's multi-obstacle scene);
* :class:`Wall`, a straight segment; ``Wall.infinite`` samples a long piece of
  a line that bounds a half-plane (OS06's "infinite wall").

:class:`ObstacleSet` joins them: ``boundary_points(spacing)`` gives the (K, 2)
point cloud a controller senses, ``signed_distance(q)`` the exact distance of
agents to the true geometry (negative inside) for metrics, and ``sense`` /
:func:`sense` the agent-point pairs within the sensing radius (KD-tree, never
N x K dense). ``cosim_obstacles()`` converts the set into the ``Circles`` and
``Walls`` that the Olfati-Saber controller understands (circles and infinite
walls exactly; polygons as a chain of small discs along their boundary, an
approximation because OS06 Algorithm 3 has no polygon obstacles).

All lengths in m; points are 2-D (the road plane).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from controllers.observation import Circles, Walls

if TYPE_CHECKING:  # imported where used: not at start-up (cosim list, config)
    from scipy.spatial import cKDTree


def _check_spacing(spacing: float) -> float:
    if not (isinstance(spacing, int | float) and math.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing must be a finite number > 0 (m), got {spacing!r}")
    return float(spacing)


def sample_segment(a: np.ndarray, b: np.ndarray, spacing: float, closed_end: bool = True):
    """Points from ``a`` to ``b`` (each (2,)), evenly spaced at most ``spacing`` apart, m.

    ``closed_end=False`` leaves out ``b`` (used for polygon edges so vertices
    appear once). Returns (n, 2).
    """
    spacing = _check_spacing(spacing)
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    n_seg = max(1, math.ceil(float(np.linalg.norm(b - a)) / spacing))
    t = np.arange(n_seg + (1 if closed_end else 0)) / n_seg
    return a[None, :] + t[:, None] * (b - a)[None, :]


def segment_distance(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distance (N,) from points ``q`` (N, 2) to the segment a-b, m."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    ab = np.asarray(b, dtype=float) - np.asarray(a, dtype=float)
    den = float(ab @ ab)
    t = np.zeros(len(q)) if den == 0 else np.clip((q - a) @ ab / den, 0.0, 1.0)
    return np.linalg.norm(q - (a + t[:, None] * ab), axis=1)


@dataclass(frozen=True)
class Circle:
    """Circular obstacle: centre (2,) and radius, m."""

    centre: tuple[float, float]
    radius: float
    name: str = "circle"

    def __post_init__(self) -> None:
        c = tuple(float(v) for v in np.asarray(self.centre, dtype=float).ravel())
        if len(c) != 2 or not all(math.isfinite(v) for v in c):
            raise ValueError(f"centre must be 2 finite numbers, got {self.centre!r}")
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"radius must be > 0 (m), got {self.radius!r}")
        object.__setattr__(self, "centre", c)

    def boundary(self, spacing: float) -> np.ndarray:
        """Points on the circle (n, 2), chord spacing <= ``spacing``, m."""
        spacing = _check_spacing(spacing)
        n = max(3, math.ceil(2.0 * math.pi * self.radius / spacing))
        ang = 2.0 * math.pi * np.arange(n) / n
        return np.asarray(self.centre) + self.radius * np.column_stack([np.cos(ang), np.sin(ang)])

    def signed_distance(self, q: np.ndarray) -> np.ndarray:
        """Distance (N,) from points to the circle's surface, negative inside, m."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return np.linalg.norm(q - np.asarray(self.centre), axis=1) - self.radius

    def extent(self) -> np.ndarray:
        """Bounding box ``[[xmin, ymin], [xmax, ymax]]``, m."""
        c = np.asarray(self.centre)
        return np.stack([c - self.radius, c + self.radius])

    def discs(self, radius: float | None = None) -> list[tuple[np.ndarray, float]]:
        """The circle itself as one Olfati-Saber disc obstacle."""
        return [(np.asarray(self.centre), self.radius)]


@dataclass(frozen=True, eq=False)
class Polygon:
    """Closed simple polygon (convex or not) given by its vertices (V, 2), m."""

    vertices: np.ndarray
    name: str = "polygon"

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=float)
        if v.ndim != 2 or v.shape[1] != 2 or len(v) < 3:
            raise ValueError(f"vertices must have shape (V >= 3, 2), got {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError("vertices must be finite")
        if np.any(np.linalg.norm(np.roll(v, -1, axis=0) - v, axis=1) == 0):
            raise ValueError("vertices: two consecutive vertices coincide")
        v = v.copy()
        v.setflags(write=False)
        object.__setattr__(self, "vertices", v)

    @property
    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """Edge start and end points, each (V, 2)."""
        return self.vertices, np.roll(self.vertices, -1, axis=0)

    def boundary(self, spacing: float) -> np.ndarray:
        """Points along all edges (vertices included once), spacing <= ``spacing``, m."""
        a, b = self.edges
        return np.vstack(
            [sample_segment(p, q, spacing, closed_end=False) for p, q in zip(a, b, strict=True)]
        )

    def contains(self, q: np.ndarray) -> np.ndarray:
        """Even-odd point-in-polygon test (N,) bool."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        a, b = self.edges
        x, y = q[:, 0:1], q[:, 1:2]
        ya, yb = a[None, :, 1], b[None, :, 1]
        crosses = (ya > y) != (yb > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_int = a[None, :, 0] + (y - ya) * (b[None, :, 0] - a[None, :, 0]) / (yb - ya)
        return (np.count_nonzero(crosses & (x < x_int), axis=1) % 2) == 1

    def signed_distance(self, q: np.ndarray) -> np.ndarray:
        """Distance (N,) from points to the polygon's boundary, negative inside, m."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        a, b = self.edges
        dist = np.min(
            np.stack([segment_distance(q, p, r) for p, r in zip(a, b, strict=True)]), axis=0
        )
        return np.where(self.contains(q), -dist, dist)

    def extent(self) -> np.ndarray:
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def discs(self, radius: float = 0.5) -> list[tuple[np.ndarray, float]]:
        """Discs of ``radius`` centred on the boundary, spaced ``radius`` apart.

        An approximation for controllers that know only discs (OS06): the union
        is the polygon's outline thickened by ``radius`` (scalloped by at most
        ``radius (1 - sqrt(3)/2)``).
        """
        return [(c, float(radius)) for c in self.boundary(radius)]


def rectangle(centre, width: float, height: float, angle: float = 0.0, name="rectangle"):
    """Axis-aligned ``width`` x ``height`` rectangle rotated by ``angle`` (rad), m."""
    if not (width > 0 and height > 0):
        raise ValueError(f"width and height must be > 0, got {width!r}, {height!r}")
    w, h = 0.5 * width, 0.5 * height
    v = np.array([[-w, -h], [w, -h], [w, h], [-w, h]])
    return Polygon(_place(v, centre, angle), name=name)


def diamond(centre, half_x: float, half_y: float | None = None, name="diamond"):
    """Rhombus with half-diagonals ``half_x`` (along x) and ``half_y`` (along y), m."""
    half_y = half_x if half_y is None else half_y
    if not (half_x > 0 and half_y > 0):
        raise ValueError(f"half diagonals must be > 0, got {half_x!r}, {half_y!r}")
    v = np.array([[half_x, 0.0], [0.0, half_y], [-half_x, 0.0], [0.0, -half_y]])
    return Polygon(_place(v, centre, 0.0), name=name)


def c_shape(
    centre, width: float, height: float, thickness: float, opening: float = 0.0, name="c_shape"
):
    """C-shaped (non-convex) polygon: outer ``width`` x ``height``, arms ``thickness`` thick.

    The mouth faces direction ``opening`` (rad; 0 = +x, pi = -x, towards the
    flock in the paper's scene). The pocket is ``width - thickness`` deep and
    ``height - 2 thickness`` wide. m.
    """
    if not (width > thickness > 0 and height > 2.0 * thickness):
        raise ValueError(
            f"need width > thickness > 0 and height > 2 thickness, got width={width!r}, "
            f"height={height!r}, thickness={thickness!r}"
        )
    w, h, t = 0.5 * width, 0.5 * height, thickness
    v = np.array(
        [
            [w, h],
            [-w, h],
            [-w, -h],
            [w, -h],
            [w, -h + t],
            [-w + t, -h + t],
            [-w + t, h - t],
            [w, h - t],
        ]
    )
    return Polygon(_place(v, centre, opening), name=name)


def _place(v: np.ndarray, centre, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    return v @ rot.T + np.asarray(centre, dtype=float)


@dataclass(frozen=True)
class Wall:
    """Straight wall segment from ``a`` to ``b`` (m), zero thickness.

    ``normal`` (optional unit vector) marks the free side: then
    ``signed_distance`` is negative behind the wall (within its length) and the
    wall converts to an Olfati-Saber infinite wall. Without a normal the wall is
    a thin barrier, free on both sides.
    """

    a: tuple[float, float]
    b: tuple[float, float]
    normal: tuple[float, float] | None = None
    name: str = "wall"

    def __post_init__(self) -> None:
        a = np.asarray(self.a, dtype=float).ravel()
        b = np.asarray(self.b, dtype=float).ravel()
        if a.shape != (2,) or b.shape != (2,) or not np.all(np.isfinite(np.r_[a, b])):
            raise ValueError(f"a and b must be 2 finite numbers each, got {self.a!r}, {self.b!r}")
        if np.allclose(a, b):
            raise ValueError("wall: a and b coincide")
        object.__setattr__(self, "a", tuple(a))
        object.__setattr__(self, "b", tuple(b))
        if self.normal is not None:
            n = np.asarray(self.normal, dtype=float).ravel()
            if n.shape != (2,) or not np.linalg.norm(n) > 0:
                raise ValueError(f"normal must be a non-zero 2-vector, got {self.normal!r}")
            n = n / np.linalg.norm(n)
            if abs(float(n @ (b - a))) > 1e-6 * np.linalg.norm(b - a):
                raise ValueError("normal must be perpendicular to the wall")
            object.__setattr__(self, "normal", tuple(n))

    @classmethod
    def infinite(cls, point, normal, half_length: float = 200.0, name="wall") -> Wall:
        """A line through ``point`` bounding the half-plane on the ``normal`` side.

        Sampled over ``2 * half_length`` (m) centred on ``point``; agents only
        sense points within ``r``, so a long segment stands for the line.
        """
        n = np.asarray(normal, dtype=float)
        n = n / np.linalg.norm(n)
        t = np.array([-n[1], n[0]])
        p = np.asarray(point, dtype=float)
        return cls(p - half_length * t, p + half_length * t, tuple(n), name=name)

    def boundary(self, spacing: float) -> np.ndarray:
        return sample_segment(np.asarray(self.a), np.asarray(self.b), spacing)

    def signed_distance(self, q: np.ndarray) -> np.ndarray:
        """Distance (N,) to the segment; with a normal, negative behind it (within its span)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        a, b = np.asarray(self.a), np.asarray(self.b)
        dist = segment_distance(q, a, b)
        if self.normal is None:
            return dist
        ab = b - a
        t = (q - a) @ ab / float(ab @ ab)
        behind = ((q - a) @ np.asarray(self.normal) < 0) & (t >= 0) & (t <= 1)
        return np.where(behind, -dist, dist)

    def extent(self) -> np.ndarray:
        pts = np.array([self.a, self.b])
        return np.stack([pts.min(axis=0), pts.max(axis=0)])

    def discs(self, radius: float = 0.5) -> list[tuple[np.ndarray, float]]:
        """Discs along the segment (see :meth:`Polygon.discs`)."""
        return [(c, float(radius)) for c in self.boundary(radius)]


Obstacle = Circle | Polygon | Wall


def sense(
    q: np.ndarray, points: np.ndarray, radius: float, tree: cKDTree | None = None
) -> np.ndarray:
    """Pairs (i, k) with ``||points_k - q_i|| < radius`` (eq. 3's ``N_i^beta``); (P, 2) int64.

    Rows are grouped by agent ``i`` in increasing order. KD-tree over the
    points (pass a prebuilt ``tree`` for a static set); memory O(N + K + P).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if len(q) == 0 or len(points) == 0:
        return np.empty((0, 2), dtype=np.int64)
    from scipy.spatial import cKDTree

    tree = cKDTree(points) if tree is None else tree
    lists = tree.query_ball_point(q, np.nextafter(radius, 0.0))
    counts = np.fromiter((len(v) for v in lists), dtype=np.int64, count=len(lists))
    if counts.sum() == 0:
        return np.empty((0, 2), dtype=np.int64)
    i = np.repeat(np.arange(len(q), dtype=np.int64), counts)
    k = np.fromiter((kk for v in lists for kk in v), dtype=np.int64, count=int(counts.sum()))
    return np.stack([i, k], axis=1)


@dataclass(frozen=True, eq=False)
class ObstacleSet:
    """A scene's obstacles; ``boundary_points`` is what a seed-003 agent perceives."""

    obstacles: tuple = ()
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        obs = tuple(self.obstacles)
        for o in obs:
            if not isinstance(o, Circle | Polygon | Wall):
                raise TypeError(f"not an obstacle: {o!r}")
        object.__setattr__(self, "obstacles", obs)

    def __len__(self) -> int:
        return len(self.obstacles)

    def __iter__(self):
        return iter(self.obstacles)

    def boundary_points(self, spacing: float = 0.5) -> np.ndarray:
        """All boundary points (K, 2), m; cached per spacing (read-only array)."""
        spacing = _check_spacing(spacing)
        key = ("pts", spacing)
        if key not in self._cache:
            pts = (
                np.vstack([o.boundary(spacing) for o in self.obstacles])
                if self.obstacles
                else np.empty((0, 2))
            )
            pts.setflags(write=False)
            self._cache[key] = pts
        return self._cache[key]

    def labels(self, spacing: float = 0.5) -> np.ndarray:
        """Index (K,) of the obstacle each boundary point belongs to."""
        sizes = [len(o.boundary(spacing)) for o in self.obstacles]
        return np.repeat(np.arange(len(sizes)), sizes)

    def tree(self, spacing: float = 0.5) -> cKDTree:
        """KD-tree of the boundary points (cached)."""
        key = ("tree", _check_spacing(spacing))
        if key not in self._cache:
            from scipy.spatial import cKDTree

            self._cache[key] = cKDTree(self.boundary_points(spacing))
        return self._cache[key]

    def sense(self, q: np.ndarray, radius: float, spacing: float = 0.5) -> np.ndarray:
        """Agent-point pairs (P, 2) within ``radius`` (see :func:`sense`)."""
        return sense(q, self.boundary_points(spacing), radius, self.tree(spacing))

    def signed_distance(self, q: np.ndarray) -> np.ndarray:
        """Smallest signed distance (N,) from each point to any obstacle, m (inf if none).

        Same values as the obstacles' own ``signed_distance``, in one vectorised
        pass over all circles and all wall/polygon segments (N x segments).
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if not self.obstacles:
            return np.full(len(q), np.inf)
        g = self._geometry()
        best = np.full(len(q), np.inf)
        if len(g["c_centre"]):
            dc = np.sqrt(
                (q[:, None, 0] - g["c_centre"][None, :, 0]) ** 2
                + (q[:, None, 1] - g["c_centre"][None, :, 1]) ** 2
            )
            best = np.minimum(best, np.min(dc - g["c_radius"][None, :], axis=1))
        if len(g["s_a"]):
            a, ab, inv = g["s_a"], g["s_ab"], g["s_inv"]
            qa_x = q[:, None, 0] - a[None, :, 0]
            qa_y = q[:, None, 1] - a[None, :, 1]
            t_raw = (qa_x * ab[None, :, 0] + qa_y * ab[None, :, 1]) * inv[None, :]
            t = np.clip(t_raw, 0.0, 1.0)
            dist = np.sqrt((qa_x - t * ab[None, :, 0]) ** 2 + (qa_y - t * ab[None, :, 1]) ** 2)
            per_obst = np.minimum.reduceat(dist, g["s_start"], axis=1)  # (N, obstacles)
            sign = np.ones_like(per_obst)
            for col, (kind, k0, k1, nrm) in enumerate(g["s_kind"]):
                if kind == "polygon":
                    # even-odd rule over this polygon's edges
                    ya, yb = a[k0:k1, 1], a[k0:k1, 1] + ab[k0:k1, 1]
                    y = q[:, 1:2]
                    crosses = (ya[None, :] > y) != (yb[None, :] > y)
                    with np.errstate(divide="ignore", invalid="ignore"):
                        x_int = (
                            a[None, k0:k1, 0]
                            + (y - ya[None, :]) * ab[None, k0:k1, 0] / (ab[None, k0:k1, 1])
                        )
                    inside = (np.count_nonzero(crosses & (q[:, 0:1] < x_int), axis=1) % 2) == 1
                    sign[inside, col] = -1.0
                elif nrm is not None:
                    behind = ((qa_x[:, k0] * nrm[0] + qa_y[:, k0] * nrm[1]) < 0) & (
                        (t_raw[:, k0] >= 0) & (t_raw[:, k0] <= 1)
                    )
                    sign[behind, col] = -1.0
            best = np.minimum(best, np.min(sign * per_obst, axis=1))
        return best

    def _geometry(self) -> dict:
        """Stacked circles and segments (cached) for :meth:`signed_distance`."""
        if "geom" in self._cache:
            return self._cache["geom"]
        cc, cr, sa, sb, kinds, starts = [], [], [], [], [], []
        for o in self.obstacles:
            if isinstance(o, Circle):
                cc.append(o.centre)
                cr.append(o.radius)
                continue
            starts.append(len(sa))
            if isinstance(o, Polygon):
                a, b = o.edges
                kinds.append(("polygon", len(sa), len(sa) + len(a), None))
                sa.extend(a)
                sb.extend(b)
            else:
                kinds.append(("wall", len(sa), len(sa) + 1, o.normal))
                sa.append(np.asarray(o.a))
                sb.append(np.asarray(o.b))
        s_a = np.array(sa, dtype=float).reshape(-1, 2)
        s_ab = np.array(sb, dtype=float).reshape(-1, 2) - s_a
        geom = {
            "c_centre": np.array(cc, dtype=float).reshape(-1, 2),
            "c_radius": np.array(cr, dtype=float),
            "s_a": s_a,
            "s_ab": s_ab,
            "s_inv": 1.0 / np.sum(s_ab * s_ab, axis=1),
            "s_start": np.array(starts, dtype=np.int64),
            "s_kind": kinds,
        }
        self._cache["geom"] = geom
        return geom

    def min_point_distance(self, q: np.ndarray, spacing: float = 0.5) -> np.ndarray:
        """Distance (N,) from each agent to its nearest boundary point, m (seed 003 Fig. 6)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if not self.obstacles:
            return np.full(len(q), np.inf)
        dist, _ = self.tree(spacing).query(q, k=1)
        return dist

    def cosim_obstacles(self, disc_radius: float = 0.5) -> tuple[Circles | None, Walls | None]:
        """``(Circles, Walls)`` for :class:`~controllers.plane.olfati_saber.OlfatiSaberController`.

        Circles map exactly; walls with a ``normal`` become OS06 infinite walls
        (hyperplanes); polygons and walls without a normal become discs of
        ``disc_radius`` along their boundary (OS06 knows no other shapes).
        """
        centres, radii, w_pts, w_nrm = [], [], [], []
        for o in self.obstacles:
            if isinstance(o, Wall) and o.normal is not None:
                w_pts.append(o.a)
                w_nrm.append(o.normal)
                continue
            for c, r in o.discs(disc_radius) if not isinstance(o, Circle) else o.discs():
                centres.append(c)
                radii.append(r)
        circles = Circles(np.array(centres), np.array(radii)) if centres else None
        walls = Walls(np.array(w_pts), np.array(w_nrm)) if w_pts else None
        return circles, walls

    def extent(self, finite_only: bool = True) -> np.ndarray:
        """Bounding box of the obstacles (infinite walls left out by default), m."""
        boxes = [
            o.extent()
            for o in self.obstacles
            if not (finite_only and isinstance(o, Wall) and o.normal is not None)
        ]
        if not boxes:
            return np.full((2, 2), np.nan)
        b = np.stack(boxes)
        return np.stack([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])
