"""reads.csv: round trips, the shared example, and one test per malformed input."""

import math

import numpy as np
import pytest

from scattertrack.io import (
    Antenna,
    FormatError,
    Reader,
    Reads,
    Scene,
    read_reads,
    read_scene,
    write_reads,
)
from scattertrack.io import csvutil

HEADER = "time_s,epc,antenna,frequency_hz,phase_rad,rssi_dbm,doppler_hz\n"
ROWS = [
    "0.100000,E2000A01,1,915250000.0,4.473088,-29.55,-2.87\n",
    "0.200000,E2000A01,2,915250000.0,4.319690,-25.99,-3.88\n",
    "0.300000,E2000A02,3,902750000.0,0.016874,-27.46,0.74\n",
    "0.400000,E2000A01,4,927250000.0,6.283185,-27.76,-1.11\n",
]
GOOD = HEADER + "".join(ROWS)


def scene_with(*antenna_ids, period="2pi") -> Scene:
    antennas = [Antenna(i, np.zeros(3)) for i in antenna_ids]
    return Scene("test", 3, Reader(kind="cots", phase_period=period), antennas)


def make_reads(n: int = 5, seed: int = 0) -> Reads:
    rng = np.random.default_rng(seed)
    rssi = rng.uniform(-80, -20, n).round(2)
    rssi[1] = math.nan
    return Reads(
        time_s=np.arange(n) * 0.0125,
        epc=np.array([f"E2000A0{i % 3}" for i in range(n)]),
        antenna=np.arange(n) % 4 + 1,
        frequency_hz=902.75e6 + 0.5e6 * (np.arange(n) % 50),
        phase_rad=rng.uniform(0, 2 * np.pi, n),
        rssi_dbm=rssi,
        doppler_hz=np.full(n, math.nan),
    )


def assert_reads_close(a: Reads, b: Reads) -> None:
    assert len(a) == len(b)
    np.testing.assert_allclose(a.time_s, b.time_s, rtol=0, atol=5e-7)
    np.testing.assert_array_equal(a.epc, b.epc)
    np.testing.assert_array_equal(a.antenna, b.antenna)
    np.testing.assert_array_equal(a.frequency_hz, b.frequency_hz)
    np.testing.assert_allclose(a.phase_rad, b.phase_rad, rtol=0, atol=1e-6)
    np.testing.assert_allclose(a.rssi_dbm, b.rssi_dbm, rtol=0, atol=5e-3)
    np.testing.assert_allclose(a.doppler_hz, b.doppler_hz, rtol=0, atol=5e-3)


def test_round_trip(tmp_path):
    reads = make_reads(200)
    write_reads(tmp_path / "reads.csv", reads)
    again = read_reads(tmp_path / "reads.csv", scene_with(1, 2, 3, 4))
    assert_reads_close(reads, again)
    assert again.reordered == 0 and again.skipped.total == 0
    assert again.time_s.dtype == np.float64 and again.antenna.dtype == np.int64


def test_writer_formats(tmp_path):
    write_reads(tmp_path / "reads.csv", make_reads(3))
    lines = (tmp_path / "reads.csv").read_text().splitlines()
    # doppler is all nan: no column; one rssi is nan: an empty cell.
    assert lines[0] == "time_s,epc,antenna,frequency_hz,phase_rad,rssi_dbm"
    assert lines[1].startswith("0.000000,E2000A00,1,902750000.0,")
    assert lines[2].endswith(",")
    assert len(lines[1].split(",")[4].split(".")[1]) == 6


def test_writer_never_rounds_onto_the_period(tmp_path):
    reads = make_reads(2)
    reads.phase_rad[:] = [np.nextafter(2 * np.pi, 0), np.nextafter(np.pi, 0)]
    write_reads(tmp_path / "reads.csv", reads)
    again = read_reads(tmp_path / "reads.csv")
    assert (again.phase_rad < 2 * np.pi).all()
    assert again.phase_rad[1] < np.pi
    np.testing.assert_allclose(again.phase_rad, reads.phase_rad, atol=1e-6)


