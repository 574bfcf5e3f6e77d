"""imu.csv, features.csv and truth.csv's orientation: round trips, the shared example, malformed inputs."""

import math

import numpy as np
import pytest

from scattertrack.io import (
    Features,
    FormatError,
    Imu,
    InputWarning,
    Truth,
    read_features,
    read_imu,
    read_scene,
    read_truth,
    write_features,
    write_imu,
    write_truth,
)

IMU_HEADER = "time_s,ax,ay,az,gx,gy,gz,baro_z\n"
FEATURES_HEADER = "time_s,range_m,azimuth_rad,elevation_rad,yaw_rad,range_sigma_m,angle_sigma_rad,yaw_sigma_rad\n"


def imu_rows(n: int, start: int = 0) -> list[str]:
    """``n`` well-formed IMU rows at 100 Hz."""
    return [f"{(start + k) / 100:.2f},0.01,-0.02,9.81,0.001,0.002,-0.003,{k * 0.01:.2f}\n" for k in range(n)]


def feature_rows(times) -> list[str]:
    return [f"{t:.2f},10.5,1.2,0.1,0.3,0.6,0.05,0.2\n" for t in times]


def make_imu(n: int = 300, baro: bool = True) -> Imu:
    rng = np.random.default_rng(1)
    return Imu(
        time_s=np.arange(n) / 100.0,
        accel=(rng.normal(size=(n, 3)) + [0, 0, 9.81]).round(6),
        gyro=(rng.normal(size=(n, 3)) * 0.1).round(8),
        baro_z=rng.normal(size=n).round(4) if baro else np.full(n, math.nan),
    )


def make_features(n: int = 80) -> Features:
    rng = np.random.default_rng(2)
    yaw = rng.uniform(-3, 3, n).round(8)
    yaw_sigma = rng.uniform(0.05, 0.5, n).round(6)
    yaw[::3] = math.nan  # epochs without yaw
    yaw_sigma[::3] = math.nan
    return Features(
        time_s=(np.arange(n) + 0.5) / 10.0,
        range_m=rng.uniform(1, 50, n).round(6),
        azimuth_rad=rng.uniform(-3, 3, n).round(8),
        elevation_rad=rng.uniform(-1.5, 1.5, n).round(8),
        yaw_rad=yaw,
        range_sigma_m=rng.uniform(0.3, 1.5, n).round(6),
        angle_sigma_rad=rng.uniform(0.02, 0.2, n).round(6),
        yaw_sigma_rad=yaw_sigma,
    )


# --- round trips ---------------------------------------------------------------


@pytest.mark.parametrize("baro", [True, False])
def test_imu_round_trip(tmp_path, baro):
    imu = make_imu(baro=baro)
    write_imu(tmp_path / "imu.csv", imu)
    back = read_imu(tmp_path / "imu.csv")
    np.testing.assert_array_equal(back.time_s, imu.time_s)
    np.testing.assert_allclose(back.accel, imu.accel, atol=1e-12)
    np.testing.assert_allclose(back.gyro, imu.gyro, atol=1e-12)
    np.testing.assert_array_equal(np.isnan(back.baro_z), np.isnan(imu.baro_z))
    np.testing.assert_allclose(back.baro_z[~np.isnan(back.baro_z)], imu.baro_z[~np.isnan(imu.baro_z)], atol=1e-12)
    assert ("baro_z" in (tmp_path / "imu.csv").read_text().splitlines()[0]) == baro
    assert back.skipped.total == 0 and back.gaps == 0


def test_features_round_trip(tmp_path):
    features = make_features()
    write_features(tmp_path / "features.csv", features)
    back = read_features(tmp_path / "features.csv")
    for name in ("time_s", "range_m", "azimuth_rad", "elevation_rad", "yaw_rad", "range_sigma_m",
                 "angle_sigma_rad", "yaw_sigma_rad"):
        np.testing.assert_allclose(getattr(back, name), getattr(features, name), atol=1e-12, err_msg=name)
    assert back.reordered == 0
    assert ",," in (tmp_path / "features.csv").read_text()  # no yaw: empty cells


