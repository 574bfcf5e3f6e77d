"""``track.csv`` written as rows come (docs/formats.md section 4).

The bytes are those of :func:`scattertrack.io.write_track` for the same rows
(sigma columns included, no quaternions): floats with 6 decimals as Python's
``"%.6f"`` writes them, ``nan`` for nan, the EPC quoted where needed. The
formatting is done in Rust without the GIL (``_core.Engine.format_track_rows``),
so it runs beside the tracker, and a large batch is formatted in two halves
on two threads (:data:`PARALLEL_ROWS`): while one batch's rows are written
nothing else of the stream runs on the second core. A track holds no row in
memory.

The file is written under a temporary name and moved into place by
:meth:`TrackWriter.close`, so a failed run leaves no half track behind.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from scattertrack import _core
from scattertrack.io.csvutil import quote_text, require_finite
from scattertrack.io.track import REQUIRED, SIGMA


PARALLEL_ROWS = 20_000
"""Batches of at least this many rows are formatted in two halves at once (the bytes are the same)."""


class TrackWriter:
    """Append rows with :meth:`write`, then :meth:`close` (or use as a context manager)."""

    def __init__(self, path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._partial = self.path.with_name(self.path.name + ".partial")
        self._file = open(self._partial, "wb")
        self._file.write((",".join(REQUIRED + SIGMA) + "\n").encode())
        self._cells: list[str] = []
        self._helper: ThreadPoolExecutor | None = None
        self.rows = 0

    def write(self, time_s: np.ndarray, epc: np.ndarray, epc_texts: list[str],
              position: np.ndarray, velocity: np.ndarray, sigma: np.ndarray) -> None:
        """Rows in order: ``epc`` codes into ``epc_texts``; metres, m/s, metres (sigma)."""
        if not len(time_s):
            return
        require_finite(self.path, "time_s", time_s)
        require_finite(self.path, "position", position)
        require_finite(self.path, "velocity", velocity[~np.isnan(velocity)])
        require_finite(self.path, "sx..", sigma[~np.isnan(sigma)])
        while len(self._cells) < len(epc_texts):
            self._cells.append(quote_text(str(epc_texts[len(self._cells)])))
        values = np.ascontiguousarray(np.hstack([position, velocity, sigma]), dtype=np.float64)
        time_s = np.ascontiguousarray(time_s, dtype=np.float64)
        epc = np.ascontiguousarray(epc, dtype=np.int64)
        n = len(time_s)
        if n < PARALLEL_ROWS:
            self._file.write(_core.Engine.format_track_rows(time_s, epc, self._cells, values))
        else:
            if self._helper is None:
                self._helper = ThreadPoolExecutor(max_workers=1, thread_name_prefix="track-format")
            half = n // 2
            first = self._helper.submit(_core.Engine.format_track_rows, time_s[:half], epc[:half], self._cells,
                                        values[:half])
            second = _core.Engine.format_track_rows(time_s[half:], epc[half:], self._cells, values[half:])
            self._file.write(first.result())
            self._file.write(second)
        self.rows += n

    def _stop_helper(self) -> None:
        if self._helper is not None:
            self._helper.shutdown()
            self._helper = None

    def close(self) -> None:
        """Finish the file and move it into place."""
        self._stop_helper()
        self._file.close()
        os.replace(self._partial, self.path)

    def discard(self) -> None:
        """Drop the partial file (after an error)."""
        self._stop_helper()
        self._file.close()
        self._partial.unlink(missing_ok=True)

    def __enter__(self) -> "TrackWriter":
        return self

    def __exit__(self, kind, *rest) -> None:
        if kind is None:
            self.close()
        else:
            self.discard()
