"""Jam figures of a run: standstills, and cross-sections that stop passing traffic.

Definitions (a vehicle *stands still* while its speed is below ``v_stop``, m/s; stopped
obstacles are not traffic and never count):

* ``max_standstill_s``: the longest uninterrupted standstill of any vehicle, s;
* ``vehicles_stopped_long``: vehicles that stood still longer than ``long_s`` (30 s by
  default) at least once;
* ``blocked_windows``: windows of ``long_s`` (after the warm-up, back to back) in which
  no vehicle passed a flow cross-section although a vehicle stood still within
  ``UPSTREAM_M`` upstream of it for the whole window: the flow there was zero while
  traffic was waiting for it (counted per cross-section and window);
* ``gridlock``: at least one blocked window.

These make a jam visible in the summary that a lower mean flow alone hides (issue:
a run whose flow past an obstacle fell to zero for 90 s).
"""

from __future__ import annotations

import numpy as np

#: How far upstream of a cross-section a waiting vehicle counts for a blocked window, m.
UPSTREAM_M = 100.0


class JamRecorder:
    """Accumulate jam figures step by step (see the module docstring).

    Args:
        dt: step, s. warmup_s: start of the windows, s. cross_sections: (K,) m.
        period: ring length, m, or None. v_stop: standstill speed, m/s.
        long_s: long-standstill threshold and window length, s.
    """

    def __init__(self, dt: float, warmup_s: float, cross_sections, period: float | None,
                 v_stop: float = 0.5, long_s: float = 30.0) -> None:
        self.dt = dt
        self.warmup_s = warmup_s
        self.xs = np.asarray(cross_sections, dtype=float)
        self.period = period
        self.v_stop = v_stop
        self.long_s = long_s
        self._since: dict = {}  # id -> time the standstill began, s
        self.max_standstill_s = 0.0
        self._long_ids: set = set()
        self._prev_front: dict = {}
        self._win_start: float | None = None
        self._win_crossed = np.zeros(len(self.xs), dtype=bool)
        self._win_waiting = np.ones(len(self.xs), dtype=bool)
        self.blocked_windows = 0
        self.blocked_log: list[dict] = []

    def record(self, t: float, ids: list, s_front: np.ndarray, v: np.ndarray,
               is_static: np.ndarray) -> None:
        """One step: ids (M,), front positions (M,) m, speeds (M,) m/s, obstacle mask (M,)."""
        moving_ids = set()
        stopped = (v < self.v_stop) & ~is_static
        for vid, stop in zip(ids, stopped, strict=True):
            if stop:
                t0 = self._since.setdefault(vid, t)
                dur = t - t0
                if dur > self.max_standstill_s:
                    self.max_standstill_s = dur
                if dur > self.long_s:
                    self._long_ids.add(vid)
            else:
                moving_ids.add(vid)
        for vid in moving_ids:
            self._since.pop(vid, None)
        present = set(ids)
        for vid in [k for k in self._since if k not in present]:
            del self._since[vid]
        self._windows(t, ids, s_front, stopped, is_static)

    def _windows(self, t, ids, s_front, stopped, is_static) -> None:
        if not len(self.xs) or t <= self.warmup_s + 1e-9:
            self._prev_front = dict(zip(ids, s_front, strict=True))
            return
        if self._win_start is None:
            self._win_start = self.warmup_s
        # crossings since the last step
        prev = np.array([self._prev_front.get(k, np.nan) for k in ids])
        ok = np.isfinite(prev) & ~is_static
        cur, prv = s_front[ok], prev[ok]
        if self.period is not None:
            cur = np.where(cur < prv - 0.5 * self.period, cur + self.period, cur)
        for k, x in enumerate(self.xs):
            hit = (prv < x) & (cur >= x)
            if self.period is not None:
                hit |= (prv < x + self.period) & (cur >= x + self.period)
            if hit.any():
                self._win_crossed[k] = True
            up = x - s_front
            if self.period is not None:
                up = np.mod(up, self.period)
            waiting = stopped & (up >= 0) & (up <= UPSTREAM_M)
            if not waiting.any():
                self._win_waiting[k] = False
        self._prev_front = dict(zip(ids, s_front, strict=True))
        if t >= self._win_start + self.long_s - 1e-9:
            blocked = ~self._win_crossed & self._win_waiting
            for k in np.flatnonzero(blocked):
                self.blocked_log.append({"t_start_s": self._win_start, "t_end_s": t,
                                         "cross_section_m": float(self.xs[k])})
            self.blocked_windows += int(np.count_nonzero(blocked))
            self._win_start = t
            self._win_crossed[:] = False
            self._win_waiting[:] = True

    def summary(self) -> dict:
        """The run's jam figures (units in the names)."""
        return {
            "max_standstill_s": float(self.max_standstill_s),
            "vehicles_stopped_long": len(self._long_ids),
            "long_standstill_s": float(self.long_s),
            "blocked_windows": int(self.blocked_windows),
            "gridlock": bool(self.blocked_windows > 0),
        }
