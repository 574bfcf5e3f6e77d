"""Input hygiene through the command line: exit 2 with one last error line naming file, line and
column; ``warning:`` lines for suspicious input; every numeric option range-checked."""

from pathlib import Path

import pytest

from cli_runs import assert_rejected, run, warning_lines, with_cell


OUTSIDE = Path(__file__).resolve().parents[3].parent / "shared" / "outside"

SCENE = """\
name = "tiny"
dimensions = 3

[reader]
kind = "cots"

[[antennas]]
id = {first_id}
position = [0.0, 0.0, 0.0]

[[antennas]]
id = 2
position = [0.0, 0.3, 0.0]

[[antennas]]
id = 3
position = [0.3, 0.0, 0.0]
"""

HEADER = "time_s,epc,antenna,frequency_hz,phase_rad"


def reads_rows(n: int = 30, start_s: float = 0.0) -> list[str]:
    return [f"{start_s + 0.01 * i:.6f},E200,{i % 3 + 1},915250000.0,{(0.37 * i) % 6.28:.6f}" for i in range(n)]


def track(capsys, tmp_path, rows: list[str], first_id: str = "1", header: str = HEADER):
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.format(first_id=first_id))
    reads = tmp_path / "reads.csv"
    reads.write_text("\n".join([header, *rows]) + "\n")
    return run(capsys, "track", "--scene", scene, "--reads", reads, "--out", tmp_path / "track.csv", "--no-progress")


COLUMN_INDEX = {name: k for k, name in enumerate(HEADER.split(","))}


@pytest.mark.parametrize(
    "row, column, value, fragment",
    [
        (3, "time_s", "1_0.5", "'_' digit separators"),
        (5, "antenna", "\uff13", "U+FF13"),
        (7, "antenna", str(2**63), "64-bit"),
        (9, "frequency_hz", "915.25", "looks like MHz: multiply by 1e6"),
        (11, "phase_rad", "300.5", "looks like degrees: multiply by pi/180"),
        (12, "epc", "b'E200'", "bytes literal"),
    ],
)
def test_malformed_reads_exit_2_naming_line_and_column(capsys, tmp_path, row, column, value, fragment):
    code, out, err = track(capsys, tmp_path, with_cell(reads_rows(), row, COLUMN_INDEX[column], value))
    # rows[0] is on line 2, after the header.
    assert_rejected(code, out, err, f"{tmp_path / 'reads.csv'}:{row + 2}:", f"column '{column}'", fragment)


def test_scene_antenna_id_beyond_int64(capsys, tmp_path):
    code, out, err = track(capsys, tmp_path, reads_rows(), first_id=str(2**63))
    assert_rejected(code, out, err, "scene.toml:8:", "column 'antennas[0].id'", "64-bit")


def test_clock_jump_is_a_warning_line_and_tracking_goes_on(capsys, tmp_path):
    rows = reads_rows(20, start_s=30.0) + reads_rows(20, start_s=10.0)  # line 22 jumps back 20 s
    code, out, err = track(capsys, tmp_path, rows)
    assert code == 0, err
    warnings = warning_lines(err)
    assert len(warnings) == 1 and f"{tmp_path / 'reads.csv'}:22: line 22, column 'time_s': clock jumps back" in warnings[0]
    assert "read 40 reads" in out


def test_warnings_come_before_the_last_error_line(capsys, tmp_path):
    rows = reads_rows(20, start_s=30.0) + reads_rows(20, start_s=10.0)
    rows[-1] = rows[-1].replace("E200", "E2G0")
    code, out, err = track(capsys, tmp_path, rows)
    assert_rejected(code, out, err, "reads.csv:41:", "column 'epc'", "not hex")


def test_accepted_variants_track(capsys, tmp_path):
    rows = [f'{r},"note, quoted",' for r in reads_rows()]
    rows[0] = rows[0].replace("0.000000", "1.7e9", 1)  # an epoch time first: the clock then jumps back
    rows = ["\ufeff" + HEADER + ",note,rssi_dbm"] + [r.replace("0.000000", "0") for r in rows]
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.format(first_id="1"))
    reads = tmp_path / "reads.csv"
    reads.write_bytes("\r\n".join(rows).encode() + b"\r\n")
    code, out, err = run(capsys, "track", "--scene", scene, "--reads", reads, "--out", tmp_path / "t.csv")
    assert code == 0, err
    assert "read 30 reads" in out and "clock jumps back" in err


