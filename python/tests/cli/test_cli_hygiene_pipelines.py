"""Input hygiene of the helper and drone pipelines through ``scattertrack track``: exit 2 with
one last error line naming file, line and column; ``warning:`` lines for suspicious input;
every row used or declined with a reason and counted in what the command prints."""

import pytest

from cli_runs import assert_rejected, run, warning_lines, with_cell
from scene_texts import helper_scene

HELPER_SCENE = helper_scene(4, """\
[region]
min = [-1.0, -1.0, 0.05]
max = [2.0, 2.0, 2.0]
""")

DRONE_SCENE = """\
name = "drone"
dimensions = 3

[reader]
kind = "lora-backscatter"
"""

FRAMES = "time_s,epc,tx,rx,frequency_hz,h_re,h_im"
IMU = "time_s,ax,ay,az,gx,gy,gz"
FEATURES = "time_s,range_m,azimuth_rad,elevation_rad,yaw_rad,range_sigma_m,angle_sigma_rad,yaw_sigma_rad"


def frames_rows(n_frames: int = 3) -> list[str]:
    rows = []
    for k in range(n_frames):
        for rx in (1, 2, 3, 4):
            for f in (902.5e6, 907.5e6, 912.5e6):
                rows.append(f"{0.01 * k:.6f},E2,0,{rx},{f!r},0.25,-0.1")
    return rows


def track_frames(capsys, tmp_path, rows: list[str], scene: str = HELPER_SCENE, header: str = FRAMES):
    (tmp_path / "scene.toml").write_text(scene)
    (tmp_path / "frames.csv").write_text("\n".join([header, *rows]) + "\n")
    return run(capsys, "track", "--method", "turbotrack", "--scene", tmp_path / "scene.toml",
               "--frames", tmp_path / "frames.csv", "--out", tmp_path / "track.csv", "--no-progress")


def imu_rows(n: int = 300, start_s: float = 0.0) -> list[str]:
    return [f"{start_s + i / 100:.2f},0,0,9.81,0,0,0" for i in range(n)]


def features_rows(n: int = 30, start_s: float = 0.05) -> list[str]:
    return [f"{start_s + i / 10:.2f},10,0.5,0.1,0.2,0.5,0.05,0.2" for i in range(n)]


def track_drone(capsys, tmp_path, imu: list[str], features: list[str], imu_header=IMU, features_header=FEATURES):
    (tmp_path / "scene.toml").write_text(DRONE_SCENE)
    (tmp_path / "imu.csv").write_text("\n".join([imu_header, *imu]) + "\n")
    (tmp_path / "features.csv").write_text("\n".join([features_header, *features]) + "\n")
    return run(capsys, "track", "--method", "marvel", "--scene", tmp_path / "scene.toml", "--imu", tmp_path / "imu.csv",
               "--features", tmp_path / "features.csv", "--out", tmp_path / "track.csv", "--no-progress")


# --- helper: frames.csv -------------------------------------------------------------------

FRAMES_COLUMN = {name: k for k, name in enumerate(FRAMES.split(","))}


@pytest.mark.parametrize(
    "row, column, value, fragment",
    [
        (2, "time_s", "1_0.5", "'_' digit separators"),
        (4, "h_re", "\uff11", "U+FF11"),
        (5, "h_im", "nan", "not a finite number"),
        (6, "h_re", "inf", "not a finite number"),
        (7, "frequency_hz", "902.5", "looks like MHz"),
        (8, "rx", "0", "antenna '0' has role 'tx' in the scene; column 'rx' needs a 'rx' antenna"),
        (9, "tx", "1", "antenna '1' has role 'rx' in the scene; column 'tx' needs a 'tx' antenna"),
        (10, "rx", "9", "antenna '9' is not in the scene"),
    ],
)
def test_malformed_frames_exit_2_naming_line_and_column(capsys, tmp_path, row, column, value, fragment):
    code, out, err = track_frames(capsys, tmp_path, with_cell(frames_rows(), row, FRAMES_COLUMN[column], value))
    assert_rejected(code, out, err, f"{tmp_path / 'frames.csv'}:{row + 2}: line {row + 2}", f"column '{column}'", fragment)


