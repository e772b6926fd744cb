"""Jam figures of a run: standstills, and cross-sections that stop passing traffic.

Definitions (a vehicle *stands still* while its speed is below ``v_stop``, m/s; stopped
obstacles are not traffic and never count):

* ``max_standstill_s``: the longest uninterrupted standstill of any vehicle, s;
  ``max_standstill_cav_s`` and ``max_standstill_hdv_s``: the same of the CAVs and of the
  other vehicles (SUMO's drivers), when the recorder is told which are CAVs;
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

from cosim.metrics import kernels as K

#: How far upstream of a cross-section a waiting vehicle counts for a blocked window, m.
UPSTREAM_M = 100.0
_NO_ROWS = np.zeros(0, dtype=np.int64)


class _Unaligned:
    """The marker :data:`UNALIGNED`."""

    def __repr__(self) -> str:
        return "UNALIGNED"


#: ``prev_rows`` of a recorder's step that its caller did not align (the recorder does:
#: :func:`align` of its own previous ids); None means the same vehicles at the same rows.
UNALIGNED = _Unaligned()


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
        self.max_standstill_cav_s = 0.0
        self.max_standstill_hdv_s = 0.0
        self._kinds_seen = False
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
        #: a cross-section not yet passed or a vehicle waiting at one in this window
        #: (``not crossed.all() or waiting.any()``): the window test has work to do
        self._win_open = True
        self.blocked_windows = 0
        self.blocked_log: list[dict] = []

    @property
    def _since(self) -> dict:
        """id -> time its current standstill began, s (the vehicles standing still now)."""
        rows = np.flatnonzero(np.isfinite(self._t0[:-1]))
        return {self._ids[r]: float(self._t0[r]) for r in rows}

    def record(self, t: float, ids: list, s_front: np.ndarray, v: np.ndarray,
               is_static: np.ndarray, prev_rows=UNALIGNED, is_cav=None) -> None:
        """One step: ids (M,), front positions (M,) m, speeds (M,) m/s, obstacle mask (M,);
        ``prev_rows``: :func:`align` of the previous step's ids and ``ids``, if the caller
        computed it (the recorders of a run share one), else :data:`UNALIGNED`;
        ``is_cav`` (M,) bool, optional: the standstills of CAVs and of the others apart."""
        ids = list(ids)  # a copy: kept for the next step, the caller may reuse its list
        idx = align(self._ids, ids) if prev_rows is UNALIGNED else prev_rows
        is_static = np.asarray(is_static, dtype=bool)
        s_front = np.asarray(s_front, dtype=float)
        t0, long_now, front_now, stopped, front_prev, longest, new_long = K.jam_step(
            float(t), np.asarray(v, dtype=float), is_static, s_front,
            _NO_ROWS if idx is None else idx, idx is None, self._t0, self._long, self._front,
            float(self.v_stop), float(self.long_s))
        if longest > self.max_standstill_s:
            self.max_standstill_s = longest
        if is_cav is not None:
            self._kinds_seen = True
            if longest > 0.0:  # someone stands: split by kind (t0 NaN: moving)
                held = t - t0[:-1]
                cav = np.asarray(is_cav, dtype=bool) & ~is_static
                hdv = ~np.asarray(is_cav, dtype=bool) & ~is_static
                for mask, name in ((cav, "max_standstill_cav_s"),
                                   (hdv, "max_standstill_hdv_s")):
                    vals = held[mask & np.isfinite(held)]
                    if vals.size and vals.max() > getattr(self, name):
                        setattr(self, name, float(vals.max()))
        if len(new_long):
            self._long_ids.update([ids[r] for r in new_long.tolist()])
        self._windows(t, s_front, stopped, is_static, front_prev)
        self._ids = ids
        self._t0 = t0
        self._long = long_now
        self._front = front_now

    def _windows(self, t, s_front, stopped, is_static, prev) -> None:
        if not len(self.xs) or t <= self.warmup_s + 1e-9:
            return
        if self._win_start is None:
            self._win_start = self.warmup_s
        if self._win_open:
            K.jam_windows(s_front, stopped, is_static, prev, self.xs, ~self._win_crossed,
                          self._win_waiting.copy(), self.period is not None,
                          0.0 if self.period is None else float(self.period), UPSTREAM_M,
                          self._win_crossed, self._win_waiting)
            self._win_open = not self._win_crossed.all() or self._win_waiting.any()
        if t >= self._win_start + self.long_s - 1e-9:
            blocked = ~self._win_crossed & self._win_waiting
            for k in np.flatnonzero(blocked):
                self.blocked_log.append({"t_start_s": self._win_start, "t_end_s": t,
                                         "cross_section_m": float(self.xs[k])})
            self.blocked_windows += int(np.count_nonzero(blocked))
            self._win_start = t
            self._win_crossed[:] = False
            self._win_waiting[:] = True
            self._win_open = True

    def summary(self) -> dict:
        """The run's jam figures (units in the names)."""
        kinds = {} if not self._kinds_seen else {
            "max_standstill_cav_s": float(self.max_standstill_cav_s),
            "max_standstill_hdv_s": float(self.max_standstill_hdv_s)}
        return {
            "max_standstill_s": float(self.max_standstill_s),
            **kinds,
            "vehicles_stopped_long": len(self._long_ids),
            "long_standstill_s": float(self.long_s),
            "blocked_windows": int(self.blocked_windows),
            "gridlock": bool(self.blocked_windows > 0),
        }
