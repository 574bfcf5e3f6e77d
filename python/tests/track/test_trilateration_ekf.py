"""The trilateration-EKF baseline through the Python API on the simulated
``glac-3d-walls`` scenario: centimetre accuracy with honest sigmas.

Seeds 7300+ (see test_track_glac.py on seed ranges).
"""

import numpy as np
import pytest

from scattertrack.sim import load_scenario, simulate
from scattertrack.track import METHODS, run


def _errors_and_sigmas(seed: int, duration_s: float = 10.0):
    sim = simulate(load_scenario("glac-3d-walls") | {"duration_s": duration_s}, seed=seed)
    track = run("trilateration-ekf", sim.scene, sim.reads)
    truth = sim.truth
    expected = np.stack([np.interp(track.time_s, truth.time_s, truth.position[:, k]) for k in range(3)], axis=1)
    return track, track.position - expected, track.sigma[:, :3]


def test_it_is_registered_as_a_reads_method():
    assert "trilateration-ekf" in METHODS


@pytest.mark.parametrize("seed", [7301, 7302])
def test_centimetre_accuracy_with_honest_sigmas(seed):
    track, error, sigma = _errors_and_sigmas(seed)
    # Silent until the first fix is resolved (a second or two), then one estimate per read.
    assert len(track.time_s) > 150 and track.time_s[0] < 4.0
    distance = np.linalg.norm(error, axis=1)
    assert np.median(distance) < 0.01, np.median(distance)
    assert np.percentile(distance, 95) < 0.025
    # Honest: normalised squared error near 1 per axis, few rows beyond 3 sigma.
    nees = np.mean((error / sigma) ** 2, axis=0)
    assert np.all(nees > 0.4) and np.all(nees < 1.6), nees
    beyond = np.mean(np.any(np.abs(error) > 3.0 * sigma, axis=1))
    assert beyond <= 0.03, beyond
