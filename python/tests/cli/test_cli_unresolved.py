"""The summary's warning for tracks that end unresolved."""

import numpy as np

from scattertrack.cli import UNRESOLVED_SIGMA_M, unresolved_warnings
from scattertrack.io.types import Track


def track(sigmas: list[float], epc: str = "E2") -> Track:
    n = len(sigmas)
    return Track(
        time_s=np.arange(n, dtype=float),
        epc=np.array([epc] * n),
        position=np.zeros((n, 3)),
        velocity=np.zeros((n, 3)),
        sigma=np.array([[s, s / 2, s / 2] for s in sigmas]),
    )


def test_a_resolved_track_says_nothing():
    assert unresolved_warnings(track([0.5, 0.2, 0.01, 0.005])) == []


def test_a_track_that_ends_unresolved_warns_with_its_share_and_width():
    (line,) = unresolved_warnings(track([0.01, 0.3, 0.5, 2 * UNRESOLVED_SIGMA_M]))
    assert line.startswith("warning: tag E2:")
    assert "75 % of its rows" in line and "up to 50 cm" in line


def test_an_empty_track_says_nothing():
    assert unresolved_warnings(track([])) == []
