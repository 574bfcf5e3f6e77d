"""Marvel: the drone pipeline behind the tracker interface (docs/marvel.md).

Methods (``MARVEL_METHODS``):

- ``marvel``: backscatter-inertial fusion (paper sec. IV,
  :mod:`scattertrack.fusion`) of pose features (``features.csv``) and the
  IMU (``imu.csv``); from a LoRa SigMF recording the features come from the
  pose-sensing DSP with the Doppler shift removed using the fused velocity
  (paper sec. III-B).
- ``ulocate``: the paper's Fig. 9 comparison, a mu-locate-style sensing that
  ignores the Doppler shift (channel phases taken as they come); from
  features it is the same fusion, so it needs a recording to differ.

The estimate at an epoch uses only samples and rows at or before it
(causal); rows the estimator declines are counted in ``Track.skipped``.
"""

from __future__ import annotations

import dataclasses

from scattertrack.io.types import Features, Imu, Scene, Track

MARVEL_METHODS = ("marvel", "ulocate")
"""The drone pipeline's methods (inputs: IMU plus features or a LoRa recording)."""

METHOD_DESCRIPTIONS = {
    "marvel": "Marvel: LoRa-backscatter range/angle/heading fused with the IMU in a "
    "sliding-window factor graph (GTSAM), controller position estimated (paper sec. IV)",
    "ulocate": "mu-locate-style Doppler-blind pose sensing (from a SigMF recording), "
    "fused the same way: the paper's Fig. 9 baseline",
}


def default_params(method: str = "marvel") -> dict:
    """The fusion parameters ``method`` accepts, with their defaults (SI units; see MarvelParams)."""
    _check_method(method)
    from scattertrack.fusion.estimator import MarvelParams

    return {field.name: field.default for field in dataclasses.fields(MarvelParams)}


def run_features(method: str, scene: Scene | None, imu: Imu, features: Features, *, progress: bool = False, **params) -> Track:
    """Fuses ``features`` (FORMATS.md 7) with ``imu`` (FORMATS.md 6): one track row per accepted epoch.

    ``params`` are :class:`scattertrack.fusion.MarvelParams` fields. Raises
    ValueError for a method outside :data:`MARVEL_METHODS`, or an unknown parameter.
    """
    _check_method(method)
    from scattertrack.fusion import run_marvel

    return run_marvel(imu, features, scene, progress=progress, **params)


def _check_method(method: str) -> None:
    if method not in MARVEL_METHODS:
        raise ValueError(f"unknown Marvel method '{method}' (known: {', '.join(MARVEL_METHODS)})")
