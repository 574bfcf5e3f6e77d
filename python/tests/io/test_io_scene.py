"""scene.toml: round trips, the shared examples, and one test per malformed input."""

import math

import numpy as np
import pytest

from scattertrack.io import (
    Antenna,
    ChannelOffset,
    FormatError,
    Reader,
    Reflector,
    Region,
    Scene,
    read_scene,
    write_scene,
)

GOOD = """\
name = "four-antennas"
dimensions = 3

[reader]
kind = "cots"
phase_sign = -1

[[antennas]]
id = 1
position = [0.0, 0.0, 0.0]

[[antennas]]
id = 2
position = [0.0, 0.3, 0.0]

[[antennas]]
id = 3
position = [0.0, 0.8, 0.0]
"""


def assert_scenes_equal(a: Scene, b: Scene) -> None:
    assert a.name == b.name
    assert a.dimensions == b.dimensions
    assert a.plane_z == b.plane_z
    assert a.reader == b.reader
    assert len(a.antennas) == len(b.antennas)
    for x, y in zip(a.antennas, b.antennas):
        assert (x.id, x.phase_offset_rad, x.role) == (y.id, y.phase_offset_rad, y.role)
        np.testing.assert_array_equal(x.position, y.position)
    assert (a.region is None) == (b.region is None)
    if a.region is not None:
        np.testing.assert_array_equal(a.region.min, b.region.min)
        np.testing.assert_array_equal(a.region.max, b.region.max)
    assert a.channel_offsets == b.channel_offsets
    assert a.extra == b.extra
    assert len(a.reflectors) == len(b.reflectors)
    for x, y in zip(a.reflectors, b.reflectors):
        assert (x.kind, x.coefficient) == (y.kind, y.coefficient)
        for key in ("point", "normal", "position"):
            assert (getattr(x, key) is None) == (getattr(y, key) is None)
            if getattr(x, key) is not None:
                np.testing.assert_array_equal(getattr(x, key), getattr(y, key))


def full_scene() -> Scene:
    return Scene(
        name='lab "B" \\ corner',
        dimensions=2,
        plane_z=0.1234567890123,
        reader=Reader(kind="cots", phase_sign=-1, phase_period="pi", phase_noise_rad=0.1),
        antennas=[
            Antenna(1, np.array([0.0, 0.1, 1 / 3]), phase_offset_rad=3.675808554136233),
            Antenna(7, np.array([-1e-5, 2.5, 1e16]), phase_offset_rad=0.0, role="tx"),
            Antenna(8, np.array([1.0, 2.0, 3.0]), phase_offset_rad=-0.5, role="rx"),
        ],
        region=Region(np.array([-1.0, -1.0, 0.0]), np.array([2.0, 2.0, 2.0])),
        channel_offsets=[ChannelOffset(902.75e6, 1.234), ChannelOffset(927.25e6, -0.1)],
        reflectors=[
            Reflector("plane", -0.7, point=np.array([10.0, 0.0, 0.0]), normal=np.array([-0.6, -0.8, 0.0])),
            Reflector("point", 1 / 3, position=np.array([0.5, 1e-7, 2.0])),
        ],
        extra={
            "site": "bench 3",
            "temperatures": [20.5, 21],
            "calibration": {"date": "2024-05-01", "operator": "ana", "nested": {"a": 1}},
        },
    )


def test_round_trip_full_scene(tmp_path):
    scene = full_scene()
    write_scene(tmp_path / "scene.toml", scene)
    again = read_scene(tmp_path / "scene.toml")
    assert_scenes_equal(scene, again)
    # Writing what was read gives the same text: nothing drifts.
    write_scene(tmp_path / "again.toml", again)
    assert (tmp_path / "again.toml").read_text() == (tmp_path / "scene.toml").read_text()


def test_round_trip_minimal_scene_and_methods(tmp_path):
    scene = Scene("lora", 3, Reader(kind="lora-backscatter"), antennas=[])
    scene.save(tmp_path / "scene.toml")
    assert_scenes_equal(scene, Scene.load(tmp_path / "scene.toml"))


