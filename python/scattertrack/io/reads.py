"""Tag reads, ``reads.csv`` (docs/formats.md section 2).

One row per phase reading: ``time_s`` (seconds), ``epc`` (tag id),
``antenna`` (port id from the scene), ``frequency_hz`` (carrier, hertz),
``phase_rad`` (radians in [0, P)), and optionally ``rssi_dbm`` (dBm),
``doppler_hz`` (hertz) and ``channel_index`` (the reader's own 1-based index
into its hop table, LLRP's ``ChannelIndex``; an empty cell for none).
"""

from __future__ import annotations

import math
import re

import numpy as np

from scattertrack.io import hop_table, units
from scattertrack.io.cells import TextTable
from scattertrack.io.csvutil import (
    CsvReader,
    format_fixed,
    repeated_cells,
    require_finite,
    sort_by_time,
    text_column,
    write_columns,
)
from scattertrack.io.timeline import warn_clock_jumps
from scattertrack.io.types import Reads, Scene, SkipReport, warn_input

REQUIRED = ["time_s", "epc", "antenna", "frequency_hz", "phase_rad"]
OPTIONAL = ["rssi_dbm", "doppler_hz"]
CHANNEL_INDEX = "channel_index"
"""The optional integer column: the reader's 1-based hop-table index (empty cell: none, -1 in :class:`Reads`)."""

PHASE_TOLERANCE_RAD = 1e-9
"""Phases this far outside [0, P), radians, are rounding noise: accepted and wrapped."""

KEY_COLUMNS = REQUIRED
"""Columns that make two rows the same read (rssi and doppler may differ)."""

HEX = re.compile(r"[0-9A-Fa-f]+")
"""An EPC: hex digits of any length, either case (kept as written)."""
BYTES_LITERAL = re.compile(r"b(['\"]).*\1")
"""``b'E200'``: how Python prints bytes; a future importer may unwrap it, reads.csv does not."""

DUPLICATE = "duplicate row"
"""The SkipReport reason for a read identical to an earlier one."""


def read_reads(path, scene: Scene | None = None) -> Reads:
    """Read and validate a ``reads.csv``; rows come back stably sorted by time.

    With a ``scene``, antenna ids must be ones it defines and phases must lie
    in [0, P) for its reader's period P (radians); without one, P = 2*pi.
    EPCs are hex of any length and case, kept exactly as written; frequencies
    must lie in 100 MHz to 10 GHz; channel indices are positive integers
    (``Reads.channel_index`` is None when the file has no such column).
    Exact duplicates of an earlier read are
    skipped and counted under ``"duplicate row"``; rows out of time order are
    counted in ``reordered``. Raises :class:`FormatError` (file, line, column)
    for a malformed file; issues an :class:`InputWarning` for a clock jump
    (:mod:`scattertrack.io.timeline`), for EPCs that differ only in case and
    for rows whose frequency disagrees with the scene's hop table for their
    channel index (kept; :mod:`scattertrack.io.hop_table`).
    """
    period = 2.0 * math.pi
    antenna_ids = None
    if scene is not None:
        period = scene.reader.period_rad
        antenna_ids = np.array([a.id for a in scene.antennas], dtype=np.int64)
    parts = []
    lines = []
    epcs = TextTable()
    with CsvReader(path, REQUIRED, OPTIONAL + [CHANNEL_INDEX]) as reader:
        for chunk in reader.chunks():
            part = parse_chunk(chunk, period, antenna_ids, epcs)
            chunk.raise_first_problem()
            parts.append(part)
            lines.append(chunk.line_numbers())
    columns = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
    lines = np.concatenate(lines)
    warn_clock_jumps(path, columns["time_s"], lines)
    warn_case_twins(path, epcs, columns["epc"], lines)
    if scene is not None and CHANNEL_INDEX in columns:
        hop_table.warn_disagreements(path, columns["frequency_hz"], columns[CHANNEL_INDEX], lines, scene.hop_table)
    return _finish(columns, lines, epcs.texts())


