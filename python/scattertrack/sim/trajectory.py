"""Tag trajectories: exact positions and velocities at any times.

One entry point, :func:`positions_velocities`, evaluates a trajectory described
by a plain dict (``{"kind": ..., **params}``, as written in a scenario's
``[tags.trajectory]`` table) at an array of times, fully vectorised. Every
velocity is the exact time derivative of the position (analytic, or through
the chain rule of an arc-length reparametrisation), so ground truth and the
simulated Doppler agree with finite differences of the positions.

Units: positions in metres (world frame, z up), times in seconds, speeds in
m/s, angles in radians. Every point parameter is a 3-vector ``[x, y, z]``.

Kinds and their parameters (defaults in brackets):

``static``
    ``position``.
``line``
    ``start``, ``speed`` (m/s) and either ``end`` (back and forth between
    ``start`` and ``end`` at constant speed, with smooth turnarounds of
    constant deceleration lasting ``turn_s`` [0.5 s]) or ``direction``
    (straight on for ever).
``circle``
    ``centre``, ``radius`` (m), ``speed`` (m/s), ``normal`` [``"xy"``: a
    3-vector or one of ``"xy"``, ``"xz"``, ``"yz"``], ``start_angle_rad`` [0],
    ``clockwise`` [false] (seen from the tip of the normal).
``figure-eight``
    Lemniscate of Gerono ``(A sin th, B sin th cos th)`` in a plane, travelled
    at constant speed: ``centre``, ``size`` = ``[width, height]`` (m, full
    extents), ``speed`` (m/s), ``normal`` [``"xy"``], ``rotation_rad`` [0]
    (turns the figure within its plane).
``random``
    Smooth band-limited random motion inside an axis-aligned box: each axis is
    ``centre + half_size * sum_k A_k sin(2 pi f_k s t + phi_k)`` with
    ``sum_k |A_k| = 1`` (so it never leaves the box); the time scale ``s`` is
    chosen so that the mean speed over the first ``speed_window_s`` [20 s]
    equals ``mean_speed``. Parameters: ``box_min``, ``box_max``,
    ``mean_speed`` (m/s), ``seed`` (integer; the simulator fills it in from
    the scenario seed when absent), ``components`` [4 sinusoids per axis],
    ``speed_window_s`` [20]. A box with zero extent along an axis keeps that
    coordinate fixed (use it for 2D scenes).
``pick-and-place``
    A robot arm moving between waypoints on straight segments, each with a
    minimum-jerk profile ``s(u) = L (10u^3 - 15u^4 + 6u^5)``, ``u = t/T``
    (zero velocity and acceleration at both ends), whose peak speed
    ``1.875 L / T`` equals ``peak_speed`` (m/s), and a pause of ``pause_s``
    [0.3 s] at every waypoint. The cycle closes back to the first waypoint and
    repeats. Either ``waypoints`` (list of points) or ``pick``, ``place`` and
    ``lift_m`` (the arm lifts the item by ``lift_m`` above ``pick``, carries
    it to ``lift_m`` above ``place``, puts it down, and comes back).

Every kind also accepts ``time_offset_s`` [0]: the trajectory is evaluated at
``t + time_offset_s`` (start several tags at different points of one path),
and ``hold_at_s`` with ``hold_s``: from session time ``hold_at_s`` the tag
stands still for ``hold_s`` seconds (velocity zero), then carries on from
where it stopped (the path is evaluated ``hold_s`` late). Put the hold where
the path is at rest, e.g. in a pick-and-place pause, for a stop without a
jump in velocity.
"""

from __future__ import annotations

import functools

import numpy as np

KINDS = ("static", "line", "circle", "figure-eight", "random", "pick-and-place")
"""Trajectory kinds understood by :func:`positions_velocities`."""

