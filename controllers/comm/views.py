"""Per-agent views of one step laid side by side for one law call (:class:`Views`).

See "Evaluating the law on per-agent views" in :mod:`controllers.comm.controller`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.comm.messages import Messages
from controllers.observation import Circles, Observation


@dataclass
class Views:
    """The per-agent views of one step, rows grouped by block (ego first)."""

    block: np.ndarray  # (R,) block of each row
    ego_rows: np.ndarray  # (B,) row of each block's ego
    egos: np.ndarray  # (B,) observation row of each ego
    q: np.ndarray  # (R, m)
    p: np.ndarray  # (R, m)
    ids: np.ndarray  # (R,) object
    size: np.ndarray | None  # (R, 2) or None
    starts: np.ndarray  # (B + 1,) row ranges

    @classmethod
    def build(cls, obs: Observation, egos, entries: Messages, entry_block, id_of) -> Views:
        nb = len(egos)
        block = np.concatenate([np.arange(nb), entry_block])
        key = np.concatenate([np.full(nb, -1), entries.send])
        order = np.lexsort((key, block))
        block = block[order]
        q = np.concatenate([obs.q[egos], entries.q])[order]
        p = np.concatenate([obs.p[egos], entries.p])[order]
        is_ego = np.concatenate([np.ones(nb, bool), np.zeros(len(entries), bool)])[order]
        ego_rows = np.flatnonzero(is_ego)
        ego_ids = np.asarray(obs.ids, dtype=object)[egos]
        ids = np.empty(len(block), dtype=object)
        rows = zip(block.tolist(), is_ego.tolist(), key[order].tolist(), strict=True)
        for r, (b, e, k) in enumerate(rows):
            # ghost rows get their own ids so per-id state in the law cannot mix them up
            ids[r] = ego_ids[b] if e else ("comm_view", ego_ids[b], id_of[k])
        size = None
        if obs.length is not None and obs.width is not None:
            own = np.column_stack([obs.length[egos], obs.width[egos]])
            size = np.concatenate([own, entries.size])[order]
            bad = np.isnan(size).any(axis=1)
            size[bad] = own[block[bad]]
        starts = np.searchsorted(block, np.arange(nb + 1))
        return cls(block, ego_rows, egos, q, p, ids, size, starts)

    def _per_row(self, value, rows_block) -> np.ndarray | None:
        """A (k,)- or (N, k)-shaped observation field as each row's ego's value, (rows, k)."""
        if value is None:
            return None
        v = np.asarray(value, dtype=float)
        if v.ndim == 1:
            return np.broadcast_to(v, (len(rows_block), len(v))).copy()
        return v[self.egos][rows_block]

    @staticmethod
    def _ego_value(value, ego: int) -> np.ndarray | None:
        """A (k,)- or (N, k)-shaped observation field as the ego's (k,) value."""
        if value is None:
            return None
        v = np.asarray(value, dtype=float)
        return v.copy() if v.ndim == 1 else v[ego].copy()

    def single(self, obs: Observation, b: int) -> Observation:
        """Block ``b`` alone, untranslated."""
        sl = slice(self.starts[b], self.starts[b + 1])
        ego = int(self.egos[b])
        return Observation(
            q=self.q[sl],
            p=self.p[sl],
            t=obs.t,
            dt=obs.dt,
            ids=self.ids[sl],
            length=None if self.size is None else self.size[sl, 0],
            width=None if self.size is None else self.size[sl, 1],
            others_q=obs.others_q,
            others_p=obs.others_p,
            others_length=obs.others_length,
            others_width=obs.others_width,
            circles=obs.circles,
            walls=obs.walls,
            road_edges=self._ego_value(obs.road_edges, ego),
            leader_q=self._ego_value(obs.leader_q, ego),
            leader_p=self._ego_value(obs.leader_p, ego),
            period_s=obs.period_s,
            desired_speed=self._by_id(obs, obs.desired_speed, self.ids[sl]),
            road=obs.road,
            others_ids=obs.others_ids,
            extras=obs.extras,
        )

    @staticmethod
    def _by_id(obs: Observation, values, ids) -> np.ndarray | None:
        """A per-agent field of ``obs`` (N,) looked up for the view's rows by vehicle id."""
        if values is None:
            return None
        index = {vid: k for k, vid in enumerate(obs.ids.tolist())}
        vals = np.asarray(values, dtype=float)
        out = np.empty(len(ids))
        for r, vid in enumerate(ids.tolist()):
            # a neighbour's row is ("comm_view", ego id, its own id); it may have left
            own = vid[-1] if isinstance(vid, tuple) and vid[:1] == ("comm_view",) else vid
            out[r] = vals[index[own]] if own in index else np.nan
        return out

    def union(self, obs: Observation, axis: int, gap: float) -> Observation:
        """All blocks in one observation, block ``b`` shifted along ``axis``."""
        nb = len(self.egos)
        lo = np.minimum.reduceat(self.q[:, axis], self.starts[:-1])
        hi = np.maximum.reduceat(self.q[:, axis], self.starts[:-1])
        # environment objects move with every block: widen each block by their extent
        env_lo, env_hi = [], []
        if obs.circles is not None and len(obs.circles.radii):
            c = obs.circles.centres[:, axis]
            env_lo.append(np.min(c - obs.circles.radii))
            env_hi.append(np.max(c + obs.circles.radii))
        if obs.others_q is not None and len(obs.others_q):
            reach = 0.5 * np.hypot(obs.others_length, obs.others_width)
            env_lo.append(np.min(obs.others_q[:, axis] - reach))
            env_hi.append(np.max(obs.others_q[:, axis] + reach))
        if env_lo:
            lo = np.minimum(lo, min(env_lo))
            hi = np.maximum(hi, max(env_hi))
        width = hi - lo + gap
        start = np.concatenate([[0.0], np.cumsum(width)[:-1]])
        shift = start - lo  # (B,)
        row_shift = shift[self.block]
        q = self.q.copy()
        q[:, axis] += row_shift
        leader_q = leader_p = None
        if obs.leader_q is not None:
            leader_q = self._per_row(obs.leader_q, self.block)
            leader_q[:, axis] += row_shift
        if obs.leader_p is not None:
            leader_p = self._per_row(obs.leader_p, self.block)
        edges = self._per_row(obs.road_edges, self.block)
        if edges is not None and axis == 1:
            edges = edges + row_shift[:, None]
        circles = None
        if obs.circles is not None and len(obs.circles.radii):
            k = len(obs.circles.radii)
            cen = np.tile(obs.circles.centres, (nb, 1))
            cen[:, axis] += np.repeat(shift, k)
            circles = Circles(cen, np.tile(obs.circles.radii, nb))
        others = {}
        if obs.others_q is not None and len(obs.others_q):
            k = len(obs.others_q)
            oq = np.tile(obs.others_q, (nb, 1))
            oq[:, axis] += np.repeat(shift, k)
            others = dict(
                others_q=oq,
                others_p=np.tile(obs.others_p, (nb, 1)),
                others_length=np.tile(obs.others_length, nb),
                others_width=np.tile(obs.others_width, nb),
            )
        return Observation(
            q=q,
            p=self.p,
            t=obs.t,
            dt=obs.dt,
            ids=self.ids,
            length=None if self.size is None else self.size[:, 0],
            width=None if self.size is None else self.size[:, 1],
            circles=circles,
            walls=obs.walls,
            road_edges=edges,
            leader_q=leader_q,
            leader_p=leader_p,
            period_s=obs.period_s,
            desired_speed=self._by_id(obs, obs.desired_speed, self.ids),
            extras=obs.extras,
            **others,
        )
