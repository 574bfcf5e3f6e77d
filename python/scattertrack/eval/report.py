"""Human-readable and JSON forms of a :class:`~scattertrack.eval.metrics.Report`.

The text table is what the CLI prints; the dict is what experiments write
next to their outputs. Both use the report's SI values and convert only for
display (mm, cm/s, s).
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.eval.metrics import Report, TagMetrics

# (header, unit, width, getter, scale, decimals): one table column each.
_COLUMNS = [
    ("rows", "", 7, lambda m: m.n, 1, 0),
    ("excl", "", 6, lambda m: m.n_excluded, 1, 0),
    ("3D med", "mm", 8, lambda m: m.median_3d_m, 1e3, 1),
    ("3D p90", "mm", 8, lambda m: m.p90_3d_m, 1e3, 1),
    ("x med", "mm", 7, lambda m: m.median_axis_m[0], 1e3, 1),
    ("y med", "mm", 7, lambda m: m.median_axis_m[1], 1e3, 1),
    ("z med", "mm", 7, lambda m: m.median_axis_m[2], 1e3, 1),
    ("v med", "cm/s", 7, lambda m: m.median_velocity_m_s, 1e2, 1),
    ("conv", "s", 7, lambda m: m.convergence_time_s, 1, 2),
    ("first", "s", 7, lambda m: m.first_estimate_s, 1, 2),
]

# Shown only when some row has both an estimated and a true orientation (Marvel).
_ORIENTATION_COLUMNS = [
    ("rot mean", "deg", 9, lambda m: m.mean_orientation_deg, 1, 2),
    ("yaw mean", "deg", 9, lambda m: m.mean_yaw_deg, 1, 2),
    ("3D mean", "mm", 9, lambda m: m.mean_3d_m, 1e3, 1),
]


def _cell(value, scale: float, decimals: int) -> str:
    """A number, or '-' for nan (no rows, never converged)."""
    value = float(value)
    if not math.isfinite(value):
        return "-"
    return f"{value * scale:.{decimals}f}"


def format_report(report: Report, *, title: str | None = None) -> str:
    """A compact text table: one line per tag and one for all tags pooled.

    Columns: rows evaluated, rows excluded (outside the truth span), median
    and 90th percentile 3D error (mm), median absolute error per axis (mm),
    median velocity error (cm/s), convergence time (s, '-' if never) and
    first-estimate delay (s); when the track and the truth carry orientations,
    also the mean orientation and heading errors (degrees) and the mean 3D
    error (mm; the Marvel paper reports means). Below the table: how many tags converged,
    rows excluded by reason, reads the tracker skipped, tags never tracked.
    """
    names = list(report.per_tag) + ["overall"]
    columns = _COLUMNS + (_ORIENTATION_COLUMNS if report.overall.n_orientation else [])
    tag_width = max(len("tag"), *(len(name) for name in names))
    metrics_of = [*report.per_tag.values(), report.overall]
    cells = [[_cell(get(m), scale, decimals) for _, _, _, get, scale, decimals in columns] for m in metrics_of]
    # A column is as wide as its widest cell plus a space (a diverged track's
    # metres of error would otherwise run into the next column).
    widths = [max(width, *(len(row[j]) + 1 for row in cells)) for j, (_, _, width, *_) in enumerate(columns)]
    header = "tag".ljust(tag_width) + "".join(c[0].rjust(w) for c, w in zip(columns, widths))
    units = " " * tag_width + "".join(c[1].rjust(w) for c, w in zip(columns, widths))
    lines = [title, "=" * len(header)] if title else []
    lines += [header, units]

    def row(name: str, values: list[str]) -> str:
        return name.ljust(tag_width) + "".join(v.rjust(w) for v, w in zip(values, widths))

    for name, values in zip(report.per_tag, cells):
        lines.append(row(name, values))
    lines.append("-" * len(header))
    lines.append(row("overall", cells[-1]))

    if not report.per_tag and not report.excluded.total:
        # A tracker that never committed to an estimate writes a header-only track.csv.
        lines.append("no estimates: the track has no rows, so there is nothing to evaluate")
    converged = sum(math.isfinite(m.convergence_time_s) for m in report.per_tag.values())
    filters = []
    if report.skip_first_s > 0:
        filters.append(f"rows in the first {report.skip_first_s:g} s of each track left out")
    if report.after_convergence_only:
        filters.append("rows before convergence left out")
    lines.append(
        f"converged: {converged}/{len(report.per_tag)} tags "
        f"(3D error < {report.convergence_threshold_m * 1e3:g} mm held >= {report.hold_s:g} s)"
        + (f"; {'; '.join(filters)}" if filters else "")
    )
    if report.excluded.total:
        lines.append("not evaluated: " + report.excluded.summary().removeprefix("skipped "))
    if report.track_skipped.total:
        lines.append("tracker " + report.track_skipped.summary())
    if report.missing_tags:
        lines.append("tags with truth but no track: " + ", ".join(report.missing_tags))
    return "\n".join(lines)


def _number(value) -> float | int | None:
    """A JSON-safe scalar: nan and infinities become None (JSON has no nan)."""
    if isinstance(value, (int, np.integer)):
        return int(value)
    value = float(value)
    return value if math.isfinite(value) else None


def _metrics_to_dict(metrics: TagMetrics) -> dict:
    return {
        "n": int(metrics.n),
        "n_rows": int(metrics.n_rows),
        "n_excluded": int(metrics.n_excluded),
        "n_velocity": int(metrics.n_velocity),
        "median_3d_m": _number(metrics.median_3d_m),
        "p90_3d_m": _number(metrics.p90_3d_m),
        "mean_3d_m": _number(metrics.mean_3d_m),
        "rmse_3d_m": _number(metrics.rmse_3d_m),
        "max_3d_m": _number(metrics.max_3d_m),
        "median_axis_m": [_number(v) for v in metrics.median_axis_m],
        "p90_axis_m": [_number(v) for v in metrics.p90_axis_m],
        "median_velocity_m_s": _number(metrics.median_velocity_m_s),
        "p90_velocity_m_s": _number(metrics.p90_velocity_m_s),
        "convergence_time_s": _number(metrics.convergence_time_s),
        "first_estimate_s": _number(metrics.first_estimate_s),
        "converged_fraction": _number(metrics.converged_fraction),
        "motion_start_s": _number(metrics.motion_start_s),
        "converged_at_s": _number(metrics.converged_at_s),
        "n_orientation": int(metrics.n_orientation),
        "mean_orientation_deg": _number(metrics.mean_orientation_deg),
        "median_orientation_deg": _number(metrics.median_orientation_deg),
        "mean_yaw_deg": _number(metrics.mean_yaw_deg),
    }


def report_to_dict(report: Report) -> dict:
    """A JSON-serialisable summary of the report, without the per-row arrays.

    Keys keep the SI unit suffixes of :class:`TagMetrics` (``_m``, ``_m_s``,
    ``_s``). Values that are nan in the report (no rows, never converged) are
    ``None``, so ``json.dumps(..., allow_nan=False)`` accepts the result.
    """
    return {
        "settings": {
            "convergence_threshold_m": float(report.convergence_threshold_m),
            "hold_s": float(report.hold_s),
            "motion_speed_m_s": float(report.motion_speed_m_s),
            "after_convergence_only": bool(report.after_convergence_only),
            "skip_first_s": float(report.skip_first_s),
        },
        "overall": _metrics_to_dict(report.overall),
        "per_tag": {epc: _metrics_to_dict(metrics) for epc, metrics in report.per_tag.items()},
        "tags": len(report.per_tag),
        "converged_tags": sum(math.isfinite(m.convergence_time_s) for m in report.per_tag.values()),
        "excluded": dict(report.excluded.counts),
        "track_skipped": dict(report.track_skipped.counts),
        "missing_tags": list(report.missing_tags),
    }