def test_features_without_optional_columns(write_file):
    path = write_file("features.csv", "time_s,range_m,azimuth_rad,elevation_rad\n0.05,3.0,1.0,0.2\n")
    features = read_features(path)
    assert len(features) == 1
    assert np.isnan(features.yaw_rad).all() and np.isnan(features.range_sigma_m).all()


def test_truth_orientation_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    q = rng.normal(size=(20, 4))
    q = (q / np.linalg.norm(q, axis=1, keepdims=True)).round(6)
    truth = Truth(
        time_s=np.arange(20) / 100.0,
        epc=np.array(["drone"] * 20),
        position=rng.normal(size=(20, 3)).round(6),
        velocity=rng.normal(size=(20, 3)).round(6),
        orientation=q,
    )
    write_truth(tmp_path / "truth.csv", truth)
    back = read_truth(tmp_path / "truth.csv")
    np.testing.assert_allclose(back.orientation, q, atol=1e-12)
    without = Truth(truth.time_s, truth.epc, truth.position, truth.velocity)
    write_truth(tmp_path / "plain.csv", without)
    assert read_truth(tmp_path / "plain.csv").orientation is None


def test_truth_with_half_a_quaternion_is_refused(write_file):
    path = write_file("truth.csv", "time_s,epc,x,y,z,qw,qx,qy\n0.0,drone,0,0,0,1,0,0\n")
    with pytest.raises(FormatError) as error:
        read_truth(path)
    assert (error.value.line, error.value.column) == (1, "qz")


def test_shared_lora_example_loads(examples):
    folder = examples / "lora-hover-circle"
    if not folder.is_dir():
        pytest.skip(f"{folder} not found")
    scene = read_scene(folder / "scene.toml")
    assert scene.reader.kind == "lora-backscatter"
    imu = read_imu(folder / "imu.csv")
    assert len(imu) > 100 and imu.skipped.total == 0
    assert abs(np.median(imu.accel[:, 2]) - 9.81) < 0.5  # specific force, body z up
    assert not np.isnan(imu.baro_z).all()
    features = read_features(folder / "features.csv")
    assert len(features) > 10
    assert np.all(features.range_m > 0)
    truth = read_truth(folder / "truth.csv")
    assert truth.orientation is not None
    np.testing.assert_allclose(np.linalg.norm(truth.orientation, axis=1), 1.0, atol=1e-5)
    assert set(truth.epc) == {"drone"}


# --- IMU: declined samples and gaps ---------------------------------------------


def test_imu_duplicates_are_declined_and_rows_out_of_order_sorted(write_file):
    rows = imu_rows(10)
    rows.insert(4, rows[3])  # line 6 repeats the time of line 5
    rows.insert(8, "0.015,0,0,9.81,0,0,0,0\n")  # line 10 goes back in time: sorted in
    path = write_file("imu.csv", IMU_HEADER + "".join(rows))
    imu = read_imu(path)
    assert len(imu) == 11
    assert np.all(np.diff(imu.time_s) > 0) and 0.015 in imu.time_s
    assert imu.reordered == 1
    assert imu.skipped.counts == {"duplicate time": 1}
    assert imu.skipped.examples == {"duplicate time": [6]}
    assert "line" in imu.skipped.summary() and "6" in imu.skipped.summary()


def test_shuffled_imu_keeps_every_sample(write_file):
    rows = imu_rows(1200)
    order = np.random.default_rng(3).permutation(len(rows))
    with pytest.warns(InputWarning, match="clock jumps back"):
        imu = read_imu(write_file("imu.csv", IMU_HEADER + "".join(rows[i] for i in order)))
    assert len(imu) == 1200 and imu.skipped.total == 0
    np.testing.assert_allclose(imu.time_s, np.arange(1200) / 100)
    # Each sample keeps its own values: baro_z was written as 0.01 x its index.
    np.testing.assert_allclose(imu.baro_z, np.arange(1200) * 0.01, atol=1e-9)
    assert imu.reordered > 500


