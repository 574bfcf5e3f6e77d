"""The shared CSV rules on truth, track, frames, imu and features: ASCII numbers, BOM/CRLF,
line numbers, empty files, clock jumps; and truth's sampling warnings."""

import warnings

import numpy as np
import pytest

from scattertrack.io import (
    FormatError,
    InputWarning,
    read_features,
    read_frames,
    read_imu,
    read_track,
    read_truth,
    write_track,
)

TRUTH = "time_s,epc,x,y,z\n"
TRACK = "time_s,epc,x,y,z,vx,vy,vz\n"
FRAMES = "time_s,epc,tx,rx,frequency_hz,h_re,h_im\n"
IMU = "time_s,ax,ay,az,gx,gy,gz\n"
FEATURES = "time_s,range_m,azimuth_rad,elevation_rad\n"

# (reader, header, a valid data row, the column set to "1_0" in the bad row's second cell)
FORMATS = [
    (read_truth, TRUTH, "0.0,drone,1,2,3", "epc"),
    (read_track, TRACK, "0.0,E2,1,2,3,0,0,0", "epc"),
    (read_frames, FRAMES, "0.0,E2,0,1,915e6,1.0,0.0", "epc"),
    (read_imu, IMU, "0.0,0,0,9.81,0,0,0", "ax"),
    (read_features, FEATURES, "0.0,10,0.5,0.1", "range_m"),
]
IDS = ["truth", "track", "frames", "imu", "features"]


def error_of(reader, path) -> FormatError:
    with pytest.raises(FormatError) as caught:
        reader(path)
    assert caught.value.path == str(path)
    return caught.value


def next_row(row: str) -> str:
    """The row 0.01 s later (so that no reader sees a duplicate)."""
    return "0.01" + row[len("0.0"):]


@pytest.mark.parametrize("reader, header, row, _", FORMATS, ids=IDS)
@pytest.mark.parametrize("cell", ["1_0", "\uff11", "inf"])
def test_ascii_numbers_with_line_and_column(write_file, reader, header, row, _, cell):
    bad = next_row(row).split(",")
    bad[0] = cell  # time_s
    path = write_file("data.csv", header + row + "\n" + ",".join(bad) + "\n")
    error = error_of(reader, path)
    assert (error.line, error.column) == (3, "time_s")
    assert str(error).startswith(f"{path}:3: line 3, column 'time_s': ")


