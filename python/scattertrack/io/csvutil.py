"""Shared CSV reading and writing for the public formats (docs/formats.md sections 2-4).

What every CSV format shares: a header line with exact lower-case column names
in any order, unknown columns ignored, one row per line, blank lines allowed
only at the end, UTF-8 with or without a byte-order mark, and a
:class:`FormatError` naming the file, the 1-based line and the column for the
first thing that is wrong.

Files are read in chunks of rows so that memory stays proportional to the
parsed arrays, not to millions of Python strings. Within a chunk every column
is converted with one fast pass; only when that pass fails is the column
walked cell by cell to find the first bad cell. A chunk's problems are all
collected before any is raised, so the error reported is the one with the
lowest line (then the leftmost column), whichever check found it.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from itertools import chain, islice
from operator import methodcaller

import numpy as np

from scattertrack.io import cells
from scattertrack.io.types import FormatError

CHUNK_ROWS = 65_536
"""Rows parsed per chunk; large enough for numpy to pay off, small enough for memory."""

_NEEDS_QUOTING = frozenset(',"\r\n')


def _is_blank(row: list[str]) -> bool:
    """True for a row that is an empty or whitespace-only line."""
    return not row or (len(row) == 1 and not row[0].strip())


@dataclass
class Chunk:
    """Up to :data:`CHUNK_ROWS` data rows of one file, and the problems found in them.

    ``columns[k]`` holds the raw cells of the header's k-th column;
    ``lines[i]`` is the 1-based file line where row ``i`` of the chunk starts.
    Conversion methods never raise: they record a problem and put a
    placeholder (nan, 0 or "") in the bad cell; :meth:`raise_first_problem`
    then raises the earliest one.
    """

    path: str
    column_position: dict[str, int]
    """Index of each column in the file's header, by name."""
    columns: list
    lines: list[int] | range
    plain: bool = False
    """Whether every cell is known to be plain ASCII without '_' (:func:`cells.is_plain_ascii`)."""
    problems: list[tuple[int, int, str, str]] = field(default_factory=list)
    """(row index in chunk, column position, column name, message)."""

    def __len__(self) -> int:
        return len(self.lines)

    def line_numbers(self) -> np.ndarray:
        """``lines`` as an int64 array (1-based file line of each row)."""
        if isinstance(self.lines, range):
            return np.arange(self.lines.start, self.lines.stop, dtype=np.int64)
        return np.array(self.lines, dtype=np.int64)

    def has(self, name: str) -> bool:
        """Whether the file has this column."""
        return name in self.column_position

    def cells(self, name: str) -> list[str]:
        """The raw text of one column, one string per row."""
        return self.columns[self.column_position[name]]

    def add_problem(self, row: int, name: str, message: str) -> None:
        """Record a problem in row ``row`` (chunk index) of column ``name``."""
        self.problems.append((row, self.column_position.get(name, -1), name, message))

    def flag(self, name: str, bad: np.ndarray, message: str) -> None:
        """Record the first row where the boolean mask ``bad`` is set.

        ``message`` may contain ``{value}``, replaced by the raw cell text.
        """
        if bad.any():
            row = int(np.argmax(bad))
            value = self.columns[self.column_position[name]][row]
            self.add_problem(row, name, message.format(value=repr(value)))

    def flag_values(self, name: str, values: np.ndarray, bad: np.ndarray, describe) -> None:
        """Like :meth:`flag`, the message being ``describe(cell text, value)``: a hint that depends on the value."""
        if bad.any():
            row = int(np.argmax(bad))
            self.add_problem(row, name, describe(self.cells(name)[row].strip(), float(values[row])))

    def raise_first_problem(self) -> None:
        """Raise the problem with the lowest line, then the leftmost column, if any."""
        if self.problems:
            row, _, name, message = min(self.problems, key=lambda p: (p[0], p[1]))
            raise FormatError(self.path, self.lines[row], name, message)

    def floats(self, name: str, allow_empty: bool = False, allow_nan: bool = False) -> np.ndarray:
        """One column as float64 (ASCII decimal only, see :mod:`scattertrack.io.cells`).

        ``allow_empty``: an empty cell reads as nan (optional columns).
        ``allow_nan``: the word ``nan`` is accepted; infinities never are.
        """
        values, problem = cells.floats(self.cells(name), allow_empty, allow_nan, self.plain)
        self._add_cell_problem(name, problem)
        return values

    def integers(self, name: str, empty: int | None = None) -> np.ndarray:
        """One column as int64: ASCII digits with an optional sign, within int64.

        ``empty``: the value an empty cell reads as (optional columns); None: an empty cell is a problem.
        """
        values, problem = cells.integers(self.cells(name), self.plain, empty)
        self._add_cell_problem(name, problem)
        return values

    def _add_cell_problem(self, name: str, problem: tuple[int, str] | None) -> None:
        if problem is not None:
            self.add_problem(problem[0], name, problem[1])

    def texts(self, name: str, table: cells.TextTable, check=None) -> np.ndarray:
        """One column of stripped texts as int64 codes into ``table`` (see :class:`cells.TextTable`).

        An empty cell is a problem; so is a text for which ``check(text)``
        returns a message (each distinct text is checked once, when first seen).
        """
        texts = [c.strip() for c in self.cells(name)]
        codes, new = table.encode(texts)
        for text in new:
            message = "empty value" if not text else (check(text) if check is not None else None)
            if message is not None:
                self.add_problem(texts.index(text), name, message)
                break
        return codes