# Keys each kind accepts (required ones first); the scenario loader checks
# tables against these so that a misspelt key is an error, not a silent default.
REQUIRED_KEYS = {
    "static": ("position",),
    "line": ("start", "speed"),
    "circle": ("centre", "radius", "speed"),
    "figure-eight": ("centre", "size", "speed"),
    "random": ("box_min", "box_max", "mean_speed"),
    "pick-and-place": ("peak_speed",),
}
OPTIONAL_KEYS = {
    "static": (),
    "line": ("end", "direction", "turn_s"),
    "circle": ("normal", "start_angle_rad", "clockwise"),
    "figure-eight": ("normal", "rotation_rad"),
    "random": ("seed", "components", "speed_window_s"),
    "pick-and-place": ("waypoints", "pick", "place", "lift_m", "pause_s"),
}
COMMON_KEYS = ("kind", "time_offset_s", "hold_at_s", "hold_s")


def positions_velocities(kind_params: dict, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions (m) and velocities (m/s), each shape (n, 3), at times ``t`` (s, shape (n,)).

    ``kind_params`` is ``{"kind": <one of KINDS>, **parameters}`` (see the
    module docstring). Raises ``ValueError`` for an unknown kind or a missing
    or malformed parameter.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    held = np.zeros(t.shape, dtype=bool)
    if "hold_at_s" in kind_params or "hold_s" in kind_params:
        if "hold_at_s" not in kind_params or "hold_s" not in kind_params:
            raise ValueError("a hold needs both 'hold_at_s' and 'hold_s'")
        hold_at_s, hold_s = float(kind_params["hold_at_s"]), float(kind_params["hold_s"])
        if not (np.isfinite(hold_at_s) and np.isfinite(hold_s)) or hold_s < 0.0:
            raise ValueError(f"'hold_s' must be a finite number >= 0, got {kind_params['hold_s']!r}")
        held = (t >= hold_at_s) & (t < hold_at_s + hold_s)
        # Path time: frozen during the hold, hold_s behind after it.
        t = np.where(held, hold_at_s, np.where(t >= hold_at_s + hold_s, t - hold_s, t))
    t = t + float(kind_params.get("time_offset_s", 0.0))
    kind = kind_params.get("kind")
    if kind not in KINDS:
        raise ValueError(f"unknown trajectory kind {kind!r}; expected one of {', '.join(KINDS)}")
    for key in REQUIRED_KEYS[kind]:
        if key not in kind_params:
            raise ValueError(f"trajectory kind {kind!r} needs '{key}'")
    function = {
        "static": _static,
        "line": _line,
        "circle": _circle,
        "figure-eight": _figure_eight,
        "random": _random,
        "pick-and-place": _pick_and_place,
    }[kind]
    position, velocity = function(kind_params, t)
    velocity[held] = 0.0
    return position, velocity


def _vector(params: dict, key: str) -> np.ndarray:
    value = np.asarray(params[key], dtype=float)
    if value.shape != (3,) or not np.all(np.isfinite(value)):
        raise ValueError(f"'{key}' must be a point [x, y, z] of finite numbers, got {params[key]!r}")
    return value


def _positive(params: dict, key: str, default: float | None = None) -> float:
    value = float(params.get(key, default))
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"'{key}' must be a positive number, got {params.get(key, default)!r}")
    return value


def plane_basis(normal) -> tuple[np.ndarray, np.ndarray]:
    """Two orthonormal in-plane axes (u, w) with u x w = n for a plane normal.

    ``normal`` is a 3-vector or ``"xy"``, ``"xz"``, ``"yz"``. For the xy plane
    (normal +z) this is (x, y), so circles and figure-eights in a 2D scene are
    drawn in the usual axes.
    """
    named = {"xy": [0.0, 0.0, 1.0], "xz": [0.0, -1.0, 0.0], "yz": [1.0, 0.0, 0.0]}
    if isinstance(normal, str):
        if normal not in named:
            raise ValueError(f"'normal' must be a 3-vector or one of xy, xz, yz, got {normal!r}")
        normal = named[normal]
    n = np.asarray(normal, dtype=float)
    if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0.0:
        raise ValueError(f"'normal' must be a non-zero 3-vector, got {normal!r}")
    n = n / np.linalg.norm(n)
    # Pick the world axis least aligned with n to build u, so the basis is
    # well conditioned; for n = +z this yields u = +x, w = +y.
    helper = np.eye(3)[np.argmin(np.abs(n))] if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = helper - n * (helper @ n)
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    return u, w


