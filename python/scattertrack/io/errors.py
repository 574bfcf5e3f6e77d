"""The errors and warnings every reader raises and issues (the :mod:`scattertrack.io` contract).

The bottom of ``io``: it imports nothing of scattertrack, so every reader,
and :mod:`scattertrack.io.types`, which re-exports these, can use it.
"""

from __future__ import annotations

import warnings


class FormatError(ValueError):
    """A file that breaks its format.

    ``path``, ``line`` (1-based, ``None`` when the whole file is at fault) and
    ``column`` (the column name for CSV, the key for TOML, ``None`` if not
    applicable) locate the fault; ``str(error)`` reads
    ``"reads.csv:12: line 12, column 'phase_rad': not a finite number: 'nan'"``.
    """

    def __init__(self, path, line: int | None, column: str | None, message: str):
        self.path = str(path)
        self.line = line
        self.column = column
        self.message = message
        # "file:N:" for editors and tools that jump to a location, and the
        # words for people: "reads.csv:12: line 12, column 'phase_rad': ...".
        where = self.path if line is None else f"{self.path}:{line}: line {line}"
        col = (", " if line is not None else ": ") + f"column '{column}'" if column is not None else ""
        super().__init__(f"{where}{col}: {message}")


class InputWarning(UserWarning):
    """Valid but suspicious input (a clock jump, an implausible prior...), issued with :func:`warnings.warn`.

    The text reads like a :class:`FormatError`'s, ``"reads.csv:12: line 12,
    column 'time_s': clock jumps back by 10 s ..."``; the command line prints it as
    a line starting ``warning:``. ``path``, ``line`` and ``column`` locate it.
    """

    def __init__(self, path, line: int | None, column: str | None, message: str):
        self.path = str(path)
        self.line = line
        self.column = column
        self.message = message
        super().__init__(str(FormatError(path, line, column, message)))


def warn_input(path, line: int | None, column: str | None, message: str) -> None:
    """Issue an :class:`InputWarning` (shown once per distinct text by Python's default filter)."""
    warnings.warn(InputWarning(path, line, column, message), stacklevel=3)
