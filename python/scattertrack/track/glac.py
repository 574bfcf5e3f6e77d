"""The old home of GLAC's tracker, kept importable: the names now live in
:mod:`scattertrack.track.core` (the tracker), :mod:`scattertrack.track.cots`
(the reads batch runner) and :mod:`scattertrack.track.base` (the estimate)."""

from scattertrack.track.base import Estimate
from scattertrack.track.columns import track_from_columns
from scattertrack.track.core import CoreTracker, Tracker, _engine
from scattertrack.track.cots import _DECLINED, run
from scattertrack.track.methods import METHODS as _METHODS
from scattertrack.track.parameters import default_params

METHODS: list[str] = list(_METHODS)
"""Every registered method (the registry in the Rust core)."""


def make(method: str, scene, **params) -> CoreTracker:
    """A core tracker by name (:func:`scattertrack.track.make` builds any method's)."""
    return CoreTracker(method, scene, **params)


__all__ = ["METHODS", "CoreTracker", "Estimate", "Tracker", "default_params", "make", "run", "track_from_columns", "_DECLINED", "_engine"]
