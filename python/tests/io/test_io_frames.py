"""frames.csv (docs/formats.md section 5) and helper scenes: round trips, the shared example,
one test per malformed input (file, line and column), duplicates and reordering."""

import numpy as np
import pytest

from scattertrack.io import FormatError, Frames, make_frames, read_frames, read_scene, read_truth, write_frames
from scattertrack.io.types import SPEED_OF_LIGHT

from scene_texts import helper_scene

HEADER = "time_s,epc,tx,rx,frequency_hz,h_re,h_im"

HELPER_SCENE = helper_scene(3)


@pytest.fixture
def scene(write_file):
    return read_scene(write_file("scene.toml", HELPER_SCENE))


def random_frames(n_frames: int = 7, seed: int = 1) -> Frames:
    """Frames of two tags on 3 rx and 4 subcarriers with random channels, built from rows."""
    rng = np.random.default_rng(seed)
    times = np.round(np.sort(rng.uniform(0.0, 1.0, n_frames)), 6)
    epcs = rng.choice(["E2FF0001", "E2FF0002"], n_frames)
    rx = np.array([1, 2, 3])
    frequencies = np.array([902.5e6, 907.5e6, 912.5e6, 917.5e6])
    shape = (n_frames, len(rx), len(frequencies))
    h = rng.standard_normal(shape) + 1j * rng.standard_normal(shape)
    h[0, 0, 0] = 1e-300 - 7.25e12j  # extreme magnitudes survive the round trip
    return make_frames(
        time_s=np.broadcast_to(times[:, None, None], shape).ravel(),
        epc=np.broadcast_to(epcs[:, None, None], shape).ravel(),
        tx=np.zeros(h.size, dtype=np.int64),
        rx=np.broadcast_to(rx[None, :, None], shape).ravel(),
        frequency_hz=np.broadcast_to(frequencies[None, None, :], shape).ravel(),
        h=h.ravel(),
    )


def assert_frames_equal(a: Frames, b: Frames) -> None:
    np.testing.assert_array_equal(a.time_s, b.time_s)
    np.testing.assert_array_equal(a.epc, b.epc)
    np.testing.assert_array_equal(a.tx, b.tx)
    np.testing.assert_array_equal(a.rx, b.rx)
    np.testing.assert_array_equal(a.frequency_hz, b.frequency_hz)
    np.testing.assert_array_equal(a.frame_start, b.frame_start)
    # 9 significant digits per component.
    np.testing.assert_allclose(a.h.real, b.h.real, rtol=1e-8, atol=0.0)
    np.testing.assert_allclose(a.h.imag, b.h.imag, rtol=1e-8, atol=0.0)


def test_round_trip(tmp_path, scene):
    frames = random_frames()
    write_frames(tmp_path / "frames.csv", frames)
    again = read_frames(tmp_path / "frames.csv", scene)
    assert_frames_equal(frames, again)
    assert again.skipped.total == 0 and again.reordered == 0
    assert again.h.dtype == np.complex128 and again.rx.dtype == np.int64
    # Written again, the file is the same text: nothing drifts.
    write_frames(tmp_path / "again.csv", again)
    assert (tmp_path / "again.csv").read_text() == (tmp_path / "frames.csv").read_text()


def test_make_frames_sorts_and_groups():
    frames = make_frames(
        time_s=[0.2, 0.1, 0.2, 0.1, 0.2],
        epc=["B", "A", "A", "A", "B"],
        tx=[0] * 5,
        rx=[2, 1, 1, 1, 1],
        frequency_hz=[1e9, 2e9, 1e9, 1e9, 1e9],
        h=[1, 2, 3, 4, 5],
    )
    np.testing.assert_array_equal(frames.time_s, [0.1, 0.1, 0.2, 0.2, 0.2])
    np.testing.assert_array_equal(frames.epc, ["A", "A", "A", "B", "B"])
    np.testing.assert_array_equal(frames.h, [4, 2, 3, 5, 1])
    np.testing.assert_array_equal(frames.frame_start, [0, 2, 3, 5])
    assert frames.n_frames == 3
    np.testing.assert_array_equal(frames.frame_time_s, [0.1, 0.2, 0.2])
    np.testing.assert_array_equal(frames.frame_epc, ["A", "A", "B"])
    rx, frequency, h = frames.frame(2)
    np.testing.assert_array_equal(rx, [1, 2])
    np.testing.assert_array_equal(h, [5, 1])
    # A grid with a hole: rx 2 has no 2 GHz subcarrier in frame 0 (it has no rx 2 at all).
    rx_ids, frequencies, grid = frames.frame_grid(2)
    np.testing.assert_array_equal(rx_ids, [1, 2])
    np.testing.assert_array_equal(frequencies, [1e9])
    np.testing.assert_array_equal(grid, [[5], [1]])
    rx_ids, frequencies, grid = make_frames([0, 0, 0], ["A"] * 3, [0] * 3, [1, 1, 2], [1, 2, 1], [1, 2, 3]).frame_grid(0)
    assert np.isnan(grid[1, 1]) and grid[1, 0] == 3
    picked = frames.select_frames(np.array([False, True, True]))
    np.testing.assert_array_equal(picked.h, [3, 5, 1])
    np.testing.assert_array_equal(picked.frame_start, [0, 1, 3])
    assert frames.epcs() == ["A", "B"]