def test_a_time_repeated_after_sorting_keeps_the_first_in_the_file(write_file):
    rows = ["0.02,1,0,9.81,0,0,0,\n", "0.01,2,0,9.81,0,0,0,\n", "0.02,3,0,9.81,0,0,0,\n"]
    imu = read_imu(write_file("imu.csv", IMU_HEADER + "".join(rows)))
    np.testing.assert_array_equal(imu.accel[:, 0], [2.0, 1.0])
    assert imu.skipped.examples == {"duplicate time": [4]} and imu.reordered == 1


def test_imu_gaps_are_counted(write_file):
    rows = imu_rows(20) + imu_rows(20, start=25) + imu_rows(20, start=48)
    path = write_file("imu.csv", IMU_HEADER + "".join(rows))
    imu = read_imu(path)
    assert len(imu) == 60
    # 0.19 -> 0.25 is 6 periods, 0.44 -> 0.48 is 4 periods: both longer than 3.
    assert imu.gaps == 2
    rows = imu_rows(20) + imu_rows(20, start=22)  # 0.19 -> 0.22: 3 periods, not longer: not a gap
    assert read_imu(write_file("imu2.csv", IMU_HEADER + "".join(rows))).gaps == 0


def test_features_out_of_order_are_sorted_and_counted(write_file):
    path = write_file("features.csv", FEATURES_HEADER + "".join(feature_rows([0.05, 0.25, 0.15, 0.35, 0.30])))
    features = read_features(path)
    np.testing.assert_allclose(features.time_s, [0.05, 0.15, 0.25, 0.30, 0.35])
    assert features.reordered == 2


# --- malformed files: line and column in the message -----------------------------


def expect_error(path, reader, line, column, text):
    with pytest.raises(FormatError) as error:
        reader(path)
    assert error.value.line == line
    assert error.value.column == column
    message = str(error.value)
    assert f":{line}:" in message if line is not None else True
    if column is not None:
        assert f"column '{column}'" in message
    assert text in message
    assert path.name in message


@pytest.mark.parametrize(
    "text, line, column, message",
    [
        ("time_s,ax,ay,az,gx,gy\n0,0,0,9.81,0,0\n", 1, "gz", "missing required column"),
        (IMU_HEADER + "".join(imu_rows(3)) + "0.03,0,nan,9.81,0,0,0,0\n", 5, "ay", "not a finite number"),
        (IMU_HEADER + "".join(imu_rows(2)) + "0.02,0,0,9.81,0,x,0,0\n", 4, "gy", "not a number"),
        (IMU_HEADER + "0.00,0,0,9.81,0,0,inf,0\n", 2, "gz", "not a finite number"),
        (IMU_HEADER + "0.00,0,0,,0,0,0,0\n", 2, "az", "empty value"),
        (IMU_HEADER + "0.00,0,0,9.81,0,0,0,nan\n", 2, "baro_z", "not a finite number"),
        (IMU_HEADER + "abc,0,0,9.81,0,0,0,0\n", 2, "time_s", "not a number"),
        (IMU_HEADER, 2, None, "no data rows"),
        ("", 1, None, "empty file"),
    ],
    ids=["missing-column", "nan", "text", "inf", "empty-required", "nan-baro", "bad-time", "no-rows", "empty"],
)
def test_malformed_imu(write_file, text, line, column, message):
    expect_error(write_file("imu.csv", text), read_imu, line, column, message)


