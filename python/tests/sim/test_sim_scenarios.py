"""Named scenarios, the scenario schema and the output folder."""

import json

import numpy as np
import pytest

from scattertrack.io.types import FormatError
from scattertrack.sim import SCENARIOS_DIR, list_scenarios, load_scenario, simulate, write_simulation
from scattertrack.sim.trajectory import positions_velocities

REQUIRED = [
    "glac-2d-10cms",
    "glac-2d-40cms",
    "glac-3d-arm",
    "glac-2d-40cms-hopping",
    "glac-3d-arm-hopping",
    "glac-2d-40cms-negsign",
    "glac-2d-40cms-modpi",
    "glac-3d-arm-5tags",
    "glac-3d-random",
    "glac-2d-line-10cms",
    "glac-2d-circle-40cms",
    "realistic-3d-arm",
]


def test_required_scenarios_are_shipped():
    assert set(REQUIRED) <= set(list_scenarios())


@pytest.mark.parametrize("name", list_scenarios())
def test_every_scenario_loads_and_simulates(name):
    scenario = load_scenario(name)
    assert scenario["name"] == name
    assert scenario["description"]
    sim = simulate(scenario | {"duration_s": 2.0})
    assert len(sim.reads) > 20
    assert set(np.unique(sim.reads.antenna)) <= {a.id for a in sim.scene.antennas}
    assert sim.reads.time_s.max() < 2.0
    assert set(sim.reads.epcs()) == {tag["epc"] for tag in scenario["tags"]}
    assert np.all(sim.reads.phase_rad >= 0.0) and np.all(sim.reads.phase_rad < sim.scene.reader.period_rad)


@pytest.mark.parametrize("name", list_scenarios())
def test_scenario_tracks_respect_the_glac_geometry(name):
    scenario = load_scenario(name)
    scene = scenario["scene"]
    antennas = np.array([a["position"] for a in scene["antennas"]])
    times = np.linspace(0.0, scenario["duration_s"], 4001)
    low, high = np.array(scene["region"]["min"]), np.array(scene["region"]["max"])
    for tag in scenario["tags"]:
        trajectory = dict(tag["trajectory"])
        position, velocity = positions_velocities(trajectory, times)
        assert np.all(position >= low) and np.all(position <= high), "leaves the region"
        distance = np.linalg.norm(position[:, None] - antennas[None], axis=2)
        assert distance.min() >= 0.25
        if trajectory["kind"] == "static" or name.startswith("calibration-"):
            continue  # reference tags (calibration-room) and sweeps (calibration-wall): anywhere in the room
        speed = np.linalg.norm(velocity, axis=1)
        if scene["dimensions"] == 2:
            assert np.all(position[:, 2] == scene["plane_z"])
            assert np.all(position[:, 0] >= 0.25) and np.all(position[:, 0] <= 1.3)
            assert np.all(position[:, 1] >= -0.2) and np.all(position[:, 1] <= 1.2)
            expected = 0.10 if "10cms" in name else 0.40
            assert speed.max() == pytest.approx(expected, rel=1e-6)
        else:
            assert np.all(position[:, 2] >= 0.4) and np.all(position[:, 2] <= 0.9)
            assert np.all(position[:, 0] >= 0.2) and np.all(position[:, 0] <= 0.8)
            assert np.all(position[:, 1] >= 0.1) and np.all(position[:, 1] <= 0.7)
            assert 0.1 <= speed.max() <= 0.45


def test_scenario_variants_have_their_impairments():
    def model(name):
        return simulate(load_scenario(name) | {"duration_s": 2.0})

    hopping = model("glac-2d-40cms-hopping")
    assert len(hopping.scene.channel_offsets) == 50
    assert model("glac-2d-40cms-negsign").scene.reader.phase_sign == -1
    assert model("glac-2d-40cms-modpi").scene.reader.phase_period == "pi"
    realistic = model("realistic-3d-arm")
    resolved = realistic.scenario["reader_model"]
    assert resolved["phase_step_units"] == 4 and resolved["outlier_probability"] == 0.005
    assert len(resolved["reflectors"]) == 1 and resolved["hopping"]
    assert resolved["white_noise_rad"] == 0.015 and resolved["wander_rad"] == 0.07
    paper = model("glac-2d-10cms").scenario["reader_model"]
    assert paper["white_noise_rad"] == 0.1 and paper["wander_rad"] == 0.0 and not paper["hopping"]
    assert paper["frequency_hz"] == 915.25e6