def test_good_file(write_file):
    reads = read_reads(write_file("reads.csv", GOOD), scene_with(1, 2, 3, 4))
    assert len(reads) == 4
    assert reads.epcs() == ["E2000A01", "E2000A02"]
    np.testing.assert_array_equal(reads.antenna, [1, 2, 3, 4])
    assert reads.frequency_hz[2] == 902.75e6
    assert reads.rssi_dbm[0] == -29.55 and reads.doppler_hz[2] == 0.74


def test_example_loads(examples):
    scene = read_scene(examples / "cots-3d-arm" / "scene.toml")
    reads = read_reads(examples / "cots-3d-arm" / "reads.csv", scene)
    assert len(reads) == 331
    assert reads.reordered == 3  # the example has a few reads out of time order
    assert (np.diff(reads.time_s) >= 0).all()
    assert reads.skipped.total == 0
    assert set(reads.antenna.tolist()) == {1, 2, 3, 4}
    assert np.isfinite(reads.rssi_dbm).all() and np.isfinite(reads.doppler_hz).all()


def test_column_order_free_extra_columns_ignored_optional_absent(write_file):
    text = "phase_rad,channel,antenna,epc,time_s,frequency_hz\n1.5,7,2,ABC,0.25,915e6\n"
    reads = read_reads(write_file("reads.csv", text))
    assert (reads.time_s[0], reads.epc[0], reads.antenna[0]) == (0.25, "ABC", 2)
    assert reads.frequency_hz[0] == 915e6 and reads.phase_rad[0] == 1.5
    assert math.isnan(reads.rssi_dbm[0]) and math.isnan(reads.doppler_hz[0])


def test_empty_optional_cell_is_nan(write_file):
    text = HEADER + "0.1,E1,1,915e6,1.0,,\n0.2,E1,1,915e6,1.0,-40.5, \n"
    reads = read_reads(write_file("reads.csv", text))
    assert np.isnan(reads.rssi_dbm[0]) and reads.rssi_dbm[1] == -40.5
    assert np.isnan(reads.doppler_hz).all()


def test_byte_order_mark_crlf_and_trailing_blank_lines(write_file):
    text = "\ufeff" + GOOD.replace("\n", "\r\n") + "\r\n\r\n"
    reads = read_reads(write_file("reads.csv", text))
    assert len(reads) == 4 and reads.time_s[0] == 0.1


def test_quoted_cells(write_file):
    header = HEADER.replace("\n", ",note\n")
    text = header + '0.1,"E200",1,"915e6",1.0,,,"a, b"\n0.2,E2FF,"1",915e6,1.0,,,"x""y"\n'
    reads = read_reads(write_file("reads.csv", text))
    assert reads.epc.tolist() == ["E200", "E2FF"]
    np.testing.assert_array_equal(reads.frequency_hz, [915e6, 915e6])


def test_epc_case_and_length_round_trip(tmp_path):
    reads = make_reads(3)
    reads.epc = np.array(["e2a0ff", "ABCDEF0123" * 100, "7"])
    write_reads(tmp_path / "reads.csv", reads)
    np.testing.assert_array_equal(read_reads(tmp_path / "reads.csv").epc, reads.epc)


def test_rows_out_of_order_are_sorted_and_counted(write_file):
    text = HEADER + ROWS[2] + ROWS[0] + ROWS[3] + ROWS[1]
    reads = read_reads(write_file("reads.csv", text))
    np.testing.assert_array_equal(reads.time_s, [0.1, 0.2, 0.3, 0.4])
    assert reads.reordered == 2  # 0.1 after 0.3, 0.2 after 0.4
    assert reads.skipped.total == 0


