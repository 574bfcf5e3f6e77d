"""JSON-lines sources (one JSON value per line), read with the same hygiene as the CSV files.

Bad lines are declined and counted, not fatal: a stream captured from a
socket often ends in a half-written line.
"""

from __future__ import annotations

import json

from scattertrack.io.importers.report import ImportReport
from scattertrack.io.types import FormatError

NOT_JSON = "not JSON"
NON_FINITE = "NaN or Infinity in JSON"
NOT_OBJECT = "not a JSON object"


def json_lines(path, report: ImportReport):
    """Yield ``(1-based line, event dict)`` of a JSON-lines file; bad lines are declined in ``report``.

    Blank lines are skipped; a line holding an array yields each of its
    objects. A file that is not UTF-8 is a FormatError.
    """
    try:
        with open(path, encoding="utf-8-sig", newline="") as file:
            text = file.read()
    except UnicodeDecodeError as error:
        raise FormatError(path, None, None, f"not UTF-8 text: {error}") from None
    # Only \n ends a line (str.splitlines would also split at form feeds and U+2028 inside strings).
    for number, line in enumerate(text.split("\n"), start=1):
        if not line.strip():
            continue
        try:
            value = json.loads(line, parse_constant=_refuse_constant)
        except _NonFinite:
            report.rows += 1
            report.decline(path, number, NON_FINITE)
            continue
        except ValueError:
            report.rows += 1
            report.decline(path, number, NOT_JSON)
            continue
        for event in value if isinstance(value, list) else [value]:
            report.rows += 1
            if not isinstance(event, dict):
                report.decline(path, number, NOT_OBJECT)
                continue
            yield number, event


class _NonFinite(ValueError):
    """JSON's NaN/Infinity extensions, which Python's json reads by default."""


def _refuse_constant(name: str):
    raise _NonFinite(name)
