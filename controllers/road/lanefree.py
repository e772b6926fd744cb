"""``flocking``: lane-free flocking for roads (placeholder until the law lands)."""

from __future__ import annotations

from controllers.road.timegap_flocking import TimeGapFlocking, TimeGapFlockingParams


class LaneFreeParams(TimeGapFlockingParams):
    pass


class LaneFreeFlocking(TimeGapFlocking):
    def __init__(self, params, ctx) -> None:
        super().__init__(params, ctx.limits.box(), ctx.limits.jerk_max_mps3)
