"""The check scripts' shared command line: ``--set`` reaches every run, bad input is one
``error:`` line and exit 2 before anything is written."""

from __future__ import annotations

import pytest

from experiments import check_cli, lanefree_checks


def test_set_overrides_every_run_and_wins_over_the_checks_own():
    data = {"sweep": {"name": "x"},
            "overrides": {"controller.kind": "flocking", "scenario.duration_s": 60.0},
            "variants": [{"name": "a#1", "demand.cav_share": 0.6},
                         {"name": "b#1", "controller.params.row_approach_gain": 0.0},
                         {"name": "humans#1", "controller.kind": "sumo"}]}
    extra = {"controller.params.row_approach_gain": 3.5, "scenario.duration_s": 30.0}
    out = check_cli.with_overrides(data, extra)
    assert out["overrides"]["scenario.duration_s"] == 30.0
    assert out["overrides"]["controller.kind"] == "flocking"
    for v in out["variants"][:2]:
        assert v["controller.params.row_approach_gain"] == 3.5
        assert v["scenario.duration_s"] == 30.0
    # SUMO's drivers alone: no law parameter, the rest as every run
    assert "controller.params.row_approach_gain" not in out["variants"][2]
    assert out["variants"][2]["scenario.duration_s"] == 30.0
    assert out["variants"][0]["demand.cav_share"] == 0.6
    assert data["variants"][1]["controller.params.row_approach_gain"] == 0.0  # not mutated
    assert check_cli.with_overrides(data, {}) is data


def test_set_reaches_the_plan_of_a_real_check():
    from cosim.sweeps.plan import sweep_from_dict

    plan = sweep_from_dict(check_cli.with_overrides(
        lanefree_checks.plan_data(True), {"controller.params.row_approach_gain": 3.5}))
    law = [p for p in plan.points if p.scenario.controller.kind == "flocking"]
    assert law
    for point in law:
        assert point.scenario.controller.params["row_approach_gain"] == 3.5


@pytest.mark.parametrize("item, needle", [
    ("controller.params.nope=1", "unknown key 'nope'"),
    ("controller.params.row_approach_gain=nan", "finite"),
    ("nokey", "KEY=VALUE"),
])
def test_a_bad_set_is_one_error_line_and_writes_nothing(tmp_path, capsys, item, needle):
    out = tmp_path / "checks"
    status = lanefree_checks.main(["--smoke", "--quiet", "--out", str(out), "--set", item])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2
    assert len(err) == 1 and err[0].startswith("error:") and needle in err[0], err
    assert not out.exists()
