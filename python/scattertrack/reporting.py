"""Report lines and files shared by several commands: durations, latencies and
distances as text, read rates, and the evaluation's figures and JSON record."""

from __future__ import annotations

import json
import math
from pathlib import Path

from scattertrack.arguments import say


def format_duration(seconds: float) -> str:
    """A wall-clock time with sensible precision: '0.0042 s', '1.23 s', '75 s'."""
    if seconds < 0.1:
        return f"{seconds:.4f} s"
    if seconds < 10:
        return f"{seconds:.2f} s"
    return f"{seconds:.0f} s"


def format_nanoseconds(nanoseconds: float) -> str:
    """A latency in microseconds, or milliseconds when large ('3.6 us', '12.5 ms')."""
    if nanoseconds >= 1e6:
        return f"{nanoseconds / 1e6:.1f} ms"
    return f"{nanoseconds / 1e3:.1f} us"


def format_millimetres(metres: float) -> str:
    """A distance in mm, or 'n/a' for nan (no rows evaluated)."""
    return f"{metres * 1e3:.1f} mm" if math.isfinite(metres) else "n/a"


def read_rates(count: int, tags: int, duration_s: float) -> str:
    """'29.0 reads/s' for one tag; 'x reads/s in all, y per tag' for several."""
    if duration_s <= 0:
        return "no duration"
    if tags <= 1:
        return f"{count / duration_s:.1f} reads/s"
    return f"{count / duration_s:.1f} reads/s in all, {count / duration_s / tags:.1f} per tag"


def save_figures(report, truth, result, out_dir: Path, tag: str | None = None) -> list[Path]:
    """Write error_cdf.png and track.png into ``out_dir``; returns the files written."""
    from scattertrack import eval as evaluation

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    if report.overall.n:
        path = out_dir / "error_cdf.png"
        evaluation.save_error_cdf(report, path)
        written.append(path)
    else:
        say("  no rows could be evaluated: error_cdf.png not written")
    if len(result):
        path = out_dir / "track.png"
        evaluation.save_track_plot(truth, result, path, epc=tag)
        written.append(path)
    else:
        say("  the track has no rows: track.png not written")
    return written


def write_json(path: Path, report, **inputs) -> None:
    """The report as JSON, with the package version and the inputs (reproducibility)."""
    from scattertrack import __version__
    from scattertrack import eval as evaluation

    record = {"version": __version__, **inputs, **evaluation.report_to_dict(report)}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=2, allow_nan=False) + "\n")


def output_path(path) -> Path:
    """A command's output file: ``path`` as a Path, its folder made if need be."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    return out
