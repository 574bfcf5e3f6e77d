"""``reads.csv`` and ``track.csv`` written row by row, as a live run goes.

A live session must lose nothing when it is killed: every row is written
and flushed to the operating system as soon as it is complete, so a crash
leaves a file that :func:`scattertrack.io.read_reads` /
:func:`scattertrack.io.read_track` accept, up to its last whole row (a
partial last line from a hard kill is the only thing a reader would
reject). The cells are formatted as :func:`~scattertrack.io.write_reads`
and :func:`~scattertrack.io.write_track` format them (time and phase with
6 decimals: 1 µs and 1 µrad; frequency in full; RSSI and Doppler with 2);
the header is fixed, with every optional column, so that rows appended
later always fit it. Appending to an existing file checks its header.
"""

from __future__ import annotations

import math
import os

import numpy as np

from scattertrack.io.csvutil import quote_text
from scattertrack.io.reads import OPTIONAL as READ_OPTIONAL
from scattertrack.io.reads import REQUIRED as READ_REQUIRED
from scattertrack.io.reads import epc_problem, phase_cells
from scattertrack.io.track import REQUIRED as TRACK_REQUIRED
from scattertrack.io.track import SIGMA

READ_HEADER = [*READ_REQUIRED, *READ_OPTIONAL, "channel_index"]
"""The journal's columns: ``reads.csv`` with every optional column."""
TRACK_HEADER = [*TRACK_REQUIRED, *SIGMA]


def _cell(value: float, decimals: int) -> str:
    """A float with ``decimals`` places, ``""`` for nan."""
    return "" if math.isnan(value) else f"{value:.{decimals}f}"


class _Appender:
    """A CSV file opened for appending whole, flushed rows under a fixed header."""

    def __init__(self, path, header: list[str]) -> None:
        self.path = os.fspath(path)
        self.rows = 0
        existing = os.path.exists(self.path) and os.path.getsize(self.path) > 0
        if existing:
            with open(self.path, encoding="utf-8", newline="") as f:
                first = f.readline().strip().lstrip("\ufeff")
            if first.split(",") != header:
                raise ValueError(f"{self.path}: line 1: cannot append: its header is {first!r}, expected {','.join(header)!r}")
        self._file = open(self.path, "a", encoding="utf-8", newline="")
        if not existing:
            self._file.write(",".join(header) + "\n")
            self._file.flush()

    def _write(self, cells: list[str]) -> None:
        self._file.write(",".join(cells) + "\n")
        self.rows += 1

    def flush(self) -> None:
        """Hand the written rows to the operating system (they survive a crash of this process)."""
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self._file.flush()
            self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


class ReadsAppender(_Appender):
    """The live journal: one ``reads.csv`` row per read, in arrival order."""

    def __init__(self, path) -> None:
        super().__init__(path, READ_HEADER)

    def append(
        self,
        time_s: float,
        epc: str,
        antenna: int,
        frequency_hz: float,
        phase_rad: float,
        rssi_dbm: float = math.nan,
        doppler_hz: float = math.nan,
        channel_index: int | None = None,
    ) -> tuple[float, float]:
        """Write one read; returns ``(time_s, phase_rad)`` as written (rounded
        to 6 decimals), so a live tracker can use exactly what an offline
        run of the journal will read. Raises ValueError for an EPC or a
        value that ``read_reads`` would reject."""
        problem = epc_problem(epc)
        if problem is not None:
            raise ValueError(f"{self.path}: cannot write {problem}")
        if not (math.isfinite(time_s) and math.isfinite(frequency_hz) and math.isfinite(phase_rad)):
            raise ValueError(f"{self.path}: cannot write a read with a non-finite time, frequency or phase")
        # As write_reads writes it: never rounded up onto π or 2π.
        time_cell, phase_cell = f"{time_s:.6f}", phase_cells(np.array([phase_rad]))[0]
        self._write(
            [
                time_cell,
                epc,
                str(int(antenna)),
                repr(float(frequency_hz)),
                phase_cell,
                _cell(rssi_dbm, 2),
                _cell(doppler_hz, 2),
                "" if channel_index is None else str(int(channel_index)),
            ]
        )
        return float(time_cell), float(phase_cell)


class TrackAppender(_Appender):
    """The live track: one ``track.csv`` row per estimate (with sigmas)."""

    def __init__(self, path) -> None:
        super().__init__(path, TRACK_HEADER)

    def append(self, time_s: float, epc: str, position, velocity, sigma) -> list[str]:
        """Write one estimate: s, m, m/s, m (velocity nan is written ``nan``).
        Returns the row's cells (:data:`TRACK_HEADER`), for outputs that must
        say exactly what the file says."""
        if not all(math.isfinite(v) for v in [time_s, *position]):
            raise ValueError(f"{self.path}: cannot write an estimate with a non-finite time or position")
        cells = track_cells(time_s, epc, position, velocity, sigma)
        self._write(cells)
        return cells


def track_cells(time_s: float, epc: str, position, velocity, sigma) -> list[str]:
    """One ``track.csv`` row's cells (:data:`TRACK_HEADER`), 6 decimals, nan as ``nan``."""
    values = [*position, *velocity, *sigma]
    return [f"{time_s:.6f}", quote_text(epc)] + ["nan" if math.isnan(v) else f"{v:.6f}" for v in values]
