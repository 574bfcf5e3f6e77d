"""check-scene's calibration lines: what a scene has not calibrated yet."""

import dataclasses

import numpy as np

from scattertrack.check.calibration import calibration_lines
from scattertrack.io.types import ChannelOffset, Reads
from scattertrack.sim import load_scenario, simulate


def _scene():
    return simulate(load_scenario("glac-3d-walls") | {"duration_s": 1.0}, seed=1).scene


def test_a_tape_measure_scene_lists_every_gap():
    scene = dataclasses.replace(_scene(), antennas=[dataclasses.replace(a, phase_offset_rad=0.0) for a in _scene().antennas], channel_offsets=[])
    text = "\n".join(calibration_lines(scene))
    for gap in ("not calibrated", "antenna phase offsets are all 0", "no channel offsets", "no hop table"):
        assert gap in text


def test_reads_say_what_the_gaps_cost():
    scene = dataclasses.replace(_scene(), channel_offsets=[])
    reads = Reads(np.array([0.0, 0.1]), np.array(["E200", "E200"]), np.array([1, 2]), np.array([902.75e6, 903.25e6]), np.zeros(2), np.full(2, np.nan), np.full(2, np.nan), channel_index=np.array([1, 2]))
    text = "\n".join(calibration_lines(scene, reads))
    assert "the reads hop, so every channel's offset is unknown" in text
    assert "the reads carry channel indices" in text


def test_a_calibrated_scene_states_how_well():
    scene = dataclasses.replace(
        _scene(),
        channel_offsets=[ChannelOffset(915.25e6, 0.3)],
        hop_table={1: 915.25e6},
        extra={"calibration": {"references": 4, "reads": 900, "phase_coherence": 0.99, "chance_coherence": 0.1, "phase_usable": False, "calibrated": ["phase_sign"]}},
    )
    lines = calibration_lines(scene)
    assert len(lines) == 2 and "phase NOT usable" in lines[0] and "no RSSI path loss" in lines[1]
