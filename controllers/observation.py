"""What a controller sees each control step: the seam between a world and a law.

All arrays are numpy, SI units. ``m`` is the space dimension (1, 2 or 3; the
road uses m = 2 with axis 0 = longitudinal ``s`` and axis 1 = lateral ``d``,
positive to the left). A world (the plane world or the SUMO adapter) builds one
:class:`Observation` per step; a controller returns ``u`` with shape (N, m).
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields

import numpy as np


class InvalidStateError(ValueError):
    """A NaN or infinite state entered a controller; the message names the agent."""


@dataclass(frozen=True)
class Walls:
    """Infinite straight walls (seed 003 eq. 5): a point ``y`` on each and its unit normal.

    Shapes: ``points`` (K, m) in m, ``normals`` (K, m) unit vectors pointing
    into the free space (towards the agents).
    """

    points: np.ndarray
    normals: np.ndarray

    def __post_init__(self) -> None:
        pts = np.atleast_2d(np.asarray(self.points, dtype=float))
        nrm = np.atleast_2d(np.asarray(self.normals, dtype=float))
        if pts.shape != nrm.shape:
            raise ValueError(f"walls: points {pts.shape} and normals {nrm.shape} differ")
        norms = np.linalg.norm(nrm, axis=1)
        if np.any(norms <= 0):
            raise ValueError("walls: a normal has zero length")
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "normals", nrm / norms[:, None])


@dataclass(frozen=True)
class Circles:
    """Circular (spherical) obstacles: centres ``y_k`` (K, m) in m and radii ``R_k`` (K,) in m."""

    centres: np.ndarray
    radii: np.ndarray

    def __post_init__(self) -> None:
        c = np.atleast_2d(np.asarray(self.centres, dtype=float))
        r = np.atleast_1d(np.asarray(self.radii, dtype=float))
        if c.shape[0] != r.shape[0]:
            raise ValueError(f"circles: {c.shape[0]} centres but {r.shape[0]} radii")
        if np.any(r <= 0):
            raise ValueError("circles: radius must be > 0")
        object.__setattr__(self, "centres", c)
        object.__setattr__(self, "radii", r)


@dataclass(frozen=True)
class RoadProfile:
    """Lateral road edges along the road, piecewise constant (pure numpy).

    ``s0`` (K,) m: start of each piece along the road (increasing, ``s0[0] <= 0``);
    ``right``, ``left`` (K,) m: lateral positions of the right and left edge on that
    piece (road frame, left positive); ``length_m``: road length, m; ``periodic``: ring.
    """

    s0: np.ndarray
    right: np.ndarray
    left: np.ndarray
    length_m: float
    periodic: bool = False

    def __post_init__(self) -> None:
        for name in ("s0", "right", "left"):
            object.__setattr__(self, name, np.atleast_1d(np.asarray(getattr(self, name), float)))
        if not (self.s0.shape == self.right.shape == self.left.shape) or len(self.s0) == 0:
            raise ValueError("road profile: s0, right and left must have one equal length K > 0")
        if np.any(np.diff(self.s0) < 0):
            raise ValueError("road profile: s0 must be increasing")
        if np.any(self.left <= self.right):
            raise ValueError("road profile: left edge must lie left of the right edge")

    @classmethod
    def constant(cls, width_m: float, length_m: float, periodic: bool = False) -> RoadProfile:
        """A road of constant width, centred on the centre line."""
        return cls(np.zeros(1), np.array([-0.5 * width_m]), np.array([0.5 * width_m]),
                   float(length_m), periodic)

    @property
    def is_constant(self) -> bool:
        return len(self.s0) == 1

    def edges(self, s: np.ndarray) -> np.ndarray:
        """Edges (N, 2) m ``[right, left]`` at positions ``s`` (N,) m (clamped at the ends)."""
        s = np.asarray(s, dtype=float)
        if self.is_constant:  # one piece: its edges everywhere
            out = np.empty((len(s), 2))
            out[:, 0] = self.right[0]
            out[:, 1] = self.left[0]
            return out
        if s.ndim == 1 and s.dtype == np.float64:  # compiled (controllers.road.profile_kernels)
            from controllers.road import profile_kernels as PK  # numba: imported when first used

            return PK.edges_at(s, self.s0, self.right, self.left, self.periodic,
                               float(self.length_m))
        if self.periodic:
            s = np.mod(s, self.length_m)
        k = np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, len(self.s0) - 1)
        out = np.empty((len(s), 2))
        out[:, 0] = self.right[k]
        out[:, 1] = self.left[k]
        return out

    def narrowest(self, s: np.ndarray, ahead_m: np.ndarray | float) -> np.ndarray:
        """Narrowest edges (N, 2) m over ``[s, s + ahead_m]``: max right, min left edge.

        One (N, K) pass over the K pieces (K is small: the road's width changes), the
        pieces that ``[s, s + ahead]`` touches (and, on a ring, the same pieces one lap on).
        """
        s = np.asarray(s, dtype=float)
        if self.is_constant:
            return self.edges(s)
        ahead = np.broadcast_to(np.asarray(ahead_m, dtype=float), s.shape)
        if s.ndim == 1:  # compiled (controllers.road.profile_kernels)
            from controllers.road import profile_kernels as PK

            return PK.narrowest_over(s, np.ascontiguousarray(ahead), self.s0, self.right,
                                     self.left, self.periodic, float(self.length_m))
        out = self.edges(s)
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


def _as_n(v: np.ndarray, n: int) -> np.ndarray:
    """``v`` as an (n,) array: itself when it has that shape, else broadcast (a scalar or
    a (1,) array: a read-only view)."""
    if v.shape == (n,):
        return v
    return np.broadcast_to(v, (n,))


@dataclass(frozen=True)
class Observation:
    """One control step's view of the world.

    Attributes:
        q: (N, m) positions of the controlled alpha-agents, m.
        p: (N, m) velocities, m/s.
        t: time, s.
        dt: control step, s.
        ids: (N,) vehicle ids (any hashable); defaults to 0..N-1.
        length, width: (N,) body sizes of the agents, m (None: points).
        others_q, others_p: (M, m) sensed but non-cooperating road users
            (human-driven vehicles, stopped vehicles), treated as rectangles.
        others_length, others_width: (M,) their sizes, m.
        circles: circular obstacles, or None.
        walls: straight walls, or None.
        road_edges: (N, 2) lateral positions of the right and left road edge
            at each agent's longitudinal position, m (road frame only).
        leader_q, leader_p: gamma-agent position (m,) or per-agent (N, m), m and m/s.
        period_s: length of a periodic axis 0 (ring road), m, or None.
        desired_speed: (N,) each agent's desired speed along the road, m/s (road only).
        road: the road's edges along its length (:class:`RoadProfile`, road only).
        others_ids: (M,) ids of the sensed vehicles (road only).
        exits: (K, 4) the road's exits (off-ramps), rows ``(s_start, s_gore, d_right,
            d_left)``, m: where the lanes that lead onto the exit start and end (the gore,
            where the exit leaves the road) and their right and left border (road only).
        exit_index: (N,) int: 0 for an agent that stays on the road, k >= 1 for one that
            leaves it by ``exits[k - 1]`` (road only).
        entries: (J, 4) the road's entry strips (an on-ramp's acceleration lane beside the
            road), rows ``(s_start, s_end, d_right, d_left)``, m (road only).
        extras: law-specific inputs (e.g. seed 003's boundary points).
    """

    q: np.ndarray
    p: np.ndarray
    t: float = 0.0
    dt: float = 0.1
    ids: np.ndarray | None = None
    length: np.ndarray | None = None
    width: np.ndarray | None = None
    others_q: np.ndarray | None = None
    others_p: np.ndarray | None = None
    others_length: np.ndarray | None = None
    others_width: np.ndarray | None = None
    circles: Circles | None = None
    walls: Walls | None = None
    road_edges: np.ndarray | None = None
    leader_q: np.ndarray | None = None
    leader_p: np.ndarray | None = None
    period_s: float | None = None
    desired_speed: np.ndarray | None = None
    road: RoadProfile | None = None
    others_ids: np.ndarray | None = None
    exits: np.ndarray | None = None
    exit_index: np.ndarray | None = None
    entries: np.ndarray | None = None
    extras: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        q = np.asarray(self.q, dtype=float)
        p = np.asarray(self.p, dtype=float)
        if q.ndim != 2:
            raise ValueError(f"q must have shape (N, m), got {q.shape}")
        if p.shape != q.shape:
            raise ValueError(f"p has shape {p.shape} but q has shape {q.shape}")
        if q.shape[1] not in (1, 2, 3):
            raise ValueError(f"space dimension m must be 1, 2 or 3, got {q.shape[1]}")
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "p", p)
        n = q.shape[0]
        if self.ids is None:
            object.__setattr__(self, "ids", np.arange(n))
        elif len(self.ids) != n:
            raise ValueError(f"ids has {len(self.ids)} entries for {n} agents")
        for name in ("length", "width"):
            v = getattr(self, name)
            if v is not None:
                v = np.asarray(v, dtype=float)
                if v.shape not in ((), (1,), (n,)):
                    raise ValueError(f"{name} must have shape ({n},), got {v.shape}")
                object.__setattr__(self, name, _as_n(v, n))
        if self.others_q is not None:
            oq = np.asarray(self.others_q, dtype=float)
            if oq.size == 0:
                oq = oq.reshape(0, q.shape[1])
            if oq.ndim != 2 or oq.shape[1] != q.shape[1]:
                raise ValueError(f"others_q must have shape (M, {q.shape[1]}), got {oq.shape}")
            op = np.zeros_like(oq) if self.others_p is None else np.asarray(self.others_p, float)
            if op.shape != oq.shape:
                raise ValueError(f"others_p has shape {op.shape} but others_q has {oq.shape}")
            object.__setattr__(self, "others_q", oq)
            object.__setattr__(self, "others_p", op)
            for name in ("others_length", "others_width"):
                v = getattr(self, name)
                v = np.zeros(len(oq)) if v is None else np.asarray(v, dtype=float)
                if v.shape not in ((), (1,), (len(oq),)):
                    raise ValueError(f"{name} must have shape ({len(oq)},), got {v.shape}")
                object.__setattr__(self, name, _as_n(v, len(oq)))
        if self.road_edges is not None:
            re = np.asarray(self.road_edges, dtype=float)
            re = np.broadcast_to(re, (n, 2)) if re.shape == (2,) else re
            if re.shape != (n, 2):
                raise ValueError(f"road_edges must have shape ({n}, 2), got {re.shape}")
            object.__setattr__(self, "road_edges", re)
        for name in ("leader_q", "leader_p"):
            v = getattr(self, name)
            if v is not None:
                v = np.asarray(v, dtype=float)
                if v.shape not in ((q.shape[1],), q.shape):
                    raise ValueError(f"{name} must have shape ({q.shape[1]},) or {q.shape}")
                object.__setattr__(self, name, v)
        if self.desired_speed is not None:
            v = _as_n(np.asarray(self.desired_speed, dtype=float), n)
            object.__setattr__(self, "desired_speed", v)
        if self.period_s is not None and not self.period_s > 0:
            raise ValueError("period_s must be > 0")

    @classmethod
    def trusted(cls, *, state_finite: bool = False, **values) -> Observation:
        """An observation of fields already in their final form, unchecked and uncopied:
        ``q``, ``p`` (N, m) float64, per-agent fields (N,) float64, ``others_*`` (M, m) and
        (M,) float64, ``road_edges`` (N, 2) float64, ``ids`` and ``others_ids`` object
        arrays; absent fields take their defaults. For a world's loop that builds every
        array itself each step (:mod:`cosim.sim.loop`; tests/test_loop.py checks that it
        equals the validating constructor's result); everything else uses the
        constructor. ``state_finite``: the caller found every entry of ``q`` and ``p``
        finite as it built them (:meth:`check_finite` then has nothing to look at)."""
        unknown = values.keys() - _NAMES
        if unknown:
            raise TypeError(f"Observation has no field(s) {', '.join(sorted(unknown))}")
        if not _REQUIRED <= values.keys():
            missing = ", ".join(sorted(_REQUIRED - values.keys()))
            raise TypeError(f"Observation needs the field(s) {missing}")
        obj = object.__new__(cls)
        state = obj.__dict__  # a frozen dataclass without slots: its fields live here
        for name, factory in _FACTORIES:
            state[name] = factory()
        state.update(_DEFAULTS)
        state.update(values)
        if obj.ids is None:
            state["ids"] = np.arange(obj.q.shape[0])
        if state_finite:
            state["_state_finite"] = True
        return obj

    @property
    def n(self) -> int:
        """Number of controlled agents N."""
        return self.q.shape[0]

    @property
    def m(self) -> int:
        """Space dimension m."""
        return self.q.shape[1]

    def check_finite(self) -> None:
        """Raise :class:`InvalidStateError` naming the first agent with a NaN/inf state."""
        if self.__dict__.get("_state_finite"):
            return  # its builder checked every entry (trusted)
        if math.isfinite(self.q.sum()) and math.isfinite(self.p.sum()):
            return  # fast path: the sums are finite only if every entry is
        bad = ~(np.isfinite(self.q).all(axis=1) & np.isfinite(self.p).all(axis=1))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InvalidStateError(
                f"agent {self.ids[i]!r} has a non-finite state: q={self.q[i]}, p={self.p[i]}"
            )

    def relative(self, dq: np.ndarray) -> np.ndarray:
        """Wrap relative positions ``dq`` (..., m) along a periodic axis 0, m."""
        if self.period_s is None:
            return dq
        out = np.array(dq, dtype=float, copy=True)
        L = self.period_s
        out[..., 0] = (out[..., 0] + 0.5 * L) % L - 0.5 * L
        return out


_FIELDS = fields(Observation)
_NAMES = frozenset(f.name for f in _FIELDS)
_REQUIRED = frozenset(f.name for f in _FIELDS
                      if f.default is MISSING and f.default_factory is MISSING)
#: the fields with a default value, and those with a default factory (name, factory)
_DEFAULTS = {f.name: f.default for f in _FIELDS if f.default is not MISSING}
_FACTORIES = tuple((f.name, f.default_factory) for f in _FIELDS
                   if f.default is MISSING and f.default_factory is not MISSING)
