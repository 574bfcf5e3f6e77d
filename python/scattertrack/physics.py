"""Physical constants and angle wrapping: the one home of each (issue 17).

The lowest layer of the package (python/pyproject.toml,
``[tool.importlinter]``): it imports nothing of scattertrack, and every
other module takes these from here instead of defining its own. The Rust
homes are ``scattertrack_core::scene::SPEED_OF_LIGHT`` and
``scattertrack_core::angle`` (crates/core; ``scattertrack_dsp`` re-exports
both).

Units are SI: m/s, rad, rad/(m Hz).
"""

from __future__ import annotations

import numpy as np

SPEED_OF_LIGHT = 299_792_458.0
"""Speed of light in vacuum, m/s (docs/formats.md section 1: lambda = c / f)."""

FOUR_PI_OVER_C = 4.0 * np.pi / SPEED_OF_LIGHT
"""The monostatic phase per unit frequency and range, ``4 pi / c``, rad/(m Hz):
a read at carrier f from range d turns by ``4 pi f d / c`` (docs/formats.md section 1)."""


def wrap_angle(angle_rad):
    """Angle(s) wrapped to (-pi, pi], radians (docs/marvel.md section 1).

    ``pi - ((pi - a) mod 2 pi)`` maps -pi to +pi, so the interval is closed
    at +pi as the contract states.
    """
    return np.pi - np.mod(np.pi - np.asarray(angle_rad, dtype=float), 2.0 * np.pi)


def wrap_2pi(angle_rad):
    """Angle(s) wrapped to [0, 2 pi), radians: a reader's reported phase (docs/formats.md section 1)."""
    return np.mod(np.asarray(angle_rad, dtype=float), 2.0 * np.pi)


def round_trip_channel(
    antenna_position: np.ndarray, tag_position: np.ndarray, frequency_hz: np.ndarray, reflectors: list[dict]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Direct distance (m) and multipath round-trip phase excess (rad) and amplitude.

    The one home of the multipath model (docs/formats.md section 1,
    ``[[reflectors]]``): the simulator draws reads with it, ``calibrate``
    fits walls with it, and the Rust trackers' apparent range
    (``scattertrack_core::model::apparent_range``) is its range form,
    ``d + excess / (2 k)``. ``reflectors``: dicts with ``kind`` ("plane":
    ``point``, ``normal``; "point": ``position``) and ``coefficient``.

    Returns ``(distance, excess_rad, amplitude)`` for rows of antenna and tag
    positions (m, shape (n, 3)) and carriers (Hz, (n,)): ``amplitude = |h|``
    (1/m^2) of the round-trip channel ``h = (sum_p a_p e^{-j 2 pi f d_p / c})^2``
    and ``excess = -arg(h e^{+j 4 pi f d / c})`` (rad, 0 without reflectors).
    """
    offset = tag_position - antenna_position
    distance = np.linalg.norm(offset, axis=1)
    wavenumber = 2.0 * np.pi * frequency_hz / SPEED_OF_LIGHT  # rad/m
    # One-way channel relative to the direct path's phase: the direct path
    # contributes 1/d, each reflected path (c_p/d_p) e^{-j k (d_p - d)}.
    relative = (1.0 / distance).astype(complex)
    for reflector in reflectors:
        coefficient = float(reflector["coefficient"])
        if reflector["kind"] == "plane":
            point = np.asarray(reflector["point"], float)
            normal = np.asarray(reflector["normal"], float)
            normal = normal / np.linalg.norm(normal)
            antenna_side = (antenna_position - point) @ normal
            tag_side = (tag_position - point) @ normal
            image = antenna_position - 2.0 * antenna_side[:, None] * normal
            length = np.linalg.norm(tag_position - image, axis=1)
            # A mirror only reflects between points on the same side of it.
            present = antenna_side * tag_side > 0.0
        else:  # point scatterer
            scatterer = np.asarray(reflector["position"], float)
            length = np.linalg.norm(scatterer - antenna_position, axis=1) + np.linalg.norm(
                tag_position - scatterer, axis=1
            )
            present = np.ones(len(distance), dtype=bool)
        path = coefficient / length * np.exp(-1j * wavenumber * (length - distance))
        relative += np.where(present, path, 0.0)
    round_trip = relative**2
    excess = -np.angle(round_trip)
    return distance, excess, np.abs(round_trip)