def test_five_tags_get_fewer_reads_each():
    one = simulate(load_scenario("glac-3d-arm"))
    five = simulate(load_scenario("glac-3d-arm-5tags"))
    one_rate = len(one.reads) / 20.0
    assert 24.0 <= one_rate <= 36.0
    for epc in five.reads.epcs():
        rate = np.sum(five.reads.epc == epc) / 20.0
        assert 13.0 <= rate <= 0.7 * one_rate


def test_simulation_output_folder(tmp_path):
    sim = simulate(load_scenario("glac-2d-40cms-hopping") | {"duration_s": 3.0}, seed=42)
    out = write_simulation(sim, tmp_path / "run")
    for name in ("scene.toml", "reads.csv", "truth.csv", "simulation.json"):
        assert (out / name).is_file()
    record = json.loads((out / "simulation.json").read_text())
    assert record["seed"] == 42 and record["scenario"]["seed"] == 42
    assert record["version"]
    assert record["scenario"]["reader_model"]["hopping"] is True
    # Replaying the recorded scenario gives the same reads.
    again = simulate(record["scenario"])
    np.testing.assert_array_equal(again.reads.phase_rad, sim.reads.phase_rad)

    from scattertrack.io import read_reads, read_scene, read_truth

    scene = read_scene(out / "scene.toml")
    assert scene.dimensions == 2 and scene.plane_z == 0.0
    assert len(scene.channel_offsets) == 50
    reads = read_reads(out / "reads.csv", scene)
    assert len(reads) == len(sim.reads) and reads.skipped.total == 0
    np.testing.assert_allclose(reads.phase_rad, sim.reads.phase_rad, atol=1e-6)
    np.testing.assert_allclose(reads.time_s, sim.reads.time_s, atol=1e-9)
    truth = read_truth(out / "truth.csv")
    assert len(truth) == len(sim.truth)
    np.testing.assert_allclose(truth.position, sim.truth.position, atol=1e-6)


def write_toml(tmp_path, text):
    path = tmp_path / "case.toml"
    path.write_text(text)
    return path


MINIMAL = """
name = "case"
duration_s = 1.0
[scene]
dimensions = 3
[[scene.antennas]]
id = 1
position = [0.0, 0.0, 0.0]
[[tags]]
epc = "E2000A01"
[tags.trajectory]
kind = "static"
position = [0.5, 0.5, 0.5]
"""


def test_minimal_scenario_file_by_path(tmp_path):
    path = write_toml(tmp_path, MINIMAL)
    scenario = load_scenario(path)
    assert scenario["source"] == str(path)
    sim = simulate(scenario)
    assert len(sim.reads) > 20 and np.all(sim.reads.antenna == 1)


@pytest.mark.parametrize(
    "text, key",
    [
        (MINIMAL + "[reader_model]\nwhite_noise = 0.1\n", "reader_model.white_noise"),
        (MINIMAL.replace('position = [0.5, 0.5, 0.5]', 'position = [0.5, 0.5]'), "tags[0].trajectory"),
        (MINIMAL.replace('kind = "static"', 'kind = "spiral"'), "tags[0].trajectory.kind"),
        (MINIMAL.replace("dimensions = 3", "dimensions = 2"), "scene.plane_z"),
        (MINIMAL.replace('epc = "E2000A01"', 'epc = "tag one"'), "tags[0].epc"),
        (MINIMAL + "[reader_model]\nphase_step_units = 3\n", "reader_model.phase_step_units"),
        (MINIMAL + "[reader_model]\nmiss_probability = -0.1\n", "reader_model.miss_probability"),
        (MINIMAL + "[reader_model]\nantenna_order = [1, 7]\n", "reader_model.antenna_order[1]"),
    ],
)
def test_invalid_scenarios_name_file_and_key(tmp_path, text, key):
    path = write_toml(tmp_path, text)
    with pytest.raises(FormatError) as raised:
        load_scenario(path)
    assert raised.value.path == str(path)
    assert raised.value.column == key


