"""Synthetic truth and tracks for the evaluation tests.

Truth is a horizontal circle of radius 0.5 m at 1 rad/s sampled at 200 Hz,
with analytic velocity, so every expected error is known exactly.
"""

import numpy as np

from scattertrack.io.types import SkipReport, Track, Truth

RADIUS_M = 0.5
ANGULAR_SPEED_RAD_S = 1.0
TRUTH_RATE_HZ = 200.0


def circle(time_s: np.ndarray, centre=(1.0, 0.5, 0.8)) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and velocity (m/s) on the circle at the given times."""
    angle = ANGULAR_SPEED_RAD_S * time_s
    position = np.column_stack(
        [centre[0] + RADIUS_M * np.cos(angle), centre[1] + RADIUS_M * np.sin(angle), np.full_like(angle, centre[2])]
    )
    speed = RADIUS_M * ANGULAR_SPEED_RAD_S
    velocity = np.column_stack([-speed * np.sin(angle), speed * np.cos(angle), np.zeros_like(angle)])
    return position, velocity


def make_truth(epc="E2000A01", start_s=0.0, duration_s=10.0, with_velocity=True, centre=(1.0, 0.5, 0.8)) -> Truth:
    time = start_s + np.arange(int(round(duration_s * TRUTH_RATE_HZ)) + 1) / TRUTH_RATE_HZ
    position, velocity = circle(time - start_s, centre)
    if not with_velocity:
        velocity = np.full_like(velocity, np.nan)
    return Truth(time_s=time, epc=np.full(len(time), epc), position=position, velocity=velocity)


def concat_truth(*truths: Truth) -> Truth:
    return Truth(
        time_s=np.concatenate([t.time_s for t in truths]),
        epc=np.concatenate([t.epc for t in truths]),
        position=np.concatenate([t.position for t in truths]),
        velocity=np.concatenate([t.velocity for t in truths]),
    )


def track_from(truth: Truth, every=4, position_offset=(0.0, 0.0, 0.0), velocity_offset=(0.0, 0.0, 0.0), sigma=None):
    """A track at every ``every``-th truth sample (so no interpolation error), with offsets."""
    rows = np.arange(0, len(truth), every)
    return Track(
        time_s=truth.time_s[rows].copy(),
        epc=truth.epc[rows].copy(),
        position=truth.position[rows] + np.asarray(position_offset, dtype=float),
        velocity=np.nan_to_num(truth.velocity[rows]) + np.asarray(velocity_offset, dtype=float),
        sigma=sigma,
        skipped=SkipReport(),
    )


def concat_tracks(*tracks: Track) -> Track:
    return Track(
        time_s=np.concatenate([t.time_s for t in tracks]),
        epc=np.concatenate([t.epc for t in tracks]),
        position=np.concatenate([t.position for t in tracks]),
        velocity=np.concatenate([t.velocity for t in tracks]),
    )

