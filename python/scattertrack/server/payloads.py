"""Tracks, reports and scenes as JSON for the page.

JSON has no nan: every non-finite number becomes ``null`` (the page draws a
gap). Arrays are sent column-wise per tag, which is what the plots take.
"""

from __future__ import annotations

import math

import numpy as np

MAX_POINTS = 4000
"""Per tag and series: longer runs are thinned evenly for the plots (the
counts sent alongside are the full ones)."""


def number(value) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def column(values) -> list:
    return [number(v) for v in np.asarray(values, dtype=float)]


def thin(n: int) -> np.ndarray:
    """Indices of at most MAX_POINTS rows out of ``n``, first and last included."""
    if n <= MAX_POINTS:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, MAX_POINTS).round().astype(int))


def scene(scene) -> dict:
    """The antennas and the region: what the config tab and the track plots draw."""
    return {
        "name": scene.name,
        "dimensions": int(scene.dimensions),
        "reader": scene.reader.kind,
        "antennas": [
            {"id": int(a.id), "position": column(a.position), "role": a.role} for a in scene.antennas
        ],
        "region": None
        if scene.region is None
        else {"min": column(scene.region.min), "max": column(scene.region.max)},
        "plane_z": None if scene.plane_z is None else number(scene.plane_z),
    }


def track(track) -> dict:
    """Per tag: time, x, y, z and the 1-sigma (norm of the per-axis sigmas) of its rows."""
    tags = {}
    epcs = np.asarray(track.epc).astype(str)
    for epc in dict.fromkeys(epcs.tolist()):
        rows = np.flatnonzero(epcs == epc)
        keep = rows[thin(len(rows))]
        sigma = (
            np.linalg.norm(track.sigma[keep], axis=1) if track.sigma is not None else np.full(len(keep), np.nan)
        )
        tags[epc] = {
            "rows": int(len(rows)),
            "t": column(track.time_s[keep]),
            "x": column(track.position[keep, 0]),
            "y": column(track.position[keep, 1]),
            "z": column(track.position[keep, 2]),
            "sigma": column(sigma),
        }
    return {"rows": int(len(track)), "tags": tags, "skipped": track.skipped.summary() if track.skipped.total else ""}


def truth(truth) -> dict:
    tags = {}
    epcs = np.asarray(truth.epc).astype(str)
    for epc in dict.fromkeys(epcs.tolist()):
        rows = np.flatnonzero(epcs == epc)
        keep = rows[thin(len(rows))]
        tags[epc] = {
            "t": column(truth.time_s[keep]),
            "x": column(truth.position[keep, 0]),
            "y": column(truth.position[keep, 1]),
            "z": column(truth.position[keep, 2]),
        }
    return {"tags": tags}


def report(report, title: str) -> dict:
    """The summary numbers, the text report, and per tag the error over time and its CDF."""
    from scattertrack import eval as evaluation

    errors = {}
    for epc, metrics in report.per_tag.items():
        keep = thin(len(metrics.errors_3d_m))
        ordered = np.sort(np.asarray(metrics.errors_3d_m, dtype=float))
        cdf_keep = thin(len(ordered))
        errors[epc] = {
            "t": column(np.asarray(metrics.times_s)[keep]),
            "error_m": column(np.asarray(metrics.errors_3d_m)[keep]),
            "cdf_error_m": column(ordered[cdf_keep]),
            "cdf_fraction": column((cdf_keep + 1) / max(len(ordered), 1)),
        }
    return {
        "summary": evaluation.report_to_dict(report),
        "text": evaluation.format_report(report, title=title),
        "errors": errors,
    }
