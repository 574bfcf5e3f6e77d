"""Simulated calibration sessions: static reference tags at known positions in a
room with unknown antenna and channel offsets (and a moving tag to track)."""

from __future__ import annotations

import copy
import dataclasses

from scattertrack.sim import load_scenario, simulate

NEAR = [[0.3, 0.3, 0.4], [3.0, 3.0, 1.2], [0.5, 3.5, 0.3], [3.5, 0.5, 1.0]]
"""Four references spread over about 4 m of range (antennas of glac-3d-walls)."""
FAR = NEAR + [[4.5, 4.5, 2.0], [2.0, 4.8, 0.5]]


def reference_epcs(positions) -> dict:
    return {f"E2000C{i:02d}": p for i, p in enumerate(positions)}


def room(duration_s: float, references, seed: int, moving: bool = False, **reader_model):
    """A hopping session of ``references`` (and the arm's tag when ``moving``)."""
    scenario = copy.deepcopy(load_scenario("glac-3d-walls"))
    scenario["duration_s"] = duration_s
    scenario["reader_model"].update({"hopping": True, **reader_model})
    scenario["reader_model"].pop("frequency_hz", None)
    statics = [{"epc": epc, "trajectory": {"kind": "static", "position": p}} for epc, p in reference_epcs(references).items()]
    scenario["tags"] = (scenario["tags"] if moving else []) + statics
    return simulate(scenario, seed=seed)


def uncalibrated(scene):
    """The scene as a new user has it: no offsets, and the other phase sign."""
    return dataclasses.replace(
        scene,
        antennas=[dataclasses.replace(a, phase_offset_rad=0.0) for a in scene.antennas],
        channel_offsets=[],
        reader=dataclasses.replace(scene.reader, phase_sign=-scene.reader.phase_sign),
    )
