"""``scattertrack calibrate`` end to end on a simulated room, and its refusals."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from scattertrack.eval import compare
from scattertrack.io import read_scene, read_track
from scattertrack.sim import load_scenario, simulate, write_simulation

from cli_runs import run

REFERENCES = {"E2000C00": "0.3,0.3,0.4", "E2000C01": "3.0,3.0,1.2", "E2000C02": "0.5,3.5,0.3", "E2000C03": "3.5,0.5,1.0"}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    scenario = copy.deepcopy(load_scenario("glac-3d-walls"))
    scenario["duration_s"] = 40.0
    scenario["reader_model"].update({"hopping": True})
    scenario["reader_model"].pop("frequency_hz", None)
    scenario["tags"] = [{"epc": e, "trajectory": {"kind": "static", "position": [float(v) for v in p.split(",")]}} for e, p in REFERENCES.items()]
    folder = tmp_path_factory.mktemp("room")
    write_simulation(simulate(scenario, seed=11), folder)
    return folder


def test_calibrate_writes_a_scene_that_states_what_it_calibrated(capsys, recorded, tmp_path):
    refs = [f"{e}={p}" for e, p in REFERENCES.items()]
    code, out, err = run(capsys, "calibrate", "--scene", recorded / "scene.toml", "--reads", recorded / "reads.csv", "--reference", *refs[:2], "--reference", *refs[2:], "--out", tmp_path / "calibrated.toml")
    assert code == 0, err
    assert "of 4 reference tags" in out and "phase is usable here" in out and "50 channels calibrated" in out
    assert "RSSI antenna 1:" in out and not err
    truth_scene = read_scene(recorded / "scene.toml")
    scene = read_scene(tmp_path / "calibrated.toml")
    assert scene.reader.phase_sign == truth_scene.reader.phase_sign and len(scene.channel_offsets) == 50
    table = scene.extra["calibration"]
    assert table["references"] == 4 and table["phase_usable"] is True and "channel_offsets" in table["calibrated"]
    sums = [
        np.angle(np.exp(1j * (a.phase_offset_rad + c.phase_offset_rad - b.phase_offset_rad - d.phase_offset_rad)))
        for a, b in zip(scene.antennas, truth_scene.antennas)
        for c, d in zip(scene.channel_offsets, truth_scene.channel_offsets)
    ]
    assert np.abs(sums).max() < 0.08


def test_calibrate_refuses_what_it_cannot_use(capsys, recorded, tmp_path):
    base = ["calibrate", "--scene", recorded / "scene.toml", "--reads", recorded / "reads.csv", "--out", tmp_path / "c.toml"]
    code, _, err = run(capsys, *base)
    assert code == 2 and "give the reference tags" in err
    code, _, err = run(capsys, *base, "--reference", "E2000C00=0.3,0.3")
    assert code == 2 and "EPC=x,y,z" in err
    code, _, err = run(capsys, *base, "--reference", "E2000C00=0.3,0.3,nan")
    assert code == 2 and "finite" in err
    code, _, err = run(capsys, *base, "--reference", "FFFF=1,1,1")
    assert code == 2 and "no read belongs to a reference tag" in err and "no reads of reference FFFF" in err
    assert not (tmp_path / "c.toml").exists()


@pytest.fixture(scope="module")
def walled_sweep(tmp_path_factory) -> Path:
    """A reference swept through glac-3d-bay's region in front of a wall the scene declares 4 cm off."""
    scenario = copy.deepcopy(load_scenario("glac-3d-bay"))
    scenario["duration_s"] = 40.0
    scenario["reader_model"]["reflectors"] = [{"kind": "plane", "point": [1.6, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0], "coefficient": 0.3}]
    scenario["scene"]["reflectors"] = [{"kind": "plane", "point": [1.56, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0], "coefficient": 0.5}]
    region = scenario["scene"]["region"]
    scenario["tags"] = [{"epc": "CA11B000", "trajectory": {"kind": "random", "box_min": region["min"], "box_max": region["max"], "mean_speed": 0.2}}]
    folder = tmp_path_factory.mktemp("walled")
    write_simulation(simulate(scenario, seed=3), folder)
    return folder


