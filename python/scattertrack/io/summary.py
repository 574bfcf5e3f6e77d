"""One-line accounts of what a reader did with a file's rows, for the command line.

Every input row is used or declined with a reason (docs/formats.md: nothing is
silently dropped). These lines say so for each input before tracking: how
many rows came back, how many were out of time order (sorted) and how many
the reader declined, by reason with example lines. Pure functions of the
readers' results; the trackers' own declines are reported after tracking.
"""

from __future__ import annotations

from scattertrack.io.types import Features, Imu, SkipReport


def plural(count: int, word: str) -> str:
    """'1 frame', '3 frames'."""
    return f"{count} {word}" if count == 1 else f"{count} {word}s"


def declined(report: SkipReport, word: str = "row") -> str:
    """'none declined', or 'declined 3 rows on reading: 2 duplicate row (lines 4, 9); 1 ...'."""
    if not report.total:
        return "none declined"
    return f"declined {plural(report.total, word)} on reading: {report.summary().removeprefix('skipped ')}"


def frames_lines(frames, path) -> list[str]:
    """What :func:`scattertrack.io.read_frames` (or the SigMF channel estimation) gave for ``path``.

    When every row was declined the last line says that nothing is left to track.
    """
    lines = [
        f"read {plural(frames.n_frames, 'frame')} of {plural(len(frames.epcs()), 'tag')} from {path}",
        f"  {frames.reordered} rows out of time order (sorted, not dropped)",
    ]
    if frames.skipped.total:
        lines.append(f"  {declined(frames.skipped)}")
        if not len(frames):
            lines.append("  no frames left to track: every row was declined")
    return lines


def imu_line(imu: Imu, path) -> str:
    """What :func:`scattertrack.io.read_imu` gave for ``path``: samples, reordering, declines, gaps."""
    return (
        f"read {plural(len(imu), 'IMU sample')} from {path}; {imu.reordered} out of time order (sorted), "
        f"{declined(imu.skipped, 'sample')}, {plural(imu.gaps, 'gap')}"
    )


def features_line(features: Features, path) -> str:
    """What :func:`scattertrack.io.read_features` gave for ``path``."""
    return f"read {plural(len(features), 'feature row')} from {path}; {features.reordered} out of time order (sorted)"