def _static(params: dict, t: np.ndarray):
    p = np.broadcast_to(_vector(params, "position"), (len(t), 3)).copy()
    return p, np.zeros_like(p)


def _line(params: dict, t: np.ndarray):
    start = _vector(params, "start")
    speed = float(params["speed"])
    if "end" not in params:
        if "direction" not in params:
            raise ValueError("trajectory kind 'line' needs 'end' or 'direction'")
        direction = _vector(params, "direction")
        direction = direction / np.linalg.norm(direction)
        p = start + np.outer(speed * t, direction)
        v = np.broadcast_to(speed * direction, p.shape).copy()
        return p, v
    end = _vector(params, "end")
    speed = _positive(params, "speed")
    turn = _positive(params, "turn_s", 0.5)
    length = float(np.linalg.norm(end - start))
    direction = (end - start) / length
    # Back and forth along s in [0, L]: cruise at +speed, then a turnaround of
    # constant deceleration 2*speed/turn lasting `turn` seconds (velocity goes
    # +speed -> -speed, continuous), which overshoots the cruise end by
    # margin = speed*turn/4; so cruising runs over [margin, L - margin].
    margin = speed * turn / 4.0
    cruise = (length - 2.0 * margin) / speed
    if cruise < 0.0:
        raise ValueError(
            f"line too short ({length:.3f} m) for turnarounds of {turn} s at {speed} m/s; "
            "lower 'turn_s' or the speed"
        )
    period = 2.0 * (cruise + turn)
    # Shift time by half a turnaround so that t = 0 is the instant the
    # start-end turnaround reaches s = 0: the tag starts at `start`, at rest,
    # and accelerates towards `end`.
    tau = np.mod(t + turn / 2.0, period)
    deceleration = 2.0 * speed / turn
    s = np.empty_like(tau)
    ds = np.empty_like(tau)
    # phase 0: turnaround at the start end, s = margin - speed*tau + deceleration*tau^2/2
    # (moving backwards at first, turning at tau = turn/2 where s = 0)
    a = tau < turn
    s[a] = margin - speed * tau[a] + 0.5 * deceleration * tau[a] ** 2
    ds[a] = -speed + deceleration * tau[a]
    # phase 1: cruise forwards
    b = (tau >= turn) & (tau < turn + cruise)
    tb = tau[b] - turn
    s[b] = margin + speed * tb
    ds[b] = speed
    # phase 2: turnaround at the end
    c = (tau >= turn + cruise) & (tau < 2.0 * turn + cruise)
    tc = tau[c] - turn - cruise
    s[c] = length - margin + speed * tc - 0.5 * deceleration * tc**2
    ds[c] = speed - deceleration * tc
    # phase 3: cruise backwards
    d = tau >= 2.0 * turn + cruise
    td = tau[d] - 2.0 * turn - cruise
    s[d] = length - margin - speed * td
    ds[d] = -speed
    return start + np.outer(s, direction), np.outer(ds, direction)


def _circle(params: dict, t: np.ndarray):
    centre = _vector(params, "centre")
    radius = _positive(params, "radius")
    speed = float(params["speed"])
    u, w = plane_basis(params.get("normal", "xy"))
    omega = speed / radius * (-1.0 if params.get("clockwise", False) else 1.0)
    angle = float(params.get("start_angle_rad", 0.0)) + omega * t
    cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
    p = centre + radius * (cos * u + sin * w)
    v = radius * omega * (-sin * u + cos * w)
    return p, v


