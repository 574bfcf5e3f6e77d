"""Backscatter pose features, ``features.csv`` (docs/formats.md section 7).

One row per sensing epoch: ``time_s`` (seconds, the IMU's clock),
``range_m`` (controller-to-drone distance, metres), ``azimuth_rad`` and
``elevation_rad`` (direction of the drone from the controller's array,
world frame, radians) and optionally ``yaw_rad`` (heading of body x about
+z, radians), ``range_sigma_m`` (metres), ``angle_sigma_rad`` and
``yaw_sigma_rad`` (radians): the 1-sigma of each. In the optional columns an
empty cell means "none for this row" (nan in :class:`Features`); a written
``nan`` is an error like any other non-finite number.

Checks: ``range_m`` and the sigmas must be positive, ``range_m`` and
``range_sigma_m`` at most 100 km, the angle sigmas at most 2 pi and
``elevation_rad`` within [-pi/2, pi/2]. Rows out of time order are sorted (stably) and counted
in ``Features.reordered``.
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.io import units
from scattertrack.io.csvutil import CsvReader, format_fixed, require_finite, sort_by_time, write_columns
from scattertrack.io.timeline import warn_clock_jumps
from scattertrack.io.types import Features

REQUIRED = ["time_s", "range_m", "azimuth_rad", "elevation_rad"]
OPTIONAL = ["yaw_rad", "range_sigma_m", "angle_sigma_rad", "yaw_sigma_rad"]
SIGMAS = ["range_sigma_m", "angle_sigma_rad", "yaw_sigma_rad"]

SIGMA_MAX = {
    "range_sigma_m": (units.RANGE_MAX_M, "100 km"),
    "angle_sigma_rad": (2.0 * math.pi, "2*pi rad"),
    "yaw_sigma_rad": (2.0 * math.pi, "2*pi rad"),
}
"""Largest meaningful sigma of each column (limit, as the message words it): a range sigma beyond
any link's range, an angle sigma beyond a full turn."""

ELEVATION_TOLERANCE_RAD = 1e-9
"""Rounding allowance beyond +-pi/2 for the elevation, radians."""


def read_features(path) -> Features:
    """Read and validate a ``features.csv``; rows come back stably sorted by time.

    Raises :class:`FormatError` (file, line, column) for a missing column, a
    non-numeric or non-finite cell, a non-positive range or sigma, an
    elevation outside [-pi/2, pi/2], or a file without data rows; warns
    (:class:`InputWarning`) at a clock jump (:mod:`scattertrack.io.timeline`).
    """
    parts: dict[str, list] = {name: [] for name in REQUIRED + OPTIONAL}
    lines = []
    with CsvReader(path, REQUIRED, OPTIONAL) as reader:
        for chunk in reader.chunks():
            values = {name: chunk.floats(name) for name in REQUIRED}
            for name in OPTIONAL:
                if chunk.has(name):
                    values[name] = chunk.floats(name, allow_empty=True)
                else:
                    values[name] = np.full(len(chunk), math.nan)
            chunk.flag("range_m", ~(values["range_m"] > 0.0) & np.isfinite(values["range_m"]),
                       "range must be positive: {value}")
            chunk.flag("range_m", values["range_m"] > units.RANGE_MAX_M,
                       f"range {{value}} m is beyond {units.RANGE_MAX_M / 1e3:g} km: no backscatter link reaches it "
                       "(ranges are in metres)")
            limit = math.pi / 2.0 + ELEVATION_TOLERANCE_RAD
            chunk.flag("elevation_rad", np.abs(values["elevation_rad"]) > limit,
                       "elevation outside [-pi/2, pi/2]: {value}")
            for name in SIGMAS:
                if chunk.has(name):
                    chunk.flag(name, values[name] <= 0.0, "sigma must be positive: {value}")
                    limit, unit = SIGMA_MAX[name]
                    chunk.flag(name, values[name] > limit,
                               f"sigma {{value}} is beyond {unit}: that wide a 1-sigma carries no information (and its "
                               "square overflows); write a plausible one or leave the cell empty")
            chunk.raise_first_problem()
            for name, column in values.items():
                parts[name].append(column)
            lines.append(chunk.line_numbers())
    columns = {name: np.concatenate(chunks) for name, chunks in parts.items()}
    columns["line"] = np.concatenate(lines)
    warn_clock_jumps(path, columns["time_s"], columns["line"])
    columns, reordered = sort_by_time(columns)
    return Features(**columns, reordered=reordered)


def write_features(path, features: Features) -> None:
    """Write ``features`` as ``features.csv``.

    Time (s) and range (m) with 6 decimals, angles (rad) with 8, sigmas with
    6. An optional column is written only when some value in it is finite; a
    nan (no yaw in this epoch) is an empty cell.
    """
    header, columns = [], []
    for name, decimals in (("time_s", 6), ("range_m", 6), ("azimuth_rad", 8), ("elevation_rad", 8)):
        values = np.asarray(getattr(features, name), dtype=np.float64)
        require_finite(path, name, values)
        header.append(name)
        columns.append(format_fixed(values, decimals))
    for name in OPTIONAL:
        values = np.asarray(getattr(features, name), dtype=np.float64)
        if not np.isfinite(values).any():
            continue
        require_finite(path, name, values[~np.isnan(values)])
        header.append(name)
        columns.append(format_fixed(values, 8 if name == "yaw_rad" else 6, empty_nan=True))
    write_columns(path, header, columns)
