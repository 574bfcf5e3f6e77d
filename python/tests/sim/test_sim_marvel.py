"""Marvel scenarios at the feature level (docs/marvel.md section 9): loading, determinism, files, noise."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from scattertrack.cli import main
from scattertrack.io import read_features, read_imu, read_scene, read_truth
from scattertrack.io.types import FormatError
from scattertrack.sim import list_scenarios, load_scenario, simulate, write_simulation
from scattertrack.sim.drone import flight
from scattertrack.sim.marvel import (
    FEATURE_MODEL_DEFAULTS,
    decode_threshold_db,
    dechirped_snr_db,
    direction_angles,
    resolve_feature_model,
    simulate_marvel,
)
from scattertrack.sim.rotation import wrap_angle

MARVEL = [
    "marvel-circle-20m",
    "marvel-distance",
    "marvel-hover",
    "marvel-liftoff-circle",
    "marvel-liftoff-circle-imu-late",
    "marvel-liftoff-circle-noisy-imu",
    "marvel-liftoff-square",
    "marvel-rail",
    "marvel-square-room",
    "marvel-square-walls",
    "marvel-turntable",
]

NOISELESS = {
    "shadowing_db": 0.0,
    "shadowing_per_wall_db": 0.0,
    "range_multipath_m": 0.0,
    "range_multipath_per_wall_m": 0.0,
    "angle_multipath_rad": 0.0,
    "angle_multipath_per_wall_rad": 0.0,
    "doppler_floor_hz": 0.0,
    "doppler_floor_per_wall_hz": 0.0,
    "snr_ceiling_db": 300.0,
    "tx_power_dbm": 250.0,
}
"""A feature model whose errors are all negligible (absurd power, no multipath)."""


def test_marvel_scenarios_are_listed_apart():
    assert list_scenarios("marvel") == MARVEL
    assert not set(MARVEL) & set(list_scenarios("glac"))
    assert not set(MARVEL) & set(list_scenarios("turbotrack"))
    assert set(MARVEL) <= set(list_scenarios("all"))


@pytest.mark.parametrize("name", MARVEL)
def test_every_marvel_scenario_loads_and_simulates(name):
    scenario = load_scenario(name)
    assert scenario["name"] == name and scenario["description"]
    sim = simulate(scenario)
    assert sim.pipeline == "marvel"
    assert sim.reads is None and sim.frames is None
    duration = scenario["duration_s"]
    dropped = sum(end - start for start, end in scenario.get("imu_model", {}).get("dropped_spans", []))
    assert len(sim.imu) == round((duration - dropped) * 100)
    assert len(sim.truth) == round(duration * 100)
    assert set(sim.truth.epc) == {"drone"}
    assert sim.truth.orientation.shape == (len(sim.truth), 4)
    np.testing.assert_array_equal(sim.imu.time_s, sim.truth.time_s[-len(sim.imu):])
    counts = sim.details["counts"]
    assert counts["rows"] + counts["rows_below_snr"] == counts["epochs"] == round(duration * 10)
    assert len(sim.features) == counts["rows"] > 0
    assert sim.details["controller_position_m"] == scenario["controller"]["position"]
    assert sim.scene.reader.kind == "lora-backscatter" and not sim.scene.antennas
    # Features follow the true geometry within a few sigmas.
    state = flight(sim.scenario["flight"], sim.features.time_s)
    distance, azimuth, elevation = direction_angles(state.position, scenario["controller"]["position"])
    assert np.all(np.abs(sim.features.range_m - distance) < 6 * sim.features.range_sigma_m + 0.2 * sim.details["walls"])
    azimuth_error = np.abs(wrap_angle(sim.features.azimuth_rad - azimuth)) * np.cos(elevation)
    assert np.all(azimuth_error < 6 * sim.features.angle_sigma_rad)
    assert np.all(np.abs(sim.features.elevation_rad - elevation) < 6 * sim.features.angle_sigma_rad)


def test_hover_and_rail_have_no_yaw_and_rotations_have_some():
    assert np.isnan(simulate(load_scenario("marvel-hover")).features.yaw_rad).all()
    assert np.isnan(simulate(load_scenario("marvel-rail")).features.yaw_rad).all()
    turntable = simulate(load_scenario("marvel-turntable")).features
    has_yaw = ~np.isnan(turntable.yaw_rad)
    assert has_yaw[turntable.time_s > 4.0].all()  # rotating at >= 0.2 rad/s after the spin-up
    assert not has_yaw[turntable.time_s < 3.0].any()  # at rest before it
    assert np.all(np.isnan(turntable.yaw_sigma_rad) == ~has_yaw)


def test_seeded_runs_are_identical_and_seeds_differ():
    scenario = load_scenario("marvel-square-walls") | {"duration_s": 20.0}
    a, b = simulate(scenario, seed=3), simulate(scenario, seed=3)
    for name in ("range_m", "azimuth_rad", "yaw_rad", "range_sigma_m"):
        np.testing.assert_array_equal(getattr(a.features, name), getattr(b.features, name))
    np.testing.assert_array_equal(a.imu.accel, b.imu.accel)
    assert a.details == b.details and a.seed == 3
    c = simulate(scenario, seed=4)
    assert not np.array_equal(a.imu.accel, c.imu.accel)
    assert simulate_marvel(scenario, seed=3).details == a.details


def test_noiseless_features_are_the_true_geometry():
    scenario = load_scenario("marvel-circle-20m") | {"feature_model": NOISELESS, "duration_s": 30.0}
    sim = simulate(scenario)
    features = sim.features
    assert len(features) == 300
    state = flight(sim.scenario["flight"], features.time_s)
    rho = np.array(scenario["controller"]["position"])
    delta = state.position - rho
    np.testing.assert_allclose(features.range_m, np.linalg.norm(delta, axis=1), atol=1e-9)
    u = np.stack([
        np.cos(features.elevation_rad) * np.cos(features.azimuth_rad),
        np.cos(features.elevation_rad) * np.sin(features.azimuth_rad),
        np.sin(features.elevation_rad),
    ], axis=1)
    np.testing.assert_allclose(u, delta / np.linalg.norm(delta, axis=1, keepdims=True), atol=1e-9)
    has_yaw = ~np.isnan(features.yaw_rad)
    assert has_yaw.sum() > 200
    np.testing.assert_allclose(wrap_angle(features.yaw_rad[has_yaw] - state.yaw[has_yaw]), 0.0, atol=1e-6)
    assert features.time_s[0] == pytest.approx(0.05) and np.allclose(np.diff(features.time_s), 0.1)


def test_rows_below_the_decoding_snr_are_counted():
    base = load_scenario("marvel-distance")
    far = simulate(base | {"controller": {"position": [2.0, -90.0, 1.0]}})
    assert far.details["counts"]["rows_below_snr"] == far.details["counts"]["epochs"] == 200
    assert len(far.features) == 0
    four_walls = simulate(base | {"controller": {"position": [2.0, -10.0, 1.0], "walls": 4}})
    assert four_walls.details["counts"]["rows_below_snr"] > 120  # the paper's link does not pass 4 walls
    three_walls = simulate(base | {"controller": {"position": [2.0, -10.0, 1.0], "walls": 3}})
    assert three_walls.details["counts"]["rows_below_snr"] < 20
    near = simulate(base | {"controller": {"position": [2.0, -5.0, 1.0]}})
    assert near.details["counts"]["rows_below_snr"] == 0


def test_link_budget_limits_match_the_paper():
    model = resolve_feature_model()
    threshold = decode_threshold_db(model)
    assert threshold == pytest.approx(-20.0 + 10 * math.log10(4096))
    # Open field: decodes at 50 m, not at 60 m (paper sec. V-B: "works at most 50 m").
    assert dechirped_snr_db(50.0, 0, model) > threshold > dechirped_snr_db(60.0, 0, model)
    # Three brick walls at 10 m pass, four do not (paper: "more than three walls" fail).
    assert dechirped_snr_db(10.0, 3, model) > threshold > dechirped_snr_db(10.0, 4, model)


def test_reported_sigmas_describe_the_errors():
    # On the rail at 3 m/s the multipath errors decorrelate within a few epochs.
    scenario = load_scenario("marvel-distance") | {"duration_s": 300.0}
    sim = simulate(scenario)
    f = sim.features
    state = flight(sim.scenario["flight"], f.time_s)
    distance, azimuth, elevation = direction_angles(state.position, scenario["controller"]["position"])
    range_z = (f.range_m - distance) / f.range_sigma_m
    az_z = wrap_angle(f.azimuth_rad - azimuth) * np.cos(elevation) / f.angle_sigma_rad
    el_z = (f.elevation_rad - elevation) / f.angle_sigma_rad
    for z in (range_z, az_z, el_z):
        assert 0.8 < z.std() < 1.2
        assert abs(z.mean()) < 0.3


def test_written_files_read_back(tmp_path):
    sim = simulate(load_scenario("marvel-square-walls") | {"duration_s": 15.0})
    out = write_simulation(sim, tmp_path / "run")
    assert sorted(p.name for p in out.iterdir()) == [
        "features.csv", "imu.csv", "scene.toml", "simulation.json", "truth.csv",
    ]
    scene = read_scene(out / "scene.toml")
    assert scene.reader.kind == "lora-backscatter" and scene.antennas == []
    np.testing.assert_allclose(scene.region.min, [-2.0, -2.0, -0.5])
    imu = read_imu(out / "imu.csv")
    np.testing.assert_allclose(imu.accel, sim.imu.accel, atol=1e-6)
    np.testing.assert_allclose(imu.gyro, sim.imu.gyro, atol=1e-8)
    np.testing.assert_allclose(imu.baro_z, sim.imu.baro_z, atol=1e-4)
    assert imu.skipped.total == 0 and imu.gaps == 0
    features = read_features(out / "features.csv")
    np.testing.assert_allclose(features.range_m, sim.features.range_m, atol=1e-6)
    np.testing.assert_allclose(features.azimuth_rad, sim.features.azimuth_rad, atol=1e-8)
    np.testing.assert_array_equal(np.isnan(features.yaw_rad), np.isnan(sim.features.yaw_rad))
    truth = read_truth(out / "truth.csv")
    np.testing.assert_allclose(truth.orientation, sim.truth.orientation, atol=1e-6)
    record = json.loads((out / "simulation.json").read_text())
    assert record["details"]["controller_position_m"] == [4.0, -5.0, 1.0]
    assert record["details"]["walls"] == 3
    assert record["scenario"]["pipeline"] == "marvel"
    assert "controller" not in (out / "scene.toml").read_text()


def test_cli_simulates_a_marvel_scenario(tmp_path, capsys):
    assert main(["simulate", "--scenario", "marvel-hover", "--out", str(tmp_path), "--duration", "5"]) == 0
    assert "feature row" in capsys.readouterr().out
    assert len(read_features(tmp_path / "features.csv")) == 50
    assert main(["simulate", "--scenario", "marvel-hover", "--out", str(tmp_path), "--pipeline", "glac"]) != 0


@pytest.mark.parametrize(
    "change, key",
    [
        ({"controller": None}, "controller"),
        ({"controller": {"walls": 1}}, "controller.position"),
        ({"controller": {"position": [0.0, 5.0, 1.0]}}, "controller.position"),  # drone behind the array
        ({"controller": {"position": [0.0, -5.0, 1.0], "walls": -1}}, "controller.walls"),
        ({"flight": {"kind": "hover", "speed": 1.0}}, "flight.speed"),
        ({"flight": {"kind": "circle", "radius": 3.0, "speed": 5.0}}, "flight.speed"),
        ({"imu_model": {"accel_noise": 1.0}}, "imu_model.accel_noise"),
        ({"feature_model": {"rate_hz": 0.0}}, "feature_model.rate_hz"),
        ({"reader_model": {}}, "reader_model"),
        ({"tags": []}, "tags"),
    ],
)
def test_invalid_marvel_scenarios_name_the_key(change, key):
    scenario = load_scenario("marvel-hover") | change
    scenario = {k: v for k, v in scenario.items() if v is not None}
    with pytest.raises(FormatError) as error:
        simulate(scenario)
    assert error.value.column == key
    assert "marvel-hover.toml" in str(error.value)


def test_feature_model_defaults_are_documented():
    doc = (Path(__file__).resolve().parents[3] / "docs" / "marvel.md").read_text()
    section = doc[doc.index("## 9. Simulator"):]
    for key in FEATURE_MODEL_DEFAULTS:
        assert re.search(rf"\b{key}\b", section), key
