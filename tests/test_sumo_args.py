"""What the runner asks of SUMO: no teleports (a gridlock stays one, counted by the jam
figures, instead of vehicles dropped onto others)."""

from __future__ import annotations

import pytest

from cosim.config.scenario import load_scenario
from cosim.sim.runner import run_scenario


class _Stop(Exception):
    pass


def test_sumo_never_teleports_a_vehicle(monkeypatch, tmp_path):
    import cosim.sumo.world as world

    seen: dict = {}

    def fake_init(self, net, sumo_args, *args, **kwargs):
        seen["args"] = list(sumo_args)
        raise _Stop

    monkeypatch.setattr(world.SumoWorld, "__init__", fake_init)
    with pytest.raises(_Stop):
        sc = load_scenario("default", {"scenario.duration_s": 5.0, "scenario.warmup_s": 1.0,
                                       "scenario.interval_s": 4.0})
        run_scenario(sc, out_dir=tmp_path / "run")
    args = seen["args"]
    assert args[args.index("--time-to-teleport") + 1] == "-1"
