"""Converting CSV cells to numbers and to interned texts, a whole column at a time.

Numbers are ASCII decimal only: an optional sign, digits with an optional
decimal point, an optional exponent (``1.5``, ``-2``, ``.5``, ``3e-4``),
with optional spaces or tabs around them. Python's ``float()`` and ``int()``
accept more: digit group separators (``1_0.5`` reads as 10.5), digits of
other scripts (a full-width ``３`` reads as 3) and the words ``nan`` and
``inf``. A file from another program that holds such a cell almost surely
means something else, so it is an error here. The words ``nan`` (any case,
optional sign) are accepted only where a column allows them; infinities
never are (docs/formats.md: non-finite values are rejected).

The fast path converts the column with ``float()``/``int()`` over the whole
list and then rules out the extra forms with two C-speed scans of the
column's text (``isascii`` and a search for ``_``); the words are caught by
the finiteness check that follows. Only a column that fails is walked cell
by cell, up to its first bad cell, to say exactly what is wrong with it.
"""

from __future__ import annotations

import math
import re

import numpy as np

NUMBER = re.compile(r"[ \t]*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?[ \t]*")
INTEGER = re.compile(r"[ \t]*[+-]?[0-9]+[ \t]*")
NAN_WORD = re.compile(r"[ \t]*[+-]?nan[ \t]*", re.IGNORECASE)
INFINITY_WORD = re.compile(r"[ \t]*[+-]?inf(?:inity)?[ \t]*", re.IGNORECASE)

INT64_MIN = -(2**63)
INT64_MAX = 2**63 - 1
"""Integer cells (antenna ids) must fit in a signed 64-bit integer, as the trackers store them."""

ASCII_HINT = "numbers are ASCII decimal: sign, digits, '.', exponent"


def is_plain_ascii(text: str) -> bool:
    """True when ``text`` holds no character that float()/int() read beyond ASCII decimal.

    Non-ASCII characters (other scripts' digits, non-breaking spaces) and
    ``_`` (digit grouping) are the only ways a cell that float() accepts
    can be outside :data:`NUMBER`, apart from the nan/inf words.
    """
    return text.isascii() and "_" not in text


def floats(cells: list[str], allow_empty: bool, allow_nan: bool, plain: bool) -> tuple[np.ndarray, tuple[int, str] | None]:
    """A column as float64 and its first problem as (row, message), or None.

    ``plain``: the caller knows the cells are :func:`is_plain_ascii` already.
    ``allow_empty``: an empty cell reads as nan. ``allow_nan``: the word
    ``nan`` is accepted. Values after the first problem are placeholders (nan).
    """
    values = None
    if plain or is_plain_ascii("".join(cells)):
        values = _floats_fast(cells, allow_empty)
    if values is None:
        return _floats_one_by_one(cells, allow_empty, allow_nan)
    bad = np.isinf(values) if allow_nan else ~np.isfinite(values)
    if bad.any() and allow_empty:
        # An empty cell also reads as nan: only a written nan or inf is bad.
        bad &= np.array([bool(c.strip()) for c in cells])
    if bad.any():
        row = int(np.argmax(bad))
        return values, (row, f"not a finite number: {cells[row]!r}")
    return values, None


def _floats_fast(cells: list[str], allow_empty: bool) -> np.ndarray | None:
    """float() over every cell (empty cells as nan if allowed), or None if any cell fails."""
    try:
        return np.array(list(map(float, cells)), dtype=np.float64)
    except ValueError:
        pass
    if allow_empty:
        try:
            return np.array([float(c) if c.strip() else math.nan for c in cells], dtype=np.float64)
        except ValueError:
            pass
    return None


def _floats_one_by_one(cells, allow_empty, allow_nan) -> tuple[np.ndarray, tuple[int, str] | None]:
    """Convert cell by cell up to the first bad cell; return the values and that problem."""
    values = np.full(len(cells), math.nan)
    for row, text in enumerate(cells):
        if allow_empty and not text.strip():
            continue
        if NUMBER.fullmatch(text) or (allow_nan and NAN_WORD.fullmatch(text)):
            values[row] = float(text)
            continue
        return values, (row, _number_problem(text, allow_nan))
    return values, None


