"""scene.toml's [[reflectors]]: known walls and scatterers, read, written back, checked and warned."""

import warnings

import numpy as np
import pytest

from scattertrack.io import Antenna, FormatError, InputWarning, Reader, Reflector, Scene, read_scene, write_scene
from scattertrack.io import types

from scene_texts import line_scene

ANTENNAS = line_scene("walls", "{kind}")
# In GOOD, lines 19-23: a wall 2 m in front of the antennas (its normal written 2 long);
# lines 25-28: a point scatterer.
REFLECTORS = """
[[reflectors]]
kind = "plane"
point = [2.0, 0.0, 0.0]
normal = [-2.0, 0.0, 0.0]
coefficient = -0.5

[[reflectors]]
kind = "point"
position = [1, 1, 0]
coefficient = 0.3
"""
GOOD = ANTENNAS.format(kind="cots") + REFLECTORS


def read_quietly(path) -> Scene:
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        return read_scene(path)


def read_warned(path) -> tuple[Scene, list[InputWarning]]:
    """The scene and the input warnings reading it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = read_scene(path)
    return scene, [w.message for w in caught if issubclass(w.category, InputWarning)]


def scene_warnings(path) -> list[InputWarning]:
    return read_warned(path)[1]


def error_for(write_file, text: str) -> FormatError:
    path = write_file("scene.toml", text)
    with pytest.raises(FormatError) as caught:
        read_scene(path)
    assert caught.value.path == str(path)
    return caught.value


def assert_reflectors_equal(a: list[Reflector], b: list[Reflector]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert (x.kind, x.coefficient) == (y.kind, y.coefficient)
        for key in ("point", "normal", "position"):
            assert (getattr(x, key) is None) == (getattr(y, key) is None), key
            if getattr(x, key) is not None:
                np.testing.assert_array_equal(getattr(x, key), getattr(y, key))


def test_reflector_is_exported_like_the_other_scene_types():
    assert types.Reflector is Reflector
    assert Scene("s", 3, Reader(), antennas=[]).reflectors == []


def test_plane_and_point_reflectors_are_read(write_file):
    scene = read_quietly(write_file("scene.toml", GOOD))
    plane, point = scene.reflectors
    assert plane.kind == "plane" and plane.coefficient == -0.5 and plane.position is None
    np.testing.assert_array_equal(plane.point, [2.0, 0.0, 0.0])
    np.testing.assert_array_equal(plane.normal, [-1.0, 0.0, 0.0])  # stored unit length
    assert point.kind == "point" and point.coefficient == 0.3
    assert point.point is None and point.normal is None
    assert point.position.dtype == np.float64 and point.position.shape == (3,)
    np.testing.assert_array_equal(point.position, [1.0, 1.0, 0.0])
    assert "reflectors" not in scene.extra


def test_a_scene_without_reflectors_has_none(write_file):
    assert read_quietly(write_file("scene.toml", ANTENNAS.format(kind="cots"))).reflectors == []


def test_reflectors_round_trip(write_file, tmp_path):
    text = GOOD.replace("[-2.0, 0.0, 0.0]", "[-1.0, 2.0, 0.5]")  # a slanted wall, normal not unit
    scene = read_quietly(write_file("scene.toml", text))
    assert np.linalg.norm(scene.reflectors[0].normal) == pytest.approx(1.0, abs=1e-15)
    write_scene(tmp_path / "again.toml", scene)
    again = read_quietly(tmp_path / "again.toml")
    assert_reflectors_equal(scene.reflectors, again.reflectors)
    # Writing what was read gives the same text: the unit normal does not drift.
    write_scene(tmp_path / "third.toml", again)
    assert (tmp_path / "third.toml").read_text() == (tmp_path / "again.toml").read_text()


def test_reflectors_built_in_code_are_written(tmp_path):
    scene = Scene(
        "code",
        3,
        Reader(),
        antennas=[Antenna(1, np.array([0.0, 0.0, 1.0]))],
        reflectors=[
            Reflector("point", -1, position=[0.5, 0.5, 0.5]),
            Reflector("plane", 0.25, point=np.zeros(3), normal=np.array([0.0, 0.0, 1.0])),
        ],
    )
    assert scene.reflectors[0].position.dtype == np.float64  # lists become float arrays
    scene.save(tmp_path / "scene.toml")
    again = read_quietly(tmp_path / "scene.toml")
    assert_reflectors_equal(scene.reflectors, again.reflectors)
    assert [r.kind for r in again.reflectors] == ["point", "plane"] and again.reflectors[0].coefficient == -1.0


# --- malformed reflectors: each names the key path and the line ---------------


@pytest.mark.parametrize(
    "old, new, line, column, words",
    [
        ('kind = "plane"\n', "", 19, "reflectors[0].kind", "missing required key"),
        ('kind = "point"', 'kind = "wall"', 26, "reflectors[1].kind", "expected one of 'plane', 'point', found 'wall'"),
        ("normal = [-2.0, 0.0, 0.0]\n", "", 19, "reflectors[0].normal", "missing required key"),
        ("point = [2.0, 0.0, 0.0]\n", "", 19, "reflectors[0].point", "missing required key"),
        ("position = [1, 1, 0]\n", "", 25, "reflectors[1].position", "missing required key"),
        ("coefficient = 0.3\n", "", 25, "reflectors[1].coefficient", "missing required key"),
        ("[-2.0, 0.0, 0.0]", "[0.0, 0, -0.0]", 22, "reflectors[0].normal", "non-zero vector"),
        ("[2.0, 0.0, 0.0]", "[2.0, nan, 0.0]", 21, "reflectors[0].point", "3 finite numbers"),
        ("[-2.0, 0.0, 0.0]", "[-2.0, inf, 0.0]", 22, "reflectors[0].normal", "3 finite numbers"),
        ("[1, 1, 0]", "[1, 1]", 27, "reflectors[1].position", "3 finite numbers"),
        ("coefficient = -0.5", "coefficient = -1.01", 23, "reflectors[0].coefficient", "in [-1, 1], found -1.01"),
        ("coefficient = 0.3", "coefficient = 2", 28, "reflectors[1].coefficient", "in [-1, 1], found 2"),
        ("coefficient = 0.3", "coefficient = nan", 28, "reflectors[1].coefficient", "finite number"),
        ("coefficient = 0.3", "coefficient = -inf", 28, "reflectors[1].coefficient", "finite number"),
        ("coefficient = 0.3", 'coefficient = "0.3"', 28, "reflectors[1].coefficient", "finite number"),
        ("coefficient = 0.3", "coefficient = true", 28, "reflectors[1].coefficient", "finite number"),
    ],
)
def test_bad_reflector(write_file, old, new, line, column, words):
    assert GOOD.count(old) == 1
    error = error_for(write_file, GOOD.replace(old, new))
    assert (error.line, error.column) == (line, column)
    assert words in error.message
    assert str(error).startswith(f"{error.path}:{line}: line {line}, column '{column}': ")


def test_reflectors_must_be_an_array_of_tables(write_file):
    text = GOOD.replace('name = "walls"', 'name = "walls"\nreflectors = 3').replace("[[reflectors]]", "[[other]]")
    error = error_for(write_file, text)
    assert (error.line, error.column) == (2, "reflectors")
    assert "array of tables ([[reflectors]])" in error.message


@pytest.mark.parametrize("kind", ["sdr-helper", "lora-backscatter"])
def test_only_cots_scenes_take_reflectors(write_file, kind):
    text = ANTENNAS.format(kind=kind) + REFLECTORS
    if kind == "sdr-helper":  # an otherwise valid helper: one tx, two rx
        text = text.replace("position = [0.0, 0.0, 0.0]", 'position = [0.0, 0.0, 0.0]\nrole = "tx"')
        text = text.replace("position = [0.0, 0.3, 0.0]", 'position = [0.0, 0.3, 0.0]\nrole = "rx"')
        text = text.replace("position = [0.0, 0.8, 0.0]", 'position = [0.0, 0.8, 0.0]\nrole = "rx"')
        read_quietly(write_file("helper.toml", text.split("\n[[reflectors]]")[0]))  # valid without them
    error = error_for(write_file, text)
    assert error.column == "reflectors"
    assert error.line == text.split("\n").index("[[reflectors]]") + 1  # the first [[reflectors]] header
    assert "only 'cots' scenes take [[reflectors]]" in error.message and repr(kind) in error.message


# --- valid but suspicious: a warning naming the reflector ---------------------


def test_good_reflectors_give_no_warning(write_file):
    assert scene_warnings(write_file("scene.toml", GOOD)) == []


def test_unknown_reflector_key_is_warned(write_file):
    path = write_file("scene.toml", GOOD.replace("coefficient = 0.3", 'coefficient = 0.3\ncolour = "red"'))
    scene, (warning,) = read_warned(path)
    assert (warning.line, warning.column) == (29, "reflectors[1].colour")
    assert "unknown key (ignored); [reflectors] keys are kind, point, normal, position, coefficient" in warning.message
    assert len(scene.reflectors) == 2


def test_a_key_of_the_other_kind_is_warned(write_file):
    path = write_file("scene.toml", GOOD.replace("coefficient = -0.5", "coefficient = -0.5\nposition = [1, 2, 3]"))
    scene, (warning,) = read_warned(path)
    assert (warning.line, warning.column) == (24, "reflectors[0].position")
    assert "not a key of a 'plane' reflector (ignored)" in warning.message
    assert scene.reflectors[0].position is None


def test_antenna_on_a_plane_is_warned(write_file):
    # The wall x = 0.0005 with normal +x: every antenna (x = 0) lies 0.5 mm behind it.
    text = GOOD.replace("[2.0, 0.0, 0.0]", "[0.0005, 0.0, 0.0]").replace("[-2.0, 0.0, 0.0]", "[1.0, 0.0, 0.0]")
    path = write_file("scene.toml", text)
    scene, (warning,) = read_warned(path)
    assert (warning.line, warning.column) == (19, "reflectors[0]")
    assert "antennas 1, 2, 3 within 1 mm of this plane reflector" in warning.message
    assert len(scene.reflectors) == 2  # valid: still read


def test_antennas_on_both_sides_of_a_plane_are_warned(write_file):
    # The wall y = 0.5 with normal +y: antennas 1 and 2 behind it, 3 in front.
    text = GOOD.replace("[2.0, 0.0, 0.0]", "[0.0, 0.5, 0.0]").replace("[-2.0, 0.0, 0.0]", "[0.0, 3.0, 0.0]")
    path = write_file("scene.toml", text)
    scene, (warning,) = read_warned(path)
    assert (warning.line, warning.column) == (19, "reflectors[0]")
    assert "antennas on both sides of this plane reflector (in front: 3; behind: 1, 2)" in warning.message
    np.testing.assert_array_equal(scene.reflectors[0].normal, [0.0, 1.0, 0.0])


def test_a_point_scatterer_in_an_antennas_near_field_is_warned(write_file):
    text = GOOD.replace("position = [1, 1, 0]", "position = [0.0, 0.0, 0.0]")  # on antenna 1
    (warning,) = scene_warnings(write_file("scene.toml", text))
    assert warning.column == "reflectors[1]" and "point scatterer within 16 cm (half a wavelength) of antenna 1" in warning.message


def test_plane_side_problems_is_the_readers_check_as_a_function():
    from scattertrack.io.scene import plane_side_problems

    antennas = [Antenna(id=1, position=np.array([0.0, 0.0, 0.0])), Antenna(id=2, position=np.array([2.0, 0.0, 0.0]))]
    assert plane_side_problems([3.0, 0.0, 0.0], [-1.0, 0.0, 0.0], antennas) == []
    (between,) = plane_side_problems([1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], antennas)
    assert "both sides" in between and "in front: 1" in between and "behind: 2" in between
    on = plane_side_problems([2.0005, 0.0, 0.0], [-1.0, 0.0, 0.0], antennas)
    assert any("antenna 2 within 1 mm" in p for p in on)
