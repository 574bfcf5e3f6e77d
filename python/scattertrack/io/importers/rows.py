"""From parsed rows to :class:`Reads`: frequencies, antennas, duplicates and time order.

Every importer parses its own format into :class:`Rows` (SI units, or nan
and -1 where a row has no value) and declines malformed rows itself; then
:func:`finish` does what all formats share, in this order:

1. rows naming an antenna the scene does not define are declined;
2. each row's carrier is its own frequency if it has one, else the scene's
   ``[[hop_table]]`` entry for its channel index, else the US channel plan
   in index order (one ``warning:``: readers shuffle their table, so this
   is a guess that calibration can correct); a row with neither is declined;
3. phases are wrapped into [0, P) of the scene's reader;
4. rows whose frequency disagrees with the hop table are warned (kept);
5. exact duplicates (time, EPC, antenna, frequency, phase) are dropped and
   counted; the rest is sorted stably by time, out-of-order rows counted.
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.io import hop_table, units
from scattertrack.io.cells import interned
from scattertrack.io.csvutil import sort_by_time
from scattertrack.io.importers.report import FREQUENCY_SOURCES, ImportReport
from scattertrack.io.reads import duplicate_rows
from scattertrack.io.types import Reads, Scene, warn_input

NO_FREQUENCY = "no frequency or channel index"
UNKNOWN_CHANNEL = "channel index in neither the hop table nor the US plan"
UNKNOWN_ANTENNA = "antenna not in the scene"
FREQUENCY_RANGE = "frequency outside 100 MHz to 10 GHz"
SOURCE = "frequency source"
"""A working column: the index into FREQUENCY_SOURCES of each row's frequency."""


class Rows:
    """Parsed rows of one import, in file order, with the file and 1-based line of each."""

    def __init__(self):
        self.values: dict[str, list] = {name: [] for name in (
            "time_s", "epc", "antenna", "frequency_hz", "phase_rad", "rssi_dbm", "doppler_hz", "channel_index")}
        self.files: list[str] = []
        self.lines: list[int] = []

    def add(self, path, line: int, time_s: float, epc: str, antenna: int, phase_rad: float,
            frequency_hz: float = math.nan, rssi_dbm: float = math.nan, doppler_hz: float = math.nan,
            channel_index: int = hop_table.NO_CHANNEL) -> None:
        """One row: seconds, hex EPC, antenna id, radians, hertz (nan: none), dBm, hertz, index (-1: none)."""
        for name, value in (("time_s", time_s), ("epc", epc), ("antenna", antenna), ("phase_rad", phase_rad),
                            ("frequency_hz", frequency_hz), ("rssi_dbm", rssi_dbm), ("doppler_hz", doppler_hz),
                            ("channel_index", channel_index)):
            self.values[name].append(value)
        self.files.append(str(path))
        self.lines.append(int(line))

    def add_source(self, path, layout, source, report, read_own, count_rows: bool = True) -> None:
        """Every row of ``source`` (``(line, get)`` pairs of ``path`` laid out by ``layout``): its
        shared fields, then ``read_own(values, get)`` puts the format's own into ``values`` and
        returns a decline reason or None. A declined row goes to ``report`` with its reason.
        ``count_rows``: count each row in ``report.rows`` (a JSON-lines source counts its events itself)."""
        for line, get in source:
            if count_rows:
                report.rows += 1
            values, reason = layout.shared(get, line)
            if reason is None:
                reason = read_own(values, get)
            if reason is not None:
                report.decline(path, line, reason)
                continue
            self.add(path, line, **values)

    def __len__(self) -> int:
        return len(self.lines)


