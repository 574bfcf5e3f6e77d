"""PNG figures: error CDFs (paper-style method comparisons) and truth-vs-estimate plots.

Matplotlib is used through its object interface on the Agg canvas, never
through ``pyplot``: no window, no global backend switch, so the functions
work headless and do not disturb a notebook that imports them. Matplotlib is
imported inside the functions to keep ``import scattertrack.eval`` fast for
the CLI.
"""

from __future__ import annotations

import os

import numpy as np

from scattertrack.eval.metrics import Report, _group_rows
from scattertrack.io.types import Track, Truth

_AXIS_NAMES = ("x", "y", "z")
_AXIS_STYLES = ("-", "--", ":")


def _new_figure(width_in: float, height_in: float):
    """A figure drawn on an Agg canvas (headless)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _empirical_cdf(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted finite values and their cumulative fractions (i / n, i = 1..n)."""
    values = np.sort(values[np.isfinite(values)])
    return values, np.arange(1, len(values) + 1) / max(len(values), 1)


def save_error_cdf(
    report: Report,
    path: str | os.PathLike,
    *,
    label: str | None = None,
    others: dict[str, Report] | None = None,
) -> None:
    """Write a PNG with the empirical CDF of the pooled errors.

    Left panel: CDF of the 3D error (x axis in cm), one curve per method,
    with the median (circle) and 90th percentile (square) marked and quoted
    in the legend. Right panel: CDFs of the absolute error per axis (cm),
    line style per axis (solid x, dashed y, dotted z), colour per method.

    Args:
        report: the main method's report (its ``overall`` errors are drawn).
        path: where to write the PNG.
        label: legend name of ``report`` (default "estimate").
        others: more methods to draw on the same axes, by legend name.
    """
    methods = [(label or "estimate", report)] + list((others or {}).items())
    figure = _new_figure(11.0, 4.5)
    axes_3d, axes_axis = figure.subplots(1, 2)
    colours = [f"C{k % 10}" for k in range(len(methods))]

    for (name, method_report), colour in zip(methods, colours):
        overall = method_report.overall
        errors_cm, fraction = _empirical_cdf(overall.errors_3d_m * 1e2)
        median_cm = overall.median_3d_m * 1e2
        p90_cm = overall.p90_3d_m * 1e2
        axes_3d.step(
            errors_cm,
            fraction,
            where="post",
            color=colour,
            label=f"{name} (median {median_cm:.2f} cm, p90 {p90_cm:.2f} cm)",
        )
        if np.isfinite(median_cm):
            axes_3d.plot([median_cm], [0.5], "o", color=colour)
            axes_3d.plot([p90_cm], [0.9], "s", color=colour)
        for k, style in enumerate(_AXIS_STYLES):
            errors_cm, fraction = _empirical_cdf(overall.errors_axis_m[:, k] * 1e2)
            axes_axis.step(
                errors_cm, fraction, where="post", color=colour, linestyle=style, label=f"{name} {_AXIS_NAMES[k]}"
            )

    for axes, title in ((axes_3d, "3D position error"), (axes_axis, "absolute error per axis")):
        axes.axhline(0.5, color="0.8", linewidth=0.8, zorder=0)
        axes.axhline(0.9, color="0.8", linewidth=0.8, zorder=0)
        axes.set_xlabel("error (cm)")
        axes.set_ylabel("CDF")
        axes.set_ylim(0.0, 1.02)
        axes.set_xlim(left=0.0)
        axes.set_title(title)
        axes.grid(True, alpha=0.3)
        axes.legend(fontsize="small", loc="lower right")
    figure.savefig(path, format="png", dpi=120)


def save_track_plot(
    truth: Truth | None,
    track: Track,
    path: str | os.PathLike,
    *,
    epc: str | None = None,
) -> None:
    """Write a PNG with truth against the estimate for one tag.

    Left panel: the x-y view (metres, equal scale). Right: x, y and z
    (metres) against time (seconds), truth as lines, estimate as dots.

    Args:
        truth: ground truth; ``None`` (or no rows for the tag) draws the estimate alone.
        track: tracker output.
        path: where to write the PNG.
        epc: the tag to draw; default the first tag in the track.

    Raises:
        ValueError: the track has no rows, or none for ``epc``.
    """
    groups = dict(_group_rows(track.epc))
    if not groups:
        raise ValueError("save_track_plot: the track has no rows")
    if epc is None:
        epc = next(iter(groups))
    if epc not in groups:
        raise ValueError(f"save_track_plot: the track has no rows for tag {epc!r} (tags: {', '.join(groups)})")
    rows = groups[epc]
    rows = rows[np.argsort(track.time_s[rows], kind="stable")]
    estimate_time = track.time_s[rows]
    estimate = track.position[rows]

    truth_time = np.zeros(0)
    truth_position = np.zeros((0, 3))
    if truth is not None:
        truth_rows = np.flatnonzero(np.asarray(truth.epc, dtype=object) == epc)
        truth_rows = truth_rows[np.argsort(truth.time_s[truth_rows], kind="stable")]
        truth_time = truth.time_s[truth_rows]
        truth_position = truth.position[truth_rows]

    figure = _new_figure(12.0, 5.5)
    left, right = figure.subfigures(1, 2, width_ratios=[1.0, 1.3])
    axes_xy = left.subplots()
    axes_time = right.subplots(3, 1, sharex=True)

    if len(truth_time):
        axes_xy.plot(truth_position[:, 0], truth_position[:, 1], "-", color="0.3", linewidth=1.2, label="truth")
    axes_xy.plot(estimate[:, 0], estimate[:, 1], ".", color="C1", markersize=2.5, label="estimate")
    axes_xy.plot(estimate[:1, 0], estimate[:1, 1], "x", color="C3", markersize=8, label="first estimate")
    axes_xy.set_xlabel("x (m)")
    axes_xy.set_ylabel("y (m)")
    axes_xy.set_aspect("equal", adjustable="datalim")
    axes_xy.grid(True, alpha=0.3)
    axes_xy.legend(fontsize="small")
    axes_xy.set_title(f"tag {epc}: x-y view")

    for k, axes in enumerate(axes_time):
        if len(truth_time):
            axes.plot(truth_time, truth_position[:, k], "-", color="0.3", linewidth=1.2, label="truth")
        axes.plot(estimate_time, estimate[:, k], ".", color="C1", markersize=2.5, label="estimate")
        axes.set_ylabel(f"{_AXIS_NAMES[k]} (m)")
        axes.grid(True, alpha=0.3)
    axes_time[0].legend(fontsize="small", loc="upper right")
    axes_time[0].set_title("position against time")
    axes_time[-1].set_xlabel("time (s)")
    figure.savefig(path, format="png", dpi=120)
