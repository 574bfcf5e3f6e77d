"""``reads.csv`` read as a stream of time-ordered batches (docs/formats.md section 2).

The same file, checks and messages as :func:`scattertrack.io.read_reads`
(the chunks are parsed by the very same functions, :func:`reads.parse_chunk`),
but memory follows the read rate, not the recording's length: rows wait in a
reorder window of :data:`REORDER_WINDOW_S` behind the latest time seen, and
are released stably sorted by time once no later row can precede them.

What the window cannot promise is refused, never changed: a row more than
the window behind the latest time (a clock jump back, which the in-memory
reader warns about) raises :class:`NeedsWholeFile`, and so does a scene with
a hop table for a file with ``channel_index`` (whose check counts the whole
file); the caller then reads the file whole. Exact duplicates share their
time, so they are always found within the window.
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.io import hop_table, timeline, units
from scattertrack.io import reads as reads_format
from scattertrack.io.cells import TextTable
from scattertrack.io.csvutil import CsvReader, is_parquet
from scattertrack.io.types import Scene, SkipReport

REORDER_WINDOW_S = timeline.BACKWARD_JUMP_S
"""Seconds a row may lag the latest time before it and still be sorted in the stream.

The in-memory reader warns of a clock jump beyond this lag; the stream hands such a file back."""

TRACKED = ("time_s", "epc", "antenna", "frequency_hz", "phase_rad", "line")
"""The columns a batch carries: what a tracker needs, and each row's 1-based file line."""


ARROW_BLOCK_BYTES = 4 << 20
"""Bytes of CSV text pyarrow parses at a time (about 70,000 reads)."""


class NeedsWholeFile(Exception):
    """The file needs the in-memory reader (the reason is the message); nothing it says is an error."""


class NeedsCheckedReader(Exception):
    """pyarrow's fast path met a cell it does not take as :func:`io.read_reads` would: read with the checked reader.

    Raised before any row of the offending block is released; the caller
    starts over with ``ReadsStream(..., fast=False)``, whose errors and
    warnings are those of ``io.read_reads`` (the file's true line and column).
    """


