"""``--param NAME=VALUE`` read by each method's table, and ``scattertrack methods``."""

from pathlib import Path

import pytest

from scattertrack import cli
from scattertrack.cli import main
from scattertrack.track import REGISTRY

from cli_runs import run


def assert_one_line_error(code: int, out: str, err: str, *fragments: str) -> None:
    assert code == 2
    assert err.startswith("scattertrack: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err + out
    for fragment in fragments:
        assert fragment in err, (fragment, err)


@pytest.mark.parametrize(
    "method, source, param, fragments",
    [
        ("glac", ["--reads", "r.csv"], "max_hypotheses=-1", ("'max_hypotheses'", "an integer >= 1", "-1")),
        ("glac", ["--reads", "r.csv"], "quick_stop=1", ("'quick_stop'", "[0, 1)")),
        ("glac", ["--reads", "r.csv"], "max_hypothesis=5", ("unknown parameter 'max_hypothesis'", "did you mean max_hypotheses")),
        ("turbotrack", ["--frames", "f.csv"], "particles=many", ("'particles'", "'many'")),
        ("marvel", ["--features", "f.csv", "--imu", "i.csv"], "baro_sigma_m=abc", ("'baro_sigma_m'", "a float > 0", "'abc'")),
        ("marvel", ["--features", "f.csv", "--imu", "i.csv"], "use_baro=perhaps", ("'use_baro'", "true or false")),
        ("ulocate", ["--sigmf", "r.sigmf-meta", "--imu", "i.csv"], "use_bar=1", ("unknown parameter 'use_bar' for method 'ulocate'", "use_baro")),
    ],
)
def test_a_bad_parameter_is_one_error_line_before_any_input_is_read(capsys, tmp_path, method, source, param, fragments):
    # The files do not exist: the parameters are checked first.
    code, out, err = run(capsys, "track", "--method", method, "--scene", tmp_path / "scene.toml", *source,
                         "--out", tmp_path / "t.csv", "--param", param)
    assert_one_line_error(code, out, err, *fragments)


def test_stream_parameters_are_read_by_the_table(capsys, tmp_path):
    code, out, err = run(capsys, "stream", "--scene", tmp_path / "s.toml", "--sigmf", tmp_path / "r.sigmf-meta",
                         "--out", tmp_path / "t.csv", "--param", "resample_threshold=2")
    assert_one_line_error(code, out, err, "'resample_threshold'", "[0, 1]")


def test_values_are_typed_by_the_method_table():
    assert cli.tracker_parameters("marvel", [("use_baro", "false")]) == {"use_baro": False}
    assert cli.tracker_parameters("glac", [("manoeuvre_q", "none"), ("max_hypotheses", "500")]) == {
        "manoeuvre_q": None, "max_hypotheses": 500}
    assert cli.tracker_parameters("glac", None) == {}


@pytest.fixture(scope="module")
def glac_session(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("glac")
    assert main(["simulate", "--scenario", "glac-2d-10cms", "--out", str(folder), "--duration", "1"]) == 0
    return folder


def test_check_parameters_builds_one_tracker(capsys, glac_session, tmp_path, monkeypatch):
    from scattertrack import track

    calls = []
    real_make = track.make
    monkeypatch.setattr(track, "make", lambda *a, **k: calls.append(k) or real_make(*a, **k))
    # A combination no single row refuses: the tracker names the parameter.
    code, out, err = run(capsys, "track", "--scene", glac_session / "scene.toml", "--reads", glac_session / "reads.csv",
                         "--out", tmp_path / "t.csv", "--param", "likelihood=paper")
    assert_one_line_error(code, out, err, "likelihood", "manoeuvre_q")
    assert len(calls) == 1
    code, _, err = run(capsys, "track", "--scene", glac_session / "scene.toml", "--reads", glac_session / "reads.csv",
                       "--out", tmp_path / "t.csv", "--param", "likelihood=paper", "--param", "manoeuvre_q=none", "--no-progress")
    assert code == 0, err


def test_methods_lists_name_description_and_input(capsys):
    code, out, _ = run(capsys, "methods")
    assert code == 0
    lines = out.splitlines()
    assert [line.split()[0] for line in lines] == list(REGISTRY)
    for line, method in zip(lines, REGISTRY.values()):
        assert method.description in line and f"(input: {method.input_files})" in line


def test_methods_prints_one_table(capsys):
    code, out, _ = run(capsys, "methods", "--params", "glac")
    assert code == 0
    header, *rows = out.splitlines()
    assert header.split()[:5] == ["parameter", "type", "default", "range", "unit"]
    row = next(r for r in rows if r.startswith("max_hypotheses "))
    assert "integer" in row and "200000" in row and ">= 1" in row
    code, out, err = run(capsys, "methods", "--params", "marvel")
    assert code == 0 and any(r.startswith("use_baro ") and "true" in r for r in out.splitlines())
    code, out, err = run(capsys, "methods", "--params", "nope")
    assert_one_line_error(code, out, err, "unknown method 'nope'", "glac")
