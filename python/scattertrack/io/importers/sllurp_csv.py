"""``sllurp-csv``: tag-report CSV files as sllurp and the tools built on it write them.

sllurp (the Python LLRP client) logs one row per tag report. Its own
``sllurp log`` writes ``timestamp, reader, antenna, rssi, epc`` with the
timestamp in seconds since the epoch (the reader's ``LastSeenTimestampUTC``,
microseconds, divided by 1e6, or the host clock); its older ``csv_recorder``
wrote ``timestamp_us`` (microseconds). Under Python 3 the EPC is a bytes
object and lands in the file as ``b'3034...'``. Tools that enable Impinj's
low-level data add ``phase_angle`` (Impinj units 0-4095: 2*pi*x/4096 rad),
``channel_index`` (the 1-based LLRP ChannelIndex into the reader's hop
table) and ``doppler_frequency`` (Impinj RFDopplerFrequency: signed 1/16 Hz).

Accepted names (matched ignoring case, ``_``, ``-`` and spaces; the first
present wins) and units:

- time: ``time_s``, ``timestamp_s`` (s); ``timestamp_us``,
  ``LastSeenTimestampUTC``, ``FirstSeenTimestampUTC`` (us); ``timestamp_ms``
  (ms); bare ``timestamp``/``time``: microseconds if the first value is at
  least 1e14, milliseconds if at least 1e11, else seconds;
- EPC: ``epc``, ``epc_hex``, ``EPC-96``, ``EPCData``, ``tag_id`` (hex, or a
  bytes literal ``b'...'``, or ``0x``-prefixed);
- antenna: ``antenna``, ``antenna_id``, ``antenna_port``, ``ant``, ``port``;
- phase: ``phase_rad`` (rad), ``phase_deg`` (degrees), ``phase_angle``,
  ``ImpinjRFPhaseAngle``, ``rf_phase_angle``, ``phase`` (Impinj units: an integer 0-4095);
- channel: ``channel_index``, ``channel`` (1-based);
- frequency: ``frequency_hz``, ``frequency_khz``, ``frequency_mhz``, or bare
  ``frequency`` (Hz, kHz or MHz by the first value's range);
- RSSI: ``rssi_dbm``, ``peak_rssi``, ``rssi`` (dBm), ``peak_rssi_cdbm`` (dBm/100);
- Doppler: ``doppler_hz`` (Hz); ``doppler_frequency``, ``rf_doppler_frequency``,
  ``ImpinjRFDopplerFrequency``, ``doppler`` (an integer in 1/16 Hz).

Other columns (``reader``, ``RunTimestamp``, ...) are ignored.
"""

from __future__ import annotations

import math

from scattertrack.io.importers import fields
from scattertrack.io.importers.layout import csv_rows
from scattertrack.io.importers.report import ImportReport
from scattertrack.io.importers.rows import Rows, finish
from scattertrack.io.types import Reads, Scene
from scattertrack.io.units import IMPINJ_PHASE_UNITS

FORMAT = "sllurp-csv"

PHASE = fields.aliases(("phase_rad", "rad"), ("phase_deg", "deg"), ("phase_angle", "impinj"),
                       ("ImpinjRFPhaseAngle", "impinj"), ("rf_phase_angle", "impinj"), ("phase", "impinj"))

PHASE_TOLERANCE_RAD = 1e-9
BAD_IMPINJ_PHASE = "phase not an integer 0-4095 (Impinj units)"
BAD_RAD_PHASE = "phase not a number in [0, 2*pi] rad"
BAD_DEG_PHASE = "phase not a number in [0, 360] degrees"


def import_sllurp_csv(paths, scene: Scene) -> tuple[Reads, ImportReport]:
    """Import sllurp-style CSV files (module docstring) into :class:`Reads` (SI units) and an :class:`ImportReport`."""
    report = ImportReport(FORMAT, [str(p) for p in paths])
    rows = Rows()
    has_channel = False
    for path in paths:
        layout, source = csv_rows(path, ("time", "epc", "antenna", "phase"), {"phase": PHASE})
        has_channel |= layout.has("channel")

        def read_phase(values, get, unit=layout.unit["phase"]):
            values["phase_rad"], reason = phase_rad(get("phase"), unit)
            return reason

        rows.add_source(path, layout, source, report, read_phase)
        for text in layout.describe():
            if text not in report.columns:
                report.columns.append(text)
    return finish(rows, scene, report, has_channel), report


def phase_rad(raw, unit: str) -> tuple[float, str | None]:
    """A phase cell in ``unit`` ("impinj", "rad" or "deg") as radians, or ``(nan, decline reason)``."""
    if unit == "impinj":
        value = fields.integer(raw)
        if value is None or not 0 <= value < IMPINJ_PHASE_UNITS:
            return math.nan, BAD_IMPINJ_PHASE
        return 2.0 * math.pi * value / IMPINJ_PHASE_UNITS, None
    value = fields.number(raw)
    if unit == "deg":
        if value is None or not 0.0 <= value <= 360.0:
            return math.nan, BAD_DEG_PHASE
        return math.radians(value), None
    if value is None or not -PHASE_TOLERANCE_RAD <= value <= 2.0 * math.pi + PHASE_TOLERANCE_RAD:
        return math.nan, BAD_RAD_PHASE
    return value, None
