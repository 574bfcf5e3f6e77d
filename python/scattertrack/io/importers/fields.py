"""Column names, units and cell parsing shared by the importers.

Reader tools name the same quantity in many ways (``timestamp``,
``Timestamp``, ``LastSeenTimestampUTC``; ``phase_angle``, ``PhaseAngle``) and
in several units. A name is matched after :func:`normalise` (lower case,
without ``_``, ``-``, spaces); each accepted name fixes its unit, except for
the few bare names whose unit the values tell (:func:`time_unit`,
:func:`frequency_unit`), and the report says which column was used and in
which unit. Numbers are ASCII decimal as everywhere in scattertrack
(:mod:`scattertrack.io.cells`).
"""

from __future__ import annotations

import base64
import binascii
import re

import numpy as np

from scattertrack.io import units
from scattertrack.io.cells import INTEGER, NUMBER
from scattertrack.io.reads import BYTES_LITERAL, epc_problem
from scattertrack.io.types import FormatError

AUTO = "auto"
"""The unit of a bare ``timestamp``/``frequency``: decided from the file's first value."""

TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
FREQUENCY_UNITS = {"Hz": 1.0, "kHz": 1e3, "MHz": 1e6}

US_EPOCH_MIN = 1e14
MS_EPOCH_MIN = 1e11
"""A bare timestamp at or above 1e14 is microseconds since the epoch (now about 1.7e15), at or
above 1e11 milliseconds (about 1.7e12), otherwise seconds (about 1.7e9, or seconds since a start)."""


def normalise(name: str) -> str:
    """A column name or JSON key as matched: lower case without ``_``, ``-``, ``.`` and spaces."""
    return re.sub(r"[\s_.\-]", "", name.strip().lower())


def aliases(*pairs: tuple[str, str]) -> dict[str, str]:
    """An alias table (normalised name -> unit) from readable (name, unit) pairs, in order of preference."""
    return {normalise(name): unit for name, unit in pairs}


TIME = aliases(("time_s", "s"), ("timestamp_s", "s"), ("timestamp_us", "us"), ("timestamp_ms", "ms"),
               ("LastSeenTimestampUTC", "us"), ("FirstSeenTimestampUTC", "us"), ("timestamp", AUTO), ("time", AUTO))
EPC = aliases(("epc", ""), ("epc_hex", ""), ("EPC-96", ""), ("EPCData", ""), ("tag_id", ""))
ANTENNA = aliases(("antenna", ""), ("antenna_id", ""), ("antenna_port", ""), ("ant", ""), ("port", ""))
RSSI = aliases(("rssi_dbm", "dBm"), ("peak_rssi", "dBm"), ("rssi", "dBm"), ("peak_rssi_cdbm", "cdBm"))
CHANNEL = aliases(("channel_index", ""), ("channel", ""))
FREQUENCY = aliases(("frequency_hz", "Hz"), ("frequency_khz", "kHz"), ("frequency_mhz", "MHz"),
                    ("frequency", AUTO))
DOPPLER = aliases(("doppler_hz", "Hz"), ("doppler_frequency", "1/16 Hz"), ("rf_doppler_frequency", "1/16 Hz"),
                  ("ImpinjRFDopplerFrequency", "1/16 Hz"), ("doppler", "1/16 Hz"))


# --- cells ------------------------------------------------------------------


def number(text) -> float | None:
    """An ASCII decimal number (str) or a JSON number (int/float, not bool), else None; never nan or inf."""
    if isinstance(text, bool):
        return None
    if isinstance(text, (int, float)):
        value = float(text)
    elif isinstance(text, str) and NUMBER.fullmatch(text):
        value = float(text)
    else:
        return None
    return value if value == value and abs(value) != float("inf") else None


def integer(text) -> int | None:
    """An ASCII integer (str) or a JSON integer (not bool, not 1.0), else None."""
    if isinstance(text, bool):
        return None
    if isinstance(text, int):
        return text
    if isinstance(text, str) and INTEGER.fullmatch(text):
        return int(text)
    return None


def is_blank(value) -> bool:
    """An absent value: None or an empty or whitespace-only cell."""
    return value is None or (isinstance(value, str) and not value.strip())


def clean_epc(text) -> tuple[str | None, str | None]:
    """``(hex EPC, None)`` or ``(None, reason)``.

    A Python bytes literal (``b'3034...'``, what sllurp's CSV holds under
    Python 3) and a ``0x`` prefix are unwrapped; the hex digits are kept
    exactly as written (case included).
    """
    if not isinstance(text, str) or not text.strip():
        return None, "empty EPC"
    epc = text.strip()
    if BYTES_LITERAL.fullmatch(epc):
        epc = epc[2:-1]
    if epc[:2] in ("0x", "0X"):
        epc = epc[2:]
    if not epc or epc_problem(epc) is not None:
        return None, "EPC not hex"
    return epc, None


def epc_from_base64(text) -> tuple[str | None, str | None]:
    """The upper-case hex of a base64 EPC (the Impinj IoT interface's ``epc``), or ``(None, reason)``."""
    try:
        raw = base64.b64decode(text, validate=True) if isinstance(text, str) else b""
    except (binascii.Error, ValueError):
        return None, "EPC not base64"
    if not raw:
        return None, "empty EPC"
    return raw.hex().upper(), None


# --- units decided by the values --------------------------------------------


def time_unit(value: float) -> str:
    """The unit of a bare timestamp, from its magnitude (:data:`US_EPOCH_MIN`, :data:`MS_EPOCH_MIN`)."""
    if abs(value) >= US_EPOCH_MIN:
        return "us"
    if abs(value) >= MS_EPOCH_MIN:
        return "ms"
    return "s"


def frequency_unit(path, line: int, column: str, value: float) -> str:
    """The unit of a bare ``frequency`` column, from its first value; FormatError when none fits.

    Small integers are what readers call a channel index: the error says to
    name that column ``channel_index``.
    """
    if not units.frequency_outside(np.array([value]))[0]:
        return "Hz"
    for low, high, unit, _ in units.FREQUENCY_UNITS:
        if unit in FREQUENCY_UNITS and low <= abs(value) <= high:
            return unit
    raise FormatError(path, line, column,
                      f"frequency {value:g} is not a carrier in Hz, kHz or MHz (100 MHz to 10 GHz); if it is the "
                      "reader's channel index, name the column channel_index")


# --- CSV headers ------------------------------------------------------------


def pick_column(header: list[str], table: dict[str, str]) -> tuple[str, str] | None:
    """``(column as written, unit)`` of the preferred alias present in ``header``, or None."""
    written = {}
    for name in header:
        written.setdefault(normalise(name), name)
    for alias, unit in table.items():
        if alias in written:
            return written[alias], unit
    return None


def require_column(path, header: list[str], table: dict[str, str], what: str) -> tuple[str, str]:
    """Like :func:`pick_column`, a FormatError at line 1 naming the accepted names when none is present."""
    found = pick_column(header, table)
    if found is None:
        raise FormatError(path, 1, None, f"no {what} column: expected one of {', '.join(table)} "
                                         "(matched ignoring case, '_', '-' and spaces)")
    return found