class ReadsStream:
    """Iterate to get batches (dicts of :data:`TRACKED` columns, ``epc`` as int64 tag codes), sorted by time.

    Tag codes count EPCs in order of first appearance (:attr:`epc_texts`).
    After the iteration: :attr:`rows` (reads kept), :attr:`reordered` (rows out
    of time order, sorted), :attr:`skipped` (duplicates, with lines), and the
    warnings :func:`io.read_reads` issues have been issued.
    """

    def __init__(self, path, scene: Scene | None = None, fast: bool = True):
        self.path = path
        self.fast = fast and not is_parquet(path)
        """Parse with pyarrow's CSV reader (:meth:`_arrow_parts`); any doubt raises :class:`NeedsCheckedReader`."""
        self.scene = scene
        self.period = scene.reader.period_rad if scene is not None else 2.0 * math.pi
        self.antenna_ids = None if scene is None else np.array([a.id for a in scene.antennas], dtype=np.int64)
        self.epcs = TextTable()
        self.first_line: list[int] = []
        """1-based line of each tag code's first row (the case-twin warning names it)."""
        self.skipped = SkipReport()
        self.rows = 0
        self.reordered = 0
        self._latest = -math.inf  # the latest time of any row so far (running maximum)
        self._gaps = []  # (step, latest before, time, line) of each forward clock gap, first one first
        self._pending = None  # rows inside the reorder window, in file order

    @property
    def epc_texts(self) -> list[str]:
        """Each tag code's EPC, as written."""
        return list(self.epcs.code_of)

    def __iter__(self):
        with CsvReader(self.path, reads_format.REQUIRED, reads_format.OPTIONAL + [reads_format.CHANNEL_INDEX]) as reader:
            # The header is checked here either way: its errors are read_reads' own.
            present = [n for n in reads_format.OPTIONAL + [reads_format.CHANNEL_INDEX] if n in reader.column_position]
            if (self.scene is not None and self.scene.hop_table
                    and reads_format.CHANNEL_INDEX in reader.column_position):
                raise NeedsWholeFile("the hop-table check counts disagreements over the whole file")
            parts = self._arrow_parts(present) if self.fast else self._checked_parts(reader)
            any_rows = False
            for part in parts:
                any_rows = any_rows or len(part["time_s"]) > 0
                ready = self._admit({name: part[name] for name in TRACKED})
                if ready is not None:
                    yield ready
            if self.fast and not any_rows:
                # A header alone: the checked reader words that error (file, line).
                raise NeedsCheckedReader("no data rows")
        if self._pending is not None and len(self._pending["time_s"]):
            yield _sorted(self._pending)
        self._pending = None
        self._warn_at_end()

    def _checked_parts(self, reader: CsvReader):
        """Parsed chunks from :class:`CsvReader`, checked as :func:`io.read_reads` checks them."""
        for chunk in reader.chunks():
            known = len(self.epcs.code_of)
            part = reads_format.parse_chunk(chunk, self.period, self.antenna_ids, self.epcs)
            chunk.raise_first_problem()
            part["line"] = chunk.line_numbers()
            self._note_new_tags(part, known)
            yield part

    def _arrow_parts(self, optional: list[str]):
        """Parsed blocks from pyarrow's streaming CSV reader, for a file every check passes.

        Only what the checked reader would read alike is taken: numbers
        pyarrow parses (correctly rounded, as ``float()``) that are finite and
        in range, integers, EPCs that are hex without spaces, one line per row
        (a quoted line break, a blank line or a ragged row is a pyarrow error).
        Anything else raises :class:`NeedsCheckedReader`, whose reader words the error.
        """
        import pyarrow as pa
        import pyarrow.csv as pacsv

        names = reads_format.REQUIRED + optional
        types = {"time_s": pa.float64(), "epc": pa.string(), "antenna": pa.int64(), "frequency_hz": pa.float64(),
                 "phase_rad": pa.float64(), "rssi_dbm": pa.float64(), "doppler_hz": pa.float64(),
                 reads_format.CHANNEL_INDEX: pa.int64()}
        try:
            blocks = pacsv.open_csv(
                self.path,
                read_options=pacsv.ReadOptions(block_size=ARROW_BLOCK_BYTES, use_threads=True),
                parse_options=pacsv.ParseOptions(newlines_in_values=False, ignore_empty_lines=False),
                convert_options=pacsv.ConvertOptions(column_types={n: types[n] for n in names}, include_columns=names,
                                                     null_values=[""], strings_can_be_null=False,
                                                     quoted_strings_can_be_null=False),
            )
            line = 2
            while True:
                try:
                    block = blocks.read_next_batch()
                except StopIteration:
                    return
                known = len(self.epcs.code_of)
                part = self._arrow_block(block, optional)
                part["line"] = np.arange(line, line + block.num_rows, dtype=np.int64)
                line += block.num_rows
                self._note_new_tags(part, known)
                yield part
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError, UnicodeDecodeError) as error:
            raise NeedsCheckedReader(str(error)) from None

    def _arrow_block(self, block, optional: list[str]) -> dict:
        import pyarrow as pa

        def column(name):
            return block.column(block.schema.get_field_index(name))

        part = {}
        for name in ("time_s", "frequency_hz", "phase_rad", "antenna"):
            values = column(name)
            if values.null_count:
                raise NeedsCheckedReader(f"an empty {name} cell")
            part[name] = values.to_numpy(zero_copy_only=False)
        for name in ("time_s", "frequency_hz", "phase_rad"):
            if not np.isfinite(part[name]).all():
                raise NeedsCheckedReader(f"a non-finite {name} cell")
        if self.antenna_ids is not None and not np.isin(part["antenna"], self.antenna_ids).all():
            raise NeedsCheckedReader("an antenna the scene lacks")
        if units.frequency_outside(part["frequency_hz"]).any():
            raise NeedsCheckedReader("a frequency out of range")
        if reads_format.phase_outside(part["phase_rad"], self.period).any():
            raise NeedsCheckedReader("a phase out of range")
        part["phase_rad"] = reads_format.fold_phase(part["phase_rad"], self.period)
        for name in optional:
            values = column(name).to_numpy(zero_copy_only=False)
            if name == reads_format.CHANNEL_INDEX:
                values = np.where(np.isnan(values), hop_table.NO_CHANNEL, values) if values.dtype.kind == "f" else values
                if ((values < 1) & (values != hop_table.NO_CHANNEL)).any():
                    raise NeedsCheckedReader("a channel index below 1")
            elif np.isinf(values).any() or (np.isnan(values).sum() != column(name).null_count):
                raise NeedsCheckedReader(f"a non-finite {name} cell")
        epc = column("epc").dictionary_encode()
        if isinstance(epc, pa.ChunkedArray):
            epc = epc.combine_chunks()
        texts = epc.dictionary.to_pylist()
        for text in texts:
            if text not in self.epcs.code_of and (text != text.strip() or reads_format.epc_problem(text) is not None):
                raise NeedsCheckedReader("an EPC the checked reader words")
        codes, _ = self.epcs.encode(texts)
        part["epc"] = codes[epc.indices.to_numpy(zero_copy_only=False)]
        return part

    def _note_new_tags(self, part: dict, known: int) -> None:
        codes = part["epc"]
        new, first = np.unique(codes[codes >= known], return_index=True)
        if new.size:
            lines = part["line"][codes >= known][first]
            self.first_line.extend(lines[np.argsort(new)].tolist())

    def _admit(self, part: dict) -> dict | None:
        """Take one parsed chunk (file order); return the rows now safe to release, sorted by time."""
        time = part["time_s"]
        # The file's first row has no row before it: it is its own latest.
        carried = time[0] if self._latest == -math.inf else self._latest
        latest_before = np.maximum.accumulate(np.concatenate([[carried], time]))[:-1]
        step = time - latest_before
        if np.any(step < -REORDER_WINDOW_S):
            raise NeedsWholeFile(f"rows more than {REORDER_WINDOW_S:g} s out of time order")
        gaps = np.flatnonzero(step > timeline.FORWARD_GAP_S)
        self._gaps.extend((step[i], latest_before[i], time[i], part["line"][i]) for i in gaps.tolist())
        self._latest = max(self._latest, float(time.max()))
        combined = part if self._pending is None else {n: np.concatenate([self._pending[n], part[n]]) for n in TRACKED}
        # Earlier rows were checked among themselves: only the chunk's own rows
        # can be new copies, of a row with the same time.
        fresh = len(time)
        held = len(combined["time_s"]) - fresh
        compared = np.concatenate([np.isin(combined["time_s"][:held], time), np.ones(fresh, dtype=bool)])
        duplicate = np.zeros(len(compared), dtype=bool)
        duplicate[compared] = reads_format.duplicate_rows({n: combined[n][compared] for n in reads_format.KEY_COLUMNS})
        new_duplicate = duplicate[held:]
        for line in part["line"][new_duplicate].tolist():
            self.skipped.add(reads_format.DUPLICATE, int(line))
        self.reordered += int(np.count_nonzero((step < 0) & ~new_duplicate))
        self.rows += int(fresh - np.count_nonzero(new_duplicate))
        if duplicate.any():
            combined = {n: values[~duplicate] for n, values in combined.items()}
        # A later row lags the latest time by at most the window: rows before that are final.
        final = combined["time_s"] < self._latest - REORDER_WINDOW_S
        self._pending = {n: values[~final] for n, values in combined.items()}
        if not final.any():
            return None
        return _sorted({n: values[final] for n, values in combined.items()})

    def _warn_at_end(self) -> None:
        """The warnings that need the whole file: forward clock gaps and EPCs that differ only in case."""
        if self._gaps:
            # The first gap and how many there are is all the warning says; a
            # small column with those gaps alone words it as the file would.
            step, latest, time, line = self._gaps[0]
            times = [latest, time] + [time + 2.0 * (k + 1) * timeline.FORWARD_GAP_S for k in range(len(self._gaps) - 1)]
            lines = [0, line] + [0] * (len(self._gaps) - 1)
            timeline.warn_clock_jumps(self.path, np.array(times), np.array(lines))
        codes = np.arange(len(self.first_line))
        reads_format.warn_case_twins(self.path, self.epcs, codes, np.array(self.first_line, dtype=np.int64))


def _sorted(columns: dict) -> dict:
    """The columns stably sorted by time (equal times keep the file's order)."""
    order = np.argsort(columns["time_s"], kind="stable")
    return {n: values[order] for n, values in columns.items()}
