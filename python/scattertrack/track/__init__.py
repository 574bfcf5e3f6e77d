"""Trackers: every method behind one causal interface (DESIGN.md, Python API).

Contract: ``make(method, scene, **params)`` builds a :class:`Tracker`;
``tracker.step(...)`` takes one read and returns an :class:`Estimate` or
``None`` (causal: only reads at or before that time are used); ``run`` is
the batch helper, a loop over ``step`` done in Rust, for many interleaved
tags: COTS phase reads (GLAC and its variants) or a localization helper's
wideband frames (TurboTrack and its variants). Inputs a tracker declines
(gated outliers, out-of-order, invalid) are counted and reported in
``Track.skipped``, never dropped silently.
"""

from scattertrack.io.frames import Frames
from scattertrack.io.types import Reads, Scene, Track
from scattertrack.track import glac, methods, parameters
from scattertrack.track.glac import METHODS, Estimate, Tracker, make
from scattertrack.track.methods import REGISTRY, WIDEBAND_METHODS
from scattertrack.track.wideband import run_frames


def default_params(method: str = "glac") -> dict:
    """The parameters ``method`` accepts, with their defaults (SI units);
    ValueError naming the known methods for an unknown one."""
    return parameters.default_params(method)


def run(method: str, scene: Scene, data: Reads | Frames, **kwargs) -> Track:
    """Tracks every tag in ``data``: phase reads (reads.csv) or wideband
    frames (frames.csv), whichever the method consumes."""
    methods.method(method)  # an unknown name fails here, naming the known ones
    if isinstance(data, Frames):
        if method not in WIDEBAND_METHODS:
            raise ValueError(f"method '{method}' takes phase reads; frames need one of {', '.join(WIDEBAND_METHODS)}")
        return run_frames(method, scene, data, **kwargs)
    if method in WIDEBAND_METHODS:
        raise ValueError(f"method '{method}' takes wideband frames (frames.csv), not phase reads")
    return glac.run(method, scene, data, **kwargs)


__all__ = ["METHODS", "REGISTRY", "WIDEBAND_METHODS", "Estimate", "Tracker", "default_params", "make", "run", "run_frames"]
