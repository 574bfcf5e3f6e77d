"""Fuzz-style runs of ``scattertrack track`` on malformed helper and drone inputs: each ends
with exit 0 (rows used or declined and counted) or exit 2 and one last error line naming
the file; never a traceback or a Python warning. Variants from fixed seeds (see
``python/tests/io/test_io_fuzz_pipelines.py``)."""

from pathlib import Path

import pytest

from cli_runs import run


FUZZ = Path(__file__).resolve().parents[1] / "io" / "test_io_fuzz_pipelines.py"
CASES = 12
"""Variants per input run through the whole command (the readers' own test covers more)."""


def fuzz():
    import importlib.util

    spec = importlib.util.spec_from_file_location("fuzz_pipelines", FUZZ)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


F = fuzz()


def assert_clean(code: int, out: str, err: str, path: Path) -> None:
    assert code in (0, 2), (code, out, err)
    assert "Traceback" not in out + err
    # Every stderr line is the command's own: a warning: line or the last error line.
    for line in err.splitlines():
        assert line.startswith(("warning: ", "scattertrack: error: ")), err
    if code == 2:
        last = err.rstrip("\n").split("\n")[-1]
        assert last.startswith(f"scattertrack: error: {path}"), err


@pytest.mark.parametrize("index", range(CASES))
def test_track_frames_variants(capsys, tmp_path, index):
    (tmp_path / "scene.toml").write_text(F.HELPER_SCENE)
    frames = tmp_path / "frames.csv"
    F.write(frames, F.variants(F.FRAMES, seed=15)[index][0])
    code, out, err = run(capsys, "track", "--method", "turbotrack", "--scene", tmp_path / "scene.toml",
                         "--frames", frames, "--out", tmp_path / "track.csv", "--no-progress")
    assert_clean(code, out, err, frames)


@pytest.mark.parametrize("which", ["imu", "features"])
@pytest.mark.parametrize("index", range(CASES))
def test_track_drone_variants(capsys, tmp_path, which, index):
    (tmp_path / "scene.toml").write_text(F.DRONE_SCENE)
    imu, features = tmp_path / "imu.csv", tmp_path / "features.csv"
    imu.write_text(F.IMU)
    features.write_text(F.FEATURES)
    target = imu if which == "imu" else features
    F.write(target, F.variants(F.IMU if which == "imu" else F.FEATURES, seed=16)[index][0])
    code, out, err = run(capsys, "track", "--method", "marvel", "--scene", tmp_path / "scene.toml", "--imu", imu,
                         "--features", features, "--out", tmp_path / "track.csv", "--no-progress")
    assert_clean(code, out, err, target)


@pytest.mark.parametrize("pipeline", ["helper", "drone"])
def test_track_with_scene_variants(capsys, tmp_path, pipeline):
    (tmp_path / "frames.csv").write_text(F.FRAMES)
    (tmp_path / "imu.csv").write_text(F.IMU)
    (tmp_path / "features.csv").write_text(F.FEATURES)
    text = F.HELPER_SCENE if pipeline == "helper" else F.DRONE_SCENE
    for k, content in enumerate(F.scene_variants(text, seed=17)[:CASES]):
        scene = tmp_path / f"scene{k}.toml"
        F.write(scene, content)
        if pipeline == "helper":
            argv = ["--method", "turbotrack", "--frames", tmp_path / "frames.csv"]
        else:
            argv = ["--method", "marvel", "--imu", tmp_path / "imu.csv", "--features", tmp_path / "features.csv"]
        code, out, err = run(capsys, "track", "--scene", scene, *argv, "--out", tmp_path / "track.csv", "--no-progress")
        assert code in (0, 2) and "Traceback" not in out + err, (content, out, err)
        if code == 2:
            last = err.rstrip("\n").split("\n")[-1]
            assert last.startswith("scattertrack: error: "), err
