"""Range checks of physical columns that name the unit a wrong value was likely written in.

Files from other programs often carry a carrier frequency in MHz or a phase
in degrees or in a reader's raw units. Such a value is rejected (docs/formats.md:
SI units everywhere) with the likely unit and its conversion, so that the
user can fix the exporter instead of guessing.
"""

from __future__ import annotations

import math

import numpy as np

FREQUENCY_MIN_HZ = 100e6
FREQUENCY_MAX_HZ = 10e9
"""Carriers outside 100 MHz to 10 GHz, hertz, are not RF backscatter (UHF RFID is 860-960 MHz,
LoRa 433 MHz to 2.4 GHz, helpers up to a few GHz): a unit mistake."""

FREQUENCY_UNITS = (
    (100.0, 10e3, "MHz", "1e6"),
    (0.1, 10.0, "GHz", "1e9"),
    (100e3, 10e6, "kHz", "1e3"),
)
"""(low, high, unit, factor): a value in [low, high] is in range once multiplied by the factor."""

DEGREES_MAX = 360.0
IMPINJ_PHASE_UNITS = 4096
"""Impinj readers report phase as an integer 0..4095 (docs/formats.md 2: x * 2*pi / 4096)."""


def frequency_outside(values: np.ndarray) -> np.ndarray:
    """Mask of frequencies (Hz) outside [:data:`FREQUENCY_MIN_HZ`, :data:`FREQUENCY_MAX_HZ`]; nan is not flagged."""
    return (values < FREQUENCY_MIN_HZ) | (values > FREQUENCY_MAX_HZ)


def frequency_message(text: str, value: float) -> str:
    """Why the frequency ``value`` (written as ``text``) is rejected, with the likely unit."""
    message = f"frequency {text} is outside 100 MHz to 10 GHz (frequencies are in hertz)"
    for low, high, unit, factor in FREQUENCY_UNITS:
        if low <= abs(value) <= high:
            return f"{message}: looks like {unit}: multiply by {factor}"
    return message


def phase_message(text: str, value: float, column: np.ndarray, period_rad: float) -> str:
    """Why the phase ``value`` (radians, written as ``text``) is outside [0, P), with the likely unit.

    ``column``: the phases around it (a chunk of the file), which tell degrees
    (all at most 360) from Impinj units (up to 4095) and from (-pi, pi].
    """
    period = "pi" if math.isclose(period_rad, math.pi) else "2*pi"
    message = f"phase {text} is outside [0, {period}) (phases are in radians)"
    finite = column[np.isfinite(column)]
    largest, smallest = float(finite.max()), float(finite.min())
    whole = bool(np.all(finite == np.round(finite)))
    impinj = "divide by 4096 and multiply by 2*pi"
    if value >= period_rad and largest <= DEGREES_MAX and smallest >= 0.0:
        if whole:
            return f"{message}: looks like degrees (multiply by pi/180) or Impinj units (0-4095: {impinj})"
        return f"{message}: looks like degrees: multiply by pi/180"
    if value >= period_rad and largest < IMPINJ_PHASE_UNITS and smallest >= 0.0:
        return f"{message}: looks like Impinj units (0-4095): {impinj}"
    if value < 0.0 and smallest >= -math.pi - 1e-9 and period == "2*pi":
        return f"{message}: looks like (-pi, pi]: add 2*pi to negative phases"
    return message


ACCEL_MAX_M_S2 = 2000.0
"""Specific force beyond this, m/s^2 (about 200 g), is no IMU's reading: drone IMUs saturate at
16 g and shock sensors at a few hundred; a larger value is a unit mistake (milli-g: 9810 at
rest) or garbage, and integrating it overflows the estimator's state."""

GYRO_MAX_RAD_S = 100.0
"""An angular rate beyond this, rad/s (about 5700 deg/s), is no MEMS gyro's reading (they
saturate at 35-70 rad/s): most likely degrees per second."""


def accel_message(text: str, value: float) -> str:
    """Why the specific force ``value`` (m/s^2, written as ``text``) is rejected, with the likely unit."""
    message = f"specific force {text} is beyond {ACCEL_MAX_M_S2:g} m/s^2 (about 200 g): no IMU measures it"
    if abs(value) <= 200 * 9810.0:
        return f"{message}; accelerations are in m/s^2: if this is milli-g (about 1000 at rest), multiply by 9.80665e-3"
    return message


def gyro_message(text: str, value: float) -> str:
    """Why the angular rate ``value`` (rad/s, written as ``text``) is rejected, with the likely unit."""
    message = f"angular rate {text} is beyond {GYRO_MAX_RAD_S:g} rad/s: no MEMS gyro measures it"
    if abs(value) <= GYRO_MAX_RAD_S * 180.0 / math.pi:
        return f"{message}; rates are in rad/s: looks like degrees per second: multiply by pi/180"
    return message


RANGE_MAX_M = 100e3
"""A controller-to-drone range beyond this, metres (100 km), is no backscatter link's (they
reach a few kilometres): garbage, whose square overflows the estimator's solve."""
