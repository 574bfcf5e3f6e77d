"""The old name of :mod:`scattertrack.track.helper` (the helper pipeline's
TurboTrack and its variants), kept importable."""

from scattertrack.track.helper import _DECLINED, WIDEBAND_METHODS, default_params, engine, run_frames

__all__ = ["WIDEBAND_METHODS", "_DECLINED", "default_params", "engine", "run_frames"]
