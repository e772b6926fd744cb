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

from itertools import repeat

import numpy as np

#: How far upstream of a cross-section a waiting vehicle counts for a blocked window, m.
UPSTREAM_M = 100.0


def align(prev_ids: list, ids: list) -> np.ndarray | None:
    """Row of each of ``ids`` in ``prev_ids``: (M,) int64, -1 where absent; None when the
    two lists are equal (every vehicle at the same row). Ids are unique within a list.

    C-level dictionary look-ups (no Python loop per vehicle)."""
    if ids == prev_ids:
        return None
    index = dict(zip(prev_ids, range(len(prev_ids)), strict=True))
    return np.fromiter(map(index.get, ids, repeat(-1)), dtype=np.int64, count=len(ids))


class JamRecorder:
    """Accumulate jam figures step by step (see the module docstring).

    Per-step state is kept in arrays aligned with the step's vehicles (ids unique within
    a step), carried to the next step by :func:`align`: no Python loop per vehicle.

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
        self.max_standstill_s = 0.0
        self._long_ids: set = set()
        # The previous step's vehicles, and per vehicle plus one sentinel row at the end
        # (what row -1 of :func:`align` reads: a vehicle not seen before):
        self._ids: list = []
        self._t0 = np.full(1, np.nan)  # (M + 1,) time its standstill began, s (NaN: moving)
        self._long = np.zeros(1, dtype=bool)  # (M + 1,) already in ``_long_ids``
        self._front = np.full(1, np.nan)  # (M + 1,) front position, m
        self._win_start: float | None = None
        self._win_crossed = np.zeros(len(self.xs), dtype=bool)
        self._win_waiting = np.ones(len(self.xs), dtype=bool)
        self.blocked_windows = 0
        self.blocked_log: list[dict] = []

    @property
    def _since(self) -> dict:
        """id -> time its current standstill began, s (the vehicles standing still now)."""
        rows = np.flatnonzero(np.isfinite(self._t0[:-1]))
        return {self._ids[r]: float(self._t0[r]) for r in rows}

    def record(self, t: float, ids: list, s_front: np.ndarray, v: np.ndarray,
               is_static: np.ndarray) -> None:
        """One step: ids (M,), front positions (M,) m, speeds (M,) m/s, obstacle mask (M,)."""
        ids = list(ids)  # a copy: kept for the next step, the caller may reuse its list
        idx = align(self._ids, ids)
        stopped = (v < self.v_stop) & ~is_static
        if idx is None:
            t0_prev, long_prev, front_prev = self._t0[:-1], self._long[:-1], self._front[:-1]
        else:
            t0_prev, long_prev, front_prev = self._t0[idx], self._long[idx], self._front[idx]
        t0 = np.full(len(ids) + 1, np.nan)
        long_now = np.zeros(len(ids) + 1, dtype=bool)
        if stopped.any():
            rows = np.flatnonzero(stopped)
            began = t0_prev[rows]
            began = np.where(np.isnan(began), t, began)
            t0[rows] = began
            dur = t - began
            longest = dur.max()
            if longest > self.max_standstill_s:
                self.max_standstill_s = longest
            is_long = dur > self.long_s
            if is_long.any():
                new = rows[is_long & ~long_prev[rows]]
                self._long_ids.update([ids[r] for r in new])
                long_now[rows[is_long]] = True
            long_now[:-1] |= long_prev & stopped
        self._windows(t, s_front, stopped, is_static, front_prev)
        self._ids = ids
        self._t0 = t0
        self._long = long_now
        self._front = np.append(np.asarray(s_front, dtype=float), np.nan)

    def _windows(self, t, s_front, stopped, is_static, prev) -> None:
        if not len(self.xs) or t <= self.warmup_s + 1e-9:
            return
        if self._win_start is None:
            self._win_start = self.warmup_s
        xs = self.xs[:, None]  # (K, 1)
        todo = ~self._win_crossed  # crossings since the last step, where still unseen
        if todo.any():
            ok = np.isfinite(prev) & ~is_static
            cur, prv = s_front[ok], prev[ok]
            x = xs[todo]
            if self.period is not None:
                cur = np.where(cur < prv - 0.5 * self.period, cur + self.period, cur)
            hit = (prv < x) & (cur >= x)
            if self.period is not None:
                hit |= (prv < x + self.period) & (cur >= x + self.period)
            self._win_crossed[todo] = hit.any(axis=1)
        todo = self._win_waiting  # a vehicle waiting upstream, where still always
        if todo.any():
            up = xs[todo] - s_front
            if self.period is not None:
                up = np.mod(up, self.period)
            waiting = stopped & (up >= 0) & (up <= UPSTREAM_M)
            self._win_waiting[todo] = waiting.any(axis=1)
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
