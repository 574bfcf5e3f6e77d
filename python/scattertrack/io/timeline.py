"""Clock jumps in a time column: valid input, but worth a warning.

Rows may arrive out of time order (docs/formats.md 2: readers batch and
interleave reports) and the readers sort them. A reorder of a few hundred
milliseconds is what buffering produces; a row more than
:data:`BACKWARD_JUMP_S` earlier than a row before it means the reader's clock
was reset or two logs were concatenated, and sorting then silently mixes two
sessions. A gap of more than :data:`FORWARD_GAP_S` with no rows at all
means a clock jump forward or a paused log: trackers coast through gaps,
but after a minute a tag may be anywhere.

Both are checked in file order against the latest time seen so far, so a
single glitched row gives one warning, not one per row after it.
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.types import warn_input

BACKWARD_JUMP_S = 1.0
"""A row earlier than the latest time before it by more than this, seconds, is a clock jump back."""

FORWARD_GAP_S = 60.0
"""A step forward from the latest time before it larger than this, seconds, is a clock jump forward."""


def warn_clock_jumps(path, time_s: np.ndarray, lines: np.ndarray, column: str = "time_s") -> None:
    """Warn (:class:`InputWarning`) at the first clock jump back and the first jump forward, in file order.

    ``time_s``: the column in file order, seconds; ``lines``: each row's
    1-based file line. Each warning says how many such jumps the file has.
    """
    if len(time_s) < 2:
        return
    latest = np.maximum.accumulate(time_s)[:-1]
    step = time_s[1:] - latest
    back = step < -BACKWARD_JUMP_S
    forward = step > FORWARD_GAP_S
    if back.any():
        # Count onsets: after a reset the rows stay behind the latest time for a while.
        jumps = int(np.count_nonzero(back & ~np.concatenate([[False], back[:-1]])))
        row = int(np.argmax(back)) + 1
        warn_input(
            path, int(lines[row]), column,
            f"clock jumps back by {-step[row - 1]:.6g} s (to {_seconds(time_s[row])} s after {_seconds(latest[row - 1])} s); "
            f"rows are sorted by time, but a reorder beyond {BACKWARD_JUMP_S:g} s suggests a clock reset "
            f"or joined logs ({_count(jumps, 'such jump')} in the file)",
        )
    if forward.any():
        row = int(np.argmax(forward)) + 1
        warn_input(
            path, int(lines[row]), column,
            f"clock jumps forward by {step[row - 1]:.6g} s (from {_seconds(latest[row - 1])} s to {_seconds(time_s[row])} s) "
            f"with no rows between: a clock jump or a paused log (gaps beyond {FORWARD_GAP_S:g} s are warned; "
            f"{_count(int(np.count_nonzero(forward)), 'such gap')} in the file)",
        )


def _seconds(value: float) -> str:
    """A time with microseconds ('12.345678'), or 6 significant digits when huge (garbage, not a clock)."""
    return f"{value:.6f}" if abs(value) < 1e12 else f"{value:.6g}"


def _count(n: int, what: str) -> str:
    """'1 such jump', '3 such jumps'."""
    return f"{n} {what}" if n == 1 else f"{n} {what}s"


def warn_outside_span(path, time_s: np.ndarray, lines: np.ndarray | None, span_path, span_time_s: np.ndarray,
                      what: str, column: str = "time_s", noun: str = "row") -> None:
    """Warn (:class:`InputWarning`) when rows of ``path`` lie before the first or after the last
    time of another file on the same clock (``span_path``: features against the IMU).

    ``time_s``: the rows' times, seconds, any order; ``lines``: their 1-based
    file lines (or None); ``span_time_s``: the other file's times, sorted;
    ``what``: its rows' name ("IMU sample"); ``noun``: the name of ours
    ("row", "epoch"). One warning per side, at the
    row furthest outside, with the count: rows outside have no inertial data
    to be fused with, so a fusion declines them; a whole file outside
    means two clocks (docs/formats.md 7: features share the IMU's clock).
    """
    if not len(time_s) or not len(span_time_s):
        return
    first, last = float(span_time_s[0]), float(span_time_s[-1])
    for outside, side, edge in ((time_s < first, "before the first", first), (time_s > last, "after the last", last)):
        count = int(np.count_nonzero(outside))
        if not count:
            continue
        far = int(np.argmax(np.abs(time_s - edge) * outside))
        line = int(lines[far]) if lines is not None and len(lines) == len(time_s) else None
        clocks = "; every row is outside: are the two files on one clock?" if count == len(time_s) else ""
        warn_input(
            path, line, column,
            f"{count} of {_count(len(time_s), noun)} lie {side} {what} of {span_path} ({_seconds(edge)} s; this {noun} "
            f"at {_seconds(time_s[far])} s is {abs(time_s[far] - edge):.6g} s {side.split()[0]} it): there is no "
            f"inertial data to fuse them with{clocks}",
        )
