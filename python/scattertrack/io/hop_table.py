"""Channel indices and hop tables: which carrier a reader's channel index stands for.

LLRP readers report a 1-based ``ChannelIndex`` into their own hop table
instead of a frequency, and that table is usually shuffled (the FCC asks for
pseudo-random hopping), so index order is not frequency order. A scene may
give the table (``[[hop_table]]``, :attr:`Scene.hop_table`); without it the
best guess is the regional channel plan in index order, which is right for
the set of carriers but not for which index is which, so phase-based
trackers then see a per-channel phase error that calibration can recover
(the true table is the ordering that makes the phases consistent).

Frequencies are in hertz; indices are 1-based integers, -1 for "none".
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.types import warn_input

US_FIRST_CHANNEL_HZ = 902.75e6
US_CHANNEL_SPACING_HZ = 500e3
US_CHANNELS = 50
"""The US (FCC part 15) RAIN plan: 50 channels of 500 kHz, 902.75 to 927.25 MHz."""

MATCH_HZ = 1e3
"""A row's frequency within this of its hop-table entry, hertz, agrees with it
(as channel offsets are matched, docs/formats.md 1)."""

NO_CHANNEL = -1
"""The channel index of a row that has none."""


def us_channel_plan_hz(channel_index: np.ndarray) -> np.ndarray:
    """Carrier of each 1-based index in the US plan taken in index order, hertz; nan outside 1..50."""
    index = np.asarray(channel_index, dtype=np.int64)
    inside = (index >= 1) & (index <= US_CHANNELS)
    return np.where(inside, US_FIRST_CHANNEL_HZ + US_CHANNEL_SPACING_HZ * (index - 1), np.nan)


US_PLAN_HZ = us_channel_plan_hz(np.arange(1, US_CHANNELS + 1))
"""The US plan's 50 carriers in frequency order, hertz: the one home of the plan
(the simulator, the reader emulator and calibration take it from here)."""


def hop_table_hz(channel_index: np.ndarray, hop_table: dict[int, float]) -> np.ndarray:
    """Carrier of each index in ``hop_table`` (index -> Hz), hertz; nan where the table has no entry."""
    index = np.asarray(channel_index, dtype=np.int64)
    out = np.full(len(index), np.nan)
    for channel, frequency in hop_table.items():
        out[index == channel] = frequency
    return out


def disagreements(frequency_hz: np.ndarray, channel_index: np.ndarray, hop_table: dict[int, float]) -> np.ndarray:
    """Mask of rows whose frequency differs by more than :data:`MATCH_HZ` from their index's entry.

    Rows without an index, without a frequency or whose index the table lacks are not flagged.
    """
    expected = hop_table_hz(channel_index, hop_table)
    frequency = np.asarray(frequency_hz, dtype=np.float64)
    known = np.isfinite(expected) & np.isfinite(frequency)
    return known & (np.abs(np.where(known, frequency - expected, 0.0)) > MATCH_HZ)


def warn_disagreements(path, frequency_hz, channel_index, lines, hop_table: dict[int, float],
                       column: str = "frequency_hz") -> int:
    """Warn once (:class:`InputWarning`) when rows disagree with the scene's hop table; return how many do.

    A disagreement is kept, not rejected: the row's own frequency is what the
    reader says it transmitted, and the scene's table may be stale. ``lines``:
    each row's 1-based file line, or None.
    """
    if not hop_table or channel_index is None:
        return 0
    bad = disagreements(frequency_hz, channel_index, hop_table)
    count = int(np.count_nonzero(bad))
    if count:
        row = int(np.argmax(bad))
        index = int(channel_index[row])
        line = None if lines is None else int(lines[row])
        warn_input(path, line, column,
                   f"frequency {float(frequency_hz[row]) / 1e6:.6f} MHz disagrees with the scene's hop table for channel "
                   f"index {index} ({hop_table[index] / 1e6:.6f} MHz); the row's frequency is kept "
                   f"({count} such row{'s' if count != 1 else ''} in the file)")
    return count