def test_example_loads(examples):
    folder = examples / "helper-3d-arm"
    scene = read_scene(folder / "scene.toml")
    frames = read_frames(folder / "frames.csv", scene)
    assert frames.skipped.total == 0 and frames.reordered == 0
    assert frames.epcs() == ["E2FF0001"]
    assert frames.n_frames > 100
    assert np.all(np.diff(frames.frame_time_s) > 0)
    assert set(frames.tx.tolist()) == {0}
    rx_ids, frequencies, grid = frames.frame_grid(0)
    np.testing.assert_array_equal(rx_ids, [1, 2, 3, 4])
    np.testing.assert_allclose(frequencies, 867.5e6 + 5e6 * np.arange(20))
    assert np.all(np.isfinite(grid))
    # An independent program's channels follow the convention h = a exp(-j 2 pi f d / c):
    # removing the phase of the true bistatic path leaves a near-constant positive real.
    truth = read_truth(folder / "truth.csv")
    tx = scene.antennas[scene.antenna_index(0)].position
    time = frames.frame_time_s[0]
    tag = np.array([np.interp(time, truth.time_s, truth.position[:, k]) for k in range(3)])
    for row, rx_id in enumerate(rx_ids):
        rx = scene.antennas[scene.antenna_index(int(rx_id))].position
        d = np.linalg.norm(tag - tx) + np.linalg.norm(tag - rx)
        aligned = grid[row] * np.exp(2j * np.pi * frequencies * d / SPEED_OF_LIGHT)
        assert abs(np.angle(aligned.mean())) < 0.3
        assert abs(aligned.mean()) > 0.7 * np.abs(aligned).mean()


# --- duplicates and order ---------------------------------------------------


def test_duplicates_are_skipped_and_counted(write_file, scene):
    lines = [
        HEADER,
        "0.1,E1,0,1,915000000,1.0,0.0",  # line 2
        "0.1,E1,0,2,915000000,2.0,0.0",
        "0.1,E1,0,1,915000000,1.0,0.0",  # line 4: exact copy of line 2
        "0.1,E1,0,1,915000000,9.0,9.0",  # line 5: same key, other channel: the first is kept
        "0.1,E2,0,1,915000000,3.0,0.0",  # another tag at the same time: not a duplicate
    ]
    frames = read_frames(write_file("frames.csv", "\n".join(lines) + "\n"), scene)
    assert len(frames) == 3 and frames.n_frames == 2
    assert frames.skipped.counts == {"duplicate row": 2}
    assert frames.skipped.examples["duplicate row"] == [4, 5]
    assert "2 duplicate row (lines 4, 5)" in frames.skipped.summary()
    np.testing.assert_array_equal(frames.h[frames.epc == "E1"], [1.0, 2.0])


