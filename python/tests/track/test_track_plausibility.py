"""A static tag tracked as moving is flagged from its own reads (track.plausibility)."""

import copy
import dataclasses

import numpy as np

from scattertrack import track
from scattertrack.sim import load_scenario, simulate
from scattertrack.track.plausibility import implausible_speed_warnings, radial_speed_bound


def _session(static: bool):
    scenario = copy.deepcopy(load_scenario("glac-3d-walls"))
    scenario["duration_s"] = 10.0
    if static:
        scenario["tags"][0]["trajectory"] = {"kind": "static", "position": [0.5, 0.6, 0.7]}
    return simulate(scenario, seed=1)


def test_a_static_tag_tracked_at_a_metre_a_second_is_flagged():
    sim = _session(static=True)
    result = track.run("glac", sim.scene, sim.reads)
    assert not implausible_speed_warnings(result, sim.reads)  # GLAC itself keeps it still here
    fast = dataclasses.replace(result, velocity=np.tile([1.0, 0.0, 0.0], (len(result), 1)))
    lines = implausible_speed_warnings(fast, sim.reads)
    assert len(lines) == 1 and "most likely static" in lines[0] and "scattertrack locate" in lines[0]
    assert radial_speed_bound(sim.reads, np.arange(len(sim.reads)), 2 * np.pi) < 0.05


def test_a_moving_tag_is_not_flagged():
    sim = _session(static=False)
    result = track.run("glac", sim.scene, sim.reads)
    assert not implausible_speed_warnings(result, sim.reads)
    assert radial_speed_bound(sim.reads, np.arange(len(sim.reads)), 2 * np.pi) > 0.05