def test_toml_syntax_error_and_unknown_name(tmp_path):
    path = write_toml(tmp_path, 'name = "x"\nduration_s = = 1\n')
    with pytest.raises(FormatError) as raised:
        load_scenario(path)
    assert raised.value.line == 2
    with pytest.raises(FormatError, match="glac-2d-10cms"):
        load_scenario("no-such-scenario")


def test_2d_trajectory_must_stay_in_the_plane(tmp_path):
    text = MINIMAL.replace("dimensions = 3", "dimensions = 2\nplane_z = 0.0")
    with pytest.raises(FormatError, match="plane"):
        load_scenario(write_toml(tmp_path, text))


def test_scenarios_dir_is_the_repository_folder():
    assert SCENARIOS_DIR.name == "scenarios" and (SCENARIOS_DIR / "glac-2d-10cms.toml").is_file()


# --- reflectors: the scene declares them, the reader model simulates them ----------------

SIMULATED_WALL = """
[[reader_model.reflectors]]
kind = "plane"
point = [2.0, 0.0, 0.0]
normal = [-1.0, 0.0, 0.0]
coefficient = 0.4
"""
DECLARED = """
[[scene.reflectors]]
kind = "plane"
point = [2.0, 0.0, 0.0]
normal = [-3.0, 0.0, 4.0]
coefficient = 0.4

[[scene.reflectors]]
kind = "point"
position = [1.0, 1.0, 0.0]
coefficient = -0.25
"""


def test_declared_reflectors_reach_scene_toml(tmp_path):
    from scattertrack.io import read_scene

    sim = simulate(load_scenario(write_toml(tmp_path, MINIMAL + DECLARED + SIMULATED_WALL)))
    out = write_simulation(sim, tmp_path / "run")
    scene = read_scene(out / "scene.toml")
    plane, point = scene.reflectors
    assert (plane.kind, plane.coefficient, point.kind, point.coefficient) == ("plane", 0.4, "point", -0.25)
    np.testing.assert_array_equal(plane.point, [2.0, 0.0, 0.0])
    np.testing.assert_allclose(plane.normal, [-0.6, 0.0, 0.8], rtol=0, atol=1e-15)  # written unit length
    np.testing.assert_array_equal(point.position, [1.0, 1.0, 0.0])
    assert "[[reflectors]]" in (out / "scene.toml").read_text()
    # The declaration tells the tracker only: the reads are those of the simulated wall alone.
    alone = simulate(load_scenario(write_toml(tmp_path, MINIMAL + SIMULATED_WALL)))
    np.testing.assert_array_equal(alone.reads.phase_rad, sim.reads.phase_rad)


def test_simulated_reflectors_stay_out_of_scene_toml(tmp_path):
    from scattertrack.io import read_scene

    sim = simulate(load_scenario(write_toml(tmp_path, MINIMAL + SIMULATED_WALL)))
    assert sim.scenario["reader_model"]["reflectors"] and sim.scene.reflectors == []
    out = write_simulation(sim, tmp_path / "run")
    assert read_scene(out / "scene.toml").reflectors == []
    assert "reflectors" not in (out / "scene.toml").read_text()


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("coefficient = -0.25", "coefficient = -1.5", "scene.reflectors[1].coefficient"),
        ("normal = [-3.0, 0.0, 4.0]", "normal = [0.0, 0.0, 0.0]", "scene.reflectors[0].normal"),
        ('kind = "point"', 'kind = "wall"', "scene.reflectors[1].kind"),
        ("position = [1.0, 1.0, 0.0]\n", "", "scene.reflectors[1].position"),
        ("coefficient = 0.4\n", "coefficient = 0.4\ncolour = 1\n", "scene.reflectors[0].colour"),
    ],
)
def test_invalid_declared_reflectors(tmp_path, old, new, key):
    assert DECLARED.count(old) == 1
    with pytest.raises(FormatError) as raised:
        load_scenario(write_toml(tmp_path, MINIMAL + DECLARED.replace(old, new)))
    assert raised.value.column == key


def test_only_glac_scenarios_declare_reflectors(tmp_path):
    text = """
name = "helper"
pipeline = "turbotrack"
[scene]
dimensions = 3
[[scene.reflectors]]
kind = "point"
position = [1.0, 1.0, 0.0]
coefficient = 0.5
"""
    with pytest.raises(FormatError, match="only COTS-reader") as raised:
        load_scenario(write_toml(tmp_path, text))
    assert raised.value.column == "scene.reflectors"
