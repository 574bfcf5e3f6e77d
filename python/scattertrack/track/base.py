"""The tracker contract, the same for every method of every pipeline.

A tracker is a causal filter over one stream of typed measurements ``z_1,
z_2, ...`` in time order::

    x̂_k = step(z_k) = E[x(t_k) | z_1 .. z_k]   or  None

``step`` returns an :class:`Estimate` of the state at the measurement's time
(position and velocity, with their covariance) from the measurements so far,
never later ones, or ``None`` while no estimate is committed (initialising,
or a measurement that only propagates: an IMU sample). Inputs a tracker
declines (out of time order, invalid, gated outliers) are not dropped
silently: they are counted by reason in ``stats()`` and, for a batch run,
in ``Track.skipped``.

The measurements, by the input kind in the registry
(:data:`scattertrack.track.methods.REGISTRY`, ``Method.input``):

- ``reads`` (COTS pipeline: GLAC and its variants): :class:`Read`;
- ``frames`` (helper pipeline: TurboTrack and its variants): :class:`Frame`;
- ``features+imu`` and ``sigmf+imu`` (drone pipeline: Marvel, mu-locate):
  :class:`ImuSample` and :class:`Feature`; a batch run takes a
  :class:`DroneData` (the IMU plus features, or a LoRa recording sensed
  epoch by epoch).

``scattertrack.track.make(name, scene, **params)`` builds a :class:`Tracker`
of any method; ``scattertrack.track.run(name, scene, data)`` is the batch
run, a loop over ``step`` (done in Rust for the core's methods).
Units: SI throughout (s, m, m/s, rad, Hz).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from scattertrack.io.types import Features, Imu


@dataclass
class Estimate:
    """One tracker output, every pipeline's."""

    time_s: float
    epc: str
    """The tag (COTS, helper) or ``drone``."""
    position: np.ndarray
    """Metres, (3,)."""
    velocity: np.ndarray
    """m/s, (3,); nan for methods without velocity."""
    covariance: np.ndarray
    """(6, 6) covariance of [p, v] (m², m²/s, m²/s²); nan where the method has none."""
    hypotheses: int = 1
    """Live candidate trajectories."""
    weight: float = 1.0
    """Normalised likelihood of the reported trajectory."""
    orientation: np.ndarray | None = None
    """world_T_body quaternion ``(qw, qx, qy, qz)`` (drone pipeline); None for a tag."""
    sigma: np.ndarray | None = None
    """1-sigma position along the world axes, (3,) m, where the method reports it so (drone pipeline)."""
    source: object = None
    """The pipeline's own record of the estimate (the drone's
    :class:`scattertrack.fusion.Estimate`: controller, biases, ...), or None."""


@dataclass(frozen=True)
class Read:
    """One phase read of a COTS reader (a row of ``reads.csv``)."""

    time_s: float
    epc: str
    antenna: int
    """The port id as in the scene."""
    frequency_hz: float
    phase_rad: float


@dataclass(frozen=True)
class Frame:
    """One wideband frame of a localization helper (the rows of ``frames.csv`` sharing a frame).

    ``rx`` (n,) receive antenna ids, ``frequency_hz`` (n,) and complex ``h``
    (n,), sorted by receiver then frequency, every receiver with the same
    subcarriers; ``tx`` the transmit antenna id.
    """

    time_s: float
    epc: str
    tx: int
    rx: np.ndarray
    frequency_hz: np.ndarray
    h: np.ndarray


@dataclass(frozen=True)
class ImuSample:
    """One inertial sample of the drone (a row of ``imu.csv``, docs/formats.md section 6): body frame."""

    time_s: float
    accel: np.ndarray
    """(3,) specific force, m/s²."""
    gyro: np.ndarray
    """(3,) angular rate, rad/s."""
    baro_z: float = float("nan")
    """Barometric height, m; nan where absent."""


@dataclass(frozen=True)
class Feature:
    """One pose feature row (a row of ``features.csv``, docs/formats.md section 7):
    the drone seen from the controller's array, world frame; nan where absent."""

    time_s: float
    range_m: float
    azimuth_rad: float
    elevation_rad: float
    yaw_rad: float = float("nan")
    range_sigma_m: float = float("nan")
    angle_sigma_rad: float = float("nan")
    yaw_sigma_rad: float = float("nan")


@dataclass
class DroneData:
    """The drone pipeline's batch input: the IMU plus pose features or a LoRa recording.

    ``recording``: a ``.sigmf-meta`` path or a
    :class:`~scattertrack.io.sigmf_lora.LoraRecording` (sensed epoch by epoch
    alongside the fusion); exactly one of ``features`` and ``recording``.
    """

    imu: Imu
    features: Features | None = None
    recording: object = None

    def __post_init__(self):
        if (self.features is None) == (self.recording is None):
            raise ValueError("DroneData takes the IMU with features or a recording (exactly one of the two)")


Measurement = Read | Frame | ImuSample | Feature
"""Anything a tracker's ``step`` takes."""


class Tracker(ABC):
    """A causal tracker (module docstring): ``step`` one measurement at a time."""

    method: str
    """The registered method name."""

    @abstractmethod
    def step(self, measurement) -> Estimate | None:
        """One measurement of the method's input kind; the estimate at its time, or None."""

    @abstractmethod
    def stats(self, epc: str | None = None) -> dict:
        """What the tracker did with its inputs, counters by reason (for one tag, with ``epc``)."""


__all__ = ["DroneData", "Estimate", "Feature", "Frame", "ImuSample", "Measurement", "Read", "Tracker"]