def test_sort_is_stable(write_file):
    text = HEADER + "1.0,B,1,915e6,1.0,,\n0.5,C,1,915e6,1.0,,\n1.0,A,1,915e6,1.0,,\n"
    reads = read_reads(write_file("reads.csv", text))
    assert reads.epc.tolist() == ["C", "B", "A"]
    assert reads.reordered == 1


def test_duplicate_rows_are_skipped_and_counted(write_file):
    text = HEADER + ROWS[0] + ROWS[1] + ROWS[0] + ROWS[2] + ROWS[1] + ROWS[0]
    reads = read_reads(write_file("reads.csv", text))
    assert len(reads) == 3
    assert reads.skipped.counts == {"duplicate row": 3}
    assert reads.skipped.examples["duplicate row"] == [4, 6, 7]
    assert "3 duplicate row (lines 4, 6, 7)" in reads.skipped.summary()


def test_same_read_with_other_rssi_is_still_a_duplicate(write_file):
    text = HEADER + ROWS[0] + ROWS[0].replace("-29.55", "-30.00")
    reads = read_reads(write_file("reads.csv", text))
    assert len(reads) == 1 and reads.skipped.counts == {"duplicate row": 1}


def test_phase_within_tolerance_is_wrapped(write_file):
    text = HEADER + f"0.1,E1,1,915e6,{2 * math.pi + 5e-10!r},,\n0.2,E1,1,915e6,-5e-10,,\n"
    reads = read_reads(write_file("reads.csv", text))
    assert ((reads.phase_rad >= 0) & (reads.phase_rad < 2 * math.pi)).all()


def test_many_chunks(tmp_path, monkeypatch):
    monkeypatch.setattr(csvutil, "CHUNK_ROWS", 7)
    reads = make_reads(100)
    write_reads(tmp_path / "reads.csv", reads)
    assert_reads_close(reads, read_reads(tmp_path / "reads.csv"))


# --- malformed inputs: each names the file, the line and the column --------


def error_for(write_file, text: str, scene: Scene | None = None) -> FormatError:
    path = write_file("reads.csv", text)
    with pytest.raises(FormatError) as caught:
        read_reads(path, scene)
    assert caught.value.path == str(path)
    return caught.value


def test_missing_column(write_file):
    error = error_for(write_file, GOOD.replace(",phase_rad", ",phase"))
    assert (error.line, error.column) == (1, "phase_rad")
    assert error.message == "missing required column"


def test_nan_value(write_file):
    error = error_for(write_file, GOOD.replace("4.319690", "nan"))
    assert (error.line, error.column) == (3, "phase_rad")
    assert str(error) == f"{error.path}:3: line 3, column 'phase_rad': not a finite number: 'nan'"


def test_nan_in_optional_column(write_file):
    error = error_for(write_file, GOOD.replace("-25.99", "NaN"))
    assert (error.line, error.column) == (3, "rssi_dbm")


def test_inf_value(write_file):
    error = error_for(write_file, GOOD.replace("0.300000", "inf"))
    assert (error.line, error.column) == (4, "time_s")
    assert error.message == "not a finite number: 'inf'"


def test_non_numeric_value(write_file):
    error = error_for(write_file, GOOD.replace("927250000.0", "927.25MHz"))
    assert (error.line, error.column) == (5, "frequency_hz")
    assert error.message == "not a number: '927.25MHz'"


def test_non_numeric_optional_value(write_file):
    error = error_for(write_file, GOOD.replace("-3.88", "n/a"))
    assert (error.line, error.column) == (3, "doppler_hz")


def test_empty_required_value(write_file):
    error = error_for(write_file, GOOD.replace("0.200000", ""))
    assert (error.line, error.column) == (3, "time_s")
    assert error.message == "empty value"


def test_unknown_antenna(write_file):
    error = error_for(write_file, GOOD, scene_with(1, 2, 4))
    assert (error.line, error.column) == (4, "antenna")
    assert error.message == "antenna '3' is not in the scene"


