"""``scattertrack track --method marvel`` from imu.csv + features.csv, and its input errors."""

from pathlib import Path

import numpy as np
import pytest

from scattertrack.cli import main
from scattertrack.io import read_track

from cli_runs import run


@pytest.fixture(scope="module")
def flight(tmp_path_factory) -> Path:
    """A 6 s hover flight (scene.toml, imu.csv, features.csv, truth.csv), shared read-only."""
    folder = tmp_path_factory.mktemp("flight")
    assert main(["simulate", "--scenario", "marvel-hover", "--out", str(folder), "--duration", "6"]) == 0
    return folder


def test_marvel_tracks_features_and_imu(capsys, flight, tmp_path):
    out = tmp_path / "track.csv"
    code, stdout, err = run(
        capsys, "track", "--method", "marvel", "--scene", flight / "scene.toml",
        "--features", flight / "features.csv", "--imu", flight / "imu.csv", "--out", out,
    )
    assert code == 0, err
    assert "controller estimated at" in stdout and "per epoch" in stdout
    track = read_track(out)
    assert len(track) > 40
    assert track.orientation is not None and np.allclose(np.linalg.norm(track.orientation, axis=1), 1.0, atol=1e-5)
    assert track.sigma is not None and np.all(track.sigma > 0)
    code, stdout, err = run(capsys, "eval", "--truth", flight / "truth.csv", "--track", out)
    assert code == 0, err
    assert "rot mean" in stdout  # orientation columns appear when both sides have them


def test_marvel_writes_the_revised_track_and_the_causal_one_on_request(capsys, flight, tmp_path):
    from scattertrack.track import marvel
    from scattertrack import io

    out, causal_out = tmp_path / "track.csv", tmp_path / "sub" / "causal.csv"
    code, stdout, err = run(
        capsys, "track", "--method", "marvel", "--scene", flight / "scene.toml",
        "--features", flight / "features.csv", "--imu", flight / "imu.csv", "--out", out, "--causal-out", causal_out,
    )
    assert code == 0, err
    assert "as the fixed-lag smoother last revised it" in stdout and "causal track" in stdout
    revised, causal = read_track(out), read_track(causal_out)
    assert np.array_equal(causal.time_s, revised.time_s)
    assert revised.orientation is not None and revised.sigma is not None
    assert not np.allclose(causal.position, revised.position)
    # --out is the run's revised track, --causal-out its rows as they came
    # (what the Python API returns, and what live publishes).
    result = marvel.run_features(
        "marvel", io.read_scene(flight / "scene.toml"), io.read_imu(flight / "imu.csv"),
        io.read_features(flight / "features.csv"),
    )
    np.testing.assert_allclose(revised.position, result.revised.position, atol=1e-5)
    np.testing.assert_allclose(causal.position, result.position, atol=1e-5)
    # Only the drone pipeline revises its past.
    code, _, err = run(
        capsys, "track", "--method", "glac", "--scene", flight / "scene.toml", "--reads", flight / "features.csv",
        "--out", tmp_path / "g.csv", "--causal-out", tmp_path / "r.csv",
    )
    assert code == 2 and "--causal-out is an output of marvel" in err


def test_marvel_method_is_listed(capsys):
    code, stdout, _ = run(capsys, "methods")
    assert code == 0 and "marvel" in stdout and "ulocate" in stdout


@pytest.mark.parametrize(
    "drop, extra, fragment",
    [
        ("--imu", [], "give --imu"),
        (None, ["--param", "no_such=1"], "unknown parameter 'no_such'"),
    ],
)
def test_marvel_usage_errors(capsys, flight, tmp_path, drop, extra, fragment):
    argv = ["track", "--method", "marvel", "--scene", flight / "scene.toml", "--features", flight / "features.csv",
            "--imu", flight / "imu.csv", "--out", tmp_path / "t.csv", *extra]
    if drop:
        i = argv.index(drop)
        del argv[i : i + 2]
    code, _, err = run(capsys, *argv)
    assert code == 2 and err.startswith("scattertrack: error: ") and fragment in err


def test_ulocate_needs_a_recording(capsys, flight, tmp_path):
    code, _, err = run(
        capsys, "track", "--method", "ulocate", "--scene", flight / "scene.toml",
        "--features", flight / "features.csv", "--imu", flight / "imu.csv", "--out", tmp_path / "t.csv",
    )
    assert code == 2 and "give --sigmf" in err


def test_features_are_refused_by_other_methods(capsys, flight, tmp_path):
    code, _, err = run(
        capsys, "track", "--method", "glac", "--scene", flight / "scene.toml",
        "--features", flight / "features.csv", "--out", tmp_path / "t.csv",
    )
    assert code == 2 and "--features and --imu are inputs of marvel" in err


