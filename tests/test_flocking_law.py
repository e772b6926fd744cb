"""The flocking law (controllers/plane/olfati_saber.py): alpha, beta, wall and gamma terms.

Numbers refer to the default parameters (seed 000 CONSTANTS.m): d = 6 m, r = 7.2 m,
eps = 0.1, a = b = 5, h_alpha = 0.2, h_beta = 0.9, d' = 12 m, d'' = 3 m,
d_vehicle = 3 m, c1_alpha = 50, c1_beta = 100, c1_wall = 150.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from controllers.errors import ParameterError
from controllers.observation import Circles, InvalidStateError, Observation, Walls
from controllers.plane.energy import flock_energy
from controllers.plane.olfati_saber import OlfatiSaberController
from controllers.plane.params import FlockingParams
from controllers.plane.references import VirtualLeader
from cosim.plane.world import PlaneWorld

NO_GAMMA = {"c1_gamma": 0.0, "c2_gamma": 0.0}


def sig(x: float, eps: float = 0.1) -> float:
    """Sigma-norm of a scalar length, by hand."""
    return (math.sqrt(1.0 + eps * x * x) - 1.0) / eps


def s1(x: float) -> float:
    return x / math.sqrt(1.0 + x * x)


def random_flock(seed: int, n: int = 12, box: float = 20.0, m: int = 2):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, box, (n, m)), rng.uniform(-3.0, 3.0, (n, m))


def full_observation(q, p, ids=None) -> Observation:
    """An observation that exercises every term: leader, circle, walls, edges, vehicles."""
    return Observation(
        q=q,
        p=p,
        ids=ids,
        length=4.5,
        width=2.0,
        leader_q=np.array([30.0, 10.0]),
        leader_p=np.array([10.0, 0.0]),
        circles=Circles([[25.0, 10.0]], [4.0]),
        walls=Walls([[0.0, -1.0]], [[0.0, 1.0]]),
        road_edges=np.array([-2.0, 22.0]),
        others_q=np.array([[10.0, 5.0], [18.0, 15.0]]),
        others_p=np.array([[8.0, 0.0], [12.0, 0.5]]),
        others_length=np.array([4.5, 12.0]),
        others_width=np.array([2.0, 2.5]),
    )


# ---------------------------------------------------------------- alpha term
def test_two_agent_alpha_force_matches_hand_value_and_is_equal_and_opposite():
    # Agents 4 m apart at rest: z_sigma = sig(4) = 6.12 < d_alpha = sig(6) = 11.45: repulsion.
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    u = law.compute(Observation(q=[[0.0, 0.0], [4.0, 0.0]], p=np.zeros((2, 2))))
    z, d_a, r_a = sig(4.0), sig(6.0), sig(7.2)
    x = (z / r_a - 0.2) / 0.8  # z / r_alpha = 0.41 lies on the bump (h = 0.2)
    rho = 0.5 * (1.0 + math.cos(math.pi * x))
    phi = 5.0 * s1(z - d_a)  # a = b = 5: phi = 5 sigma_1
    n_01 = 4.0 / math.sqrt(1.0 + 0.1 * 16.0)
    expected = 50.0 * rho * phi * n_01  # about -270 m/s^2 on agent 0 (pushed to -x)
    assert u[0, 0] == pytest.approx(expected, rel=1e-12)
    assert expected < -100.0
    np.testing.assert_allclose(u[1], -u[0], rtol=0, atol=1e-12)
    assert u[0, 1] == 0.0


def test_agents_at_the_lattice_spacing_and_equal_velocity_feel_no_alpha_force():
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    u = law.compute(Observation(q=[[0.0, 0.0], [6.0, 0.0]], p=[[3.0, 1.0], [3.0, 1.0]]))
    np.testing.assert_allclose(u, 0.0, atol=1e-12)


def test_agents_beyond_the_interaction_range_feel_nothing():
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    u = law.compute(Observation(q=[[0.0, 0.0], [7.3, 0.0]], p=[[5.0, 0.0], [-5.0, 0.0]]))
    np.testing.assert_array_equal(u, 0.0)
    assert law.last_terms.n_pairs == 0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_alpha_terms_are_antisymmetric_so_the_total_flock_force_is_zero(seed):
    q, p = random_flock(seed)
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    u = law.compute(Observation(q=q, p=p))
    assert law.last_terms.n_pairs > 5
    assert np.abs(u).max() > 1.0  # the forces are not trivially zero
    np.testing.assert_allclose(u.sum(axis=0), 0.0, atol=1e-10 * np.abs(u).max())


@pytest.mark.parametrize("seed", [0, 5])
def test_permuting_agents_permutes_u_with_every_term_active(seed):
    q, p = random_flock(seed)
    ids = np.arange(100, 100 + len(q))
    law = OlfatiSaberController(FlockingParams())
    u = law.compute(full_observation(q, p, ids))
    terms = law.last_terms
    assert np.abs(terms.beta).max() > 0 and np.abs(terms.wall).max() > 0
    perm = np.random.default_rng(seed + 10).permutation(len(q))
    u_perm = law.compute(full_observation(q[perm], p[perm], ids[perm]))
    np.testing.assert_allclose(u_perm, u[perm], rtol=1e-12, atol=1e-9)


# ---------------------------------------------------------------- anisotropic spacing
@pytest.mark.parametrize("seed", [0, 3])
def test_anisotropic_law_with_equal_spacings_equals_isotropic_law_exactly(seed):
    q, p = random_flock(seed)
    iso = OlfatiSaberController(FlockingParams())
    aniso_params = FlockingParams(d_long=6.0, d_lat=6.0)
    assert not aniso_params.is_anisotropic
    aniso = OlfatiSaberController(aniso_params)
    u_iso = iso.compute(full_observation(q, p))
    u_aniso = aniso.compute(full_observation(q, p))
    assert np.abs(u_iso).max() > 1.0
    np.testing.assert_array_equal(u_aniso, u_iso)


def test_anisotropic_pairs_settle_at_d_long_along_and_d_lat_across_the_road():
    # d_long = 10 m, d_lat = 4 m. Two independent pairs (100 m apart), both starting slightly
    # stretched (scaled distance 6.6 m, inside r = 7.2 m), no gamma term.
    prm = FlockingParams(d=6.0, r=7.2, d_long=10.0, d_lat=4.0, **NO_GAMMA)
    q0 = np.array([[0.0, 0.0], [11.0, 0.0], [100.0, 0.0], [100.0, 4.4]])
    world = PlaneWorld(
        q0,
        np.zeros((4, 2)),
        OlfatiSaberController(prm),
        0.01,
        integrator="semi_implicit",
        record_every=0,
        metrics_every=10**9,
    )
    world.run(6.0)
    gap_long = world.q[1] - world.q[0]
    gap_lat = world.q[3] - world.q[2]
    assert gap_long[0] == pytest.approx(10.0, abs=1e-3)
    assert gap_lat[1] == pytest.approx(4.0, abs=1e-3)
    assert abs(gap_long[1]) < 1e-9 and abs(gap_lat[0]) < 1e-9
    assert gap_long[0] > gap_lat[1]
    assert np.abs(world.p).max() < 1e-3  # at rest


def test_anisotropic_force_is_the_gradient_of_the_scaled_potential():
    # U(q) = c1 psi_alpha(||S (q1 - q0)||_sigma); u_0 = -dU/dq_0 by finite differences.
    from controllers.plane.potentials import psi_alpha, sigma_norm

    prm = FlockingParams(d_long=10.0, d_lat=4.0, **NO_GAMMA)
    law = OlfatiSaberController(prm)
    s = prm.scale(2)
    q = np.array([[0.0, 0.0], [7.0, 1.5]])

    def potential(q0):
        z = sigma_norm((q[1] - q0) * s, prm.epsilon)
        return prm.c1_alpha * psi_alpha(z, law.r_alpha, law.d_alpha, prm.h_alpha, prm.a, prm.b)

    u = law.compute(Observation(q=q, p=np.zeros((2, 2))))
    step = 1e-6
    grad = [
        (potential(q[0] + step * e) - potential(q[0] - step * e)) / (2 * step) for e in np.eye(2)
    ]
    np.testing.assert_allclose(u[0], -np.array(grad), rtol=1e-6)


# ---------------------------------------------------------------- energy and Theorem 1
def test_energy_never_increases_with_static_leader_and_theorem1_bound_holds():
    """Seed 003 Theorem 1 (i): H is non-increasing, so ||q_i - q_r|| <= sqrt(2 H0 / c1_gamma).

    Semi-implicit Euler, dt = 4 ms. The law dissipates c2 * sum a_ij ||p_j - p_i||^2 and
    c2_gamma ||p_i||^2 per unit time; at this dt the dissipation per step (>= 4e-6 m^2/s^2
    in this run) exceeds the O(dt^2) energy error of the symplectic step, so H must fall at
    every step up to rounding. Tolerance per step: 1e-9 H0 (about 2.5e-6 m^2/s^2, a
    sum of ~20 terms of size <= H0 in double precision is exact to ~1e-13 H0).
    """
    rng = np.random.default_rng(0)
    n = 6
    q0 = rng.uniform(-8.0, 8.0, (n, 2))
    p0 = rng.uniform(-3.0, 3.0, (n, 2))
    c1_gamma = 1.0
    law = OlfatiSaberController(FlockingParams(c1_gamma=c1_gamma, c2_gamma=1.0))
    origin = np.zeros(2)
    h0 = flock_energy(law, q0, p0, origin, origin)
    energies, leader_dist = [h0], [float(np.linalg.norm(q0, axis=1).max())]

    def record(world):
        energies.append(flock_energy(law, world.q, world.p, origin, origin))
        leader_dist.append(float(np.linalg.norm(world.q, axis=1).max()))

    world = PlaneWorld(
        q0,
        p0,
        law,
        0.004,
        reference=VirtualLeader(q=origin, p=origin),
        integrator="semi_implicit",
        record_every=0,
        metrics_every=10**9,
        on_step=record,
    )
    world.run(5.0)
    energies = np.array(energies)
    assert len(energies) == 1251
    assert np.max(np.diff(energies)) <= 1e-9 * h0
    assert energies.max() <= h0 * (1.0 + 1e-12)
    assert energies[-1] < 0.2 * energies[0]  # the damping actually removes energy
    bound = math.sqrt(2.0 * h0 / c1_gamma)
    assert max(leader_dist) <= bound
    # and the state stays where it started: the leader is static
    np.testing.assert_array_equal(world.reference.q, origin)


def test_energy_of_a_perfect_pair_at_the_leader_is_the_far_pair_free_zero():
    # Two agents 6 m apart (psi_alpha(d_alpha) = 0) with the leader at their midpoint and
    # matched velocities: H = c1_gamma * 2 * 3^2 / 2 = 9 for c1_gamma = 1.
    law = OlfatiSaberController(FlockingParams(c1_gamma=1.0, c2_gamma=1.0))
    q = np.array([[-3.0, 0.0], [3.0, 0.0]])
    p = np.array([[2.0, 0.0], [2.0, 0.0]])
    h = flock_energy(law, q, p, np.zeros(2), np.array([2.0, 0.0]))
    assert h == pytest.approx(9.0, abs=1e-9)


# ---------------------------------------------------------------- beta terms: circles
def test_agent_approaching_a_circular_obstacle_is_pushed_away_from_the_centre():
    # Obstacle R = 10 m at (15, 0); agent at the origin, gap 5 m < d' = 12 m.
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    circles = Circles([[15.0, 0.0]], [10.0])
    law.compute(Observation(q=[[0.0, 0.0]], p=[[0.0, 0.0]], circles=circles))
    beta = law.last_terms.beta[0]
    # Hand value: q_hat - q = (1 - R/15)(15, 0) = (5, 0); z = sig(5) = 8.71 < h d_beta.
    # The gap is floored at the repulsion's peak for d' = 12 m (saturated barrier).
    g = max(5.0, peak_gap(12.0))
    expected = -beta_push(g, d=12.0, c1=100.0)
    assert beta[0] == pytest.approx(expected, rel=1e-5)
    assert beta[0] < -500.0
    assert beta[1] == 0.0


@pytest.mark.parametrize("angle_deg", [0, 45, 100, 200, 300])
def test_circle_force_points_radially_away_for_agents_all_around(angle_deg):
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    centre = np.array([40.0, -3.0])
    direction = np.array([math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))])
    q = centre + 14.0 * direction  # gap 4 m to the R = 10 m surface
    p = -2.0 * direction  # moving towards the obstacle
    law.compute(Observation(q=[q], p=[p], circles=Circles([centre], [10.0])))
    beta = law.last_terms.beta[0]
    assert beta @ direction > 100.0
    cross = beta[0] * direction[1] - beta[1] * direction[0]
    assert abs(cross) < 1e-9 * np.linalg.norm(beta)


def test_circle_far_beyond_its_range_has_no_effect():
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    law.compute(Observation(q=[[0.0, 0.0]], p=[[5.0, 0.0]], circles=Circles([[40.0, 0.0]], [10.0])))
    np.testing.assert_array_equal(law.last_terms.beta, 0.0)


@pytest.mark.parametrize("dist", [9.5, 8.0])
def test_agent_inside_a_circular_obstacle_is_pushed_out(dist):
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    law.compute(Observation(q=[[dist, 0.0]], p=[[0.0, 0.0]], circles=Circles([[0.0, 0.0]], [10.0])))
    assert law.last_terms.beta[0, 0] > 0.0


# ---------------------------------------------------------------- walls and road edges
@pytest.mark.parametrize("y", [-24.5, -23.0, -22.5])
def test_wall_pushes_agents_near_it_inward(y):
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    walls = Walls([[0.0, -25.0], [0.0, 25.0]], [[0.0, 1.0], [0.0, -1.0]])
    law.compute(Observation(q=[[0.0, y]], p=[[10.0, 0.0]], walls=walls))
    wall = law.last_terms.wall[0]
    assert wall[1] > 50.0
    assert wall[0] == pytest.approx(0.0, abs=1e-12)  # tangential motion is not damped


def wall_push(
    gap: float, normal_speed: float = 0.0, edges: bool = False, floor: str | float = "peak"
) -> float:
    """Inward wall/edge acceleration (m/s^2) on a point agent ``gap`` m inside a wall at y = 0."""
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA, barrier_floor=floor))
    q, p = [[0.0, gap]], [[0.0, -normal_speed]]
    if edges:
        obs = Observation(q=q, p=p, road_edges=[0.0, 100.0])
    else:
        obs = Observation(q=q, p=p, walls=Walls([[0.0, 0.0]], [[0.0, 1.0]]))
    law.compute(obs)
    return float(law.last_terms.wall[0, 1])


def peak_gap(d: float = 3.0) -> float:
    """Gap (m) where the hand-value repulsion peaks: the floor of the saturated barrier."""
    from scipy.optimize import minimize_scalar

    res = minimize_scalar(lambda g: -beta_push(g, d), bounds=(1e-6, d), method="bounded",
                          options={"xatol": 1e-10})
    return float(res.x)


def beta_push(gap: float, d: float = 3.0, c1: float = 150.0) -> float:
    """Hand value of the OS06 beta repulsion c1 |phi_beta(sig(g))| |n_hat(g)| on the plateau."""
    return c1 * (1.0 - s1(sig(gap) - sig(d))) * gap / math.sqrt(1.0 + 0.1 * gap * gap)


PEAK = peak_gap(3.0)  # about 2.4 m for eps = 0.1, d = 3 m, h = 0.9


@pytest.mark.parametrize("edges", [False, True])
@pytest.mark.parametrize("gap", [1.5, 1.0, 0.0, -0.5, -2.0, -10.0])
def test_wall_and_road_edge_push_inward_also_at_or_beyond_the_edge(gap, edges):
    # Saturated barrier: gaps below the repulsion peak (~2.4 m) count as the peak gap, so an agent
    # in contact with or past the edge is pushed in with the peak value (about 509 m/s^2).
    push = wall_push(gap, edges=edges)
    assert push == pytest.approx(beta_push(PEAK), rel=1e-5)
    assert push > 500.0


@pytest.mark.parametrize("edges", [False, True])
def test_wall_and_road_edge_damp_outward_velocity_of_an_agent_beyond_the_edge(edges):
    # Beyond the edge b_ik = 1: the normal velocity is damped with c2'' = 2 sqrt(150) = 24.5 1/s.
    push = wall_push(-1.0, normal_speed=5.0, edges=edges)
    assert push == pytest.approx(beta_push(PEAK) + 2.0 * math.sqrt(150.0) * 5.0, rel=1e-5)


@pytest.mark.parametrize("gap", [2.5, 2.8])
def test_wall_push_inside_d_wall_matches_hand_value(gap):
    assert wall_push(gap) == pytest.approx(beta_push(gap), rel=1e-12)


def test_wall_push_is_zero_beyond_d_wall_and_strong_inside_it():
    assert wall_push(3.5) == 0.0
    assert wall_push(3.0) == 0.0
    assert wall_push(2.5) > 400.0
    assert wall_push(1.0) > 200.0


@pytest.mark.parametrize("edges", [False, True])
def test_push_beyond_the_edge_is_at_least_the_push_one_metre_inside(edges):
    assert wall_push(-0.5, edges=edges) >= wall_push(1.0, edges=edges)


@pytest.mark.parametrize("edges", [False, True])
def test_wall_push_never_weakens_as_the_agent_gets_closer(edges):
    gaps = np.linspace(3.0, -1.0, 81)
    push = np.array([wall_push(g, edges=edges) for g in gaps])
    assert np.all(np.diff(push) >= -1e-9)


def test_wall_damps_the_velocity_towards_it():
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    walls = Walls([[0.0, 25.0]], [[0.0, -1.0]])
    law.compute(Observation(q=[[0.0, 23.0]], p=[[0.0, 0.0]], walls=walls))
    at_rest = law.last_terms.wall[0, 1]
    law.compute(Observation(q=[[0.0, 23.0]], p=[[0.0, 5.0]], walls=walls))
    approaching = law.last_terms.wall[0, 1]
    assert approaching < at_rest < 0.0
    # Far from the wall (gap 10 m > r'' = 3.6 m): nothing.
    law.compute(Observation(q=[[0.0, 15.0]], p=[[0.0, 3.0]], walls=walls))
    np.testing.assert_array_equal(law.last_terms.wall, 0.0)


@pytest.mark.parametrize(("y", "sign"), [(24.0, -1.0), (23.0, -1.0), (-24.0, 1.0), (-22.5, 1.0)])
def test_road_edges_push_inward(y, sign):
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    law.compute(Observation(q=[[5.0, y]], p=[[10.0, 0.0]], road_edges=[-25.0, 25.0]))
    wall = law.last_terms.wall[0]
    assert sign * wall[1] > 50.0
    assert wall[0] == pytest.approx(0.0, abs=1e-12)


def test_road_edge_gap_is_measured_from_the_vehicle_side():
    # Centre 3.5 m from the left edge: a point feels nothing (3.5 > d'' = 3), a 2 m wide car
    # (side 2.5 m from the edge) is pushed right.
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    obs = {"q": [[0.0, 21.5]], "p": [[10.0, 0.0]], "road_edges": [-25.0, 25.0]}
    law.compute(Observation(**obs))
    assert law.last_terms.wall[0, 1] == 0.0
    law.compute(Observation(**obs, width=2.0, length=4.5))
    assert law.last_terms.wall[0, 1] < -10.0


# ---------------------------------------------------------------- sensed vehicles
def vehicle_obs(agent_x: float, agent_y: float = 0.0, own_length=4.5, own_width=2.0):
    return Observation(
        q=[[agent_x, agent_y]],
        p=[[10.0, 0.0]],
        length=own_length,
        width=own_width,
        others_q=[[0.0, 0.0]],
        others_p=[[10.0, 0.0]],
        others_length=[4.5],
        others_width=[2.0],
    )


def test_vehicle_two_metres_behind_a_car_is_repelled_bumper_to_bumper():
    # Both 4.5 m long: centres 6.5 m apart, bumpers 2 m apart (< d_vehicle = 3 m).
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    law.compute(vehicle_obs(-6.5))
    beta = law.last_terms.beta[0]
    # 2 m is below the barrier's floor (the repulsion peak near 2.4 m): counts as the peak.
    assert beta[0] == pytest.approx(-beta_push(max(2.0, PEAK), d=3.0, c1=100.0), rel=1e-5)
    assert beta[0] < -300.0
    assert beta[1] == pytest.approx(0.0, abs=1e-12)


def test_point_agent_two_metres_behind_the_rear_bumper_is_repelled():
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    law.compute(vehicle_obs(-(2.25 + 2.0), own_length=None, own_width=None))
    assert law.last_terms.beta[0, 0] < -300.0


def test_vehicle_forty_metres_behind_feels_no_repulsion():
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    law.compute(vehicle_obs(-(4.5 + 40.0)))
    np.testing.assert_array_equal(law.last_terms.beta, 0.0)


def test_vehicle_alongside_with_small_lateral_gap_is_pushed_sideways():
    # Lateral centre distance 3.5 m, both 2 m wide, overlapping longitudinally: side gap 1.5 m.
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    law.compute(vehicle_obs(1.0, 3.5))
    beta = law.last_terms.beta[0]
    # A 1.5 m side gap is below the barrier's floor: it counts as the peak gap.
    assert beta[1] == pytest.approx(beta_push(PEAK, d=3.0, c1=100.0), rel=1e-5)
    assert beta[1] > 250.0
    assert beta[0] == pytest.approx(0.0, abs=1e-12)


def test_overlapping_vehicle_is_pushed_out_through_the_face_of_least_penetration():
    # Centres 4 m apart, lengths 4.5 m: 0.5 m longitudinal overlap, 1.8 m lateral overlap.
    # Saturated barrier: the gap counts as the repulsion peak's gap (about 2.4 m).
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    law.compute(vehicle_obs(-4.0, 0.2))
    beta = law.last_terms.beta[0]
    assert beta[0] == pytest.approx(-beta_push(PEAK, d=3.0, c1=100.0), rel=1e-5)  # -263 m/s^2
    assert beta[1] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("gap", [1.0, 0.2])
def test_vehicle_closer_than_the_repulsion_peak_gets_the_saturated_push(gap):
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    law.compute(vehicle_obs(-(4.5 + gap)))
    assert law.last_terms.beta[0, 0] == pytest.approx(-beta_push(PEAK, d=3.0, c1=100.0), rel=1e-5)


def test_vehicle_damping_matches_the_sensed_vehicle_velocity():
    # 2 m behind and 5 m/s faster than the car ahead: the velocity term brakes by c2_beta * 5.
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA))
    obs = vehicle_obs(-6.5)
    law.compute(obs)
    same_speed = law.last_terms.beta[0, 0]
    law.compute(dataclasses.replace(obs, p=np.array([[15.0, 0.0]])))
    assert law.last_terms.beta[0, 0] == pytest.approx(same_speed - 20.0 * 5.0, rel=1e-12)


# ---------------------------------------------------------------- barrier floor
def test_default_barrier_floor_is_the_repulsion_peak():
    assert FlockingParams().barrier_floor == "peak"
    law = OlfatiSaberController(FlockingParams())
    assert law.wall_floor == pytest.approx(PEAK, abs=2e-3)  # 2.39 m of d'' = 3 m
    assert law.circle_floor == pytest.approx(peak_gap(12.0), abs=1e-2)  # 10.19 m of d' = 12 m


@pytest.mark.parametrize("edges", [False, True])
@pytest.mark.parametrize("gap", [2.8, 2.0, 1.0, 0.3])
def test_without_floor_the_wall_push_is_the_paper_law_at_every_gap(gap, edges):
    # The paper's c1'' |phi_beta| |n_hat|, also below the repulsion peak where "peak" floors it.
    push = wall_push(gap, edges=edges, floor="none")
    assert push == pytest.approx(beta_push(gap), rel=1e-12)
    if gap < PEAK:
        assert push < wall_push(gap, edges=edges) - 10.0


@pytest.mark.parametrize("edges", [False, True])
def test_without_floor_the_paper_law_vanishes_at_contact_and_pushes_out_past_the_edge(edges):
    assert wall_push(0.0, edges=edges, floor="none") == 0.0
    # Past the edge the beta-agent lies on the other side: the paper's term pushes outward.
    for gap in (-0.5, -1.0):
        push = wall_push(gap, edges=edges, floor="none")
        assert push == pytest.approx(-beta_push(-gap), rel=1e-12)
        assert push < 0.0


@pytest.mark.parametrize("edges", [False, True])
def test_numeric_floor_counts_smaller_gaps_as_the_floor(edges):
    assert wall_push(0.5, edges=edges, floor=1.0) == pytest.approx(beta_push(1.0), rel=1e-12)
    assert wall_push(-2.0, edges=edges, floor=1.0) == pytest.approx(beta_push(1.0), rel=1e-12)
    assert wall_push(2.0, edges=edges, floor=1.0) == pytest.approx(beta_push(2.0), rel=1e-12)


def test_without_floor_the_circle_push_is_the_paper_law():
    # Gap 5 m to the R = 10 m surface: below the 10.19 m floor of "peak", so the two differ.
    circles = Circles([[15.0, 0.0]], [10.0])
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA, barrier_floor="none"))
    law.compute(Observation(q=[[0.0, 0.0]], p=[[0.0, 0.0]], circles=circles))
    beta = law.last_terms.beta[0]
    assert beta[0] == pytest.approx(-beta_push(5.0, d=12.0, c1=100.0), rel=1e-12)
    assert beta[0] > -beta_push(peak_gap(12.0), d=12.0, c1=100.0) + 10.0
    # Inside the circle the paper's beta-agent lies outward: the term pulls towards the centre.
    law.compute(Observation(q=[[9.0, 0.0]], p=[[0.0, 0.0]], circles=Circles([[0.0, 0.0]], [10.0])))
    assert law.last_terms.beta[0, 0] == pytest.approx(-beta_push(1.0, d=12.0, c1=100.0), rel=1e-12)


def test_without_floor_the_vehicle_push_is_the_paper_law():
    law = OlfatiSaberController(FlockingParams(**NO_GAMMA, barrier_floor="none"))
    law.compute(vehicle_obs(-6.5))  # bumpers 2 m apart
    assert law.last_terms.beta[0, 0] == pytest.approx(-beta_push(2.0, d=3.0, c1=100.0), rel=1e-12)


@pytest.mark.parametrize("value", ["peak", "none", 2.5, 1, np.float64(0.5)])
def test_barrier_floor_accepts_peak_none_and_positive_gaps(value):
    got = FlockingParams(barrier_floor=value).barrier_floor
    assert got == value
    assert isinstance(got, str) or type(got) is float


@pytest.mark.parametrize(
    "value", [float("nan"), float("inf"), -float("inf"), 0.0, -1.0, "Peak", "off", True, None, []]
)
def test_barrier_floor_rejects_anything_else_with_one_parameter_error(value):
    with pytest.raises(ParameterError, match=r"^barrier_floor must be 'peak', 'none' or a finite"):
        FlockingParams(barrier_floor=value)


# ---------------------------------------------------------------- gamma and dynamic weights
def test_gamma_term_is_linear_feedback_to_the_leader_hand_value():
    prm = FlockingParams(c1_gamma=(5.0, 2.0), c2_gamma=(1.0, 3.0))
    law = OlfatiSaberController(prm)
    law.compute(
        Observation(q=[[0.0, 0.0]], p=[[1.0, 1.0]], leader_q=[10.0, -2.0], leader_p=[3.0, 0.0])
    )
    # -c1 (q - q_r) - c2 (p - p_r) = (-5 * -10 - 1 * -2, -2 * 2 - 3 * 1) = (52, -7)
    np.testing.assert_allclose(law.last_terms.gamma[0], [52.0, -7.0])


def test_sigma1_gamma_position_term_is_bounded_by_c1():
    law = OlfatiSaberController(FlockingParams(c1_gamma=5.0, c2_gamma=0.0, gamma_position="sigma1"))
    law.compute(Observation(q=[[0.0, 0.0]], p=[[0.0, 0.0]], leader_q=[3000.0, 4000.0]))
    gamma = law.last_terms.gamma[0]
    assert np.linalg.norm(gamma) < 5.0
    assert np.linalg.norm(gamma) > 4.99
    np.testing.assert_allclose(gamma / np.linalg.norm(gamma), [0.6, 0.8])


def test_dynamic_weights_reduce_gamma_gains_when_beta_is_strongly_negative():
    # Agent 5 m in front of a circle, leader behind the obstacle: u_beta_x ~ -534 m/s^2.
    circles = Circles([[15.0, 0.0]], [10.0])
    obs = Observation(
        q=[[0.0, 0.0]], p=[[1.0, 0.0]], circles=circles, leader_q=[60.0, 0.0], leader_p=[10.0, 0.0]
    )
    plain = OlfatiSaberController(FlockingParams(dynamic_weights=False))
    weighted = OlfatiSaberController(FlockingParams(dynamic_weights=True))
    plain.compute(obs)
    weighted.compute(obs)
    beta = plain.last_terms.beta[0]
    assert beta[0] < -500.0
    g_plain, g_weighted = plain.last_terms.gamma[0], weighted.last_terms.gamma[0]
    assert g_plain[0] > 100.0  # gamma pulls towards the leader, into the obstacle
    # C(c, u) = c (tanh(u) + 1): tanh(-534) + 1 is 0 in double precision.
    assert abs(g_weighted[0]) < 1e-6 * g_plain[0]
    np.testing.assert_allclose(g_weighted, (np.tanh(beta) + 1.0) * g_plain, rtol=1e-12)


def test_dynamic_weights_change_nothing_without_obstacles():
    q, p = random_flock(4)
    obs = Observation(q=q, p=p, leader_q=[30.0, 10.0], leader_p=[10.0, 0.0])
    u_plain = OlfatiSaberController(FlockingParams()).compute(obs)
    u_weighted = OlfatiSaberController(FlockingParams(dynamic_weights=True)).compute(obs)
    np.testing.assert_array_equal(u_weighted, u_plain)


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("changes", "name"),
    [
        ({"h_alpha": 0.0}, "h_alpha"),
        ({"h_alpha": 1.0}, "h_alpha"),
        ({"h_alpha": 1.5}, "h_alpha"),
        ({"h_beta": -0.1}, "h_beta"),
        ({"h_beta": 1.0}, "h_beta"),
        ({"a": 6.0, "b": 5.0}, "a must be <= b"),
        ({"a": 0.0}, "a"),
        ({"b": -1.0}, "b"),
        ({"r": 6.0, "d": 6.0}, "r must be > d"),
        ({"r": 5.0, "d": 6.0}, "r must be > d"),
        ({"d": -1.0}, "d"),
        ({"epsilon": 0.0}, "epsilon"),
        ({"d_long": -3.0}, "d_long"),
        ({"d_lat": 0.0}, "d_lat"),
        ({"d_beta": 12.0, "r_beta": 10.0}, "r_beta"),
        ({"d_wall": 3.0, "r_wall": 2.0}, "r_wall"),
        ({"d_vehicle": 3.0, "r_vehicle": 2.0}, "r_vehicle"),
        ({"c1_alpha": -1.0}, "c1_alpha"),
        ({"c2_alpha": -0.5}, "c2_alpha"),
        ({"c1_beta": -1.0}, "c1_beta"),
        ({"c2_beta": -1.0}, "c2_beta"),
        ({"c1_wall": -1.0}, "c1_wall"),
        ({"c2_wall": -1.0}, "c2_wall"),
        ({"c1_gamma": -1.0}, "c1_gamma"),
        ({"c2_gamma": (1.0, -1.0)}, "c2_gamma"),
        ({"c1_gamma": (1.0, 2.0, 3.0, 4.0)}, "c1_gamma"),
        ({"c1_alpha": float("nan")}, "c1_alpha"),
        ({"d": float("inf"), "r": float("inf")}, "d"),
        ({"gamma_position": "quadratic"}, "gamma_position"),
        ({"neighbour_search": "octree"}, "neighbour_search"),
    ],
)
def test_invalid_parameter_raises_one_clear_error_naming_it(changes, name):
    with pytest.raises(ParameterError, match=name):
        FlockingParams(**changes)
    assert issubclass(ParameterError, ValueError)


def test_per_axis_gamma_gains_of_the_wrong_dimension_raise_at_compute():
    law = OlfatiSaberController(FlockingParams(c1_gamma=(1.0, 2.0)))
    obs = Observation(q=np.zeros((1, 3)), p=np.zeros((1, 3)), leader_q=np.ones(3))
    with pytest.raises(ParameterError, match="c1_gamma"):
        law.compute(obs)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"q": np.zeros((3, 2)), "p": np.zeros((2, 2))}, "p has shape"),
        ({"q": np.zeros(3), "p": np.zeros(3)}, "q must have shape"),
        ({"q": np.zeros((3, 4)), "p": np.zeros((3, 4))}, "dimension m"),
        ({"q": np.zeros((3, 2)), "p": np.zeros((3, 2)), "ids": [1, 2]}, "ids"),
        (
            {"q": np.zeros((3, 2)), "p": np.zeros((3, 2)), "road_edges": np.zeros((2, 2))},
            "road_edges",
        ),
        ({"q": np.zeros((3, 2)), "p": np.zeros((3, 2)), "leader_q": np.zeros(3)}, "leader_q"),
        (
            {"q": np.zeros((3, 2)), "p": np.zeros((3, 2)), "leader_p": np.zeros((2, 2))},
            "leader_p",
        ),
        ({"q": np.zeros((3, 2)), "p": np.zeros((3, 2)), "period_s": -5.0}, "period_s"),
    ],
)
def test_observation_with_mismatched_shapes_raises_value_error_naming_the_field(kwargs, name):
    with pytest.raises(ValueError, match=name):
        Observation(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"others_q": np.zeros((2, 2)), "others_p": np.zeros((3, 2))}, "others_p"),
        ({"length": np.ones(3)}, "length"),
        ({"others_q": np.zeros((2, 2)), "others_width": np.ones(3)}, "others_width"),
        ({"others_q": np.zeros(3)}, "others_q"),
    ],
)
def test_observation_with_mismatched_vehicle_arrays_names_the_field(kwargs, name):
    with pytest.raises(ValueError, match=name):
        Observation(q=np.zeros((2, 2)), p=np.zeros((2, 2)), **kwargs)


@pytest.mark.parametrize(
    ("build", "name"),
    [
        (lambda: Walls([[0.0, 0.0], [0.0, 1.0]], [[0.0, 1.0]]), "normals"),
        (lambda: Walls([[0.0, 0.0]], [[0.0, 0.0]]), "normal"),
        (lambda: Circles([[0.0, 0.0], [5.0, 5.0]], [1.0]), "radii"),
        (lambda: Circles([[0.0, 0.0]], [-1.0]), "radius"),
    ],
)
def test_walls_and_circles_with_bad_shapes_raise_value_error_naming_the_field(build, name):
    with pytest.raises(ValueError, match=name):
        build()


def test_walls_normals_are_normalised():
    walls = Walls([[0.0, 0.0]], [[0.0, 5.0]])
    np.testing.assert_allclose(walls.normals, [[0.0, 1.0]])


@pytest.mark.parametrize(
    ("field", "value"), [("q", np.nan), ("q", np.inf), ("p", -np.inf), ("p", np.nan)]
)
def test_non_finite_state_raises_invalid_state_error_naming_the_agent(field, value):
    q = np.array([[0.0, 0.0], [6.0, 0.0], [12.0, 0.0]])
    p = np.zeros((3, 2))
    {"q": q, "p": p}[field][1, 1] = value
    obs = Observation(q=q, p=p, ids=np.array(["cav_a", "cav_b", "cav_c"]))
    with pytest.raises(InvalidStateError, match="cav_b"):
        OlfatiSaberController().compute(obs)
    assert issubclass(InvalidStateError, ValueError)
