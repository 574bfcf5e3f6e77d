"""sllurp-csv: the sample, units, column aliases, every declined row kind, broken files, round trip."""

import math

import numpy as np
import pytest

from scattertrack.io import FormatError, read_scene
from scattertrack.io.importers import import_files, import_sllurp_csv

from import_helpers import assert_round_trip, run_quietly

HEADER = "timestamp,reader,antenna,rssi,epc,phase_angle,channel_index,doppler_frequency\n"
GOOD = "1700000000.0,r:5084,1,-60,b'e2801170',1024,3,16\n"


def imported(write_file, scene, text, name="log.csv"):
    return run_quietly(lambda: import_sllurp_csv([write_file(name, text)], scene))


def test_sample_values_units_and_counts(data, scene):
    (reads, report), found = run_quietly(lambda: import_sllurp_csv([data / "sllurp_log.csv"], scene))
    assert reads.epc.tolist() == ["e28011700000020a1b2c3d01"] * 3 + ["E28011700000020A1B2C3D02"] * 2
    np.testing.assert_allclose(reads.time_s - 1700000000.0, [0.0, 0.015625, 0.03125, 0.0625, 0.09375], atol=1e-6)
    assert reads.antenna.tolist() == [1, 3, 2, 4, 1]
    np.testing.assert_allclose(reads.phase_rad, [0.0, math.pi, math.pi / 2, 2 * math.pi * 4095 / 4096, 3 * math.pi / 2])
    assert reads.channel_index.tolist() == [1, 2, 1, 50, 50]
    assert reads.frequency_hz.tolist() == [902.75e6, 903.25e6, 902.75e6, 927.25e6, 927.25e6]
    np.testing.assert_allclose(reads.doppler_hz, [1.0, 0.0, -2.0, 10.0, np.nan])  # 1/16 Hz units
    assert reads.rssi_dbm.tolist() == [-58.0, -64.0, -61.0, -66.0, -59.0]
    assert (report.rows, report.kept, report.duplicates, report.reordered, report.declined_total) == (6, 5, 1, 1, 0)
    assert report.frequency_from == {"US channel plan": 5}
    assert "time_s <- 'timestamp' (seconds)" in report.columns
    assert any("phase_angle' (Impinj units" in c for c in report.columns)
    assert len(found) == 1 and found[0].line == 2 and "US channel plan in index order" in found[0].message
    assert "calibration can recover" in found[0].message
    assert "kept 5, 1 duplicate dropped, 1 reordered, declined 0" in report.summary()


def test_sample_round_trip(data, scene, tmp_path):
    (reads, _), _ = run_quietly(lambda: import_files("sllurp-csv", [data / "sllurp_log.csv"], scene))
    assert_round_trip(reads, scene, tmp_path / "reads.csv")


def test_hop_table_gives_the_frequency_without_warning(data, write_file):
    text = (data / "import_scene.toml").read_text()
    for index, mhz in ((1, 915.25), (2, 903.75), (50, 926.25)):
        text += f"\n[[hop_table]]\nchannel_index = {index}\nfrequency_hz = {mhz}e6\n"
    scene = read_scene(write_file("scene.toml", text))
    (reads, report), found = run_quietly(lambda: import_sllurp_csv([data / "sllurp_log.csv"], scene))
    assert reads.frequency_hz.tolist() == [915.25e6, 903.75e6, 915.25e6, 926.25e6, 926.25e6]
    assert report.frequency_from == {"hop table": 5} and found == []


@pytest.mark.parametrize(
    "header, time, expected",
    [
        ("timestamp_us", "1700000000000000", 1700000000.0),
        ("timestamp", "1700000000000000", 1700000000.0),  # microseconds by magnitude
        ("Timestamp", "1700000000000", 1700000000.0),  # milliseconds by magnitude
        ("LastSeenTimestampUTC", "1700000000123456", 1700000000.123456),
        ("time_s", "12.5", 12.5),
    ],
)
def test_time_columns_and_units(write_file, scene, header, time, expected):
    text = f"{header},antenna,epc,phase_angle,channel_index\n{time},1,E2,0,1\n"
    (reads, report), _ = imported(write_file, scene, text)
    assert reads.time_s[0] == pytest.approx(expected, abs=1e-6)
    assert report.columns[0].startswith(f"time_s <- '{header}'")


