"""Drone flights (docs/marvel.md sections 1-3): kinematics, attitude, tags, determinism."""

import math

import numpy as np
import pytest

from scattertrack.sim.drone import (
    DEFAULT_TAGS,
    GRAVITY,
    MAX_SPEED,
    TAG_DIAMETER_M,
    FlightError,
    check_flight,
    flight,
    pattern_start_s,
    resolve_flight,
    tag_positions,
)
from scattertrack.sim.rotation import (
    angular_velocity_body,
    euler_zyx_from_quat,
    matrix_to_quat,
    quat_exp,
    quat_from_euler_zyx,
    quat_log,
    quat_multiply,
    quat_to_matrix,
    rotate,
    wrap_angle,
    yaw_of_matrix,
)

FLIGHTS = {
    "hover": {"kind": "hover"},
    "circle": {"kind": "circle", "radius": 6.0, "speed": 2.5},
    "circle-offset": {"kind": "circle", "radius": 4.0, "speed": 2.0, "centre": [8.0, 3.0], "clockwise": True},
    "square": {"kind": "square", "side": 8.0, "side_y": 5.0, "speed": 1.5},
    "figure-eight": {"kind": "figure-eight", "size": [10.0, 5.0], "speed": 2.5, "rotation_rad": 0.3},
    "rail": {"kind": "rail", "length": 6.0, "speed": 3.0},
    "rail-velocity-yaw": {"kind": "rail", "length": 6.0, "speed": 3.0, "yaw": "velocity", "altitude": 1.0},
    "turntable": {"kind": "turntable"},
    "circle-spinning": {"kind": "circle", "radius": 6.0, "speed": 2.0, "yaw": "rate", "yaw_rate": 0.8},
}
QUADROTOR = ["hover", "circle", "circle-offset", "square", "figure-eight", "circle-spinning"]
PEAK_SPEED = {"circle": 2.5, "circle-offset": 2.0, "square": 1.5, "figure-eight": 2.5, "rail": 3.0}


@pytest.fixture(scope="module")
def dense():
    """Every flight on a 5 ms grid over 60 s."""
    t = np.arange(0.0, 60.0, 0.005)
    return t, {name: flight(params, t) for name, params in FLIGHTS.items()}


@pytest.mark.parametrize("name", FLIGHTS)
def test_starts_at_rest_on_the_ground_at_the_origin(name):
    params = FLIGHTS[name]
    t = np.array([-5.0, 0.0, 0.5, 1.99])  # ground_s = 2 s by default
    state = flight(params, t)
    for array in (state.position, state.velocity, state.acceleration, state.angular_velocity):
        assert np.abs(array).max() < 1e-12
    # Level at rest: the accelerometer would read +g on body z.
    np.testing.assert_allclose(quat_to_matrix(state.orientation)[:, :, 2], [[0, 0, 1]] * 4, atol=1e-12)


def test_take_off_is_a_vertical_minimum_jerk_climb():
    params = {"kind": "hover", "altitude": 2.0, "climb_speed": 1.0}
    climb_s = 1.875 * 2.0 / 1.0
    t = np.linspace(2.0, 2.0 + climb_s, 501)
    state = flight(params, t)
    assert np.abs(state.position[:, :2]).max() == 0.0
    np.testing.assert_allclose(state.position[[0, -1], 2], [0.0, 2.0], atol=1e-12)
    assert np.all(np.diff(state.position[:, 2]) >= 0.0)
    assert state.velocity[:, 2].max() == pytest.approx(1.0, abs=1e-4)
    np.testing.assert_allclose(state.velocity[[0, -1], 2], 0.0, atol=1e-12)
    later = flight(params, np.array([30.0]))
    np.testing.assert_allclose(later.position, [[0.0, 0.0, 2.0]], atol=1e-12)


