"""Inertial samples, ``imu.csv`` (docs/formats.md section 6).

Columns: ``time_s`` (seconds, the features' clock), ``ax``, ``ay``, ``az``
(specific force in the body frame, m/s^2; at rest about ``(0, 0, +9.81)``),
``gx``, ``gy``, ``gz`` (angular rate in the body frame, rad/s) and
optionally ``baro_z`` (barometric height, metres; an empty cell is no
reading).

Rows may arrive out of time order (a logger that flushes several buffers);
they are sorted stably by time and counted in ``Imu.reordered``, as reads
and features are. After sorting, a sample whose time equals an earlier
one's is declined (``"duplicate time"``: an integrator cannot step by zero)
and counted in ``Imu.skipped`` with its line; the first in the file is kept.
Gaps longer than 3 nominal periods (the median spacing) are counted in
``Imu.gaps``. A clock that jumps back by more than a second is also warned
(:mod:`scattertrack.io.timeline`): sorting then mixes two sessions.
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.io import units
from scattertrack.io.csvutil import CsvReader, format_fixed, require_finite, sort_by_time, write_columns
from scattertrack.io.timeline import warn_clock_jumps
from scattertrack.io.types import Imu, SkipReport

ACCEL = ["ax", "ay", "az"]
GYRO = ["gx", "gy", "gz"]
REQUIRED = ["time_s", *ACCEL, *GYRO]
OPTIONAL = ["baro_z"]

DUPLICATE = "duplicate time"
"""SkipReport reason: a sample at the same time as an earlier one."""
GAP_PERIODS = 3.0
"""A spacing longer than this many nominal sample periods is a gap."""


def read_imu(path) -> Imu:
    """Read and validate an ``imu.csv``; returns samples in strictly increasing time.

    Rows out of time order are sorted (``Imu.reordered``); repeated times
    are declined (``Imu.skipped``). Raises :class:`FormatError` (file, line,
    column) for a missing column, a non-numeric or non-finite cell (``nan``
    included; an empty ``baro_z`` is allowed and reads as nan), a specific
    force beyond 2000 m/s^2 or a rate beyond 100 rad/s (no sensor's: a unit
    mistake, :mod:`scattertrack.io.units`) or a file without data rows;
    warns (:class:`InputWarning`) at a clock jump (:mod:`scattertrack.io.timeline`).
    """
    parts: dict[str, list] = {"time_s": [], "accel": [], "gyro": [], "baro_z": [], "line": []}
    with CsvReader(path, REQUIRED, OPTIONAL) as reader:
        for chunk in reader.chunks():
            parts["time_s"].append(chunk.floats("time_s"))
            parts["accel"].append(np.column_stack([_checked(chunk, name, units.ACCEL_MAX_M_S2, units.accel_message)
                                                   for name in ACCEL]))
            parts["gyro"].append(np.column_stack([_checked(chunk, name, units.GYRO_MAX_RAD_S, units.gyro_message)
                                                  for name in GYRO]))
            if chunk.has("baro_z"):
                parts["baro_z"].append(chunk.floats("baro_z", allow_empty=True))
            else:
                parts["baro_z"].append(np.full(len(chunk), math.nan))
            chunk.raise_first_problem()
            parts["line"].append(chunk.line_numbers())
    columns = {name: np.concatenate(values) for name, values in parts.items()}
    warn_clock_jumps(path, columns["time_s"], columns["line"])
    columns, reordered = sort_by_time(columns)
    keep, skipped = _first_of_each_time(columns["time_s"], columns["line"])
    time = columns["time_s"][keep]
    return Imu(
        time_s=time,
        accel=columns["accel"][keep],
        gyro=columns["gyro"][keep],
        baro_z=columns["baro_z"][keep],
        skipped=skipped,
        gaps=count_gaps(time),
        reordered=reordered,
    )


def _checked(chunk, name: str, limit: float, describe) -> np.ndarray:
    """One inertial column, a value beyond ``limit`` in magnitude recorded as a problem (no sensor's)."""
    values = chunk.floats(name)
    chunk.flag_values(name, values, np.abs(values) > limit, describe)
    return values


def _first_of_each_time(time: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, SkipReport]:
    """Mask of the samples (sorted stably by time) whose time differs from the previous one's,
    and the report of the others (``"duplicate time"``, with their file lines in file order)."""
    duplicate = np.concatenate([[False], time[1:] == time[:-1]])
    skipped = SkipReport()
    lines = np.sort(line[duplicate])
    for number in lines[:5].tolist():
        skipped.add(DUPLICATE, int(number))
    if len(lines) > 5:
        skipped.add(DUPLICATE, None, n=len(lines) - 5)
    return ~duplicate, skipped


def count_gaps(time_s: np.ndarray) -> int:
    """Spacings longer than :data:`GAP_PERIODS` nominal periods (the median spacing), seconds."""
    if len(time_s) < 3:
        return 0
    spacing = np.diff(time_s)
    nominal = float(np.median(spacing))
    # The 1e-6 margin keeps a spacing of exactly 3 periods, written in decimal, from counting.
    return int(np.count_nonzero(spacing > GAP_PERIODS * nominal * (1.0 + 1e-6)))


def write_imu(path, imu: Imu) -> None:
    """Write ``imu`` as ``imu.csv``: time (s) and accelerations (m/s^2) with 6 decimals,
    rates (rad/s) with 8, barometric height (m) with 4; ``baro_z`` only when some is finite
    (a nan one is an empty cell).
    """
    time = np.asarray(imu.time_s, dtype=np.float64)
    accel = np.asarray(imu.accel, dtype=np.float64).reshape(-1, 3)
    gyro = np.asarray(imu.gyro, dtype=np.float64).reshape(-1, 3)
    require_finite(path, "time_s", time)
    require_finite(path, "accel", accel)
    require_finite(path, "gyro", gyro)
    if len(time) and np.any(np.diff(time) <= 0.0):
        raise ValueError(f"{path}: IMU times must increase strictly")
    header = list(REQUIRED)
    columns = [format_fixed(time, 6)]
    columns += [format_fixed(accel[:, k], 6) for k in range(3)]
    columns += [format_fixed(gyro[:, k], 8) for k in range(3)]
    baro = np.asarray(imu.baro_z, dtype=np.float64).reshape(-1) if imu.baro_z is not None else None
    if baro is not None and np.isfinite(baro).any():
        require_finite(path, "baro_z", baro[~np.isnan(baro)])
        header.append("baro_z")
        columns.append(format_fixed(baro, 4, empty_nan=True))
    write_columns(path, header, columns)