def test_defaults_and_unknown_keys(write_file):
    text = GOOD.replace('name = "four-antennas"', 'name = "x"\nowner = "lab"')
    text += '[notes]\ntext = "hi"\n'
    scene = read_scene(write_file("scene.toml", text))
    assert scene.reader == Reader("cots", -1, "2pi", None)
    assert [a.id for a in scene.antennas] == [1, 2, 3]
    assert scene.antennas[0].role == "txrx"
    assert scene.antennas[0].phase_offset_rad == 0.0
    assert scene.region is None and scene.channel_offsets == [] and scene.plane_z is None
    assert scene.extra == {"owner": "lab", "notes": {"text": "hi"}}


def test_integer_positions_and_byte_order_mark(write_file):
    text = "\ufeff" + GOOD.replace("[0.0, 0.3, 0.0]", "[0, 1, 2]")
    scene = read_scene(write_file("scene.toml", text))
    assert scene.antennas[1].position.dtype == np.float64
    np.testing.assert_array_equal(scene.antennas[1].position, [0.0, 1.0, 2.0])


def test_examples_load(examples):
    cots = read_scene(examples / "cots-3d-arm" / "scene.toml")
    assert cots.reader.kind == "cots" and cots.reader.phase_sign == -1
    assert [a.id for a in cots.antennas] == [1, 2, 3, 4]
    assert math.isclose(cots.antennas[0].phase_offset_rad, 3.675808554136233)
    helper = read_scene(examples / "helper-3d-arm" / "scene.toml")
    assert [a.role for a in helper.antennas] == ["tx", "rx", "rx", "rx", "rx"]
    lora = read_scene(examples / "lora-hover-circle" / "scene.toml")
    assert lora.reader.kind == "lora-backscatter" and lora.antennas == []
    np.testing.assert_array_equal(lora.region.max, [60.0, 60.0, 20.0])


def test_examples_round_trip(examples, tmp_path):
    for folder in ("cots-3d-arm", "helper-3d-arm", "lora-hover-circle"):
        scene = read_scene(examples / folder / "scene.toml")
        write_scene(tmp_path / f"{folder}.toml", scene)
        assert_scenes_equal(scene, read_scene(tmp_path / f"{folder}.toml"))


# --- malformed inputs: each names the file, the line and the key path ------


def error_for(write_file, text: str, name: str = "scene.toml") -> FormatError:
    path = write_file(name, text)
    with pytest.raises(FormatError) as caught:
        read_scene(path)
    assert caught.value.path == str(path)
    return caught.value


def test_scene_without_antennas(write_file):
    text = 'name = "x"\ndimensions = 3\n\n[reader]\nkind = "cots"\n'
    error = error_for(write_file, text)
    assert (error.line, error.column) == (5, "antennas")  # at the reader kind that needs them
    assert "needs [[antennas]]" in error.message


def test_helper_scene_without_antennas(write_file):
    error = error_for(write_file, 'dimensions = 3\n[reader]\nkind = "sdr-helper"\n')
    assert (error.line, error.column) == (3, "antennas")


def test_dimensions_2_without_plane_z(write_file):
    error = error_for(write_file, GOOD.replace("dimensions = 3", "dimensions = 2"))
    assert (error.line, error.column) == (2, "plane_z")
    assert str(error).startswith(f"{error.path}:2: line 2, column 'plane_z': required when dimensions = 2")


def test_dimensions_2_with_plane_z(write_file):
    text = GOOD.replace("dimensions = 3", "dimensions = 2\nplane_z = 0.5")
    scene = read_scene(write_file("scene.toml", text))
    assert scene.dimensions == 2 and scene.plane_z == 0.5


def test_toml_syntax_error(write_file):
    error = error_for(write_file, GOOD.replace("id = 2", "id = = 2"))
    assert (error.line, error.column) == (13, "6")
    assert "TOML syntax error" in error.message


