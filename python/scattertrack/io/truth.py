"""Ground truth, ``truth.csv`` (docs/formats.md section 3).

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
from scattertrack.io.types import Truth, warn_input

POSITION = ["x", "y", "z"]
VELOCITY = ["vx", "vy", "vz"]
ORIENTATION = ["qw", "qx", "qy", "qz"]
REQUIRED = ["time_s", "epc", *POSITION]
MIN_RATE_HZ = 100.0
"""Truth should be sampled at least this often, Hz (docs/formats.md 3), for linear interpolation."""


def read_truth(path) -> Truth:
    """Read and validate a ``truth.csv``; rows are stably sorted by time.

    Velocity (m/s) is nan where its column is absent or its cell is empty;
    ``orientation`` is None without the quaternion columns, else (n, 4)
    with nan where a row's cells are empty. Raises :class:`FormatError` (file, line, column) for a malformed file;
    warns (:class:`InputWarning`) for a tag sampled below 100 Hz or with rows at one time that disagree.
    """
    times, epcs, positions, velocities, orientations, lines = [], [], [], [], [], []
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
            lines.append(chunk.line_numbers())
    time = np.concatenate(times)
    codes = np.concatenate(epcs)
    position = np.concatenate(positions)
    _warn_sampling(path, time, codes, position, np.concatenate(lines), table.texts())
    # Keep the file's order among equal times: truth of several tags may interleave.
    order = np.argsort(time, kind="stable")
    return Truth(
        time_s=time[order],
        epc=table.decode(codes[order]),
        position=position[order],
        velocity=np.concatenate(velocities)[order],
        orientation=np.concatenate(orientations)[order] if has_orientation else None,
    )


def _warn_sampling(path, time, codes, position, lines, names) -> None:
    """Warn (:class:`InputWarning`) about truth that evaluation cannot interpolate faithfully.

    Per tag (``codes`` index ``names``): a median spacing of distinct times
    longer than 1 / :data:`MIN_RATE_HZ` seconds, and two rows at one time
    with different positions (evaluation uses the first in the file).
    """
    order = np.lexsort((np.arange(len(time)), time, codes))  # by tag, then time, file order kept
    time, codes, position, lines = time[order], codes[order], position[order], lines[order]
    same_tag = codes[1:] == codes[:-1]
    step = np.diff(time)
    conflict = same_tag & (step == 0.0) & np.any(position[1:] != position[:-1], axis=1)
    if conflict.any():
        row = int(np.argmax(conflict)) + 1
        warn_input(path, int(lines[row]), "time_s",
                   f"tag {names[codes[row]]!r} has rows at time {time[row]:.6f} s with different positions "
                   f"(line {int(lines[row - 1])} and this one): the first is used; "
                   f"{int(np.count_nonzero(conflict))} such rows in the file")
    starts = np.flatnonzero(np.concatenate([[True], ~same_tag]))
    for start, end in zip(starts, [*starts[1:], len(time)]):
        spacing = step[start : end - 1]
        spacing = spacing[spacing > 0.0]
        # The 1e-6 margin keeps 100 Hz written in decimal (0.01 s steps) from warning.
        if len(spacing) and np.median(spacing) > (1.0 + 1e-6) / MIN_RATE_HZ:
            rate = 1.0 / float(np.median(spacing))
            warn_input(path, int(lines[start]), "time_s",
                       f"truth of tag {names[codes[start]]!r} is sampled at {rate:.3g} Hz (median spacing "
                       f"{1.0 / rate:.4g} s), below the {MIN_RATE_HZ:g} Hz that docs/formats.md asks for: "
                       "linear interpolation between rows adds error to the evaluation")


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