@pytest.mark.parametrize("name", FLIGHTS)
def test_orientation_is_unit_and_body_z_follows_the_specific_force(name, dense):
    _, states = dense
    state = states[name]
    np.testing.assert_allclose(np.linalg.norm(state.orientation, axis=1), 1.0, atol=1e-12)
    body_z = quat_to_matrix(state.orientation)[:, :, 2]
    if name in QUADROTOR:
        force = state.acceleration - GRAVITY
        np.testing.assert_allclose(body_z, force / np.linalg.norm(force, axis=1, keepdims=True), atol=1e-12)
    else:  # on the rail's or turntable's plate: level
        np.testing.assert_allclose(body_z, [[0.0, 0.0, 1.0]] * len(body_z), atol=1e-12)


@pytest.mark.parametrize("name", FLIGHTS)
def test_velocity_and_acceleration_are_the_derivatives(name):
    params = FLIGHTS[name]
    t = np.random.default_rng(3).uniform(0.0, 60.0, 2000)
    h = 1e-4
    state, before, after = flight(params, t), flight(params, t - h), flight(params, t + h)
    velocity = (after.position - before.position) / (2 * h)
    np.testing.assert_allclose(velocity, state.velocity, atol=1e-6)
    acceleration = (after.velocity - before.velocity) / (2 * h)
    # Minimum-jerk legs have a jump in jerk where they start and end: allow h * jump.
    np.testing.assert_allclose(acceleration, state.acceleration, atol=2e-3)
    assert np.percentile(np.abs(acceleration - state.acceleration), 99) < 1e-6


@pytest.mark.parametrize("name", ["circle", "figure-eight", "turntable", "circle-spinning", "circle-offset"])
def test_angular_velocity_is_the_derivative_of_the_rotation(name):
    params = FLIGHTS[name]
    # The patterns themselves are smooth (speed ramps are minimum-jerk in
    # speed, so jerk is continuous): the rotation's derivative is exact there.
    t = np.random.default_rng(4).uniform(pattern_start_s(params), 60.0, 2000)
    h = 1e-3
    state, before, after = flight(params, t), flight(params, t - h), flight(params, t + h)
    numeric = angular_velocity_body(before.orientation, after.orientation, 2 * h)
    np.testing.assert_allclose(numeric, state.angular_velocity, atol=2e-5)


def test_angular_velocity_of_the_square_matches_except_at_leg_ends():
    params = FLIGHTS["square"]
    t = np.random.default_rng(5).uniform(0.0, 60.0, 4000)
    h = 1e-3
    state, before, after = flight(params, t), flight(params, t - h), flight(params, t + h)
    error = np.abs(angular_velocity_body(before.orientation, after.orientation, 2 * h) - state.angular_velocity)
    # Tilt rate jumps where a minimum-jerk leg starts or stops (jerk 60 L / T^3);
    # a window of +-h straddles a jump for a few of 4000 random times at most.
    assert np.mean(error.max(axis=1) > 1e-5) < 0.01
    assert error.max() < 0.2


def test_yaw_follows_the_direction_of_travel():
    params = FLIGHTS["figure-eight"]
    t = np.linspace(pattern_start_s(params) + 3.0, 60.0, 3000)
    state = flight(params, t)
    travel = np.arctan2(state.velocity[:, 1], state.velocity[:, 0])
    yaw = yaw_of_matrix(quat_to_matrix(state.orientation))
    np.testing.assert_allclose(wrap_angle(yaw - travel), 0.0, atol=1e-9)


def test_square_holds_its_heading_when_slow_and_turns_at_corners():
    params = FLIGHTS["square"]
    t = np.arange(0.0, 60.0, 0.01)
    state = flight(params, t)
    yaw = state.yaw
    speed = np.linalg.norm(state.velocity, axis=1)
    moving = speed > 0.1
    travel = np.arctan2(state.velocity[:, 1], state.velocity[:, 0])
    np.testing.assert_allclose(wrap_angle(yaw[moving] - travel[moving]), 0.0, atol=1e-9)
    # Heading changes are smooth: no step larger than max_yaw_rate * dt (+ margin).
    assert np.abs(wrap_angle(np.diff(yaw))).max() < 1.0 * 0.01 * 1.01
    # Legs of 8 m along x and 5 m along y from the take-off corner.
    assert np.abs(state.position[:, 0]).max() == pytest.approx(8.0, abs=1e-9)
    assert state.position[:, 1].max() == pytest.approx(5.0, abs=1e-9)
    assert state.position[:, :2].min() == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("name", FLIGHTS)