class CsvReader:
    """A CSV file opened for reading, header checked; iterate :meth:`chunks`.

    ``required`` columns must be in the header (else an error at line 1);
    ``optional`` ones may be. Other columns are ignored.

    Plain files (no quotes, ``\\n`` or ``\\r\\n`` line ends) are split with
    ``str.split``, several times faster than the csv module; from the first
    chunk that is not plain on, the csv module reads the rest.
    """

    def __init__(self, path, required: list[str], optional: list[str] = (), allow_no_rows: bool = False):
        self.path = str(path)
        self.required = list(required)
        self.optional = list(optional)
        self.allow_no_rows = allow_no_rows
        """Whether a header without data rows is a valid (empty) file, as for a track with no estimates."""
        self.column_position: dict[str, int] = {}
        self.width = 0
        self._file = None
        self._plain = False  # whether the last block from the fast path is plain ASCII (csv's never are)
        self._csv_rows = None  # a csv.reader once the plain fast path no longer applies
        self._last_line = 0  # the last file line consumed

    def __enter__(self) -> "CsvReader":
        if is_parquet(self.path):
            # The Parquet twin is read as the CSV it stands for, so that every
            # check applies alike; its "line N" is table row N - 1.
            self._file = io.StringIO(parquet_as_csv_text(self.path))
            self._read_header()
            return self
        # utf-8-sig drops a byte-order mark; newline="" keeps line ends for csv.
        self._file = open(self.path, newline="", encoding="utf-8-sig")
        self._read_header()
        return self

    def __exit__(self, *exc) -> None:
        self._file.close()

    def _read_header(self) -> None:
        line = self._decode(self._file.readline)
        self._last_line = 1
        while line.count('"') % 2 and line.endswith(("\n", "\r")):
            # A quoted column name spans lines: the header ends where its quotes close.
            more = self._decode(self._file.readline)
            if not more:
                break
            line += more
            self._last_line += 1
        self._header_lines = self._last_line
        header = next(csv.reader([line]), [])
        if _is_blank(header):
            raise FormatError(self.path, 1, None, "empty file: expected a header line")
        header = [name.strip() for name in header]
        self.width = len(header)
        wanted = set(self.required) | set(self.optional)
        for position, name in enumerate(header):
            if name in self.column_position and name in wanted:
                raise FormatError(self.path, 1, name, "column appears twice in the header")
            self.column_position.setdefault(name, position)
        for name in self.required:
            if name not in self.column_position:
                raise FormatError(self.path, 1, name, "missing required column")

    def _decode(self, read):
        """Call ``read()``; a file that is not UTF-8 is a FormatError."""
        try:
            return read()
        except UnicodeDecodeError as error:
            raise FormatError(self.path, None, None, f"not UTF-8 text: {error}") from None

    def chunks(self):
        """Yield :class:`Chunk` objects of data rows in file order.

        Raises for a header with no data rows, a blank line followed by more
        data, and a row with a different number of fields than the header.
        """
        blank_line = None  # line of the first blank line seen, if any
        any_rows = False
        while True:
            columns, lines = self._read_plain() if self._csv_rows is None else (None, None)
            if columns is None:
                rows, lines = self._read_csv()
                if not rows:
                    break
                rows, lines, blank_line = self._check_rows(rows, lines, blank_line)
                columns = list(zip(*rows)) if rows else None
            if columns:
                any_rows = True
                yield Chunk(self.path, self.column_position, columns, lines, plain=self._plain)
        if not any_rows and not self.allow_no_rows:
            raise FormatError(self.path, self._header_lines + 1, None, "no data rows")

    def _read_plain(self):
        """Fast path: up to CHUNK_ROWS lines as columns, or (None, None) to use csv.

        Only taken when every line of the chunk has exactly the header's
        number of fields and nothing needs the csv module's rules.
        """
        text_lines = self._decode(lambda: list(islice(self._file, CHUNK_ROWS)))
        block = "".join(text_lines)
        first = self._last_line + 1
        if "\r" in block:
            block = block.replace("\r\n", "\n")  # Windows line ends; a lone \r goes to csv
        self._plain = False
        if block and '"' not in block and "\r" not in block and self.width > 1:
            if block.endswith("\n"):
                block = block[:-1]
            field_counts = set(map(methodcaller("count", ","), block.split("\n")))
            if field_counts == {self.width - 1}:
                self._last_line += len(text_lines)
                # One scan of the whole block spares each numeric column its own.
                self._plain = cells.is_plain_ascii(block)
                fields = block.replace("\n", ",").split(",")
                columns = [fields[k :: self.width] for k in range(self.width)]
                return columns, range(first, first + len(text_lines))
        # Hand these lines and the rest of the file to the csv module.
        self._csv_rows = csv.reader(chain(text_lines, self._file))
        self._csv_line_base = self._last_line
        return None, None

    def _read_csv(self) -> tuple[list[list[str]], list[int]]:
        """Up to CHUNK_ROWS rows via the csv module and the 1-based line where each starts."""
        rows, end_lines = [], []
        reader = self._csv_rows
        base = self._csv_line_base
        try:
            for row in islice(reader, CHUNK_ROWS):
                rows.append(row)
                end_lines.append(base + reader.line_num)
        except UnicodeDecodeError as error:
            raise FormatError(self.path, None, None, f"not UTF-8 text: {error}") from None
        except csv.Error as error:
            line = base + reader.line_num
            raise FormatError(self.path, line, None, f"bad CSV: {error}") from None
        # A row starts on the line after the previous row ended (quoted cells
        # may span lines, so the row count alone does not give the line).
        start_lines = [self._last_line + 1] + [end + 1 for end in end_lines[:-1]]
        if end_lines:
            self._last_line = end_lines[-1]
        return rows, start_lines

    def _check_rows(self, rows, lines, blank_line):
        """Check field counts row by row; blank lines are fine only if no data follows."""
        kept_rows, kept_lines = [], []
        for row, line in zip(rows, lines):
            if _is_blank(row):
                blank_line = blank_line or line
                continue
            if len(row) != self.width:
                message = f"expected {self.width} fields (as in the header), found {len(row)}"
                raise FormatError(self.path, line, None, message)
            if blank_line is not None:
                raise FormatError(self.path, blank_line, None, "blank line before more data rows")
            kept_rows.append(row)
            kept_lines.append(line)
        return kept_rows, kept_lines, blank_line