@pytest.mark.parametrize(
    "text, line, column, message",
    [
        ("time_s,range_m,azimuth_rad\n0,1,2\n", 1, "elevation_rad", "missing required column"),
        (FEATURES_HEADER + "".join(feature_rows([0.05])) + "0.15,nan,1,0.1,0.3,0.6,0.05,0.2\n", 3, "range_m",
         "not a finite number"),
        (FEATURES_HEADER + "0.05,10,one,0.1,0.3,0.6,0.05,0.2\n", 2, "azimuth_rad", "not a number"),
        (FEATURES_HEADER + "0.05,10,1,0.1,nan,0.6,0.05,0.2\n", 2, "yaw_rad", "not a finite number"),
        (FEATURES_HEADER + "0.05,0,1,0.1,,0.6,0.05,\n", 2, "range_m", "range must be positive"),
        (FEATURES_HEADER + "0.05,10,1,1.7,,0.6,0.05,\n", 2, "elevation_rad", "elevation outside"),
        (FEATURES_HEADER + "0.05,10,1,0.1,,-0.6,0.05,\n", 2, "range_sigma_m", "sigma must be positive"),
        (FEATURES_HEADER + "".join(feature_rows([0.05, 0.15])) + "0.25,10,1,0.1,0.3,0.6,0,0.2\n", 4,
         "angle_sigma_rad", "sigma must be positive"),
        (FEATURES_HEADER, 2, None, "no data rows"),
    ],
    ids=["missing-column", "nan", "text", "nan-yaw", "zero-range", "elevation", "negative-sigma", "zero-sigma",
         "no-rows"],
)
def test_malformed_features(write_file, text, line, column, message):
    expect_error(write_file("features.csv", text), read_features, line, column, message)


def test_empty_yaw_cells_are_epochs_without_yaw(write_file):
    path = write_file("features.csv", FEATURES_HEADER + "0.05,10,1,0.1,,0.6,0.05,\n0.15,10,1,0.1,0.5,0.6,0.05,0.2\n")
    features = read_features(path)
    assert math.isnan(features.yaw_rad[0]) and features.yaw_rad[1] == 0.5
    assert math.isnan(features.yaw_sigma_rad[0])


def test_writers_refuse_what_readers_would_reject(tmp_path):
    imu = make_imu(5)
    imu.accel[2, 1] = math.nan
    with pytest.raises(ValueError):
        write_imu(tmp_path / "imu.csv", imu)
    backwards = make_imu(5)
    backwards.time_s[3] = 0.0
    with pytest.raises(ValueError):
        write_imu(tmp_path / "imu.csv", backwards)
    features = make_features(5)
    features.range_m[1] = math.inf
    with pytest.raises(ValueError):
        write_features(tmp_path / "features.csv", features)


@pytest.mark.parametrize(
    "row, column, fragment",
    [
        ("0.00,0,0,9810,0,0,0,0\n", "az", "if this is milli-g (about 1000 at rest), multiply by 9.80665e-3"),
        ("0.00,-2500.5,0,9.81,0,0,0,0\n", "ax", "specific force -2500.5 is beyond 2000 m/s^2"),
        ("0.00,0,0,9.81,0,180,0,0\n", "gy", "looks like degrees per second: multiply by pi/180"),
        ("0.00,0,0,9.81,1e300,0,0,0\n", "gx", "angular rate 1e300 is beyond 100 rad/s"),
    ],
)
def test_imu_values_no_sensor_measures_are_rejected_with_the_unit(write_file, row, column, fragment):
    expect_error(write_file("imu.csv", IMU_HEADER + "".join(imu_rows(2)) + row), read_imu, 4, column, fragment)


def test_features_range_beyond_100_km_is_rejected(write_file):
    path = write_file("features.csv", FEATURES_HEADER + "0.05,1e300,1,0.1,,0.6,0.05,\n")
    expect_error(path, read_features, 2, "range_m", "beyond 100 km")


@pytest.mark.parametrize("cells, column", [("1e300,0.05,0.2", "range_sigma_m"), ("0.6,7,0.2", "angle_sigma_rad"),
                                           ("0.6,0.05,1e300", "yaw_sigma_rad")])
def test_features_sigmas_beyond_meaning_are_rejected(write_file, cells, column):
    path = write_file("features.csv", FEATURES_HEADER + f"0.05,10,1,0.1,0.3,{cells}\n")
    expect_error(path, read_features, 2, column, "carries no information")
