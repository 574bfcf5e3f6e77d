"""scene.toml input hygiene: 2D regions, id bounds, frequency units, warnings, accepted variants."""

import warnings
from pathlib import Path

import numpy as np
import pytest

from scattertrack.io import FormatError, InputWarning, read_scene, write_scene

PLANAR_SCENE = Path(__file__).resolve().parents[3].parent / "shared" / "outside" / "cots-2d-planar" / "scene.toml"

BASE = """\
name = "s"
dimensions = {dimensions}
plane_z = 0.25

[reader]
kind = "cots"
{reader}
[[antennas]]
id = {id}
position = [0.0, 0.0, 0.0]

[[antennas]]
id = 2
position = [0.0, 0.3, 0.0]
{tail}"""


def scene_text(dimensions=2, reader="", id="1", tail="") -> str:
    return BASE.format(dimensions=dimensions, reader=reader, id=id, tail=tail)


def read_quietly(path):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        return read_scene(path)


def scene_warnings(path) -> list[InputWarning]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_scene(path)
    return [w.message for w in caught if issubclass(w.category, InputWarning)]


def scene_error(path) -> FormatError:
    with pytest.raises(FormatError) as caught:
        read_scene(path)
    assert caught.value.path == str(path)
    return caught.value


# --- regions of a 2D scene ------------------------------------------------------


def test_planar_region_with_zero_z_extent(write_file):
    region = "\n[region]\nmin = [-0.5, -0.5, 0.25]\nmax = [1.5, 1.5, 0.25]\n"
    scene = read_quietly(write_file("scene.toml", scene_text(tail=region)))
    np.testing.assert_array_equal(scene.region.min, [-0.5, -0.5, 0.25])
    np.testing.assert_array_equal(scene.region.max, [1.5, 1.5, 0.25])


def test_planar_region_with_two_values_per_corner(write_file, tmp_path):
    region = "\n[region]\nmin = [-0.5, -0.5]\nmax = [1.5, 1]\n"
    scene = read_quietly(write_file("scene.toml", scene_text(tail=region)))
    np.testing.assert_array_equal(scene.region.min, [-0.5, -0.5, 0.25])  # z is plane_z
    np.testing.assert_array_equal(scene.region.max, [1.5, 1.0, 0.25])
    write_scene(tmp_path / "again.toml", scene)  # written with 3 values, read back equal
    again = read_quietly(tmp_path / "again.toml")
    np.testing.assert_array_equal(again.region.max, scene.region.max)


@pytest.mark.skipif(not PLANAR_SCENE.is_file(), reason="shared outside cases not found")
def test_the_outside_planar_scene_is_read():
    scene = read_quietly(PLANAR_SCENE)
    assert scene.dimensions == 2 and scene.region.min[2] == scene.region.max[2] == 0.0


@pytest.mark.parametrize(
    "region, key, fragment",
    [
        ("min = [0.0, 0.0]\nmax = [0.0, 1.0]", "region.max", "in x and y"),
        ("min = [0.0, 0.0, 0.3]\nmax = [1.0, 1.0, 0.2]", "region.max", "z must be at least"),
        ("min = [0.0]\nmax = [1.0, 1.0]", "region.min", "expected 2 or 3 finite numbers"),
        ("min = [0.0, 0.0]\nmax = [1.0, nan]", "region.max", "expected 2 or 3 finite numbers"),
        ("min = [0.0, 0.0]\nmax = \"far\"", "region.max", "expected 3 finite numbers"),
        ("min = [0.0, 0.0]", "region.max", "missing required key"),
    ],
)
def test_bad_planar_regions(write_file, region, key, fragment):
    text = scene_text(tail=f"\n[region]\n{region}\n")
    error = scene_error(write_file("scene.toml", text))
    assert error.column == key and fragment in error.message
    assert error.line is not None


def test_a_3d_region_still_needs_extent_on_every_axis(write_file):
    region = "\n[region]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 0.0]\n"
    error = scene_error(write_file("scene.toml", scene_text(dimensions=3, tail=region)))
    assert (error.column, error.line) == ("region.max", 18)


