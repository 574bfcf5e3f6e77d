"""reads.csv input hygiene: ASCII numbers, hex EPCs, id bounds, units, clock jumps, accepted variants.

Each malformed case asserts the file, the 1-based line and the column of
the error; each warning asserts its line; each accepted variant reads back
the values it holds.
"""

import math
import warnings

import numpy as np
import pytest

from scattertrack.io import FormatError, InputWarning, read_reads, write_reads
from scattertrack.io.cells import TextTable

HEADER = "time_s,epc,antenna,frequency_hz,phase_rad\n"
ROW = "0.1,E200,1,915e6,1.0\n"


def error_for(write_file, text: str) -> FormatError:
    path = write_file("reads.csv", text)
    with pytest.raises(FormatError) as caught:
        read_reads(path)
    assert caught.value.path == str(path)
    return caught.value


def read_quietly(path):
    """read_reads, failing the test on any InputWarning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        return read_reads(path)


def input_warnings(path) -> list[InputWarning]:
    """The InputWarnings read_reads issues for ``path``."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_reads(path)
    return [w.message for w in caught if issubclass(w.category, InputWarning)]


# --- numbers: ASCII decimal only ---------------------------------------------


@pytest.mark.parametrize(
    "cell, fragment",
    [
        ("1_0.5", "'_' digit separators"),
        ("\uff13", "U+FF13"),  # full-width 3
        ("1\u00a0", "U+00A0"),  # no-break space, which float() strips
        ("\u0661.5", "U+0661"),  # Arabic-Indic digit one
        ("infinity", "not a finite number"),
        ("-inf", "not a finite number"),
        ("nan", "not a finite number"),
        ("1.2.3", "not a number"),
        ("0x10", "not a number"),
    ],
)
def test_time_must_be_an_ascii_decimal(write_file, cell, fragment):
    error = error_for(write_file, HEADER + ROW + f"{cell},E200,1,915e6,1.0\n")
    assert (error.line, error.column) == (3, "time_s")
    assert fragment in error.message


@pytest.mark.parametrize("cell", ["\uff13", "3_0", "3.0", "+", "nan"])
def test_antenna_must_be_ascii_digits(write_file, cell):
    error = error_for(write_file, HEADER + ROW + f"0.2,E200,{cell},915e6,1.0\n")
    assert (error.line, error.column) == (3, "antenna")
    assert "not an integer" in error.message or "not a finite number" in error.message


@pytest.mark.parametrize("cell", ["9223372036854775808", "-9223372036854775809", "1" * 40])
def test_antenna_id_must_fit_in_int64(write_file, cell):
    error = error_for(write_file, HEADER + ROW + f"0.2,E200,{cell},915e6,1.0\n")
    assert (error.line, error.column) == (3, "antenna")
    assert "out of range" in error.message and "64-bit" in error.message


def test_int64_extremes_are_accepted(write_file):
    text = HEADER + "0.1,E200,9223372036854775807,915e6,1.0\n0.2,E200,-9223372036854775808,915e6,1.0\n"
    reads = read_reads(write_file("reads.csv", text))
    assert reads.antenna.tolist() == [2**63 - 1, -(2**63)]


@pytest.mark.parametrize("cell, value", [("+.5", 0.5), ("5.", 5.0), ("1E-1", 0.1), (" 2.5\t", 2.5), ("-0", 0.0)])
def test_ascii_number_forms_are_accepted(write_file, cell, value):
    reads = read_reads(write_file("reads.csv", HEADER + f"{cell},E200,1,915e6,1.0\n"))
    assert reads.time_s[0] == value


def test_bad_number_in_an_optional_column(write_file):
    text = "time_s,epc,antenna,frequency_hz,phase_rad,rssi_dbm\n0.1,E200,1,915e6,1.0,\n0.2,E200,1,915e6,1.0,-4_0\n"
    error = error_for(write_file, text)
    assert (error.line, error.column) == (3, "rssi_dbm")


def test_non_ascii_epc_does_not_hide_a_bad_number(write_file):
    # The plain-block shortcut must not skip the per-column check when another column is not ASCII.
    error = error_for(write_file, HEADER + "0.1,\u00e9,1,915e6,1_0\n")
    assert (error.line, error.column) == (2, "epc")
    error = error_for(write_file, HEADER + "1_0,\u00e9,1,915e6,1.0\n")
    assert (error.line, error.column) == (2, "time_s")


# --- EPCs: hex of any length and case -------------------------------------------