# Arc-length table of the figure-eight: per-interval integrals by 3-point
# Gauss-Legendre (exact to rounding for these smooth integrands), inverted by
# interpolation and then polished with Newton steps on the exact arc length,
# so theta(s) is the true inverse and the chain-rule velocity is the exact
# derivative of the position.
_ARC_TABLE_SAMPLES = 4096
_GAUSS_NODES = np.array([0.5 - np.sqrt(0.15), 0.5, 0.5 + np.sqrt(0.15)])
_GAUSS_WEIGHTS = np.array([5.0, 8.0, 5.0]) / 18.0


def _figure_eight(params: dict, t: np.ndarray):
    centre = _vector(params, "centre")
    size = np.asarray(params["size"], dtype=float)
    if size.shape != (2,) or not np.all(size > 0.0):
        raise ValueError(f"'size' must be [width, height] in metres, both > 0, got {params['size']!r}")
    speed = float(params["speed"])
    u, w = plane_basis(params.get("normal", "xy"))
    rotation = float(params.get("rotation_rad", 0.0))
    u, w = np.cos(rotation) * u + np.sin(rotation) * w, -np.sin(rotation) * u + np.cos(rotation) * w
    half_width, height = size[0] / 2.0, size[1]

    # Curve q(th) = (A sin th, B sin th cos th); |q'(th)| never vanishes
    # (q'_x = 0 only at th = pi/2 + k pi, where q'_y = -B), so the arc length
    # is strictly increasing and invertible.
    def derivative(theta):
        return half_width * np.cos(theta), height * np.cos(2.0 * theta)

    def speed_along(theta):
        return np.hypot(*derivative(theta))

    def integral(lower, upper):
        width = upper - lower
        nodes = lower[..., None] + width[..., None] * _GAUSS_NODES
        return width * (speed_along(nodes) @ _GAUSS_WEIGHTS)

    step = 2.0 * np.pi / _ARC_TABLE_SAMPLES
    theta_table = np.arange(_ARC_TABLE_SAMPLES + 1) * step
    arc_table = np.concatenate([[0.0], np.cumsum(integral(theta_table[:-1], theta_table[1:]))])
    perimeter = arc_table[-1]
    arc = np.mod(speed * t, perimeter)
    theta = np.interp(arc, arc_table, theta_table)
    for _ in range(3):
        index = np.clip(np.floor(theta / step).astype(np.int64), 0, _ARC_TABLE_SAMPLES - 1)
        arc_at_theta = arc_table[index] + integral(theta_table[index], theta)
        theta = theta - (arc_at_theta - arc) / speed_along(theta)
    qx, qy = half_width * np.sin(theta), height * np.sin(theta) * np.cos(theta)
    dx, dy = derivative(theta)
    # Chain rule: dq/dt = q'(th) * dth/ds * ds/dt = q'(th) * speed / |q'(th)|.
    scale = speed / np.hypot(dx, dy)
    p = centre + qx[:, None] * u + qy[:, None] * w
    v = (scale * dx)[:, None] * u + (scale * dy)[:, None] * w
    return p, v


def _random(params: dict, t: np.ndarray):
    low, high = _vector(params, "box_min"), _vector(params, "box_max")
    if np.any(high < low):
        raise ValueError("'box_max' must be >= 'box_min' on every axis")
    mean_speed = _positive(params, "mean_speed")
    components = int(params.get("components", 4))
    if components < 1:
        raise ValueError("'components' must be >= 1")
    window = _positive(params, "speed_window_s", 20.0)
    centre, half = (low + high) / 2.0, (high - low) / 2.0
    frequency, amplitude, phase = _random_coefficients(
        int(params.get("seed", 0)), components, tuple(half), mean_speed, window
    )
    angle = 2.0 * np.pi * frequency[None] * t[:, None, None] + phase[None]
    p = centre + half * np.sum(amplitude[None] * np.sin(angle), axis=2)
    v = half * np.sum(amplitude[None] * 2.0 * np.pi * frequency[None] * np.cos(angle), axis=2)
    return p, v


