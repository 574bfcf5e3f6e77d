"""iq-phasors: CSV and JSON-lines samples, phase and level from I/Q, declined rows, round trip."""

import math

import numpy as np
import pytest

from scattertrack.io.importers import import_iq_phasors
from scattertrack.io.importers.iq_phasors import is_json_lines

from import_helpers import assert_round_trip, run_quietly


def test_csv_sample(data, scene, tmp_path):
    (reads, report), found = run_quietly(lambda: import_iq_phasors([data / "iq_phasors.csv"], scene))
    assert reads.time_s.tolist() == [0.0, 0.005, 0.01, 0.02]
    np.testing.assert_allclose(reads.phase_rad, [0.0, math.pi, math.pi / 2, 3 * math.pi / 2])  # atan2(Q, I) mod 2 pi
    np.testing.assert_allclose(reads.rssi_dbm, [60.0, 60.0, 60.0, 20.0])  # 20 log10 |I + jQ|
    assert reads.frequency_hz.tolist() == [866.9e6, 866.3e6, 866.9e6, 865.7e6]  # MHz column
    assert (report.kept, report.reordered, report.declined_total) == (4, 1, 0)
    assert any(c.startswith("phase_rad <- atan2('q', 'i')") for c in report.columns)
    assert any("not calibrated dBm" in c for c in report.columns)
    assert found == []
    assert_round_trip(reads, scene, tmp_path / "reads.csv")


def test_json_lines_sample(data, scene, tmp_path):
    (reads, report), found = run_quietly(lambda: import_iq_phasors([data / "iq_phasors.jsonl"], scene))
    assert reads.epc.tolist() == ["3000AD38", "3000AD38"]  # 0x unwrapped
    assert reads.time_s.tolist() == [1700000000.0, 1700000000.01]  # microseconds by magnitude
    np.testing.assert_allclose(reads.phase_rad, [math.atan2(4, 3), math.atan2(-4, -3) + 2 * math.pi])
    np.testing.assert_allclose(reads.rssi_dbm, [np.nan, -60.5])  # an RSSI key in the file: no level from I/Q
    assert reads.channel_index.tolist() == [3, 4]
    assert reads.frequency_hz.tolist() == [903.75e6, 904.25e6]
    assert report.frequency_from == {"US channel plan": 2} and len(found) == 1
    assert_round_trip(reads, scene, tmp_path / "reads.csv")


@pytest.mark.parametrize(
    "row, reason",
    [
        ("0.5,E2,1,915.0,,1", "I or Q not a number"),
        ("0.5,E2,1,915.0,1,nan", "I or Q not a number"),
        ("0.5,E2,1,915.0,0,0", "zero phasor (no phase)"),
        ("0.5,E2,1,x,1,1", "frequency not a number"),
        ("0.5,E2,1,99999.0,1,1", "frequency outside 100 MHz to 10 GHz"),
    ],
)
def test_declined_rows(write_file, scene, row, reason):
    path = write_file("iq.csv", "time_s,epc,antenna,frequency_mhz,i,q\n0.1,E2,1,915.0,1,0\n" + row + "\n")
    (reads, report), _ = run_quietly(lambda: import_iq_phasors([path], scene))
    assert len(reads) == 1 and report.declined_by_reason() == {reason: 1}
    assert report.declined[str(path)].examples == {reason: [3]}


def test_json_detection_skips_a_byte_order_mark_and_blank_lines(tmp_path):
    (tmp_path / "a").write_bytes(b"\xef\xbb\xbf\n  {\"i\": 1}\n")
    (tmp_path / "b").write_text("time_s,epc\n")
    assert is_json_lines(tmp_path / "a") and not is_json_lines(tmp_path / "b")
