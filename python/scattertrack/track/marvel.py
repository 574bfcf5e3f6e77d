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

Pose sensing from a recording: :mod:`scattertrack.dsp.lora_sensing` (the
DSP, docs/marvel.md sections 5-8), given the fusion through
:class:`_SensingFusion`. Declined epochs never vanish: each is counted by
reason (:data:`SENSING_DECLINE_REASONS`) in ``Track.skipped`` and
``stats["drone"]["sensing_declined"]``; the estimator's own declines are
counted as in :func:`scattertrack.fusion.run_marvel`.

:class:`MarvelTracker` is the pipeline behind the tracker interface
(:mod:`scattertrack.track.base`): ``step`` takes an
:class:`~scattertrack.track.base.ImuSample` or a
:class:`~scattertrack.track.base.Feature`; its ``run`` is the loop over
``step`` (features) or over the sensed epochs (a recording), ended by
:func:`scattertrack.fusion.run.finish_run`; :func:`run_features` and
:func:`run_sigmf` are that run under their old names.

Units: SI throughout (s, m, m/s, rad, rad/s, Hz, dB where named).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator

import numpy as np

from scattertrack.dsp import lora_sensing
from scattertrack.dsp.lora_sensing import SENSING_DECLINE_REASONS, SensedEpoch, features_of  # also importable from here, their old home
from scattertrack.io.types import Features, Imu, Scene, Track
from scattertrack.track import base
from scattertrack.track import methods as registry
from scattertrack.track.base import DroneData, Estimate, Feature, ImuSample
from scattertrack.track.marvel_params import SENSING_DEFAULTS, sensing_table
from scattertrack.track.marvel_params import table as parameter_table

MARVEL_METHODS = tuple(m.name for m in registry.REGISTRY.values() if m.pipeline == "drone")
"""The drone pipeline's methods (inputs: IMU plus features or a LoRa recording), from the registry."""

EPC = "drone"
"""The track's ``epc`` column: the pipeline tracks one body, the drone."""


def default_params(method: str = "marvel") -> dict:
    """The parameters ``method`` accepts, with their defaults (SI units).

    The fusion's (:class:`scattertrack.fusion.MarvelParams` fields) and the
    pose sensing's (:data:`SENSING_DEFAULTS`, used with a recording only).
    """
    _check_method(method)
    return dict(parameter_table(method).defaults())


