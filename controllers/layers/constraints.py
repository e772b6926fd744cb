"""Constraint layers applied after a control law, each separate and composable.

A layer maps a command ``u`` (N, m) m/s^2 to a constrained command, given the
observation, and counts how many agent-steps it changed (``clipped``) out of
how many it saw (``seen``). Order matters and is the caller's choice; the
default stack is: speed saturation, acceleration box, jerk limit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from controllers.errors import ParameterError
from controllers.observation import Observation


@dataclass(frozen=True)
class ActuatorLimits:
    """A road vehicle's actuator limits (road frame); the ``[limits]`` section of a scenario.

    Attributes:
        long_min_mps2, long_max_mps2: longitudinal acceleration range, m/s^2
            (``long_min < 0 < long_max``).
        lat_max_mps2: lateral acceleration bound (absolute), m/s^2.
        lat_speed_max_mps: lateral speed bound, m/s.
        jerk_max_mps3: jerk bound, m/s^3, or 0 for none.
        emergency_decel_mps2: deceleration the safety layer may use, m/s^2
            (at least ``-long_min_mps2``).
    """

    long_min_mps2: float = -4.5
    long_max_mps2: float = 2.6
    lat_max_mps2: float = 1.5
    lat_speed_max_mps: float = 1.5
    jerk_max_mps3: float = 0.0
    emergency_decel_mps2: float = 9.0

    def __post_init__(self) -> None:
        for name in ("long_min_mps2", "long_max_mps2", "lat_max_mps2", "lat_speed_max_mps",
                     "jerk_max_mps3", "emergency_decel_mps2"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
                raise ParameterError(f"{name} must be a finite number, got {v!r}")
        if not self.long_min_mps2 < 0:
            raise ParameterError(f"long_min_mps2 must be < 0, got {self.long_min_mps2}")
        for name in ("long_max_mps2", "lat_max_mps2", "lat_speed_max_mps"):
            if not getattr(self, name) > 0:
                raise ParameterError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.jerk_max_mps3 < 0:
            raise ParameterError(f"jerk_max_mps3 must be >= 0, got {self.jerk_max_mps3}")
        if self.emergency_decel_mps2 < -self.long_min_mps2:
            raise ParameterError(
                f"emergency_decel_mps2 must be >= -long_min_mps2 = {-self.long_min_mps2}, "
                f"got {self.emergency_decel_mps2}"
            )

    def box(self) -> AccelerationBox:
        """The acceleration box layer of these limits."""
        return AccelerationBox(self.long_min_mps2, self.long_max_mps2, self.lat_max_mps2)

    def layers(self) -> list[Layer]:
        """The constraint stack of these limits: the box, then the jerk limit if any."""
        out: list[Layer] = [self.box()]
        if self.jerk_max_mps3 > 0:
            out.append(JerkLimit(self.jerk_max_mps3))
        return out


@dataclass
class Layer:
    """Base class: ``apply(u, obs) -> u`` and clip statistics."""

    clipped: int = field(default=0, init=False)
    seen: int = field(default=0, init=False)

    name = "layer"

    def apply(self, u: np.ndarray, obs: Observation) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def _count(self, changed: np.ndarray) -> None:
        self.clipped += int(np.count_nonzero(changed))
        self.seen += len(changed)

    @property
    def clip_rate(self) -> float:
        """Fraction of agent-steps this layer changed (0 when it saw none)."""
        return self.clipped / self.seen if self.seen else 0.0


@dataclass
class SpeedSaturation(Layer):
    """Speed saturation, seed 003 eq. 2: ``sat(p, p_max) = p`` if ``||p|| <= p_max``,
    else ``p p_max / ||p||``, applied to the next velocity ``p + u dt``.

    The command is changed to ``(sat(p + u dt) - p) / dt`` so that the velocity
    after the step never exceeds ``p_max`` (m/s).
    """

    p_max: float = 10.0
    name = "speed_saturation"

    def __post_init__(self) -> None:
        if not self.p_max > 0:
            raise ParameterError(f"p_max must be > 0, got {self.p_max!r}")

    def apply(self, u: np.ndarray, obs: Observation) -> np.ndarray:
        nxt = obs.p + u * obs.dt
        speed = np.linalg.norm(nxt, axis=1)
        over = speed > self.p_max
        self._count(over)
        if not over.any():
            return u
        nxt[over] *= (self.p_max / speed[over])[:, None]
        return (nxt - obs.p) / obs.dt


@dataclass
class AccelerationBox(Layer):
    """Separate longitudinal and lateral acceleration limits (road frame), m/s^2.

    Defaults are car-like: -4.5 to +2.6 m/s^2 along the road, +-1.5 m/s^2
    across it. Axis 2 (m = 3) uses the lateral limits. Optionally also a bound
    on the norm ``a_max`` (seed 001's actuator saturation).
    """

    long_min: float = -4.5
    long_max: float = 2.6
    lat_max: float = 1.5
    a_max: float | None = None
    name = "acceleration_box"

    def __post_init__(self) -> None:
        if not self.long_min < 0 < self.long_max:
            raise ParameterError(
                f"need long_min < 0 < long_max, got {self.long_min}, {self.long_max}"
            )
        if not self.lat_max > 0:
            raise ParameterError(f"lat_max must be > 0, got {self.lat_max!r}")
        if self.a_max is not None and not self.a_max > 0:
            raise ParameterError(f"a_max must be > 0, got {self.a_max!r}")

    def apply(self, u: np.ndarray, obs: Observation) -> np.ndarray:
        m = u.shape[1]
        lo, hi = self._bounds(m)
        if (m == 2 and self.a_max is None and u.dtype == np.float64
                and u.flags.c_contiguous):  # the road's commands: one compiled pass
            from controllers.layers.constraint_kernels import box_clip

            out, changed = box_clip(u, self.long_min, self.long_max, -self.lat_max,
                                    self.lat_max)
            self.clipped += int(changed)
            self.seen += u.shape[0]
            return out
        out = np.clip(u, lo, hi)
        if self.a_max is not None:
            norm = np.linalg.norm(out, axis=1)
            big = norm > self.a_max
            out[big] *= (self.a_max / norm[big])[:, None]
        changed = out != u
        if m == 2:  # the road (an axis reduction costs more than the or of two columns)
            self._count(changed[:, 0] | changed[:, 1])
        else:
            self._count(np.any(changed, axis=1))
        return out

    def _bounds(self, m: int) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bound (m,) per axis, m/s^2 (kept per m)."""
        cache = self.__dict__.setdefault("_bounds_by_m", {})
        if m not in cache:
            lo = np.full(m, -self.lat_max)
            hi = np.full(m, self.lat_max)
            lo[0], hi[0] = self.long_min, self.long_max
            cache[m] = (lo, hi)
        return cache[m]


@dataclass
class JerkLimit(Layer):
    """Limit the change of command between steps to ``j_max * dt`` per axis (m/s^3).

    Keeps the previous command per vehicle id, so vehicles may enter and leave.
    """

    j_max: float = 5.0
    name = "jerk_limit"
    _prev: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.j_max > 0:
            raise ParameterError(f"j_max must be > 0, got {self.j_max!r}")

    def apply(self, u: np.ndarray, obs: Observation) -> np.ndarray:
        step = self.j_max * obs.dt
        prev = np.array([self._prev.get(k, u[n]) for n, k in enumerate(obs.ids)]).reshape(u.shape)
        out = np.clip(u, prev - step, prev + step)
        self._count(np.any(out != u, axis=1))
        self._prev = {k: out[n] for n, k in enumerate(obs.ids)}
        return out


class ConstrainedController:
    """A control law followed by constraint layers: ``layers[-1](...layers[0](law(obs)))``."""

    def __init__(self, law, layers: Sequence[Layer] = ()) -> None:
        self.law = law
        self.layers = list(layers)
        self.name = getattr(law, "name", type(law).__name__)

    def compute(self, obs: Observation) -> np.ndarray:
        """Constrained accelerations (N, m), m/s^2."""
        u = self.law.compute(obs)
        for layer in self.layers:
            u = layer.apply(u, obs)
        return u

    def clip_stats(self) -> dict[str, float]:
        """``{layer_name: clip_rate}`` over all steps so far."""
        return {layer.name: layer.clip_rate for layer in self.layers}