def test_huge_channels_are_declined_counted_and_said(capsys, tmp_path):
    rows = [",".join(r.split(",")[:5] + ["3e200", "-1e250"]) for r in frames_rows()]
    code, out, err = track_frames(capsys, tmp_path, rows)
    assert code == 0, err
    assert "declined 36 rows on reading: 36 channel beyond 1e100 (lines 2, 3, 4, 5, 6, ...)" in out
    assert "no frames left to track: every row was declined" in out
    assert "wrote 0 rows" in out


def test_a_few_huge_channels_are_declined_and_the_rest_tracked(capsys, tmp_path):
    rows = frames_rows()
    rows[3] = ",".join(rows[3].split(",")[:5] + ["1e150", "0"])
    code, out, err = track_frames(capsys, tmp_path, rows)
    assert code == 0, err
    assert "read 3 frames of 1 tag" in out and "declined 1 row on reading: 1 channel beyond 1e100 (lines 5)" in out


def test_helper_antennas_in_line_with_the_transmitter_warn(capsys, tmp_path):
    scene = HELPER_SCENE.replace("position = [0.4, 0.0, 0.0]", "position = [1.2, 0.4, 0.0]")  # rx 3 onto the x line
    code, out, err = track_frames(capsys, tmp_path, frames_rows(), scene=scene)
    assert code == 0, err
    (line,) = warning_lines(out)
    assert "receive antennas 1, 2 and 3 lie on one line with the transmitter 0 (along x)" in line
    code, out, err = run(capsys, "check-scene", tmp_path / "scene.toml")
    assert code == 0 and warning_lines(out) == [line]


def test_a_scene_the_tracker_cannot_use_names_the_scene_file(capsys, tmp_path):
    scene = HELPER_SCENE.replace('id = 4\nposition = [0.4, 0.8, 0.0]\nrole = "rx"\n', "")
    scene = scene.replace('id = 3\nposition = [0.4, 0.0, 0.0]\nrole = "rx"\n', "").replace("[[antennas]]\n\n", "")
    code, out, err = track_frames(capsys, tmp_path, [r for r in frames_rows() if ",1," in r or ",2," in r], scene=scene)
    assert_rejected(code, out, err, f"{tmp_path / 'scene.toml'}: invalid scene: a wideband tracker needs")


def test_the_cross_layout_tracks_without_a_warning(capsys, tmp_path):
    code, out, err = track_frames(capsys, tmp_path, frames_rows())
    assert code == 0, err
    assert warning_lines(out + err) == [] and "none declined" not in out


# --- drone: imu.csv and features.csv --------------------------------------------------------

FEATURES_COLUMN = {name: k for k, name in enumerate(FEATURES.split(","))}
IMU_COLUMN = {name: k for k, name in enumerate(IMU.split(","))}


@pytest.mark.parametrize(
    "row, column, value, fragment",
    [
        (3, "elevation_rad", "1.5708", "elevation outside [-pi/2, pi/2]"),
        (4, "elevation_rad", "-2", "elevation outside [-pi/2, pi/2]"),
        (5, "range_m", "-3", "range must be positive"),
        (6, "range_sigma_m", "-0.5", "sigma must be positive"),
        (7, "angle_sigma_rad", "0", "sigma must be positive"),
        (8, "azimuth_rad", "\u0661", "U+0661"),
        (9, "time_s", "1_0", "'_' digit separators"),
        (10, "yaw_rad", "inf", "not a finite number"),
    ],
)
def test_malformed_features_exit_2_naming_line_and_column(capsys, tmp_path, row, column, value, fragment):
    rows = with_cell(features_rows(), row, FEATURES_COLUMN[column], value)
    code, out, err = track_drone(capsys, tmp_path, imu_rows(), rows)
    assert_rejected(code, out, err, f"{tmp_path / 'features.csv'}:{row + 2}: line {row + 2}", f"column '{column}'",
                    fragment)