def parse_chunk(chunk, period: float, antenna_ids: np.ndarray | None, epcs: TextTable) -> dict:
    """Convert and check one chunk's columns (``epc`` as codes into ``epcs``); problems are recorded in the chunk.

    Shared by :func:`read_reads` and the stream (:mod:`scattertrack.io.reads_chunks`), so both check alike.
    """
    time = chunk.floats("time_s")
    epc = chunk.texts("epc", epcs, check=epc_problem)
    antenna = chunk.integers("antenna")
    if antenna_ids is not None:
        chunk.flag("antenna", ~np.isin(antenna, antenna_ids), "antenna {value} is not in the scene")
    frequency = chunk.floats("frequency_hz")
    chunk.flag_values("frequency_hz", frequency, units.frequency_outside(frequency), units.frequency_message)
    phase = chunk.floats("phase_rad")
    outside = phase_outside(phase, period)
    chunk.flag_values("phase_rad", phase, outside, lambda text, value: units.phase_message(text, value, phase, period))
    phase = fold_phase(phase, period)
    optional = {}
    for name in OPTIONAL:
        if chunk.has(name):
            optional[name] = chunk.floats(name, allow_empty=True)
        else:
            optional[name] = np.full(len(chunk), math.nan)
    if chunk.has(CHANNEL_INDEX):
        index = chunk.integers(CHANNEL_INDEX, empty=hop_table.NO_CHANNEL)
        written = np.array([bool(c.strip()) for c in chunk.cells(CHANNEL_INDEX)])
        chunk.flag(CHANNEL_INDEX, written & (index < 1),
                   "channel index {value} is not positive (the reader's 1-based hop-table index; empty cell for none)")
        optional[CHANNEL_INDEX] = index
    return {
        "time_s": time,
        "epc": epc,
        "antenna": antenna,
        "frequency_hz": frequency,
        "phase_rad": phase,
        **optional,
    }


def phase_outside(phase: np.ndarray, period: float) -> np.ndarray:
    """Mask of phases (radians) outside [0, P) by more than :data:`PHASE_TOLERANCE_RAD`."""
    return (phase < -PHASE_TOLERANCE_RAD) | (phase >= period + PHASE_TOLERANCE_RAD)


def fold_phase(phase: np.ndarray, period: float) -> np.ndarray:
    """Phases within the tolerance of [0, P) folded into it: rounding noise, not a reading."""
    phase = np.where(phase >= period, phase - period, phase)
    return np.where(phase < 0.0, 0.0, phase)


def epc_problem(epc: str) -> str | None:
    """Why ``epc`` is not a hex EPC, or None if it is one."""
    if HEX.fullmatch(epc):
        return None
    if BYTES_LITERAL.fullmatch(epc):
        return (f"EPC {epc!r} looks like a Python bytes literal: write the hex digits alone "
                f"({epc[2:-1]!r}); EPCs are hex digits 0-9, a-f, A-F")
    odd = next((c for c in epc if not (c.isascii() and c.isprintable())), None)
    if odd is not None:
        return f"EPC {epc!r} holds the control or non-ASCII character U+{ord(odd):04X}; EPCs are hex digits 0-9, a-f, A-F"
    return f"EPC {epc!r} is not hex: EPCs are hex digits 0-9, a-f, A-F (any length, either case)"


def warn_case_twins(path, epcs: TextTable, codes: np.ndarray, lines: np.ndarray) -> None:
    """Warn when two EPCs differ only in letter case: they are tracked as two tags."""
    first_of: dict[str, str] = {}
    for epc in epcs.code_of:
        twin = first_of.setdefault(epc.upper(), epc)
        if twin != epc:
            line = int(lines[int(np.argmax(codes == epcs.code_of[epc]))])
            warn_input(path, line, "epc", f"EPC {epc!r} differs from {twin!r} only in letter case: "
                                          "they are kept as written and tracked as two tags")
            return


def _finish(columns: dict, lines: np.ndarray, epc_table: np.ndarray) -> Reads:
    """Skip exact duplicates, count out-of-order rows and sort stably by time.

    ``columns["epc"]`` holds codes into ``epc_table`` until the end, where
    they become the shared strings (see :class:`scattertrack.io.cells.TextTable`).
    """
    skipped = SkipReport()
    duplicate = duplicate_rows(columns)
    for i in np.flatnonzero(duplicate).tolist():
        skipped.add(DUPLICATE, int(lines[i]))
    if duplicate.any():
        columns = {name: values[~duplicate] for name, values in columns.items()}
    columns, reordered = sort_by_time(columns)
    return Reads(
        time_s=columns["time_s"],
        epc=epc_table[columns["epc"]],
        antenna=columns["antenna"],
        frequency_hz=columns["frequency_hz"],
        phase_rad=columns["phase_rad"],
        rssi_dbm=columns["rssi_dbm"],
        doppler_hz=columns["doppler_hz"],
        skipped=skipped,
        reordered=reordered,
        channel_index=columns.get(CHANNEL_INDEX),
    )


