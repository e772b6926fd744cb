"""Seed 003 boundary-point flocking (controllers/plane/boundary_points.py, obstacles.py).

Hand-made configurations for the weights, the sampling and the phase
comparison; a loop reference for the vectorised terms; the split/rejoin
memory under vehicles entering and leaving; short runs of the paper's
two-obstacle scenes from ``experiments/seed003_obstacles.py``.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from controllers.layers.constraints import ConstrainedController, SpeedSaturation
from controllers.observation import Observation
from controllers.plane.boundary_points import (
    A1,
    A2,
    A3,
    A4,
    CCW,
    CW,
    NONE,
    BoundaryPointController,
    BoundaryPointParams,
    eta,
    goal_blocking,
    phase_choice,
)
from controllers.plane.obstacles import (
    Circle,
    ObstacleSet,
    Polygon,
    Wall,
    c_shape,
    diamond,
    rectangle,
    sample_segment,
    sense,
)
from controllers.plane.potentials import (
    adjacency,
    phi_alpha,
    sigma_grad,
    sigma_norm,
    sigma_norm_scalar,
)

ROOT = Path(__file__).resolve().parents[1]
P = BoundaryPointParams()


def _experiment():
    name = "seed003_obstacles"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, ROOT / "experiments" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def _obs(q, p=None, goal=(10.0, 0.0), points=None, ids=None, vel=None, t=0.0):
    q = np.atleast_2d(np.asarray(q, dtype=float))
    extras = {}
    if points is not None:
        extras["boundary_points"] = np.asarray(points, dtype=float)
    if vel is not None:
        extras["boundary_point_velocities"] = np.asarray(vel, dtype=float)
    return Observation(
        q=q,
        p=np.zeros_like(q) if p is None else np.asarray(p, dtype=float),
        t=t,
        dt=0.1,
        ids=ids,
        leader_q=None if goal is None else np.asarray(goal, dtype=float),
        leader_p=None if goal is None else np.zeros(q.shape[1]),
        extras=extras,
    )


# ------------------------------------------------------------------------ parameters
def test_table3_defaults_and_early_warning_distance():
    assert (P.r, P.d, P.epsilon, P.h, P.a, P.b) == (6.0, 4.0, 0.5, 0.2, 2.0, 20.0)
    assert (P.tau_a, P.tau_e, P.tau_s) == (0.1, 10.0, 10000.0)
    assert P.delta_theta == pytest.approx(math.pi / 4)
    assert (P.p_max, P.d_min, P.dt) == (5.0, 1.0, 0.1)
    assert P.d_e == pytest.approx(1.0 + 2 * 5.0 * 0.1)  # d_e = d_min + 2 p_max dt = 2 m
    assert P.with_(p_max=2.0, dt=0.25, d_min=0.5).d_e == pytest.approx(0.5 + 2 * 2.0 * 0.25)
    assert P.tau_beta == P.tau_alpha
    assert P.with_(tau_e_beta=50.0, tau_s_beta=100.0).tau_beta == (0.1, 50.0, 100.0)


@pytest.mark.parametrize(
    ("dist", "weight"),
    [
        (0.0, 1e4),
        (0.5, 1e4),
        (1.999, 1e4),  # separation region (0, d_e)
        (2.0, 10.0),  # early warning [d_e, d], closed at both ends
        (3.0, 10.0),
        (4.0, 10.0),
        (4.001, 0.1),  # attraction region (d, r)
        (5.999, 0.1),
        (6.0, 0.0),  # outside the sensing radius
        (9.0, 0.0),
    ],
)
def test_eta_piecewise_weights(dist, weight):
    assert eta(dist, P.d_e, P.d, P.r, P.tau_alpha) == pytest.approx(weight)


def test_eta_is_vectorised_and_follows_d_e():
    prm = P.with_(p_max=10.0)  # d_e = 1 + 2 * 10 * 0.1 = 3 m
    w = eta(np.array([2.5, 2.99, 3.0, 3.5]), prm.d_e, prm.d, prm.r, prm.tau_alpha)
    np.testing.assert_array_equal(w, [1e4, 1e4, 10.0, 10.0])


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"r": -1.0}, "r"),
        ({"r": 3.0}, "r"),  # r must exceed d
        ({"d": 0.0}, "d"),
        ({"epsilon": 0.0}, "epsilon"),
        ({"h": 1.0}, "h"),
        ({"a": 30.0}, "a"),
        ({"c2_beta": -1.0}, "c2_beta"),
        ({"tau_a": -0.1}, "tau_a"),
        ({"tau_e": 0.01}, "tau_e"),
        ({"tau_s": 5.0}, "tau_s"),
        ({"tau_s_beta": 1.0}, "tau_s_beta"),
        ({"delta_theta": 0.0}, "delta_theta"),
        ({"delta_theta": 7.0}, "delta_theta"),
        ({"p_max": float("nan")}, "p_max"),
        ({"d_min": 3.5}, "d_min"),  # d_e = 4.5 > d
        ({"dt": 0.0}, "dt"),
        ({"direction": "left"}, "direction"),
        ({"block_width": 0.0}, "block_width"),
        ({"gamma_position": "quadratic"}, "gamma_position"),
        ({"beta_potential": "none"}, "beta_potential"),
        ({"follow_timeout": 0.0}, "follow_timeout"),
        ({"c1_gamma": True}, "c1_gamma"),
    ],
)
def test_bad_parameters_raise_value_error_naming_the_field(changes, field):
    with pytest.raises(ValueError, match=rf"^{field}\b"):
        BoundaryPointParams(**changes)


# ------------------------------------------------------------------------ obstacles
def _spacings(pts: np.ndarray, closed: bool = True) -> np.ndarray:
    nxt = np.roll(pts, -1, axis=0) if closed else pts[1:]
    return np.linalg.norm(nxt - pts[: len(nxt)], axis=1)


@pytest.mark.parametrize("spacing", [0.3, 0.5, 1.0])
def test_circle_boundary_points_lie_on_the_circle_at_most_spacing_apart(spacing):
    c = Circle((3.0, -2.0), 5.0)
    pts = c.boundary(spacing)
    np.testing.assert_allclose(np.linalg.norm(pts - [3.0, -2.0], axis=1), 5.0, rtol=1e-12)
    gaps = _spacings(pts)
    assert gaps.max() <= spacing + 1e-12
    assert gaps.min() > 0.9 * gaps.max()  # evenly spaced
    assert len(pts) == math.ceil(2 * math.pi * 5.0 / spacing)
    np.testing.assert_allclose(c.signed_distance(pts), 0.0, atol=1e-12)


def test_polygon_boundary_points_are_on_the_edges_with_vertices_once():
    sq = rectangle((0.0, 0.0), 4.0, 2.0)
    pts = sq.boundary(0.45)
    np.testing.assert_allclose(sq.signed_distance(pts), 0.0, atol=1e-12)
    assert _spacings(pts).max() <= 0.45 + 1e-12
    for v in sq.vertices:
        assert np.sum(np.all(np.isclose(pts, v), axis=1)) == 1
    assert sq.signed_distance([[0.0, 0.0]])[0] == pytest.approx(-1.0)  # inside
    assert sq.signed_distance([[5.0, 0.0]])[0] == pytest.approx(3.0)


def test_diamond_points_satisfy_the_rhombus_equation():
    dm = diamond((10.0, 5.0), 3.0, 2.0)
    pts = dm.boundary(0.25)
    np.testing.assert_allclose(
        np.abs(pts[:, 0] - 10.0) / 3.0 + np.abs(pts[:, 1] - 5.0) / 2.0, 1.0, atol=1e-12
    )
    assert _spacings(pts).max() <= 0.25 + 1e-12


def test_c_shape_is_non_convex_and_sampled_on_its_outline():
    c = c_shape((0.0, 0.0), width=10.0, height=16.0, thickness=2.0, opening=0.0)
    assert len(c.vertices) == 8
    pts = c.boundary(0.5)
    np.testing.assert_allclose(c.signed_distance(pts), 0.0, atol=1e-12)
    assert _spacings(pts).max() <= 0.5 + 1e-12
    # outline: outer 10 + 16 + 10, arm ends 2 + 2, inner arms 8 + 8, inner back 12 = 68 m
    assert len(pts) == 136
    sd = c.signed_distance([[1.0, 0.0], [-4.0, 0.0], [0.0, 7.0], [20.0, 0.0]])
    assert sd[0] == pytest.approx(4.0)  # in the pocket: outside, 4 m from the inner back wall
    assert sd[1] < 0 and sd[2] < 0  # back wall and upper arm: inside
    assert sd[3] > 0
    # mouth towards -x: the pocket opens to the left
    cl = c_shape((0.0, 0.0), 10.0, 16.0, 2.0, opening=math.pi)
    assert cl.signed_distance([[-1.0, 0.0]])[0] == pytest.approx(4.0)
    assert cl.signed_distance([[4.0, 0.0]])[0] < 0


def test_wall_sampling_and_signed_distance():
    w = Wall.infinite((0.0, 0.0), (0.0, 1.0), half_length=10.0)
    pts = w.boundary(0.5)
    assert len(pts) == 41 and np.allclose(pts[:, 1], 0.0)
    assert w.signed_distance([[3.0, 2.0], [3.0, -2.0]]).tolist() == pytest.approx([2.0, -2.0])
    thin = Wall((0.0, 0.0), (4.0, 0.0))
    assert thin.signed_distance([[2.0, -1.0], [6.0, 0.0]]).tolist() == pytest.approx([1.0, 2.0])


def test_obstacle_set_distance_matches_the_obstacles_and_converts_for_olfati_saber():
    obst = ObstacleSet(
        (
            Circle((0.0, 0.0), 2.0),
            c_shape((15.0, 0.0), 8.0, 10.0, 2.0),
            Wall.infinite((0.0, -10.0), (0.0, 1.0)),
            Wall((30.0, 0.0), (30.0, 5.0)),
        )
    )
    q = np.random.default_rng(3).uniform(-12.0, 35.0, (400, 2))
    ref = np.min(np.stack([o.signed_distance(q) for o in obst]), axis=0)
    np.testing.assert_allclose(obst.signed_distance(q), ref, atol=1e-12)
    pts = obst.boundary_points(0.5)
    assert np.abs(obst.signed_distance(pts)).max() < 1e-9
    assert len(obst.labels(0.5)) == len(pts)
    circles, walls = obst.cosim_obstacles(disc_radius=0.5)
    assert walls is not None and len(walls.points) == 1  # only the wall with a normal
    assert circles.radii[0] == 2.0 and np.all(circles.radii[1:] == 0.5)


def test_bad_obstacles_raise():
    with pytest.raises(ValueError, match="radius"):
        Circle((0.0, 0.0), 0.0)
    with pytest.raises(ValueError, match="vertices"):
        Polygon([[0.0, 0.0], [1.0, 0.0]])
    with pytest.raises(ValueError, match="thickness"):
        c_shape((0.0, 0.0), 4.0, 3.0, 2.0)
    with pytest.raises(ValueError, match="spacing"):
        sample_segment(np.zeros(2), np.ones(2), 0.0)
    with pytest.raises(ValueError, match="perpendicular"):
        Wall((0.0, 0.0), (1.0, 0.0), normal=(1.0, 1.0))


def test_sense_returns_exactly_the_points_within_the_radius():
    rng = np.random.default_rng(0)
    q = rng.uniform(0, 30, (40, 2))
    pts = rng.uniform(0, 30, (500, 2))
    pairs = sense(q, pts, 6.0)
    dist = np.linalg.norm(pts[None] - q[:, None], axis=-1)
    ref = np.argwhere(dist < 6.0)
    assert sorted(map(tuple, pairs.tolist())) == sorted(map(tuple, ref.tolist()))
    assert np.all(np.diff(pairs[:, 0]) >= 0)  # grouped by agent


# ------------------------------------------------------------------------ sensing radius
def test_only_boundary_points_within_the_sensing_radius_act():
    law = BoundaryPointController()
    q = [[0.0, 0.0]]
    far = [[0.0, 6.2], [6.5, 0.0], [-3.0, -5.5]]  # all farther than r = 6 m
    u_none = law.compute(_obs(q, points=np.empty((0, 2))))
    law.reset()
    u_far = law.compute(_obs(q, points=far))
    np.testing.assert_array_equal(u_none, u_far)
    assert law.last_terms.scenario[0] == NONE and law.last_terms.n_beta_pairs == 0
    law.reset()
    u_near = law.compute(_obs(q, points=far + [[0.0, 5.9]]))
    assert law.last_terms.n_beta_pairs == 1
    assert not np.allclose(u_near, u_far)
    law.reset()
    u_near_and_far = law.compute(_obs(q, points=far + [[0.0, 5.9]] + [[0.0, -7.0]]))
    np.testing.assert_allclose(u_near, u_near_and_far)


def test_constructor_obstacles_and_extras_points_give_the_same_command():
    obst = ObstacleSet((Circle((6.0, 0.5), 2.0), Wall((0.0, -4.0), (12.0, -4.0))))
    q = np.array([[0.0, 0.0], [1.0, 2.5], [2.5, -1.5]])
    p = np.array([[1.0, 0.0], [0.5, 0.5], [1.0, -0.2]])
    a = BoundaryPointController(obstacles=obst, spacing=0.5)
    b = BoundaryPointController()
    ua = a.compute(_obs(q, p, goal=(20.0, 0.0)))
    ub = b.compute(_obs(q, p, goal=(20.0, 0.0), points=obst.boundary_points(0.5)))
    np.testing.assert_allclose(ua, ub, rtol=1e-12, atol=1e-9)


def _loop_reference(q, p, pts, prm: BoundaryPointParams):
    """Gradient terms and sum of b_ik by explicit loops with the olfati_saber building blocks."""
    r_a = float(sigma_norm_scalar(prm.r, prm.epsilon))
    d_a = float(sigma_norm_scalar(prm.d, prm.epsilon))
    n = len(q)
    alpha = np.zeros_like(q)
    beta = np.zeros_like(q)
    b_sum = np.zeros(n)
    for i in range(n):
        for j in range(n):
            z = q[j] - q[i]
            dist = np.linalg.norm(z)
            if i == j or dist >= prm.r:
                continue
            zs = sigma_norm(z, prm.epsilon)
            w = eta(dist, prm.d_e, prm.d, prm.r, prm.tau_alpha)
            alpha[i] += (
                prm.c1_alpha
                * w
                * phi_alpha(zs, r_a, d_a, prm.h, prm.a, prm.b)
                * (sigma_grad(z, prm.epsilon))
            )
            alpha[i] += prm.c2_alpha * adjacency(zs, r_a, prm.h) * (p[j] - p[i])
        for k in range(len(pts)):
            z = pts[k] - q[i]
            dist = np.linalg.norm(z)
            if dist >= prm.r:
                continue
            zs = sigma_norm(z, prm.epsilon)
            w = eta(dist, prm.d_e, prm.d, prm.r, prm.tau_beta)
            beta[i] += (
                prm.c1_beta
                * w
                * phi_alpha(zs, r_a, d_a, prm.h, prm.a, prm.b)
                * (sigma_grad(z, prm.epsilon))
            )
            b_sum[i] += adjacency(zs, r_a, prm.h)
    return alpha, beta, b_sum


def test_vectorised_terms_match_a_loop_reference():
    rng = np.random.default_rng(7)
    q = rng.uniform(0, 14, (25, 2))
    p = rng.uniform(-2, 2, (25, 2))
    pts = Circle((7.0, 7.0), 3.0).boundary(0.5)
    prm = P.with_(tau_s=50.0)
    law = BoundaryPointController(prm)
    law.compute(_obs(q, p, goal=(40.0, 40.0), points=pts))
    t = law.last_terms
    alpha, beta, b_sum = _loop_reference(q, p, pts, prm)
    np.testing.assert_allclose(t.alpha, alpha, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(t.beta_gradient, beta, rtol=1e-10, atol=1e-9)
    # consensus term: c2b * sum_k b_ik * (p_hat - p)
    has = b_sum > 0
    p_hat = (t.q_hat - q) / prm.dt
    np.testing.assert_allclose(
        t.beta_consensus[has], (prm.c2_beta * b_sum[has, None]) * (p_hat[has] - p[has])
    )
    assert np.all(t.beta_consensus[~has] == 0)


# ------------------------------------------------------------------------ phase comparison
def _ring(deg, radius=1.0):
    a = np.radians(np.asarray(deg, dtype=float))
    return radius * np.column_stack([np.cos(a), np.sin(a)])


def _choose(deg, mode, ref=(1.0, 0.0)):
    rel = _ring(deg)
    chosen = phase_choice(
        rel, np.zeros(len(rel), dtype=np.int64), 1, np.array([ref]), np.array([mode]), P.delta_theta
    )
    return float(np.degrees(np.arctan2(*rel[chosen[0]][::-1])))


def test_phase_comparison_picks_the_end_of_the_first_cluster_in_each_sense():
    deg = [10, 20, 30, 100, 110]  # gap of 70 deg >= 45 deg between 30 and 100
    assert _choose(deg, CCW) == pytest.approx(30.0)  # eq. 15: ascending, first gap
    assert _choose(deg, CW) == pytest.approx(100.0)  # eq. 16: descending from 2 pi
    covering = [-20, -10, 0, 10, 20, 90, 100]  # the cluster covering the reference ray
    assert _choose(covering, CCW) == pytest.approx(20.0)
    assert _choose(covering, CW) == pytest.approx(-20.0)
    # the reference direction rotates the frame (A2: towards the split point)
    assert _choose(deg, CCW, ref=(0.0, 1.0)) == pytest.approx(110.0)  # from 90 deg: 100, 110
    assert _choose(deg, CW, ref=(0.0, 1.0)) == pytest.approx(10.0)  # from 90 deg: 30, 20, 10


def test_phase_comparison_edge_cases():
    assert _choose([77.0], CCW) == pytest.approx(77.0)  # a single point
    everywhere = np.arange(0, 360, 30)  # no gap >= 45 deg: the last point in scan order
    assert _choose(everywhere, CCW) == pytest.approx(-30.0)
    assert _choose(everywhere, CW) == pytest.approx(30.0)
    out = phase_choice(np.empty((0, 2)), np.empty(0, dtype=np.int64), 3, np.ones((3, 2)),
                       np.ones(3, dtype=np.int64), P.delta_theta)  # fmt: skip
    assert out.tolist() == [-1, -1, -1]


def test_goal_blocking_uses_the_corridor_towards_the_gamma_agent():
    rel = np.array([[3.0, 0.5], [3.0, 1.5], [12.0, 0.0], [-2.0, 0.0], [2.0, -0.9]])
    owner = np.zeros(len(rel), dtype=np.int64)
    blocked, anchor = goal_blocking(rel, owner, 1, np.array([[10.0, 0.0]]), 1.0, 6.0)
    assert blocked[0] and anchor[0] == 4  # nearest point within 1 m of the ray, ahead
    blocked, _ = goal_blocking(rel[[1, 2, 3]], owner[:3], 1, np.array([[10.0, 0.0]]), 1.0, 6.0)
    assert not blocked[0]  # beside the corridor, beyond the goal and r, behind


def _wall_x3():
    """A wall across the way at x = 3 from y = -2 to y = +4 (agent at 0, goal at (10, 0))."""
    return sample_segment(np.array([3.0, -2.0]), np.array([3.0, 4.0]), 0.25)


@pytest.mark.parametrize(
    ("direction", "expected"),
    [("ccw", (3.0, 4.0)), ("cw", (3.0, -2.0)), ("nearest", (3.0, -2.0)), ("auto", (3.0, -2.0))],
)
def test_split_point_expected_position_clockwise_vs_counterclockwise(direction, expected):
    law = BoundaryPointController(P.with_(direction=direction))
    law.compute(_obs([[0.0, 0.0]], points=_wall_x3()))
    t = law.last_terms
    assert t.scenario[0] == A1 and t.blocked[0]
    np.testing.assert_allclose(t.q_hat[0], expected)
    assert t.mode[0] == (CCW if expected[1] > 0 else CW)
    # the expected velocity points at q_hat: p_hat = (q_hat - q) / dt
    assert np.dot(t.beta_consensus[0], np.asarray(expected)) > 0


def test_a4_expected_position_is_the_gamma_agent():
    law = BoundaryPointController()
    law.compute(_obs([[0.0, 0.0]], points=[[2.0, 3.0], [2.5, 3.0]]))  # sensed, not blocking
    t = law.last_terms
    assert t.scenario[0] == A4 and not t.blocked[0]
    np.testing.assert_allclose(t.q_hat[0], [10.0, 0.0])
    assert law.memory == {}


def test_moving_boundary_points_add_their_velocity_to_the_expected_velocity():
    pts = _wall_x3()
    a, b = BoundaryPointController(), BoundaryPointController()
    ua = a.compute(_obs([[0.0, 0.0]], points=pts))
    ub = b.compute(_obs([[0.0, 0.0]], points=pts, vel=np.tile([2.0, 0.0], (len(pts), 1))))
    b_sum = np.sum(adjacency(sigma_norm(pts - 0.0, P.epsilon), a.r_alpha, P.h)[
        np.linalg.norm(pts, axis=1) < P.r])  # fmt: skip
    np.testing.assert_allclose(ub - ua, [[P.c2_beta * b_sum * 2.0, 0.0]], rtol=1e-9)


# ------------------------------------------------------------------------ split / rejoin memory
def test_split_and_rejoin_memory_is_kept_per_vehicle_id_as_vehicles_enter_and_leave():
    law = BoundaryPointController(P.with_(direction="ccw"))
    wall = _wall_x3()
    # step 1: 'a' is blocked by the wall (split point), 'b' is far away
    law.compute(_obs([[0.0, 0.0], [0.0, 30.0]], points=wall, ids=["a", "b"]))
    assert law.last_terms.scenario.tolist() == [A1, NONE]
    assert set(law.memory) == {"a"}
    np.testing.assert_allclose(law.memory["a"].split, [0.0, 0.0])
    assert law.memory["a"].mode == CCW
    # step 2: 'b' left, 'c' entered, rows reordered; 'a' moved away from the goal
    law.compute(_obs([[0.0, -40.0], [-0.5, 1.0]], points=wall, ids=["c", "a"]))
    t = law.last_terms
    assert t.scenario.tolist() == [NONE, A2]  # 'a' between its split and rejoin points
    assert set(law.memory) == {"a"}
    np.testing.assert_allclose(law.memory["a"].split, [0.0, 0.0])  # kept, not reset
    assert law.memory["a"].steps == 1
    # same ids again (fast path): still A2, the reference direction is the split point
    law.compute(_obs([[0.0, -40.0], [-0.6, 1.5]], points=wall, ids=["c", "a"]))
    assert law.last_terms.scenario[1] == A2 and law.memory["a"].steps == 2
    # step 4: 'a' nearer the goal than its split point and out of the corridor: rejoined
    law.compute(_obs([[4.5, 5.0], [0.0, -40.0]], points=wall, ids=["a", "c"]))
    assert law.last_terms.scenario[0] == A4
    assert law.memory == {}


def test_rejoin_point_still_blocked_is_a_new_split_point_with_the_same_sense():
    law = BoundaryPointController(P.with_(direction="cw"))
    wall = _wall_x3()
    law.compute(_obs([[0.0, 0.0]], points=wall, ids=[7]))
    law.compute(_obs([[0.4, 0.0]], points=wall, ids=[7]))  # closer to the goal, still blocked
    t = law.last_terms
    assert t.scenario[0] == A3
    np.testing.assert_allclose(law.memory[7].split, [0.4, 0.0])
    assert law.memory[7].mode == CW and law.memory[7].steps == 0


def test_follow_timeout_gives_up_an_old_split_point():
    prm = P.with_(follow_timeout=0.3)  # three steps of 0.1 s
    law = BoundaryPointController(prm)
    wall = _wall_x3()
    law.compute(_obs([[0.0, 0.0]], points=wall))
    for k in range(1, 4):
        law.compute(_obs([[-0.1 * k, 0.5]], points=wall))  # moving away: A2
        assert law.last_terms.scenario[0] == A2
    law.compute(_obs([[-0.5, 0.5]], points=wall))
    assert law.last_terms.scenario[0] == A3  # timed out while blocked: split again here
    np.testing.assert_allclose(law.memory[0].split, [-0.5, 0.5])
    assert BoundaryPointController(P.with_(follow_timeout=None)).params.follow_timeout is None


def test_neighbours_nearer_the_goal_set_the_sense_at_a_split():
    law = BoundaryPointController(P.with_(direction="auto"))
    wall = _wall_x3()
    # agent 0 splits alone; its nearest-deviation side is cw (towards y = -2)
    law.compute(_obs([[0.0, 0.0]], points=wall, ids=["lead"]))
    assert law.memory["lead"].mode == CW
    law.reset()
    # a neighbour nearer the goal already going round ccw: the newcomer follows it
    law.compute(_obs([[1.0, 2.5]], points=wall, ids=["lead"], goal=(10.0, 0.0)))
    law._mem_mode[:] = CCW  # pretend 'lead' chose ccw
    law.compute(_obs([[1.0, 2.5], [0.0, 0.0]], points=wall, ids=["lead", "new"]))
    assert law.memory["new"].mode == CCW
    law2 = BoundaryPointController(P.with_(direction="nearest"))
    law2.compute(_obs([[1.0, 2.5]], points=wall, ids=["lead"]))
    law2._mem_mode[:] = CCW
    law2.compute(_obs([[1.0, 2.5], [0.0, 0.0]], points=wall, ids=["lead", "new"]))
    assert law2.memory["new"].mode == CW  # no vote with "nearest"


# ------------------------------------------------------------------------ other checks
def test_gamma_term_linear_and_sigma1():
    q = np.array([[3.0, 4.0]])
    lin = BoundaryPointController().gamma_term(_obs(q, goal=(0.0, 0.0)))
    sig = BoundaryPointController(P.with_(gamma_position="sigma1")).gamma_term(
        _obs(q, goal=(0.0, 0.0))
    )
    np.testing.assert_allclose(lin, [[-3.0, -4.0]])
    np.testing.assert_allclose(sig, [[-3.0, -4.0]] / np.sqrt(26.0))


def test_no_gamma_agent_no_expected_velocity_and_no_plane_no_points():
    law = BoundaryPointController()
    u = law.compute(_obs([[0.0, 0.0], [3.0, 0.0]], goal=None, points=_wall_x3()))
    assert np.all(law.last_terms.beta_consensus == 0) and np.all(np.isfinite(u))
    q3 = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    u3 = law.compute(_obs(q3, goal=(5.0, 0.0, 0.0)))  # 3-D without points works
    assert u3.shape == (2, 3)
    with pytest.raises(ValueError, match="m = 2"):
        law.compute(_obs(q3, goal=(5.0, 0.0, 0.0), points=[[1.0, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="boundary_points"):
        law.compute(_obs([[0.0, 0.0]], points=[[1.0, 0.0, 0.0]]))


def test_saturated_controller_limits_the_speed():
    ctrl = BoundaryPointController.saturated()
    assert isinstance(ctrl, ConstrainedController)
    assert isinstance(ctrl.layers[0], SpeedSaturation) and ctrl.layers[0].p_max == 5.0
    obs = _obs([[0.0, 0.0], [1.5, 0.0]], goal=(50.0, 0.0))  # in each other's separation region
    u = ctrl.compute(obs)
    assert np.all(np.linalg.norm(obs.p + u * obs.dt, axis=1) <= 5.0 + 1e-9)
    assert u[0, 0] < 0 < u[1, 0]  # pushed apart


# ------------------------------------------------------------------------ scenes
@pytest.fixture(scope="module")
def exp():
    return _experiment()


def test_two_circle_scene_no_collision_and_min_distance_above_d_min(exp):
    scene = exp.scene_two_circles()
    for seed in (0, 3):
        s, ts, _ = exp.simulate(scene, "proposed", seed, duration=40.0)
        assert s["min_agent_m"] > P.d_min
        assert s["min_point_m"] > P.d_min
        assert s["min_obstacle_m"] > P.d_min
        assert s["n_not_arrived"] == 0 and s["t_conv_s"] < 40.0


def test_trap_scene_olfati_saber_stalls_while_the_boundary_point_law_passes(exp):
    scene = exp.scene_two_circles()
    notch = np.mean([o.centre for o in scene.obstacles], axis=0)
    prop, _, _ = exp.simulate(scene, "proposed", 0, duration=40.0)
    assert prop["n_not_arrived"] == 0 and prop["converged"]
    s, ts, tr = exp.simulate(scene, "os", 0, duration=150.0, record=10)
    assert s["n_not_arrived"] >= 2 and not s["converged"]
    final = tr[-1]
    stuck = np.linalg.norm(final - np.asarray(scene.goal), axis=1) > scene.arrive_radius
    # the stalled agents sit in front of the notch and no longer move (trajectory every 1 s)
    assert np.all(np.linalg.norm(final[stuck] - notch, axis=1) < 12.0)
    assert np.linalg.norm(final[stuck] - tr[-21][stuck], axis=1).max() < 0.2
    assert s["min_obstacle_m"] > P.d_min  # the baseline (obstacle gains 10) is collision-free