def test_calibrate_refines_the_declared_wall_and_track_stops_warning(capsys, walled_sweep, tmp_path):
    scene, reads = walled_sweep / "scene.toml", walled_sweep / "reads.csv"
    code, out, err = run(capsys, "track", "--scene", scene, "--reads", reads, "--out", tmp_path / "t.csv")
    assert code == 0 and "warning: the scene declares 1 reflector that scattertrack calibrate has not refined" in out + err
    code, out, err = run(capsys, "check-scene", scene)
    assert code == 0 and "has not refined" in out + err
    code, out, err = run(capsys, "locate", "--scene", scene, "--reads", reads, "--out", tmp_path / "p.csv")
    assert code == 0 and "has not refined" in out + err and "the phase model includes the scene's 1 reflector" in out + err
    code, out, err = run(capsys, "calibrate", "--scene", scene, "--reads", reads, "--truth", walled_sweep / "truth.csv", "--out", tmp_path / "c.toml")
    assert code == 0, err
    assert "reflector 0 (plane): moved -4.0 cm along its normal" in out and ": kept" in out, out
    calibrated = read_scene(tmp_path / "c.toml")
    assert abs(calibrated.reflectors[0].point[0] - 1.6) < 0.003
    code, out, err = run(capsys, "track", "--scene", tmp_path / "c.toml", "--reads", reads, "--out", tmp_path / "t2.csv")
    assert code == 0 and "has not refined" not in out + err and "does not model" not in out + err
    code, out, err = run(capsys, "track", "--method", "trilateration-ekf", "--scene", tmp_path / "c.toml", "--reads", reads, "--out", tmp_path / "t3.csv")
    assert code == 0 and "warning: trilateration-ekf does not model the scene's 1 reflector" in out + err
    code, out, err = run(capsys, "locate", "--scene", tmp_path / "c.toml", "--reads", reads, "--out", tmp_path / "p2.csv")
    assert code == 0 and "has not refined" not in out + err and "the phase model includes" in out + err


def test_calibrate_checks_the_reflector_search(capsys, walled_sweep, tmp_path):
    base = ["calibrate", "--scene", walled_sweep / "scene.toml", "--reads", walled_sweep / "reads.csv", "--truth", walled_sweep / "truth.csv", "--out", tmp_path / "c.toml"]
    code, out, err = run(capsys, *base, "--reflector-search-m", "5")
    assert code == 2 and "Traceback" not in err and "--reflector-search-m: must be between 0.01 and 2 m" in err.splitlines()[-1]
    code, out, err = run(capsys, *base, "--reflector-search-m", "0.01")
    assert code == 0 and "LEFT OUT" in out and "warning:" in err and "widen --reflector-search-m" in err, (out, err)
    assert read_scene(tmp_path / "c.toml").reflectors == []


def test_calibrate_finds_a_wall_nobody_declared(capsys, walled_sweep, tmp_path):
    scene = read_scene(walled_sweep / "scene.toml")
    scene.reflectors = []
    scene.save(tmp_path / "bare.toml")
    base = ["calibrate", "--scene", tmp_path / "bare.toml", "--reads", walled_sweep / "reads.csv", "--truth", walled_sweep / "truth.csv", "--out", tmp_path / "c.toml"]
    code, out, err = run(capsys, *base, "--find-walls", "--wall-reach-m", "0.5")
    assert code == 0, err
    assert "wall found: the plane x = 1.60" in out, out
    assert abs(read_scene(tmp_path / "c.toml").reflectors[0].point[0] - 1.6) < 0.003
    code, out, err = run(capsys, *base, "--wall-reach-m", "0.5")
    assert code == 2 and "--wall-reach-m goes with --find-walls" in err
    code, out, err = run(capsys, *base, "--find-walls", "--wall-reach-m", "9")
    assert code == 2 and "--wall-reach-m: must be between 0.1 and 5 m" in err


def test_the_wall_calibration_scenario_calibrates_the_realistic_arms_room(capsys, tmp_path):
    # docs/calibration.md's walk-through, shortened: the sweep and the arm share seed 12 (the same offsets).
    sweep = load_scenario("calibration-wall") | {"duration_s": 40.0}
    write_simulation(simulate(sweep), tmp_path / "sweep")
    arm = simulate(load_scenario("realistic-3d-arm") | {"duration_s": 12.0})
    write_simulation(arm, tmp_path / "arm")
    code, out, err = run(capsys, "calibrate", "--scene", tmp_path / "sweep" / "scene.toml", "--reads", tmp_path / "sweep" / "reads.csv",
                         "--truth", tmp_path / "sweep" / "truth.csv", "--out", tmp_path / "calibrated.toml")
    assert code == 0 and ": kept" in out, (out, err)
    assert abs(read_scene(tmp_path / "calibrated.toml").reflectors[0].point[0] - 1.6) < 0.003
    medians = []
    for scene in (tmp_path / "arm" / "scene.toml", tmp_path / "calibrated.toml"):
        code, out, err = run(capsys, "track", "--scene", scene, "--reads", tmp_path / "arm" / "reads.csv", "--out", tmp_path / "t.csv")
        assert code == 0, err
        medians.append(compare(arm.truth, read_track(tmp_path / "t.csv")).overall.median_3d_m)
    assert medians[1] < 0.008 and medians[1] < medians[0], medians
