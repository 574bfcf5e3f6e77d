"""The ``scattertrack`` command, driven in-process through ``main([...])``.

Short simulated sessions (3 s) keep every test fast. Bad input must end in
exit code 2 and one ``scattertrack: error:`` line naming the file, line and
column, never in a traceback.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from scattertrack.cli import DEMO_SCENARIO, main
from scattertrack.io import read_track

from cli_runs import run, with_cell

SHORT_SCENARIO = "glac-2d-10cms"
SHORT_DURATION = "3"


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    """A 3 s simulated session (scene.toml, reads.csv, truth.csv), shared read-only."""
    folder = tmp_path_factory.mktemp("session")
    code = main(["simulate", "--scenario", SHORT_SCENARIO, "--out", str(folder), "--duration", SHORT_DURATION])
    assert code == 0
    return folder


def track_with_reads(capsys, session: Path, tmp_path: Path, lines: list[str], *extra):
    """Write ``lines`` as a reads file and track it against the session's scene."""
    reads = tmp_path / "reads.csv"
    reads.write_text("\n".join(lines) + ("\n" if lines else ""))
    return run(
        capsys,
        "track",
        "--scene", session / "scene.toml",
        "--reads", reads,
        "--out", tmp_path / "track.csv",
        *extra,
    )


def reads_lines(session: Path) -> list[str]:
    return (session / "reads.csv").read_text().splitlines()


def assert_input_error(code: int, out: str, err: str, *fragments: str) -> None:
    """Exit code 2, a one-line message with every fragment, no traceback."""
    assert code == 2
    assert err.startswith("scattertrack: error: ")
    assert "Traceback" not in err + out
    for fragment in fragments:
        assert fragment in err, (fragment, err)


# --- the happy path -------------------------------------------------------------


def test_simulate_track_eval_round_trip(capsys, tmp_path):
    code, out, err = run(
        capsys, "simulate", "--scenario", SHORT_SCENARIO, "--out", tmp_path, "--duration", SHORT_DURATION, "--seed", 5
    )
    assert code == 0, err
    for name in ("scene.toml", "reads.csv", "truth.csv", "simulation.json"):
        assert (tmp_path / name).is_file()
    assert "reads/s" in out and "seed 5" in out

    code, out, err = run(
        capsys,
        "track",
        "--scene", tmp_path / "scene.toml",
        "--reads", tmp_path / "reads.csv",
        "--out", tmp_path / "track.csv",
        "--no-progress",
    )
    assert code == 0, err
    track = read_track(tmp_path / "track.csv")
    assert len(track) > 0
    assert f"wrote {len(track)} rows of 1 tag" in out
    assert "0 rows out of time order" in out
    assert "reads/s wall clock" in out and "per read" in out
    assert "initialising" in out and "reinitialisations" in out and "hypotheses" in out

    code, out, err = run(
        capsys,
        "eval",
        "--truth", tmp_path / "truth.csv",
        "--track", tmp_path / "track.csv",
        "--json", tmp_path / "report.json",
        "--threshold-m", "0.03",
    )
    assert code == 0, err
    assert "3D med" in out and "overall" in out and "30 mm" in out
    assert (tmp_path / "error_cdf.png").stat().st_size > 0
    assert (tmp_path / "track.png").stat().st_size > 0
    record = json.loads((tmp_path / "report.json").read_text())
    assert record["overall"]["n"] == len(track)
    assert record["settings"]["convergence_threshold_m"] == 0.03
    assert "version" in record


def test_eval_writes_figures_to_out_folder(capsys, session, tmp_path):
    code, _, err = run(
        capsys, "track", "--scene", session / "scene.toml", "--reads", session / "reads.csv", "--out", tmp_path / "t.csv"
    )
    assert code == 0, err
    figures = tmp_path / "figures"
    code, out, err = run(capsys, "eval", "--truth", session / "truth.csv", "--track", tmp_path / "t.csv", "--out", figures)
    assert code == 0, err
    assert (figures / "error_cdf.png").is_file() and (figures / "track.png").is_file()
    assert str(figures / "track.png") in out


