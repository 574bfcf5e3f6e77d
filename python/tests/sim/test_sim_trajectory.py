"""Trajectories: exact velocities (finite differences), speeds, bounds."""

import numpy as np
import pytest

from scattertrack.sim.trajectory import pick_and_place_waypoints, positions_velocities

KINDS = {
    "static": {"kind": "static", "position": [0.5, 0.2, 0.1]},
    "line-end": {"kind": "line", "start": [0.4, 0.0, 0.0], "end": [1.1, 0.4, 0.0], "speed": 0.4, "turn_s": 0.5},
    "line-direction": {"kind": "line", "start": [0.4, 0.0, 0.2], "direction": [1.0, 2.0, 0.5], "speed": 0.3},
    "circle": {"kind": "circle", "centre": [0.7, 0.3, 0.0], "radius": 0.25, "speed": 0.4},
    "circle-tilted": {
        "kind": "circle",
        "centre": [0.5, 0.4, 0.6],
        "radius": 0.2,
        "speed": 0.3,
        "normal": [1.0, 1.0, 1.0],
        "clockwise": True,
        "start_angle_rad": 1.0,
    },
    "figure-eight": {"kind": "figure-eight", "centre": [0.7, 0.3, 0.0], "size": [0.6, 0.3], "speed": 0.4},
    "figure-eight-xz": {
        "kind": "figure-eight",
        "centre": [0.5, 0.4, 0.6],
        "size": [0.4, 0.2],
        "speed": 0.2,
        "normal": "xz",
        "rotation_rad": 0.3,
    },
    "random": {"kind": "random", "box_min": [0.2, 0.1, 0.4], "box_max": [0.8, 0.7, 0.9], "mean_speed": 0.2, "seed": 3},
    "pick-and-place": {
        "kind": "pick-and-place",
        "pick": [0.3, 0.2, 0.45],
        "place": [0.7, 0.6, 0.5],
        "lift_m": 0.3,
        "peak_speed": 0.25,
        "pause_s": 0.3,
        "time_offset_s": 1.7,
    },
}


@pytest.mark.parametrize("name", sorted(KINDS))
def test_velocity_is_the_derivative_of_position(name):
    params = KINDS[name]
    t = np.linspace(0.0, 30.0, 3001) + 0.00123
    h = 1e-6
    p_plus, _ = positions_velocities(params, t + h)
    p_minus, _ = positions_velocities(params, t - h)
    p, v = positions_velocities(params, t)
    assert p.shape == v.shape == (len(t), 3)
    finite_difference = (p_plus - p_minus) / (2.0 * h)
    # Central differences: O(h^2) where smooth; piecewise-constant
    # acceleration (line turnarounds) adds O(h * jump) at a few instants.
    np.testing.assert_allclose(v, finite_difference, atol=2e-6, rtol=0)


@pytest.mark.parametrize("name", ["circle", "circle-tilted", "figure-eight", "figure-eight-xz", "line-direction"])
def test_constant_speed_kinds(name):
    params = KINDS[name]
    _, v = positions_velocities(params, np.linspace(0.0, 20.0, 2001))
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), params["speed"], rtol=1e-9)


def test_figure_eight_stays_in_its_box_and_plane():
    params = KINDS["figure-eight"]
    p, _ = positions_velocities(params, np.linspace(0.0, 30.0, 6001))
    assert np.allclose(p[:, 2], 0.0)
    assert p[:, 0].min() == pytest.approx(0.4, abs=1e-4) and p[:, 0].max() == pytest.approx(1.0, abs=1e-4)
    assert p[:, 1].min() == pytest.approx(0.15, abs=1e-4) and p[:, 1].max() == pytest.approx(0.45, abs=1e-4)


def test_line_goes_back_and_forth_between_its_ends():
    params = KINDS["line-end"]
    p, v = positions_velocities(params, np.linspace(0.0, 20.0, 20001))
    start, end = np.array(params["start"]), np.array(params["end"])
    s = (p - start) @ (end - start) / np.sum((end - start) ** 2)
    assert s.min() == pytest.approx(0.0, abs=1e-6) and s.max() == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(p[0], start)
    assert np.linalg.norm(v, axis=1).max() == pytest.approx(params["speed"])