@pytest.mark.parametrize(
    "row, column, value, fragment",
    [(10, "az", "9.81\u00a0", "U+00A0"), (11, "gx", "nan", "not a finite number"), (12, "time_s", "", "empty value")],
)
def test_malformed_imu_exit_2_naming_line_and_column(capsys, tmp_path, row, column, value, fragment):
    rows = with_cell(imu_rows(), row, IMU_COLUMN[column], value)
    code, out, err = track_drone(capsys, tmp_path, rows, features_rows())
    assert_rejected(code, out, err, f"{tmp_path / 'imu.csv'}:{row + 2}: line {row + 2}", f"column '{column}'", fragment)


def test_shuffled_imu_is_sorted_and_every_sample_kept(capsys, tmp_path):
    import numpy as np

    rows = imu_rows()
    shuffled = [rows[i] for i in np.random.default_rng(4).permutation(len(rows))]
    code, out, err = track_drone(capsys, tmp_path, shuffled, features_rows())
    assert code == 0, err
    assert "read 300 IMU samples" in out and "out of time order (sorted), none declined, 0 gaps" in out
    assert any("clock jumps back" in line for line in warning_lines(err))


def test_imu_clock_jump_back_is_a_warning_line(capsys, tmp_path):
    rows = imu_rows(150, start_s=1.5) + imu_rows(150)  # line 152 jumps back to 0 s
    code, out, err = track_drone(capsys, tmp_path, rows, features_rows())
    assert code == 0, err
    (line,) = warning_lines(err)
    assert line.startswith(f"warning: {tmp_path / 'imu.csv'}:152: line 152, column 'time_s': clock jumps back by 2.99 s")


def test_features_before_the_imu_warn_and_every_decline_is_reported(capsys, tmp_path):
    code, out, err = track_drone(capsys, tmp_path, imu_rows(300, start_s=100.0), features_rows())
    assert code == 0, err
    (line,) = warning_lines(err)
    assert line.startswith(f"warning: {tmp_path / 'features.csv'}:2: line 2, column 'time_s': 30 of 30 rows lie "
                           f"before the first IMU sample of {tmp_path / 'imu.csv'}")
    assert "are the two files on one clock?" in line
    assert "wrote 0 rows" in out and "no estimates from 30 epochs" in out
    assert "skipped 30 feature row before the first IMU sample" in out


def test_features_partly_outside_the_imu_span_warn_with_the_count(capsys, tmp_path):
    code, out, err = track_drone(capsys, tmp_path, imu_rows(200, start_s=0.5), features_rows())
    assert code == 0, err
    before, after = warning_lines(err)
    assert "5 of 30 rows lie before the first IMU sample" in before and ":2: line 2," in before
    assert "5 of 30 rows lie after the last IMU sample" in after and ":31: line 31," in after


def test_quiet_drone_inputs_have_no_warning(capsys, tmp_path):
    code, out, err = track_drone(capsys, tmp_path, imu_rows(), features_rows())
    assert code == 0, err
    assert warning_lines(err) == [] and "wrote 30 rows" in out


