"""eval on inputs from outside: an empty track, tags as object arrays of shared strings."""

import numpy as np

from scattertrack import eval as evaluation
from scattertrack.io import Track, Truth
from scattertrack.io.cells import interned


def truth_of(epcs) -> Truth:
    time = np.repeat(np.arange(20) * 0.01, len(epcs))
    epc = np.tile(np.array(epcs, dtype=object), 20)
    position = np.column_stack([time, np.zeros_like(time), np.zeros_like(time)])
    return Truth(time, epc, position, np.full_like(position, np.nan))


def test_an_empty_track_reports_no_estimates():
    empty = Track(np.zeros(0), np.zeros(0, dtype=object), np.zeros((0, 3)), np.zeros((0, 3)))
    report = evaluation.compare(truth_of(["E2"]), empty)
    assert report.per_tag == {} and report.overall.n == 0
    assert report.missing_tags == ["E2"]
    text = evaluation.format_report(report)
    assert "no estimates: the track has no rows" in text


def test_a_track_with_rows_says_nothing_of_no_estimates():
    truth = truth_of(["E2"])
    track = Track(truth.time_s[5:8], truth.epc[5:8], truth.position[5:8], truth.velocity[5:8])
    assert "no estimates" not in evaluation.format_report(evaluation.compare(truth, track))


def test_long_and_mixed_epcs_group_by_tag_in_order_of_appearance():
    long_epc = "E2" * 500
    truth = truth_of([long_epc, "aa"])
    rows = np.arange(4, 12)
    track = Track(truth.time_s[rows], interned(truth.epc[rows]), truth.position[rows] + [0.001, 0.0, 0.0], truth.velocity[rows])
    report = evaluation.compare(truth, track)
    assert list(report.per_tag) == [long_epc, "aa"]
    assert all(m.n == 4 for m in report.per_tag.values())
    np.testing.assert_allclose(report.overall.median_3d_m, 0.001)