@pytest.mark.parametrize(
    "cell, fragment",
    [
        ("E2G0", "is not hex"),
        ("E2\x0000", "U+0000"),
        ("b'E200'", "bytes literal"),
        ('"b""E200"""', "bytes literal"),
        ("E2-00", "is not hex"),
        ('"E2,00"', "is not hex"),
        ("\u0415200", "U+0415"),  # Cyrillic capital IE, looks like E
    ],
)
def test_epc_must_be_hex(write_file, cell, fragment):
    error = error_for(write_file, HEADER + ROW + f"0.2,{cell},1,915e6,1.0\n")
    assert (error.line, error.column) == (3, "epc")
    assert fragment in error.message


def test_empty_epc(write_file):
    error = error_for(write_file, HEADER + ROW + "0.2, ,1,915e6,1.0\n")
    assert (error.line, error.column, error.message) == (3, "epc", "empty value")


def test_epc_case_and_length_are_kept(write_file, tmp_path):
    long_epc = "e2" * 500
    text = HEADER + f"0.1,{long_epc},1,915e6,1.0\n0.2,aBcD,2,915e6,1.0\n"
    reads = read_quietly(write_file("reads.csv", text))
    assert reads.epc.tolist() == [long_epc, "aBcD"]
    write_reads(tmp_path / "again.csv", reads)
    assert f",{long_epc}," in (tmp_path / "again.csv").read_text()


def test_epcs_share_one_string_per_tag(write_file):
    text = HEADER + "".join(f"0.{i},E2{i % 2},1,915e6,1.0\n" for i in range(1, 9))
    reads = read_reads(write_file("reads.csv", text))
    assert reads.epc.dtype == object
    first = reads.epc[reads.epc == "E20"]
    assert all(e is first[0] for e in first)  # interned: one object, not copies
    assert reads.epcs() == ["E21", "E20"]


def test_epcs_differing_only_in_case_warn(write_file):
    text = HEADER + "0.1,e200,1,915e6,1.0\n0.2,E2FF,1,915e6,1.0\n0.3,E200,1,915e6,1.0\n"
    path = write_file("reads.csv", text)
    (warning,) = input_warnings(path)
    assert (warning.line, warning.column) == (4, "epc")
    assert "only in letter case" in warning.message
    with pytest.warns(InputWarning):
        assert sorted(set(read_reads(path).epc.tolist())) == ["E200", "E2FF", "e200"]  # kept as written


def test_writer_refuses_what_the_reader_rejects(tmp_path):
    reads = read_reads_from_text(tmp_path, HEADER + ROW)
    reads.epc = np.array(["not hex"], dtype=object)
    with pytest.raises(ValueError, match="is not hex"):
        write_reads(tmp_path / "out.csv", reads)
    reads.epc = np.array(["E200"], dtype=object)
    reads.frequency_hz = np.array([915.25])
    with pytest.raises(ValueError, match="looks like MHz"):
        write_reads(tmp_path / "out.csv", reads)


def read_reads_from_text(folder, text):
    path = folder / "in.csv"
    path.write_text(text)
    return read_reads(path)


def test_text_table_codes_follow_first_appearance():
    table = TextTable()
    codes, new = table.encode(["b", "a", "b"])
    assert codes.tolist() == [0, 1, 0] and new == ["b", "a"]
    codes, new = table.encode(["a", "c"])
    assert codes.tolist() == [1, 2] and new == ["c"]
    assert table.decode(np.array([2, 0])).tolist() == ["c", "b"]


# --- units ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "cell, fragment",
    [
        ("915.25", "looks like MHz: multiply by 1e6"),
        ("0.91525", "looks like GHz: multiply by 1e9"),
        ("915250", "looks like kHz: multiply by 1e3"),
        ("99e6", "outside 100 MHz to 10 GHz"),
        ("10.5e9", "outside 100 MHz to 10 GHz"),
        ("-915e6", "outside 100 MHz to 10 GHz"),
        ("0", "outside 100 MHz to 10 GHz"),
    ],
)
def test_frequency_range_and_unit_hint(write_file, cell, fragment):
    error = error_for(write_file, HEADER + ROW + f"0.2,E200,1,{cell},1.0\n")
    assert (error.line, error.column) == (3, "frequency_hz")
    assert fragment in error.message


def test_frequency_range_ends_are_accepted(write_file):
    reads = read_reads(write_file("reads.csv", HEADER + "0.1,E2,1,100e6,1.0\n0.2,E2,1,10e9,1.0\n"))
    assert reads.frequency_hz.tolist() == [100e6, 10e9]


def phase_rows(phases) -> str:
    return HEADER + "".join(f"0.{i + 1},E200,1,915e6,{p}\n" for i, p in enumerate(phases))


