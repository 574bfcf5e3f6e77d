"""Wideband channel frames, ``frames.csv`` (docs/formats.md section 5).

What the SDR localization helper's one-shot channel estimation produces:
one row per (frame, receive antenna, subcarrier) with ``time_s`` (frame
time, seconds), ``epc`` (tag id), ``tx`` and ``rx`` (antenna ids of the
helper's transmit and receive antennas, from the scene), ``frequency_hz``
(subcarrier, hertz) and ``h_re``, ``h_im`` (the calibrated tag channel,
reflective minus non-reflective, dimensionless). One *frame* is every row
with the same ``(time_s, epc)``: one tag reply seen by every receive antenna.

Convention: one path of length ``d = |tx - tag| + |tag - rx|`` gives
``h(f) = a exp(-j 2 pi f d / c)`` with ``a > 0`` real, ``c = 299792458 m/s``
(physics in :mod:`scattertrack.sim.wideband`).

In memory a :class:`Frames` is columnar: one numpy array per column, rows
sorted by ``(time_s, epc, rx, frequency_hz)``, and ``frame_start`` offsets
so that frame ``k`` is rows ``frame_start[k]:frame_start[k + 1]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scattertrack.io import units
from scattertrack.io.cells import TextTable
from scattertrack.io.csvutil import (
    CsvReader,
    repeated_cells,
    require_finite,
    text_column,
    write_columns,
)
from scattertrack.io.timeline import warn_clock_jumps
from scattertrack.io.types import Scene, SkipReport

REQUIRED = ["time_s", "epc", "tx", "rx", "frequency_hz", "h_re", "h_im"]

KEY_COLUMNS = ("time_s", "epc", "rx", "frequency_hz")
"""Columns that make two rows the same measurement (the channel may differ)."""

DUPLICATE = "duplicate row"
"""The SkipReport reason for a row whose (time_s, epc, rx, frequency_hz) came earlier in the file."""

HUGE_CHANNEL = 1e100
"""A channel component beyond this (dimensionless) is declined: a calibrated tag channel is a
path loss, far below 1, and the power |h|^2 of a larger one leaves float64 too little headroom
(max 1.8e308) for the sums over a frame's rows that every tracker forms, which then overflow
to inf and silently yield no estimate."""

HUGE = "channel beyond 1e100"
"""The SkipReport reason for a row with a :data:`HUGE_CHANNEL` component."""

CHANNEL_FORMAT = "%.8e"
"""How ``h_re`` and ``h_im`` are written: 9 significant digits, a relative
rounding of 5e-9, far below any channel estimate's noise."""


