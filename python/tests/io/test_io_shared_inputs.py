"""Every shared example and outside case (docs/formats.md files written by other programs) still
reads: scenes, reads, frames, imu and features, with their time spans agreeing; and every
row of them is used (none declined on reading)."""

import warnings
from pathlib import Path

import pytest

from scattertrack.io import InputWarning, read_features, read_frames, read_imu, read_reads, read_scene, read_truth
from scattertrack.io.timeline import warn_outside_span

SHARED = Path(__file__).resolve().parents[3].parent / "shared"
CASES = sorted(p.parent for p in SHARED.glob("*/**/scene.toml")) if SHARED.is_dir() else []


@pytest.mark.skipif(not CASES, reason=f"shared examples not found at {SHARED}")
@pytest.mark.parametrize("case", CASES, ids=[str(c.relative_to(SHARED)) for c in CASES])
def test_shared_case_reads_quietly(case):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        scene = read_scene(case / "scene.toml")
        if (case / "reads.csv").is_file():
            reads = read_reads(case / "reads.csv", scene)
            assert reads.skipped.total == 0
        if (case / "frames.csv").is_file():
            frames = read_frames(case / "frames.csv", scene)
            assert frames.skipped.total == 0 and frames.n_frames > 0
        if (case / "imu.csv").is_file():
            imu = read_imu(case / "imu.csv")
            features = read_features(case / "features.csv")
            assert imu.skipped.total == 0 and len(features) > 0
            warn_outside_span(case / "features.csv", features.time_s, features.line, case / "imu.csv", imu.time_s,
                              "IMU sample")
        read_truth(case / "truth.csv")
