"""Drone flights with attitude, and the tags on the landing gear (docs/marvel.md sections 1-3).

:func:`flight` evaluates a flight described by a plain dict (the scenario's
``[flight]`` table) at an array of times and returns a :class:`FlightTruth`:
position, velocity and acceleration (world frame), orientation
(``world_T_body`` quaternion) and angular velocity (body frame). It is exact
and deterministic at any time: positions are closed-form functions of time
(polynomials, circles, a lemniscate), so the IQ simulator can evaluate it at
every sample of a chirp and the truth at 100 Hz, and both agree. Nothing is
random and nothing depends on how ``t`` is sampled.

Frames and units (docs/marvel.md section 1): world z up, origin at the body
origin at rest on the ground before take-off; body x forward, y left, z up;
metres, seconds, radians, m/s, m/s^2, rad/s.

Every flight
------------
1. rests on the ground at the origin for ``ground_s`` [2 s] (the pose
   sensing estimates the tags' CFO at rest, the fusion its IMU biases);
2. climbs vertically to ``altitude`` (m) with a minimum-jerk profile
   ``z = altitude * (10 u^3 - 15 u^4 + 6 u^5)``, ``u = t / T``, whose peak
   speed ``1.875 altitude / T`` is ``climb_speed`` [1 m/s] (no climb when
   ``altitude = 0``: the paper's rail and turntable are on the ground);
3. hovers ``hover_s`` [1 s] (longer if it must turn to its first heading,
   see ``max_yaw_rate``), flies to the pattern's start point if that is not
   above the origin (a minimum-jerk leg), and flies the pattern for ever
   (periodic patterns repeat).

For ``t < 0`` the drone is at rest at the origin.

Kinds (parameters; defaults in brackets; speeds are peak speeds in m/s and
at most :data:`MAX_SPEED`):

``hover``
    Stays above the origin.
``circle``
    ``radius`` (m), ``speed`` (m/s), ``centre`` [``[radius, 0]``: the circle
    passes above the origin] (x, y in metres; the circle is at ``altitude``),
    ``clockwise`` [false] (seen from above), ``ramp_s`` [2 s]: the speed
    rises from 0 to ``speed`` as ``speed * h(t / ramp_s)`` with the
    minimum-jerk ``h``, so acceleration (and attitude) stays continuous.
``square``
    ``side`` (m), ``side_y`` [side] (the second side: a rectangle),
    ``speed`` (peak speed of each minimum-jerk leg, m/s), ``pause_s`` [1 s]
    at each corner (longer when turning to the next leg needs it),
    ``rotation_rad`` [0] (direction of the first leg), ``clockwise`` [false],
    ``corner`` [``[0, 0]``] (x, y of the first corner).
``figure-eight``
    Lemniscate of Gerono ``(A sin th, B sin th cos th)`` with ``A = width/2``,
    ``B = height``: ``size = [width, height]`` (m, full extents), ``speed``
    (m/s, the peak speed, reached at the crossing), ``centre`` [``[0, 0]``]
    (the crossing point), ``rotation_rad`` [0], ``ramp_s`` [2 s]. ``th``
    grows at ``speed / sqrt(A^2 + B^2)`` rad/s after the ramp (the
    parametrisation is not arc length: speed varies along the figure, as a
    real drone following waypoints does).
``rail``
    The paper's sliding rail (sec. V-B): ``length`` (m), ``speed`` (m/s),
    ``direction`` [``[1, 0, 0]``] (normalised), ``ramp_s`` [1 s] (the
    speed ramps up and down with the minimum-jerk ``h``), ``pause_s`` [1 s]
    at each end, ``back_and_forth`` [true] (false: stop at the end).
    ``altitude`` defaults to 0: no take-off; ``attitude`` defaults to
    ``"level"``.
``turntable``
    The paper's rotation test (sec. V-B): fixed position, ``yaw = "rate"``
    with the sweep 0.2 -> 1.5 -> 0.2 rad/s in 0.05 rad/s steps over 52 s.
    ``altitude`` defaults to 0, ``attitude`` to ``"level"``.

Common keys: ``altitude`` [1.5 m; 0 for rail and turntable], ``ground_s``
[2 s; 0: the flight lifts off at once], ``climb_speed`` [1 m/s], ``hover_s`` [1 s],
``log_start_s`` [0 s: the log begins this long into the flight, so with
``ground_s = 0`` and ``log_start_s > 0`` it begins in the climb, already
moving, as a log started late does; the world origin stays the take-off
point], ``attitude``
[``"quadrotor"``, or ``"level"``], ``yaw``, ``yaw_rad``
[0: the heading at rest], ``max_yaw_rate`` [1 rad/s: the peak rate of the
minimum-jerk turns], ``yaw_rate`` [0.5 rad/s], ``yaw_sweep`` (``[low,
high, step]`` rad/s), ``sweep_s`` [52 s], ``step_s`` [0.2 s],
``spin_up_s`` [1 s].

Attitude
--------
Quadrotor kinematics: thrust is along body z, so body z is the direction of
the specific force ``f = a - g`` (``g = (0, 0, -9.80665)`` m/s^2). The yaw
profile gives the heading ``psi``; the rotation is the ZYX product
``R = Rz(psi) Ry(pitch) Rx(roll)`` with pitch and roll chosen so that
``R e_z = f / |f|`` (so the yaw read back as ``atan2(R[1,0], R[0,0])`` is
exactly ``psi``). With ``attitude = "level"`` (the default of rail and
turntable, where the drone sits on a plate) body z stays vertical instead:
the accelerometer then sees the horizontal acceleration on its x and y
axes. Yaw profiles (``yaw``):

``fixed``
    ``psi = yaw_rad`` throughout (default for hover and rail).
``velocity``
    Face the direction of travel (default for circle, square and
    figure-eight): the heading is the path's tangent, which is defined from
    the geometry even where the speed is zero, so the drone holds it when
    slow; at a corner (or a rail end) it turns during the pause, and after
    take-off it turns from ``yaw_rad`` to the first heading while hovering.
    Turns are minimum-jerk in angle with a peak rate of at most
    ``max_yaw_rate``.
``rate``
    ``psi = yaw_rad + integral of the rate``, starting at the pattern
    start: the rate spins up from 0 over ``spin_up_s`` (minimum-jerk), then
    stays at ``yaw_rate`` or, with ``yaw_sweep = [low, high, step]``, steps
    low -> high -> low by ``step`` with every plateau ``sweep_s /
    n_steps`` long and each step a minimum-jerk transition of ``step_s``
    seconds; the sweep repeats (default for turntable: ``[0.2, 1.5, 0.05]``
    over 52 s).

Angular velocity (body frame) is ``log(q(t - h)^-1 q(t + h)) / (2 h)`` with
``h`` = :data:`DIFFERENCE_STEP_S`, evaluated inside :func:`flight`: the exact
derivative of the rotation up to O(h^2) (~1e-9 rad/s), without writing out
the derivative of every pattern's attitude.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scattertrack.sim.drone_segments import (
    Circle,
    Cruise,
    Cycle,
    Hold,
    Leg,
    Lemniscate,
    Segment,
    SequenceSegment,
    evaluate_sequence,
    min_jerk_integral,
    turn_duration,
)
from scattertrack.sim.rotation import (
    angular_velocity_body,
    quat_from_euler_zyx,
    rotate,
    yaw_of_quat,
)

GRAVITY = np.array([0.0, 0.0, -9.80665])
"""Gravity in the world frame, m/s^2 (docs/marvel.md section 1)."""

MAX_SPEED = 3.0
"""Highest peak speed a flight may ask for, m/s (the paper's rail maximum, sec. V-B)."""

MAX_TILT_RAD = math.radians(35.0)
"""Highest tilt of body z from vertical a flight may need; beyond it the pattern is too aggressive."""

DIFFERENCE_STEP_S = 1e-4
"""Half-step of the symmetric difference of the rotation that gives the angular velocity, s.

Truncation error ~ h^2 * (angular jerk) / 6 and round-off ~ 1e-16 / h: both
far below a gyroscope's noise at 1e-4 s."""

KINDS = ("hover", "circle", "square", "figure-eight", "rail", "turntable")
YAW_PROFILES = ("fixed", "velocity", "rate")
ATTITUDES = ("quadrotor", "level")

COMMON_KEYS = (
    "kind",
    "altitude",
    "ground_s",
    "climb_speed",
    "hover_s",
    "yaw",
    "yaw_rad",
    "attitude",
    "max_yaw_rate",
    "yaw_rate",
    "yaw_sweep",
    "sweep_s",
    "step_s",
    "spin_up_s",
    "log_start_s",
)
"""Keys every kind accepts."""
REQUIRED_KEYS = {
    "hover": (),
    "circle": ("radius", "speed"),
    "square": ("side", "speed"),
    "figure-eight": ("size", "speed"),
    "rail": ("length", "speed"),
    "turntable": (),
}
OPTIONAL_KEYS = {
    "hover": (),
    "circle": ("centre", "clockwise", "ramp_s"),
    "square": ("side_y", "pause_s", "rotation_rad", "clockwise", "corner"),
    "figure-eight": ("centre", "rotation_rad", "ramp_s"),
    "rail": ("direction", "ramp_s", "pause_s", "back_and_forth"),
    "turntable": (),
}

COMMON_DEFAULTS = {
    "altitude": 1.5,  # m
    "ground_s": 2.0,  # s at rest before take-off
    "climb_speed": 1.0,  # m/s, peak speed of the climb
    "hover_s": 1.0,  # s after the climb
    "yaw_rad": 0.0,  # rad, heading at rest
    "max_yaw_rate": 1.0,  # rad/s, peak rate of the minimum-jerk turns
    "yaw_rate": 0.5,  # rad/s, constant rate of yaw = "rate"
    "sweep_s": 52.0,  # s, one sweep of yaw = "rate" with yaw_sweep
    "step_s": 0.2,  # s, each step of the sweep
    "spin_up_s": 1.0,  # s, rate ramp from rest
    "log_start_s": 0.0,  # s into the flight at which the log (time 0) begins
}
KIND_DEFAULTS = {
    "hover": {"yaw": "fixed", "attitude": "quadrotor"},
    "circle": {"yaw": "velocity", "attitude": "quadrotor", "clockwise": False, "ramp_s": 2.0},
    "square": {
        "yaw": "velocity",
        "attitude": "quadrotor",
        "pause_s": 1.0,
        "rotation_rad": 0.0,
        "clockwise": False,
        "corner": [0.0, 0.0],
    },
    "figure-eight": {
        "yaw": "velocity",
        "attitude": "quadrotor",
        "centre": [0.0, 0.0],
        "rotation_rad": 0.0,
        "ramp_s": 2.0,
    },
    "rail": {
        "yaw": "fixed",
        "attitude": "level",
        "altitude": 0.0,
        "direction": [1.0, 0.0, 0.0],
        "ramp_s": 1.0,
        "pause_s": 1.0,
        "back_and_forth": True,
    },
    "turntable": {"yaw": "rate", "attitude": "level", "altitude": 0.0, "yaw_sweep": [0.2, 1.5, 0.05]},
}


class ParameterError(ValueError):
    """A malformed parameter table (flight, IMU or feature model); ``key`` names the key (None: the table)."""

    def __init__(self, key: str | None, message: str):
        self.key = key
        self.message = message
        super().__init__(f"{key}: {message}" if key else message)


def with_defaults(given: dict | None, defaults: dict) -> dict:
    """A model's table: ``defaults`` updated by ``given``; a key of ``given``
    that ``defaults`` lacks is a :class:`ParameterError` naming it."""
    given = dict(given or {})
    for key in given:
        if key not in defaults:
            raise ParameterError(key, f"unknown key (expected one of: {', '.join(sorted(defaults))})")
    return {**defaults, **given}


class FlightError(ParameterError):
    """A malformed flight table."""


# --------------------------------------------------------------------------
# truth and tags


@dataclass
class FlightTruth:
    """The drone's state at each time (docs/marvel.md section 3).

    All world-frame quantities refer to the body origin (the IMU).
    """

    time_s: np.ndarray  # (n,) seconds
    position: np.ndarray  # (n, 3) metres, world
    velocity: np.ndarray  # (n, 3) m/s, world
    acceleration: np.ndarray  # (n, 3) m/s^2, world (kinematic, gravity not included)
    orientation: np.ndarray  # (n, 4) qw, qx, qy, qz, world_T_body (continuous in time, not sign-normalised)
    angular_velocity: np.ndarray  # (n, 3) rad/s, body frame

    def __len__(self) -> int:
        return len(self.time_s)

    @property
    def yaw(self) -> np.ndarray:
        """Heading of body x about +z, radians in (-pi, pi]."""
        return yaw_of_quat(self.orientation)


@dataclass(frozen=True)
class TagLayout:
    """Tags on the drone: body-frame positions (m) and uplink frequency shifts (Hz)."""

    names: tuple
    positions_body: np.ndarray  # (k, 3) metres, body frame
    shifts_hz: np.ndarray  # (k,) hertz


TAG_DIAMETER_M = 0.66
"""Diameter of the circle of tags on the landing gear (DJI M100), metres (docs/marvel.md section 2)."""
GEAR_HEIGHT_M = -0.30
"""Height of the tags below the body origin, metres."""
TAG_SHIFTS_HZ = (1.0e6, 2.0e6, 3.0e6, 4.0e6)
"""Uplink frequency shift of tags 1, 1' (2), 3, 3' (4), hertz."""

DEFAULT_TAGS = TagLayout(
    names=("1", "1'", "3", "3'"),
    positions_body=np.array(
        [
            [TAG_DIAMETER_M / 2, 0.0, GEAR_HEIGHT_M],
            [-TAG_DIAMETER_M / 2, 0.0, GEAR_HEIGHT_M],
            [0.0, TAG_DIAMETER_M / 2, GEAR_HEIGHT_M],
            [0.0, -TAG_DIAMETER_M / 2, GEAR_HEIGHT_M],
        ]
    ),
    shifts_hz=np.array(TAG_SHIFTS_HZ),
)
"""The four tags of docs/marvel.md section 2: opposing pairs along body x (1, 1') and body y (3, 3')."""


def tag_positions(truth: FlightTruth, layout: TagLayout = DEFAULT_TAGS) -> tuple[np.ndarray, np.ndarray]:
    """World positions (n, k, 3) in metres and velocities (n, k, 3) in m/s of each tag.

    ``p_k = p + R r_k`` and ``v_k = v + R (omega x r_k)`` (omega in the body
    frame), so the velocities contain the rotational part the rotational
    Doppler comes from.
    """
    offsets = np.asarray(layout.positions_body, dtype=float)[None, :, :]
    q = np.asarray(truth.orientation, dtype=float)[:, None, :]
    positions = np.asarray(truth.position)[:, None, :] + rotate(q, offsets)
    spin = np.cross(np.asarray(truth.angular_velocity)[:, None, :], offsets)
    velocities = np.asarray(truth.velocity)[:, None, :] + rotate(q, spin)
    return positions, velocities


# --------------------------------------------------------------------------
# building a flight from its parameters


def resolve_flight(params: dict) -> dict:
    """The flight table with every default filled in, checked; raises :class:`FlightError`.

    Checks types and ranges (speeds at most :data:`MAX_SPEED`), not the
    attitude: :func:`check_flight` evaluates the flight for that.
    """
    if not isinstance(params, dict):
        raise FlightError(None, f"must be a table, got {params!r}")
    kind = params.get("kind")
    if kind not in KINDS:
        raise FlightError("kind", f"must be one of {', '.join(map(repr, KINDS))}, got {kind!r}")
    allowed = (*COMMON_KEYS, *REQUIRED_KEYS[kind], *OPTIONAL_KEYS[kind])
    for key in params:
        if key not in allowed:
            raise FlightError(key, f"unknown key for a {kind!r} flight (expected one of: {', '.join(sorted(allowed))})")
    for key in REQUIRED_KEYS[kind]:
        if key not in params:
            raise FlightError(key, f"missing (a {kind!r} flight needs it)")
    data = {**COMMON_DEFAULTS, **KIND_DEFAULTS[kind], **params}

    def number(key, minimum=None, strict=False, maximum=None):
        value = data[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise FlightError(key, f"must be a finite number, got {value!r}")
        if minimum is not None and (value < minimum or (strict and value == minimum)):
            raise FlightError(key, f"must be {'>' if strict else '>='} {minimum}, got {value!r}")
        if maximum is not None and value > maximum:
            raise FlightError(key, f"must be <= {maximum}, got {value!r}")
        data[key] = float(value)

    def vector(key, size):
        value = data[key]
        if not isinstance(value, (list, tuple)) or len(value) != size:
            raise FlightError(key, f"must be a list of {size} numbers, got {value!r}")
        for v in value:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise FlightError(key, f"must be a list of {size} finite numbers, got {value!r}")
        data[key] = [float(v) for v in value]

    def boolean(key):
        if not isinstance(data[key], bool):
            raise FlightError(key, f"must be true or false, got {data[key]!r}")

    number("altitude", 0.0, maximum=100.0)
    number("ground_s", 0.0)
    number("climb_speed", 0.0, strict=True, maximum=MAX_SPEED)
    number("hover_s", 0.0)
    number("yaw_rad")
    number("max_yaw_rate", 0.0, strict=True)
    number("yaw_rate")
    number("sweep_s", 0.0, strict=True)
    number("step_s", 0.0, strict=True)
    number("spin_up_s", 0.0, strict=True)
    number("log_start_s", 0.0)
    if data["attitude"] not in ATTITUDES:
        raise FlightError("attitude", f"must be one of {', '.join(map(repr, ATTITUDES))}, got {data['attitude']!r}")
    if data["yaw"] not in YAW_PROFILES:
        raise FlightError("yaw", f"must be one of {', '.join(map(repr, YAW_PROFILES))}, got {data['yaw']!r}")
    if "yaw_sweep" in data:
        vector("yaw_sweep", 3)
        low, high, step = data["yaw_sweep"]
        if not (step > 0.0 and low < high):
            raise FlightError(
                "yaw_sweep", f"must be [low, high, step] with low < high and step > 0, got {data['yaw_sweep']!r}"
            )
        steps = (high - low) / step
        if abs(steps - round(steps)) > 1e-6:
            raise FlightError("yaw_sweep", f"high - low must be a whole number of steps, got {data['yaw_sweep']!r}")
        if data["step_s"] >= data["sweep_s"] / (2 * round(steps)):
            raise FlightError("step_s", "must be shorter than one plateau of the sweep (sweep_s / number of steps)")
    if "speed" in data:
        number("speed", 0.0, strict=True, maximum=MAX_SPEED)
    for key in ("radius", "side", "length"):
        if key in data:
            number(key, 0.0, strict=True)
    if kind == "square":
        data.setdefault("side_y", data["side"])
        number("side_y", 0.0, strict=True)
    for key in ("pause_s",):
        if key in data:
            number(key, 0.0)
    for key in ("ramp_s",):
        if key in data:
            number(key, 0.0, strict=True)
    for key in ("rotation_rad",):
        if key in data:
            number(key)
    for key in ("clockwise", "back_and_forth"):
        if key in data:
            boolean(key)
    for key in ("centre", "corner"):
        if key in data:
            vector(key, 2)
    if kind == "figure-eight":
        vector("size", 2)
        if min(data["size"]) <= 0.0:
            raise FlightError("size", f"must be two positive extents [width, height] in metres, got {data['size']!r}")
    if kind == "rail":
        vector("direction", 3)
        if np.linalg.norm(data["direction"]) == 0.0:
            raise FlightError("direction", "must be a non-zero vector")
        if data["length"] < data["speed"] * data["ramp_s"]:
            raise FlightError(
                "length", f"must be at least speed * ramp_s = {data['speed'] * data['ramp_s']:g} m (both ramps fit)"
            )
    return data


class _Plan:
    """A resolved flight: preamble segments + pattern, and the yaw profile."""

    def __init__(self, data: dict):
        self.data = data
        altitude = data["altitude"]
        hover_point = np.array([0.0, 0.0, altitude])
        yaw0 = data["yaw_rad"]
        segments: list[Segment] = [Hold(np.zeros(3), data["ground_s"], yaw0)]
        if altitude > 0.0:
            segments.append(Leg(np.zeros(3), hover_point, data["climb_speed"], yaw0))
        pattern, start_point, first_heading = self._pattern(hover_point)
        velocity_yaw = data["yaw"] == "velocity"
        max_rate = data["max_yaw_rate"]
        transit = start_point - hover_point
        heading = yaw0
        if np.linalg.norm(transit) > 1e-9:
            # Fly to the pattern's start, facing the way there when yaw follows the velocity.
            transit_heading = math.atan2(transit[1], transit[0]) if velocity_yaw else yaw0
            turn = turn_duration(transit_heading - heading, max_rate) if velocity_yaw else 0.0
            segments.append(Hold(hover_point, max(data["hover_s"], turn), heading, transit_heading))
            segments.append(Leg(hover_point, start_point, data.get("speed", 1.0), transit_heading))
            heading = transit_heading
            hover_before_pattern = 0.0
        else:
            hover_before_pattern = data["hover_s"]
        target = first_heading if velocity_yaw else heading
        turn = turn_duration(target - heading, max_rate) if velocity_yaw else 0.0
        segments.append(Hold(start_point, max(hover_before_pattern, turn), heading, target))
        self.pattern_start = sum(s.duration for s in segments)
        segments.append(pattern)
        self.segments = segments
        self._rate_setup()

    def _pattern(self, hover_point):
        """(pattern segment, its start point, its first heading) for the flight's kind."""
        d = self.data
        kind = d["kind"]
        yaw0 = d["yaw_rad"]
        altitude = hover_point[2]
        velocity_yaw = d["yaw"] == "velocity"
        max_rate = d["max_yaw_rate"]
        if kind in ("hover", "turntable"):
            return Hold(hover_point, math.inf, yaw0), hover_point, yaw0
        if kind == "circle":
            radius = d["radius"]
            centre = np.array([*d.get("centre", [radius, 0.0]), altitude])
            away = hover_point - centre
            angle0 = math.atan2(away[1], away[0]) if np.linalg.norm(away[:2]) > 1e-9 else 0.0
            start = centre + radius * np.array([math.cos(angle0), math.sin(angle0), 0.0])
            circle = Circle(centre, radius, angle0, d["speed"], d["ramp_s"], d["clockwise"])
            return circle, start, circle.start_heading()
        if kind == "figure-eight":
            centre = np.array([*d["centre"], altitude])
            eight = Lemniscate(centre, d["size"][0] / 2.0, d["size"][1], d["rotation_rad"], d["speed"], d["ramp_s"])
            return eight, centre, eight.start_heading()
        if kind == "square":
            corner = np.array([*d["corner"], altitude])
            sign = -1.0 if d["clockwise"] else 1.0
            legs = []
            point = corner
            for index in range(4):
                heading = d["rotation_rad"] + sign * index * math.pi / 2.0
                side = d["side"] if index % 2 == 0 else d["side_y"]
                end = point + side * np.array([math.cos(heading), math.sin(heading), 0.0])
                next_heading = heading + sign * math.pi / 2.0
                leg = Leg(point, end, d["speed"], heading)
                if velocity_yaw:
                    pause = max(d["pause_s"], turn_duration(next_heading - heading, max_rate))
                    hold = Hold(end, pause, heading, next_heading)
                else:
                    leg.heading = yaw0
                    hold = Hold(end, d["pause_s"], yaw0)
                legs += [leg, hold]
                point = end
            first = d["rotation_rad"] if velocity_yaw else yaw0
            return Cycle(legs), corner, first
        if kind == "rail":
            direction = np.asarray(d["direction"], dtype=float)
            direction = direction / np.linalg.norm(direction)
            out_heading = math.atan2(direction[1], direction[0]) if np.linalg.norm(direction[:2]) > 1e-9 else yaw0
            back_heading = out_heading + math.pi
            if not velocity_yaw:
                out_heading = back_heading = yaw0
            end = hover_point + d["length"] * direction
            out = Cruise(hover_point, direction, d["length"], d["speed"], d["ramp_s"], out_heading)
            if not d["back_and_forth"]:
                return SequenceSegment([out, Hold(end, math.inf, out_heading)]), hover_point, out_heading
            pause = d["pause_s"]
            if velocity_yaw:
                pause = max(pause, turn_duration(math.pi, max_rate))
            back = Cruise(end, -direction, d["length"], d["speed"], d["ramp_s"], back_heading)
            cycle = [
                out,
                Hold(end, pause, out_heading, back_heading),
                back,
                Hold(hover_point, pause, back_heading, out_heading),
            ]
            return Cycle(cycle), hover_point, out_heading
        raise FlightError("kind", f"unknown kind {kind!r}")

    # --- yaw = "rate" -----------------------------------------------------

    def _rate_setup(self):
        d = self.data
        if "yaw_sweep" in d:
            low, high, step = d["yaw_sweep"]
            up = int(round((high - low) / step))
            levels = np.concatenate([low + step * np.arange(up + 1), high - step * np.arange(1, up + 1)])
        else:
            levels = np.array([d["yaw_rate"]])
        self.levels = levels
        n_steps = len(levels) - 1
        self.plateau_s = d["sweep_s"] / n_steps if n_steps else math.inf
        # Integral of the rate over each plateau interval [jP, (j+1)P): the step to
        # the next level is a minimum-jerk transition filling its last step_s seconds
        # (its mean is the midpoint of the two levels).
        if n_steps:
            step_s = d["step_s"]
            nxt = np.roll(levels, -1)[:-1]
            cur = levels[:-1]
            per_interval = cur * (self.plateau_s - step_s) + step_s * (cur + nxt) / 2.0
            self.cumulative = np.concatenate([[0.0], np.cumsum(per_interval)])
            self.sweep_integral = float(self.cumulative[-1])

    def rate_yaw(self, t):
        """Yaw (rad) of the ``rate`` profile: yaw_rad + integral of the rate from the pattern start."""
        d = self.data
        spin_up = d["spin_up_s"]
        tau = np.maximum(t - self.pattern_start, 0.0)
        first = self.levels[0]
        # Spin-up 0 -> first level: integral first * spin_up * S(u).
        yaw = d["yaw_rad"] + first * spin_up * min_jerk_integral(tau / spin_up)
        after = tau - spin_up
        running = after > 0.0
        if len(self.levels) == 1:
            return yaw + np.where(running, first * after, 0.0)
        period = self.sweep_integral
        sweep_s = self.plateau_s * (len(self.levels) - 1)
        s = np.maximum(after, 0.0)
        cycles = np.floor(s / sweep_s)
        within = s - cycles * sweep_s
        index = np.minimum((within / self.plateau_s).astype(int), len(self.levels) - 2)
        local = within - index * self.plateau_s
        level = self.levels[index]
        jump = self.levels[index + 1] - level
        step_s = d["step_s"]
        transition = step_s * min_jerk_integral((local - (self.plateau_s - step_s)) / step_s)
        partial = self.cumulative[index] + level * local + jump * transition
        return yaw + np.where(running, cycles * period + partial, 0.0)

    # --- evaluation -------------------------------------------------------

    def kinematics(self, t):
        """(position, velocity, acceleration, yaw) at log times ``t`` (s); flight time
        ``t + log_start_s`` below 0 is at rest."""
        t = np.maximum(np.asarray(t, dtype=float) + self.data["log_start_s"], 0.0)
        position, velocity, acceleration, heading = evaluate_sequence(self.segments, t)
        profile = self.data["yaw"]
        if profile == "fixed":
            yaw = np.full(len(t), self.data["yaw_rad"])
        elif profile == "velocity":
            yaw = heading
        else:
            yaw = self.rate_yaw(t)
        return position, velocity, acceleration, yaw

    def orientation(self, acceleration, yaw):
        """world_T_body quaternions whose body z is along ``a - g`` and whose ZYX yaw is ``yaw``.

        With ``attitude = "level"`` (a drone on the rail's or the
        turntable's plate) body z stays vertical whatever the acceleration.
        """
        if self.data["attitude"] == "level":
            zeros = np.zeros(len(yaw))
            return quat_from_euler_zyx(yaw, zeros, zeros)
        force = acceleration - GRAVITY
        b3 = force / np.linalg.norm(force, axis=1, keepdims=True)
        c, s = np.cos(yaw), np.sin(yaw)
        # b3 in the frame turned by yaw: Ry(pitch) Rx(roll) e_z = (cos r sin p, -sin r, cos r cos p).
        x = c * b3[:, 0] + s * b3[:, 1]
        y = -s * b3[:, 0] + c * b3[:, 1]
        z = b3[:, 2]
        roll = np.arctan2(-y, np.hypot(x, z))
        pitch = np.arctan2(x, z)
        return quat_from_euler_zyx(yaw, pitch, roll)


def flight(params: dict, t) -> FlightTruth:
    """The drone's exact state at times ``t`` (seconds, any shape, flattened; any order).

    ``params`` is the flight table (see the module docstring); raises
    :class:`FlightError` for a malformed one. Deterministic: the same
    parameters and time give the same state however ``t`` is sampled.
    """
    plan = _Plan(resolve_flight(params))
    t = np.asarray(t, dtype=float).reshape(-1)
    position, velocity, acceleration, yaw = plan.kinematics(t)
    orientation = plan.orientation(acceleration, yaw)
    h = DIFFERENCE_STEP_S
    # Symmetric difference of the rotation; before t = 0 the drone is at rest,
    # so clipping at 0 inside kinematics keeps the difference exact there.
    _, _, a_before, yaw_before = plan.kinematics(t - h)
    _, _, a_after, yaw_after = plan.kinematics(t + h)
    angular_velocity = angular_velocity_body(
        plan.orientation(a_before, yaw_before), plan.orientation(a_after, yaw_after), 2.0 * h
    )
    return FlightTruth(
        time_s=t,
        position=position,
        velocity=velocity,
        acceleration=acceleration,
        orientation=orientation,
        angular_velocity=angular_velocity,
    )


def pattern_start_s(params: dict) -> float:
    """Log time (s) the pattern starts: after resting, climbing, hovering and any transit."""
    plan = _Plan(resolve_flight(params))
    return plan.pattern_start - plan.data["log_start_s"]


def check_flight(params: dict, duration_s: float) -> dict:
    """Resolve ``params`` and check the attitude it needs over [0, duration_s] s.

    Raises :class:`FlightError` when the flight tilts more than
    :data:`MAX_TILT_RAD` (too aggressive for a quadrotor) or leaves the
    ground below z = 0. Returns the resolved table.
    """
    data = resolve_flight(params)
    times = np.linspace(0.0, duration_s, int(duration_s * 50) + 2)
    plan = _Plan(data)
    position, _, acceleration, _ = plan.kinematics(times)
    force = acceleration - GRAVITY
    tilt = np.arccos(np.clip(force[:, 2] / np.linalg.norm(force, axis=1), -1.0, 1.0))
    if data["attitude"] == "quadrotor" and tilt.max() > MAX_TILT_RAD:
        where = float(times[np.argmax(tilt)])
        raise FlightError(
            None,
            f"needs a tilt of {math.degrees(tilt.max()):.0f} deg at t = {where:.2f} s "
            f"(at most {math.degrees(MAX_TILT_RAD):.0f}): lower the speed or widen the pattern",
        )
    if position[:, 2].min() < -1e-9:
        raise FlightError("direction" if data["kind"] == "rail" else None, "the flight goes below the ground (z < 0)")
    return data
