"""The helper-layout check: receive antennas in line with the transmitter."""

import numpy as np
import pytest

from scattertrack.check import check_helper_scene
from scattertrack.check.helper import lines_through_tx
from scattertrack.io.types import Antenna, Reader, Scene


def helper(tx, *rx) -> Scene:
    antennas = [Antenna(0, np.array(tx, dtype=float), role="tx")]
    antennas += [Antenna(i + 1, np.array(p, dtype=float), role="rx") for i, p in enumerate(rx)]
    return Scene("helper", 3, Reader(kind="sdr-helper"), antennas)


def test_the_cross_layout_is_quiet():
    # The project's layout: two receiver pairs on two lines through the transmitter check each other.
    scene = helper([0.4, 0.4, 0], [0, 0.4, 0], [0.8, 0.4, 0], [0.4, 0, 0], [0.4, 0.8, 0])
    assert lines_through_tx(scene) == [[1, 2], [3, 4]]
    result = check_helper_scene(scene)
    assert result.warnings == [] and "fixes the position" in result.summary


def test_all_but_one_receiver_in_line_warns_naming_them():
    scene = helper([0.6, 0, 0], [0, 0, 0], [0.4, 0, 0], [0.8, 0, 0], [0.6, 0.4, 0])
    (finding,) = check_helper_scene(scene).warnings
    assert finding.line().startswith("warning: receive antennas 1, 2 and 3 lie on one line with the transmitter 0 "
                                     "(along x)")
    assert "only receive antenna 4 tells" in finding.text and "lobe error" in finding.text


def test_every_receiver_in_line_warns_of_the_circle():
    scene = helper([0, 0, 0], [0.3, 0.3, 0.3], [-0.2, -0.2, -0.2], [0.6, 0.6, 0.6])
    (finding,) = check_helper_scene(scene).warnings
    assert "receive antennas 1, 2 and 3" in finding.text and "along (0.58, 0.58, 0.58)" in finding.text
    assert "no frame tells where on a circle" in finding.text


@pytest.mark.parametrize("offset_m, warned", [(0.009, True), (0.03, False)])
def test_in_line_within_a_centimetre(offset_m, warned):
    scene = helper([0, 0, 0], [0.3, 0, 0], [0.6, offset_m, 0], [0, 0.5, 0.2])
    assert bool(check_helper_scene(scene).warnings) == warned