def duplicate_rows(columns: dict) -> np.ndarray:
    """Mask of rows equal to an earlier row in time, epc, antenna, frequency and phase.

    Vectorised: the rows are sorted by those columns with the file order as
    the last key, so that copies lie next to each other with the first copy
    (in file order) first; every row equal to its predecessor is a
    duplicate. Text columns are compared through their codes. (A Python
    loop over the rows that share a time took 9 s of a 5.9 M-read file.)
    """
    time = np.asarray(columns["time_s"])
    n = len(time)
    duplicate = np.zeros(n, dtype=bool)
    if n < 2:
        return duplicate
    # Copies share their time and distinct reads rarely do: only rows whose
    # time occurs more than once are compared in full.
    by_time = np.argsort(time, kind="stable")
    same_time = time[by_time][1:] == time[by_time][:-1]
    candidates = np.unique(np.concatenate([by_time[1:][same_time], by_time[:-1][same_time]]))
    if not candidates.size:
        return duplicate
    keys = []
    for name in KEY_COLUMNS:
        values = np.asarray(columns[name])[candidates]
        if values.dtype.kind in "OUS":
            values = np.unique(values.astype(str), return_inverse=True)[1]
        keys.append(values)
    # np.lexsort sorts by the last key first: time, epc, ... then file order
    # (candidates are ascending), so the first copy of a row comes first.
    order = np.lexsort((np.arange(len(candidates)), *reversed(keys)))
    same = np.ones(len(candidates) - 1, dtype=bool)
    for values in keys:
        ordered = values[order]
        same &= ordered[1:] == ordered[:-1]
    duplicate[candidates[order[1:][same]]] = True
    return duplicate


def write_reads(path, reads: Reads) -> None:
    """Write ``reads`` as ``reads.csv``.

    Time (seconds) and phase (radians) with 6 decimals, frequency (hertz) in
    full, RSSI (dBm) and Doppler (hertz) with 2 decimals; the optional columns
    only when some value is finite, with an empty cell for nan; ``channel_index``
    when some row has one (an empty cell for -1).
    """
    for name in ("time_s", "frequency_hz", "phase_rad"):
        require_finite(path, name, getattr(reads, name))
    _require_readable(path, reads)
    header = list(REQUIRED)
    columns = [
        format_fixed(reads.time_s, 6),
        text_column(reads.epc),
        repeated_cells(np.asarray(reads.antenna, dtype=np.int64), str),
        repeated_cells(np.asarray(reads.frequency_hz, dtype=np.float64), repr),
        phase_cells(reads.phase_rad),
    ]
    for name in OPTIONAL:
        values = np.asarray(getattr(reads, name), dtype=np.float64)
        if np.isfinite(values).any():
            require_finite(path, name, values[~np.isnan(values)])
            header.append(name)
            columns.append(format_fixed(values, 2, empty_nan=True))
    if reads.channel_index is not None:
        index = np.asarray(reads.channel_index, dtype=np.int64)
        if (index != hop_table.NO_CHANNEL).any():
            bad = (index != hop_table.NO_CHANNEL) & (index < 1)
            if bad.any():
                raise ValueError(f"{path}: cannot write channel_index[{int(np.argmax(bad))}] = "
                                 f"{int(index[np.argmax(bad)])}: channel indices are positive (-1 for none)")
            header.append(CHANNEL_INDEX)
            columns.append(["" if i == hop_table.NO_CHANNEL else str(i) for i in index.tolist()])
    write_columns(path, header, columns)


def _require_readable(path, reads: Reads) -> None:
    """Refuse (ValueError) EPCs and frequencies that :func:`read_reads` would reject."""
    for epc in dict.fromkeys(np.asarray(reads.epc, dtype=object).tolist()):
        problem = epc_problem(str(epc))
        if problem is not None:
            raise ValueError(f"{path}: cannot write {problem}")
    frequency = np.asarray(reads.frequency_hz, dtype=np.float64)
    outside = units.frequency_outside(frequency)
    if outside.any():
        value = float(frequency[np.argmax(outside)])
        raise ValueError(f"{path}: cannot write {units.frequency_message(repr(value), value)}")


def phase_cells(phase_rad: np.ndarray) -> list[str]:
    """Phases with 6 decimals, never rounded up onto the period.

    A phase just below pi or 2*pi would round up to a value at or above the
    period, which readers reject; such values are truncated instead (the
    error stays below 1e-6 rad either way).
    """
    phase = np.asarray(phase_rad, dtype=np.float64)
    cells = format_fixed(phase, 6)
    for period in (math.pi, 2.0 * math.pi):
        near = (phase < period) & (phase > period - 1e-6)
        for i in np.flatnonzero(near).tolist():
            if float(cells[i]) >= period:
                cells[i] = "%.6f" % (math.floor(phase[i] * 1e6) / 1e6)
    return cells
