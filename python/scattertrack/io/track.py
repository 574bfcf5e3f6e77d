"""Tracker output, ``track.csv`` (docs/formats.md section 4).

Columns: ``time_s`` (seconds), ``epc`` (tag id), ``x``, ``y``, ``z``
(position, metres), ``vx``, ``vy``, ``vz`` (velocity, m/s; the literal
``nan`` when the method has none), and optionally ``sx``, ``sy``, ``sz``
(1-sigma position uncertainty, metres) and ``qw``, ``qx``, ``qy``, ``qz``
(world_T_body unit quaternion). One row per update, in time order per tag.
"""

from __future__ import annotations

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
from scattertrack.io.types import FormatError, Track

POSITION = ["x", "y", "z"]
VELOCITY = ["vx", "vy", "vz"]
SIGMA = ["sx", "sy", "sz"]
ORIENTATION = ["qw", "qx", "qy", "qz"]
REQUIRED = ["time_s", "epc", *POSITION, *VELOCITY]


def read_track(path) -> Track:
    """Read and validate a ``track.csv``, keeping the file's row order.

    ``nan`` is accepted only in the velocity, sigma and quaternion columns
    (an empty cell also reads as nan in the optional ones). ``sigma`` and
    ``orientation`` are None when their columns are absent; a partial group
    (say ``sx`` without ``sz``) is an error. Each tag's times must not
    decrease. Raises :class:`FormatError` (file, line, column).
    """
    parts = {"time": [], "epc": [], "position": [], "velocity": [], "sigma": [], "q": []}
    lines = []
    table = TextTable()
    # A tracker that never committed to an estimate writes the header alone: a valid, empty track.
    with CsvReader(path, REQUIRED, SIGMA + ORIENTATION, allow_no_rows=True) as reader:
        has_sigma = whole_group(reader, SIGMA)
        has_orientation = whole_group(reader, ORIENTATION)
        for chunk in reader.chunks():
            parts["time"].append(chunk.floats("time_s"))
            parts["epc"].append(chunk.texts("epc", table))
            parts["position"].append(np.column_stack([chunk.floats(n) for n in POSITION]))
            velocity = [chunk.floats(n, allow_nan=True) for n in VELOCITY]
            parts["velocity"].append(np.column_stack(velocity))
            if has_sigma:
                sigma = [chunk.floats(n, allow_empty=True, allow_nan=True) for n in SIGMA]
                parts["sigma"].append(np.column_stack(sigma))
            if has_orientation:
                q = [chunk.floats(n, allow_empty=True, allow_nan=True) for n in ORIENTATION]
                parts["q"].append(np.column_stack(q))
            chunk.raise_first_problem()
            lines.append(chunk.line_numbers())
    widths = {"time": 0, "epc": 0, "position": 3, "velocity": 3, "sigma": 3, "q": 4}
    columns = {name: _joined(chunks, widths[name]) for name, chunks in parts.items()}
    track = Track(
        time_s=columns["time"],
        epc=table.decode(columns["epc"]),
        position=columns["position"],
        velocity=columns["velocity"],
        sigma=columns["sigma"] if has_sigma else None,
        orientation=columns["q"] if has_orientation else None,
    )
    _check_time_order(path, track, _joined(lines, 0))
    return track


def _joined(chunks: list[np.ndarray], width: int) -> np.ndarray:
    """The chunks of one column joined; shape (0,) or (0, width) for a track without rows."""
    if chunks:
        return np.concatenate(chunks)
    return np.zeros((0, width) if width else 0)


def _check_time_order(path, track: Track, lines: np.ndarray) -> None:
    """Each tag's rows must be in time order (docs/formats.md 4); name the first that is not."""
    order = np.lexsort((np.arange(len(track)), track.epc))  # by tag, file order kept
    time = track.time_s[order]
    same_tag = track.epc[order][1:] == track.epc[order][:-1]
    backwards = same_tag & (time[1:] < time[:-1])
    if backwards.any():
        row = int(order[1:][backwards].min())
        raise FormatError(
            path, int(lines[row]), "time_s", f"time goes backwards for tag {track.epc[row]!r}"
        )


def write_track(path, track: Track) -> None:
    """Write ``track`` as ``track.csv``, all floats with 6 decimals (s, m, m/s).

    ``sx..sz`` are written only when ``track.sigma`` is set, ``qw..qz`` only
    when ``track.orientation`` is; nan is written as ``nan``.
    """
    position = np.asarray(track.position, dtype=np.float64).reshape(-1, 3)
    velocity = np.asarray(track.velocity, dtype=np.float64).reshape(-1, 3)
    require_finite(path, "time_s", track.time_s)
    require_finite(path, "position", position)
    require_finite(path, "velocity", velocity[~np.isnan(velocity)])
    header = list(REQUIRED)
    columns = [format_fixed(np.asarray(track.time_s, dtype=np.float64), 6), text_column(track.epc)]
    columns += [format_fixed(position[:, k], 6) for k in range(3)]
    columns += [format_fixed(velocity[:, k], 6) for k in range(3)]
    for names, values in ((SIGMA, track.sigma), (ORIENTATION, track.orientation)):
        if values is None:
            continue
        values = np.asarray(values, dtype=np.float64).reshape(-1, len(names))
        require_finite(path, names[0] + "..", values[~np.isnan(values)])
        header += names
        columns += [format_fixed(values[:, k], 6) for k in range(len(names))]
    write_columns(path, header, columns)
