"""Olfati-Saber building blocks (controllers/plane/potentials.py) against hand values.

Hand values use epsilon = 1 or 0.5 where the sigma-norm has a closed form:
``||z||_sigma = (sqrt(1 + eps ||z||^2) - 1) / eps``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.plane.potentials import (
    adjacency,
    n_ij,
    phi,
    phi_alpha,
    phi_beta,
    psi_alpha,
    rho_h,
    sigma_1,
    sigma_1_vec,
    sigma_grad,
    sigma_norm,
    sigma_norm_scalar,
)

# Seed 000 constants: d = 6 m, r = 1.2 d, eps = 0.1, h = 0.2, a = b = 5.
EPS = 0.1
D = 6.0
R = 7.2
R_ALPHA = float(sigma_norm_scalar(R, EPS))
D_ALPHA = float(sigma_norm_scalar(D, EPS))
H = 0.2


# ---------------------------------------------------------------- sigma-norm
@pytest.mark.parametrize(
    ("z", "eps", "expected"),
    [
        ([0.0, 0.0], 0.1, 0.0),
        ([math.sqrt(3.0), 0.0], 1.0, 1.0),  # sqrt(1 + 3) - 1 = 1
        ([2.0, 2.0], 1.0, 2.0),  # sqrt(1 + 8) - 1 = 2
        ([2.0, 1.0, 1.0], 0.5, 2.0),  # (sqrt(1 + 0.5 * 6) - 1) / 0.5 = 2
        ([3.0, 4.0], 0.1, (math.sqrt(3.5) - 1.0) / 0.1),  # ||z|| = 5
    ],
)
def test_sigma_norm_matches_hand_values(z, eps, expected):
    assert sigma_norm(np.array(z), eps) == pytest.approx(expected, rel=1e-12, abs=1e-15)


def test_sigma_norm_of_a_batch_has_one_value_per_row_and_equals_scalar_form():
    z = np.array([[3.0, 4.0], [0.0, 6.0], [0.0, 0.0]])
    out = sigma_norm(z, EPS)
    assert out.shape == (3,)
    np.testing.assert_allclose(out, sigma_norm_scalar(np.array([5.0, 6.0, 0.0]), EPS), rtol=1e-14)


def test_sigma_norm_is_below_euclidean_norm_and_tends_to_half_square_for_small_eps():
    z = np.array([3.0, 4.0])
    # sqrt(1 + eps x^2) - 1 <= x sqrt(eps) gives ||z||_sigma <= ||z|| / sqrt(eps).
    assert sigma_norm(z, EPS) < 5.0 / math.sqrt(EPS)
    # eps -> 0: ||z||_sigma -> ||z||^2 / 2 = 12.5.
    assert sigma_norm(z, 1e-8) == pytest.approx(12.5, rel=1e-6)


def test_sigma_grad_is_the_gradient_of_the_sigma_norm_and_has_hand_value():
    # eps = 1, z = (sqrt 3, 0): z / sqrt(1 + 3) = (sqrt(3)/2, 0).
    np.testing.assert_allclose(
        sigma_grad(np.array([math.sqrt(3.0), 0.0]), 1.0), [math.sqrt(3.0) / 2.0, 0.0]
    )
    rng = np.random.default_rng(3)
    z = rng.normal(size=2) * 5.0
    step = 1e-6
    fd = [
        (sigma_norm(z + step * e, EPS) - sigma_norm(z - step * e, EPS)) / (2 * step)
        for e in np.eye(2)
    ]
    np.testing.assert_allclose(sigma_grad(z, EPS), fd, rtol=1e-7)


def test_n_ij_points_from_i_to_j():
    n = n_ij(np.array([1.0, 1.0]), np.array([1.0 + math.sqrt(3.0), 1.0]), 1.0)
    np.testing.assert_allclose(n, [math.sqrt(3.0) / 2.0, 0.0])


def test_sigma_1_hand_values_and_bound():
    assert sigma_1(np.array(0.0)) == 0.0
    assert sigma_1(np.array(math.sqrt(3.0))) == pytest.approx(math.sqrt(3.0) / 2.0)
    assert sigma_1(np.array(-math.sqrt(3.0))) == pytest.approx(-math.sqrt(3.0) / 2.0)
    big = sigma_1_vec(np.array([[300.0, 400.0]]))
    assert np.linalg.norm(big) < 1.0
    np.testing.assert_allclose(big, [[300.0, 400.0]] / np.sqrt(1.0 + 500.0**2))


# ---------------------------------------------------------------- bump function
@pytest.mark.parametrize("h", [0.2, 0.5, 0.9])
def test_rho_h_is_one_below_h_and_zero_above_one(h):
    below = np.linspace(0.0, h, 50, endpoint=False)
    above = np.linspace(1.0 + 1e-9, 3.0, 50)
    np.testing.assert_array_equal(rho_h(below, h), 1.0)
    np.testing.assert_array_equal(rho_h(above, h), 0.0)
    assert rho_h(np.array(1.0), h) == pytest.approx(0.0, abs=1e-15)
    # Halfway through the cosine fall: 0.5 (1 + cos(pi / 2)) = 0.5.
    assert rho_h(np.array(0.5 * (h + 1.0)), h) == pytest.approx(0.5)


@pytest.mark.parametrize("h", [0.2, 0.9])
def test_rho_h_is_continuous_lipschitz_with_slope_pi_over_two_one_minus_h(h):
    z = np.linspace(0.0, 1.5, 30001)
    jumps = np.abs(np.diff(rho_h(z, h)))
    dz = z[1] - z[0]
    # Max slope of 0.5 (1 + cos(pi x)) with x = (z - h)/(1 - h) is pi / (2 (1 - h)).
    assert jumps.max() <= math.pi / (2.0 * (1.0 - h)) * dz * (1.0 + 1e-9)
    # No jump at the two joints.
    for z0 in (h, 1.0):
        assert abs(rho_h(np.array(z0 + 1e-12), h) - rho_h(np.array(z0 - 1e-12), h)) < 1e-9


def test_rho_h_is_zero_for_negative_arguments():
    np.testing.assert_array_equal(rho_h(np.array([-1.0, -1e-12]), 0.2), 0.0)


# ---------------------------------------------------------------- phi and phi_alpha
@pytest.mark.parametrize(("a", "b"), [(5.0, 5.0), (1.0, 5.0), (0.1, 10.0), (3.0, 3.0001)])
def test_phi_is_zero_at_zero_when_a_le_b(a, b):
    assert phi(np.array(0.0), a, b) == pytest.approx(0.0, abs=1e-12)


def test_phi_is_not_zero_at_zero_when_a_gt_b():
    # sigma_1(c) = |a - b| / (a + b), so phi(0) = (|a - b| + (a - b)) / 2 = a - b = 4 for a > b.
    assert phi(np.array(0.0), 5.0, 1.0) == pytest.approx(4.0)


def test_phi_limits_are_plus_a_and_minus_b():
    # sigma_1 -> +-1: phi -> (+-(a + b) + (a - b)) / 2, i.e. a as z -> inf and -b as z -> -inf.
    assert phi(np.array(1e9), 1.0, 5.0) == pytest.approx(1.0, rel=1e-6)
    assert phi(np.array(-1e9), 1.0, 5.0) == pytest.approx(-5.0, rel=1e-6)


def test_phi_alpha_is_zero_at_d_alpha_and_beyond_r_alpha():
    assert phi_alpha(np.array(D_ALPHA), R_ALPHA, D_ALPHA, H, 5.0, 5.0) == pytest.approx(
        0.0, abs=1e-14
    )
    beyond = np.array([R_ALPHA, R_ALPHA * 1.01, 10 * R_ALPHA])
    np.testing.assert_array_equal(phi_alpha(beyond, R_ALPHA, D_ALPHA, H, 5.0, 5.0), 0.0)


def test_phi_alpha_repels_below_d_and_attracts_between_d_and_r():
    z_close = np.array(0.5 * D_ALPHA)
    z_mid = np.array(0.5 * (D_ALPHA + R_ALPHA))
    assert phi_alpha(z_close, R_ALPHA, D_ALPHA, H, 5.0, 5.0) < 0.0
    assert phi_alpha(z_mid, R_ALPHA, D_ALPHA, H, 5.0, 5.0) > 0.0


def test_phi_alpha_on_plateau_is_plain_phi_hand_value():
    # a = b = 5: phi(z) = 5 sigma_1(z). With r_alpha = 100, d_alpha = 1 + sqrt(3) and z = 1
    # (z / r_alpha = 0.01 < h: rho_h = 1): phi(-sqrt(3)) = 5 * (-sqrt(3) / 2).
    z = np.array(1.0)
    assert phi_alpha(z, 100.0, 1.0 + math.sqrt(3.0), H, 5.0, 5.0) == pytest.approx(
        -2.5 * math.sqrt(3.0)
    )


# ---------------------------------------------------------------- psi_alpha
def test_psi_alpha_is_zero_at_d_alpha_and_positive_elsewhere():
    assert psi_alpha(np.array(D_ALPHA), R_ALPHA, D_ALPHA, H, 5.0, 5.0) == pytest.approx(
        0.0, abs=1e-12
    )
    z = np.array([0.0, 0.3 * D_ALPHA, 0.9 * D_ALPHA, 1.1 * D_ALPHA, R_ALPHA, 2 * R_ALPHA])
    assert np.all(psi_alpha(z, R_ALPHA, D_ALPHA, H, 5.0, 5.0) > 0.0)


@pytest.mark.parametrize(("a", "b"), [(5.0, 5.0), (1.0, 4.0)])
@pytest.mark.parametrize("frac", [0.05, 0.15, 0.3, 0.6, 0.95, 1.0, 1.02, 1.1])
def test_derivative_of_psi_alpha_equals_phi_alpha_by_finite_differences(a, b, frac):
    # frac is z / r_alpha: the plateau (< h = 0.2), the bump (h..1) and beyond r.
    # Central differences have error O(step^2 * phi'') ~ 1e-10 here; quadrature is ~1e-13.
    z = frac * R_ALPHA
    step = 1e-5
    fd = (
        psi_alpha(np.array(z + step), R_ALPHA, D_ALPHA, H, a, b)
        - psi_alpha(np.array(z - step), R_ALPHA, D_ALPHA, H, a, b)
    ) / (2.0 * step)
    exact = phi_alpha(np.array(z), R_ALPHA, D_ALPHA, H, a, b)
    assert fd == pytest.approx(exact, abs=1e-6)


def test_psi_alpha_is_constant_beyond_r_alpha():
    vals = psi_alpha(np.array([R_ALPHA, 1.5 * R_ALPHA, 40.0 * R_ALPHA]), R_ALPHA, D_ALPHA, H, 5, 5)
    np.testing.assert_allclose(vals, vals[0], rtol=1e-14)


def test_psi_alpha_on_plateau_matches_closed_form_antiderivative():
    # a = b = 5: phi(s) = 5 sigma_1(s), integral = 5 sqrt(1 + s^2). psi between two plateau
    # points z1 < z2 is 5 (sqrt(1 + (z2 - d)^2) - sqrt(1 + (z1 - d)^2)).
    z1, z2 = 0.02 * R_ALPHA, 0.1 * R_ALPHA
    diff = psi_alpha(np.array(z2), R_ALPHA, D_ALPHA, H, 5, 5) - psi_alpha(
        np.array(z1), R_ALPHA, D_ALPHA, H, 5, 5
    )
    expected = 5.0 * (math.sqrt(1 + (z2 - D_ALPHA) ** 2) - math.sqrt(1 + (z1 - D_ALPHA) ** 2))
    assert diff == pytest.approx(expected, rel=1e-12)


# ---------------------------------------------------------------- phi_beta and adjacency
def test_phi_beta_is_repulsive_below_d_beta_and_zero_beyond():
    d_beta = float(sigma_norm_scalar(12.0, EPS))
    z = np.array([0.01, 0.5 * d_beta, 0.89 * d_beta, 0.95 * d_beta])
    assert np.all(phi_beta(z, d_beta, 0.9) < 0.0)
    np.testing.assert_array_equal(phi_beta(np.array([d_beta, 2 * d_beta]), d_beta, 0.9), 0.0)
    # Plateau hand value with d_beta = 10, z = 10 - sqrt(3) (z / d_beta = 0.83 < h = 0.9):
    # sigma_1(-sqrt(3)) - 1 = -sqrt(3)/2 - 1.
    assert phi_beta(np.array(10.0 - math.sqrt(3.0)), 10.0, 0.9) == pytest.approx(
        -math.sqrt(3.0) / 2.0 - 1.0
    )


def test_phi_beta_magnitude_grows_as_the_gap_closes():
    d_beta = float(sigma_norm_scalar(12.0, EPS))
    z = np.linspace(0.0, d_beta, 200)
    vals = phi_beta(z, d_beta, 0.9)
    assert np.all(np.diff(vals) >= -1e-15)  # non-decreasing towards 0 at d_beta
    assert vals[0] < -1.9  # close to sigma_1(-d_beta) - 1 = about -2


def test_adjacency_is_one_near_zero_outside_range_and_bounded():
    z = np.linspace(0.0, 2 * R_ALPHA, 500)
    a = adjacency(z, R_ALPHA, H)
    assert np.all((a >= 0.0) & (a <= 1.0))
    assert adjacency(np.array(0.1 * R_ALPHA), R_ALPHA, H) == 1.0
    assert adjacency(np.array(1.01 * R_ALPHA), R_ALPHA, H) == 0.0
