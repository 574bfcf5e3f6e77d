"""reads.csv's optional channel_index column and the scene's [[hop_table]].

Each malformed case asserts the file, the 1-based line and the column (or
key) of the error; each warning asserts its line and count.
"""

import warnings

import numpy as np
import pytest

from scattertrack.io import FormatError, InputWarning, Reads, read_reads, read_scene, write_reads, write_scene
from scattertrack.io.hop_table import disagreements, us_channel_plan_hz

HEADER = "time_s,epc,antenna,frequency_hz,phase_rad,channel_index\n"

SCENE = """\
dimensions = 3

[reader]
kind = "cots"

[[antennas]]
id = 1
position = [0.0, 0.0, 0.0]
{tail}"""

HOP_TABLE = """
[[hop_table]]
channel_index = 1
frequency_hz = 910.25e6

[[hop_table]]
channel_index = 2
frequency_hz = 902.75e6
"""


def caught_warnings(call) -> list[InputWarning]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    return [w.message for w in caught if issubclass(w.category, InputWarning)]


def reads_error(path, scene=None) -> FormatError:
    with pytest.raises(FormatError) as caught:
        read_reads(path, scene)
    assert caught.value.path == str(path)
    return caught.value


def scene_error(path) -> FormatError:
    with pytest.raises(FormatError) as caught:
        read_scene(path)
    assert caught.value.path == str(path)
    return caught.value


# --- reads.csv ----------------------------------------------------------------


def test_channel_index_is_read_with_empty_cells_as_minus_one(write_file):
    path = write_file("reads.csv", HEADER + "0.2,E2,1,910.25e6,1.0,1\n0.1,E2,1,902.75e6,2.0,\n0.3,E2,1,915e6,3.0,50\n")
    reads = read_reads(path)
    assert reads.channel_index.dtype == np.int64
    assert reads.channel_index.tolist() == [-1, 1, 50]  # sorted by time with the other columns


def test_without_the_column_channel_index_is_none(write_file):
    reads = read_reads(write_file("reads.csv", "time_s,epc,antenna,frequency_hz,phase_rad\n0.1,E2,1,915e6,1.0\n"))
    assert reads.channel_index is None
    assert reads.select(np.array([True])).channel_index is None


def test_select_keeps_channel_index(write_file):
    reads = read_reads(write_file("reads.csv", HEADER + "0.1,E2,1,915e6,1.0,3\n0.2,E2,1,915e6,1.0,4\n"))
    assert reads.select(np.array([False, True])).channel_index.tolist() == [4]


@pytest.mark.parametrize(
    "cell, fragment",
    [
        ("1.5", "not an integer: '1.5'"),
        ("x", "not an integer: 'x'"),
        ("1_0", "'_' digit separators"),
        ("\uff13", "U+FF13"),
        ("0", "channel index '0' is not positive"),
        ("-2", "channel index '-2' is not positive"),
    ],
)
def test_bad_channel_index_cells_name_file_line_and_column(write_file, cell, fragment):
    path = write_file("reads.csv", HEADER + "0.1,E2,1,915e6,1.0,1\n" + f"0.2,E2,1,915e6,1.0,{cell}\n")
    error = reads_error(path)
    assert (error.line, error.column) == (3, "channel_index")
    assert fragment in error.message


def test_write_reads_writes_channel_index_only_when_some_row_has_one(tmp_path):
    def reads(index):
        n = len(index)
        return Reads(np.arange(n) * 0.1, np.array(["E2"] * n, dtype=object), np.ones(n, dtype=np.int64),
                     np.full(n, 915e6), np.full(n, 1.0), np.full(n, np.nan), np.full(n, np.nan),
                     channel_index=np.array(index, dtype=np.int64))

    write_reads(tmp_path / "a.csv", reads([7, -1]))
    assert (tmp_path / "a.csv").read_text().splitlines()[0].endswith(",channel_index")
    assert read_reads(tmp_path / "a.csv").channel_index.tolist() == [7, -1]
    write_reads(tmp_path / "b.csv", reads([-1, -1]))
    assert "channel_index" not in (tmp_path / "b.csv").read_text()
    with pytest.raises(ValueError, match="channel indices are positive"):
        write_reads(tmp_path / "c.csv", reads([0, 1]))


