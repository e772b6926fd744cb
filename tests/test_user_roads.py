"""Roads as a user draws them (issue 28): netconvert's defaults from plain XML written
here, drawn at random within each class from seeds nobody tuned on
(:mod:`cosim.road.user_roads`).

* Unit: the drawing (each class's geometry, seeded) and the sublane width rule
  (:mod:`cosim.sumo.sublanes`).
* SUMO, one run per joint class (a seed and a CAV share each, 120 s): every vehicle read
  back from SUMO every step (tests/sumo_cases/user_road_case.py): SUMO's x, y equal our
  frame's, every CAV's commanded lateral position lands, 0 collisions involving a CAV
  (SUMO's check and ours), 0 CAV-steps outside the road, nobody stands still 30 s.
* ``long`` (``make test-long``): the whole family, every class at 100, 60 and 40 % CAVs
  on 3 seeds, and the stopped car in a neck, through ``experiments/user_road_checks.py``.
"""

from __future__ import annotations

import os
import re

import numpy as np
import pytest
from sumo_cases.isolated import run_isolated

from cosim.errors import NetworkError
from cosim.road import user_roads
from cosim.sumo.sublanes import auto_resolution_m, narrowing

# ---------------------------------------------------------------------------- drawing


@pytest.mark.parametrize("kind", user_roads.CLASSES)
def test_a_class_draws_the_same_road_from_a_seed_and_another_from_another(kind):
    a, b, c = user_roads.draw(kind, 7), user_roads.draw(kind, 7), user_roads.draw(kind, 8)
    assert (a.nod, a.edg) == (b.nod, b.edg)
    assert (a.nod, a.edg) != (c.nod, c.edg)
    assert a.narrow_from_m < a.narrow_to_m
    ids = re.findall(r'<edge id="([^"]+)"', a.edg)
    assert list(a.route) == ids  # the route is every edge, in driving order


def test_steps_are_drawn_with_netconverts_defaults_unless_centred():
    left = user_roads.draw("step", 3, "left")
    right = user_roads.draw("step", 3, "right")
    centre = user_roads.draw("step", 3, "centre")
    assert "spreadType" not in left.edg and "shape" not in left.edg
    assert "shape" in right.edg  # drawn lower: right borders in line
    assert centre.edg.count('spreadType="center"') == 3
    assert left.narrow_width_m < user_roads.WIDE_M
    with pytest.raises(NetworkError, match="alignment"):
        user_roads.draw("step", 3, "diagonal")
    with pytest.raises(NetworkError, match="class"):
        user_roads.draw("roundabout", 3)


def test_a_taper_narrows_piece_by_piece_and_a_lane_drop_changes_lane_counts():
    t = user_roads.draw("taper", 5)
    widths = [float(w) for w in re.findall(r'width="([0-9.]+)"', t.edg)]
    assert widths[0] == pytest.approx(user_roads.WIDE_M)
    assert all(b < a for a, b in zip(widths[:-2], widths[1:-1], strict=True))
    d = user_roads.draw("lane_drop", 5)
    assert re.findall(r'numLanes="(\d)"', d.edg) == ["3", "2", "3"]


def test_an_obstacle_lands_in_the_narrow_section():
    r = user_roads.draw("s_curve", 4, obstacle=True)
    edge, frac, side = r.obstacle
    assert edge == "curve" and 0.3 < frac < 0.7 and side in ("right", "left")


# ---------------------------------------------------------------------------- sublanes


def test_the_sublane_width_is_coarse_where_nothing_narrows_and_fine_where_it_does():
    assert not narrowing([10.2, 10.2]) and auto_resolution_m(False) == 0.8
    assert narrowing([10.2, 6.8, 10.2]) and auto_resolution_m(True) == 0.2
    assert narrowing([10.2], obstacle=True)
    assert not narrowing([10.2, 10.23])  # a few cm of drawing noise is no narrowing


# ---------------------------------------------------------------------------- SUMO

#: (class, alignment, seed, CAV share, inflow veh/h): each joint class once, the seeds
#: and shares rotated (seeds 201-208: the check script uses 101-103)
CASES = [("step", "left", 201, 1.0, 5000.0), ("step", "right", 202, 0.6, 4000.0),
         ("step", "centre", 203, 0.4, 4000.0), ("taper", None, 204, 1.0, 5000.0),
         ("s_curve", None, 205, 0.6, 4000.0),
         ("long_junction", None, 206, 1.0, 5000.0), ("lane_drop", None, 207, 0.6, 4000.0),
         ("bend", None, 208, 0.4, 4000.0)]
_IDS = ["step-left-201", "step-right-202", "step-centre-203", "taper-204", "s_curve-205",
        "long_junction-206", "lane_drop-207", "bend-208"]


@pytest.mark.sumo
@pytest.mark.slow(seconds=8)
@pytest.mark.parametrize("kind,alignment,seed,share,inflow", CASES, ids=_IDS)
def test_cavs_cross_every_joint_where_they_are_commanded(kind, alignment, seed, share,
                                                         inflow, tmp_path):
    from sumo_cases.user_road_case import run

    env = {**os.environ, "COSIM_NETWORK_CACHE": str(tmp_path / "cache")}
    r = run_isolated(run, kind, alignment, seed, share, inflow, 120.0, str(tmp_path),
                     env=env)
    assert r["n_vehicle_steps"] > 10_000 and r["n_junction_steps"] > 10, r
    assert r["vehicles_arrived"] > 0, r
    # SUMO's x, y and ours: the same point (joints and junction lanes included; a
    # junction lane beside the frame's chain where the lane count changes is drawn by
    # SUMO on its own curve, in lane coordinates it is where the frame says)
    assert r["worst_xy_m"] < 1e-6, r
    # every CAV is where the law commanded it, one step later
    assert r["n_commands"] > 5_000 and r["worst_command_m"] < 1e-3, r
    assert r["collisions_geometric_cav"] == 0, r
    assert r["collisions_sumo_cav"] == 0, r
    assert r["boundary_vehicle_steps_cav"] == 0, r
    if share >= 0.5:
        assert r["max_standstill_s"] <= 30.0 and r["blocked_windows"] == 0, r


@pytest.mark.long
@pytest.mark.sumo
def test_the_whole_user_road_family_is_clean(tmp_path):
    """experiments/user_road_checks.py in full: every check on every seed (about 10 min
    on 2 cores)."""
    from experiments import user_road_checks

    out = tmp_path / "checks"
    status = user_road_checks.main(["--out", str(out), "--quiet"])
    checks = __import__("pandas").read_csv(out / "checks.csv")
    failed = checks[~checks["passed"].astype(bool)]
    assert status == 0 and failed.empty, failed.to_string()
    assert len(checks) == len(np.unique(checks["arm"] + checks["check"]))
