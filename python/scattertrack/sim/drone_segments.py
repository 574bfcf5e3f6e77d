"""The pieces a drone flight is made of (:mod:`scattertrack.sim.drone`), each exact at any time.

Profiles: the minimum-jerk blend ``10 u^3 - 15 u^4 + 6 u^5`` and its
integral, and a speed ramp. Segments: finite pieces of a flight, each
evaluated at a local time ``tau`` in ``[0, duration)`` to position, velocity,
acceleration (world frame, m, m/s, m/s^2) and yaw (rad): a hold, a straight
leg, a cruise, a circle, a lemniscate, a repeating cycle and a one-way
sequence. Closed-form functions of time: nothing random, nothing that
depends on how ``tau`` is sampled.
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.physics import wrap_angle


# --------------------------------------------------------------------------
# profiles


def min_jerk(u):
    """Minimum-jerk fraction h(u) = 10u^3 - 15u^4 + 6u^5 and its first two derivatives in u.

    h(0) = 0, h(1) = 1, h' and h'' vanish at both ends: position, velocity
    and acceleration stay continuous where segments join.
    """
    u = np.clip(u, 0.0, 1.0)
    u2 = u * u
    return (
        u2 * u * (10.0 - 15.0 * u + 6.0 * u2),
        30.0 * u2 * (1.0 - u) ** 2,
        60.0 * u * (1.0 - u) * (1.0 - 2.0 * u),
    )


def min_jerk_integral(u):
    """S(u) = integral of h from 0 to u = 2.5u^4 - 3u^5 + u^6 for u in [0, 1]; S(1) = 1/2."""
    u = np.clip(u, 0.0, 1.0)
    u4 = u**4
    return u4 * (2.5 - 3.0 * u + u * u)


def ramp(tau, speed: float, ramp_s: float):
    """Distance (m), speed (m/s) and acceleration (m/s^2) of a speed ramp 0 -> ``speed`` over ``ramp_s``.

    The speed is ``speed * h(tau / ramp_s)`` then constant: the distance is
    ``speed * ramp_s * S(u)`` during the ramp and grows linearly after.
    """
    tau = np.maximum(tau, 0.0)
    u = tau / ramp_s
    fraction, slope, _ = min_jerk(u)
    distance = np.where(u < 1.0, speed * ramp_s * min_jerk_integral(u), speed * (ramp_s / 2.0 + tau - ramp_s))
    return distance, speed * fraction, speed * slope / ramp_s


# --------------------------------------------------------------------------
# segments: finite pieces of a flight, each exact at any local time tau in [0, duration)


class Segment:
    duration = math.inf

    def evaluate(self, tau):
        """(position (n,3), velocity (n,3), acceleration (n,3), heading (n,)) at local times ``tau``."""
        raise NotImplementedError

    @property
    def end_heading(self) -> float:
        raise NotImplementedError


class Hold(Segment):
    """At rest at ``point``; the heading turns from ``heading_from`` to ``heading_to`` (minimum-jerk)."""

    def __init__(self, point, duration: float, heading_from: float, heading_to: float | None = None):
        self.point = np.asarray(point, dtype=float)
        self.duration = duration
        self.heading_from = heading_from
        self.turn = 0.0 if heading_to is None else float(wrap_angle(heading_to - heading_from))

    def evaluate(self, tau):
        n = len(tau)
        position = np.broadcast_to(self.point, (n, 3)).copy()
        zeros = np.zeros((n, 3))
        if self.turn == 0.0 or not math.isfinite(self.duration):
            heading = np.full(n, self.heading_from)
        else:
            heading = self.heading_from + self.turn * min_jerk(tau / self.duration)[0]
        return position, zeros, zeros.copy(), heading

    @property
    def end_heading(self) -> float:
        return self.heading_from + self.turn


def turn_duration(turn_rad: float, max_yaw_rate: float) -> float:
    """Seconds a minimum-jerk turn of ``turn_rad`` needs at a peak rate ``max_yaw_rate`` (rad/s)."""
    return 1.875 * abs(float(wrap_angle(turn_rad))) / max_yaw_rate


class Leg(Segment):
    """Straight minimum-jerk leg from ``start`` to ``end`` (rest at both ends) with peak speed ``speed``."""

    def __init__(self, start, end, speed: float, heading: float):
        self.start = np.asarray(start, dtype=float)
        self.delta = np.asarray(end, dtype=float) - self.start
        self.length = float(np.linalg.norm(self.delta))
        self.duration = 1.875 * self.length / speed  # the peak speed of h is 1.875 L / T
        self.heading = heading

    def evaluate(self, tau):
        fraction, slope, curvature = min_jerk(tau / self.duration)
        position = self.start + fraction[:, None] * self.delta
        velocity = (slope / self.duration)[:, None] * self.delta
        acceleration = (curvature / self.duration**2)[:, None] * self.delta
        return position, velocity, acceleration, np.full(len(tau), self.heading)

    @property
    def end_heading(self) -> float:
        return self.heading


class Cruise(Segment):
    """Straight leg of ``length`` along unit ``direction``: ramp up, constant ``speed``, ramp down."""

    def __init__(self, start, direction, length: float, speed: float, ramp_s: float, heading: float):
        self.start = np.asarray(start, dtype=float)
        self.direction = np.asarray(direction, dtype=float)
        self.length, self.speed, self.ramp_s = length, speed, ramp_s
        # Each ramp covers speed * ramp_s / 2; the rest is at constant speed.
        self.duration = ramp_s + length / speed
        self.heading = heading

    def evaluate(self, tau):
        up_distance, up_speed, up_accel = ramp(tau, self.speed, self.ramp_s)
        remaining = self.duration - tau
        down_distance, down_speed, down_accel = ramp(remaining, self.speed, self.ramp_s)
        braking = remaining < self.ramp_s
        distance = np.where(braking, self.length - down_distance, up_distance)
        speed = np.where(braking, down_speed, up_speed)
        accel = np.where(braking, -down_accel, up_accel)
        position = self.start + distance[:, None] * self.direction
        return (
            position,
            speed[:, None] * self.direction,
            accel[:, None] * self.direction,
            np.full(len(tau), self.heading),
        )

    @property
    def end_heading(self) -> float:
        return self.heading


class Circle(Segment):
    """Circle at constant height from angle ``angle0``, speed ramped up from rest, for ever."""

    def __init__(self, centre, radius: float, angle0: float, speed: float, ramp_s: float, clockwise: bool):
        self.centre = np.asarray(centre, dtype=float)
        self.radius, self.angle0, self.speed, self.ramp_s = radius, angle0, speed, ramp_s
        self.sign = -1.0 if clockwise else 1.0

    def start_heading(self) -> float:
        return self.angle0 + self.sign * math.pi / 2.0

    def evaluate(self, tau):
        distance, speed, accel = ramp(tau, self.speed, self.ramp_s)
        angle = self.angle0 + self.sign * distance / self.radius
        rate = self.sign * speed / self.radius  # rad/s
        rate_dot = self.sign * accel / self.radius
        radial = np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
        tangent = np.stack([-np.sin(angle), np.cos(angle), np.zeros_like(angle)], axis=1)
        position = self.centre + self.radius * radial
        velocity = (self.radius * rate)[:, None] * tangent
        acceleration = (self.radius * rate_dot)[:, None] * tangent - (self.radius * rate**2)[:, None] * radial
        # Tangent heading: defined by the geometry even at rest, so it holds when slow.
        return position, velocity, acceleration, angle + self.sign * math.pi / 2.0


class Lemniscate(Segment):
    """Gerono lemniscate ``centre + Rz(rotation) (A sin th, B sin th cos th, 0)``, th ramped up from 0."""

    def __init__(self, centre, half_width: float, height: float, rotation: float, speed: float, ramp_s: float):
        self.centre = np.asarray(centre, dtype=float)
        self.a, self.b = half_width, height
        self.rotation = rotation
        # |dp/dth| = sqrt(A^2 cos^2 th + B^2 cos^2 2th) peaks at th = 0 with sqrt(A^2 + B^2).
        self.phase_rate = speed / math.hypot(half_width, height)
        self.ramp_s = ramp_s

    def start_heading(self) -> float:
        return self.rotation + math.atan2(self.b, self.a)

    def evaluate(self, tau):
        th, th_dot, th_ddot = ramp(tau, self.phase_rate, self.ramp_s)
        a, b = self.a, self.b
        local = np.stack([a * np.sin(th), 0.5 * b * np.sin(2 * th)], axis=1)
        d1 = np.stack([a * np.cos(th), b * np.cos(2 * th)], axis=1)  # dp/dth
        d2 = np.stack([-a * np.sin(th), -2.0 * b * np.sin(2 * th)], axis=1)  # d2p/dth2
        velocity_local = d1 * th_dot[:, None]
        accel_local = d2 * (th_dot**2)[:, None] + d1 * th_ddot[:, None]
        c, s = math.cos(self.rotation), math.sin(self.rotation)

        def lift(xy):
            # Element-wise (not a matrix product), so a sample's value does not depend on the batch.
            return np.column_stack([c * xy[:, 0] - s * xy[:, 1], s * xy[:, 0] + c * xy[:, 1], np.zeros(len(xy))])

        # dp/dth never vanishes (cos th = 0 makes cos 2th = -1), so the tangent heading is always defined.
        heading = self.rotation + np.arctan2(d1[:, 1], d1[:, 0])
        return self.centre + lift(local), lift(velocity_local), lift(accel_local), heading


class Cycle(Segment):
    """Finite segments repeated for ever (a closed pattern: square, rail back and forth)."""

    def __init__(self, segments: list[Segment]):
        self.segments = segments
        self.period = sum(s.duration for s in segments)

    def evaluate(self, tau):
        return evaluate_sequence(self.segments, np.mod(tau, self.period))


def evaluate_sequence(segments: list[Segment], tau: np.ndarray):
    """Evaluate consecutive segments (the last may be infinite) at times from the first's start."""
    n = len(tau)
    position, velocity, acceleration = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    heading = np.zeros(n)
    start = 0.0
    for index, segment in enumerate(segments):
        end = start + segment.duration
        last = index == len(segments) - 1
        pick = tau >= start if last else (tau >= start) & (tau < end)
        if index == 0:
            pick |= tau < start
        if pick.any():
            p, v, a, h = segment.evaluate(tau[pick] - start)
            position[pick], velocity[pick], acceleration[pick], heading[pick] = p, v, a, h
        start = end
    return position, velocity, acceleration, heading


class SequenceSegment(Segment):
    """Consecutive segments as one (the last infinite): a one-way rail."""

    def __init__(self, segments):
        self.segments = segments

    def evaluate(self, tau):
        return evaluate_sequence(self.segments, tau)