def test_toml_syntax_error_at_end_of_document(write_file):
    error = error_for(write_file, GOOD + "extra = [1,\n")
    assert error.line == 19 and error.column is None


def test_bad_phase_sign(write_file):
    error = error_for(write_file, GOOD.replace("phase_sign = -1", "phase_sign = 2"))
    assert (error.line, error.column) == (6, "reader.phase_sign")
    assert "expected one of 1, -1, found 2" in error.message


def test_phase_sign_must_be_an_integer(write_file):
    error = error_for(write_file, GOOD.replace("phase_sign = -1", "phase_sign = -1.0"))
    assert (error.line, error.column) == (6, "reader.phase_sign")


def test_bad_dimensions(write_file):
    error = error_for(write_file, GOOD.replace("dimensions = 3", "dimensions = 4"))
    assert (error.line, error.column) == (2, "dimensions")


def test_missing_dimensions(write_file):
    error = error_for(write_file, GOOD.replace("dimensions = 3\n", ""))
    assert (error.line, error.column) == (None, "dimensions")


def test_missing_reader(write_file):
    text = 'dimensions = 3\n[[antennas]]\nid = 1\nposition = [0.0, 0.0, 0.0]\n'
    error = error_for(write_file, text)
    assert (error.line, error.column) == (None, "reader")


def test_bad_reader_kind_and_period(write_file):
    error = error_for(write_file, GOOD.replace('kind = "cots"', 'kind = "llrp"'))
    assert (error.line, error.column) == (5, "reader.kind")
    text = GOOD.replace("phase_sign = -1", 'phase_sign = -1\nphase_period = "2*pi"')
    error = error_for(write_file, text)
    assert (error.line, error.column) == (7, "reader.phase_period")


def test_bad_phase_noise(write_file):
    text = GOOD.replace("phase_sign = -1", "phase_sign = -1\nphase_noise_rad = 0")
    error = error_for(write_file, text)
    assert (error.line, error.column) == (7, "reader.phase_noise_rad")


def test_bad_antenna_position(write_file):
    error = error_for(write_file, GOOD.replace("[0.0, 0.8, 0.0]", "[0.0, 0.8]"))
    assert (error.line, error.column) == (18, "antennas[2].position")
    error = error_for(write_file, GOOD.replace("[0.0, 0.3, 0.0]", "[0.0, nan, 0.0]"))
    assert (error.line, error.column) == (14, "antennas[1].position")


def test_missing_antenna_position(write_file):
    error = error_for(write_file, GOOD.replace("position = [0.0, 0.3, 0.0]\n", ""))
    assert (error.line, error.column) == (12, "antennas[1].position")  # the [[antennas]] header


def test_duplicate_antenna_id(write_file):
    error = error_for(write_file, GOOD.replace("id = 3", "id = 1"))
    assert (error.line, error.column) == (17, "antennas[2].id")


def test_antenna_id_not_an_integer(write_file):
    error = error_for(write_file, GOOD.replace("id = 2", 'id = "2"'))
    assert (error.line, error.column) == (13, "antennas[1].id")


def test_bad_antenna_role(write_file):
    error = error_for(write_file, GOOD + 'role = "sender"\n')
    assert (error.line, error.column) == (19, "antennas[2].role")


def test_bad_region(write_file):
    text = GOOD + "\n[region]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 0.0, 1.0]\n"
    error = error_for(write_file, text)
    assert (error.line, error.column) == (22, "region.max")


def test_bad_channel_offset(write_file):
    text = GOOD + "\n[[channel_offsets]]\nfrequency_hz = -902.75e6\nphase_offset_rad = 1.0\n"
    error = error_for(write_file, text)
    assert (error.line, error.column) == (21, "channel_offsets[0].frequency_hz")


def test_bad_bytes(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_bytes(b'name = "caf\xe9"\n')
    with pytest.raises(FormatError) as caught:
        read_scene(path)
    assert caught.value.line is None and "UTF-8" in caught.value.message
