"""Marvel's pose sensing from a LoRa recording: epochs of backscattered
chirps to feature rows (range, direction, yaw of the drone), with the fusion
alongside.

docs/marvel.md sections 5-8. The recording (``NAME.sigmf-meta``, read by
:mod:`scattertrack.io.sigmf_lora`, or a :class:`LoraRecording` in memory) is
streamed one epoch at a time, in time order, and the fusion runs alongside,
because the sensing of an epoch needs the fusion's prediction for it:

1. The epoch's features are stamped at its reference time ``t = t_0 +
   t_ref``: the first chirp's start plus the DSP's reference time (the mean
   chirp centre, 8.192 ms after ``t_0`` with two back-to-back SF12 chirps),
   where its phases and its range refer. Every IMU sample at or before ``t``
   goes to the :class:`~scattertrack.fusion.MarvelEstimator` first.
2. **Tag clock** (paper sec. III-B, DSP note 3): while the estimator says the
   drone is still on the ground (no IMU sample has shown motion) the epochs'
   peak frequencies are collected and the tags' clock error ``eps`` (the
   CFO ``eps s_k`` of every tag) is estimated from all rest epochs so far
   (``lora_clock_error``: the two opposing pairs' means give ``eps`` and the
   common chirp timing); the rest epoch is then sensed with that estimate.
   From take-off on it is fixed. Until the estimate's uncertainty moves the
   chirp-timing range by less than ``clock_settle_m`` (or less than the
   epoch's own timing sigma, which waiting cannot reduce), rest epochs are
   sensed but not fused (counted as ``clock_unsettled``): the timing range
   picks the phase range's fringe (5.8 m apart), the first fused row places
   the controller, and a fringe error there would stay. A recording that starts in flight has no
   rest epoch: the first ``clock_flight_epochs`` epochs are used instead (the
   pair means cancel the rotational shift, and the translational one is
   common to all tags to 1 part in 900).
3. **Doppler** (``marvel``): the IMU-propagated state at ``t``
   (``MarvelEstimator.predict``) gives the velocity (m/s) and the attitude;
   the gyroscope's newest rate minus the estimated bias gives the body rate
   (rad/s), for the gear centre's lever-arm velocity and the heading; the
   direction is this epoch's own MUSIC angle (which needs no Doppler
   correction: the ramps are common to the antennas) unless
   ``doppler_direction`` says otherwise. ``ulocate`` removes no Doppler
   (``ignore_doppler``) and reports no heading.
4. The Rust ``LoraEpochProcessor`` senses the epoch: the range and the
   direction of the **tags' centroid** (the landing-gear centre, body
   ``c = (0, 0, -0.30)`` m) from the array centre, the yaw.
5. **Lever arm**: the feature row is about the body origin, so ``r u_body =
   r_c u_c - R c`` with the predicted attitude ``R`` (identity before the
   first estimate: the drone rests level on the ground); range ``|r u|``,
   azimuth and elevation of ``u`` in the world frame (docs/formats.md section 7).
6. **Sigmas**: range = the DSP's range sigma and ``range_sigma_floor_m`` in
   quadrature; angle = the phase-noise bound of the array (the DSP's phase
   sigmas over the 8 channels and the antennas' spread along each tangent
   axis) and ``angle_sigma_floor_rad``; yaw = the DSP's and
   ``yaw_sigma_floor_rad``. The floors stand for what the thermal bounds
   leave out (multipath, the signal model's small approximations).
7. The row goes to ``MarvelEstimator.add_features``.

Declined epochs never vanish: :func:`sense_epochs` yields every epoch, a
declined one with the reason (a key of :data:`SENSING_DECLINE_REASONS`),
which the runner counts in ``Track.skipped``.

The fusion is reached through :class:`Fusion` only (this layer is below
:mod:`scattertrack.fusion` and :mod:`scattertrack.track`, and imports
neither): the runner, :mod:`scattertrack.track.marvel`, passes one in.

Units: SI throughout (s, m, m/s, rad, rad/s, Hz, dB where named).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from scattertrack.io.types import Features
from scattertrack.physics import SPEED_OF_LIGHT

SENSING_DECLINE_REASONS = {
    "non_finite_samples": "LoRa epoch with non-finite samples (declined)",
    "no_signal": "LoRa epoch with a chirp of all-zero samples (declined)",
    "clock_unsettled": "LoRa epoch at rest before the tags' clock error settled (sensed, not fused)",
    "fringe_unsettled": "LoRa epoch at rest before the rest epochs' timing ranges settled the range fringe (sensed, not fused)",
    "low_snr": "LoRa epoch below the decoding SNR (declined)",
    "dsp_error": "LoRa epoch the pose-sensing DSP could not process (declined)",
    "no_range": "LoRa epoch without a range (declined)",
    "non_finite_features": "LoRa epoch with a non-finite or zero range, or a non-finite angle (declined)",
}
"""Why the pose sensing declines an epoch: counter key -> the text in ``Track.skipped``."""



class Fusion(Protocol):
    """What the sensing asks of the fusion running alongside it (world frame, SI units)."""

    on_ground: bool
    """The drone still rests on the ground (no IMU sample has shown motion)."""
    controller: np.ndarray | None
    """The controller's estimated position, (3,) m; None before the first estimate."""
    velocity_covariance: np.ndarray | None
    """(3, 3) covariance of the newest velocity, m²/s²; None before the first estimate."""

    def advance(self, time_s: float) -> np.ndarray | None:
        """Gives the fusion every IMU sample at or before ``time_s`` (s) not given yet;
        returns the newest gyroscope rate given so far, (3,) rad/s (None before any)."""

    def predict(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The IMU-propagated state at ``time_s``: position m, velocity m/s, world_R_body; None before the first row."""

    def predicted_range(self, predicted, centroid: np.ndarray) -> tuple[float, float] | None:
        """The predicted range (m) of the body point ``centroid`` from the controller and its 1-sigma (m), or None."""

    def add_features(self, time_s, range_m, azimuth_rad, elevation_rad, yaw_rad, range_sigma_m, angle_sigma_rad, yaw_sigma_rad):
        """Fuses one feature row; the estimate (with ``wall_time_s`` and ``gyro_bias``) or None when declined."""


@dataclass
class SensedEpoch:
    """What :func:`sense_epochs` yields for one epoch of the recording (SI units)."""

    index: int
    """The epoch's index in the recording."""
    time_s: float
    """The feature row's time: the first chirp's start plus the DSP's reference time, s."""
    declined: str | None
    """None, or the key of :data:`SENSING_DECLINE_REASONS` that declined the epoch."""
    range_m: float = float("nan")
    """Body origin's range from the array centre, m (after the lever arm)."""
    azimuth_rad: float = float("nan")
    elevation_rad: float = float("nan")
    """Direction of the body origin from the array centre, world frame, rad."""
    yaw_rad: float = float("nan")
    range_sigma_m: float = float("nan")
    angle_sigma_rad: float = float("nan")
    yaw_sigma_rad: float = float("nan")
    centroid_range_m: float = float("nan")
    """The DSP's range of the tags' centroid, m (before the lever arm)."""
    centroid_direction: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    """The DSP's unit direction to the tags' centroid, world frame."""
    snr_db: float = float("nan")
    """Mean per-sample SNR of the epoch's peaks, dB (nan when not processed)."""
    on_ground: bool = False
    """Whether the estimator still had the drone at rest on the ground (a clock-error epoch)."""
    fringe_from_timing: bool = False
    """In flight: the fusion's predicted range contradicted the timing range,
    which alone picked the fringe (``fringe_consistency_sigmas``)."""
    clock_error: float = float("nan")
    """The tags' clock error used for this epoch (dimensionless, cfo_k = eps s_k)."""
    dsp_time_s: float = 0.0
    """Wall time in the DSP for this epoch (both passes on the ground), s."""
    fusion_time_s: float = float("nan")
    """Wall time of ``add_features`` for this row, s (nan when not fused)."""
    estimate: object = None
    """The estimator's :class:`~scattertrack.fusion.Estimate` of the row, or None (declined, or not fused)."""
    dsp: dict | None = None
    """The DSP's whole output for the epoch, when ``keep_dsp`` was asked."""

    @property
    def accepted(self) -> bool:
        """Sensed and given to the fusion."""
        return self.declined is None

    @property
    def sensed(self) -> bool:
        """Has a feature row (given to the fusion, or held back while the clock error settled)."""
        return self.declined in (None, "clock_unsettled", "fringe_unsettled")


class _Recording:
    """A recording as metadata plus an epoch iterator (memory map for a file: bounded memory)."""

    def __init__(self, recording):
        from scattertrack.io.sigmf_lora import LoraEpoch, LoraRecording, open_lora_sigmf

        if isinstance(recording, LoraRecording):
            self.metadata = recording.metadata
            self.n_epochs = recording.n_epochs
            self.source = "<LoraRecording>"

            def epochs():
                for e in range(recording.n_epochs):
                    yield LoraEpoch(e, float(recording.epoch_time_s[e]), np.asarray(recording.chirp_start_s[e]),
                                    recording.samples[e])

            self._epochs = epochs
        else:
            handle = open_lora_sigmf(recording)
            self.metadata = handle.metadata
            self.n_epochs = handle.n_epochs
            self.source = str(handle.meta_path)
            self._epochs = lambda: iter(handle)

    def __iter__(self):
        return self._epochs()


class _Sensor:
    """The DSP configured from a recording's metadata, one processor per chirp layout."""

    def __init__(self, metadata: dict, ignore_doppler: bool, source: str):
        from scattertrack import _core

        self._core = _core
        frequencies = np.asarray(metadata["channel_frequencies_hz"], dtype=float)
        excitation = [int(i) for i in metadata["excitation_channels"]]
        shifts = [float(s) for s in metadata["tag_shifts_hz"]]
        if len(excitation) != 2 or len(shifts) != 4:
            raise ValueError(
                f"{source}: the pose sensing takes 2 excitation channels x 4 tags (docs/marvel.md sections 2 and 5), "
                f"this recording has {len(excitation)} x {len(shifts)}"
            )
        self.tags = np.asarray(metadata["tag_body_positions_m"], dtype=float)  # (4, 3) body m
        self.centroid = self.tags.mean(axis=0)  # body m: the landing-gear centre
        self.elements = np.asarray(metadata["array_offsets_m"], dtype=float)  # (M, 3) world m
        offsets = np.asarray(metadata["rx_phase_offsets_rad"], dtype=float)  # (J, K, M)
        antennas = self.elements.shape[0]
        self.options = {
            "spreading_factor": int(metadata["spreading_factor"]),
            "bandwidth_hz": float(metadata["bandwidth_hz"]),
            "channels_hz": (float(frequencies[excitation[0]]), float(frequencies[excitation[1]])),
            "tag_shifts_hz": shifts,
            "tag_positions": self.tags,
            "array_elements": self.elements,
            # The DSP wants (antenna, received channel j * 4 + k).
            "calibration_rad": np.ascontiguousarray(np.transpose(offsets, (2, 0, 1)).reshape(antennas, -1)),
            "ignore_doppler": ignore_doppler,
        }
        self.shifts = np.asarray(shifts)
        self.carriers = np.add.outer(np.asarray(self.options["channels_hz"]), self.shifts / 2.0)  # (2, 4) Hz
        # Half the spacing of the phase range's fringes, m: one tag's two
        # carriers repeat every c / (2 |f_1 - f_0|) of range (5.78 m for 25.9 MHz).
        spacing = abs(self.options["channels_hz"][1] - self.options["channels_hz"][0])
        self.half_fringe_m = 0.25 * SPEED_OF_LIGHT / spacing if spacing > 0.0 else math.inf
        self._processors: dict[tuple[float, float], object] = {}

    def processor(self, chirp_offsets_s) -> object:
        """The processor for chirps starting ``chirp_offsets_s`` (s) after the epoch's origin (cached per layout)."""
        key = tuple(round(float(v), 9) for v in chirp_offsets_s)
        if key not in self._processors:
            self._processors[key] = self._core.LoraEpochProcessor(chirp_starts_s=key, **self.options)
        return self._processors[key]

    def angle_sigma(self, phase_sigma_rad: np.ndarray, direction: np.ndarray) -> float:
        """Phase-noise bound of the direction along each tangent axis (RMS of the two), rad.

        ``lambda / (2 pi) sigma_phi / sqrt(N sum_m (e . x_m)^2)`` over the
        ``N`` = 8 received channels, ``x_m`` the antennas' offsets from their
        centroid, ``e`` the azimuth and elevation tangents of ``direction``
        (the bound docs/marvel.md section 9 uses). An axis the array cannot
        see (endfire) is floored at a projection of 1 cm.
        """
        sigma_phi = float(np.sqrt(np.mean(np.square(phase_sigma_rad))))
        u = direction / np.linalg.norm(direction)
        azimuth, elevation = math.atan2(u[1], u[0]), math.asin(max(-1.0, min(1.0, u[2])))
        e_az = np.array([-math.sin(azimuth), math.cos(azimuth), 0.0])
        e_el = np.array([-math.sin(elevation) * math.cos(azimuth), -math.sin(elevation) * math.sin(azimuth),
                         math.cos(elevation)])
        centred = self.elements - self.elements.mean(axis=0)
        wavelength = SPEED_OF_LIGHT / float(self.carriers.mean())
        channels = self.carriers.size
        sigmas = []
        for axis in (e_az, e_el):
            aperture = max(float(np.sum((centred @ axis) ** 2)), 1e-4)
            sigmas.append(wavelength / (2.0 * math.pi) * sigma_phi / math.sqrt(channels * aperture))
        return float(min(math.sqrt(0.5 * (sigmas[0] ** 2 + sigmas[1] ** 2)), math.pi / 2.0))



def _spread(value) -> float:
    """A DSP consistency spread (m or rad) as a sigma share: 0 when the DSP had none (fewer than two tags or groups)."""
    return float(value) if value is not None and math.isfinite(value) and value > 0.0 else 0.0


def _rest_rows(frequency_hz: np.ndarray, snr_db: np.ndarray | None = None, min_snr_db: float = -math.inf) -> np.ndarray:
    """The DSP's peak frequencies (2, 4, M) Hz as ``lora_clock_error`` rows (2 M, 4): one per (channel, antenna).

    With ``snr_db`` (2, 4, M, per-sample dB) only the rows whose four peaks
    are all at least ``min_snr_db``: a tag in a multipath fade on one antenna
    reads noise there, its peak anywhere in +-250 kHz, and one such row made
    the least-squares clock error a thousand times too large (a reflecting
    room, docs/marvel.md section 11).
    """
    rows = np.transpose(frequency_hz, (0, 2, 1)).reshape(-1, frequency_hz.shape[1])
    if snr_db is None:
        return rows
    clear = np.all(np.transpose(snr_db, (0, 2, 1)).reshape(-1, snr_db.shape[1]) >= min_snr_db, axis=1)
    return rows[clear]



def sense_epochs(
    recording,
    fusion: Fusion,
    options: dict,
    *,
    doppler: bool = True,
    keep_dsp: bool = False,
) -> Iterator[SensedEpoch]:
    """Sense a LoRa recording epoch by epoch, fusing as it goes (module docstring, steps 1-7).

    ``recording``: a ``.sigmf-meta`` path (streamed from a memory map) or a
    :class:`~scattertrack.io.sigmf_lora.LoraRecording`. ``fusion``: the
    estimator's side (:class:`Fusion`); it receives every IMU sample up to
    each epoch and every sensed row, so after the loop it holds the fused
    state and its counters. ``options``: every pose-sensing parameter,
    checked (``scattertrack.track.marvel_params.SENSING_DEFAULTS`` and the
    caller's values). ``doppler``: remove the Doppler shift with the fused
    velocity and report the heading (``marvel``); False takes the channel
    phases as they come (``ulocate``). ``keep_dsp``: attach the DSP's whole
    output dict to each :class:`SensedEpoch`.

    Yields one :class:`SensedEpoch` per epoch of the recording, in time
    order, declined ones included. Causal: an epoch's row uses only samples
    and IMU data at or before its time. Raises FormatError for a bad
    recording (:mod:`scattertrack.io.sigmf_lora`).
    """
    source = _Recording(recording)
    sensor = _Sensor(source.metadata, ignore_doppler=not doppler, source=source.source)
    core = sensor._core
    shifts = [float(s) for s in sensor.shifts]

    rest_rows: list[np.ndarray] = []  # peak rows for the clock error
    flight_rows: list[np.ndarray] = []
    clock_error = 0.0
    clock_fixed = False
    previous_direction: np.ndarray | None = None
    gyro_bias = np.zeros(3)
    marvel = doppler

    # Range (m) per unit of clock error: the timing term's CFO is eps times
    # the mean shift (Hz), the chirp rate BW / T turns hertz into delay.
    chirp_rate = float(source.metadata["bandwidth_hz"]) ** 2 / 2 ** int(source.metadata["spreading_factor"])
    range_per_clock_error = 0.5 * SPEED_OF_LIGHT * float(np.mean(sensor.shifts)) / chirp_rate
    # Range (m) per m/s of radial velocity: the translational Doppler 2 f v / c0
    # removed from the timing term moves it by f / (BW / T) (about 15 m per m/s
    # at 915 MHz, BW 500 kHz, SF12): an error of the fused velocity along the
    # line of sight biases the timing range (and so the fringe) by that much.
    range_per_velocity = float(np.mean(sensor.carriers)) / chirp_rate
    clock_range_sigma = math.inf  # m, the clock error's share of the timing range's sigma
    rest_timing = [0.0, 0.0]  # sum of 1/sigma^2 and of range/sigma^2 of the rest epochs' timing ranges (m^-2, m^-1)

    def estimate_clock(rows: list[np.ndarray]) -> float:
        nonlocal clock_range_sigma
        fit = core.lora_clock_error(np.concatenate(rows), tag_shifts_hz=shifts)
        clock_range_sigma = math.inf if fit["sigma"] is None else range_per_clock_error * float(fit["sigma"])
        return float(fit["clock_error"])

    for epoch in source:
        processor = sensor.processor(np.asarray(epoch.chirp_start_s, dtype=float) - epoch.time_s)
        time_s = float(epoch.time_s + processor.reference_time_s)
        # Every IMU sample at or before the epoch's time first (causal).
        newest_gyro = fusion.advance(time_s)
        on_ground = fusion.on_ground
        # Which peak rows this epoch adds to the clock error (None: it is fixed).
        collect = None
        if on_ground:
            collect = rest_rows
        elif not clock_fixed:
            if rest_rows:
                clock_error, clock_fixed = estimate_clock(rest_rows), True
            elif len(flight_rows) < options["clock_flight_epochs"]:
                collect = flight_rows
            else:
                clock_fixed = True
        sensed = SensedEpoch(index=int(epoch.index), time_s=time_s, declined=None, on_ground=on_ground)

        samples = np.ascontiguousarray(epoch.samples, dtype=np.complex64)
        if not np.all(np.isfinite(samples.view(np.float32))):
            sensed.declined = "non_finite_samples"
            yield sensed
            continue
        if np.any(np.max(np.abs(samples.view(np.float32)), axis=-1) == 0.0):  # per chirp
            sensed.declined = "no_signal"
            yield sensed
            continue

        # Corrections: the IMU-propagated state at the epoch (None before the first row).
        predicted = fusion.predict(time_s)
        attitude = predicted[2] if predicted is not None else None
        omega = None
        if newest_gyro is not None:
            omega = newest_gyro - gyro_bias
        corrections: dict = {"epoch_time_s": float(epoch.time_s)}
        if marvel:
            velocity = np.asarray(predicted[1], dtype=float) if predicted is not None else np.zeros(3)
            speed = float(np.linalg.norm(velocity))
            if not math.isfinite(speed):
                velocity = np.zeros(3)
            elif speed > options["max_doppler_speed_m_s"]:
                velocity = velocity * (options["max_doppler_speed_m_s"] / speed)
            corrections["velocity"] = velocity
            if attitude is not None and omega is not None:
                corrections["attitude"] = np.ascontiguousarray(attitude)
                corrections["omega_body"] = np.ascontiguousarray(omega, dtype=float)
            direction = None
            if options["doppler_direction"] == "previous":
                direction = previous_direction
            elif options["doppler_direction"] == "predicted" and predicted is not None and fusion.controller is not None:
                gear = predicted[0] + predicted[2] @ sensor.centroid - fusion.controller
                direction = gear / np.linalg.norm(gear)
            if direction is not None:
                corrections["direction"] = np.asarray(direction, dtype=float)

        started = time.perf_counter()
        try:
            result = processor.process(samples, clock_error=clock_error, **corrections)
            if collect is not None and result["mean_snr_db"] >= options["min_snr_db"]:
                # The clock error from every collected epoch so far, this one
                # included (its peaks do not depend on the corrections), then
                # this epoch again with it. An epoch below the decoding SNR
                # would add noise peaks: it is left out (and declined below).
                rows = _rest_rows(np.asarray(result["frequency_hz"]), np.asarray(result["snr_db"]), options["min_snr_db"])
                if len(rows):
                    collect.append(rows)
                if collect:
                    clock_error = estimate_clock(collect)
                result = processor.process(samples, clock_error=clock_error, **corrections)
        except core.DspError:
            sensed.dsp_time_s = time.perf_counter() - started
            sensed.declined = "dsp_error"
            yield sensed
            continue
        sensed.dsp_time_s = time.perf_counter() - started
        sensed.clock_error = clock_error
        sensed.snr_db = float(result["mean_snr_db"])
        if keep_dsp:
            sensed.dsp = result
        if not sensed.snr_db >= options["min_snr_db"]:
            sensed.declined = "low_snr"
            yield sensed
            continue
        if result["range_m"] is None:
            sensed.declined = "no_range"
            yield sensed
            continue
        centroid_range = float(result["range_m"])
        u_centroid = np.asarray(result["direction"], dtype=float)
        if not (math.isfinite(centroid_range) and centroid_range > 0.0 and np.all(np.isfinite(u_centroid))):
            sensed.declined = "non_finite_features"
            yield sensed
            continue
        u_centroid = u_centroid / np.linalg.norm(u_centroid)
        previous_direction = u_centroid
        # Settled: the clock's share of the timing range's uncertainty is
        # below clock_settle_m or below the epoch's own (thermal) share, which
        # no wait can reduce (at 50 m or through walls the latter is metres).
        own_sigma = result["timing_range_sigma_m"]
        own_sigma = float(own_sigma) if own_sigma is not None and math.isfinite(own_sigma) else 0.0
        unsettled = collect is not None and not clock_range_sigma <= max(options["clock_settle_m"], own_sigma)

        # Fringe (docs/marvel.md section 7, step 4): the phases place the range
        # to centimetres within the fringe (2 x half_fringe_m apart) the DSP's
        # timing range picked. The timing range's sigma has a thermal, a clock
        # and — for marvel — a Doppler share: the fused velocity's uncertainty
        # along the line of sight times range_per_velocity (about 15 m per m/s;
        # with the yaw still loose, |v| sigma_yaw across the track). The
        # fusion's own predicted range of the gear centre is a second opinion
        # that does not depend on the Doppler; the fringe nearest to the two
        # combined (inverse-variance) is taken. Without the prior, a radial
        # velocity error of 0.4 m/s picks a wrong fringe, the wrong range pulls
        # the yaw and the velocity, and the next epochs' Doppler picks wrong
        # fringes in turn (measured: a steady 2-fringe, 11.8 m, error at 30 m).
        timing_sigma = math.hypot(own_sigma, clock_range_sigma if math.isfinite(clock_range_sigma) else 0.0)
        fringe_sigma = timing_sigma
        fringe_unsettled = False
        if marvel:
            velocity_cov = fusion.velocity_covariance
            if velocity_cov is not None:
                radial_var = float(u_centroid @ velocity_cov @ u_centroid)
                if math.isfinite(radial_var) and radial_var > 0.0:
                    timing_sigma = math.hypot(timing_sigma, range_per_velocity * math.sqrt(radial_var))
            fringe_sigma = timing_sigma
            prior = fusion.predicted_range(predicted, sensor.centroid)
            timing_range = result.get("timing_range_m")
            usable = timing_range is not None and math.isfinite(timing_range) and timing_sigma > 0.0
            if usable and on_ground:
                # At rest the range does not change: the timing ranges of all
                # rest epochs so far average (inverse variance) to the fringe
                # choice. The fusion's prediction is no second opinion yet — it
                # was built from these same rows.
                # Each was computed with the clock error of its time; the
                # timing range grows by range_per_clock_error per unit of clock
                # error (the CFO eps s_k is subtracted from the tone), so the
                # sums keep the clock-free part and the newest clock error is
                # added back: early epochs' worse clock estimates do not bias it.
                rest_timing[0] += 1.0 / timing_sigma**2
                rest_timing[1] += (timing_range - range_per_clock_error * clock_error) / timing_sigma**2
                centre = rest_timing[1] / rest_timing[0] + range_per_clock_error * clock_error
                fringe_sigma = 1.0 / math.sqrt(rest_timing[0])
                fringe = 2.0 * sensor.half_fringe_m
                centroid_range += round((centre - centroid_range) / fringe) * fringe
                # Until the fringe is settled (3 sigma inside half a fringe) a
                # rest row is not fused: the first fused rows place the
                # controller, and a later change of fringe would be a 5.8 m
                # jump of a range the ground factors do not let the drone follow.
                fringe_unsettled = 3.0 * fringe_sigma > sensor.half_fringe_m
            elif usable and prior is not None:
                predicted_range, predicted_sigma = prior
                fringe = 2.0 * sensor.half_fringe_m
                disagreement = abs(predicted_range - timing_range) / math.hypot(timing_sigma, predicted_sigma)
                if disagreement <= options["fringe_consistency_sigmas"]:
                    weights = (1.0 / timing_sigma**2, 1.0 / predicted_sigma**2)
                    centre = (weights[0] * timing_range + weights[1] * predicted_range) / sum(weights)
                    fringe_sigma = 1.0 / math.sqrt(sum(weights))
                else:
                    # The two opinions contradict each other: the fusion's
                    # prediction is the one that can be wrong by many fringes
                    # (a diverging state picks fringes that confirm it, the
                    # measured runaway was one fringe per second to 50 m in a
                    # room with reflecting walls); the timing range is this
                    # epoch's own, at worst a fringe or so off. It alone
                    # picks the fringe, and the row says so in its sigma.
                    centre = timing_range
                    fringe_sigma = timing_sigma
                    sensed.fringe_from_timing = True
                centroid_range += round((centre - centroid_range) / fringe) * fringe

        # Lever arm: the DSP sees the gear centre, the row is about the body origin.
        rotation = attitude if attitude is not None else np.eye(3)
        body = centroid_range * u_centroid - rotation @ sensor.centroid
        range_m = float(np.linalg.norm(body))
        sensed.centroid_range_m = centroid_range
        sensed.centroid_direction = u_centroid
        sensed.range_m = range_m
        sensed.azimuth_rad = math.atan2(body[1], body[0])
        sensed.elevation_rad = math.asin(max(-1.0, min(1.0, body[2] / range_m)))
        dsp_range_sigma = result["range_sigma_m"]
        dsp_range_sigma = float(dsp_range_sigma) if dsp_range_sigma is not None and math.isfinite(dsp_range_sigma) else 0.0
        sensed.range_sigma_m = math.hypot(dsp_range_sigma, options["range_sigma_floor_m"])
        sensed.angle_sigma_rad = math.hypot(
            sensor.angle_sigma(np.asarray(result["phase_sigma_rad"], dtype=float), u_centroid),
            options["angle_sigma_floor_rad"],
        )
        if options["consistency_sigmas"]:
            sensed.range_sigma_m = math.hypot(sensed.range_sigma_m, _spread(result.get("range_spread_m")))
            sensed.angle_sigma_rad = math.hypot(sensed.angle_sigma_rad, _spread(result.get("angle_spread_rad")))
        if 3.0 * fringe_sigma > sensor.half_fringe_m:
            sensed.range_sigma_m = max(sensed.range_sigma_m, fringe_sigma)
        if marvel and result["yaw"] is not None and math.isfinite(result["yaw"]):
            sensed.yaw_rad = float(result["yaw"])
            yaw_sigma = result["yaw_sigma_rad"]
            yaw_sigma = float(yaw_sigma) if yaw_sigma is not None and math.isfinite(yaw_sigma) else 0.0
            sensed.yaw_sigma_rad = math.hypot(yaw_sigma, options["yaw_sigma_floor_rad"])
        if unsettled or fringe_unsettled:
            sensed.declined = "clock_unsettled" if unsettled else "fringe_unsettled"
            yield sensed
            continue

        estimate = fusion.add_features(
            time_s, sensed.range_m, sensed.azimuth_rad, sensed.elevation_rad, sensed.yaw_rad,
            sensed.range_sigma_m, sensed.angle_sigma_rad, sensed.yaw_sigma_rad,
        )
        sensed.estimate = estimate
        if estimate is not None:
            sensed.fusion_time_s = float(estimate.wall_time_s)
            gyro_bias = np.asarray(estimate.gyro_bias, dtype=float)
        yield sensed



def features_of(epochs: list[SensedEpoch]) -> Features:
    """The sensed rows (body origin, docs/formats.md section 7) as :class:`Features`: the epochs given
    to the fusion and those held back at rest while the clock error settled."""
    kept = [e for e in epochs if e.sensed]

    def column(name):
        return np.array([getattr(e, name) for e in kept], dtype=float)

    return Features(
        time_s=column("time_s"),
        range_m=column("range_m"),
        azimuth_rad=column("azimuth_rad"),
        elevation_rad=column("elevation_rad"),
        yaw_rad=column("yaw_rad"),
        range_sigma_m=column("range_sigma_m"),
        angle_sigma_rad=column("angle_sigma_rad"),
        yaw_sigma_rad=column("yaw_sigma_rad"),
    )

