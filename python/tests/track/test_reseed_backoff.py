"""GLAC's re-seeding back-off (`reseed_max_interval_s`, issue 21): on a
track that cannot resolve (the paper's three antennas on one line leave a
twin family), searches an unresolved track starts on its own come at
doubling intervals, so there are fewer of them; the default keeps one a
second. Counts, not times."""

import copy

import pytest

from scattertrack.sim import load_scenario, simulate
from scattertrack.track import default_params, run


@pytest.fixture(scope="module")
def unresolved():
    scenario = copy.deepcopy(load_scenario("glac-3d-arm-paper-layout")) | {"duration_s": 16.0}
    return simulate(scenario, seed=7102)


def _reseeds(sim, **params):
    track = run("glac", sim.scene, sim.reads, **params)
    return sum(s["reseeds"] for s in track.stats.values())


def test_the_default_does_not_back_off():
    assert default_params("glac")["reseed_max_interval_s"] == default_params("glac")["reseed_interval_s"]


def test_backing_off_searches_less_often(unresolved):
    every_second = _reseeds(unresolved)
    backed_off = _reseeds(unresolved, reseed_max_interval_s=8.0)
    # Over 16 s an unresolved track searches about once a second; doubling
    # intervals (1, 2, 4, 8, 8 s) leave about five.
    assert every_second >= 8
    assert 0 < backed_off <= every_second // 2


def test_a_cap_below_the_interval_is_the_interval(unresolved):
    assert _reseeds(unresolved, reseed_max_interval_s=0.5) == _reseeds(unresolved)