def test_track_several_interleaved_tags(capsys, tmp_path):
    code, _, err = run(
        capsys, "simulate", "--scenario", "glac-3d-arm-5tags", "--out", tmp_path, "--duration", SHORT_DURATION
    )
    assert code == 0, err
    code, out, err = run(
        capsys, "track", "--scene", tmp_path / "scene.toml", "--reads", tmp_path / "reads.csv", "--out", tmp_path / "t.csv"
    )
    assert code == 0, err
    assert "of 5 tags from" in out
    assert len(set(read_track(tmp_path / "t.csv").epc.tolist())) == 5


def test_track_accepts_parameters(capsys, session, tmp_path):
    code, out, err = track_with_reads(
        capsys, session, tmp_path, reads_lines(session), "--param", "q=0.1", "--param", "max_hypotheses=500"
    )
    assert code == 0, err


def test_track_too_few_reads_writes_an_empty_track_and_says_why(capsys, session, tmp_path):
    code, out, err = track_with_reads(capsys, session, tmp_path, reads_lines(session)[:4])
    assert code == 0, err
    assert "wrote 0 rows" in out and "no estimates" in out
    assert (tmp_path / "track.csv").read_text().startswith("time_s,epc,x,y,z")


def test_eval_unknown_tag(capsys, session, tmp_path):
    code, _, err = run(
        capsys, "track", "--scene", session / "scene.toml", "--reads", session / "reads.csv", "--out", tmp_path / "t.csv"
    )
    assert code == 0, err
    code, out, err = run(
        capsys, "eval", "--truth", session / "truth.csv", "--track", tmp_path / "t.csv", "--tag", "NOPE"
    )
    assert_input_error(code, out, err, "--tag NOPE", "no rows")


# --- rows out of order, duplicates ----------------------------------------------


def test_track_sorts_rows_out_of_order_and_says_how_many(capsys, session, tmp_path):
    lines = reads_lines(session)
    lines[3], lines[4] = lines[4], lines[3]  # two adjacent data rows swapped: one out of order
    lines[10], lines[12] = lines[12], lines[10]  # one row moved two places back: two out of order
    code, out, err = track_with_reads(capsys, session, tmp_path, lines)
    assert code == 0, err
    assert "3 rows out of time order (sorted, not dropped)" in out
    # The track is still in time order per tag (read_track checks it).
    assert len(read_track(tmp_path / "track.csv")) > 0


def test_track_counts_and_reports_duplicate_rows(capsys, session, tmp_path):
    lines = reads_lines(session)
    lines = lines[:6] + [lines[5], lines[5]] + lines[6:]  # file lines 7 and 8 repeat line 6
    code, out, err = track_with_reads(capsys, session, tmp_path, lines)
    assert code == 0, err
    assert "2 duplicate row (lines 7, 8)" in out


# --- malformed input ---------------------------------------------------------------


def test_track_missing_column(capsys, session, tmp_path):
    lines = [",".join(line.split(",")[:4]) for line in reads_lines(session)]  # phase_rad and after dropped
    code, out, err = track_with_reads(capsys, session, tmp_path, lines)
    assert_input_error(code, out, err, str(tmp_path / "reads.csv") + ":1:", "column 'phase_rad'", "missing")


def test_track_nan_value(capsys, session, tmp_path):
    lines = reads_lines(session)
    lines = with_cell(lines, 4, lines[0].split(",").index("phase_rad"), "nan")
    code, out, err = track_with_reads(capsys, session, tmp_path, lines)
    assert_input_error(code, out, err, "reads.csv:5:", "column 'phase_rad'", "not a finite number")


def test_track_unknown_antenna(capsys, session, tmp_path):
    lines = reads_lines(session)
    lines = with_cell(lines, 6, lines[0].split(",").index("antenna"), "9")
    code, out, err = track_with_reads(capsys, session, tmp_path, lines)
    assert_input_error(code, out, err, "reads.csv:7:", "column 'antenna'", "not in the scene")


def test_track_empty_file(capsys, session, tmp_path):
    code, out, err = track_with_reads(capsys, session, tmp_path, [])
    assert_input_error(code, out, err, "reads.csv:1:", "empty file")