def sort_by_time(columns: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], int]:
    """The columns stably sorted by ``columns["time_s"]`` (s), and how many rows were out of order.

    A row is out of order when an earlier row has a later time; equal times keep the file's order.
    """
    time = columns["time_s"]
    latest_before = np.maximum.accumulate(time)
    reordered = int(np.count_nonzero(time[1:] < latest_before[:-1]))
    if reordered:
        order = np.argsort(time, kind="stable")
        columns = {name: values[order] for name, values in columns.items()}
    return columns, reordered


def whole_group(reader: CsvReader, names: list[str]) -> bool:
    """Whether an optional column group (``sx, sy, sz``; ``qw, qx, qy, qz``) is present.

    Half a group is an error naming the first missing column, at line 1.
    """
    present = [name in reader.column_position for name in names]
    if any(present) and not all(present):
        missing = names[present.index(False)]
        raise FormatError(reader.path, 1, missing, f"missing column (needed with {names[0]}..)")
    return all(present)


def format_fixed(values: np.ndarray, decimals: int, empty_nan: bool = False) -> list[str]:
    """Format floats with ``decimals`` places; nan as "" if ``empty_nan`` else "nan"."""
    values = np.asarray(values, dtype=np.float64)
    pattern = f"%.{decimals}f"
    out = [pattern % v for v in values.tolist()]
    if empty_nan:
        for i in np.flatnonzero(np.isnan(values)).tolist():
            out[i] = ""
    return out