@pytest.mark.parametrize("reader, header, row, _", FORMATS, ids=IDS)
def test_bom_crlf_and_quoted_cells(write_file, reader, header, row, _):
    quoted = ",".join(f'"{cell}"' for cell in next_row(row).split(","))
    text = "\ufeff" + (header + row + "\n" + quoted + "\n").replace("\n", "\r\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        if reader is read_truth:
            warnings.filterwarnings("ignore", "truth of tag", InputWarning)  # two rows: far below 100 Hz
        result = reader(write_file("data.csv", text))
    assert len(result) == 2


@pytest.mark.parametrize("reader, header, row, _", FORMATS, ids=IDS)
def test_line_numbers_after_a_quoted_line_break(write_file, reader, header, row, _):
    text = header.replace("\n", ",note\n") + row + ',"two\nlines"\n' + next_row(row) + ",\n0.02_0" + row[3:] + ",\n"
    error = error_of(reader, write_file("data.csv", text))
    assert (error.line, error.column) == (5, "time_s")


@pytest.mark.parametrize("reader, header, row, _", FORMATS, ids=IDS)
@pytest.mark.parametrize("text, line, fragment", [("", 1, "empty file"), ("\ufeff", 1, "empty file"), ("\n\n", 1, "empty file")])
def test_empty_files(write_file, reader, header, row, _, text, line, fragment):
    error = error_of(reader, write_file("data.csv", text))
    assert error.line == line and fragment in error.message


@pytest.mark.parametrize("reader, header, row, _", [f for f in FORMATS if f[0] is not read_track], ids=IDS[:1] + IDS[2:])
def test_header_only_is_no_data(write_file, reader, header, row, _):
    error = error_of(reader, write_file("data.csv", header))
    assert error.line == 2 and "no data rows" in error.message


@pytest.mark.parametrize("text", [TRACK, TRACK + "\n", "\ufeff" + TRACK.replace("\n", "\r\n"), TRACK.replace("\n", ",sx,sy,sz\n")])
def test_header_only_track_is_an_empty_track(write_file, text):
    track = read_track(write_file("track.csv", text))
    assert len(track) == 0
    assert track.position.shape == (0, 3) and track.velocity.shape == (0, 3)
    assert (track.sigma is None) == ("sx" not in text)


def test_empty_track_round_trip(tmp_path):
    track = read_track_from(tmp_path, TRACK)
    write_track(tmp_path / "again.csv", track)
    assert (tmp_path / "again.csv").read_text() == TRACK
    assert len(read_track(tmp_path / "again.csv")) == 0


def read_track_from(folder, text):
    (folder / "track.csv").write_text(text)
    return read_track(folder / "track.csv")


@pytest.mark.parametrize("cell", ["0.5", "\uff10"])
def test_frames_ids_are_ascii_integers(write_file, cell):
    error = error_of(read_frames, write_file("frames.csv", FRAMES + f"0.0,E2,{cell},1,915e6,1.0,0.0\n"))
    assert (error.line, error.column) == (2, "tx")


def test_frames_frequency_unit_hint(write_file):
    error = error_of(read_frames, write_file("frames.csv", FRAMES + "0.0,E2,0,1,867.5,1.0,0.0\n"))
    assert (error.line, error.column) == (2, "frequency_hz")
    assert "looks like MHz: multiply by 1e6" in error.message


@pytest.mark.parametrize(
    "reader, header, row",
    [(read_frames, FRAMES, ",E2,0,1,915e6,1.0,0.0"), (read_imu, IMU, ",0,0,9.81,0,0,0"), (read_features, FEATURES, ",10,0.5,0.1")],
    ids=["frames", "imu", "features"],
)
def test_clock_jump_back_warns_in_every_time_series(write_file, reader, header, row):
    path = write_file("data.csv", header + "".join(f"{t}{row}\n" for t in (30.0, 30.1, 12.0, 30.2)))
    with pytest.warns(InputWarning, match="clock jumps back by 18.1 s") as caught:
        reader(path)
    # Only the input's warnings: a ResourceWarning of an earlier test's
    # garbage can land here too.
    found = [(w.message.line, w.message.column) for w in caught if isinstance(w.message, InputWarning)]
    assert found == [(4, "time_s")]


# --- truth sampling -------------------------------------------------------------------


def truth_text(times, epc="E2", positions=None) -> str:
    positions = positions or [(0.1 * i, 0.0, 0.0) for i in range(len(times))]
    return TRUTH + "".join(f"{t},{epc},{x},{y},{z}\n" for t, (x, y, z) in zip(times, positions))


def truth_warnings(path) -> list[InputWarning]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_truth(path)
    return [w.message for w in caught if issubclass(w.category, InputWarning)]


def test_truth_below_100_hz_warns(write_file):
    times = np.round(np.arange(20) * 0.02, 6).tolist()  # 50 Hz
    (warning,) = truth_warnings(write_file("truth.csv", truth_text(times)))
    assert (warning.line, warning.column) == (2, "time_s")
    assert "sampled at 50 Hz" in warning.message and "E2" in warning.message


def test_truth_at_100_hz_is_quiet(write_file):
    times = np.round(np.arange(50) * 0.01, 6).tolist()
    assert truth_warnings(write_file("truth.csv", truth_text(times))) == []


def test_truth_rate_is_per_tag(write_file):
    fast = truth_text(np.round(np.arange(30) * 0.005, 6).tolist(), "A")
    slow = truth_text([0.0, 0.5, 1.0], "B")
    (warning,) = truth_warnings(write_file("truth.csv", fast + slow[len(TRUTH):]))
    assert "'B'" in warning.message and warning.line == 32


def test_truth_conflicting_rows_warn(write_file):
    times = np.round(np.arange(40) * 0.005, 6).tolist()
    positions = [(0.001 * i, 0.0, 0.0) for i in range(40)]
    times.insert(11, times[10])
    positions.insert(11, (5.0, 5.0, 5.0))  # line 13: same time as line 12, another place
    (warning,) = truth_warnings(write_file("truth.csv", truth_text(times, positions=positions)))
    assert (warning.line, warning.column) == (13, "time_s")
    assert "different positions" in warning.message and "line 12" in warning.message


def test_truth_identical_repeated_rows_are_quiet(write_file):
    times = np.round(np.arange(40) * 0.005, 6).tolist()
    positions = [(0.0, 0.0, 0.0)] * 40
    times.insert(11, times[10])
    positions.insert(11, positions[10])
    assert truth_warnings(write_file("truth.csv", truth_text(times, positions=positions))) == []
