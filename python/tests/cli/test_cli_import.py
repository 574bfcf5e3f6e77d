"""``scattertrack import``: reader logs to reads.csv through the command line."""

from pathlib import Path

import pytest

from scattertrack.io import read_reads, read_scene

from cli_runs import run

DATA = Path(__file__).resolve().parents[1] / "io" / "data"
SCENE = DATA / "import_scene.toml"


@pytest.mark.parametrize(
    "format, files, kept",
    [
        ("sllurp-csv", ["sllurp_log.csv"], 5),
        ("impinj-iot", ["impinj_iot.jsonl"], 3),
        ("iq-phasors", ["iq_phasors.csv"], 4),
    ],
)
def test_import_writes_reads_and_reports(capsys, tmp_path, format, files, kept):
    out = tmp_path / "reads.csv"
    code, stdout, stderr = run(capsys, "import", format, *[DATA / f for f in files], "--scene", SCENE, "--out", out)
    assert code == 0, stderr
    assert stdout.startswith("columns: ")
    assert f"kept {kept}," in stdout and f"wrote {kept} reads" in stdout
    assert len(read_reads(out, read_scene(SCENE))) == kept


def test_channel_plan_fallback_prints_one_warning_line(capsys, tmp_path):
    code, stdout, stderr = run(capsys, "import", "sllurp-csv", DATA / "sllurp_log.csv", "--scene", SCENE,
                               "--out", tmp_path / "reads.csv")
    assert code == 0
    assert [line for line in stderr.splitlines() if line.startswith("warning:")] == [
        line for line in stderr.splitlines() if "US channel plan" in line]
    assert stderr.count("warning:") == 1
    assert "frequencies: 5 from the US channel plan in index order" in stdout


def test_broken_file_exits_2_naming_file_and_line(capsys, tmp_path):
    log = tmp_path / "log.csv"
    log.write_text("timestamp,antenna,epc,phase_angle,channel_index\n1,1,E2,0,1\n1,1\n")
    code, stdout, stderr = run(capsys, "import", "sllurp-csv", log, "--scene", SCENE, "--out", tmp_path / "r.csv")
    assert code == 2
    assert stderr.strip().splitlines()[-1].startswith(f"scattertrack: error: {log}:3: line 3")
    assert not (tmp_path / "r.csv").exists()


def test_unknown_format_is_a_usage_error(capsys, tmp_path):
    code, _, stderr = run(capsys, "import", "octane-csv", DATA / "sllurp_log.csv", "--scene", SCENE, "--out", tmp_path / "r")
    assert code == 2 and "invalid choice" in stderr
