"""Filter consistency of GLAC on simulated reads: the reported sigmas cover
the truth as often as they claim (NEES, rows beyond 3 sigma).

The normalised estimation error squared per axis, (error / sigma)², has
mean 1 for a filter whose covariance is exactly right. GLAC's is
deliberately on the safe side (the IMM's manoeuvre model, the bias states,
tempered hypothesis weights), so the test asks for the range a user can
rely on: neither overconfident (mean ≤ 2) nor uninformative (mean ≥ 0.15)
on layouts that fix the position, and on every layout, the paper's
ambiguous one included, at most 5 % of rows beyond 3 sigma on some axis.
"""

import numpy as np
import pytest

from scattertrack import track
from scattertrack.sim import load_scenario, simulate


def errors_and_sigmas(name: str, seed: int, duration_s: float = 10.0):
    sim = simulate(load_scenario(name) | {"duration_s": duration_s}, seed=seed)
    result = track.run("glac", sim.scene, sim.reads)
    rows = result.time_s >= 2.0  # the first estimates are from the initial search
    truth = sim.truth
    expected = np.stack([np.interp(result.time_s[rows], truth.time_s, truth.position[:, j]) for j in range(3)], 1)
    axes = sim.scene.dimensions
    return (result.position[rows] - expected)[:, :axes], result.sigma[rows][:, :axes]


@pytest.mark.parametrize("name", ["glac-2d-10cms", "glac-3d-walls"])
def test_nees_per_axis_is_neither_overconfident_nor_vacuous(name):
    error, sigma = errors_and_sigmas(name, seed=3)
    nees = np.mean((error / sigma) ** 2, axis=0)
    assert np.all(nees <= 2.0) and np.all(nees >= 0.15), nees


@pytest.mark.parametrize("name", ["glac-2d-10cms", "glac-3d-walls", "glac-3d-arm-paper-layout"])
def test_at_most_five_percent_of_rows_beyond_three_sigma(name):
    error, sigma = errors_and_sigmas(name, seed=4)
    beyond = np.mean(np.any(np.abs(error) > 3.0 * sigma, axis=1))
    assert beyond <= 0.05, beyond


def test_the_paper_layout_twins_show_in_the_sigma():
    """Three antennas on a line leave twin trajectories decimetres away:
    the reported sigma must be that wide, not a centimetre."""
    _, sigma = errors_and_sigmas("glac-3d-arm-paper-layout", seed=4)
    assert np.median(sigma.max(axis=1)) > 0.1