def test_out_of_order_rows_are_sorted_and_counted(write_file, scene):
    lines = [
        HEADER,
        "0.3,E1,0,1,915000000,3.0,0.0",
        "0.1,E1,0,2,915000000,2.0,0.0",  # earlier than the row above: out of order
        "0.1,E1,0,1,915000000,1.0,0.0",  # out of order too; within its frame rx order is free
        "0.4,E1,0,1,915000000,4.0,0.0",
        "0.2,E1,0,1,920000000,5.0,0.0",  # out of order
    ]
    frames = read_frames(write_file("frames.csv", "\n".join(lines) + "\n"), scene)
    assert frames.reordered == 3
    np.testing.assert_array_equal(frames.time_s, [0.1, 0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(frames.rx, [1, 2, 1, 1, 1])
    np.testing.assert_array_equal(frames.h.real, [1.0, 2.0, 5.0, 3.0, 4.0])
    np.testing.assert_array_equal(frames.frame_start, [0, 2, 3, 4, 5])
    assert frames.skipped.total == 0


def test_without_a_scene_ids_are_not_checked(write_file):
    frames = read_frames(write_file("frames.csv", HEADER + "\n0.1,E1,7,9,915000000,1.0,-1.0\n"))
    assert frames.tx.tolist() == [7] and frames.rx.tolist() == [9] and frames.h.tolist() == [1 - 1j]


def test_extra_columns_and_column_order(write_file, scene):
    text = "h_im,h_re,snr_db,frequency_hz,rx,tx,epc,time_s\n-1.5,0.5,12,915000000,3,0,E1,0.25\n"
    frames = read_frames(write_file("frames.csv", text), scene)
    assert frames.h.tolist() == [0.5 - 1.5j] and frames.rx.tolist() == [3]


# --- malformed files: file, line and column ------------------------------------


def error_for(write_file, text: str, scene=None) -> FormatError:
    path = write_file("frames.csv", text)
    with pytest.raises(FormatError) as caught:
        read_frames(path, scene)
    assert caught.value.path == str(path)
    return caught.value


GOOD_ROW = "0.1,E1,0,1,915000000,1.0,0.0"


@pytest.mark.parametrize("column", ["time_s", "epc", "tx", "rx", "frequency_hz", "h_re", "h_im"])
def test_missing_required_column(write_file, scene, column):
    names = HEADER.split(",")
    keep = [i for i, name in enumerate(names) if name != column]
    row = GOOD_ROW.split(",")
    text = ",".join(names[i] for i in keep) + "\n" + ",".join(row[i] for i in keep) + "\n"
    error = error_for(write_file, text, scene)
    assert (error.line, error.column) == (1, column)
    assert "missing required column" in error.message


@pytest.mark.parametrize(
    "row, column, fragment",
    [
        ("x,E1,0,1,915000000,1.0,0.0", "time_s", "not a number"),
        ("0.1,E1,0,1,915000000,abc,0.0", "h_re", "not a number"),
        ("0.1,E1,0,1,915000000,1.0,", "h_im", "empty value"),
        ("0.1,E1,0,1,915000000,nan,0.0", "h_re", "not a finite number"),
        ("0.1,E1,0,1,915000000,1.0,inf", "h_im", "not a finite number"),
        ("inf,E1,0,1,915000000,1.0,0.0", "time_s", "not a finite number"),
        ("0.1,E1,0,1,-915000000,1.0,0.0", "frequency_hz", "outside 100 MHz to 10 GHz"),
        ("0.1,E1,0.5,1,915000000,1.0,0.0", "tx", "not an integer"),
        ("0.1,,0,1,915000000,1.0,0.0", "epc", "empty value"),
        ("0.1,E1,1,1,915000000,1.0,0.0", "tx", "role 'rx'"),
        ("0.1,E1,0,0,915000000,1.0,0.0", "rx", "role 'tx'"),
        ("0.1,E1,0,7,915000000,1.0,0.0", "rx", "antenna '7' is not in the scene"),
        ("0.1,E1,5,1,915000000,1.0,0.0", "tx", "antenna '5' is not in the scene"),
    ],
)
def test_bad_value(write_file, scene, row, column, fragment):
    text = "\n".join([HEADER, GOOD_ROW, GOOD_ROW.replace("0.1", "0.2"), row]) + "\n"
    error = error_for(write_file, text, scene)
    assert (error.line, error.column) == (4, column), str(error)
    assert fragment in error.message
    assert str(error).startswith(f"{error.path}:4: line 4, column '{column}':")


def test_first_bad_line_is_reported(write_file, scene):
    rows = [GOOD_ROW] * 5 + ["0.1,E1,0,1,915000000,nan,0.0", "0.1,E1,0,9,915000000,1.0,0.0"]
    error = error_for(write_file, "\n".join([HEADER, *rows]) + "\n", scene)
    assert (error.line, error.column) == (7, "h_re")


def test_empty_file(write_file):
    error = error_for(write_file, "")
    assert error.line == 1 and "empty file" in error.message


def test_header_without_rows(write_file):
    error = error_for(write_file, HEADER + "\n")
    assert error.line == 2 and "no data rows" in error.message


def test_writer_refuses_non_finite(tmp_path):
    frames = random_frames()
    frames.h[3] = complex(np.nan, 0.0)
    with pytest.raises(ValueError, match="h_re"):
        write_frames(tmp_path / "frames.csv", frames)


# --- helper scenes ------------------------------------------------------------


def scene_error(write_file, text: str) -> FormatError:
    path = write_file("scene.toml", text)
    with pytest.raises(FormatError) as caught:
        read_scene(path)
    assert caught.value.path == str(path)
    return caught.value


def test_helper_scene_with_two_transmitters(write_file):
    text = HELPER_SCENE.replace('id = 2\nposition = [0.8, 0.4, 0.0]\nrole = "rx"', 'id = 2\nposition = [0.8, 0.4, 0.0]\nrole = "tx"')
    error = scene_error(write_file, text)
    assert (error.line, error.column) == (20, "antennas[2].role")
    assert "exactly one 'tx'" in error.message


def test_helper_scene_without_transmitter(write_file):
    error = scene_error(write_file, HELPER_SCENE.replace('role = "tx"', 'role = "rx"'))
    assert (error.line, error.column) == (7, "antennas")  # the first [[antennas]]
    assert "needs one antenna with role 'tx'" in error.message


def test_helper_scene_with_one_receiver(write_file):
    text = HELPER_SCENE.split("[[antennas]]\nid = 2")[0]
    error = scene_error(write_file, text)
    assert error.column == "antennas" and "at least 2 antennas with role 'rx', found 1" in error.message


def test_helper_scene_with_a_monostatic_antenna(write_file):
    text = HELPER_SCENE.replace('id = 3\nposition = [0.4, 0.0, 0.0]\nrole = "rx"\n', "id = 3\nposition = [0.4, 0.0, 0.0]\n")
    error = scene_error(write_file, text)
    assert (error.line, error.column) == (22, "antennas[3].role")  # the table: the role is not written
    assert "role 'tx' or 'rx', found 'txrx'" in error.message


def test_helper_table(write_file):
    table = "\n[helper]\ncentre_frequency_hz = 915e6\nbandwidth_hz = 100e6\nn_subcarriers = 20\nblf_hz = 40e3\n"
    scene = read_scene(write_file("scene.toml", HELPER_SCENE + table))
    assert scene.extra["helper"]["n_subcarriers"] == 20
    error = scene_error(write_file, HELPER_SCENE + table.replace("n_subcarriers = 20", "n_subcarriers = 2.5"))
    assert (error.line, error.column) == (30, "helper.n_subcarriers")
    error = scene_error(write_file, HELPER_SCENE + table.replace("blf_hz = 40e3", "blf_hz = -1"))
    assert (error.line, error.column) == (31, "helper.blf_hz")


def test_huge_channels_are_declined_and_counted(write_file, scene):
    rows = [HEADER]
    for rx in (1, 2, 3):
        for k, f in enumerate((915e6, 916e6)):
            h_re = "1e101" if (rx, k) == (2, 1) else "0.25"
            rows.append(f"0.5,E2,0,{rx},{f!r},{h_re},-0.1")
    rows.append("0.6,E2,0,1,915e6,0.3,-1.5e300")
    frames = read_frames(write_file("frames.csv", "\n".join(rows) + "\n"), scene)
    assert len(frames) == 5 and frames.n_frames == 1
    assert frames.skipped.counts == {"channel beyond 1e100": 2}
    assert frames.skipped.examples == {"channel beyond 1e100": [5, 8]}
    assert np.abs(frames.h).max() < 1.0


def test_helper_table_carrier_unit_and_unknown_keys(write_file):
    import warnings

    from scattertrack.io import InputWarning

    table = "\n[helper]\ncentre_frequency_hz = 915.0\nbandwidth_hz = 100e6\n"
    error = scene_error(write_file, HELPER_SCENE + table)
    assert error.column == "helper.centre_frequency_hz" and "looks like MHz: multiply by 1e6" in error.message
    typo = "\n[helper]\ncentre_frequency_hz = 915e6\nbandwith_hz = 100e6\n"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_scene(write_file("scene.toml", HELPER_SCENE + typo))
    (warning,) = [w.message for w in caught if issubclass(w.category, InputWarning)]
    assert warning.column == "helper.bandwith_hz" and "unknown key" in warning.message
