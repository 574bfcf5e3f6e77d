"""Ground truth, ``truth.csv`` (FORMATS.md section 3).

Columns: ``time_s`` (seconds, the reads' clock), ``epc`` (tag id),
``x``, ``y``, ``z`` (position, metres) and optionally ``vx``, ``vy``, ``vz``
(velocity, m/s), and optionally ``qw``, ``qx``, ``qy``, ``qz`` (orientation,
world_T_body unit quaternion, for drones: docs/marvel.md section 1). A
partial quaternion group (``qw`` without ``qz``) is an error; other columns
are ignored.
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.io.cells import TextTable
from scattertrack.io.csvutil import (
    CsvReader,
    whole_group,
    format_fixed,
    require_finite,
    text_column,
    write_columns,
)
from scattertrack.io.types import Truth

POSITION = ["x", "y", "z"]
VELOCITY = ["vx", "vy", "vz"]
ORIENTATION = ["qw", "qx", "qy", "qz"]
REQUIRED = ["time_s", "epc", *POSITION]


def read_truth(path) -> Truth:
    """Read and validate a ``truth.csv``; rows are stably sorted by time.

    Velocity (m/s) is nan where its column is absent or its cell is empty;
    ``orientation`` is None without the quaternion columns, else (n, 4)
    with nan where a row's cells are empty. Raises :class:`FormatError` (file, line, column) for a malformed file.
    """
    times, epcs, positions, velocities, orientations = [], [], [], [], []
    table = TextTable()
    with CsvReader(path, REQUIRED, VELOCITY + ORIENTATION) as reader:
        has_orientation = whole_group(reader, ORIENTATION)
        for chunk in reader.chunks():
            times.append(chunk.floats("time_s"))
            epcs.append(chunk.texts("epc", table))
            positions.append(np.column_stack([chunk.floats(name) for name in POSITION]))
            velocity = [
                chunk.floats(name, allow_empty=True)
                if chunk.has(name)
                else np.full(len(chunk), math.nan)
                for name in VELOCITY
            ]
            velocities.append(np.column_stack(velocity))
            if has_orientation:
                q = [chunk.floats(name, allow_empty=True) for name in ORIENTATION]
                orientations.append(np.column_stack(q))
            chunk.raise_first_problem()
    time = np.concatenate(times)
    # Keep the file's order among equal times: truth of several tags may interleave.
    order = np.argsort(time, kind="stable")
    return Truth(
        time_s=time[order],
        epc=table.decode(np.concatenate(epcs)[order]),
        position=np.concatenate(positions)[order],
        velocity=np.concatenate(velocities)[order],
        orientation=np.concatenate(orientations)[order] if has_orientation else None,
    )


def write_truth(path, truth: Truth) -> None:
    """Write ``truth`` as ``truth.csv``: time (s), position (m), velocity (m/s), 6 decimals.

    The velocity columns are written only when some velocity is finite; a nan
    velocity is an empty cell. ``qw..qz`` (6 decimals) are written when
    ``truth.orientation`` is set.
    """
    position = np.asarray(truth.position, dtype=np.float64).reshape(-1, 3)
    velocity = np.asarray(truth.velocity, dtype=np.float64).reshape(-1, 3)
    require_finite(path, "time_s", truth.time_s)
    require_finite(path, "position", position)
    header = list(REQUIRED)
    columns = [format_fixed(np.asarray(truth.time_s, dtype=np.float64), 6), text_column(truth.epc)]
    columns += [format_fixed(position[:, k], 6) for k in range(3)]
    if np.isfinite(velocity).any():
        require_finite(path, "velocity", velocity[~np.isnan(velocity)])
        header += VELOCITY
        columns += [format_fixed(velocity[:, k], 6, empty_nan=True) for k in range(3)]
    if truth.orientation is not None:
        orientation = np.asarray(truth.orientation, dtype=np.float64).reshape(-1, 4)
        require_finite(path, "orientation", orientation[~np.isnan(orientation)])
        orientation = np.round(orientation, 6) + 0.0  # no "-0.000000" for components that are 0 up to rounding
        header += ORIENTATION
        columns += [format_fixed(orientation[:, k], 6, empty_nan=True) for k in range(4)]
    write_columns(path, header, columns)