def test_other_aliases_and_units(write_file, scene):
    text = ("Time_S,AntennaPort,EPC-96,PhaseDeg,Frequency_kHz,Peak_RSSI_cdBm,Doppler_Hz\n"
            "1.0,2,0x3034ABCD,90,915250,-6050,1.25\n")
    (reads, report), found = imported(write_file, scene, text)
    assert (reads.epc[0], reads.antenna[0], reads.frequency_hz[0]) == ("3034ABCD", 2, 915.25e6)
    assert (reads.phase_rad[0], reads.rssi_dbm[0], reads.doppler_hz[0]) == (pytest.approx(math.pi / 2), -60.5, 1.25)
    assert reads.channel_index is None and found == []
    assert report.frequency_from == {"row": 1}


def test_phase_in_radians(write_file, scene):
    (reads, _), _ = imported(write_file, scene, "time_s,antenna,epc,phase_rad,frequency_hz\n1.0,1,E2,6.2831853071795862,915e6\n")
    assert 0.0 <= reads.phase_rad[0] < 2 * math.pi


def test_bare_frequency_takes_its_unit_from_the_values(write_file, scene):
    (reads, _), _ = imported(write_file, scene, "time_s,antenna,epc,phase_angle,frequency\n1.0,1,E2,0,915.25\n")
    assert reads.frequency_hz[0] == 915.25e6


def test_a_channel_index_under_a_frequency_name_is_a_clean_error(write_file, scene):
    path = write_file("log.csv", "Timestamp,EPC,AntennaPort,RSSI,PhaseAngle,Frequency\n1744305900601152,E2,1,-52,36,48\n")
    with pytest.raises(FormatError) as caught:
        import_sllurp_csv([path], scene)
    assert (caught.value.path, caught.value.line, caught.value.column) == (str(path), 2, "Frequency")
    assert "name the column channel_index" in caught.value.message


@pytest.mark.parametrize(
    "row, reason",
    [
        ("x,r,1,-60,b'e2801170',1024,3,16", "time not a number"),
        ("1700000000.5,r,1,-60,,1024,3,16", "empty EPC"),
        ("1700000000.5,r,1,-60,b'zz',1024,3,16", "EPC not hex"),
        ("1700000000.5,r,1.5,-60,b'e2801170',1024,3,16", "antenna not an integer"),
        ("1700000000.5,r,9,-60,b'e2801170',1024,3,16", "antenna not in the scene"),
        ("1700000000.5,r,1,-60,b'e2801170',4096,3,16", "phase not an integer 0-4095 (Impinj units)"),
        ("1700000000.5,r,1,-60,b'e2801170',3.6,3,16", "phase not an integer 0-4095 (Impinj units)"),
        ("1700000000.5,r,1,-60,b'e2801170',,3,16", "phase not an integer 0-4095 (Impinj units)"),
        ("1700000000.5,r,1,-60,b'e2801170',1024,0,16", "channel index not a positive integer"),
        ("1700000000.5,r,1,-60,b'e2801170',1024,51,16", "channel index in neither the hop table nor the US plan"),
        ("1700000000.5,r,1,-60,b'e2801170',1024,,16", "no frequency or channel index"),
        ("1700000000.5,r,1,loud,b'e2801170',1024,3,16", "RSSI not a number"),
        ("1700000000.5,r,1,-60,b'e2801170',1024,3,1.5", "Doppler not an integer (1/16 Hz units)"),
        ("1700000000.5,r,1,-60,b'e2801170',1024,3,1_6", "Doppler not an integer (1/16 Hz units)"),
    ],
)
def test_each_malformed_row_kind_is_declined_and_counted_with_its_line(write_file, scene, row, reason):
    (reads, report), _ = imported(write_file, scene, HEADER + GOOD + row + "\n" + GOOD.replace(".0,", ".9,"))
    assert len(reads) == 2
    assert report.declined_by_reason() == {reason: 1}
    assert report.rows == report.kept + report.duplicates + report.declined_total == 3
    assert f"1 {reason} (" in report.summary() and "log.csv line 3)" in report.summary()


