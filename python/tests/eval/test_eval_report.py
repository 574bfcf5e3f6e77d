"""format_report(), report_to_dict() and compare_files()."""

import json

import numpy as np
import pytest

from eval_synthetic import concat_tracks, concat_truth, make_truth, track_from
from scattertrack.eval import compare, compare_files, format_report, report_to_dict


def _two_tag_report(skip_reasons=None):
    truth_a, truth_b = make_truth("E2000A01"), make_truth("E2000B02")
    track_a = track_from(truth_a, position_offset=(0.005, 0.0, 0.0), velocity_offset=(0.01, 0.0, 0.0))
    track_b = track_from(truth_b, position_offset=(0.0, 0.0, 0.05))  # never converges
    track = concat_tracks(track_a, track_b)
    for reason, count in (skip_reasons or {}).items():
        track.skipped.add(reason, n=count)
    return compare(concat_truth(truth_a, truth_b, make_truth("E2000C03")), track)


def test_format_report_lists_tags_overall_and_units():
    text = format_report(_two_tag_report({"phase outlier": 7}), title="glac on circle")
    lines = text.splitlines()
    assert lines[0] == "glac on circle"
    assert any(line.startswith("E2000A01") for line in lines)
    assert any(line.startswith("overall") for line in lines)
    row_a = next(line for line in lines if line.startswith("E2000A01")).split()
    # rows, excluded, 3D median, 3D p90, x, y, z medians (mm), velocity (cm/s), convergence, first (s)
    assert row_a == ["E2000A01", "501", "0", "5.0", "5.0", "5.0", "0.0", "0.0", "1.0", "0.00", "0.00"]
    row_b = next(line for line in lines if line.startswith("E2000B02")).split()
    assert row_b[3] == "50.0" and row_b[-2] == "-"  # never converged
    assert "mm" in text and "cm/s" in text
    assert "converged: 1/2 tags" in text
    assert "7 phase outlier" in text
    assert "E2000C03" in text  # truth but no track


def test_format_report_keeps_columns_apart_for_huge_errors():
    """A diverged track (kilometres of error) widens its columns instead of running numbers together."""
    truth = make_truth()
    far = track_from(truth, position_offset=(3000.0, 400.0, 0.0))
    lines = format_report(compare(truth, far)).splitlines()
    row = next(line for line in lines if line.startswith("E2000A01"))
    assert row.split() == ["E2000A01", "501", "0", "3026549.2", "3026549.2", "3000000.0", "400000.0", "0.0", "0.0", "-", "0.00"]
    assert len(lines[0]) == len(row) == len(lines[3])  # header, row and rule line up


def test_format_report_without_rows():
    truth = make_truth()
    never = track_from(truth, position_offset=(0.05, 0.0, 0.0))
    text = format_report(compare(truth, never, after_convergence_only=True))
    assert "overall" in text and "rows before convergence left out" in text


def test_report_to_dict_is_strict_json_without_arrays():
    summary = report_to_dict(_two_tag_report())
    text = json.dumps(summary, allow_nan=False)
    assert "errors_3d_m" not in text and "times_s" not in text
    assert summary["per_tag"]["E2000A01"]["median_3d_m"] == pytest.approx(0.005)
    assert summary["per_tag"]["E2000A01"]["median_axis_m"] == pytest.approx([0.005, 0.0, 0.0])
    assert summary["per_tag"]["E2000B02"]["convergence_time_s"] is None
    assert summary["overall"]["convergence_time_s"] is None
    assert summary["overall"]["n"] == 1002
    assert (summary["tags"], summary["converged_tags"]) == (2, 1)
    assert summary["missing_tags"] == ["E2000C03"]
    assert summary["settings"]["convergence_threshold_m"] == 0.02


def _write_csv(path, header, columns):
    with open(path, "w") as file:
        file.write(",".join(header) + "\n")
        for row in zip(*columns):
            file.write(",".join(str(value) for value in row) + "\n")


def test_compare_files(tmp_path):
    io = pytest.importorskip("scattertrack.io")
    if not hasattr(io, "read_truth") or not hasattr(io, "read_track"):
        pytest.skip("scattertrack.io.read_truth/read_track not available yet")
    truth = make_truth(duration_s=3.0)
    track = track_from(truth, position_offset=(0.0, 0.004, 0.0))
    _write_csv(
        tmp_path / "truth.csv",
        ["time_s", "epc", "x", "y", "z"],
        [truth.time_s, truth.epc, *truth.position.T],
    )
    _write_csv(
        tmp_path / "track.csv",
        ["time_s", "epc", "x", "y", "z", "vx", "vy", "vz"],
        [track.time_s, track.epc, *track.position.T, *np.full((3, len(track)), "nan")],
    )
    report = compare_files(tmp_path / "truth.csv", tmp_path / "track.csv", hold_s=0.5)
    tag = report.per_tag["E2000A01"]
    assert tag.median_3d_m == pytest.approx(0.004, abs=1e-9)
    assert tag.n_velocity == 0
