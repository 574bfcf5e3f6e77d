"""Trackers: every method of every pipeline behind one causal interface (DESIGN.md, Python API).

Contract (:mod:`scattertrack.track.base`): ``make(method, scene, **params)``
builds a :class:`~scattertrack.track.base.Tracker`; ``tracker.step(z)``
takes one typed measurement of the method's input kind and returns an
:class:`Estimate` or ``None`` (causal: only measurements at or before that
time are used); ``run(method, scene, data)`` is the batch run, a loop over
``step``. Inputs a tracker declines (gated outliers, out-of-order, invalid)
are counted in ``stats()`` and reported in ``Track.skipped``, never dropped
silently.

One registry (:data:`REGISTRY`, read from the Rust core) names every method
with its pipeline and input kind; ``run`` dispatches by it:

- ``reads`` (COTS pipeline, GLAC and its variants): :class:`Read` steps,
  :class:`~scattertrack.io.types.Reads` batches (:mod:`.cots`);
- ``frames`` (helper pipeline, TurboTrack and its variants): :class:`Frame`
  steps, :class:`~scattertrack.io.frames.Frames` batches (:mod:`.helper`);
- ``features+imu`` / ``sigmf+imu`` (drone pipeline, Marvel): :class:`ImuSample`
  and :class:`Feature` steps, :class:`DroneData` batches (:mod:`.marvel`).

``default_params(method)`` lists each method's typed parameters (the
tables behind ``scattertrack methods --params`` and docs/parameters.md).
``Tracker`` stays the core tracker's old name (:class:`CoreTracker`); the
interface itself is :class:`scattertrack.track.base.Tracker`.
"""

from scattertrack.io.frames import Frames
from scattertrack.io.types import Reads, Scene, Track
from scattertrack.track import base, cots, methods, parameters
from scattertrack.track.base import DroneData, Estimate, Feature, Frame, ImuSample, Measurement, Read
from scattertrack.track.core import CoreTracker, Tracker
from scattertrack.track.helper import run_frames
from scattertrack.track.marvel import MarvelTracker
from scattertrack.track.methods import DRONE_METHODS, HELPER_METHODS, REGISTRY, WIDEBAND_METHODS

METHODS: list[str] = list(methods.METHODS)
"""Every registered method (the registry in the Rust core)."""

_BATCH_INPUTS = {"reads": (Reads, "phase reads (Reads, reads.csv)"), "frames": (Frames, "wideband frames (Frames, frames.csv)")}
_DRONE_INPUT = (DroneData, "the drone's IMU with features or a LoRa recording (DroneData)")


def default_params(method: str = "glac") -> dict:
    """The parameters ``method`` accepts, with their defaults (SI units);
    ValueError naming the known methods for an unknown one."""
    return parameters.default_params(method)


def make(method: str, scene: Scene | None, **params) -> base.Tracker:
    """A tracker of any registered method; ``params`` override :func:`default_params`.

    The core's methods (``reads`` and ``frames`` input) give a
    :class:`CoreTracker`, the drone's a :class:`MarvelTracker`. ValueError
    naming the known methods for an unknown one, or the parameter for a bad value.
    """
    if methods.method(method).estimator == "core":
        return CoreTracker(method, scene, **params)
    return MarvelTracker(method, scene, **params)


def run(method: str, scene: Scene | None, data: Reads | Frames | DroneData, **kwargs) -> Track:
    """Tracks everything in ``data``, the batch input of the method's kind
    (module docstring): one estimate row per update, in time order.

    ``kwargs``: the method's parameters and the runner's options
    (``progress``; ``chunk`` and ``covariance`` for reads). ValueError
    naming the input the method takes when ``data`` is another kind.
    """
    entry = methods.method(method)  # an unknown name fails here, naming the known ones
    expected, wanted = _BATCH_INPUTS.get(entry.input, _DRONE_INPUT)
    if not isinstance(data, expected):
        given = next((text for kind, text in (*_BATCH_INPUTS.values(), _DRONE_INPUT) if isinstance(data, kind)), type(data).__name__)
        raise ValueError(f"method '{method}' takes {wanted}, not {given}")
    if entry.input == "reads":
        return cots.run(method, scene, data, **kwargs)
    if entry.input == "frames":
        return run_frames(method, scene, data, **kwargs)
    progress = kwargs.pop("progress", False)
    return MarvelTracker(method, scene, recording=data.recording is not None, **kwargs).run(data, progress=progress)


__all__ = [
    "DRONE_METHODS",
    "HELPER_METHODS",
    "METHODS",
    "REGISTRY",
    "WIDEBAND_METHODS",
    "CoreTracker",
    "DroneData",
    "Estimate",
    "Feature",
    "Frame",
    "ImuSample",
    "MarvelTracker",
    "Measurement",
    "Read",
    "Tracker",
    "default_params",
    "make",
    "run",
    "run_frames",
]
