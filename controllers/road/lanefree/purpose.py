"""The road each CAV of the lane-free law drives on: its route's purpose (pure numpy).

On a road with exits (off-ramps) or entry strips (an on-ramp's acceleration lane) the CAVs
do not all drive on the same road: one bound for an exit drives in a funnel onto its strip,
one staying on the road leaves the strips to the traffic they serve, one merging from an
entry strip keeps to it while a human driver beside it would not see it merge.
:class:`RoutePurpose` groups the CAVs by the road they drive on and builds each road once
(:mod:`controllers.road.exits`); the law (:mod:`controllers.road.lanefree.law`) takes its
band edges and narrowing bounds from these roads instead of ``obs.road``.
"""

from __future__ import annotations

import numpy as np

from controllers.observation import Observation

from .params import LaneFreeParams


class RoutePurpose:
    """The CAVs' roads by route purpose (see the module docstring; one per law, it caches
    the roads it builds for the road and exits it was last asked about)."""

    def __init__(self, params: LaneFreeParams) -> None:
        self.params = params
        self._cache = None  # (key of the road, exits and entries, {group: road})

    def roads(self, obs: Observation, keep_clear: bool = True) -> list:
        """``(k, rows, road, reach_m)`` covering the CAVs: the road each group drives on
        (k = 0: on the road, k >= 1: leaving by exit k; :mod:`controllers.road.exits`) and
        how far ahead (m) its band edges look at most. Without exits or entry strips, every
        CAV on ``obs.road``. With them:

        * a CAV that stays on the road drives on it without the exits' strips (their lanes
          lead off the road); one leaving by exit k on its funnel (``exit_prepare_m``,
          ``exit_commit_m``): its strategic purpose, a band at the exit's side that
          narrows to the strip before the gore. It looks no further than
          ``edge_lookahead_min_m`` for its band edges: its road shifts sideways onto the
          strip, and the narrowest edges over a longer stretch (the road's right edge
          before the strip, the strip's left border near the gore) leave no room between
          them;
        * a CAV that stays on the road with a human driver near (:meth:`humans_near`)
          keeps ``exit_keep_clear_m`` beside the exit's strip free for that driver to
          cross (not with ``keep_clear=False``: the road a CAV may evade a human driver
          on);
        * a CAV whose body is not on an entry strip (an on-ramp's acceleration lane) drives
          on its road without the strip: through traffic leaves it to merging traffic;
        * a CAV on an entry strip with a human driver in the road's band beside the strip,
          behind or alongside it (:meth:`humans_beside_strip`), keeps to the strip: it
          merges in front of CAVs, which yield, but not across the path of a driver who
          does not (SUMO's drivers do not see a vehicle that reaches over their lane's
          border from the lane beside it, so one that straddles it in front of them is
          hit from behind). Its band edges are those where it is (ahead the strip ends:
          the narrowing bound stops it before the end, inside the strip)."""
        n = obs.n
        exits = obs.exits if obs.exits is not None and obs.exit_index is not None \
            and len(obs.exits) else None
        entries = obs.entries if obs.entries is not None and len(obs.entries) else None
        if exits is None and entries is None:
            return [(0, slice(None), obs.road, np.inf)]
        key = (id(obs.road), None if exits is None else exits.tobytes(),
               None if entries is None else entries.tobytes())
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, {})
        cache = self._cache[1]
        idx = (np.zeros(n, np.int64) if exits is None
               else np.asarray(obs.exit_index, dtype=np.int64).reshape(n))
        keep = ((idx == 0) & self.humans_near(obs)) if exits is not None and keep_clear \
            else np.zeros(n, bool)
        view = np.ones(n, np.int64)  # 0: off the entry strips, 1: on one, 2: strip only
        if entries is not None:
            s, d = obs.q[:, 0], obs.q[:, 1]
            half = 0.5 * (obs.width if obs.width is not None else np.full(n, 1.8))
            on = np.zeros(n, bool)
            for s0, s1, d_r, d_l in entries:
                on |= (s >= s0 - 5.0) & (s <= s1) & (d - half < d_l - 0.05) \
                    & (d + half > d_r + 0.05)
            view = np.where(on, 1, 0)
            if on.any() and self.STRIP_ONLY_BESIDE_HUMANS:
                view[on & self.humans_beside_strip(obs, entries)] = 2
        group = (idx * 2 + keep) * 3 + view
        out = []
        for g in np.unique(group).tolist():
            if g not in cache:
                cache[g] = self._road_of(obs.road, exits, entries, g // 6,
                                              bool((g // 3) % 2), g % 3)
            cap = (0.0 if g % 3 == 2 else self.params.edge_lookahead_min_m if g // 6 else
                   np.inf)
            out.append((g // 6, np.flatnonzero(group == g), cache[g], cap))
        return out

    #: Keep a CAV on an entry strip there while a human driver in the band beside it will
    #: reach it soon (view 2 of :meth:`roads`; :meth:`humans_beside_strip`).
    STRIP_ONLY_BESIDE_HUMANS = True

    #: A human driver within this distance ahead of (m, first) or behind (second) a CAV
    #: that stays on the road makes it keep the band beside an exit's strip clear.
    KEEP_CLEAR_REACH_M = (150.0, 50.0)
    #: A human driver in the road's band of this width (m) beside an entry strip keeps a
    #: CAV on the strip there from this far ahead of it (m) to a distance behind it of
    #: ``BESIDE_STRIP[2]`` m plus his speed times ``BESIDE_STRIP[3]`` s plus his closing
    #: speed times ``BESIDE_STRIP[4]`` s: he will be alongside before it has merged.
    BESIDE_STRIP = (3.0, 5.0, 10.0, 1.0, 2.5)
    #: The reach of :data:`BESIDE_STRIP` times these for a CAV still on the strip (first)
    #: and for one already over its border (second).
    BESIDE_STRIP_HYSTERESIS = (1.0, 0.5)

    def humans_near(self, obs: Observation) -> np.ndarray:
        """(N,) bool: a moving vehicle that is not a CAV is within
        :data:`KEEP_CLEAR_REACH_M` along the road (it may be bound for the exit, and CAVs
        do not know; CAVs bound for it cross the band cooperatively)."""
        n = obs.n
        if obs.others_q is None or len(obs.others_q) == 0:
            return np.zeros(n, bool)
        hs = np.sort(obs.others_q[np.abs(obs.others_p[:, 0]) > 0.5, 0])
        if not len(hs):
            return np.zeros(n, bool)
        ahead, behind = self.KEEP_CLEAR_REACH_M
        s = obs.q[:, 0]
        return np.searchsorted(hs, s + ahead, side="right") > np.searchsorted(hs, s - behind)

    def humans_beside_strip(self, obs: Observation, entries: np.ndarray) -> np.ndarray:
        """(N,) bool: a moving vehicle that is not a CAV has its body in the road's band of
        ``BESIDE_STRIP[0]`` m beside an entry strip, at most ``BESIDE_STRIP[1]`` m ahead
        of the CAV and closer behind it than the reach of :data:`BESIDE_STRIP`. One loop
        over the CAVs on a strip (few) against the drivers in the band (few)."""
        n = obs.n
        out = np.zeros(n, bool)
        if obs.others_q is None or len(obs.others_q) == 0:
            return out
        band, ahead, base_m, own_s, closing_s = self.BESIDE_STRIP
        moving = np.abs(obs.others_p[:, 0]) > 0.5
        oq, v_h = obs.others_q[moving], obs.others_p[moving, 0]
        half = 0.5 * obs.others_width[moving]
        for s0, s1, d_r, d_l in entries:
            if d_l <= 1e-9:  # strip on the right: the band left of it
                near = (oq[:, 1] - half < d_l + band) & (oq[:, 1] + half > d_l)
            else:
                near = (oq[:, 1] + half > d_r - band) & (oq[:, 1] - half < d_r)
            near &= (oq[:, 0] >= s0 - 200.0) & (oq[:, 0] <= s1 + ahead)
            if not near.any():
                continue
            sh, vh = oq[near, 0], v_h[near]
            w = obs.width if obs.width is not None else np.full(n, 1.8)
            over = (obs.q[:, 1] + 0.5 * w > d_l + 0.05) if d_l <= 1e-9 else \
                (obs.q[:, 1] - 0.5 * w < d_r - 0.05)
            for i in np.flatnonzero(obs.q[:, 0] <= s1 + ahead).tolist():
                ds = obs.q[i, 0] - sh  # > 0: the driver is behind
                reach = base_m + own_s * vh + closing_s * np.maximum(vh - obs.p[i, 0], 0.0)
                # hysteresis: a merge starts only with room to spare and, once over the
                # border, is called off only for a driver much closer (called off, the CAV
                # stands across the border braking, unseen by SUMO's driver)
                reach = reach * (self.BESIDE_STRIP_HYSTERESIS[1] if over[i]
                                 else self.BESIDE_STRIP_HYSTERESIS[0])
                out[i] |= bool(np.any((ds > -ahead) & (ds < reach)))
        return out

    def exit_road(self, obs: Observation, k: int):
        """The road of a CAV leaving by exit ``k`` without its funnel: the road with the
        other exits' strips taken out, then the strip of exit ``k`` after its gore
        (:func:`controllers.road.exits.exit_road`); the walls it must not pass."""
        from controllers.road import exits as X

        rows = np.asarray(obs.exits, dtype=float)
        others = np.delete(rows, k - 1, axis=0)
        own = X.through_road(obs.road, others) if len(others) else obs.road
        return X.exit_road(own, rows[k - 1])

    def _road_of(self, road, exits, entries, k: int, keep: bool, view: int):
        """The road of group (exit ``k``, keeping the band clear, entry ``view``)."""
        from controllers.road import exits as X

        p = self.params
        if exits is None:
            base = road
        elif k == 0:
            base = (X.through_road(road, exits, p.exit_keep_clear_m, p.exit_commit_m) if keep
                    else X.through_road(road, exits))
        else:
            rows = np.asarray(exits, dtype=float)
            row = rows[k - 1]
            # the bound reaches the road's far edge exit_prepare_m before the gore
            span = (float(np.max(road.left)) - row[3] if row[3] <= 1e-9
                    else row[2] - float(np.min(road.right)))
            slope = max(span, 0.0) / (p.exit_prepare_m - p.exit_commit_m)
            # the other exits' strips are not its road: it would leave by them
            others = np.delete(rows, k - 1, axis=0)
            own = X.through_road(road, others) if len(others) else road
            base = X.exit_funnel(own, row, p.exit_prepare_m, p.exit_commit_m, slope)
        if entries is None or view == 1:
            return base
        if view == 0:
            return X.through_road(base, entries)
        return X.strip_only(base, entries)