def _number_problem(text: str, allow_nan: bool = False) -> str:
    """Why ``text`` is not an acceptable number, for the error message."""
    if not text.strip():
        return "empty value"
    if INFINITY_WORD.fullmatch(text) or NAN_WORD.fullmatch(text):
        return f"not a finite number: {text!r}"
    odd = next((c for c in text if not c.isascii()), None)
    if odd is not None:
        return f"not a number: {text!r}: {odd!r} (U+{ord(odd):04X}) is not ASCII; {ASCII_HINT}"
    if "_" in text:
        return f"not a number: {text!r}: '_' digit separators are not allowed; {ASCII_HINT}"
    return f"not a number: {text!r}"


def integers(cells: list[str], plain: bool, empty: int | None = None) -> tuple[np.ndarray, tuple[int, str] | None]:
    """A column as int64 and its first problem as (row, message), or None.

    Values must fit in int64 (:data:`INT64_MIN` to :data:`INT64_MAX`).
    ``empty``: the value an empty cell reads as (optional columns); None: an empty cell is a problem.
    """
    if plain or is_plain_ascii("".join(cells)):
        try:
            if empty is None:
                return np.array(list(map(int, cells)), dtype=np.int64), None
            return np.array([int(c) if c.strip() else empty for c in cells], dtype=np.int64), None
        except (ValueError, OverflowError):
            pass
    values = np.zeros(len(cells), dtype=np.int64)
    for row, text in enumerate(cells):
        if empty is not None and not text.strip():
            values[row] = empty
            continue
        if not INTEGER.fullmatch(text):
            if NUMBER.fullmatch(text):
                return values, (row, f"not an integer: {text!r}")
            return values, (row, _number_problem(text).replace("not a number", "not an integer", 1))
        value = int(text)
        if not INT64_MIN <= value <= INT64_MAX:
            return values, (row, f"integer out of range: {text.strip()!r} (ids must fit in a signed 64-bit integer, "
                                 f"{INT64_MIN} to {INT64_MAX})")
        values[row] = value
    return values, None


class TextTable:
    """The distinct texts of a column, each stored once, and an integer code per row.

    A numpy unicode array is as wide as its longest string: one 1000-character
    tag id in a 200k-row file would cost 800 MB. Here each distinct text is
    one Python string and each row an int64 code (codes in order of first
    appearance); :meth:`decode` gives an object array whose rows share those
    strings (8 bytes a row).
    """

    def __init__(self):
        self.code_of: dict[str, int] = {}

    def encode(self, texts: list[str]) -> tuple[np.ndarray, list[str]]:
        """The codes of ``texts`` (adding unseen ones to the table), and the texts that were new."""
        new = [text for text in dict.fromkeys(texts) if text not in self.code_of]
        for text in new:
            self.code_of[text] = len(self.code_of)
        codes = np.fromiter(map(self.code_of.__getitem__, texts), dtype=np.int64, count=len(texts))
        return codes, new

    def texts(self) -> np.ndarray:
        """Object array of the distinct texts, indexed by code."""
        table = np.empty(len(self.code_of), dtype=object)
        table[:] = list(self.code_of)
        return table

    def decode(self, codes: np.ndarray) -> np.ndarray:
        """Object array of the texts of ``codes`` (shared string objects, not copies)."""
        return self.texts()[np.asarray(codes, dtype=np.int64)]


def interned(values) -> np.ndarray:
    """Any array or list of strings as an object array of interned strings (see :class:`TextTable`)."""
    table = TextTable()
    texts = [str(v) for v in np.asarray(values, dtype=object).reshape(-1).tolist()]
    codes, _ = table.encode(texts)
    return table.decode(codes)