def test_rows_are_counted_across_files_with_their_own_lines(write_file, scene):
    first = write_file("a.csv", HEADER + GOOD + "x,r,1,-60,E2,0,1,0\n")
    second = write_file("b.csv", HEADER + GOOD.replace("1700000000.0", "1699999999.0") + GOOD + "y,r,1,-60,E2,0,1,0\n")
    (reads, report), _ = run_quietly(lambda: import_sllurp_csv([first, second], scene))
    assert (report.kept, report.duplicates, report.reordered, report.declined_total) == (2, 1, 1, 2)
    assert report.declined[str(first)].examples == {"time not a number": [3]}
    assert report.declined[str(second)].examples == {"time not a number": [4]}


@pytest.mark.parametrize(
    "text, line, column, fragment",
    [
        ("time_s,antenna,phase_angle,channel_index\n1,1,0,1\n", 1, None, "no epc column"),
        ("time_s,antenna,epc,channel_index\n1,1,E2,1\n", 1, None, "no phase column"),
        ("time_s,antenna,epc,phase_angle\n1,1,E2,0\n", 1, None, "no frequency or channel index column"),
        (HEADER + GOOD + "1,r,1\n", 3, None, "expected 8 fields"),
        (HEADER, 2, None, "no data rows"),
    ],
)
def test_broken_files_are_clean_errors(write_file, scene, text, line, column, fragment):
    path = write_file("log.csv", text)
    with pytest.raises(FormatError) as caught:
        import_sllurp_csv([path], scene)
    assert (caught.value.path, caught.value.line, caught.value.column) == (str(path), line, column)
    assert fragment in caught.value.message


def test_not_utf8_is_a_clean_error(tmp_path, scene):
    path = tmp_path / "log.csv"
    path.write_bytes(HEADER.encode() + b"1,r,1,-60,\xff\xfe,0,1,0\n")
    with pytest.raises(FormatError, match="not UTF-8"):
        import_sllurp_csv([path], scene)


def test_no_row_kept_is_an_error_with_the_summary(write_file, scene):
    with pytest.raises(ValueError, match="no reads kept.*1 antenna not in the scene"):
        imported(write_file, scene, HEADER + GOOD.replace(",1,-60", ",7,-60"))


def test_row_frequency_disagreeing_with_the_hop_table_is_kept_and_warned(data, write_file):
    text = (data / "import_scene.toml").read_text() + "\n[[hop_table]]\nchannel_index = 3\nfrequency_hz = 915.25e6\n"
    scene = read_scene(write_file("scene.toml", text))
    log = "time_s,antenna,epc,phase_angle,channel_index,frequency_hz\n1.0,1,E2,0,3,915.25e6\n2.0,1,E2,0,3,920.25e6\n"
    (reads, report), found = imported(write_file, scene, log)
    assert reads.frequency_hz.tolist() == [915.25e6, 920.25e6]
    assert report.hop_table_disagreements == 1
    assert [(w.line, w.column) for w in found] == [(3, "frequency_hz")]
    assert any(line.startswith("hop table: 1 rows disagree") for line in report.lines())


def test_phases_wrap_into_the_scene_period(data, write_file):
    text = (data / "import_scene.toml").read_text().replace('kind = "cots"', 'kind = "cots"\nphase_period = "pi"')
    scene = read_scene(write_file("scene.toml", text))
    (reads, _), _ = imported(write_file, scene, "time_s,antenna,epc,phase_angle,channel_index\n1.0,1,E2,3072,1\n")
    assert reads.phase_rad[0] == pytest.approx(math.pi / 2)
