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