def test_antenna_not_an_integer(write_file):
    error = error_for(write_file, GOOD.replace(",2,915250000.0", ",2.0,915250000.0"))
    assert (error.line, error.column) == (3, "antenna")


@pytest.mark.parametrize("frequency", ["0.0", "-915e6"])
def test_frequency_not_positive(write_file, frequency):
    error = error_for(write_file, GOOD.replace("902750000.0", frequency))
    assert (error.line, error.column) == (4, "frequency_hz")


def test_phase_outside_period(write_file):
    error = error_for(write_file, GOOD.replace("4.319690", "6.3"))
    assert (error.line, error.column) == (3, "phase_rad")
    error = error_for(write_file, GOOD.replace("4.319690", "-0.1"))
    assert (error.line, error.column) == (3, "phase_rad")


def test_phase_outside_pi_period_of_the_scene(write_file):
    error = error_for(write_file, GOOD, scene_with(1, 2, 3, 4, period="pi"))
    assert (error.line, error.column) == (2, "phase_rad")


def test_empty_epc(write_file):
    error = error_for(write_file, GOOD.replace("E2000A02", " "))
    assert (error.line, error.column) == (4, "epc")


def test_wrong_number_of_fields(write_file):
    error = error_for(write_file, GOOD.replace(",-25.99", ""))
    assert (error.line, error.column) == (3, None)
    assert error.message == "expected 7 fields (as in the header), found 6"


def test_empty_file(write_file):
    error = error_for(write_file, "")
    assert (error.line, error.column) == (1, None)
    assert "empty file" in error.message


def test_header_only(write_file):
    error = error_for(write_file, HEADER + "\n")
    assert (error.line, error.column) == (2, None)
    assert error.message == "no data rows"


def test_blank_line_between_rows(write_file):
    error = error_for(write_file, HEADER + ROWS[0] + "\n" + ROWS[1])
    assert (error.line, error.column) == (3, None)


def test_duplicate_column(write_file):
    error = error_for(write_file, GOOD.replace("rssi_dbm", "epc"))
    assert (error.line, error.column) == (1, "epc")


def test_first_error_in_file_order_wins(write_file):
    # Line 3 has a bad phase, line 2 an unknown antenna: line 2 is reported.
    text = GOOD.replace("4.319690", "7.0").replace(",1,915250000.0", ",9,915250000.0")
    error = error_for(write_file, text, scene_with(1, 2, 3, 4))
    assert (error.line, error.column) == (2, "antenna")
    # On one line, the leftmost column is reported.
    error = error_for(write_file, GOOD.replace("0.200000,E2000A01,2", "x,E2000A01,x"))
    assert (error.line, error.column) == (3, "time_s")


def test_line_numbers_after_many_chunks_and_quotes(write_file, monkeypatch):
    monkeypatch.setattr(csvutil, "CHUNK_ROWS", 3)
    rows = [f'{i * 0.1:.6f},"E1",1,915e6,1.0,,\n' for i in range(10)]
    rows[8] = rows[8].replace("1.0,,", "nan,,")
    error = error_for(write_file, HEADER + "".join(rows))
    assert (error.line, error.column) == (10, "phase_rad")


def test_line_numbers_with_a_quoted_line_break(write_file):
    header = HEADER.replace("\n", ",note\n")
    text = header + '0.1,E1,1,915e6,1.0,,,"two\nlines"\n0.2,E1,1,915e6,x,,,\n'
    error = error_for(write_file, text)
    assert (error.line, error.column) == (4, "phase_rad")


def test_not_utf8(tmp_path):
    path = tmp_path / "reads.csv"
    path.write_bytes(GOOD.replace("E2000A02", "E2\xe9").encode("latin-1"))
    with pytest.raises(FormatError) as caught:
        read_reads(path)
    assert "UTF-8" in caught.value.message