def quote_text(value: str) -> str:
    """A text cell, quoted the CSV way only when it contains a comma, quote or line break."""
    if _NEEDS_QUOTING.isdisjoint(value):
        return value
    return '"' + value.replace('"', '""') + '"'


PARQUET_SUFFIX = ".parquet"
TEXT_COLUMNS = frozenset({"epc", "cue"})
"""Columns that stay text in a Parquet twin; the others are typed from their cells."""
_INTEGER_CELL = re.compile(r"[+-]?[0-9]+")


def is_parquet(path) -> bool:
    """Whether ``path`` names a Parquet twin (by its extension)."""
    return str(path).lower().endswith(PARQUET_SUFFIX)


def parquet_as_csv_text(path) -> str:
    """A Parquet file's table as the CSV text of its twin (FormatError if unreadable)."""
    import pyarrow.csv
    import pyarrow.parquet

    try:
        table = pyarrow.parquet.read_table(path)
    except (OSError, ValueError) as error:  # pyarrow's ArrowInvalid is a ValueError
        raise FormatError(str(path), None, None, f"not a readable Parquet file: {error}") from None
    buffer = io.BytesIO()
    pyarrow.csv.write_csv(table, buffer)
    return buffer.getvalue().decode("utf-8")


def _typed(name: str, cells: list[str]):
    """A Parquet column from formatted cells: text, int64 (all integers; empty = null) or float64."""
    import pyarrow

    if name in TEXT_COLUMNS:
        return pyarrow.array(cells, pyarrow.string())
    present = [c for c in cells if c != ""]
    if present and all(_INTEGER_CELL.fullmatch(c) for c in present):
        return pyarrow.array([int(c) if c != "" else None for c in cells], pyarrow.int64())
    return pyarrow.array([float(c) if c != "" else float("nan") for c in cells], pyarrow.float64())


def write_columns(path, header: list[str], columns: list[list[str]]) -> None:
    """Write a CSV file (or its Parquet twin, by extension) from formatted columns (one list of strings each)."""
    if is_parquet(path):
        import pyarrow
        import pyarrow.parquet

        table = pyarrow.table({name: _typed(name, list(cells)) for name, cells in zip(header, columns)} if columns else {name: pyarrow.array([], pyarrow.float64()) for name in header})
        pyarrow.parquet.write_table(table, path)
        return
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(",".join(header) + "\n")
        f.writelines(",".join(row) + "\n" for row in zip(*columns))


def text_column(values) -> list[str]:
    """Strings for a text column such as ``epc``, quoted where needed.

    Each distinct text is quoted once; no fixed-width array is made, whose
    size would follow the longest text (see :class:`cells.TextTable`).
    """
    texts = [str(v) for v in np.asarray(values, dtype=object).reshape(-1).tolist()]
    quoted = {text: quote_text(text) for text in dict.fromkeys(texts)}
    return list(map(quoted.__getitem__, texts))


def repeated_cells(values: np.ndarray, to_text) -> list[str]:
    """``[to_text(v) for v in values]``, computed once per distinct value.

    For columns with few distinct values (tag ids, channel frequencies) this
    is several times faster than formatting every cell.
    """
    if len(values) == 0:
        return []
    distinct, inverse = np.unique(values, return_inverse=True)
    texts = np.array([to_text(v) for v in distinct.tolist()], dtype=object)
    return texts[inverse.reshape(-1)].tolist()


def require_finite(path, name: str, values: np.ndarray) -> None:
    """Refuse to write a non-finite value where the reader would reject it."""
    values = np.asarray(values, dtype=np.float64)
    if not np.isfinite(values).all():
        row = int(np.argmax(~np.isfinite(values)))
        raise ValueError(f"{path}: cannot write {name}[{row}] = {values.flat[row]}: not finite")