def test_speeds_stay_within_limits(name, dense):
    _, states = dense
    speed = np.linalg.norm(states[name].velocity, axis=1)
    assert speed.max() <= MAX_SPEED + 1e-9
    if name in PEAK_SPEED:
        assert speed.max() == pytest.approx(PEAK_SPEED[name], rel=1e-3)


def test_flight_at_arbitrary_times_agrees_with_dense_sampling(dense):
    t, states = dense
    rng = np.random.default_rng(6)
    pick = rng.choice(len(t), 300, replace=False)  # shuffled, not sorted
    for name, params in FLIGHTS.items():
        subset = flight(params, t[pick])
        full = states[name]
        for field in ("position", "velocity", "acceleration", "orientation", "angular_velocity"):
            np.testing.assert_array_equal(getattr(subset, field), getattr(full, field)[pick], err_msg=f"{name} {field}")
        one = flight(params, t[pick[:1]])
        np.testing.assert_array_equal(one.position, full.position[pick[:1]])
    # Between grid points the dense samples interpolate to the exact state.
    params = FLIGHTS["circle"]
    between = t[:-1][::97] + 0.0025
    exact = flight(params, between).position
    interpolated = np.column_stack([np.interp(between, t, states["circle"].position[:, k]) for k in range(3)])
    np.testing.assert_allclose(interpolated, exact, atol=1e-5)


def test_turntable_sweeps_the_yaw_rate_in_steps():
    params = FLIGHTS["turntable"]
    sweep_start = pattern_start_s(params) + 1.0  # after the 1 s spin-up
    middles = sweep_start + np.arange(52) + 0.5
    state = flight(params, middles)
    rate = rotate(state.orientation, state.angular_velocity)[:, 2]
    expected = np.concatenate([0.2 + 0.05 * np.arange(27), 1.5 - 0.05 * np.arange(1, 26)])
    np.testing.assert_allclose(rate, expected, atol=1e-6)
    np.testing.assert_allclose(np.abs(state.position).max(), 0.0)
    # The sweep repeats: 52 s later the rates are the same.
    again = flight(params, middles + 52.0)
    np.testing.assert_allclose(rotate(again.orientation, again.angular_velocity)[:, 2], expected, atol=1e-6)
    # The yaw is the integral of the rate (exact, not accumulated sample by sample).
    t = np.linspace(0.0, 120.0, 240001)
    fine = flight(params, t)
    yaw_rate = rotate(fine.orientation, fine.angular_velocity)[:, 2]
    integral = np.concatenate([[0.0], np.cumsum((yaw_rate[1:] + yaw_rate[:-1]) / 2 * np.diff(t))])
    np.testing.assert_allclose(wrap_angle(fine.yaw - integral), 0.0, atol=1e-6)