class MarvelTracker(base.Tracker):
    """The drone pipeline's tracker: backscatter-inertial fusion, one measurement at a time.

    ``params``: :class:`scattertrack.fusion.MarvelParams` fields; with
    ``recording=True`` (a tracker for :func:`run_sigmf`) the pose sensing's
    too (:data:`SENSING_DEFAULTS`), and the multipath model defaults to
    ``inflation`` (:func:`run_sigmf`). ValueError for a method outside
    :data:`MARVEL_METHODS` or an unknown parameter.
    """

    def __init__(self, method: str = "marvel", scene: Scene | None = None, *, recording: bool = False, **params):
        _check_method(method)
        from scattertrack.fusion.run import new_estimator

        self.method = method
        self.scene = scene
        self.params = dict(params)
        self.recording = recording
        if recording:
            fusion, sensing = _split_params(params)
            # The DSP's sigmas are thermal plus floors: they say nothing about the
            # multipath error, so the Gauss-Markov states (whose 1-sigma is the row's)
            # would model it as centimetres. Measured in a room with three reflecting
            # walls (docs/marvel.md section 8): the states diverged to 13 m mean, the
            # inflation stayed at 0.7 m. The feature files' sigmas do include it.
            fusion.setdefault("multipath", "inflation")
            self.sensing = _resolve_sensing(sensing)
        else:
            sensing = sorted(set(params) & set(SENSING_DEFAULTS))
            if sensing:
                raise ValueError(f"parameter(s) {', '.join(sensing)} tune the pose sensing of a LoRa recording: give --sigmf, not features")
            fusion, self.sensing = params, None
        self.estimator = new_estimator(fusion)
        self.rows: list = []
        """The fusion's estimates of the accepted rows (:class:`scattertrack.fusion.Estimate`), in order."""

    def step(self, measurement) -> Estimate | None:
        """An :class:`ImuSample` (propagates: None) or a :class:`Feature` (the
        estimate at its time, or None when the estimator declines it)."""
        if isinstance(measurement, ImuSample):
            self.estimator.add_imu(measurement.time_s, measurement.accel, measurement.gyro, measurement.baro_z)
            return None
        if isinstance(measurement, Feature):
            fused = self.fuse(measurement)
            return None if fused is None else _estimate(fused)
        raise ValueError(f"method '{self.method}' takes ImuSample and Feature measurements, got {type(measurement).__name__}")

    def fuse(self, feature: Feature):
        """One feature row into the fusion: its :class:`scattertrack.fusion.Estimate`, or None (declined)."""
        fused = self.estimator.add_features(
            feature.time_s, feature.range_m, feature.azimuth_rad, feature.elevation_rad, feature.yaw_rad,
            feature.range_sigma_m, feature.angle_sigma_rad, feature.yaw_sigma_rad,
        )
        if fused is not None:
            self.rows.append(fused)
        return fused

    def stats(self, epc: str | None = None) -> dict:
        """The estimator's counters: epochs and IMU samples taken, declined rows and samples by reason."""
        e = self.estimator
        return {"epochs": e.epochs, "imu_samples": e.imu_samples, "declined": dict(e.declined), "imu_declined": dict(e.imu_declined)}

    def run(self, data: DroneData, *, progress: bool = False) -> Track:
        """The batch run of a fresh tracker: one track row per accepted epoch (:func:`run_features`, :func:`run_sigmf`)."""
        from scattertrack.fusion.run import ImuFeed, drive, finish_run

        if (data.recording is not None) != self.recording:
            made = "a recording (recording=True)" if self.recording else "features"
            raise ValueError(f"this {self.method} tracker was made for {made}; the data has {'a recording' if data.recording is not None else 'features'}")
        if self.recording:
            fusion = _SensingFusion(self.estimator, data.imu, add_imu=self.step, add_features=self.fuse)
            epochs = drive(
                lora_sensing.sense_epochs(data.recording, fusion, self.sensing, doppler=self.method == "marvel"),
                progress=progress,
                desc=self.method,
            )
            return _finish_recording(self.method, self.scene, data.imu, self.estimator, epochs)
        features, feed = data.features, ImuFeed(data.imu)
        order = np.argsort(features.time_s, kind="stable")

        def epochs():
            # The IMU samples at or before each row's time first, then the row (causal).
            for row in order:
                _give_imu(feed, float(features.time_s[row]), self.step)
                yield self.step(Feature(
                    features.time_s[row], features.range_m[row], features.azimuth_rad[row], features.elevation_rad[row],
                    features.yaw_rad[row], features.range_sigma_m[row], features.angle_sigma_rad[row], features.yaw_sigma_rad[row],
                ))

        drive(epochs(), progress=progress, total=len(order), desc="marvel")
        return finish_run(self.estimator, list(self.rows), self.scene, input_skips=(features.skipped, data.imu.skipped))


def _estimate(fused) -> Estimate:
    """The interface's :class:`Estimate` of a fusion estimate: covariance known on the position's diagonal only."""
    sigma = np.asarray(fused.sigma, dtype=float)
    covariance = np.full((6, 6), np.nan)
    covariance[[0, 1, 2], [0, 1, 2]] = sigma**2
    return Estimate(
        float(fused.time_s), EPC, np.asarray(fused.position, dtype=float), np.asarray(fused.velocity, dtype=float),
        covariance, orientation=np.asarray(fused.orientation, dtype=float), sigma=sigma, source=fused,
    )


def _give_imu(feed, time_s: float, add_imu) -> None:
    """Every sample of ``feed`` (:class:`scattertrack.fusion.run.ImuFeed`) at or before ``time_s`` not given yet, to ``add_imu``."""
    for i in feed.take_until(time_s):
        add_imu(ImuSample(feed.time_s[i], feed.accel[i], feed.gyro[i], feed.baro[i]))


class _SensingFusion:
    """The fusion side of the pose sensing (:class:`scattertrack.dsp.lora_sensing.Fusion`) over a
    :class:`~scattertrack.fusion.MarvelEstimator`: samples and rows go through ``add_imu``
    (an :class:`ImuSample`) and ``add_features`` (a :class:`Feature`; the estimator's by default)."""

    def __init__(self, estimator, imu: Imu, *, add_imu=None, add_features=None):
        from scattertrack.fusion.run import ImuFeed

        self.estimator = estimator
        self.feed = ImuFeed(imu)
        self._add_imu = add_imu or (lambda s: estimator.add_imu(s.time_s, s.accel, s.gyro, s.baro_z))
        self._add_features = add_features or (lambda f: estimator.add_features(*dataclasses.astuple(f)))

    @property
    def on_ground(self) -> bool:
        return self.estimator.on_ground

    @property
    def controller(self):
        return self.estimator.controller

    @property
    def velocity_covariance(self):
        return self.estimator.velocity_covariance

    def advance(self, time_s: float):
        _give_imu(self.feed, time_s, self._add_imu)
        return self.feed.gyro[self.feed.next - 1] if self.feed.next > 0 else None

    def predict(self, time_s: float):
        return self.estimator.predict(time_s)

    def predicted_range(self, predicted, centroid: np.ndarray):
        return _predicted_range(self.estimator, predicted, centroid)

    def add_features(self, *row):
        return self._add_features(Feature(*row))


