"""SUMO's drivers moving onto an exit strip (the SUMO world's ``_onto_strip``).

SL2015 with ``latAlignment="arbitrary"`` stops moving sideways once a driver is on the
strip's lane, his body still reaching over the border into the road, and SUMO's drivers on
the road beside do not see it: on the corridor with SUMO's drivers alone they ran into
such drivers from behind 8-18 times per 600 s run. The SUMO world moves a driver bound for
the exit the rest of the way in. One run with the rule, one without, each in its own
process.
"""

from __future__ import annotations

import pytest
from sumo_cases.isolated import run_isolated
from test_corridor import SMALL, sumo_env

pytestmark = pytest.mark.sumo

#: SUMO's drivers alone, many of them bound for the exit
OD = [["main", "main", 2500.0], ["main", "off", 1500.0], ["ramp", "main", 400.0],
      ["ramp", "off", 400.0]]


def _humans_on_the_corridor(keep_overhang: bool) -> dict:
    from cosim.config import load_scenario
    from cosim.sim.runner import run_scenario
    from cosim.sumo.world import SumoWorld

    if keep_overhang:
        SumoWorld._onto_strip = lambda self, *args: None
    sc = load_scenario("corridor", {
        **SMALL, "demand.od_vph": OD, "demand.cav_share": 0.0, "scenario.duration_s": 300.0,
        "scenario.warmup_s": 30.0, "scenario.interval_s": 30.0,
        "outputs.sumo_collisions": True})
    row = run_scenario(sc).summary.iloc[0]
    return {k: int(row[k]) for k in ("collisions_sumo_hdv_only", "strip_lateral_fixes",
                                     "missed_exits_hdv")}


@pytest.mark.slow(seconds=60)
def test_drivers_moved_fully_onto_the_strip_are_not_run_into(tmp_path):
    kept = run_isolated(_humans_on_the_corridor, True, env=sumo_env(tmp_path))
    assert kept["collisions_sumo_hdv_only"] >= 1, kept  # the artefact
    fixed = run_isolated(_humans_on_the_corridor, False, env=sumo_env(tmp_path))
    assert fixed["strip_lateral_fixes"] > 0, fixed
    assert fixed["collisions_sumo_hdv_only"] == 0, fixed