def test_rows_disagreeing_with_the_hop_table_are_kept_with_one_counted_warning(write_file):
    scene = read_scene(write_file("scene.toml", SCENE.format(tail=HOP_TABLE)))
    path = write_file("reads.csv", HEADER + "0.1,E2,1,910.25e6,1.0,1\n0.2,E2,1,915e6,1.0,1\n"
                                            "0.3,E2,1,902.7505e6,1.0,2\n0.4,E2,1,916e6,1.0,2\n0.5,E2,1,916e6,1.0,9\n")
    found = caught_warnings(lambda: read_reads(path, scene))
    assert len(found) == 1
    assert (found[0].line, found[0].column) == (3, "frequency_hz")
    assert "channel index 1" in found[0].message and "(2 such rows in the file)" in found[0].message
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InputWarning)
        assert len(read_reads(path, scene)) == 5  # kept, not rejected


def test_disagreement_ignores_rows_without_index_or_table_entry():
    bad = disagreements(np.array([915e6, 915e6, 910.25e6 + 999.0]), np.array([-1, 9, 1]), {1: 910.25e6})
    assert bad.tolist() == [False, False, False]


def test_us_channel_plan_in_index_order():
    assert us_channel_plan_hz(np.array([1, 2, 50, 0, 51])).tolist()[:3] == [902.75e6, 903.25e6, 927.25e6]
    assert np.isnan(us_channel_plan_hz(np.array([0, 51]))).all()


# --- scene.toml [[hop_table]] -------------------------------------------------------


def test_hop_table_is_parsed_and_saved_back(write_file, tmp_path):
    scene = read_scene(write_file("scene.toml", SCENE.format(tail=HOP_TABLE)))
    assert scene.hop_table == {1: 910.25e6, 2: 902.75e6}
    write_scene(tmp_path / "again.toml", scene)
    assert read_scene(tmp_path / "again.toml").hop_table == scene.hop_table
    assert read_scene(write_file("plain.toml", SCENE.format(tail=""))).hop_table == {}


@pytest.mark.parametrize(
    "entry, line, key, fragment",
    [
        ("channel_index = 1\nfrequency_hz = 915e6\n[[hop_table]]\nchannel_index = 1\nfrequency_hz = 916e6\n",
         14, "hop_table[1].channel_index", "given twice"),
        ("channel_index = 0\nfrequency_hz = 915e6\n", 11, "hop_table[0].channel_index", "positive integer"),
        ("channel_index = 1.0\nfrequency_hz = 915e6\n", 11, "hop_table[0].channel_index", "positive integer"),
        ("channel_index = true\nfrequency_hz = 915e6\n", 11, "hop_table[0].channel_index", "positive integer"),
        ("frequency_hz = 915e6\n", 10, "hop_table[0].channel_index", "missing required key"),
        ("channel_index = 1\n", 10, "hop_table[0].frequency_hz", "missing required key"),
        ("channel_index = 1\nfrequency_hz = 915.25\n", 12, "hop_table[0].frequency_hz", "looks like MHz"),
        ("channel_index = 1\nfrequency_hz = \"915e6\"\n", 12, "hop_table[0].frequency_hz", "finite number"),
    ],
)
def test_bad_hop_table_entries_name_line_and_key(write_file, entry, line, key, fragment):
    error = scene_error(write_file("scene.toml", SCENE.format(tail="\n[[hop_table]]\n" + entry)))
    assert (error.line, error.column) == (line, key)
    assert fragment in error.message


def test_unknown_hop_table_key_is_warned(write_file):
    path = write_file("scene.toml", SCENE.format(tail="\n[[hop_table]]\nchannel_index = 1\nfrequency_hz = 915e6\n"
                                                      "frequency_mhz = 915.0\n"))
    found = caught_warnings(lambda: read_scene(path))
    assert [(w.line, w.column) for w in found] == [(13, "hop_table[0].frequency_mhz")]
