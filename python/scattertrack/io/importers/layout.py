"""Which column holds each quantity, in which unit, and the parsing of the fields all formats share.

A :class:`Layout` is made once per CSV file (from its header) or JSON-lines
file (from its first event's keys): it picks, for each field, the preferred
accepted name present (:mod:`scattertrack.io.importers.fields`) and its unit.
:meth:`Layout.shared` then turns one row's raw values (CSV cells or JSON
values) into SI values, or names the reason the row is declined.
"""

from __future__ import annotations

import math

from scattertrack.io import hop_table
from scattertrack.io.importers import fields
from scattertrack.io.types import FormatError

SHARED = {
    "time": fields.TIME,
    "epc": fields.EPC,
    "antenna": fields.ANTENNA,
    "frequency": fields.FREQUENCY,
    "channel": fields.CHANNEL,
    "rssi": fields.RSSI,
    "doppler": fields.DOPPLER,
}
"""The fields every importer reads, by accepted names (normalised) and their units."""

TARGET = {"time": "time_s", "epc": "epc", "antenna": "antenna", "frequency": "frequency_hz",
          "channel": "channel_index", "rssi": "rssi_dbm", "doppler": "doppler_hz", "phase": "phase_rad"}
"""The reads.csv column each field fills."""

UNIT_WORDS = {
    "s": "seconds", "ms": "milliseconds since the epoch", "us": "microseconds since the epoch",
    "Hz": "Hz", "kHz": "kHz", "MHz": "MHz", "dBm": "dBm", "cdBm": "centi-dBm, / 100",
    "1/16 Hz": "1/16 Hz, / 16", "rad": "radians", "deg": "degrees", "impinj": "Impinj units 0-4095, x 2*pi/4096",
}

# Decline reasons (the summary counts rows by these words).
BAD_TIME = "time not a number"
BAD_ANTENNA = "antenna not an integer"
BAD_FREQUENCY = "frequency not a number"
BAD_CHANNEL = "channel index not a positive integer"
BAD_RSSI = "RSSI not a number"
BAD_DOPPLER = "Doppler not a number"
BAD_DOPPLER_UNITS = "Doppler not an integer (1/16 Hz units)"


class Layout:
    """The columns (or JSON keys) of one source file: ``column[field]`` as written, ``unit[field]``.

    ``required`` fields must be present (FormatError at line 1 naming the
    accepted names); a frequency or a channel index column must be.
    """

    def __init__(self, path, names: list[str], tables: dict[str, dict[str, str]], required: tuple[str, ...]):
        self.path = str(path)
        self.column: dict[str, str] = {}
        self.unit: dict[str, str] = {}
        for field, table in tables.items():
            found = fields.require_column(path, names, table, field) if field in required else \
                fields.pick_column(names, table)
            if found is not None:
                self.column[field], self.unit[field] = found
        if "frequency" not in self.column and "channel" not in self.column:
            raise FormatError(path, 1, None, "no frequency or channel index column: expected one of "
                                             f"{', '.join(list(fields.FREQUENCY) + list(fields.CHANNEL))}")

    def has(self, field: str) -> bool:
        return field in self.column

    def describe(self) -> list[str]:
        """``"time_s <- 'timestamp' (seconds)"`` per field used, for the report."""
        out = []
        for field, name in self.column.items():
            unit = self.unit[field]
            words = UNIT_WORDS.get(unit, "")
            out.append(f"{TARGET.get(field, field)} <- {name!r}" + (f" ({words})" if words else ""))
        return out

    def shared(self, get, line: int) -> tuple[dict | None, str | None]:
        """The shared fields of one row as SI values, or ``(None, decline reason)``.

        ``get(field)``: the row's raw value of a field (a CSV cell or a JSON
        value; None when absent). A bare ``timestamp`` or ``frequency`` takes
        its unit from the file's first value (FormatError when a frequency fits no unit).
        """
        time = fields.number(get("time"))
        if time is None:
            return None, BAD_TIME
        if self.unit["time"] == fields.AUTO:
            self.unit["time"] = fields.time_unit(time)
        epc, reason = fields.clean_epc(get("epc"))
        if reason:
            return None, reason
        antenna = fields.integer(get("antenna"))
        if antenna is None:
            return None, BAD_ANTENNA
        values = {"time_s": time * fields.TIME_UNITS[self.unit["time"]], "epc": epc, "antenna": antenna,
                  "frequency_hz": math.nan, "channel_index": hop_table.NO_CHANNEL,
                  "rssi_dbm": math.nan, "doppler_hz": math.nan}
        raw = get("frequency")
        if not fields.is_blank(raw):
            frequency = fields.number(raw)
            if frequency is None:
                return None, BAD_FREQUENCY
            if self.unit["frequency"] == fields.AUTO:
                self.unit["frequency"] = fields.frequency_unit(self.path, line, self.column["frequency"], frequency)
            values["frequency_hz"] = frequency * fields.FREQUENCY_UNITS[self.unit["frequency"]]
        raw = get("channel")
        if not fields.is_blank(raw):
            index = fields.integer(raw)
            if index is None or index < 1:
                return None, BAD_CHANNEL
            values["channel_index"] = index
        raw = get("rssi")
        if not fields.is_blank(raw):
            rssi = fields.number(raw)
            if rssi is None:
                return None, BAD_RSSI
            values["rssi_dbm"] = rssi / 100.0 if self.unit["rssi"] == "cdBm" else rssi
        raw = get("doppler")
        if not fields.is_blank(raw):
            if self.unit["doppler"] == "1/16 Hz":
                doppler = fields.integer(raw)
                if doppler is None:
                    return None, BAD_DOPPLER_UNITS
                values["doppler_hz"] = doppler / 16.0
            else:
                doppler = fields.number(raw)
                if doppler is None:
                    return None, BAD_DOPPLER
                values["doppler_hz"] = doppler
        return values, None


def csv_rows(path, required: tuple[str, ...], extra: dict[str, dict[str, str]]):
    """Open a CSV source: ``(layout, iterator of (line, get))`` where ``get(field)`` is that row's cell.

    Uses the project's CSV reader (UTF-8 with or without BOM, field counts
    checked, a FormatError with file and line for a broken file).
    """
    from scattertrack.io.csvutil import CsvReader

    reader = CsvReader(path, [], [])
    reader.__enter__()
    try:
        layout = Layout(path, list(reader.column_position), {**SHARED, **extra}, required)
    except Exception:
        reader.__exit__(None, None, None)
        raise

    def rows():
        try:
            for chunk in reader.chunks():
                cells = {field: chunk.cells(name) for field, name in layout.column.items()}
                for i, line in enumerate(chunk.line_numbers().tolist()):
                    yield line, (lambda field, i=i: cells[field][i] if field in cells else None)
        finally:
            reader.__exit__(None, None, None)

    return layout, rows()
