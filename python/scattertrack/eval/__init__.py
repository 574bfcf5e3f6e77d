"""Evaluation: accuracy of a track against ground truth, as numbers, text and figures.

Contract
--------
Inputs are the in-memory :class:`~scattertrack.io.types.Truth` and
:class:`~scattertrack.io.types.Track` (docs/formats.md sections 3-4); units are
SI (metres, seconds, m/s) in every field, converted only for display.

- :func:`compare` ``(truth, track, *, convergence_threshold_m=0.02, hold_s=1.0,
  motion_speed_m_s=0.01, after_convergence_only=False, skip_first_s=0.0) -> Report``:
  per tag of the track, truth is interpolated linearly at the track times;
  track rows outside that tag's truth time span are excluded and counted
  (``Report.excluded``, ``TagMetrics.n_excluded``), never extrapolated.
  Errors: 3D, per axis, velocity (rows without an estimated velocity are left
  out of the velocity statistics). Convergence time is measured from the
  start of the tag's motion; nan if it never converges. ``Report.overall``
  pools the rows of all tags; its convergence time is the worst tag's (nan if
  any tag never converged).
- :func:`nees` ``(truth, track) -> dict[epc, float]``: diagonal-only NEES from
  the track's 1-sigma columns (about 3 for a consistent 3D filter).
- :func:`format_report` ``(report, *, title=None) -> str``: the text table the CLI prints.
- :func:`report_to_dict` ``(report) -> dict``: JSON-serialisable summary (nan -> None),
  without the per-row arrays.
- :func:`save_error_cdf` ``(report, path, *, label=None, others=None)``: PNG of the
  3D and per-axis error CDFs; ``others`` adds more methods to the same figure.
- :func:`save_track_plot` ``(truth, track, path, *, epc=None)``: PNG of truth against
  the estimate (x-y view and x, y, z against time).
- :func:`compare_files` ``(truth_path, track_path, **kw) -> Report``: the same as
  :func:`compare` on files read with :mod:`scattertrack.io`.

Figures are drawn with matplotlib on the Agg canvas (headless), imported only
when a figure is drawn.
"""

from scattertrack.eval.metrics import Report, TagMetrics, compare, compare_files, nees
from scattertrack.eval.plots import save_error_cdf, save_track_plot
from scattertrack.eval.report import format_report, report_to_dict

__all__ = [
    "Report",
    "TagMetrics",
    "compare",
    "compare_files",
    "format_report",
    "nees",
    "report_to_dict",
    "save_error_cdf",
    "save_track_plot",
]
