"""Constraint layers (controllers/layers/constraints.py): saturation, acceleration box, jerk."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.errors import ParameterError
from controllers.layers.constraints import (
    AccelerationBox,
    ConstrainedController,
    JerkLimit,
    SpeedSaturation,
)
from controllers.observation import InvalidStateError, Observation
from controllers.plane.olfati_saber import OlfatiSaberController
from controllers.plane.params import FlockingParams
from cosim.plane.world import PlaneWorld

# Rounding slack: p + ((sat - p) / dt) * dt reproduces sat to a few ulps of 10 m/s.
SPEED_TOL = 1e-9


def obs_of(p, dt=0.1, ids=None, q=None):
    p = np.asarray(p, dtype=float)
    q = np.zeros_like(p) if q is None else q
    return Observation(q=q, p=p, dt=dt, ids=ids)


class ConstantLaw:
    """A law that returns a fixed command (N, m)."""

    name = "constant"

    def __init__(self, u):
        self.u = np.asarray(u, dtype=float)

    def compute(self, obs):
        obs.check_finite()
        return np.broadcast_to(self.u, obs.q.shape).copy()


# ---------------------------------------------------------------- speed saturation
def test_speed_saturation_hand_values():
    # p = (8, 0), u = (50, 0), dt = 0.1: next velocity (13, 0) -> (10, 0), so u' = (20, 0).
    # p = (0, 6), u = (80, 0): next (8, 6), speed 10 exactly: unchanged.
    layer = SpeedSaturation(p_max=10.0)
    u = layer.apply(np.array([[50.0, 0.0], [80.0, 0.0]]), obs_of([[8.0, 0.0], [0.0, 6.0]]))
    np.testing.assert_allclose(u, [[20.0, 0.0], [80.0, 0.0]])
    assert (layer.clipped, layer.seen) == (1, 2)
    assert layer.clip_rate == pytest.approx(0.5)


def test_speed_saturation_keeps_the_direction_of_the_next_velocity():
    # p = (0, 0), u = (300, 400), dt = 0.1: next (30, 40) -> 10 * (0.6, 0.8) = (6, 8).
    layer = SpeedSaturation(p_max=10.0)
    u = layer.apply(np.array([[300.0, 400.0]]), obs_of([[0.0, 0.0]]))
    np.testing.assert_allclose(u * 0.1, [[6.0, 8.0]])


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("m", [1, 2, 3])
def test_speed_saturation_never_leaves_a_speed_above_p_max_after_a_step(seed, m):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-100.0, 100.0, (200, m))
    p[:100] *= 0.02  # half of them slow (below 3.5 m/s)
    u = rng.normal(scale=10.0 ** rng.uniform(-1, 4, (200, 1)), size=(200, m))
    dt = float(rng.choice([0.01, 0.1, 0.5]))
    layer = SpeedSaturation(p_max=10.0)
    u_sat = layer.apply(u, obs_of(p, dt=dt))
    speed_after = np.linalg.norm(p + u_sat * dt, axis=1)
    assert speed_after.max() <= 10.0 + SPEED_TOL
    assert layer.clipped > 0
    # Agents whose next speed was already within the limit keep their command (to rounding:
    # the layer recomputes (p + u dt - p) / dt for all rows).
    ok = np.linalg.norm(p + u * dt, axis=1) <= 10.0
    assert ok.any()
    np.testing.assert_allclose(u_sat[ok], u[ok], rtol=1e-9, atol=1e-9)


def test_speed_saturation_in_the_plane_world_caps_every_speed_after_the_first_step():
    rng = np.random.default_rng(2)
    q0 = rng.uniform(0.0, 60.0, (20, 2))
    p0 = rng.uniform(-40.0, 40.0, (20, 2))
    law = ConstrainedController(OlfatiSaberController(), [SpeedSaturation(p_max=10.0)])
    world = PlaneWorld(q0, p0, law, 0.05, record_every=1, metrics_every=1)
    result = world.run(2.0)
    assert result.metrics["max_speed_mps"].iloc[0] > 10.0
    after = result.metrics.loc[result.metrics["step"] >= 1, "max_speed_mps"]
    assert len(after) == 40
    assert after.max() <= 10.0 + SPEED_TOL


# ---------------------------------------------------------------- acceleration box
def test_acceleration_box_clips_to_car_limits_and_counts_clip_rate():
    layer = AccelerationBox()
    u = np.array([[5.0, 0.0], [-10.0, 3.0], [1.0, -0.5], [2.6, -1.5], [0.0, -2.0]])
    out = layer.apply(u, obs_of(np.zeros((5, 2))))
    np.testing.assert_array_equal(
        out, [[2.6, 0.0], [-4.5, 1.5], [1.0, -0.5], [2.6, -1.5], [0.0, -1.5]]
    )
    assert (layer.clipped, layer.seen) == (3, 5)
    assert layer.clip_rate == pytest.approx(0.6)
    # A second call accumulates.
    layer.apply(np.zeros((5, 2)), obs_of(np.zeros((5, 2))))
    assert layer.clip_rate == pytest.approx(0.3)


def test_acceleration_box_bounds_hold_for_random_commands():
    rng = np.random.default_rng(0)
    u = rng.normal(scale=20.0, size=(500, 2))
    out = AccelerationBox().apply(u, obs_of(np.zeros((500, 2))))
    assert out[:, 0].min() >= -4.5 and out[:, 0].max() <= 2.6
    assert np.abs(out[:, 1]).max() <= 1.5
    assert out[:, 0].min() == -4.5 and out[:, 0].max() == 2.6  # limits are reached


def test_acceleration_box_uses_lateral_limit_for_the_third_axis():
    out = AccelerationBox().apply(np.array([[0.0, 0.0, -7.0]]), obs_of(np.zeros((1, 3))))
    np.testing.assert_array_equal(out, [[0.0, 0.0, -1.5]])


def test_acceleration_box_norm_bound_scales_the_vector():
    layer = AccelerationBox(long_min=-100.0, long_max=100.0, lat_max=100.0, a_max=5.0)
    out = layer.apply(np.array([[30.0, 40.0], [3.0, 4.0]]), obs_of(np.zeros((2, 2))))
    np.testing.assert_allclose(out, [[3.0, 4.0], [3.0, 4.0]])
    assert layer.clipped == 1


def test_clip_rate_is_zero_before_any_step():
    assert AccelerationBox().clip_rate == 0.0


# ---------------------------------------------------------------- jerk limit
def test_jerk_limit_passes_the_first_command_and_bounds_the_change_per_step():
    layer = JerkLimit(j_max=5.0)  # 0.5 m/s^2 per 0.1 s step
    obs = obs_of(np.zeros((2, 2)), ids=["a", "b"])
    first = layer.apply(np.array([[2.0, -1.0], [0.0, 0.0]]), obs)
    np.testing.assert_array_equal(first, [[2.0, -1.0], [0.0, 0.0]])
    second = layer.apply(np.array([[-3.0, -1.2], [0.3, 4.0]]), obs)
    np.testing.assert_allclose(second, [[1.5, -1.2], [0.3, 0.5]])
    third = layer.apply(np.array([[-3.0, -1.2], [0.3, 4.0]]), obs)
    np.testing.assert_allclose(third, [[1.0, -1.2], [0.3, 1.0]])
    assert layer.clipped == 4 and layer.seen == 6


@pytest.mark.parametrize("seed", range(3))
def test_jerk_limit_change_per_step_never_exceeds_j_max_dt(seed):
    rng = np.random.default_rng(seed)
    layer = JerkLimit(j_max=3.0)
    obs = obs_of(np.zeros((10, 2)), dt=0.05, ids=np.arange(10))
    prev = layer.apply(rng.normal(size=(10, 2)), obs)
    for _ in range(30):
        out = layer.apply(rng.normal(scale=5.0, size=(10, 2)), obs)
        assert np.abs(out - prev).max() <= 3.0 * 0.05 + 1e-12
        prev = out


def test_jerk_limit_handles_vehicles_entering_leaving_and_reordering():
    layer = JerkLimit(j_max=10.0)  # 1 m/s^2 per 0.1 s step
    layer.apply(np.array([[0.0, 0.0], [2.0, 0.0]]), obs_of(np.zeros((2, 2)), ids=[7, 3]))
    # Vehicle 7 left, 3 moved to the front, 9 entered: 3 is limited from its previous 2.0,
    # 9 gets its command unchanged.
    out = layer.apply(np.array([[-5.0, 0.0], [-5.0, 0.0]]), obs_of(np.zeros((2, 2)), ids=[3, 9]))
    np.testing.assert_allclose(out, [[1.0, 0.0], [-5.0, 0.0]])
    # 7 comes back: its old command was forgotten when it left, so it is not limited.
    out = layer.apply(
        np.array([[5.0, 0.0], [5.0, 0.0], [5.0, 0.0]]), obs_of(np.zeros((3, 2)), ids=[9, 7, 3])
    )
    np.testing.assert_allclose(out, [[-4.0, 0.0], [5.0, 0.0], [2.0, 0.0]])


def test_jerk_limit_with_no_vehicles_returns_an_empty_command():
    out = JerkLimit().apply(np.zeros((0, 2)), obs_of(np.zeros((0, 2))))
    assert out.shape == (0, 2)


# ---------------------------------------------------------------- composition
def test_constrained_controller_applies_layers_in_order_and_reports_clip_rates():
    # Law asks for 50 m/s^2 forward at 9.5 m/s: saturation allows (10 - 9.5)/0.1 = 5 m/s^2,
    # the box then clips to 2.6, the jerk layer passes it (first call).
    law = ConstrainedController(
        ConstantLaw([[50.0, -3.0]]),
        [SpeedSaturation(p_max=10.0), AccelerationBox(), JerkLimit(j_max=1.0)],
    )
    u = law.compute(obs_of([[9.5, 0.0]]))
    assert u[0, 0] == pytest.approx(2.6)
    assert u[0, 1] == pytest.approx(-1.5)
    assert law.clip_stats() == {"speed_saturation": 1.0, "acceleration_box": 1.0, "jerk_limit": 0.0}
    assert law.name == "constant"


def test_constrained_controller_passes_invalid_state_errors_through():
    law = ConstrainedController(OlfatiSaberController(), [SpeedSaturation(), AccelerationBox()])
    with pytest.raises(InvalidStateError, match="'car9'"):
        law.compute(obs_of([[np.nan, 0.0]], ids=["car9"]))


def test_constrained_flocking_respects_box_in_the_plane_world():
    rng = np.random.default_rng(4)
    law = ConstrainedController(
        OlfatiSaberController(FlockingParams()), [SpeedSaturation(p_max=15.0), AccelerationBox()]
    )
    world = PlaneWorld(
        rng.uniform(0, 30, (8, 2)), rng.uniform(-5, 5, (8, 2)), law, 0.1, record_every=1
    )
    traj = world.run(3.0).trajectories.dropna()  # the final row has no command (NaN)
    assert traj["ux_mps2"].between(-4.5, 2.6).all()
    assert traj["uy_mps2"].abs().max() <= 1.5
    assert law.clip_stats()["acceleration_box"] > 0.0


# ---------------------------------------------------------------- bad limits
@pytest.mark.parametrize(
    ("build", "name"),
    [
        (lambda: SpeedSaturation(p_max=-1.0), "p_max"),
        (lambda: SpeedSaturation(p_max=0.0), "p_max"),
        (lambda: AccelerationBox(long_min=1.0), "long_min"),
        (lambda: AccelerationBox(long_max=-1.0), "long_max"),
        (lambda: AccelerationBox(lat_max=-1.5), "lat_max"),
        (lambda: AccelerationBox(a_max=-2.0), "a_max"),
        (lambda: JerkLimit(j_max=-5.0), "j_max"),
        (lambda: JerkLimit(j_max=0.0), "j_max"),
    ],
)
def test_invalid_limit_raises_parameter_error_naming_it(build, name):
    with pytest.raises(ParameterError, match=name):
        build()


def test_acceleration_box_compiled_pass_equals_numpy_clip_and_its_count():
    """The road's (N, 2) commands take one compiled pass: the same values as ``np.clip``
    (bounds hit exactly, infinities, negative zeros, NaN kept) and the same clip count as
    ``out != u`` row by row."""
    rng = np.random.default_rng(5)
    layer = AccelerationBox()
    lo, hi = np.array([-4.5, -1.5]), np.array([2.6, 1.5])
    seen = clipped = 0
    for n in (0, 1, 7, 300):
        u = rng.normal(0.0, 4.0, (n, 2))
        special = np.array([-4.5, 2.6, -1.5, 1.5, np.inf, -np.inf, np.nan, -0.0, 0.0])
        mask = rng.random((n, 2)) < 0.3
        u[mask] = rng.choice(special, int(mask.sum()))
        want = np.clip(u, lo, hi)
        got = layer.apply(u, obs_of(np.zeros((n, 2))))
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(np.signbit(got), np.signbit(want))
        seen += n
        clipped += int(np.count_nonzero(np.any(want != u, axis=1)))
        assert (layer.seen, layer.clipped) == (seen, clipped)
    assert clipped > 50