def test_track_header_only(capsys, session, tmp_path):
    code, out, err = track_with_reads(capsys, session, tmp_path, reads_lines(session)[:1])
    assert_input_error(code, out, err, "reads.csv:2:", "no data rows")


def test_track_scene_without_antennas(capsys, session, tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text('name = "bare"\ndimensions = 3\n\n[reader]\nkind = "cots"\n')
    code, out, err = run(
        capsys, "track", "--scene", scene, "--reads", session / "reads.csv", "--out", tmp_path / "t.csv"
    )
    assert_input_error(code, out, err, str(scene) + ":", "column 'antennas'", "needs [[antennas]]")


def test_track_missing_file(capsys, session, tmp_path):
    missing = tmp_path / "nowhere.csv"
    code, out, err = run(
        capsys, "track", "--scene", session / "scene.toml", "--reads", missing, "--out", tmp_path / "t.csv"
    )
    assert_input_error(code, out, err, str(missing), "no such file")


def test_eval_malformed_track(capsys, session, tmp_path):
    bad = tmp_path / "track.csv"
    bad.write_text("time_s,epc,x,y\n0.1,E1,0,0\n")
    code, out, err = run(capsys, "eval", "--truth", session / "truth.csv", "--track", bad)
    assert_input_error(code, out, err, str(bad) + ":1:", "column 'z'")


# --- methods and parameters ----------------------------------------------------------


def test_track_unknown_method(capsys, session, tmp_path):
    code, out, err = track_with_reads(capsys, session, tmp_path, reads_lines(session), "--method", "kalman-magic")
    assert_input_error(code, out, err, "unknown method 'kalman-magic'", "glac")
    assert not (tmp_path / "track.csv").exists()


def test_track_unknown_parameter(capsys, session, tmp_path):
    code, out, err = track_with_reads(capsys, session, tmp_path, reads_lines(session), "--param", "gate_sigma=2")
    assert_input_error(code, out, err, "unknown parameter 'gate_sigma'", "gate_sigmas")


def test_track_parameter_of_the_wrong_type(capsys, session, tmp_path):
    code, out, err = track_with_reads(capsys, session, tmp_path, reads_lines(session), "--param", "q=lots")
    assert_input_error(code, out, err, "invalid parameter 'q'", "a float > 0", "'lots'")


def test_track_parameter_out_of_range(capsys, session, tmp_path):
    code, out, err = track_with_reads(capsys, session, tmp_path, reads_lines(session), "--param", "q=-1")
    assert_input_error(code, out, err, "invalid parameter 'q'", "a float > 0", "got -1")


def test_track_parameter_without_value_is_a_usage_error(capsys, session, tmp_path):
    code, out, err = track_with_reads(capsys, session, tmp_path, reads_lines(session), "--param", "q")
    assert code == 2
    assert "expected name=value" in err


# --- listings ------------------------------------------------------------------------


def test_methods_lists_glac(capsys):
    code, out, _ = run(capsys, "methods")
    assert code == 0
    names = [line.split()[0] for line in out.splitlines()]
    assert "glac" in names and "glac-naive" in names


def test_scenarios_lists_names_with_descriptions(capsys):
    code, out, _ = run(capsys, "scenarios")
    assert code == 0
    lines = {line.split()[0]: line for line in out.splitlines()}
    assert DEMO_SCENARIO in lines and SHORT_SCENARIO in lines
    assert len(lines[SHORT_SCENARIO].split()) > 3  # a description follows the name


def test_simulate_unknown_scenario(capsys, tmp_path):
    code, out, err = run(capsys, "simulate", "--scenario", "no-such-scenario", "--out", tmp_path)
    assert_input_error(code, out, err, "no-such-scenario", "no such scenario")


def test_no_command_is_a_usage_error(capsys):
    code, _, err = run(capsys)
    assert code == 2
    assert "usage" in err


# --- demo -----------------------------------------------------------------------------


def test_demo_short(capsys, tmp_path):
    code, out, err = run(capsys, "demo", "--out", tmp_path, "--duration", SHORT_DURATION, "--no-progress")
    assert code == 0, err
    for name in ("scene.toml", "reads.csv", "truth.csv", "track.csv", "error_cdf.png", "track.png", "report.json"):
        assert (tmp_path / name).is_file(), name
        assert str(tmp_path / name) in out
    assert f"scenario {DEMO_SCENARIO}" in out
    assert "median 3D error" in out
    assert "faster than real time" in out
    assert "per read" in out


def test_demo_duration_is_hidden_from_help(capsys):
    code, out, _ = run(capsys, "demo", "--help")
    assert code == 0
    assert "--out" in out and "--duration" not in out


# --- installed entry points -----------------------------------------------------------------


def test_console_script_help():
    script = Path(sys.executable).parent / "scattertrack"
    if not script.exists():
        script = shutil.which("scattertrack")
    if script is None or not Path(script).exists():
        pytest.skip("the scattertrack console script is not installed (run make setup)")
    result = subprocess.run([str(script), "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    for command in ("simulate", "track", "eval", "demo"):
        assert command in result.stdout


def test_python_dash_m():
    result = subprocess.run(
        [sys.executable, "-m", "scattertrack", "--version"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("scattertrack ")


# --- turbotrack (reader + SDR helper) scenarios ----------------------------------


def test_simulate_turbotrack_scenario_writes_frames(capsys, tmp_path):
    from scattertrack.io import read_frames, read_scene

    code, out, err = run(
        capsys, "simulate", "--scenario", "turbotrack-3d-arm", "--out", tmp_path, "--duration", "1", "--seed", 4
    )
    assert code == 0, err
    for name in ("scene.toml", "frames.csv", "truth.csv", "simulation.json"):
        assert (tmp_path / name).is_file()
    assert not (tmp_path / "reads.csv").exists()
    frames = read_frames(tmp_path / "frames.csv", read_scene(tmp_path / "scene.toml"))
    assert f"{frames.n_frames} frames of 1 tag" in out
    assert "frames/s" in out and "(turbotrack), seed 4" in out and "20 subcarriers over 100 MHz" in out
    code, _, err = run(
        capsys, "simulate", "--scenario", "turbotrack-static", "--out", tmp_path / "b", "--duration", "1",
        "--pipeline", "turbotrack",
    )
    assert code == 0, err


def test_simulate_scenario_of_the_other_pipeline(capsys, tmp_path):
    code, out, err = run(capsys, "simulate", "--scenario", "turbotrack-static", "--out", tmp_path, "--pipeline", "glac")
    assert_input_error(code, out, err, "turbotrack-static is for the turbotrack pipeline, not glac", "glac-3d-arm")
    code, out, err = run(capsys, "simulate", "--scenario", SHORT_SCENARIO, "--out", tmp_path, "--pipeline", "turbotrack")
    assert_input_error(code, out, err, "is for the glac pipeline, not turbotrack", "turbotrack-3d-arm")
    assert not any(tmp_path.iterdir())


def test_scenarios_lists_the_pipeline(capsys):
    code, out, _ = run(capsys, "scenarios")
    assert code == 0
    lines = {line.split()[0]: line.split()[1] for line in out.splitlines()}
    assert lines["turbotrack-3d-arm"] == "turbotrack" and lines["turbotrack-2d-speed-50"] == "turbotrack"
    assert lines[SHORT_SCENARIO] == "glac"


@pytest.fixture(scope="module")
def iq_session(tmp_path_factory) -> Path:
    """0.1 s of the thesis arm at IQ level (30 replies), SigMF + calibration."""
    folder = tmp_path_factory.mktemp("iq")
    code = main(["simulate", "--scenario", "turbotrack-3d-arm", "--iq", "--duration", "0.1", "--out", str(folder)])
    assert code == 0
    return folder


def test_simulate_iq_writes_sigmf_and_its_calibration(iq_session):
    for name in ("recording.sigmf-meta", "recording.sigmf-data", "calibration.sigmf-meta", "scene.toml", "truth.csv"):
        assert (iq_session / name).is_file(), name


def test_track_sigmf_finds_the_calibration_beside_it(capsys, iq_session, tmp_path):
    code, out, err = run(
        capsys, "track", "--scene", iq_session / "scene.toml", "--sigmf", iq_session / "recording.sigmf-meta",
        "--method", "turbotrack", "--out", tmp_path / "track.csv", "--no-progress",
    )
    assert code == 0, err
    assert "calibration.sigmf-meta" in out
    assert len(read_track(tmp_path / "track.csv")) > 20


def test_track_picks_the_helper_method_for_a_helper_recording(capsys, iq_session, tmp_path):
    """No --method: a SigMF recording of an sdr-helper scene is tracked by turbotrack."""
    code, out, err = run(
        capsys, "track", "--scene", iq_session / "scene.toml", "--sigmf", iq_session / "recording.sigmf-meta",
        "--out", tmp_path / "track.csv", "--no-progress",
    )
    assert code == 0, err
    assert "tracked with turbotrack" in out


def test_stream_prints_throughput_and_latency(capsys, iq_session, tmp_path):
    code, out, err = run(
        capsys, "stream", "--scene", iq_session / "scene.toml", "--sigmf", iq_session / "recording.sigmf-meta",
        "--calibration", iq_session / "calibration.sigmf-meta", "--fast", "--out", tmp_path / "track.csv",
    )
    assert code == 0, err
    assert "frames/s" in out and "p99" in out and "dispatch" in out
    assert len(read_track(tmp_path / "track.csv")) > 20


def test_stream_takes_a_thread_layout_and_refuses_a_negative_prewake(capsys, iq_session, tmp_path):
    common = (
        "stream", "--scene", iq_session / "scene.toml", "--sigmf", iq_session / "recording.sigmf-meta",
        "--calibration", iq_session / "calibration.sigmf-meta", "--out", tmp_path / "track.csv",
    )
    code, out, err = run(capsys, *common, "--layout", "per-antenna", "--workers", "1", "--fast")
    assert code == 0 and "p99" in out, err
    code, _, err = run(capsys, *common, "--prewake-us", "-5")
    assert code == 2 and "--prewake-us" in err
    code, _, err = run(capsys, *common, "--layout", "pools")
    assert code == 2 and "pools" in err


def test_stream_and_track_without_calibration_are_usage_errors(capsys, iq_session, tmp_path):
    lone = tmp_path / "lone"
    lone.mkdir()
    for suffix in ("sigmf-meta", "sigmf-data"):
        shutil.copy(iq_session / f"recording.{suffix}", lone / f"recording.{suffix}")
    for command in ("stream", "track"):
        code, _, err = run(
            capsys, command, "--scene", iq_session / "scene.toml", "--sigmf", lone / "recording.sigmf-meta",
            "--method", "turbotrack", "--out", tmp_path / "track.csv",
        )
        assert code == 2 and "--calibration" in err


def test_stream_a_cots_method_and_iq_of_a_glac_scenario_are_usage_errors(capsys, iq_session, tmp_path):
    code, _, err = run(
        capsys, "stream", "--scene", iq_session / "scene.toml", "--sigmf", iq_session / "recording.sigmf-meta",
        "--method", "glac", "--out", tmp_path / "track.csv",
    )
    assert code == 2 and "glac" in err
    code, _, err = run(capsys, "simulate", "--scenario", "glac-2d-10cms", "--iq", "--out", tmp_path / "x")
    assert code == 2 and "glac pipeline" in err


def test_stream_a_corrupt_recording_names_the_file(capsys, iq_session, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    for name in ("recording.sigmf-meta", "recording.sigmf-data", "calibration.sigmf-meta", "calibration.sigmf-data"):
        shutil.copy(iq_session / name, bad / name)
    data = bad / "recording.sigmf-data"
    data.write_bytes(data.read_bytes()[:-6])  # cut mid-sample
    code, _, err = run(
        capsys, "stream", "--scene", iq_session / "scene.toml", "--sigmf", bad / "recording.sigmf-meta",
        "--fast", "--out", tmp_path / "track.csv",
    )
    assert code == 2 and "recording.sigmf-data" in err and "Traceback" not in err