def test_empty_features_file_names_the_file(capsys, flight, tmp_path):
    empty = tmp_path / "features.csv"
    empty.write_text("time_s,range_m,azimuth_rad,elevation_rad\n")
    code, _, err = run(
        capsys, "track", "--method", "marvel", "--scene", flight / "scene.toml",
        "--features", empty, "--imu", flight / "imu.csv", "--out", tmp_path / "t.csv",
    )
    assert code == 2 and str(empty) in err and "Traceback" not in err


def test_non_monotonic_imu_is_counted_and_reported(capsys, flight, tmp_path):
    lines = (flight / "imu.csv").read_text().splitlines()
    lines.insert(50, lines[20])  # a sample whose time goes backwards
    imu = tmp_path / "imu.csv"
    imu.write_text("\n".join(lines) + "\n")
    code, stdout, err = run(
        capsys, "track", "--method", "marvel", "--scene", flight / "scene.toml",
        "--features", flight / "features.csv", "--imu", imu, "--out", tmp_path / "t.csv",
    )
    assert code == 0, err
    assert "skipped 1" in stdout


def test_marvel_parameters_reach_the_fusion_typed(capsys, flight, tmp_path, monkeypatch):
    from scattertrack import track

    seen = {}

    def capture(method, scene, data, progress=False, **params):
        assert isinstance(data, track.DroneData) and data.features is not None
        seen.update(params)
        raise ValueError("stop here")

    # The CLI's one dispatch point for every pipeline.
    monkeypatch.setattr(track, "run", capture)
    code, _, err = run(
        capsys, "track", "--method", "marvel", "--scene", flight / "scene.toml", "--features", flight / "features.csv",
        "--imu", flight / "imu.csv", "--out", tmp_path / "t.csv", "--param", "use_baro=false", "--param", "smoother_lag_s=3",
    )
    assert code == 2 and "stop here" in err
    assert seen == {"use_baro": False, "smoother_lag_s": 3.0}


def test_the_method_follows_the_input_when_none_is_named(capsys, flight, tmp_path):
    out = tmp_path / "track.csv"
    code, stdout, err = run(
        capsys, "track", "--scene", flight / "scene.toml",
        "--features", flight / "features.csv", "--imu", flight / "imu.csv", "--out", out,
    )
    assert code == 0, err
    assert "tracked with marvel" in stdout


def test_an_imu_noisier_than_stated_is_measured_and_warned_about(capsys, flight, tmp_path):
    """imu.csv with four times the default accelerometer noise: the summary says the
    measured density was used; a density the user stated gets one 'warning:' line
    naming the file and the parameter."""
    lines = (flight / "imu.csv").read_text().splitlines()
    header = lines[0].split(",")
    column = header.index("ax")
    rng = np.random.default_rng(4)
    rows = []
    for line in lines[1:]:
        cells = line.split(",")
        cells[column] = f"{float(cells[column]) + 0.04 * rng.standard_normal():.6f}"  # 4e-3 m/s^2/sqrt(Hz) at 100 Hz
        rows.append(",".join(cells))
    noisy = tmp_path / "imu.csv"
    noisy.write_text("\n".join([lines[0], *rows]) + "\n")
    code, stdout, err = run(
        capsys, "track", "--method", "marvel", "--scene", flight / "scene.toml",
        "--features", flight / "features.csv", "--imu", noisy, "--out", tmp_path / "track.csv",
    )
    assert code == 0, err
    assert "IMU white noise measured from its samples: accelerometer" in stdout
    assert "used instead of accel_noise_density" in stdout and "agrees with gyro_noise_density" in stdout
    assert "warning:" not in err  # the default density is not the user's claim
    code, stdout, err = run(
        capsys, "track", "--method", "marvel", "--scene", flight / "scene.toml", "--features", flight / "features.csv",
        "--imu", noisy, "--out", tmp_path / "stated.csv", "--param", "accel_noise_density=1e-3",
    )
    assert code == 0, err
    warnings = [line for line in err.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and str(noisy) in warnings[0] and "accel_noise_density" in warnings[0], err
    assert "gyro_noise_density" not in warnings[0]
    code, stdout, err = run(
        capsys, "track", "--method", "marvel", "--scene", flight / "scene.toml", "--features", flight / "features.csv",
        "--imu", noisy, "--out", tmp_path / "kept.csv", "--param", "imu_noise_from_data=false",
    )
    assert code == 0 and "warning:" not in err and "IMU white noise" not in stdout
