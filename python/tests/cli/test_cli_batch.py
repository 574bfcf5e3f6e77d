"""``scattertrack batch``: recordings on a Dask LocalCluster (loopback) give the
tracks a sequential run gives; a bad recording is reported, the others go on."""

from __future__ import annotations

import csv

import pytest

from scattertrack.cli import main
from scattertrack.sim import load_scenario, simulate
from scattertrack.sim.simulation import write_simulation


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    folder = tmp_path_factory.mktemp("recordings")
    paths = []
    for seed in (1, 2, 3):
        scenario = load_scenario("glac-3d-walls")
        scenario["duration_s"] = 4.0
        write_simulation(simulate(scenario, seed=seed), folder / f"walls-{seed}")
        paths.append(folder / f"walls-{seed}")
    bad = folder / "bad"
    bad.mkdir()
    (bad / "scene.toml").write_text((paths[0] / "scene.toml").read_text())
    (bad / "reads.csv").write_text("time_s,epc,antenna,frequency_hz,phase_rad\n0.1,E2000A01,1,915250000,abc\n")
    return paths, bad


def test_a_local_cluster_gives_the_sequential_tracks(recordings, tmp_path, capsys):
    paths, _ = recordings
    args = ["batch", *map(str, paths)]
    assert main([*args, "--out-dir", str(tmp_path / "dask"), "--workers", "2", "--summary", str(tmp_path / "summary.csv")]) == 0
    assert "Dask LocalCluster of 2 workers on 127.0.0.1" in capsys.readouterr().out
    assert main([*args, "--out-dir", str(tmp_path / "sequential"), "--sequential"]) == 0
    for path in paths:
        on_dask = (tmp_path / "dask" / path.name / "track.csv").read_text()
        assert on_dask == (tmp_path / "sequential" / path.name / "track.csv").read_text()
        assert len(on_dask.splitlines()) > 50
    rows = list(csv.DictReader(open(tmp_path / "summary.csv")))
    assert [r["recording"] for r in rows] == [str(p) for p in paths] and {r["status"] for r in rows} == {"ok"}


def test_a_malformed_recording_is_reported_and_the_others_are_tracked(recordings, tmp_path, capsys):
    paths, bad = recordings
    assert main(["batch", str(paths[0]), str(bad), "--out-dir", str(tmp_path), "--sequential", "--summary", str(tmp_path / "s.csv")]) == 1
    out = capsys.readouterr().out
    assert f"{bad}: error: " in out and "reads.csv" in out and "line 2" in out
    assert (tmp_path / paths[0].name / "track.csv").exists() and not (tmp_path / "bad").exists()
    rows = {r["recording"]: r for r in csv.DictReader(open(tmp_path / "s.csv"))}
    assert rows[str(bad)]["status"] == "error" and "line 2" in rows[str(bad)]["error"]


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--method", "turbotrack"], "batch tracks phase reads"),
        (["--workers", "2", "--sequential"], "not allowed with"),
    ],
)
def test_batch_options_are_checked(recordings, tmp_path, capsys, extra, message):
    paths, _ = recordings
    assert main(["batch", str(paths[0]), "--out-dir", str(tmp_path), *extra]) == 2
    assert message in capsys.readouterr().err


def test_a_folder_that_is_not_there_and_twin_names_are_refused(recordings, tmp_path, capsys):
    paths, _ = recordings
    assert main(["batch", str(paths[0]), str(tmp_path / "nothere"), "--out-dir", str(tmp_path)]) == 2
    assert "not a recording folder" in capsys.readouterr().err
    twin = tmp_path / "other" / paths[0].name
    twin.mkdir(parents=True)
    assert main(["batch", str(paths[0]), str(twin), "--out-dir", str(tmp_path)]) == 2
    assert "two recordings named" in capsys.readouterr().err
