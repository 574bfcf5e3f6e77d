"""``iq-phasors``: reads given as I/Q phasors (SDR readers, research firmware), as CSV or JSON lines.

One read per row (CSV with a header) or per line (a JSON object whose keys
are the column names); a file whose first non-blank character is ``{`` or
``[`` is JSON lines, any other CSV. In a JSON-lines file the names used are
picked from all the events' keys, and an event without one has no value there. The shared names and units are those of
``sllurp-csv`` (time, EPC, antenna, frequency or channel index, RSSI,
Doppler; :mod:`scattertrack.io.importers.sllurp_csv`), plus:

- ``i`` (or ``i_value``, ``in_phase``) and ``q`` (or ``q_value``,
  ``quadrature``): the phasor, in any linear unit (ADC counts, volts).

The phase is ``atan2(Q, I)`` wrapped into [0, 2*pi) rad. Without an RSSI
column the RSSI is ``20*log10(|I + jQ|)``: decibels of the phasor's own
unit, good for comparing reads of one file but not calibrated dBm. A zero
phasor has no phase and is declined.
"""

from __future__ import annotations

import math

from scattertrack.io.importers import fields
from scattertrack.io.importers.jsonlines import json_lines
from scattertrack.io.importers.layout import SHARED, Layout, csv_rows
from scattertrack.io.importers.report import ImportReport
from scattertrack.io.importers.rows import Rows, finish
from scattertrack.io.types import FormatError, Reads, Scene

FORMAT = "iq-phasors"

I_COLUMN = fields.aliases(("i", ""), ("i_value", ""), ("in_phase", ""))
Q_COLUMN = fields.aliases(("q", ""), ("q_value", ""), ("quadrature", ""))
EXTRA = {"i": I_COLUMN, "q": Q_COLUMN}
REQUIRED = ("time", "epc", "antenna", "i", "q")

BAD_IQ = "I or Q not a number"
ZERO_PHASOR = "zero phasor (no phase)"
RSSI_FROM_PHASOR = "rssi_dbm <- 20*log10(|I + jQ|) (dB of the phasor's unit, not calibrated dBm)"


def import_iq_phasors(paths, scene: Scene) -> tuple[Reads, ImportReport]:
    """Import I/Q phasor files (module docstring) into :class:`Reads` and an :class:`ImportReport`."""
    report = ImportReport(FORMAT, [str(p) for p in paths])
    rows = Rows()
    has_channel = False
    for path in paths:
        json_source = is_json_lines(path)
        # json_lines counts its events itself (a line may hold several).
        layout, source = _json_rows(path, report) if json_source else csv_rows(path, REQUIRED, EXTRA)
        has_rssi = layout.has("rssi")
        rows.add_source(path, layout, source, report, lambda values, get: _add_phasor(values, get("i"), get("q"), has_rssi),
                        count_rows=not json_source)
        has_channel |= layout.has("channel")
        described = [text for text in layout.describe() if not text.startswith(("i <-", "q <-"))]
        described.append(f"phase_rad <- atan2({layout.column['q']!r}, {layout.column['i']!r}) (radians)")
        described += [] if layout.has("rssi") else [RSSI_FROM_PHASOR]
        report.columns += [text for text in described if text not in report.columns]
    return finish(rows, scene, report, has_channel), report


def _add_phasor(values: dict, i_raw, q_raw, has_rssi: bool) -> str | None:
    """Put the phase (rad) and, without an RSSI column, the phasor's level (dB) into ``values``; or a decline reason."""
    i, q = fields.number(i_raw), fields.number(q_raw)
    if i is None or q is None:
        return BAD_IQ
    if i == 0.0 and q == 0.0:
        return ZERO_PHASOR
    values["phase_rad"] = math.atan2(q, i) % (2.0 * math.pi)
    if not has_rssi:
        values["rssi_dbm"] = 20.0 * math.log10(math.hypot(i, q))
    return None


def is_json_lines(path) -> bool:
    """Whether the file's first non-blank character opens a JSON object or array."""
    with open(path, "rb") as file:
        head = file.read(4096).lstrip(b"\xef\xbb\xbf \t\r\n")
    return head[:1] in (b"{", b"[")


def _json_rows(path, report: ImportReport):
    """``(layout, rows)`` of a JSON-lines phasor file; the layout is picked from every event's keys."""
    events = list(json_lines(path, report))
    if not events:
        raise FormatError(path, None, None, "no JSON events")
    keys = list(dict.fromkeys(key for _, event in events for key in event))
    layout = Layout(path, keys, {**SHARED, **EXTRA}, REQUIRED)

    def getter(event):
        return lambda field: event.get(layout.column[field]) if field in layout.column else None

    return layout, [(line, getter(event)) for line, event in events]