@pytest.mark.parametrize(
    "phases, fragment",
    [
        ([10.5, 359.9, 120.25], "looks like degrees: multiply by pi/180"),
        ([12, 359, 120], "looks like degrees (multiply by pi/180) or Impinj units"),
        ([100, 4095, 2048], "looks like Impinj units (0-4095): divide by 4096 and multiply by 2*pi"),
        ([1.0, -3.0, 2.0], "looks like (-pi, pi]: add 2*pi to negative phases"),
        ([1.0, 5000.0], "outside [0, 2*pi)"),
    ],
)
def test_phase_unit_hint(write_file, phases, fragment):
    error = error_for(write_file, phase_rows(phases))
    assert error.column == "phase_rad"
    assert error.line == 2 + next(i for i, p in enumerate(phases) if not 0 <= p < 2 * math.pi)
    assert fragment in error.message


# --- clock jumps ------------------------------------------------------------------


def times_file(write_file, times) -> str:
    return write_file("reads.csv", HEADER + "".join(f"{t},E200,1,915e6,1.0\n" for t in times))


def test_backward_jump_beyond_one_second_warns(write_file):
    path = times_file(write_file, [20.0, 20.1, 20.2, 10.0, 10.1, 20.3])
    (warning,) = input_warnings(path)
    assert (warning.path, warning.line, warning.column) == (str(path), 5, "time_s")
    assert "clock jumps back by 10.2 s" in warning.message and "1 such jump" in warning.message
    assert str(warning).startswith(f"{path}:5: line 5, column 'time_s': ")
    with pytest.warns(InputWarning):
        reads = read_reads(path)
    assert reads.time_s.tolist() == sorted(reads.time_s.tolist())  # still sorted, nothing dropped
    assert len(reads) == 6


def test_small_reorder_is_not_a_jump(write_file):
    reads = read_quietly(times_file(write_file, [1.0, 1.5, 0.6, 2.0]))  # 0.9 s back: a plausible reorder
    assert reads.reordered == 1


def test_forward_gap_beyond_a_minute_warns(write_file):
    path = times_file(write_file, [1.0, 2.0, 63.0, 64.0, 200.0])
    (warning,) = input_warnings(path)
    assert (warning.line, warning.column) == (4, "time_s")
    assert "clock jumps forward by 61 s" in warning.message and "2 such gaps" in warning.message


def test_a_gap_of_a_minute_is_not_a_jump(write_file):
    read_quietly(times_file(write_file, [1.0, 61.0]))


# --- accepted variants -------------------------------------------------------------


def test_bom_crlf_and_quotes(write_file):
    text = "\ufeff" + (HEADER + '0.1,"E200",1,"915e6",1.0\n0.2,E200,2,915e6,2.0\n').replace("\n", "\r\n")
    reads = read_quietly(write_file("reads.csv", text))
    assert reads.epc.tolist() == ["E200", "E200"] and reads.antenna.tolist() == [1, 2]


def test_unknown_columns_and_empty_optional_cells(write_file):
    text = "note,time_s,epc,antenna,frequency_hz,phase_rad,rssi_dbm,doppler_hz\n" \
           "hello,0.1,E200,1,915e6,1.0,,\nworld \u00e9,0.2,E200,1,915e6,1.0,-40.5,\n"
    reads = read_quietly(write_file("reads.csv", text))
    assert np.isnan(reads.rssi_dbm[0]) and reads.rssi_dbm[1] == -40.5
    assert np.isnan(reads.doppler_hz).all()


def test_unix_epoch_times(write_file):
    reads = read_quietly(write_file("reads.csv", HEADER + "1.7e9,E200,1,915e6,1.0\n1700000000.012345,E200,2,915e6,1.0\n"))
    assert reads.time_s.tolist() == [1.7e9, 1700000000.012345]


def test_a_single_data_row(write_file):
    reads = read_quietly(write_file("reads.csv", HEADER + ROW.rstrip("\n")))  # no final line end either
    assert len(reads) == 1 and reads.reordered == 0


def test_line_numbers_after_quoted_line_breaks(write_file):
    header = HEADER.replace("\n", ',"a\nnote"\n')  # the header itself spans lines 1-2
    text = header + '0.1,E200,1,915e6,1.0,"x\ny\nz"\n0.2,E200,1,915e6,1.0,\n0.3,E200,1,915_0,1.0,\n'
    error = error_for(write_file, text)
    assert (error.line, error.column) == (7, "frequency_hz")


def test_line_numbers_on_the_fast_path(write_file):
    error = error_for(write_file, HEADER + ROW * 3 + "0.5,E200,1,915e6,1.0x\n")
    assert (error.line, error.column) == (5, "phase_rad")