def test_a_planar_region_that_misses_plane_z_warns(write_file):
    region = "\n[region]\nmin = [0.0, 0.0, 1.0]\nmax = [1.0, 1.0, 1.0]\n"
    (warning,) = scene_warnings(write_file("scene.toml", scene_text(tail=region)))
    assert (warning.column, warning.line) == ("region.min", 17)
    assert "plane_z" in warning.message


# --- antenna ids -------------------------------------------------------------------


@pytest.mark.parametrize("antenna_id", ["9223372036854775808", "-9223372036854775809"])
def test_antenna_id_must_fit_in_int64(write_file, antenna_id):
    error = scene_error(write_file("scene.toml", scene_text(id=antenna_id)))
    assert (error.column, error.line) == ("antennas[0].id", 9)
    assert "64-bit" in error.message


def test_int64_antenna_id_is_accepted(write_file):
    scene = read_quietly(write_file("scene.toml", scene_text(id="9223372036854775807")))
    assert scene.antennas[0].id == 2**63 - 1


# --- channel offsets -----------------------------------------------------------------


@pytest.mark.parametrize(
    "frequency, fragment",
    [("902.75", "looks like MHz: multiply by 1e6"), ("0.90275", "looks like GHz"), ("50e6", "outside 100 MHz")],
)
def test_channel_offset_frequency_range(write_file, frequency, fragment):
    tail = f"\n[[channel_offsets]]\nfrequency_hz = {frequency}\nphase_offset_rad = 0.5\n"
    error = scene_error(write_file("scene.toml", scene_text(tail=tail)))
    assert (error.column, error.line) == ("channel_offsets[0].frequency_hz", 17)
    assert fragment in error.message


# --- warnings and accepted variants -----------------------------------------------------


@pytest.mark.parametrize("noise", ["0.001", "1e-5", "1.5", "6.3"])
def test_implausible_noise_prior_warns(write_file, noise):
    (warning,) = scene_warnings(write_file("scene.toml", scene_text(reader=f"phase_noise_rad = {noise}\n")))
    assert (warning.column, warning.line) == ("reader.phase_noise_rad", 7)
    assert "implausible" in warning.message


@pytest.mark.parametrize("noise", ["0.0011", "0.1", "1.0"])
def test_plausible_noise_prior_is_quiet(write_file, noise):
    read_quietly(write_file("scene.toml", scene_text(reader=f"phase_noise_rad = {noise}\n")))


def test_unknown_keys_are_accepted_with_a_warning(write_file):
    antenna = "\n[[antennas]]\nid = 3\nposition = [1.0, 0.0, 0.0]\ngain_dbi = 6\n"
    text = 'generator = "outside tool"\n' + scene_text(reader="phase_noise = 0.1\n", tail=antenna + "\n[custom]\nanything = 1\n")
    path = write_file("scene.toml", text)
    found = scene_warnings(path)
    assert [(w.column, w.line) for w in found] == [("reader.phase_noise", 8), ("antennas[2].gain_dbi", 21)]
    assert all("unknown key" in w.message for w in found)
    with pytest.warns(InputWarning):
        scene = read_scene(path)
    assert scene.reader.phase_noise_rad is None and len(scene.antennas) == 3
    assert scene.extra == {"generator": "outside tool", "custom": {"anything": 1}}  # kept quietly


def test_bom_and_crlf(write_file):
    text = "\ufeff" + scene_text(tail="\n[region]\nmin = [0.0, 0.0]\nmax = [1.0, 1.0]\n").replace("\n", "\r\n")
    scene = read_quietly(write_file("scene.toml", text))
    assert [a.id for a in scene.antennas] == [1, 2]


def test_errors_after_crlf_name_the_right_line(write_file):
    text = scene_text(id="1.5").replace("\n", "\r\n")
    error = scene_error(write_file("scene.toml", text))
    assert (error.column, error.line) == ("antennas[0].id", 9)