@functools.lru_cache(maxsize=64)
def _random_coefficients(seed: int, components: int, half: tuple, mean_speed: float, window: float):
    """Frequencies (Hz), amplitudes and phases (rad), each (3, components), of a ``random`` path.

    Cached: the speed scaling below is the only costly part, and the
    simulator evaluates the same path several times (validation, reads, truth).
    """
    rng = np.random.default_rng(seed)
    half = np.asarray(half)
    # Relative frequencies within a factor of 5 ([0.2, 1] before scaling):
    # the motion is smooth (no fast wiggles) and not periodic.
    frequency = rng.uniform(0.2, 1.0, size=(3, components))
    amplitude = rng.uniform(0.5, 1.0, size=(3, components))
    amplitude /= amplitude.sum(axis=1, keepdims=True)  # sum |A| = 1 keeps it in the box
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(3, components))
    if np.all(half == 0.0):
        return frequency, amplitude, phase
    # Scale the frequencies so the mean speed over the window matches the
    # target. The mean speed is nearly proportional to the scale, so a few
    # fixed-point steps converge; the window is fixed (not the scenario's
    # duration) so a shorter run replays the same path.
    grid = np.linspace(0.0, window, int(window * 50.0) + 1)
    scale = 1.0
    for _ in range(100):
        angle = 2.0 * np.pi * frequency[None] * scale * grid[:, None, None] + phase[None]
        v = half * np.sum(amplitude[None] * 2.0 * np.pi * frequency[None] * scale * np.cos(angle), axis=2)
        measured = float(np.mean(np.linalg.norm(v, axis=1)))
        new_scale = scale * mean_speed / measured
        converged = abs(new_scale - scale) <= 1e-12 * scale
        scale = new_scale
        if converged:
            break
    return frequency * scale, amplitude, phase


def pick_and_place_waypoints(params: dict) -> np.ndarray:
    """Waypoints (k, 3) in metres of a ``pick-and-place`` trajectory (explicit or built)."""
    if "waypoints" in params:
        points = np.asarray(params["waypoints"], dtype=float)
        if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2 or not np.all(np.isfinite(points)):
            raise ValueError("'waypoints' must be a list of at least two points [x, y, z]")
        return points
    for key in ("pick", "place", "lift_m"):
        if key not in params:
            raise ValueError("trajectory kind 'pick-and-place' needs 'waypoints' or 'pick', 'place' and 'lift_m'")
    pick, place = _vector(params, "pick"), _vector(params, "place")
    lift = np.array([0.0, 0.0, float(params["lift_m"])])
    return np.array([pick, pick + lift, place + lift, place, place + lift, pick + lift])


def _pick_and_place(params: dict, t: np.ndarray):
    points = pick_and_place_waypoints(params)
    peak_speed = _positive(params, "peak_speed")
    pause = float(params.get("pause_s", 0.3))
    if pause < 0.0:
        raise ValueError("'pause_s' must be >= 0")
    starts = points
    ends = np.roll(points, -1, axis=0)  # the last segment closes the loop
    lengths = np.linalg.norm(ends - starts, axis=1)
    # Minimum-jerk peak speed is 1.875 L / T at mid-segment.
    durations = 1.875 * lengths / peak_speed
    # Timeline per waypoint: pause at the start point, then move to the next.
    block = pause + durations
    block_start = np.concatenate([[0.0], np.cumsum(block)[:-1]])
    period = float(np.sum(block))
    tau = np.mod(t, period)
    index = np.clip(np.searchsorted(block_start, tau, side="right") - 1, 0, len(points) - 1)
    local = tau - block_start[index] - pause
    duration = durations[index]
    moving = (local > 0.0) & (duration > 0.0)
    u = np.zeros_like(tau)
    u[moving] = np.clip(local[moving] / duration[moving], 0.0, 1.0)
    shape = 10.0 * u**3 - 15.0 * u**4 + 6.0 * u**5
    shape_rate = np.zeros_like(tau)
    shape_rate[moving] = (30.0 * u[moving] ** 2 - 60.0 * u[moving] ** 3 + 30.0 * u[moving] ** 4) / duration[moving]
    delta = ends[index] - starts[index]
    p = starts[index] + shape[:, None] * delta
    v = shape_rate[:, None] * delta
    return p, v