@pytest.mark.skipif(not (OUTSIDE / "cots-2d-planar").is_dir(), reason="shared outside cases not found")
def test_outside_planar_scene_tracks(capsys, tmp_path):
    case = OUTSIDE / "cots-2d-planar"
    code, out, err = run(capsys, "track", "--scene", case / "scene.toml", "--reads", case / "reads.csv",
                         "--out", tmp_path / "track.csv", "--no-progress")
    assert code == 0, err
    assert "warning:" not in err
    code, out, err = run(capsys, "eval", "--truth", case / "truth.csv", "--track", tmp_path / "track.csv",
                         "--out", tmp_path)
    assert code == 0, err


def test_eval_of_an_empty_track(capsys, tmp_path):
    truth = tmp_path / "truth.csv"
    truth.write_text("time_s,epc,x,y,z\n" + "".join(f"{0.01 * i:.2f},E200,0,0,0\n" for i in range(10)))
    empty = tmp_path / "track.csv"
    empty.write_text("time_s,epc,x,y,z,vx,vy,vz\n")
    code, out, err = run(capsys, "eval", "--truth", truth, "--track", empty, "--out", tmp_path,
                         "--json", tmp_path / "report.json")
    assert code == 0, err
    assert "no estimates: the track has no rows" in out
    assert "tags with truth but no track: E200" in out
    assert (tmp_path / "report.json").is_file()


def test_eval_warns_for_sparse_truth(capsys, tmp_path):
    truth = tmp_path / "truth.csv"
    truth.write_text("time_s,epc,x,y,z\n" + "".join(f"{0.1 * i:.1f},E200,0,0,0\n" for i in range(10)))
    track_file = tmp_path / "track.csv"
    track_file.write_text("time_s,epc,x,y,z,vx,vy,vz\n0.5,E200,0,0,0,nan,nan,nan\n")
    code, out, err = run(capsys, "eval", "--truth", truth, "--track", track_file, "--out", tmp_path)
    assert code == 0, err
    assert err.startswith(f"warning: {truth}:2: line 2, column 'time_s': truth of tag 'E200' is sampled at 10 Hz")


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["simulate", "--scenario", "glac-2d-10cms", "--out", "OUT", "--duration", "-1"], "--duration must be > 0"),
        (["simulate", "--scenario", "glac-2d-10cms", "--out", "OUT", "--duration", "nan"], "--duration must be > 0"),
        (["simulate", "--scenario", "glac-2d-10cms", "--out", "OUT", "--duration", "inf"], "--duration must be > 0"),
        (["simulate", "--scenario", "glac-2d-10cms", "--out", "OUT", "--seed", "-5"], "--seed must be an integer from 0"),
        (["demo", "--out", "OUT", "--seed", str(2**63)], "--seed must be an integer from 0"),
        (["stream", "--scene", "S", "--sigmf", "R", "--out", "OUT", "--speed", "0"], "--speed must be > 0"),
        (["stream", "--scene", "S", "--sigmf", "R", "--out", "OUT", "--speed", "inf"], "--speed must be > 0"),
        (["stream", "--scene", "S", "--sigmf", "R", "--out", "OUT", "--workers", "0"], "--workers must be from 1"),
        (["stream", "--scene", "S", "--sigmf", "R", "--out", "OUT", "--prewake-us", "-1"], "--prewake-us must be in"),
        (["stream", "--scene", "S", "--sigmf", "R", "--out", "OUT", "--ema-alpha", "1.5"], "--ema-alpha must be in (0, 1]"),
        (["stream", "--scene", "S", "--sigmf", "R", "--out", "OUT", "--ema-alpha", "0"], "--ema-alpha must be in (0, 1]"),
        (["eval", "--truth", "T", "--track", "K", "--threshold-m", "0"], "--threshold-m must be > 0"),
        (["eval", "--truth", "T", "--track", "K", "--threshold-m=-inf"], "--threshold-m must be > 0"),
    ],
)
def test_option_ranges(capsys, tmp_path, argv, fragment):
    argv = [str(tmp_path / "out") if a == "OUT" else a for a in argv]
    code, out, err = run(capsys, *argv)
    assert_rejected(code, out, err, fragment)
    assert err.count("\n") == 1  # one line
    assert not (tmp_path / "out").exists()  # refused before anything ran
