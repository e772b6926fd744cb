"""Message copies in flight or buffered (:class:`Messages`); per-agent clocks (:class:`Clocks`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class Messages:
    """Message copies as parallel arrays (E rows)."""

    __slots__ = ("recv", "send", "t_send", "t_arrive", "q", "p", "size")

    def __init__(self, recv, send, t_send, t_arrive, q, p, size) -> None:
        self.recv = recv  # receiver slot (E,) int
        self.send = send  # sender slot (E,) int
        self.t_send = t_send  # (E,) s
        self.t_arrive = t_arrive  # (E,) s
        self.q = q  # (E, m) m
        self.p = p  # (E, m) m/s
        self.size = size  # (E, 2) length, width in m (NaN: unknown)

    @classmethod
    def empty(cls, m: int) -> Messages:
        return cls(
            np.empty(0, np.int64),
            np.empty(0, np.int64),
            np.empty(0),
            np.empty(0),
            np.empty((0, m)),
            np.empty((0, m)),
            np.empty((0, 2)),
        )

    def __len__(self) -> int:
        return len(self.recv)

    def take(self, idx) -> Messages:
        return Messages(*(getattr(self, k)[idx] for k in self.__slots__))

    @staticmethod
    def concat(a: Messages, b: Messages) -> Messages:
        if len(a) == 0:
            return b
        if len(b) == 0:
            return a
        return Messages(*(np.concatenate([getattr(a, k), getattr(b, k)]) for k in a.__slots__))


@dataclass
class Clocks:
    """Per-slot clock and command state (grown on demand)."""

    base: np.ndarray = field(default_factory=lambda: np.empty(0))  # s
    period: np.ndarray = field(default_factory=lambda: np.empty(0))  # s
    count: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    present: np.ndarray = field(default_factory=lambda: np.empty(0, bool))

    def grow(self, cap: int) -> None:
        extra = cap - len(self.base)
        if extra <= 0:
            return
        self.base = np.concatenate([self.base, np.zeros(extra)])
        self.period = np.concatenate([self.period, np.ones(extra)])
        self.count = np.concatenate([self.count, np.zeros(extra, np.int64)])
        self.present = np.concatenate([self.present, np.zeros(extra, bool)])

    def next_instant(self, slots: np.ndarray) -> np.ndarray:
        return self.base[slots] + self.count[slots] * self.period[slots]