def finish(rows: Rows, scene: Scene, report: ImportReport, has_channel_column: bool) -> Reads:
    """The kept rows as :class:`Reads` (steps in the module docstring); ``report`` is filled in.

    ``has_channel_column``: whether any source had a channel index column
    (``Reads.channel_index`` is None otherwise). Raises ValueError when no row is kept.
    """
    files = np.array(rows.files, dtype=object)
    lines = np.array(rows.lines, dtype=np.int64)
    columns = {
        "time_s": np.array(rows.values["time_s"], dtype=np.float64),
        "epc": np.array(rows.values["epc"], dtype=object),
        "antenna": np.array(rows.values["antenna"], dtype=np.int64),
        "frequency_hz": np.array(rows.values["frequency_hz"], dtype=np.float64),
        "phase_rad": np.array(rows.values["phase_rad"], dtype=np.float64),
        "rssi_dbm": np.array(rows.values["rssi_dbm"], dtype=np.float64),
        "doppler_hz": np.array(rows.values["doppler_hz"], dtype=np.float64),
        "channel_index": np.array(rows.values["channel_index"], dtype=np.int64),
    }
    keep = _known_antennas(columns, files, lines, scene, report)
    keep &= _resolve_frequencies(columns, files, lines, scene, report, keep)
    columns = {name: values[keep] for name, values in columns.items()}
    files, lines = files[keep], lines[keep]
    period = scene.reader.period_rad
    columns["phase_rad"] = np.mod(columns["phase_rad"], period)
    columns["phase_rad"] = np.where(columns["phase_rad"] >= period, 0.0, columns["phase_rad"])
    for path in dict.fromkeys(files.tolist()):
        mine = files == path
        report.hop_table_disagreements += hop_table.warn_disagreements(
            path, columns["frequency_hz"][mine], columns["channel_index"][mine], lines[mine], scene.hop_table)
    duplicate = duplicate_rows(columns)
    report.duplicates = int(np.count_nonzero(duplicate))
    columns = {name: values[~duplicate] for name, values in columns.items()}
    columns, report.reordered = sort_by_time(columns)
    report.kept = len(columns["time_s"])
    source = columns.pop(SOURCE)
    for code, name in enumerate(FREQUENCY_SOURCES):
        n = int(np.count_nonzero(source == code))
        if n:
            report.frequency_from[name] = n
    if report.kept == 0:
        raise ValueError(f"no reads kept from {', '.join(report.files)}: {report.summary()}")
    return Reads(
        time_s=columns["time_s"],
        epc=interned(columns["epc"]),
        antenna=columns["antenna"],
        frequency_hz=columns["frequency_hz"],
        phase_rad=columns["phase_rad"],
        rssi_dbm=columns["rssi_dbm"],
        doppler_hz=columns["doppler_hz"],
        channel_index=columns["channel_index"] if has_channel_column else None,
    )


def _known_antennas(columns, files, lines, scene: Scene, report: ImportReport) -> np.ndarray:
    """Mask of rows whose antenna the scene defines; the others are declined."""
    known = np.isin(columns["antenna"], np.array([a.id for a in scene.antennas], dtype=np.int64))
    for i in np.flatnonzero(~known).tolist():
        report.decline(files[i], int(lines[i]), UNKNOWN_ANTENNA)
    return known


def _resolve_frequencies(columns, files, lines, scene: Scene, report: ImportReport, keep: np.ndarray) -> np.ndarray:
    """Fill missing frequencies (hop table, then US plan with a warning); mask of rows that have one.

    Only rows still kept (``keep``) are counted or declined.
    """
    frequency = columns["frequency_hz"]
    index = columns["channel_index"]
    given = np.isfinite(frequency)
    table = hop_table.hop_table_hz(index, scene.hop_table)
    plan = hop_table.us_channel_plan_hz(index)
    from_table = ~given & np.isfinite(table)
    from_plan = ~given & ~from_table & np.isfinite(plan)
    frequency = np.select([from_table, from_plan], [table, plan], default=frequency)
    columns["frequency_hz"] = frequency
    outside = given & units.frequency_outside(frequency)
    resolved = (given & ~outside) | from_table | from_plan
    for i in np.flatnonzero(keep & ~resolved).tolist():
        reason = FREQUENCY_RANGE if outside[i] else (NO_FREQUENCY if index[i] == hop_table.NO_CHANNEL else UNKNOWN_CHANNEL)
        report.decline(files[i], int(lines[i]), reason)
    # Where each frequency came from, counted once duplicates are gone.
    columns[SOURCE] = np.select([from_table, from_plan], [1, 2], default=0)
    planned = from_plan & keep
    if planned.any():
        first = int(np.argmax(planned))
        n = int(np.count_nonzero(planned))
        warn_input(files[first], int(lines[first]), "channel_index",
                   f"{n} row{'s' if n != 1 else ''} have no frequency and the scene has no [[hop_table]] entry for "
                   "their channel index: their frequency is the US channel plan in index order (902.75 + "
                   "0.5*(index - 1) MHz), but readers shuffle their hop table, so channels may be mislabelled; "
                   "calibration can recover the true table (or give [[hop_table]] in the scene)")
    return resolved
