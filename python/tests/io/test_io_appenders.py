"""Row-by-row reads.csv and track.csv (scattertrack.io.appenders)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scattertrack.io import read_reads, read_track
from scattertrack.io.appenders import READ_HEADER, ReadsAppender, TrackAppender


def test_the_journal_is_a_reads_csv_at_every_row(tmp_path):
    path = tmp_path / "reads.csv"
    with ReadsAppender(path) as journal:
        written = journal.append(1_796_000_000.1234564, "E2000A01", 1, 915.25e6, 2 * math.pi - 1e-7, -55.5, 1.25, 30)
        journal.flush()
        # Readable while still open: a crash now loses nothing.
        assert len(read_reads(path)) == 1
        journal.append(1_796_000_000.2, "e2000a02", 2, 902.75e6, 1.0)
    assert written[0] == 1_796_000_000.123456 and written[1] < 2 * math.pi
    reads = read_reads(path)
    assert list(reads.epc) == ["E2000A01", "e2000a02"]
    assert reads.time_s[0] == written[0] and reads.phase_rad[0] == written[1]
    assert reads.rssi_dbm[0] == -55.5 and math.isnan(reads.rssi_dbm[1])


def test_appending_to_a_journal_keeps_its_rows(tmp_path):
    path = tmp_path / "reads.csv"
    for t in (1.0, 2.0):
        with ReadsAppender(path) as journal:
            journal.append(t, "E200", 1, 915.25e6, 0.5)
    assert list(read_reads(path).time_s) == [1.0, 2.0]
    assert path.read_text().count("time_s") == 1


def test_appending_to_another_kind_of_file_is_refused(tmp_path):
    path = tmp_path / "other.csv"
    path.write_text("time_s,epc,antenna,frequency_hz,phase_rad\n")
    with pytest.raises(ValueError, match=r"other.csv: line 1: cannot append"):
        ReadsAppender(path)
    assert READ_HEADER[-1] == "channel_index"


def test_a_read_the_reader_would_refuse_is_not_written(tmp_path):
    with ReadsAppender(tmp_path / "reads.csv") as journal:
        with pytest.raises(ValueError, match="cannot write"):
            journal.append(1.0, "not-hex", 1, 915.25e6, 0.5)
        with pytest.raises(ValueError, match="non-finite"):
            journal.append(math.nan, "E200", 1, 915.25e6, 0.5)
        assert journal.rows == 0


def test_the_track_appender_writes_what_read_track_reads(tmp_path):
    path = tmp_path / "track.csv"
    with TrackAppender(path) as track:
        track.append(1.5, "E200", [0.1, 0.2, 0.3], [math.nan] * 3, [0.001, 0.002, 0.003])
        track.append(1.6, "E200", [0.1, 0.2, 0.31], [0.0, 0.0, 0.1], [0.001, 0.002, 0.003])
    result = read_track(path)
    assert len(result) == 2 and np.isnan(result.velocity[0]).all()
    assert result.sigma[1].tolist() == [0.001, 0.002, 0.003]
