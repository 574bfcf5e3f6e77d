"""What an Impinj (Octane LLRP) tag report means, in the units of ``reads.csv``.

Pure functions, no network. The encodings (Impinj Octane LLRP extensions,
LLRP 1.0.1 sections 13–14):

* ``ImpinjRFPhaseAngle``: 12 bits, 0–4095 over one turn, so
  ``phase_rad = 2π · units / 4096`` (resolution 1.53 mrad).
* ``ImpinjRFDopplerFrequency``: signed 16 bits in 1/16 Hz, so
  ``doppler_hz = units / 16``.
* ``ImpinjPeakRSSI``: signed 16 bits in 1/100 dBm (cdBm).
* ``ChannelIndex``: 1-based index into the reader's ``FrequencyHopTable``
  (kHz), reported in ``GET_READER_CAPABILITIES``. The table is the reader's
  own hop order, not the band plan in frequency order: a US reader hops
  over 50 channels of 500 kHz from 902.75 to 927.25 MHz in a shuffled
  sequence, so channel 1 is rarely 902.75 MHz. The phase jumps at every
  hop because each channel has its own phase offset (calibration measures
  them).
* ``FirstSeenTimestampUTC``: microseconds since the Unix epoch, the
  reader's clock. ``time_s = microseconds / 1e6``; ``reads.csv`` keeps six
  decimals, so no precision is lost.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

PHASE_UNITS_PER_TURN = 4096
"""Impinj phase angle: units per 2π."""
DOPPLER_UNITS_PER_HZ = 16
"""Impinj Doppler: units per hertz."""
RSSI_UNITS_PER_DBM = 100
"""Impinj peak RSSI: units per dBm."""


def phase_rad(units: int) -> float:
    """Radians in [0, 2π) of an Impinj phase angle (0–4095 units)."""
    return 2.0 * math.pi * (int(units) % PHASE_UNITS_PER_TURN) / PHASE_UNITS_PER_TURN


def phase_units(phase: float) -> int:
    """The Impinj encoding of a phase in radians: nearest unit, mod 4096."""
    return round(phase / (2.0 * math.pi) * PHASE_UNITS_PER_TURN) % PHASE_UNITS_PER_TURN


def doppler_hz(units: int) -> float:
    """Hertz of an Impinj Doppler value (1/16 Hz units)."""
    return int(units) / DOPPLER_UNITS_PER_HZ


def doppler_units(doppler: float) -> int:
    """The Impinj encoding of a Doppler shift in hertz, clamped to 16 bits."""
    return max(-32768, min(32767, round(doppler * DOPPLER_UNITS_PER_HZ)))


def rssi_dbm(units: int) -> float:
    """dBm of an Impinj peak RSSI value (1/100 dBm units)."""
    return int(units) / RSSI_UNITS_PER_DBM


def hop_table_hz(frequencies_khz: Sequence[int]) -> dict[int, float]:
    """The reader's hop table as ``{channel index (1-based): carrier Hz}``."""
    return {index: 1e3 * float(khz) for index, khz in enumerate(frequencies_khz, start=1)}


@dataclass(frozen=True)
class ReportedRead:
    """One tag report as ``reads.csv`` has it (SI units; nan where absent)."""

    time_s: float
    """Reader clock, seconds since the Unix epoch (FirstSeenTimestampUTC)."""
    epc: str
    """Hex, upper case, as the EPC bank's bytes."""
    antenna: int
    """The reader's antenna port (1-based), the scene's antenna id."""
    frequency_hz: float
    phase_rad: float
    rssi_dbm: float
    doppler_hz: float
    channel_index: int
    """As the reader reported it (1-based into its hop table)."""
    first_seen_us: int
    """The raw timestamp, kept for de-duplication."""


def reported_read(
    *,
    epc: bytes,
    antenna: int | None,
    channel_index: int | None,
    first_seen_us: int | None,
    phase_deg: float | None,
    rssi: float | None,
    doppler: float | None,
    hop_table: Mapping[int, float],
) -> ReportedRead | str:
    """A report's read, or the reason it cannot be one (a ``str``).

    ``phase_deg`` is llrpkit's view of the phase (units · 360/4096, exact in
    binary floating point, so the radians below equal ``phase_rad(units)``).
    """
    if antenna is None:
        return "report without an antenna id"
    if first_seen_us is None:
        return "report without a FirstSeenTimestampUTC"
    if phase_deg is None:
        return "report without a phase (the reader did not enable ImpinjRFPhaseAngle)"
    if channel_index is None:
        return "report without a channel index"
    frequency = hop_table.get(int(channel_index))
    if frequency is None:
        return f"channel index {channel_index} is not in the reader's hop table"
    phase = math.radians(phase_deg) % (2.0 * math.pi)
    return ReportedRead(
        time_s=first_seen_us / 1e6,
        epc=epc.hex().upper(),
        antenna=int(antenna),
        frequency_hz=frequency,
        phase_rad=phase,
        rssi_dbm=math.nan if rssi is None else float(rssi),
        doppler_hz=math.nan if doppler is None else float(doppler),
        channel_index=int(channel_index),
        first_seen_us=int(first_seen_us),
    )
