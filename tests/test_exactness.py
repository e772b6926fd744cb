"""The fast paths of issue 15 compute what the code before them computed.

References (``tests/golden/record_exactness.py``, recorded on a copy of the code before the
speed-ups): observations captured from five runs (SUMO: issue 15's benchmark case, dense
mixed traffic, a stopped obstacle, an on-ramp; road world: a narrowing, a ring) replayed in
order through one fresh ``LaneFreeFlocking``; the safety layer on the same steps, with the
law's commands and with harsh ones that make every rule act; and whole runs (a SUMO run with
an obstacle, a road-world narrowing, 40 s each): every vehicle's state every 10th step and
the commands applied to the CAVs every 5th.

Tolerances: the law's and the safety layer's commands agree to ``1e-9`` relative (plus
``1e-12`` m/s^2 absolute, for zeros); counters (target changes, yields, safety activations)
exactly. Whole runs: states and commands to ``1e-9`` relative (plus ``1e-9`` m, m/s) and the
same vehicles at the same steps; a run is a closed loop, so any difference larger than
round-off would grow and show.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

GOLDEN = Path(__file__).resolve().parent / "golden"
sys.path.insert(0, str(GOLDEN))
import record_exactness as rx  # noqa: E402

REL = 1e-9
ABS_LAW = 1e-12

LAW = np.load(rx.LAW_FILE)
TRAJ = np.load(rx.TRAJ_FILE)


def _close(got: np.ndarray, want: np.ndarray, rel: float, abs_: float) -> tuple[bool, float]:
    got, want = np.asarray(got, float), np.asarray(want, float)
    assert got.shape == want.shape, (got.shape, want.shape)
    same_inf = (got == want) | (np.isnan(got) & np.isnan(want))
    err = np.where(same_inf, 0.0, np.abs(got - want))
    ok = err <= rel * np.abs(np.where(np.isfinite(want), want, 0.0)) + abs_
    return bool(ok.all()), float(np.max(err, initial=0.0))


def _limits(name: str):
    from controllers.layers.constraints import ActuatorLimits

    return ActuatorLimits(**json.loads(str(LAW[f"{name}/limits"])))


def _safety(name: str):
    from controllers.layers.safety import SafetyParams

    return SafetyParams(**json.loads(str(LAW[f"{name}/safety"])))


@pytest.mark.parametrize("name", sorted(rx.LAW_CASES))
def test_lanefree_law_matches_reference(name):
    steps = rx.unpack_steps(name, LAW)
    assert len(steps) == rx.LAW_CASES[name][3]
    u, stats = rx.replay_law(steps, _limits(name))
    ok, err = _close(np.concatenate(u), LAW[f"{name}/u_law"], REL, ABS_LAW)
    assert ok, f"{name}: law commands differ by up to {err:g} m/s^2"
    want = json.loads(str(LAW[f"{name}/law_stats"]))
    assert {k: stats[k] for k in want} == want
    # counters added after the reference was recorded: no reference case has an exit
    assert stats.keys() - want.keys() <= {"creeps"} and stats.get("creeps", 0) == 0


@pytest.mark.parametrize("harsh", [False, True], ids=["law_commands", "harsh_commands"])
@pytest.mark.parametrize("name", sorted(rx.LAW_CASES))
def test_safety_layer_matches_reference(name, harsh):
    steps = rx.unpack_steps(name, LAW)
    tag = "_harsh" if harsh else ""
    us, vls, counts = rx.replay_safety(steps, _limits(name), _safety(name),
                                       float(LAW[f"{name}/dt"]), harsh_cmd=harsh)
    ok, err = _close(np.concatenate(us), LAW[f"{name}/u_safe{tag}"], REL, ABS_LAW)
    assert ok, f"{name}: safe commands differ by up to {err:g} m/s^2"
    ok, err = _close(np.concatenate(vls), LAW[f"{name}/v_lat_next{tag}"], REL, ABS_LAW)
    assert ok, f"{name}: next lateral speeds differ by up to {err:g} m/s"
    want = json.loads(str(LAW[f"{name}/safety_counts{tag}"]))
    assert counts == want
    if harsh:  # the harsh commands do make the layer act (the test could fail)
        assert want["safety_edge_activations"] > 0


def test_references_cover_the_interesting_paths():
    """Yields, target changes and every safety rule occur somewhere in the references."""
    stats = [json.loads(str(LAW[f"{n}/law_stats"])) for n in rx.LAW_CASES]
    harsh = [json.loads(str(LAW[f"{n}/safety_counts_harsh"])) for n in rx.LAW_CASES]
    assert sum(s["yields"] for s in stats) > 0
    assert min(s["target_changes"] for s in stats) > 0
    for rule in ("edge", "side", "speed"):
        assert sum(h[f"safety_{rule}_activations"] for h in harsh) > 0, rule
    assert os.path.getsize(rx.LAW_FILE) + os.path.getsize(rx.TRAJ_FILE) < 1_000_000


def _compare_run(name: str, got: dict) -> None:
    for part, caught in (("states", got["states"]), ("cmds", got["cmds"])):
        want = rx.unpack_traj(name, part, TRAJ)
        have = {(k, i): x[r] for k, ids, x in caught for r, i in enumerate(ids)}
        assert set(have) == set(want), f"{name} {part}: other vehicles or steps"
        keys = sorted(want)
        ok, err = _close(np.array([have[k] for k in keys]), np.array([want[k] for k in keys]),
                         REL, 1e-9)
        assert ok, f"{name} {part}: differ by up to {err:g}"
    assert got["inserted"] == int(TRAJ[f"{name}/inserted"])


def test_road_world_run_matches_reference():
    _compare_run("road_narrowing", rx.capture_traj("road_narrowing"))


@pytest.mark.sumo
def test_sumo_run_matches_reference(tmp_path):
    root = str(Path(__file__).resolve().parents[1])
    got = rx._run_child("traj", "sumo_obstacle", root, tmp_path)
    _compare_run("sumo_obstacle", got)


@pytest.mark.sumo
@pytest.mark.parametrize("scen", ["obstacle", "ring", "onramp", "width_drop"])
def test_cav_action_step_leaves_cav_motion_unchanged(scen, tmp_path):
    """With only CAVs on the road, SUMO's action step for CAVs (one step or 1 s) changes
    nothing of their motion nor of SUMO's insertions: every state and command is
    bit-identical (SUMO's Euler update kept: without --step-method.ballistic false it
    switches to the ballistic one when the CAVs get the long action step, and the width
    drop's entrance inserts otherwise; changeSublane moves are made in steps where the CAV
    acts)."""
    root = str(Path(__file__).resolve().parents[1])
    every, slow = (rx._run_child("traj", f"{scen}_asl_{a:g}", root, tmp_path) for a in (0.1, 1.0))
    assert every["inserted"] == slow["inserted"] > 10
    for part in ("states", "cmds"):
        a, b = every[part], slow[part]
        assert [(k, ids) for k, ids, _ in a] == [(k, ids) for k, ids, _ in b], part
        assert all(np.array_equal(x, y) for (_, _, x), (_, _, y) in zip(a, b, strict=True)), part