@dataclass
class Frames:
    """Wideband channel frames (``frames.csv``), columnar.

    Rows are sorted by ``(time_s, epc, rx, frequency_hz)``; frame ``k`` (one
    tag reply) is rows ``frame_start[k]:frame_start[k + 1]``, so
    ``frame_start`` has ``n_frames + 1`` entries, the last being ``len(self)``.
    Build one from arrays with :func:`make_frames`, which sorts and groups.
    """

    time_s: np.ndarray
    """Frame time, seconds, float64 (n,)."""
    epc: np.ndarray
    """Tag id (n,): strings, an object array from :func:`read_frames` (each distinct id stored once)."""
    tx: np.ndarray
    """Transmit antenna id (scene ``role = "tx"``), int64 (n,)."""
    rx: np.ndarray
    """Receive antenna id (scene ``role = "rx"``), int64 (n,)."""
    frequency_hz: np.ndarray
    """Subcarrier frequency, hertz, float64 (n,)."""
    h: np.ndarray
    """Calibrated tag channel (reflective minus non-reflective), complex128 (n,)."""
    frame_start: np.ndarray
    """Row offsets of the frames, int64 (n_frames + 1,)."""
    skipped: SkipReport = field(default_factory=SkipReport)
    """Rows the reader declined (duplicates), by reason, with file lines."""
    reordered: int = 0
    """How many rows were out of time order in the file (sorted, not dropped)."""

    def __len__(self) -> int:
        """Number of rows (frame x receive antenna x subcarrier)."""
        return len(self.time_s)

    @property
    def n_frames(self) -> int:
        return len(self.frame_start) - 1

    @property
    def frame_time_s(self) -> np.ndarray:
        """Time of each frame, seconds (n_frames,)."""
        return self.time_s[self.frame_start[:-1]]

    @property
    def frame_epc(self) -> np.ndarray:
        """Tag of each frame (n_frames,)."""
        return self.epc[self.frame_start[:-1]]

    def frame(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rows of frame ``k``: ``(rx ids, frequencies Hz, h)``, each (rows,), sorted by (rx, f).

        ``scene.antenna_index(rx_id)`` maps an id to the scene's antenna list.
        """
        rows = slice(int(self.frame_start[k]), int(self.frame_start[k + 1]))
        return self.rx[rows], self.frequency_hz[rows], self.h[rows]

    def frame_grid(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Frame ``k`` as a grid: ``(rx ids (R,), frequencies Hz (F,), h (R, F))``.

        ``R`` and ``F`` are the distinct receive antennas and subcarriers of
        this frame, ascending; a (rx, subcarrier) pair the frame lacks is nan.
        """
        rx, frequency, h = self.frame(k)
        rx_ids, row = np.unique(rx, return_inverse=True)
        frequencies, column = np.unique(frequency, return_inverse=True)
        grid = np.full((len(rx_ids), len(frequencies)), np.nan + 1j * np.nan, dtype=np.complex128)
        grid[row, column] = h
        return rx_ids, frequencies, grid

    def epcs(self) -> list[str]:
        """Distinct tags in order of first appearance."""
        _, first = np.unique(self.epc, return_index=True)
        return [str(self.epc[i]) for i in sorted(first)]

    def select_frames(self, mask_or_index) -> "Frames":
        """A new Frames with the frames (not rows) picked by a mask or index over frames."""
        picked = np.arange(self.n_frames)[mask_or_index]
        counts = np.diff(self.frame_start)[picked]
        starts = self.frame_start[picked]
        # Row indices of the picked frames, in order: start of each frame plus 0..count-1.
        rows = np.repeat(starts - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts) + np.arange(counts.sum())
        return Frames(
            time_s=self.time_s[rows],
            epc=self.epc[rows],
            tx=self.tx[rows],
            rx=self.rx[rows],
            frequency_hz=self.frequency_hz[rows],
            h=self.h[rows],
            frame_start=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        )


def make_frames(time_s, epc, tx, rx, frequency_hz, h) -> Frames:
    """Frames from row arrays (n,): sorted stably by (time_s, epc, rx, frequency_hz), grouped.

    Does not look for duplicates (:func:`read_frames` does); units as in :class:`Frames`.
    """
    time_s = np.asarray(time_s, dtype=np.float64).reshape(-1)
    epc = np.asarray(epc, dtype=str).reshape(-1)
    tx = np.asarray(tx, dtype=np.int64).reshape(-1)
    rx = np.asarray(rx, dtype=np.int64).reshape(-1)
    frequency_hz = np.asarray(frequency_hz, dtype=np.float64).reshape(-1)
    h = np.asarray(h, dtype=np.complex128).reshape(-1)
    n = len(time_s)
    if not all(len(column) == n for column in (epc, tx, rx, frequency_hz, h)):
        raise ValueError("make_frames: every column must have the same length")
    order = np.lexsort((frequency_hz, rx, epc, time_s))
    if np.any(order != np.arange(n)):
        time_s, epc, tx, rx, frequency_hz, h = (c[order] for c in (time_s, epc, tx, rx, frequency_hz, h))
    return Frames(time_s, epc, tx, rx, frequency_hz, h, _frame_starts(time_s, epc))


def _frame_starts(time_s: np.ndarray, epc: np.ndarray) -> np.ndarray:
    """Offsets (n_frames + 1,) of the (time_s, epc) groups of sorted rows."""
    n = len(time_s)
    if n == 0:
        return np.zeros(1, dtype=np.int64)
    new = (time_s[1:] != time_s[:-1]) | (epc[1:] != epc[:-1])
    return np.concatenate([[0], np.flatnonzero(new) + 1, [n]]).astype(np.int64)


# --------------------------------------------------------------------------
# reading


def read_frames(path, scene: Scene | None = None) -> Frames:
    """Read and validate a ``frames.csv``; rows come back sorted and grouped into frames.

    With a ``scene``, ``tx`` must be the id of an antenna with ``role = "tx"``
    and ``rx`` one with ``role = "rx"``. Rows repeating an earlier row's
    ``(time_s, epc, rx, frequency_hz)`` are skipped and counted under
    ``"duplicate row"`` (the first in the file is kept), rows with a channel
    component beyond :data:`HUGE_CHANNEL` under ``"channel beyond 1e100"``
    (what is left of their frame is the tracker's to use or decline); rows
    out of time order are counted in ``reordered`` and sorted. Raises
    :class:`FormatError` (file, line, column) for a missing column, a
    non-numeric or non-finite value, a frequency outside 100 MHz to 10 GHz, an antenna
    that is not in the scene or has the wrong role, or an empty file.
    """
    roles = None
    if scene is not None:
        roles = {int(a.id): a.role for a in scene.antennas}
    parts, lines = [], []
    epcs = TextTable()
    with CsvReader(path, REQUIRED) as reader:
        for chunk in reader.chunks():
            part = _parse_chunk(chunk, roles, epcs)
            chunk.raise_first_problem()
            parts.append(part)
            lines.append(chunk.line_numbers())
    columns = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
    columns["epc"] = epcs.decode(columns["epc"])
    lines = np.concatenate(lines)
    warn_clock_jumps(path, columns["time_s"], lines)
    return _finish(columns, lines)


def _check_antennas(chunk, name: str, ids: np.ndarray, roles: dict, wanted: str) -> None:
    """Flag ids the scene lacks, and ids whose antenna has another role than ``wanted``."""
    known = np.array(sorted(roles), dtype=np.int64)
    chunk.flag(name, ~np.isin(ids, known), "antenna {value} is not in the scene")
    for role in sorted(set(roles.values()) - {wanted}):
        other = np.array([i for i, r in roles.items() if r == role], dtype=np.int64)
        chunk.flag(
            name,
            np.isin(ids, other),
            f"antenna {{value}} has role {role!r} in the scene; column {name!r} needs a {wanted!r} antenna",
        )


def _parse_chunk(chunk, roles: dict | None, epcs: TextTable) -> dict:
    """Convert and check one chunk's columns (``epc`` as codes into ``epcs``); problems are recorded in the chunk."""
    time = chunk.floats("time_s")
    epc = chunk.texts("epc", epcs)
    tx = chunk.integers("tx")
    rx = chunk.integers("rx")
    if roles is not None:
        _check_antennas(chunk, "tx", tx, roles, "tx")
        _check_antennas(chunk, "rx", rx, roles, "rx")
    frequency = chunk.floats("frequency_hz")
    chunk.flag_values("frequency_hz", frequency, units.frequency_outside(frequency), units.frequency_message)
    channel = np.empty(len(chunk), dtype=np.complex128)
    channel.real = chunk.floats("h_re")
    channel.imag = chunk.floats("h_im")
    return {
        "time_s": time,
        "epc": epc,
        "tx": tx,
        "rx": rx,
        "frequency_hz": frequency,
        "h": channel,
    }


def _finish(columns: dict, lines: np.ndarray) -> Frames:
    """Count out-of-order rows, sort by the key, skip duplicates (first in the file kept) and huge channels."""
    time = columns["time_s"]
    # A row is out of order when an earlier row of the file has a later time.
    latest_before = np.maximum.accumulate(time)
    reordered = int(np.count_nonzero(time[1:] < latest_before[:-1]))
    # lexsort is stable: among equal keys the earlier file row comes first.
    order = np.lexsort(tuple(columns[name] for name in reversed(KEY_COLUMNS)))
    columns = {name: values[order] for name, values in columns.items()}
    lines = lines[order]
    same_as_previous = np.ones(len(order) - 1, dtype=bool)
    for name in KEY_COLUMNS:
        values = columns[name]
        same_as_previous &= values[1:] == values[:-1]
    duplicate = np.concatenate([[False], same_as_previous])
    h = columns["h"]
    huge = ~duplicate & (np.maximum(np.abs(h.real), np.abs(h.imag)) > HUGE_CHANNEL)
    skipped = SkipReport()
    for reason, mask in ((DUPLICATE, duplicate), (HUGE, huge)):
        for line in np.sort(lines[mask]).tolist():
            skipped.add(reason, int(line))
    declined = duplicate | huge
    if declined.any():
        columns = {name: values[~declined] for name, values in columns.items()}
    frames = Frames(
        time_s=columns["time_s"],
        epc=columns["epc"],
        tx=columns["tx"],
        rx=columns["rx"],
        frequency_hz=columns["frequency_hz"],
        h=columns["h"],
        frame_start=_frame_starts(columns["time_s"], columns["epc"]),
        skipped=skipped,
        reordered=reordered,
    )
    return frames


# --------------------------------------------------------------------------
# writing


def write_frames(path, frames: Frames) -> None:
    """Write ``frames`` as ``frames.csv`` in their row order.

    Time (seconds) with 6 decimals (1 microsecond, as the simulators stamp
    frames), frequency (hertz) in full, the channel with
    :data:`CHANNEL_FORMAT`. Refuses (ValueError) a non-finite value, which
    the reader would reject.
    """
    h = np.asarray(frames.h, dtype=np.complex128)
    for name, values in (("time_s", frames.time_s), ("frequency_hz", frames.frequency_hz)):
        require_finite(path, name, values)
    require_finite(path, "h_re", h.real)
    require_finite(path, "h_im", h.imag)
    columns = [
        # Every row of a frame shares its time: format each distinct time once.
        repeated_cells(np.asarray(frames.time_s, dtype=np.float64), lambda t: "%.6f" % t),
        text_column(frames.epc),
        repeated_cells(np.asarray(frames.tx, dtype=np.int64), str),
        repeated_cells(np.asarray(frames.rx, dtype=np.int64), str),
        repeated_cells(np.asarray(frames.frequency_hz, dtype=np.float64), repr),
        _channel_cells(h.real),
        _channel_cells(h.imag),
    ]
    write_columns(path, REQUIRED, columns)


def _channel_cells(values: np.ndarray) -> list[str]:
    """Channel components as text with :data:`CHANNEL_FORMAT` (numpy's vectorised formatter)."""
    if len(values) == 0:
        return []
    return np.char.mod(CHANNEL_FORMAT, values).tolist()

