"""Parameters of the Olfati-Saber flocking law, validated on construction.

Names follow OS06 and seed 000's CONSTANTS.m: ``d`` and ``r`` (alpha lattice
spacing and interaction range), ``d_beta``/``r_beta`` (d' and r', obstacles),
``d_wall``/``r_wall`` (seed 000's d'' and r'', road edges), gains ``c1_*`` and
``c2_*``. All lengths in m, gains in SI (c1 in 1/s^2 for the gamma term, c2 in 1/s).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields, replace

import numpy as np

from controllers.errors import ParameterError


def _gain_vector(value, name: str) -> tuple[float, ...]:
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1 or len(arr) not in (1, 2, 3):
        raise ParameterError(f"{name} must be a scalar or a vector of 1 to 3 per-axis gains")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ParameterError(f"{name} must be finite and >= 0, got {value!r}")
    return tuple(float(v) for v in arr)


BARRIER_FLOORS = ("peak", "none")


def _barrier_floor(value) -> str | float:
    """``value`` if it is "peak" or "none", else a float gap > 0 in m; ParameterError otherwise."""
    if isinstance(value, str):
        if value in BARRIER_FLOORS:
            return value
    elif isinstance(value, numbers.Real) and not isinstance(value, bool):
        v = float(value)
        if math.isfinite(v) and v > 0.0:
            return v
    raise ParameterError(
        f"barrier_floor must be 'peak', 'none' or a finite gap > 0 in m, got {value!r}"
    )


@dataclass(frozen=True)
class FlockingParams:
    """Olfati-Saber Algorithm 3 parameters (defaults: seed 000 CONSTANTS.m).

    Attributes:
        d: desired inter-agent distance, m (isotropic).
        r: interaction range, m (r > d; seed 000: 1.2 d).
        d_long, d_lat: anisotropic desired spacing along and across the road, m.
            None means ``d``. The law works in coordinates scaled by
            ``diag(d / d_long, d / d_lat)``, so equal values give the isotropic law.
        epsilon: sigma-norm parameter (> 0).
        h_alpha, h_beta: bump parameters in (0, 1).
        a, b: phi parameters, 0 < a <= b.
        d_beta, r_beta: obstacle spacing d' and range r', m.
        d_vehicle, r_vehicle: gap to keep from sensed non-cooperating vehicles
            (rectangle to rectangle) and its sensing range, m.
        d_wall, r_wall: spacing d'' and range r'' to walls and road edges, m
            (measured from the vehicle's side when its width is known).
        c1_alpha, c2_alpha, c1_beta, c2_beta, c1_wall, c2_wall: gains (>= 0).
        c1_gamma, c2_gamma: navigational gains, scalar or per axis (seed 000).
        gamma_position: "linear" (OS06 eq. 24 / seed 000) or "sigma1" (bounded,
            seed 003 eq. 11).
        dynamic_weights: seed 000's ``C(x, u) = x (tanh(u) + 1)`` applied to the
            gamma gains with the obstacle beta term ``u_beta`` per axis.
        neighbour_search: "auto", "kdtree" or "dense".
        barrier_floor: floor on the gap of every beta interaction (walls, road
            edges, circles, sensed vehicles). The paper's repulsion
            ``phi_beta(z) n_hat(z)`` vanishes at contact (``n_hat`` is
            proportional to the gap) and, past a wall or inside an obstacle,
            pushes further out of the free space. "peak" (default) floors each
            gap at the gap where that repulsion peaks (for seed 000's
            constants: 2.39 m of the 3 m edge range, 10.19 m of the 12 m
            obstacle range), a saturated barrier that is monotone and at its
            largest in contact, inside or past; "none" is the paper's law
            exactly; a number > 0 floors every gap at that many m (scaled m
            for sensed vehicles when the spacing is anisotropic).
    """

    d: float = 6.0
    r: float = 7.2
    d_long: float | None = None
    d_lat: float | None = None
    epsilon: float = 0.1
    h_alpha: float = 0.2
    h_beta: float = 0.9
    a: float = 5.0
    b: float = 5.0
    d_beta: float = 12.0
    r_beta: float = 14.4
    d_vehicle: float = 3.0
    r_vehicle: float = 30.0
    d_wall: float = 3.0
    r_wall: float = 3.6
    c1_alpha: float = 50.0
    c2_alpha: float = 2.0 * math.sqrt(50.0)
    c1_beta: float = 100.0
    c2_beta: float = 20.0
    c1_wall: float = 150.0
    c2_wall: float = 2.0 * math.sqrt(150.0)
    c1_gamma: tuple[float, ...] | float = (5.0, 2.0)
    c2_gamma: tuple[float, ...] | float = (2.0 * math.sqrt(5.0), 2.0 * math.sqrt(2.0))
    gamma_position: str = "linear"
    dynamic_weights: bool = False
    neighbour_search: str = "auto"
    barrier_floor: str | float = "peak"

    def __post_init__(self) -> None:
        object.__setattr__(self, "barrier_floor", _barrier_floor(self.barrier_floor))
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float | int) and not isinstance(v, bool):
                if not math.isfinite(v):
                    raise ParameterError(f"{f.name} must be finite, got {v!r}")
        positive = ["d", "r", "epsilon", "d_beta", "r_beta", "d_vehicle", "r_vehicle"]
        positive += ["d_wall", "r_wall", "a", "b"]
        for name in positive:
            if not getattr(self, name) > 0:
                raise ParameterError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("d_long", "d_lat"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise ParameterError(f"{name} must be > 0, got {v!r}")
        for name in ("h_alpha", "h_beta"):
            v = getattr(self, name)
            if not 0.0 < v < 1.0:
                raise ParameterError(f"{name} must lie in (0, 1), got {v!r}")
        if self.a > self.b:
            raise ParameterError(f"a must be <= b (need 0 < a <= b), got a={self.a} b={self.b}")
        if self.r <= self.d:
            raise ParameterError(f"r must be > d, got r={self.r}, d={self.d}")
        if self.r_beta < self.d_beta:
            raise ParameterError(f"r_beta must be >= d_beta, got {self.r_beta} < {self.d_beta}")
        if self.r_wall < self.d_wall:
            raise ParameterError(f"r_wall must be >= d_wall, got {self.r_wall} < {self.d_wall}")
        if self.r_vehicle < self.d_vehicle:
            raise ParameterError(
                f"r_vehicle must be >= d_vehicle, got {self.r_vehicle} < {self.d_vehicle}"
            )
        for name in ("c1_alpha", "c2_alpha", "c1_beta", "c2_beta", "c1_wall", "c2_wall"):
            if getattr(self, name) < 0:
                raise ParameterError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        object.__setattr__(self, "c1_gamma", _gain_vector(self.c1_gamma, "c1_gamma"))
        object.__setattr__(self, "c2_gamma", _gain_vector(self.c2_gamma, "c2_gamma"))
        if self.gamma_position not in ("linear", "sigma1"):
            raise ParameterError(
                f"gamma_position must be 'linear' or 'sigma1', got {self.gamma_position!r}"
            )
        if self.neighbour_search not in ("auto", "kdtree", "dense"):
            raise ParameterError(
                f"neighbour_search must be auto, kdtree or dense, got {self.neighbour_search!r}"
            )

    # Derived quantities -------------------------------------------------
    def scale(self, m: int) -> np.ndarray:
        """Axis scaling (m,) that maps anisotropic spacing onto the isotropic ``d``."""
        s = np.ones(m)
        if self.d_long is not None:
            s[0] = self.d / self.d_long
        if m > 1 and self.d_lat is not None:
            s[1] = self.d / self.d_lat
        return s

    @property
    def is_anisotropic(self) -> bool:
        """True when a longitudinal or lateral spacing differs from ``d``."""
        return (self.d_long not in (None, self.d)) or (self.d_lat not in (None, self.d))

    def gains(self, name: str, m: int) -> np.ndarray:
        """Per-axis gamma gains (m,), broadcasting a scalar."""
        g = np.asarray(getattr(self, name), dtype=float)
        if len(g) == 1:
            return np.full(m, g[0])
        if len(g) != m:
            raise ParameterError(f"{name} has {len(g)} per-axis gains for m={m}")
        return g

    def with_(self, **changes) -> FlockingParams:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)
