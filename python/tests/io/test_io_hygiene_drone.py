"""Drone-pipeline inputs across files: features outside the IMU's time span, and the
one-line accounts of what the readers did with the rows (io.summary)."""

import warnings

import numpy as np
import pytest

from scattertrack.io import InputWarning, SkipReport, read_features, read_frames, read_imu
from scattertrack.io import summary
from scattertrack.io.timeline import warn_outside_span

FEATURES = "time_s,range_m,azimuth_rad,elevation_rad\n"
IMU = "time_s,ax,ay,az,gx,gy,gz\n"


def span_warnings(*args) -> list[InputWarning]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_outside_span(*args)
    return [w.message for w in caught if issubclass(w.category, InputWarning)]


def test_features_inside_the_imu_span_are_quiet():
    imu = np.arange(0.0, 10.0, 0.01)
    assert span_warnings("f.csv", np.array([0.0, 5.0, 9.99]), None, "imu.csv", imu, "IMU sample") == []


def test_features_before_the_imu_warn_at_the_furthest_row_with_the_count():
    imu = np.arange(5.0, 10.0, 0.01)
    times = np.array([4.5, 4.9, 5.0, 6.0])
    lines = np.array([2, 3, 4, 5])
    (warning,) = span_warnings("features.csv", times, lines, "imu.csv", imu, "IMU sample")
    assert (warning.path, warning.line, warning.column) == ("features.csv", 2, "time_s")
    assert "2 of 4 rows lie before the first IMU sample of imu.csv (5.000000 s" in warning.message
    assert "one clock" not in warning.message


def test_features_all_after_the_imu_ask_about_the_clock():
    imu = np.arange(0.0, 10.0, 0.01)
    times = np.array([100.0, 100.1, 100.2])
    (warning,) = span_warnings("features.csv", times, np.array([2, 3, 4]), "imu.csv", imu, "IMU sample")
    assert warning.line == 4 and "3 of 3 rows lie after the last IMU sample" in warning.message
    assert "are the two files on one clock?" in warning.message


def test_both_sides_warn_once_each():
    imu = np.arange(1.0, 2.0, 0.01)
    found = span_warnings("f.csv", np.array([0.5, 1.5, 2.5, 3.0]), None, "imu.csv", imu, "IMU sample")
    assert [w.line for w in found] == [None, None]
    assert "before the first" in found[0].message and "after the last" in found[1].message


def test_read_features_keeps_each_rows_line_through_sorting(write_file):
    path = write_file("features.csv", FEATURES + "0.3,10,0,0\n0.1,10,0,0\n0.2,10,0,0\n")
    features = read_features(path)
    np.testing.assert_array_equal(features.line, [3, 4, 2])


def test_imu_line_reports_reordering_declines_and_gaps(write_file):
    rows = ["0.02,0,0,9.81,0,0,0\n", "0.01,0,0,9.81,0,0,0\n", "0.01,0,0,9.81,0,0,0\n", "0.03,0,0,9.81,0,0,0\n"]
    imu = read_imu(write_file("imu.csv", IMU + "".join(rows)))
    line = summary.imu_line(imu, "imu.csv")
    assert line == ("read 3 IMU samples from imu.csv; 2 out of time order (sorted), declined 1 sample on reading: "
                    "1 duplicate time (lines 4), 0 gaps")


def test_frames_lines_say_when_every_row_was_declined(write_file):
    header = "time_s,epc,tx,rx,frequency_hz,h_re,h_im\n"
    frames = read_frames(write_file("frames.csv", header + "0.0,E2,0,1,915e6,1e200,0\n0.0,E2,0,2,915e6,0,-1e200\n"))
    assert summary.frames_lines(frames, "frames.csv") == [
        "read 0 frames of 0 tags from frames.csv",
        "  0 rows out of time order (sorted, not dropped)",
        "  declined 2 rows on reading: 2 channel beyond 1e100 (lines 2, 3)",
        "  no frames left to track: every row was declined",
    ]


def test_declined_says_none():
    assert summary.declined(SkipReport()) == "none declined"
