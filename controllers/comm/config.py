"""The communication model's parameters (:class:`CommConfig`) and counters (:class:`CommStats`).

The model itself is described in :mod:`controllers.comm.controller`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from controllers.errors import ParameterError

MODES = ("synchronous", "asynchronous")


@dataclass(frozen=True)
class CommConfig:
    """Communication model parameters, validated on construction (``ValueError`` names the field).

    Attributes:
        r_comm_m: communication (sensing) radius, m, > 0 (``math.inf``: everyone).
        delay_min_s, delay_max_s: delay bounds, s, ``0 <= delay_min_s <= delay_max_s``.
        loss_prob: probability that one (sender, receiver) copy is lost, in [0, 1).
        period_s: update (broadcast and control) period T, s, > 0.
        expiry_s: a buffered message is dropped when older than this, s, > 0.
        mode: "synchronous" (common clock) or "asynchronous" (own clock per agent).
        period_jitter: asynchronous only: each agent's period is
            ``period_s (1 + period_jitter U(-1, 1))``, in [0, 1).
        seed: seed of the generator for losses, delays and clocks (int >= 0).
        extrapolate: dead reckoning (not in seed 001): the receiver uses
            ``q_j + p_j (t - t_send)`` instead of the received ``q_j``.
    """

    r_comm_m: float = math.inf
    delay_min_s: float = 0.0
    delay_max_s: float = 0.0
    loss_prob: float = 0.0
    period_s: float = 0.1
    expiry_s: float = 1.0
    mode: str = "synchronous"
    period_jitter: float = 0.0
    seed: int = 0
    extrapolate: bool = False

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "mode":
                if v not in MODES:
                    raise ParameterError(f"CommConfig.mode must be one of {MODES}, got {v!r}")
                continue
            if f.name == "extrapolate":
                if not isinstance(v, bool | np.bool_):
                    raise ParameterError(f"CommConfig.extrapolate must be a bool, got {v!r}")
                continue
            if isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating):
                raise ParameterError(f"CommConfig.{f.name} must be a number, got {v!r}")
            if math.isnan(v):
                raise ParameterError(f"CommConfig.{f.name} must not be NaN")
        if not self.r_comm_m > 0:
            raise ParameterError(f"CommConfig.r_comm_m must be > 0 m, got {self.r_comm_m!r}")
        for name in ("delay_min_s", "delay_max_s"):
            v = getattr(self, name)
            if not (v >= 0 and math.isfinite(v)):
                raise ParameterError(f"CommConfig.{name} must be finite and >= 0 s, got {v!r}")
        if self.delay_max_s < self.delay_min_s:
            raise ParameterError(
                f"CommConfig.delay_max_s must be >= delay_min_s, got "
                f"{self.delay_max_s!r} < {self.delay_min_s!r}"
            )
        if not 0.0 <= self.loss_prob < 1.0:
            raise ParameterError(f"CommConfig.loss_prob must lie in [0, 1), got {self.loss_prob!r}")
        if not (self.period_s > 0 and math.isfinite(self.period_s)):
            raise ParameterError(
                f"CommConfig.period_s must be finite and > 0 s, got {self.period_s!r}"
            )
        if not self.expiry_s > 0:
            raise ParameterError(f"CommConfig.expiry_s must be > 0 s, got {self.expiry_s!r}")
        if not 0.0 <= self.period_jitter < 1.0:
            raise ParameterError(
                f"CommConfig.period_jitter must lie in [0, 1), got {self.period_jitter!r}"
            )
        if not (float(self.seed).is_integer() and self.seed >= 0):
            raise ParameterError(f"CommConfig.seed must be an integer >= 0, got {self.seed!r}")

    @property
    def is_ideal(self) -> bool:
        """No delay, no loss, infinite radius: the views can only lag by the clock."""
        return self.delay_max_s == 0 and self.loss_prob == 0 and math.isinf(self.r_comm_m)


@dataclass
class CommStats:
    """Counters since construction (message copies, i.e. per sender and receiver)."""

    sent: int = 0  # copies addressed to receivers within r_comm
    lost: int = 0  # dropped by packet loss
    delivered: int = 0  # reached the receiver's buffer
    too_late: int = 0  # delay > expiry_s: would arrive expired, discarded
    out_of_order: int = 0  # arrived after a newer copy from the same sender, discarded
    expired: int = 0  # dropped from a buffer by expiry
    agent_updates: int = 0  # control recomputations (agent-instants)
    law_calls: int = 0  # calls of the wrapped law
    union_rows: int = 0  # rows passed to the law in union calls

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}
