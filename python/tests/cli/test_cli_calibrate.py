"""``scattertrack calibrate`` end to end on a simulated room, and its refusals."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from scattertrack.io import read_scene
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