def run_features(method: str, scene: Scene | None, imu: Imu, features: Features, *, progress: bool = False, **params) -> Track:
    """Fuses ``features`` (docs/formats.md 7) with ``imu`` (docs/formats.md 6): one track row per accepted epoch.

    ``params`` are :class:`scattertrack.fusion.MarvelParams` fields. Raises
    ValueError for a method outside :data:`MARVEL_METHODS`, an unknown
    parameter, or a pose-sensing parameter (those need a recording). The
    loop over :meth:`MarvelTracker.step`; the same track as
    :func:`scattertrack.fusion.run_marvel`.
    """
    return MarvelTracker(method, scene, **params).run(DroneData(imu, features), progress=progress)


def sense_epochs(
    method: str,
    recording,
    imu: Imu,
    estimator=None,
    *,
    keep_dsp: bool = False,
    **sensing,
) -> Iterator[SensedEpoch]:
    """Sense a LoRa recording epoch by epoch, fusing as it goes (:func:`scattertrack.dsp.lora_sensing.sense_epochs`).

    ``recording``: a ``.sigmf-meta`` path (streamed from a memory map) or a
    :class:`~scattertrack.io.sigmf_lora.LoraRecording`. ``imu``: the drone's
    :class:`Imu`. ``estimator``: a :class:`~scattertrack.fusion.MarvelEstimator`
    (default: a new one with default parameters); it receives every IMU
    sample up to each epoch and every sensed row, so after the loop it
    holds the fused state and its counters. ``sensing``: keys of
    :data:`SENSING_DEFAULTS`. ``keep_dsp``: attach the DSP's whole output
    dict to each :class:`SensedEpoch`. ValueError for a bad method or parameter.
    """
    _check_method(method)
    options = _resolve_sensing(sensing)
    if estimator is None:
        from scattertrack.fusion import MarvelEstimator

        estimator = MarvelEstimator()
    fusion = _SensingFusion(estimator, imu)
    yield from lora_sensing.sense_epochs(recording, fusion, options, doppler=method == "marvel", keep_dsp=keep_dsp)


def _check_method(method: str) -> None:
    if method not in MARVEL_METHODS:
        raise ValueError(f"unknown Marvel method '{method}' (known: {', '.join(MARVEL_METHODS)})")



def _resolve_sensing(params: dict) -> dict:
    """:data:`SENSING_DEFAULTS` updated by ``params``, validated (ValueError naming the parameter)."""
    unknown = sorted(set(params) - set(SENSING_DEFAULTS))
    if unknown:
        raise ValueError(f"unknown pose-sensing parameter(s): {', '.join(unknown)} (known: {', '.join(SENSING_DEFAULTS)})")
    # The table checks every value (type, range) and reads text as the
    # command line does: the same rules as every other method's parameters.
    return {**SENSING_DEFAULTS, **sensing_table().check(dict(params))}


def _split_params(params: dict) -> tuple[dict, dict]:
    """``(fusion, sensing)`` parameters; ValueError for a name that is neither."""
    from scattertrack.fusion.estimator import MarvelParams

    fusion_names = {f.name for f in dataclasses.fields(MarvelParams)}
    unknown = sorted(set(params) - fusion_names - set(SENSING_DEFAULTS))
    if unknown:
        known = ", ".join(sorted(fusion_names | set(SENSING_DEFAULTS)))
        raise ValueError(f"unknown Marvel parameter(s): {', '.join(unknown)} (known: {known})")
    fusion = {k: v for k, v in params.items() if k in fusion_names}
    sensing = {k: v for k, v in params.items() if k in SENSING_DEFAULTS}
    return fusion, sensing


def _predicted_range(estimator, predicted, centroid: np.ndarray) -> tuple[float, float] | None:
    """The fusion's predicted range (m) of the gear centre from the controller and its 1-sigma (m).

    From the IMU-propagated state (``predicted``: position, velocity,
    world_R_body) and the controller estimate, with the newest position and
    controller covariances projected on the line of sight; None before
    there is a controller or a covariance.
    """
    controller = estimator.controller
    position_cov, controller_cov = estimator.position_covariance, estimator.controller_covariance
    if predicted is None or controller is None or position_cov is None or controller_cov is None:
        return None
    gear = predicted[0] + predicted[2] @ centroid - controller
    distance = float(np.linalg.norm(gear))
    if not distance > 0.0:
        return None
    u = gear / distance
    variance = float(u @ (position_cov + controller_cov) @ u)
    if not (math.isfinite(variance) and variance > 0.0):
        return None
    return distance, math.sqrt(variance)