def test_random_motion_stays_in_box_at_the_target_mean_speed():
    params = KINDS["random"]
    # The mean speed is matched over the first speed_window_s (default 20 s).
    p, v = positions_velocities(params, np.linspace(0.0, 20.0, 2001))
    assert np.all(p >= np.array(params["box_min"])) and np.all(p <= np.array(params["box_max"]))
    assert np.mean(np.linalg.norm(v, axis=1)) == pytest.approx(0.2, rel=1e-3)
    longer = params | {"speed_window_s": 60.0}
    _, v = positions_velocities(longer, np.linspace(0.0, 60.0, 6001))
    assert np.mean(np.linalg.norm(v, axis=1)) == pytest.approx(0.2, rel=1e-3)
    other, _ = positions_velocities(params | {"seed": 4}, np.linspace(0.0, 20.0, 2001))
    assert not np.allclose(p, other)


def test_random_motion_with_a_flat_box_stays_in_the_plane():
    params = {"kind": "random", "box_min": [0.3, 0.0, 0.0], "box_max": [1.0, 0.5, 0.0], "mean_speed": 0.3}
    p, v = positions_velocities(params, np.linspace(0.0, 20.0, 2001))
    assert np.all(p[:, 2] == 0.0) and np.all(v[:, 2] == 0.0)


def test_pick_and_place_visits_waypoints_with_pauses_and_peak_speed():
    params = KINDS["pick-and-place"] | {"time_offset_s": 0.0}
    points = pick_and_place_waypoints(params)
    assert len(points) == 6
    t = np.linspace(0.0, 40.0, 40001)
    p, v = positions_velocities(params, t)
    speed = np.linalg.norm(v, axis=1)
    assert speed.max() == pytest.approx(0.25, rel=1e-3)
    # Paused at the first waypoint at the start.
    np.testing.assert_allclose(p[t <= 0.3], np.broadcast_to(points[0], p[t <= 0.3].shape))
    for point in points:
        assert np.min(np.linalg.norm(p - point, axis=1)) < 1e-9
    assert 0.45 - 1e-9 <= p[:, 2].min() and p[:, 2].max() <= 0.8 + 1e-9


def test_unknown_kind_and_missing_parameter_are_errors():
    with pytest.raises(ValueError, match="unknown trajectory kind"):
        positions_velocities({"kind": "spiral"}, np.zeros(1))
    with pytest.raises(ValueError, match="speed"):
        positions_velocities({"kind": "circle", "centre": [0, 0, 0], "radius": 1.0}, np.zeros(1))


def test_a_hold_stops_the_tag_then_it_carries_on_from_where_it_stopped():
    arm = KINDS["pick-and-place"] | {"time_offset_s": 0.0}
    held = arm | {"hold_at_s": 3.0, "hold_s": 8.0}
    t = np.linspace(0.0, 20.0, 4001)
    position, velocity = positions_velocities(held, t)
    plain_position, plain_velocity = positions_velocities(arm, t)
    before, during, after = t < 3.0, (t >= 3.0) & (t < 11.0), t >= 11.0
    np.testing.assert_array_equal(position[before], plain_position[before])
    at_stop, _ = positions_velocities(arm, np.array([3.0]))
    assert np.all(position[during] == at_stop[0]) and np.all(velocity[during] == 0.0)
    late, late_velocity = positions_velocities(arm, t[after] - 8.0)
    np.testing.assert_allclose(position[after], late)
    np.testing.assert_allclose(velocity[after], late_velocity)
    assert np.abs(plain_velocity[during]).max() > 0.05  # without the hold it would have moved


def test_a_hold_needs_both_keys():
    with pytest.raises(ValueError, match="hold_at_s"):
        positions_velocities(KINDS["static"] | {"hold_s": 2.0}, np.array([0.0]))
    with pytest.raises(ValueError, match="hold_s"):
        positions_velocities(KINDS["static"] | {"hold_at_s": 1.0, "hold_s": -1.0}, np.array([0.0]))