# --- helper: SigMF recordings -----------------------------------------------------------------


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A short simulated helper recording, its calibration and scene.toml (as simulate --iq writes them)."""
    import numpy as np

    from scattertrack.io import read_scene
    from scattertrack.sim import iq

    folder = tmp_path_factory.mktemp("recorded")
    (folder / "scene.toml").write_text(HELPER_SCENE)
    sim = iq.simulate_iq(read_scene(folder / "scene.toml"), {"E1": {"kind": "static", "position": [0.55, 0.3, 0.6]}},
                         seed=2, duration_s=0.014)
    out = iq.write_iq_simulation(sim, folder / "run")
    assert np.isfinite(sim.recording.data).all()
    return out


@pytest.fixture
def recording(recorded, tmp_path):
    """Fresh copies of the recorded files in ``tmp_path``."""
    import shutil

    for path in recorded.iterdir():
        shutil.copy(path, tmp_path / path.name)
    return tmp_path


def track_sigmf(capsys, folder, *extra):
    return run(capsys, "track", "--method", "turbotrack", "--scene", folder / "scene.toml",
               "--sigmf", folder / "recording.sigmf-meta", "--out", folder / "track.csv", "--no-progress", *extra)


def edit_global(meta, change):
    import json

    document = json.loads(meta.read_text())
    change(document)
    meta.write_text(json.dumps(document))


def test_a_good_recording_tracks_quietly(capsys, recording):
    code, out, err = track_sigmf(capsys, recording)
    assert code == 0, err
    assert warning_lines(out + err) == [] and "read 4 frames of 1 tag" in out


@pytest.mark.parametrize(
    "change, column, fragment",
    [
        (lambda d: d["global"].pop("scattertrack:blf_hz"), "global.scattertrack:blf_hz", "missing required key"),
        (lambda d: d["global"].__setitem__("core:datatype", "ci8"), "global.core:datatype", "unsupported datatype"),
        (lambda d: d["captures"][1].pop("scattertrack:time_s"), "captures[1].scattertrack:time_s", "not a finite number"),
        (lambda d: d["captures"][2].__setitem__("core:sample_start", 10), "captures[2].core:sample_start",
         "increasing samples"),
        (lambda d: d["global"]["scattertrack:antennas"][2].__setitem__("role", "tx"),
         "global.scattertrack:antennas[2].role", "listed as 'tx'"),
    ],
    ids=["missing-key", "datatype", "capture-time", "capture-start", "tx-as-rx"],
)
def test_broken_recordings_exit_2_naming_the_key(capsys, recording, change, column, fragment):
    edit_global(recording / "recording.sigmf-meta", change)
    code, out, err = track_sigmf(capsys, recording)
    assert_rejected(code, out, err, f"{recording / 'recording.sigmf-meta'}: column '{column}'", fragment)


def test_a_data_file_not_whole_samples_exits_2(capsys, recording):
    data = recording / "recording.sigmf-data"
    with open(data, "r+b") as handle:
        handle.truncate(data.stat().st_size - 6)
    code, out, err = track_sigmf(capsys, recording)
    assert_rejected(code, out, err, f"{data}: ", "is not a whole number of samples (16 bytes each: 4 channels x ci16_le)")


def test_a_missing_data_file_exits_2(capsys, recording):
    (recording / "recording.sigmf-data").unlink()
    code, out, err = track_sigmf(capsys, recording)
    assert_rejected(code, out, err, f"{recording / 'recording.sigmf-data'}: data file not found")


def test_a_missing_calibration_recording_exits_2(capsys, recording):
    code, out, err = track_sigmf(capsys, recording, "--calibration", recording / "nothere.sigmf-meta")
    assert_rejected(code, out, err, f"{recording / 'nothere.sigmf-meta'}: metadata file not found")
    (recording / "calibration.sigmf-meta").unlink()
    code, out, err = track_sigmf(capsys, recording)
    assert_rejected(code, out, err, "give --calibration")


def test_a_calibration_missing_its_data_exits_2(capsys, recording):
    (recording / "calibration.sigmf-data").unlink()
    code, out, err = track_sigmf(capsys, recording)
    assert_rejected(code, out, err, f"{recording / 'calibration.sigmf-data'}: data file not found")


def test_a_scene_beyond_5_cm_of_the_recording_warns_and_tracks(capsys, recording):
    scene = recording / "scene.toml"
    scene.write_text(scene.read_text().replace("position = [0.8, 0.4, 0.0]", "position = [0.8, 0.5, 0.0]"))
    code, out, err = track_sigmf(capsys, recording)
    assert code == 0, err
    found = warning_lines(err)
    assert len(found) == 2  # the recording and its calibration each list the antenna
    for line, name in zip(found, ("recording", "calibration")):
        assert line.startswith(f"warning: {recording / (name + '.sigmf-meta')}: column 'global.scattertrack:antennas[2]"
                               ".position': antenna 2 is at (0.800, 0.400, 0.000) m in the recording but at "
                               "(0.800, 0.500, 0.000) m in scene 'helper', 10.0 cm apart")


# --- drone: LoRa SigMF recordings ---------------------------------------------------------------


@pytest.fixture(scope="module")
def lora_recorded(tmp_path_factory):
    """A 3-epoch LoRa recording (0.3 s) with scene.toml, read-only."""
    import numpy as np

    from scattertrack.io.sigmf_lora import write_lora_sigmf
    from scattertrack.sim import lora

    def hover(t):
        t = np.asarray(t, dtype=float)
        position = np.stack([1.0 + 0.5 * t, 15.0 + 0 * t, 2.0 + 0 * t], axis=1)
        return position, np.stack([np.cos(0.15 + 0 * t), 0 * t, 0 * t, np.sin(0.15 + 0 * t)], axis=1)

    folder = tmp_path_factory.mktemp("lora")
    recording = lora.simulate_lora_iq(hover, {"position": [0.0, 0.0, 1.0], "walls": 0}, None, 0.3, seed=11)
    write_lora_sigmf(folder / "recording", recording)
    (folder / "scene.toml").write_text(DRONE_SCENE)
    return folder


@pytest.fixture
def lora_copy(lora_recorded, tmp_path):
    import shutil

    for path in lora_recorded.iterdir():
        shutil.copy(path, tmp_path / path.name)
    return tmp_path


def track_lora(capsys, folder, imu: list[str]):
    (folder / "imu.csv").write_text("\n".join([IMU, *imu]) + "\n")
    return run(capsys, "track", "--method", "marvel", "--scene", folder / "scene.toml", "--imu", folder / "imu.csv",
               "--sigmf", folder / "recording.sigmf-meta", "--out", folder / "track.csv", "--no-progress")


def test_a_broken_lora_capture_exits_2_naming_the_key(capsys, lora_copy):
    edit_global(lora_copy / "recording.sigmf-meta", lambda d: d["captures"][3].pop("scattertrack:epoch"))
    code, out, err = track_lora(capsys, lora_copy, imu_rows(100))
    assert_rejected(code, out, err, f"{lora_copy / 'recording.sigmf-meta'}: column 'captures[3].scattertrack:epoch'")


def test_a_lora_data_file_of_another_size_exits_2(capsys, lora_copy):
    data = lora_copy / "recording.sigmf-data"
    with open(data, "ab") as handle:
        handle.write(b"\0" * 48)  # one more sample of 12 ci16 channels
    code, out, err = track_lora(capsys, lora_copy, imu_rows(100))
    assert_rejected(code, out, err, f"{data}: size does not match the captures")


def test_lora_epochs_after_the_imu_warn(capsys, lora_copy):
    code, out, err = track_lora(capsys, lora_copy, imu_rows(10))  # IMU to 0.09 s, epochs to 0.2 s
    assert code == 0, err
    (line,) = warning_lines(err)
    assert line.startswith(f"warning: {lora_copy / 'recording.sigmf-meta'}: column 'captures.scattertrack:time_s': ")
    assert "epochs lie after the last IMU sample" in line


# --- the shared examples (written by another program) -----------------------------------------

from pathlib import Path  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[3].parent / "shared" / "examples"


@pytest.mark.skipif(not (EXAMPLES / "helper-3d-arm").is_dir(), reason="shared examples not found")
def test_the_shared_helper_example_tracks_with_its_layout_warning(capsys, tmp_path):
    case = EXAMPLES / "helper-3d-arm"
    code, out, err = run(capsys, "track", "--method", "turbotrack", "--scene", case / "scene.toml", "--frames",
                         case / "frames.csv", "--out", tmp_path / "track.csv", "--no-progress")
    assert code == 0, err
    assert "declined" not in out and warning_lines(err) == []
    (line,) = warning_lines(out)
    assert "receive antennas 1, 2 and 3 lie on one line with the transmitter 0 (along x)" in line


@pytest.mark.skipif(not (EXAMPLES / "lora-hover-circle").is_dir(), reason="shared examples not found")
def test_the_shared_drone_example_tracks_quietly(capsys, tmp_path):
    case = EXAMPLES / "lora-hover-circle"
    code, out, err = run(capsys, "track", "--method", "marvel", "--scene", case / "scene.toml", "--imu", case / "imu.csv",
                         "--features", case / "features.csv", "--out", tmp_path / "track.csv", "--no-progress")
    assert code == 0, err
    assert warning_lines(out + err) == [] and "none declined" in out and "wrote 115 rows" in out