def _quantiles_ns(seconds) -> dict:
    values = np.asarray([s for s in seconds if math.isfinite(s)], dtype=float) * 1e9
    if not values.size:
        return {}
    return {
        "p50": float(np.percentile(values, 50)),
        "p99": float(np.percentile(values, 99)),
        "mean": float(np.mean(values)),
        "max": float(np.max(values)),
    }


def run_sigmf(method: str, scene: Scene | None, recording, imu: Imu, *, progress: bool = False, **params) -> Track:
    """Pose sensing of a LoRa recording fused with the IMU: one track row per fused epoch.

    ``recording``: a ``.sigmf-meta`` path or a
    :class:`~scattertrack.io.sigmf_lora.LoraRecording`; ``method``:
    ``marvel`` or ``ulocate`` (module docstring). ``params``: fusion
    (:class:`scattertrack.fusion.MarvelParams`) and sensing
    (:data:`SENSING_DEFAULTS`) parameters, SI units. ``scene``: its region
    refuses estimates outside it (the controller's position is estimated).
    The end of the run is :func:`scattertrack.fusion.run.finish_run`, the
    same as for features.

    The track carries orientation and 1-sigma position like
    :func:`scattertrack.fusion.run_marvel`; ``skipped`` counts the epochs the
    sensing declined and the rows and measurements the estimator declined;
    ``stats["drone"]`` has the estimator's counters, ``sensing_declined``,
    ``features`` (the sensed rows as :class:`Features`, for scoring
    snapshots), ``epochs`` (recording epochs), ``rows`` (sensed rows),
    ``clock`` (the clock error used after take-off, the rest epochs behind
    it), the DSP's and the fusion's wall time per epoch (``dsp_time_ns_p50``,
    ``dsp_time_ns_p99``, ``time_ns_p50``, ``time_ns_p99``) and their sum per
    fused epoch in ``epoch_times_ns``; ``latency_quantiles_ns`` is the
    fusion's, as for features; ``revised`` and ``smoothed`` the fixed-lag
    smoothed track, as for features.
    """
    return MarvelTracker(method, scene, recording=True, **params).run(DroneData(imu, recording=recording), progress=progress)


def _finish_recording(method: str, scene: Scene | None, imu: Imu, estimator, epochs: list[SensedEpoch]) -> Track:
    """The end of a recording's run (:func:`run_sigmf`): the fused rows, the
    sensing's declines and counters, then :func:`scattertrack.fusion.run.finish_run`."""
    from scattertrack.fusion.run import finish_run

    rows = [e.estimate for e in epochs if e.estimate is not None]

    sensing_declined = {key: 0 for key in SENSING_DECLINE_REASONS}
    for e in epochs:
        if e.declined is not None:
            sensing_declined[e.declined] += 1
    dsp = _quantiles_ns([e.dsp_time_s for e in epochs if e.declined not in ("non_finite_samples", "no_signal")])
    fused = [e for e in epochs if math.isfinite(e.fusion_time_s)]
    rest = [e for e in epochs if e.on_ground and math.isfinite(e.clock_error)]
    after = next((e for e in epochs if not e.on_ground and math.isfinite(e.clock_error)), None)
    return finish_run(
        estimator,
        rows,
        scene,
        input_skips=(imu.skipped,),
        extra_declines=((sensing_declined, SENSING_DECLINE_REASONS),),
        stats={
            "method": method,
            "epochs": len(epochs),
            "rows": sum(e.sensed for e in epochs),
            "fused": len(rows),
            "sensing_declined": sensing_declined,
            "fringe_from_timing": sum(e.fringe_from_timing for e in epochs),
            "clock": {
                "clock_error": after.clock_error if after is not None else (epochs[-1].clock_error if epochs else None),
                "rest_epochs": len(rest),
                "source": "rest" if rest else "flight",
            },
            "features": features_of(epochs),
            "snr_db": np.array([e.snr_db for e in epochs], dtype=float),
            "dsp_time_ns_p50": dsp.get("p50", float("nan")),
            "dsp_time_ns_p99": dsp.get("p99", float("nan")),
            # The DSP's and the fusion's time together, per fused epoch.
            "epoch_times_ns": np.array([(e.dsp_time_s + e.fusion_time_s) * 1e9 for e in fused], dtype=float),
        },
    )
