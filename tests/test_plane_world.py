"""Plane world (cosim/plane.py) integrators and outputs; flock metrics (cosim/flock_metrics.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from controllers.observation import Circles, InvalidStateError, Walls
from controllers.plane.olfati_saber import OlfatiSaberController
from controllers.plane.params import FlockingParams
from controllers.plane.references import VirtualLeader
from cosim.metrics.flock import (
    average_nn_distance,
    connectivity,
    deviation_energy,
    dispersion,
    flock_metrics,
    min_obstacle_distance,
    min_pair_distance,
    nearest_neighbour_distances,
    velocity_alignment,
    velocity_mismatch,
)
from cosim.plane.world import PlaneResult, PlaneWorld


class ConstantLaw:
    """Returns the same acceleration for every agent, m/s^2."""

    name = "constant"

    def __init__(self, u):
        self.u = np.asarray(u, dtype=float)

    def compute(self, obs):
        obs.check_finite()
        return np.broadcast_to(self.u, obs.q.shape).copy()


def one_agent_world(integrator: str, **kwargs) -> PlaneWorld:
    # q0 = 0 m, p0 = 1 m/s, u = 2 m/s^2, dt = 0.1 s (axis 1 at rest).
    return PlaneWorld(
        [[0.0, 0.0]], [[1.0, 0.0]], ConstantLaw([2.0, 0.0]), 0.1, integrator=integrator, **kwargs
    )


# ---------------------------------------------------------------- integrators
def test_forward_euler_step_hand_values():
    # q += p dt; p += u dt. Velocities used: 1.0, 1.2, 1.4 -> q = 0.1 + 0.12 + 0.14 = 0.36 m.
    world = one_agent_world("euler")
    world.step()
    assert world.q[0, 0] == pytest.approx(0.1)
    assert world.p[0, 0] == pytest.approx(1.2)
    world.step()
    world.step()
    assert world.q[0, 0] == pytest.approx(0.36)
    assert world.p[0, 0] == pytest.approx(1.6)
    assert world.t == pytest.approx(0.3)
    assert world.q[0, 1] == 0.0 and world.p[0, 1] == 0.0


def test_semi_implicit_step_hand_values():
    # p += u dt; q += p dt. Velocities used: 1.2, 1.4, 1.6 -> q = 0.12 + 0.14 + 0.16 = 0.42 m.
    world = one_agent_world("semi_implicit")
    world.step()
    assert world.q[0, 0] == pytest.approx(0.12)
    assert world.p[0, 0] == pytest.approx(1.2)
    world.step()
    world.step()
    assert world.q[0, 0] == pytest.approx(0.42)
    assert world.p[0, 0] == pytest.approx(1.6)


def test_the_two_integrators_bracket_the_exact_constant_acceleration_solution():
    # Exact q(t) = t + t^2 at t = 2 s: 6 m. After n = 20 steps of dt = 0.1 s with u = 2 m/s^2,
    # Euler gives p0 t + u dt^2 n (n - 1) / 2 = 2 + 3.8 = 5.8 m and semi-implicit
    # p0 t + u dt^2 n (n + 1) / 2 = 2 + 4.2 = 6.2 m; both end with the exact velocity 5 m/s.
    euler = one_agent_world("euler")
    semi = one_agent_world("semi_implicit")
    euler.run(2.0)
    semi.run(2.0)
    assert euler.q[0, 0] == pytest.approx(5.8)
    assert semi.q[0, 0] == pytest.approx(6.2)
    assert euler.p[0, 0] == pytest.approx(5.0) and semi.p[0, 0] == pytest.approx(5.0)
    assert 0.5 * (euler.q[0, 0] + semi.q[0, 0]) == pytest.approx(6.0)


def test_periodic_axis_wraps_positions_into_the_ring():
    world = PlaneWorld([[99.5, 0.0]], [[10.0, 0.0]], ConstantLaw([0.0, 0.0]), 0.1, period_s=100.0)
    world.step()
    assert world.q[0, 0] == pytest.approx(0.5)


def test_leader_moves_with_constant_velocity_and_is_recorded():
    leader = VirtualLeader(q=[50.0, 0.0], p=[10.0, 1.0])
    world = PlaneWorld([[0.0, 0.0]], [[0.0, 0.0]], ConstantLaw([0.0, 0.0]), 0.1, reference=leader)
    result = world.run(1.0)
    np.testing.assert_allclose(leader.q, [60.0, 1.0])
    last = result.leader.iloc[-1]
    assert last["t_s"] == pytest.approx(1.0)
    assert last["qx_m"] == pytest.approx(60.0) and last["py_mps"] == pytest.approx(1.0)
    # max_leader_distance_m at t = 1 s: from (0, 0) to (60, 1).
    assert result.metrics["max_leader_distance_m"].iloc[-1] == pytest.approx(math.hypot(60, 1))


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"dt": 0.0}, "dt"),
        ({"dt": -0.1}, "dt"),
        ({"integrator": "rk4"}, "integrator"),
        ({"p0": np.zeros((3, 2))}, "p0"),
    ],
)
def test_plane_world_rejects_bad_arguments(kwargs, name):
    args = {"q0": np.zeros((2, 2)), "p0": np.zeros((2, 2)), "dt": 0.1}
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        PlaneWorld(args.pop("q0"), args.pop("p0"), ConstantLaw([0.0, 0.0]), **args)


def test_plane_world_rejects_a_controller_returning_the_wrong_shape():
    class Bad:
        def compute(self, obs):
            return np.zeros((obs.n + 1, obs.m))

    world = PlaneWorld(np.zeros((2, 2)), np.zeros((2, 2)), Bad(), 0.1)
    with pytest.raises(ValueError, match="shape"):
        world.step()


def test_non_finite_velocity_in_the_world_raises_invalid_state_error_naming_the_agent():
    p0 = np.array([[0.0, 0.0], [np.nan, 0.0]])
    world = PlaneWorld(np.array([[0.0, 0.0], [6.0, 0.0]]), p0, OlfatiSaberController(), 0.1)
    with pytest.raises(InvalidStateError, match="agent np.int64\\(1\\)|agent 1"):
        world.step()


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_position_in_the_world_raises_invalid_state_error(bad):
    q0 = np.array([[0.0, 0.0], [6.0, bad]])
    world = PlaneWorld(q0, np.zeros((2, 2)), OlfatiSaberController(), 0.1)
    with pytest.raises(InvalidStateError, match="1"):
        world.step()


# ---------------------------------------------------------------- outputs
TRAJ_COLUMNS_2D = ["t_s", "agent", "x_m", "y_m", "vx_mps", "vy_mps", "ux_mps2", "uy_mps2"]
METRIC_COLUMNS = [
    "t_s",
    "step",
    "min_agent_distance_m",
    "min_obstacle_distance_m",
    "velocity_mismatch_m2ps2",
    "leader_velocity_mismatch_m2ps2",
    "deviation_energy_m2",
    "avg_nn_distance_m",
    "velocity_alignment",
    "dispersion_m",
    "n_components",
    "largest_component_share",
    "max_speed_mps",
]


def small_run(m: int = 2, **kwargs) -> PlaneResult:
    rng = np.random.default_rng(0)
    q0 = rng.uniform(0.0, 20.0, (4, m))
    leader = VirtualLeader(q=np.full(m, 10.0), p=np.full(m, 1.0))
    world = PlaneWorld(
        q0,
        np.zeros((4, m)),
        OlfatiSaberController(FlockingParams(c1_gamma=1.0, c2_gamma=1.0)),
        0.1,
        reference=leader,
        **kwargs,
    )
    return world.run(0.5)


def test_write_produces_the_documented_csv_columns(tmp_path):
    result = small_run(road_edges=(-25.0, 25.0))
    out = result.write(tmp_path / "run")
    assert sorted(p.name for p in out.iterdir()) == [
        "leader.csv",
        "meta.json",
        "metrics.csv",
        "trajectories.csv",
    ]
    traj = pd.read_csv(out / "trajectories.csv")
    assert list(traj.columns) == TRAJ_COLUMNS_2D
    assert len(traj) == 4 * 6  # 4 agents, steps 0..5
    assert sorted(traj["agent"].unique()) == [0, 1, 2, 3]
    np.testing.assert_allclose(traj["t_s"].unique(), np.arange(6) * 0.1, atol=1e-12)
    metrics = pd.read_csv(out / "metrics.csv")
    assert list(metrics.columns) == METRIC_COLUMNS + [
        "max_edge_excursion_m",
        "max_leader_distance_m",
    ]
    assert len(metrics) == 6
    leader = pd.read_csv(out / "leader.csv")
    assert list(leader.columns) == ["t_s", "qx_m", "qy_m", "px_mps", "py_mps"]
    np.testing.assert_allclose(leader["qx_m"], 10.0 + np.arange(6) * 0.1)
    assert json.loads((out / "meta.json").read_text()) == {}


def test_trajectory_csv_round_trips_the_final_world_state(tmp_path):
    world = one_agent_world("semi_implicit")
    result = world.run(0.3)
    traj = pd.read_csv(result.write(tmp_path) / "trajectories.csv")
    last = traj.iloc[-1]
    assert last["t_s"] == pytest.approx(0.3)
    assert last["x_m"] == pytest.approx(0.42)  # hand value of test_semi_implicit_step_hand_values
    assert last["vx_mps"] == pytest.approx(1.6)


def test_three_dimensional_runs_have_z_columns(tmp_path):
    result = small_run(m=3)
    traj = pd.read_csv(result.write(tmp_path) / "trajectories.csv")
    assert list(traj.columns) == [
        "t_s",
        "agent",
        "x_m",
        "y_m",
        "z_m",
        "vx_mps",
        "vy_mps",
        "vz_mps",
        "ux_mps2",
        "uy_mps2",
        "uz_mps2",
    ]
    leader = pd.read_csv(result.write(tmp_path) / "leader.csv")
    assert list(leader.columns) == ["t_s", "qx_m", "qy_m", "qz_m", "px_mps", "py_mps", "pz_mps"]


def test_meta_is_written_as_json(tmp_path):
    result = small_run()
    result.meta.update({"scenario": "tiny", "seed": 3})
    meta = json.loads((result.write(tmp_path) / "meta.json").read_text())
    assert meta == {"scenario": "tiny", "seed": 3}


def test_edge_excursion_metric_hand_value():
    # Agent at y = 26 with edges (-25, 25): 1 m beyond the left edge.
    world = PlaneWorld(
        [[0.0, 26.0], [10.0, 0.0]],
        np.zeros((2, 2)),
        ConstantLaw([0.0, 0.0]),
        0.1,
        road_edges=(-25.0, 25.0),
    )
    result = world.run(0.1)
    assert result.metrics["max_edge_excursion_m"].iloc[0] == pytest.approx(1.0)


def test_trajectory_row_holds_the_command_applied_from_that_state():
    world = one_agent_world("euler", record_every=1)
    traj = world.run(0.3).trajectories
    rows = traj[traj["agent"] == 0].reset_index(drop=True)
    # p(t + dt) = p(t) + u(t) dt for every recorded row but the last.
    for k in range(len(rows) - 1):
        assert rows.loc[k + 1, "vx_mps"] == pytest.approx(
            rows.loc[k, "vx_mps"] + rows.loc[k, "ux_mps2"] * 0.1
        )


# ---------------------------------------------------------------- flock metrics
LINE_Q = np.array([[0.0, 0.0], [7.0, 0.0], [15.0, 0.0]])  # gaps 7 m and 8 m


def test_nearest_neighbour_distances_three_agents_on_a_line():
    np.testing.assert_allclose(nearest_neighbour_distances(LINE_Q), [7.0, 7.0, 8.0])
    assert min_pair_distance(LINE_Q) == pytest.approx(7.0)
    assert average_nn_distance(LINE_Q) == pytest.approx(22.0 / 3.0)


def test_nearest_neighbour_distances_on_a_ring_use_the_short_way_round():
    q = np.array([[1.0, 0.0], [99.0, 0.0], [50.0, 0.0]])
    np.testing.assert_allclose(nearest_neighbour_distances(q, period=100.0), [2.0, 2.0, 49.0])


def test_nearest_neighbour_distances_on_a_ring_do_not_wrap_the_lateral_axis():
    q = np.array([[0.0, 0.0], [0.0, 10.0]])
    np.testing.assert_allclose(nearest_neighbour_distances(q, period=100.0), [10.0, 10.0])


def test_deviation_energy_hand_value():
    # d = 7, r = 8.4: edges (0,1) with deviation 0 and (1,2) with deviation 1 (15 m pair is out).
    # E = 2 * (0^2 + 1^2) / (2 * 2 + 1) = 0.4 m^2.
    assert deviation_energy(LINE_Q, d=7.0, r=8.4) == pytest.approx(0.4)
    # A perfect lattice: zero.
    assert deviation_energy(np.array([[0.0, 0.0], [7.0, 0.0], [14.0, 0.0]]), 7.0, 8.4) == 0.0
    # No edges: zero.
    assert deviation_energy(LINE_Q, d=7.0, r=5.0) == 0.0


def test_velocity_alignment_is_one_for_parallel_and_zero_for_opposite_velocities():
    assert velocity_alignment(np.array([[1.0, 0.0], [5.0, 0.0], [0.1, 0.0]])) == pytest.approx(1.0)
    assert velocity_alignment(np.array([[3.0, 4.0], [-3.0, -4.0]])) == pytest.approx(0.0)
    # Perpendicular pair: ||(1, 1) / 2|| = 1 / sqrt(2).
    assert velocity_alignment(np.array([[2.0, 0.0], [0.0, 9.0]])) == pytest.approx(
        1.0 / math.sqrt(2.0)
    )
    assert math.isnan(velocity_alignment(np.zeros((3, 2))))


def test_dispersion_hand_value():
    # x = 0, 7, 14: sample variance (49 + 0 + 49) / 2 = 49, y constant: dispersion 7 m.
    assert dispersion(np.array([[0.0, 1.0], [7.0, 1.0], [14.0, 1.0]])) == pytest.approx(7.0)
    # Two points (0, 0) and (6, 8): sample variances 18 and 32, dispersion sqrt(50) m.
    assert dispersion(np.array([[0.0, 0.0], [6.0, 8.0]])) == pytest.approx(math.sqrt(50.0))
    assert dispersion(np.array([[3.0, 3.0]])) == 0.0


def test_velocity_mismatch_hand_values():
    p = np.array([[1.0, 0.0], [3.0, 0.0]])
    # Mean velocity (2, 0): deviations 1 and 1 -> 1 m^2/s^2; w.r.t. the leader (0, 0): (1 + 9)/2.
    assert velocity_mismatch(p) == pytest.approx(1.0)
    assert velocity_mismatch(p, np.array([0.0, 0.0])) == pytest.approx(5.0)


def test_connectivity_components_on_a_line():
    q = np.array([[0.0, 0.0], [7.0, 0.0], [20.0, 0.0]])
    assert connectivity(q, 8.4) == (2, pytest.approx(2.0 / 3.0))
    assert connectivity(q, 14.0) == (1, 1.0)
    assert connectivity(q, 5.0) == (3, pytest.approx(1.0 / 3.0))


def test_min_obstacle_distance_to_circle_surface_and_walls():
    q = np.array([[0.0, 0.0], [20.0, 3.0]])
    circles = Circles([[20.0, 10.0]], [5.0])  # agent 1 is 7 m from the centre: 2 m from surface
    walls = Walls([[0.0, -25.0]], [[0.0, 1.0]])  # agent 0 is 25 m above the wall
    assert min_obstacle_distance(q, circles=circles) == pytest.approx(2.0)
    assert min_obstacle_distance(q, walls=walls) == pytest.approx(25.0)
    assert min_obstacle_distance(q, circles, walls) == pytest.approx(2.0)
    inside = np.array([[20.0, 8.0]])
    assert min_obstacle_distance(inside, circles=circles) == pytest.approx(-3.0)
    assert min_obstacle_distance(q) == math.inf


def test_flock_metrics_collects_every_metric():
    p = np.array([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0]])
    out = flock_metrics(LINE_Q, p, d=7.0, r=8.4, p_ref=np.array([2.0, 0.0]))
    assert out["min_agent_distance_m"] == pytest.approx(7.0)
    assert out["velocity_mismatch_m2ps2"] == pytest.approx(0.0)
    assert out["leader_velocity_mismatch_m2ps2"] == pytest.approx(1.0)
    assert out["deviation_energy_m2"] == pytest.approx(0.4)
    assert out["velocity_alignment"] == pytest.approx(1.0)
    assert out["n_components"] == 1 and out["largest_component_share"] == 1.0
    assert out["min_obstacle_distance_m"] == math.inf


# ---------------------------------------------------------------- figures
@pytest.fixture(scope="module")
def seed000_short():
    from cosim.plane.scenarios import run_plane_scenario

    return run_plane_scenario("seed000", duration_s=0.5)


def test_seed000_meta_records_the_obstacle_and_the_road_edges(seed000_short, tmp_path):
    meta = json.loads((seed000_short.write(tmp_path) / "meta.json").read_text())
    assert meta["obstacles"] == {
        "circles": {"centres_m": [[55.0, 0.0]], "radii_m": [10.0]},
        "walls": {"points_m": [[0.0, -25.0], [0.0, 25.0]], "normals": [[0.0, 1.0], [0.0, -1.0]]},
    }


def test_trajectory_figure_draws_the_obstacle_and_the_road_edges(seed000_short):
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle as CirclePatch

    from cosim.plane.plots import trajectory_figure

    fig = trajectory_figure(seed000_short)
    try:
        (ax,) = fig.axes
        discs = [p for p in ax.patches if isinstance(p, CirclePatch)]
        assert len(discs) == 1
        assert discs[0].center == (55.0, 0.0) and discs[0].radius == 10.0
        # The walls y = -25 m and y = 25 m: horizontal segments across the drawn area.
        edges = [
            ln for ln in ax.lines if len(ln.get_ydata()) == 2 and np.ptp(ln.get_ydata()) == 0.0
        ]
        assert sorted(float(ln.get_ydata()[0]) for ln in edges) == [-25.0, 25.0]
        x_traj = seed000_short.trajectories["x_m"]
        for ln in edges:
            assert min(ln.get_xdata()) < x_traj.min() and max(ln.get_xdata()) > 65.0
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert {"obstacle", "road edge / wall", "agents", "virtual leader"} <= set(labels)
        assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"
        assert ax.get_title().startswith("seed000")
    finally:
        plt.close(fig)


def test_trajectory_figure_without_obstacles_draws_none():
    import matplotlib.pyplot as plt

    from cosim.plane.plots import trajectory_figure

    res = small_run()
    res.meta["scenario"] = "tiny"
    fig = trajectory_figure(res)
    try:
        (ax,) = fig.axes
        assert len(ax.patches) == 0
        assert all(len(ln.get_xdata()) != 2 for ln in ax.lines)  # only paths (6 points each)
        assert ax.get_title().startswith("tiny")
    finally:
        plt.close(fig)


def test_distance_figure_has_units_and_names_the_scenario(seed000_short):
    import matplotlib.pyplot as plt

    from cosim.plane.plots import distance_figure

    fig = distance_figure(seed000_short)
    try:
        (ax,) = fig.axes
        assert ax.get_xlabel() == "t (s)" and ax.get_ylabel() == "distance (m)"
        assert ax.get_title().startswith("seed000")
        assert len(ax.lines) == 2  # agents and obstacles
    finally:
        plt.close(fig)


def test_plot_plane_result_writes_both_pngs(seed000_short, tmp_path):
    from cosim.plane.plots import plot_plane_result

    paths = plot_plane_result(seed000_short, tmp_path)
    assert [p.name for p in paths] == ["trajectories.png", "min_distance.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_trajectory_figure_draws_constant_road_edges():
    import matplotlib.pyplot as plt

    from cosim.plane.plots import trajectory_figure
    from cosim.plane.scenarios import obstacles_meta

    world = PlaneWorld(
        [[0.0, 0.0], [30.0, 2.0]], np.zeros((2, 2)), ConstantLaw([1.0, 0.0]), 0.1,
        road_edges=(-3.0, 5.0),
    )
    res = world.run(0.3)
    res.meta["obstacles"] = obstacles_meta(world)
    assert res.meta["obstacles"] == {"road_edges_m": [-3.0, 5.0]}
    fig = trajectory_figure(res)
    try:
        (ax,) = fig.axes
        edges = [ln for ln in ax.lines if len(ln.get_ydata()) == 2]
        assert sorted(float(ln.get_ydata()[0]) for ln in edges) == [-3.0, 5.0]
        assert all(np.ptp(ln.get_ydata()) == 0.0 for ln in edges)
    finally:
        plt.close(fig)
