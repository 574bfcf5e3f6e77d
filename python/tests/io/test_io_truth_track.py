"""truth.csv and track.csv: round trips, the shared examples, malformed inputs."""

import math

import numpy as np
import pytest

from scattertrack.io import (
    FormatError,
    Track,
    Truth,
    read_track,
    read_truth,
    write_track,
    write_truth,
)


HEADER = "time_s,epc,x,y,z,vx,vy,vz\n"
"""The required columns of track.csv."""


def make_truth(n: int = 50, with_velocity: bool = True) -> Truth:
    rng = np.random.default_rng(1)
    velocity = rng.normal(size=(n, 3)).round(6) if with_velocity else np.full((n, 3), math.nan)
    return Truth(
        time_s=np.arange(n) * 0.005,
        epc=np.array(["T1", "T2"] * (n // 2)),
        position=rng.uniform(-2, 2, (n, 3)).round(6),
        velocity=velocity,
    )


def make_track(n: int = 40, sigma: bool = True, orientation: bool = True) -> Track:
    rng = np.random.default_rng(2)
    velocity = rng.normal(size=(n, 3)).round(6)
    velocity[0] = math.nan  # a method may have no velocity at its first estimate
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return Track(
        time_s=np.repeat(np.arange(n // 2) * 0.01, 2),
        epc=np.array(["A", "B"] * (n // 2)),
        position=rng.uniform(-2, 2, (n, 3)).round(6),
        velocity=velocity,
        sigma=rng.uniform(0, 0.1, (n, 3)).round(6) if sigma else None,
        orientation=q.round(6) if orientation else None,
    )


# --- truth ------------------------------------------------------------------


def assert_truth_equal(a: Truth, b: Truth) -> None:
    np.testing.assert_allclose(a.time_s, b.time_s, rtol=0, atol=5e-7)
    np.testing.assert_array_equal(a.epc, b.epc)
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.velocity, b.velocity)


@pytest.mark.parametrize("with_velocity", [True, False])
def test_truth_round_trip(tmp_path, with_velocity):
    truth = make_truth(with_velocity=with_velocity)
    write_truth(tmp_path / "truth.csv", truth)
    header = (tmp_path / "truth.csv").read_text().splitlines()[0]
    assert header == "time_s,epc,x,y,z" + (",vx,vy,vz" if with_velocity else "")
    assert_truth_equal(truth, read_truth(tmp_path / "truth.csv"))


@pytest.mark.filterwarnings("ignore:.*sampled at 10 Hz")  # 10 Hz keeps the file short
def test_truth_sorted_by_time_keeping_file_order(write_file):
    text = "epc,time_s,x,y,z\nB,0.2,1,1,1\nA,0.1,2,2,2\nC,0.2,3,3,3\nA,0.0,4,4,4\n"
    truth = read_truth(write_file("truth.csv", text))
    np.testing.assert_array_equal(truth.time_s, [0.0, 0.1, 0.2, 0.2])
    assert truth.epc.tolist() == ["A", "A", "B", "C"]
    np.testing.assert_array_equal(truth.position[:, 0], [4, 2, 1, 3])
    assert truth.velocity.shape == (4, 3) and np.isnan(truth.velocity).all()


def test_truth_examples_load(examples):
    cots = read_truth(examples / "cots-3d-arm" / "truth.csv")
    assert len(cots) == 2001 and cots.position.shape == (2001, 3)
    assert np.isfinite(cots.velocity).all()
    helper = read_truth(examples / "helper-3d-arm" / "truth.csv")
    assert len(helper) == 201
    lora = read_truth(examples / "lora-hover-circle" / "truth.csv")  # extra qw..qz ignored
    assert len(lora) == 1151 and set(lora.epc.tolist()) == {"drone"}


def truth_error(write_file, text: str) -> FormatError:
    path = write_file("truth.csv", text)
    with pytest.raises(FormatError) as caught:
        read_truth(path)
    assert caught.value.path == str(path)
    return caught.value


def test_truth_missing_column(write_file):
    error = truth_error(write_file, "time_s,epc,x,y\n0.0,A,1,2\n")
    assert (error.line, error.column) == (1, "z")


def test_truth_non_finite_and_non_numeric(write_file):
    error = truth_error(write_file, "time_s,epc,x,y,z\n0.0,A,1,2,3\n0.1,A,1,nan,3\n")
    assert (error.line, error.column) == (3, "y")
    error = truth_error(write_file, "time_s,epc,x,y,z,vx,vy,vz\n0.0,A,1,2,3,0,inf,0\n")
    assert (error.line, error.column) == (2, "vy")
    error = truth_error(write_file, "time_s,epc,x,y,z\n0.0,A,1,2,3\n0.1,A,1 m,2,3\n")
    assert (error.line, error.column) == (3, "x")


def test_truth_header_only_and_field_count(write_file):
    assert truth_error(write_file, "time_s,epc,x,y,z\n").line == 2
    error = truth_error(write_file, "time_s,epc,x,y,z\n0.0,A,1,2,3,4\n")
    assert (error.line, error.column) == (2, None)


# --- track ------------------------------------------------------------------


def assert_track_equal(a: Track, b: Track) -> None:
    np.testing.assert_allclose(a.time_s, b.time_s, rtol=0, atol=5e-7)
    np.testing.assert_array_equal(a.epc, b.epc)
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.velocity, b.velocity)
    for x, y in ((a.sigma, b.sigma), (a.orientation, b.orientation)):
        assert (x is None) == (y is None)
        if x is not None:
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize(
    "sigma,orientation", [(True, True), (False, False), (True, False), (False, True)]
)
def test_track_round_trip(tmp_path, sigma, orientation):
    track = make_track(sigma=sigma, orientation=orientation)
    write_track(tmp_path / "track.csv", track)
    header = (tmp_path / "track.csv").read_text().splitlines()[0].split(",")
    assert header[:8] == ["time_s", "epc", "x", "y", "z", "vx", "vy", "vz"]
    assert ("sx" in header) == sigma and ("qw" in header) == orientation
    assert_track_equal(track, read_track(tmp_path / "track.csv"))


def test_track_writes_nan_velocity_literally(tmp_path):
    write_track(tmp_path / "track.csv", make_track(sigma=False, orientation=False))
    first_row = (tmp_path / "track.csv").read_text().splitlines()[1].split(",")
    assert first_row[5:8] == ["nan", "nan", "nan"]


def test_track_keeps_file_order_across_tags(write_file):
    text = HEADER + "0.2,B,0,0,0,nan,nan,nan\n0.1,A,0,0,0,0,0,0\n0.3,A,1,0,0,0,0,0\n"
    track = read_track(write_file("track.csv", text))
    assert track.epc.tolist() == ["B", "A", "A"]
    assert track.sigma is None and track.orientation is None
    assert np.isnan(track.velocity[0]).all()


def test_track_optional_nan_and_empty(write_file):
    text = "time_s,epc,x,y,z,vx,vy,vz,sx,sy,sz\n0.1,A,0,0,0,0,0,0,nan,,0.1\n"
    track = read_track(write_file("track.csv", text))
    assert np.isnan(track.sigma[0, :2]).all() and track.sigma[0, 2] == 0.1


def track_error(write_file, text: str) -> FormatError:
    path = write_file("track.csv", text)
    with pytest.raises(FormatError) as caught:
        read_track(path)
    assert caught.value.path == str(path)
    return caught.value



def test_track_nan_only_allowed_in_velocity(write_file):
    error = track_error(write_file, HEADER + "0.1,A,0,0,0,nan,0,0\n0.2,A,0,nan,0,0,0,0\n")
    assert (error.line, error.column) == (3, "y")


def test_track_inf_velocity_and_empty_velocity(write_file):
    error = track_error(write_file, HEADER + "0.1,A,0,0,0,0,-inf,0\n")
    assert (error.line, error.column) == (2, "vy")
    error = track_error(write_file, HEADER + "0.1,A,0,0,0,0,,0\n")
    assert (error.line, error.column) == (2, "vy")


def test_track_missing_velocity_column(write_file):
    error = track_error(write_file, "time_s,epc,x,y,z\n0.1,A,0,0,0\n")
    assert (error.line, error.column) == (1, "vx")


def test_track_partial_optional_group(write_file):
    error = track_error(write_file, "time_s,epc,x,y,z,vx,vy,vz,sx,sy\n0.1,A,0,0,0,0,0,0,1,1\n")
    assert (error.line, error.column) == (1, "sz")


def test_track_time_backwards_for_a_tag(write_file):
    text = HEADER + "0.1,A,0,0,0,0,0,0\n0.2,B,0,0,0,0,0,0\n0.3,A,0,0,0,0,0,0\n0.15,B,0,0,0,0,0,0\n"
    error = track_error(write_file, text)
    assert (error.line, error.column) == (5, "time_s")
    assert "'B'" in error.message


def test_writers_refuse_what_readers_reject(tmp_path):
    track = make_track()
    track.position[3, 1] = math.nan
    with pytest.raises(ValueError):
        write_track(tmp_path / "track.csv", track)