def test_tags_sit_on_the_landing_gear_and_move_with_the_body():
    params = FLIGHTS["figure-eight"]
    t = np.random.default_rng(7).uniform(0.0, 60.0, 500)
    state = flight(params, t)
    positions, velocities = tag_positions(state)
    assert positions.shape == velocities.shape == (500, 4, 3)
    np.testing.assert_allclose(np.linalg.norm(positions[:, 0] - positions[:, 1], axis=1), TAG_DIAMETER_M)
    np.testing.assert_allclose(np.linalg.norm(positions[:, 2] - positions[:, 3], axis=1), TAG_DIAMETER_M)
    inverse = matrix_to_quat(np.swapaxes(quat_to_matrix(state.orientation), 1, 2))
    body = rotate(inverse[:, None], positions - state.position[:, None])
    np.testing.assert_allclose(body, np.broadcast_to(DEFAULT_TAGS.positions_body, body.shape), atol=1e-12)
    h = 1e-4
    before, _ = tag_positions(flight(params, t - h))
    after, _ = tag_positions(flight(params, t + h))
    np.testing.assert_allclose((after - before) / (2 * h), velocities, atol=2e-5)
    np.testing.assert_allclose(DEFAULT_TAGS.shifts_hz, [1e6, 2e6, 3e6, 4e6])


def test_malformed_flights_name_the_key():
    cases = [
        ({"kind": "spiral"}, "kind"),
        ({"kind": "circle", "radius": 5.0}, "speed"),
        ({"kind": "circle", "radius": 5.0, "speed": 4.0}, "speed"),
        ({"kind": "circle", "radius": 5.0, "speed": 2.0, "colour": "red"}, "colour"),
        ({"kind": "hover", "yaw": "sideways"}, "yaw"),
        ({"kind": "rail", "length": 1.0, "speed": 3.0}, "length"),
        ({"kind": "figure-eight", "size": [10.0], "speed": 1.0}, "size"),
        ({"kind": "turntable", "yaw_sweep": [0.2, 1.53, 0.05]}, "yaw_sweep"),
    ]
    for params, key in cases:
        with pytest.raises(FlightError) as error:
            resolve_flight(params)
        assert error.value.key == key, params
    with pytest.raises(FlightError, match="tilt"):
        check_flight({"kind": "circle", "radius": 0.5, "speed": 3.0}, 30.0)
    assert check_flight(FLIGHTS["circle"], 60.0)["altitude"] == 1.5


def test_rotation_helpers_agree():
    rng = np.random.default_rng(8)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    np.testing.assert_allclose(matrix_to_quat(quat_to_matrix(q)), q, atol=1e-12)
    v = rng.normal(size=(200, 3))
    np.testing.assert_allclose(rotate(q, v), np.einsum("nij,nj->ni", quat_to_matrix(q), v), atol=1e-12)
    p = quat_exp(rng.normal(size=(200, 3)))
    np.testing.assert_allclose(
        quat_to_matrix(quat_multiply(p, q)), quat_to_matrix(p) @ quat_to_matrix(q), atol=1e-12
    )
    small = rng.normal(size=(200, 3)) * 0.5
    np.testing.assert_allclose(quat_log(quat_exp(small)), small, atol=1e-12)
    yaw, pitch, roll = rng.uniform(-3, 3, 200), rng.uniform(-1.5, 1.5, 200), rng.uniform(-3, 3, 200)
    back = euler_zyx_from_quat(quat_from_euler_zyx(yaw, pitch, roll))
    np.testing.assert_allclose(wrap_angle(back[0] - yaw), 0, atol=1e-9)
    np.testing.assert_allclose(back[1], pitch, atol=1e-9)
    np.testing.assert_allclose(wrap_angle(back[2] - roll), 0, atol=1e-9)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)


def test_a_log_can_begin_in_the_lift_off():
    """``ground_s = 0`` and ``log_start_s``: the log's time 0 is that far into
    the climb (already moving up); the origin stays the take-off point."""
    from scattertrack.sim.drone import flight as drone_flight

    table = {"kind": "hover", "altitude": 2.0, "ground_s": 0.0}
    late = drone_flight({**table, "log_start_s": 0.3}, [0.0, 1.0])
    early = drone_flight(table, [0.3, 1.3])
    np.testing.assert_allclose(late.position, early.position)
    np.testing.assert_allclose(late.velocity, early.velocity)
    assert late.velocity[0, 2] > 0.05 and late.position[0, 2] > 0.0
    np.testing.assert_allclose(drone_flight(table, [0.0]).position, 0.0)
