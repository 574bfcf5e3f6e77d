"""``impinj-iot``: the Impinj IoT device interface's event stream (R700/R720 HTTP stream, MQTT, Kafka).

One JSON object per line (newline-delimited JSON, as ``/data/stream``
sends it); a line may also hold an array of events (webhook batches).
A tag read is an event with ``"eventType": "tagInventory"`` and a
``tagInventoryEvent`` object; other events (``inventoryStatus``,
``antennaConnected``, ...) are counted as ignored. Fields and units:

- time: ``tagInventoryEvent.lastSeenTime``, else the event's ``timestamp``:
  ISO 8601 (``2024-05-01T12:00:00.123456789Z``; any number of fractional
  digits; an offset or ``Z``; a time without offset is taken as UTC),
  written as seconds since the epoch;
- EPC: ``epcHex`` (kept as written), else ``epc`` (base64, written as upper-case hex);
- antenna: ``antennaPort`` (integer);
- phase: ``phaseAngle``, degrees 0-360 (the reader's 0-4095 units times
  360/4096), to radians; enable it in the preset's
  ``eventConfig.tagInventory.phaseAngle``, a row without it is declined;
- frequency: ``frequency``, kHz (``926750`` = 926.75 MHz), to hertz;
- channel: ``channel`` or ``channelIndex`` when present (1-based), kept as ``channel_index``;
- RSSI: ``peakRssiCdbm``, centi-dBm, / 100 to dBm.

The interface reports no Doppler.
"""

from __future__ import annotations

import datetime
import math
import re

from scattertrack.io import hop_table
from scattertrack.io.importers import fields
from scattertrack.io.importers.jsonlines import json_lines
from scattertrack.io.importers.report import ImportReport
from scattertrack.io.importers.rows import Rows, finish
from scattertrack.io.types import Reads, Scene

FORMAT = "impinj-iot"
TAG_EVENT = "tagInventory"

ISO_8601 = re.compile(r"(\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}:\d{2})(?:[.,](\d+))?(Z|[+-]\d{2}:?\d{2})?", re.IGNORECASE)

BAD_TIME = "time not ISO 8601"
NO_EPC = "no EPC"
BAD_ANTENNA = "antenna not an integer"
NO_PHASE = "no phaseAngle"
BAD_PHASE = "phase not a number in [0, 360] degrees"
BAD_FREQUENCY = "frequency not a number (kHz)"
BAD_CHANNEL = "channel index not a positive integer"
BAD_RSSI = "RSSI not a number (centi-dBm)"

COLUMNS = [
    "time_s <- 'lastSeenTime' or 'timestamp' (ISO 8601, seconds since the epoch)",
    "epc <- 'epcHex' or 'epc' (base64)",
    "antenna <- 'antennaPort'",
    "phase_rad <- 'phaseAngle' (degrees)",
    "frequency_hz <- 'frequency' (kHz)",
    "channel_index <- 'channel' or 'channelIndex'",
    "rssi_dbm <- 'peakRssiCdbm' (centi-dBm, / 100)",
]


def import_impinj_iot(paths, scene: Scene) -> tuple[Reads, ImportReport]:
    """Import Impinj IoT interface event streams (module docstring) into :class:`Reads` and an :class:`ImportReport`."""
    report = ImportReport(FORMAT, [str(p) for p in paths], columns=list(COLUMNS))
    rows = Rows()
    for path in paths:
        for line, event in json_lines(path, report):
            tag = event.get("tagInventoryEvent")
            if event.get("eventType", TAG_EVENT if tag is not None else None) != TAG_EVENT or not isinstance(tag, dict):
                kind = event.get("eventType")
                kind = f"{kind} events" if isinstance(kind, str) else "events without eventType"
                report.ignored[kind] = report.ignored.get(kind, 0) + 1
                continue
            values, reason = tag_values(event, tag)
            if reason is not None:
                report.decline(path, line, reason)
                continue
            rows.add(path, line, **values)
    has_channel = any(index != hop_table.NO_CHANNEL for index in rows.values["channel_index"])
    return finish(rows, scene, report, has_channel), report


def tag_values(event: dict, tag: dict) -> tuple[dict | None, str | None]:
    """One ``tagInventoryEvent`` as :meth:`Rows.add` keywords (SI units), or ``(None, decline reason)``."""
    time = iso_seconds(tag.get("lastSeenTime", event.get("timestamp")))
    if time is None:
        return None, BAD_TIME
    if tag.get("epcHex") is not None:
        epc, reason = fields.clean_epc(tag.get("epcHex"))
    elif tag.get("epc") is not None:
        epc, reason = fields.epc_from_base64(tag.get("epc"))
    else:
        epc, reason = None, NO_EPC
    if reason:
        return None, reason
    antenna = fields.integer(tag.get("antennaPort"))
    if antenna is None:
        return None, BAD_ANTENNA
    if tag.get("phaseAngle") is None:
        return None, NO_PHASE
    degrees = fields.number(tag.get("phaseAngle"))
    if degrees is None or not 0.0 <= degrees <= 360.0:
        return None, BAD_PHASE
    values = {"time_s": time, "epc": epc, "antenna": antenna, "phase_rad": math.radians(degrees)}
    if tag.get("frequency") is not None:
        khz = fields.number(tag.get("frequency"))
        if khz is None:
            return None, BAD_FREQUENCY
        values["frequency_hz"] = khz * 1e3
    channel = tag.get("channel", tag.get("channelIndex"))
    if channel is not None:
        index = fields.integer(channel)
        if index is None or index < 1:
            return None, BAD_CHANNEL
        values["channel_index"] = index
    else:
        values["channel_index"] = hop_table.NO_CHANNEL
    if tag.get("peakRssiCdbm") is not None:
        cdbm = fields.number(tag.get("peakRssiCdbm"))
        if cdbm is None:
            return None, BAD_RSSI
        values["rssi_dbm"] = cdbm / 100.0
    return values, None


def iso_seconds(text) -> float | None:
    """Seconds since the epoch of an ISO 8601 date-time (UTC when it has no offset), or None.

    The fraction is read digit for digit (the reader writes nanoseconds,
    which :func:`datetime.fromisoformat` would not all keep).
    """
    if not isinstance(text, str):
        return None
    found = ISO_8601.fullmatch(text.strip())
    if not found:
        return None
    base, fraction, offset = found.groups()
    offset = offset or "Z"
    offset = "+00:00" if offset.upper() == "Z" else offset
    try:
        moment = datetime.datetime.fromisoformat(base.replace(" ", "T") + offset)
    except ValueError:
        return None
    return moment.timestamp() + (float("0." + fraction) if fraction else 0.0)
