"""``_core.Scene``: a ``scattertrack.io.Scene`` read once by the binding
(``python/src/scene.rs``), then taken by ``_core.Engine``,
``_core.analyse_scene`` and ``_core.twin_positions``."""

import dataclasses

import numpy as np
import pytest

from scattertrack import _core
from scattertrack.io.scene import Antenna, Reader, Region, Scene


def _scene(**changes) -> Scene:
    antennas = [Antenna(i + 1, np.array(p, dtype=float)) for i, p in enumerate([[0, 0, 0], [1, 0, 0.2], [0, 1, 0.4], [1, 1, 1]])]
    scene = Scene("test", 3, Reader(), antennas, region=Region(np.array([0.1, 0.1, 0.1]), np.array([0.9, 0.9, 0.9])))
    return dataclasses.replace(scene, **changes)


def test_reads_the_scene_and_defaults_the_phase_noise():
    scene = _core.Scene(_scene())
    assert (scene.dimensions, scene.antennas, scene.phase_noise_rad) == (3, 4, _core.DEFAULT_PHASE_NOISE_RAD)
    assert _core.DEFAULT_PHASE_NOISE_RAD == 0.1
    assert _core.Scene(_scene(reader=Reader(phase_noise_rad=0.0))).phase_noise_rad == 0.1
    assert _core.Scene(_scene(reader=Reader(phase_noise_rad=0.05))).phase_noise_rad == 0.05


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"dimensions": 4}, "dimensions must be 2 or 3"),
        ({"antennas": []}, "no antennas"),
        ({"reader": Reader(phase_sign=2)}, "phase_sign must be +1 or -1"),
        ({"region": Region(np.array([1.0, 0, 0]), np.array([0.0, 1, 1]))}, "region min > max"),
    ],
)
def test_a_bad_scene_is_a_value_error_with_the_cores_message(changes, message):
    with pytest.raises(ValueError) as error:
        _core.Scene(_scene(**changes))
    assert str(error.value) == f"invalid scene: {message}"


def test_a_helper_scene_brings_its_roles():
    roles = ["tx", "rx", "rx", "rx"]
    helper = _scene(reader=Reader(kind="sdr-helper"), antennas=[dataclasses.replace(a, role=r) for a, r in zip(_scene().antennas, roles)])
    _core.Engine(_core.Scene(helper), "turbotrack", {})
    with pytest.raises(ValueError, match="role"):
        # Monostatic antennas only: no transmitter for the wideband tracker.
        _core.Engine(_core.Scene(_scene()), "turbotrack", {})
    bad = dataclasses.replace(helper, antennas=[dataclasses.replace(a, role="both") for a in helper.antennas])
    with pytest.raises(ValueError, match="antenna role must be txrx, tx or rx, got both"):
        _core.Scene(bad)


def test_the_engine_and_the_geometry_check_take_it():
    scene = _core.Scene(_scene())
    engine = _core.Engine(scene, "glac", {"q": 0.05})
    assert engine.stats(0)["measurements"] == 0
    with pytest.raises(ValueError, match="unknown method 'nope'"):
        _core.Engine(scene, "nope")
    assert "families" in _core.analyse_scene(scene, [915.25e6], None, False)
    assert isinstance(_core.twin_positions(scene, [0.5, 0.5, 0.5], [915.25e6]), list)
