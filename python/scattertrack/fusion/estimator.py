"""Causal backscatter-inertial estimator on a GTSAM fixed-lag smoother (paper sec. IV).

One state per sensing epoch k: ``X(k)`` pose (world_T_body), ``V(k)``
velocity (m/s, world), ``B(k)`` IMU biases, ``O(k)`` the barometer's offset
(m, when a barometer is used), ``M(k)`` the features' multipath errors
(range m, direction's two tangent components rad; ``multipath = "states"``),
and one ``L(0)``: the controller's position
``rho`` (m, world). Between epochs the IMU samples are preintegrated into one
``CombinedImuFactor`` (eq. 13, with the bias random walk inside); each
feature row adds range, direction and yaw factors (eq. 12, see
:mod:`scattertrack.fusion.factors`). An ``IncrementalFixedLagSmoother``
(iSAM2 that marginalises states older than the lag) solves eq. 10; the
controller's time stamp is renewed every epoch so it is never marginalised.

Causality: :meth:`MarvelEstimator.add_features` returns the smoother's
estimate of the newest state right after the update with that row, using
only IMU samples and rows given before (at or before its time).

Revised (fixed-lag smoothed) estimates: every state stays in the window for
``smoother_lag_s`` to ``smoother_lag_s + marginalize_every_s`` (states leave
in groups, once per ``marginalize_every_s``) and is revised by each later
row until it leaves. :attr:`MarvelEstimator.revised` collects each state as
last revised, just before the update that marginalises it (and the rest at
:meth:`finish`): a track delayed by the lag that uses the rows of at least
the lag after each state. A state whose smoother failed before it left
keeps its causal estimate (counted in ``revised_fallbacks``).
"""

from __future__ import annotations

import math
import statistics
import time
from collections import deque
from dataclasses import dataclass, field

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, M, O, V, X

from scattertrack.fusion import divergence, factors, rest
from scattertrack.fusion.ground import GroundPhase
from scattertrack.fusion.keys import CONTROLLER, RANGE_BIAS
from scattertrack.fusion.latency import Latency
from scattertrack.fusion.params import GRAVITY_M_S2, MarvelParams
from scattertrack.fusion.restart import Diverged, Restarts
from scattertrack.fusion.revised import RevisedTrack, _quaternion, _world_position_covariance


# Reasons a feature row (or one of its measurements) is declined; the keys
# are the counters in ``MarvelEstimator.declined``, the values the text of
# ``Track.skipped``.
DECLINE_REASONS = {
    "non_finite": "feature row with a non-finite time, range or angle (declined)",
    "before_imu": "feature row before the first IMU sample (declined)",
    "not_after_previous": "feature row not after the previous epoch (declined)",
    "too_close": "feature row within min_epoch_interval_s of the previous epoch (declined)",
    "before_latest_imu": "feature row older than an IMU sample already integrated (declined)",
    "range_gate": "range outside the innovation gate (declined)",
    "direction_gate": "direction outside the innovation gate (declined)",
    "yaw_gate": "yaw outside the innovation gate (declined)",
    "solver_failure": "feature row on which the smoother's linear system failed (declined; smoother restarted)",
    "diverged": "feature row whose solve left the physical bounds, max_speed_m_s, max_controller_range_m or max_position_m (refused; smoother restarted from the features)",
    "persistently_gated": "feature row after persistent gating (divergence_gated_fraction of divergence_window_epochs; declined; smoother restarted from the features)",
}


# IMU samples the estimator ignores, counted in ``MarvelEstimator.imu_declined``.
IMU_DECLINE_REASONS = {
    "non_finite": "IMU sample with a non-finite time, force or rate (ignored)",
    "not_after_previous": "IMU sample not after the previous one (ignored)",
}


@dataclass
class Estimate:
    """The estimate of one sensing epoch (world frame, SI units)."""

    time_s: float
    position: np.ndarray
    """Body origin, (3,) m."""
    velocity: np.ndarray
    """(3,) m/s."""
    orientation: np.ndarray
    """world_T_body quaternion ``(qw, qx, qy, qz)``, ``qw >= 0``."""
    sigma: np.ndarray
    """1-sigma position along the world axes, (3,) m; nan when not computed."""
    controller: np.ndarray
    """Controller position ``rho``, (3,) m."""
    controller_sigma: np.ndarray
    """1-sigma of ``rho`` along the world axes, (3,) m; nan when not computed."""
    accel_bias: np.ndarray
    """(3,) m/s^2."""
    gyro_bias: np.ndarray
    """(3,) rad/s."""
    used: dict = field(default_factory=dict)
    """Which measurements of the row entered the graph: ``range``, ``direction``, ``yaw``, ``baro``."""
    wall_time_s: float = float("nan")
    """Wall time spent in :meth:`MarvelEstimator.add_features` for this row, s."""


def chi_square_gate(probability: float, dof: int) -> float:
    """Chi-square quantile for 1 or 2 degrees of freedom (closed forms, no scipy).

    1 dof: the square of the two-sided normal quantile; 2 dof: the
    exponential distribution, ``-2 ln(1 - P)``.
    """
    if dof == 1:
        return statistics.NormalDist().inv_cdf(0.5 + 0.5 * probability) ** 2
    if dof == 2:
        return -2.0 * math.log1p(-probability)
    raise ValueError("chi_square_gate: only 1 or 2 degrees of freedom")


def tilt_from_specific_force(specific_force) -> tuple[float, float]:
    """Roll and pitch (rad) of a body at rest from its accelerometer (m/s^2).

    At rest ``f = R^T (0, 0, g)``; with ``R = Rz(yaw) Ry(pitch) Rx(roll)``
    that is ``g (-sin pitch, cos pitch sin roll, cos pitch cos roll)``.
    """
    f = np.asarray(specific_force, dtype=float)
    return math.atan2(f[1], f[2]), math.atan2(-f[0], math.hypot(f[1], f[2]))


def _finite_or(value: float, default: float) -> float:
    return float(value) if value is not None and math.isfinite(value) and value > 0.0 else default


class MarvelEstimator(GroundPhase, Restarts, RevisedTrack):
    """Causal backscatter-inertial fusion: feed IMU samples and feature rows in time order.

    ``add_imu`` for every IMU sample, ``add_features`` for every feature row
    (after the IMU samples at or before its time); the latter returns the
    :class:`Estimate` of that epoch, or ``None`` when the row is declined
    (counted in :attr:`declined`).
    """

    def __init__(self, params: MarvelParams | None = None, **kwargs):
        if params is None:
            params = MarvelParams.from_kwargs(**kwargs)
        elif kwargs:
            raise ValueError("pass either a MarvelParams or keyword parameters, not both")
        self.params = params
        self.declined: dict[str, int] = {key: 0 for key in DECLINE_REASONS}
        self.epochs = 0
        self.wall_times_s: list[float] = []
        self.cpu_times_s: list[float] = []
        """Thread CPU time per accepted row, s (see :mod:`scattertrack.fusion.latency`)."""
        self.imu_samples = 0
        self.imu_wall_time_s = 0.0
        """Wall time spent in :meth:`add_imu`, all samples together, s."""
        self.imu_declined: dict[str, int] = {key: 0 for key in IMU_DECLINE_REASONS}

        p = params
        # Preintegration: continuous-time densities squared (GTSAM divides by
        # dt when it discretises); gravity along -z (MakeSharedU).
        self._imu_params = gtsam.PreintegrationCombinedParams.MakeSharedU(p.gravity_m_s2)
        eye = np.eye(3)
        self._imu_params.setAccelerometerCovariance(eye * (p.accel_noise_density * p.imu_noise_scale) ** 2)
        self._imu_params.setGyroscopeCovariance(eye * (p.gyro_noise_density * p.imu_noise_scale) ** 2)
        self._imu_params.setBiasAccCovariance(eye * p.accel_bias_random_walk**2)
        self._imu_params.setBiasOmegaCovariance(eye * p.gyro_bias_random_walk**2)
        self._imu_params.setIntegrationCovariance(eye * p.integration_sigma**2)
        self._preintegrated = gtsam.PreintegratedCombinedMeasurements(self._imu_params)

        self._smoother = self._new_smoother()

        self._gate = (
            {1: chi_square_gate(p.gate_probability, 1), 2: chi_square_gate(p.gate_probability, 2)}
            if p.gate_probability and p.gate_probability > 0.0
            else None
        )

        # IMU stream: the newest sample (time s, specific force m/s^2, rate
        # rad/s) and the time the preintegration has reached.
        self._first_imu_time: float | None = None
        self._last_sample: tuple[float, np.ndarray, np.ndarray] | None = None
        self._integrated_to: float | None = None
        self._tilt_sum = np.zeros(3)
        self._tilt_count = 0
        self._baro: deque[tuple[float, float]] = deque()

        # Graph state.
        self._key = -1  # index of the newest state, -1 before take-off
        self._last_epoch_time: float | None = None
        self._nav: gtsam.NavState | None = None  # newest state's estimate
        self._bias = gtsam.imuBias.ConstantBias()
        self._controller: np.ndarray | None = None
        self._baro_chain = False  # O(k) exists for the newest state
        self._baro_key = -1  # index k of the newest O(k)
        self._baro_time = float("nan")
        self._baro_offset = 0.0
        self._range_bias = 0.0  # estimate of the constant range bias, m
        self._multipath_chain = False  # M(k) exists for the newest state
        self._multipath_key = -1  # index k of the newest M(k)
        self._multipath = np.zeros(3)  # its estimate: range m, direction tangent rad
        self._multipath_sigma = np.ones(3)  # its stationary 1-sigma
        self._cov_position = np.full((3, 3), np.nan)  # world, m^2
        self._cov_velocity = np.full((3, 3), np.nan)
        self._cov_yaw = float("nan")
        self._cov_controller = np.full((3, 3), np.nan)
        self._declined_run = 0
        self._range_declined_run = 0
        self.restarts = 0
        """Times the smoother was restarted after a solver failure."""
        # The states in the smoother's window: key -> (time stamp s, causal Estimate).
        self._window: dict[int, tuple[float, Estimate]] = {}
        # Revised rows read ahead of their bucket's marginalisation (see _prefetch).
        self._prefetched: dict[int, Estimate] = {}
        self._lag = p.smoother_lag_s  # the smoother's lag now (longer while the heading is held)
        self._heading_held = p.heading_hold_sigma_rad > 0.0
        self._first_epoch_time: float | None = None
        self.heading_hold_end_s = float("nan")
        """Time (s) of the first update after the heading hold
        (``heading_hold_sigma_rad``) ended; nan while held or without a hold."""
        self.revised: list[Estimate] = []
        """Each accepted epoch's state as last revised before it left the
        window (fixed-lag smoothed, delayed by ``smoother_lag_s``), in time order."""
        self.revised_fallbacks = 0
        """Revised rows that are the causal estimate: the smoother failed (and
        restarted) while the state was in its window."""
        # Rest (fusion/rest.py): the first tilt_window_s of IMU samples are
        # tested; until the verdict the state is "pending", then "rest" or
        # "moving". Ground factors only while "rest" and not left.
        self._rest_state = "pending"
        self._rest_samples: list[tuple[float, np.ndarray, np.ndarray]] = []
        self._rest_baro: list[tuple[float, float]] = []
        self.rest_test: rest.RestTest | None = None
        """The rest test's verdict on the first ``tilt_window_s`` of IMU samples (None while pending)."""
        self._rest_reference = np.zeros(3)  # mean specific force at rest, m/s^2
        self._rest_baro_mean = float("nan")  # mean barometer height at rest, m
        self._left_ground = False  # True once the ground phase is over (or never began)
        self.ground_end_reason = ""
        """Why the ground phase ended: "imu" (motion), "barometer", "not_at_rest" (the test failed), or ""."""
        self._ground_epochs: list[tuple[float, int]] = []  # (time s, k) of epochs whose ground factors are in the graph
        self._ground_factor_indices: dict[int, list[int]] = {}  # k -> the smoother's indices of its ground factors
        self._ground_backlog: list[int] = []  # epochs before the verdict, to get ground factors if at rest
        self._pending_removals: list[int] = []  # factor indices to remove with the next update
        self.ground_factors_dropped = 0
        """Ground factors removed because the IMU or the barometer contradicted them."""
        # Features before the first IMU sample (a log missing its first
        # seconds of IMU): the first such row anchors the world frame.
        self._anchor_row: tuple[float, float, float, float, float, float] | None = None
        self._anchor_used = False  # whether the anchor row placed the origin (the IMU began in motion)
        self._anchor_position_sigma = float("nan")  # m, the first state's spread about where the rows put it
        self._gate_monitor = divergence.GateMonitor(p.divergence_window_epochs, p.divergence_gated_fraction)
        self.divergences = 0
        """Times the state was found diverged (bounds or persistent gating) and restarted from the features."""
        self.divergences_recovered = 0
        """Of those, the ones followed by ``recovery_epochs`` accepted epochs
        without another (all since the last recovery count then)."""
        self._since_divergence: int | None = None  # accepted epochs since the last divergence, None when recovered
        self.divergence_reasons: list[str] = []
        self._baro_datum = float("nan")  # the barometer offset over the first seconds, m
        self._controller_fallback = np.zeros(3)  # where the first row put the controller, m

    # --- IMU ---------------------------------------------------------------

    def add_imu(self, time_s: float, accel, gyro, baro_z: float = float("nan")) -> None:
        """One IMU sample: specific force (m/s^2) and angular rate (rad/s) in
        the body frame, optional barometric height (m). Samples must come in
        increasing time; a sample not after the previous one, or with a
        non-finite value, is ignored and counted in :attr:`imu_declined`."""
        started = time.perf_counter()
        try:
            self._add_imu(float(time_s), np.asarray(accel, dtype=float), np.asarray(gyro, dtype=float), baro_z)
        finally:
            self.imu_wall_time_s += time.perf_counter() - started

    def _add_imu(self, time_s: float, accel: np.ndarray, gyro: np.ndarray, baro_z) -> None:
        if not (math.isfinite(time_s) and np.all(np.isfinite(accel)) and np.all(np.isfinite(gyro))):
            self.imu_declined["non_finite"] += 1
            return
        if self._last_sample is not None and time_s <= self._last_sample[0]:
            self.imu_declined["not_after_previous"] += 1
            return
        self.imu_samples += 1
        if self._rest_state == "pending":
            self._collect_rest(time_s, accel, gyro, baro_z)
        elif self._rest_state == "rest" and not self._left_ground:
            self._watch_take_off(time_s, accel, gyro)
        if self._first_imu_time is None:
            self._first_imu_time = time_s
            self._integrated_to = time_s
        elif time_s > self._integrated_to:
            # Trapezoid over (integrated_to, t] on the line between the
            # previous sample and this one: second order in dt, where holding
            # the old sample would lag the signal by half a period.
            t_prev, a_prev, w_prev = self._last_sample
            span = time_s - t_prev
            fraction = (self._integrated_to - t_prev) / span
            a_start = a_prev + fraction * (accel - a_prev)
            w_start = w_prev + fraction * (gyro - w_prev)
            self._preintegrated.integrateMeasurement(
                0.5 * (a_start + accel), 0.5 * (w_start + gyro), time_s - self._integrated_to
            )
            self._integrated_to = time_s
        self._last_sample = (time_s, accel, gyro)
        if self._key < 0 and time_s <= self._first_imu_time + self.params.tilt_window_s:
            self._tilt_sum += accel
            self._tilt_count += 1
        if baro_z is not None and math.isfinite(baro_z):
            self._baro.append((time_s, float(baro_z)))
            while self._baro and self._baro[0][0] <= time_s - self.params.baro_window_s:
                self._baro.popleft()

    def predict(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The newest state propagated by the IMU to ``time_s`` (s): position (m),
        velocity (m/s), world_R_body (3x3); None before the first epoch.

        Causal: it uses the IMU samples received so far (the newest one held up
        to ``time_s``). The pose sensing calls it to remove the translational
        Doppler shift of the epoch at ``time_s`` before that epoch's features
        exist (paper sec. III-B: "the super-accuracy algorithm corrects the
        drift and feeds back"). ``time_s`` must not precede the newest sample.
        """
        if self._nav is None or self._last_sample is None:
            return None
        self._integrate_to(time_s)
        state = self._preintegrated.predict(self._nav, self._bias)
        return np.asarray(state.position(), dtype=float), np.asarray(state.velocity(), dtype=float), np.asarray(
            state.attitude().matrix(), dtype=float
        )

    def _integrate_to(self, time_s: float) -> None:
        """Extends the preintegration to ``time_s`` holding the newest sample
        (the next one is not known yet: causal)."""
        if time_s > self._integrated_to:
            _, accel, gyro = self._last_sample
            self._preintegrated.integrateMeasurement(accel, gyro, time_s - self._integrated_to)
            self._integrated_to = time_s

    # --- features ----------------------------------------------------------

    def add_features(
        self,
        time_s: float,
        range_m: float,
        azimuth_rad: float,
        elevation_rad: float,
        yaw_rad: float = float("nan"),
        range_sigma_m: float = float("nan"),
        angle_sigma_rad: float = float("nan"),
        yaw_sigma_rad: float = float("nan"),
    ) -> Estimate | None:
        """One feature row (docs/formats.md section 7): adds the epoch's state and
        factors, updates the smoother and returns the newest state's estimate;
        ``None`` when the row is declined."""
        started = time.perf_counter()
        cpu_started = time.thread_time()
        values = (time_s, range_m, azimuth_rad, elevation_rad)
        if not all(v is not None and math.isfinite(v) for v in values) or range_m <= 0.0:
            return self._decline("non_finite")
        time_s = float(time_s)
        if self._first_imu_time is None or time_s < self._first_imu_time:
            if self._anchor_row is None:
                # The world origin is where the drone was at the log's first
                # row; without IMU yet, this row is all that ties the
                # controller to it (see _take_off).
                self._anchor_row = (time_s, float(range_m), float(azimuth_rad), float(elevation_rad),
                                    _finite_or(range_sigma_m, self.params.range_sigma_m),
                                    _finite_or(angle_sigma_rad, self.params.angle_sigma_rad))
            return self._decline("before_imu")
        if self._last_epoch_time is not None and time_s <= self._last_epoch_time:
            return self._decline("not_after_previous")
        if self._last_epoch_time is not None and time_s - self._last_epoch_time < self.params.min_epoch_interval_s:
            return self._decline("too_close")
        if time_s < self._last_sample[0]:
            return self._decline("before_latest_imu")
        p = self.params
        range_sigma = _finite_or(range_sigma_m, p.range_sigma_m)
        angle_sigma = _finite_or(angle_sigma_rad, p.angle_sigma_rad)
        yaw_sigma = _finite_or(yaw_sigma_rad, p.yaw_sigma_rad)
        has_yaw = p.use_yaw and yaw_rad is not None and math.isfinite(yaw_rad)

        self._integrate_to(time_s)
        graph = gtsam.NonlinearFactorGraph()
        initial = gtsam.Values()
        stamps: dict[int, float] = {}
        previous_position = None if self._nav is None else np.asarray(self._nav.position(), dtype=float)

        if self._key < 0:
            self._take_off(graph, initial, stamps, float(yaw_rad) if has_yaw else 0.0,
                           (float(range_m), float(azimuth_rad), float(elevation_rad), range_sigma, angle_sigma))
            # A row at the take-off instant itself measures X(0).
            if self._preintegrated.deltaTij() > 0.0:
                self._key = 1
                self._add_imu_factor(graph, initial, 0)
            else:
                self._key = 0
        else:
            # A new state joins the previous one through the preintegrated IMU.
            self._key += 1
            self._add_imu_factor(graph, initial, self._key - 1)
        k = self._key
        for key in (X(k), V(k), B(k)):
            stamps[key] = time_s
        predicted = self._nav
        ground_slots = self._ground_for_epoch(graph, k, time_s)

        # Controller: initialised from the first row, rho = p - d u.
        # No gate on the ground: the controller is placed by the rest rows
        # together (a least-squares mean), not by whichever row came first.
        gated = (
            self._controller is not None
            and self._gate is not None
            and self._declined_run < p.max_declined_epochs
            and not self.on_ground
        )
        if self._controller is None:
            self._controller = predicted.position() - range_m * factors.direction(azimuth_rad, elevation_rad)
            if self._anchor_used:
                # Features before the IMU: the controller as the anchor row
                # (drone at the origin) places it, with that row's spread.
                _, d0, az0, el0, range_sigma0, angle_sigma0 = self._anchor_row
                self._controller = divergence.controller_from_origin(d0, az0, el0)
                spread = divergence.feature_position_sigmas(d0, range_sigma0, angle_sigma0)
                graph.add(gtsam.PriorFactorPoint3(CONTROLLER, self._controller, gtsam.noiseModel.Isotropic.Sigma(3, spread)))
            self._controller_fallback = self._controller.copy()
            initial.insert(CONTROLLER, self._controller)
            if self._has_range_bias():
                graph.add(gtsam.PriorFactorDouble(RANGE_BIAS, 0.0, gtsam.noiseModel.Isotropic.Sigma(1, p.range_bias_sigma_m)))
                initial.insert(RANGE_BIAS, 0.0)
        stamps[CONTROLLER] = time_s
        if self._has_range_bias():
            stamps[RANGE_BIAS] = time_s

        used = {"range": True, "direction": True, "yaw": has_yaw, "baro": False}
        inflation = self._correlation_inflation(time_s, predicted)
        states = p.multipath == "states"
        if not states:
            range_sigma *= inflation
            angle_sigma *= inflation
        yaw_sigma *= inflation
        direction_sigma = factors.direction_sigmas(elevation_rad, angle_sigma)
        multipath_predicted = np.zeros(3)
        if states:
            multipath_predicted = self._add_multipath(
                graph, initial, stamps, time_s, np.concatenate([[range_sigma], direction_sigma]),
                previous_position, predicted,
            )
        if gated:
            used["range"], used["direction"], yaw_ok = self._innovation_tests(
                predicted, range_m, azimuth_rad, elevation_rad, yaw_rad if has_yaw else None,
                range_sigma, direction_sigma, yaw_sigma,
                multipath_predicted + np.array([self._range_bias if self._has_range_bias() else 0.0, 0.0, 0.0]),
            )
            used["yaw"] = has_yaw and yaw_ok
            # Recovery of one measurement on its own: ranges gated for
            # max_declined_epochs epochs in a row while the directions pass
            # mean the range's fringe (or the controller's range) is what is
            # wrong; the next range is taken ungated so the state can move.
            if not used["range"] and self._range_declined_run >= p.max_declined_epochs:
                used["range"] = True
            self._range_declined_run = 0 if used["range"] else self._range_declined_run + 1
            for name in ("range", "direction", "yaw"):
                if (name != "yaw" or has_yaw) and not used[name]:
                    self.declined[f"{name}_gate"] += 1
            self._declined_run = 0 if (used["range"] or used["direction"] or used["yaw"]) else self._declined_run + 1
            if self._gate_monitor.add(not (used["range"] and used["direction"])):
                # Persistently beyond the gate: the state is wrong, not the rows.
                return self._diverge(k, time_s, predicted, "persistently_gated", (range_m, azimuth_rad, elevation_rad, yaw_rad if has_yaw else None))
        else:
            self._declined_run = 0

        if states:
            # The white (thermal) share; the rest is in M(k).
            white = p.multipath_white_fraction
            range_white = max(white * range_sigma, p.white_floor_range_m)
            direction_white = np.maximum(white * direction_sigma, p.white_floor_angle_rad)
            if used["range"]:
                graph.add(
                    factors.range_factor_multipath(
                        X(k), CONTROLLER, M(k), range_m, self._noise(np.array([range_white])),
                        RANGE_BIAS if self._has_range_bias() else None,
                    )
                )
            if used["direction"]:
                graph.add(
                    factors.direction_factor_multipath(
                        X(k), CONTROLLER, M(k), azimuth_rad, elevation_rad, self._noise(direction_white)
                    )
                )
        else:
            if used["range"]:
                graph.add(factors.range_factor(X(k), CONTROLLER, range_m, self._noise(np.array([range_sigma]))))
            if used["direction"]:
                graph.add(
                    factors.direction_factor(X(k), CONTROLLER, azimuth_rad, elevation_rad, self._noise(direction_sigma))
                )
        if used["yaw"]:
            if states:
                # The yaw's azimuth share is M(k)'s; what is left is the
                # rotational Doppler's own error (inflated: not in M). The
                # features give one yaw sigma, so the split is a guess: the
                # own share is kept at half the whole or more, lest a row
                # whose sigma is mostly azimuth pin the heading to M(k).
                azimuth_sigma = direction_sigma[0] / max(math.cos(elevation_rad), 1e-3)
                own = math.sqrt(max(yaw_sigma**2 - (inflation * azimuth_sigma) ** 2, (0.5 * yaw_sigma) ** 2))
                graph.add(
                    factors.yaw_factor_multipath(
                        X(k), M(k), float(yaw_rad), elevation_rad, self._noise(np.array([own]))
                    )
                )
            else:
                graph.add(factors.yaw_factor(X(k), float(yaw_rad), self._noise(np.array([yaw_sigma]))))
        used["baro"] = self._add_baro(graph, initial, stamps, time_s, predicted)

        # The update marginalises the states stamped before now - lag (a
        # whole bucket at once: see marginalize_every_s): their last
        # revision is the smoother's estimate now, before the update.
        stamps = {key: self._stamp(t) for key, t in stamps.items()}
        lag = self._lag_for(time_s)
        if lag != self._lag:
            self._smoother.setSmootherLag(lag)
            self._lag = lag
        self._release(self._stamp(time_s) - lag)
        removals, self._pending_removals = self._pending_removals, []
        try:
            self._smoother.update(graph, initial, stamps, removals)
            if ground_slots:
                self._record_ground(k, time_s, ground_slots)
            for _ in range(p.extra_iterations):
                self._smoother.update()
            estimate = self._read_estimate(time_s, used)
        except Diverged as failure:
            self._release(math.inf, revise=False)
            self._last_epoch_time = time_s
            return self._diverge(k, time_s, predicted, "diverged", (range_m, azimuth_rad, elevation_rad, yaw_rad if has_yaw else None), str(failure))
        except RuntimeError as failure:
            # GTSAM reports an ill-conditioned system (IndeterminateLinearSystem)
            # by throwing; the smoother's state is then unusable, and so is
            # one that left the physical bounds. The row is declined and the
            # smoother restarts from the predicted state, with priors as wide
            # as the last covariances, so a bad row never ends the run.
            # The failed smoother's values are unusable: the states in its
            # window keep their causal estimates.
            self._release(math.inf, revise=False)
            self._restart(k, time_s, predicted)
            self._last_epoch_time = time_s
            self._preintegrated.resetIntegrationAndSetBias(self._bias)
            self.restarts += 1
            del failure
            return self._decline("solver_failure")
        self._window[k] = (float(stamps[X(k)]), estimate)
        self._prefetch(time_s)
        if self._since_divergence is not None:
            self._since_divergence += 1
            if self._since_divergence >= p.recovery_epochs:
                # Every divergence since the last recovery is over (one that
                # followed another within recovery_epochs superseded it).
                self.divergences_recovered = self.divergences
                self._since_divergence = None
        self._last_epoch_time = time_s
        # The next interval integrates against the newest bias estimate.
        self._preintegrated.resetIntegrationAndSetBias(self._bias)
        self.epochs += 1
        estimate.wall_time_s = time.perf_counter() - started
        self.wall_times_s.append(estimate.wall_time_s)
        self.cpu_times_s.append(time.thread_time() - cpu_started)
        return estimate

    def _lag_for(self, time_s: float) -> float:
        """The smoother's lag for the update at ``time_s`` (s): ``smoother_lag_s``,
        or longer than the flight so far while the heading is held
        (``heading_hold_sigma_rad``). Once released, the hold does not return."""
        p = self.params
        if self._heading_held:
            if self._first_epoch_time is None:
                self._first_epoch_time = time_s
            since = time_s - self._first_epoch_time
            unknown = not (math.isfinite(self._cov_yaw) and math.sqrt(max(self._cov_yaw, 0.0)) <= p.heading_hold_sigma_rad)
            if unknown and since <= p.heading_hold_max_s:
                # The newest stamp is at most one bucket past now, so this
                # horizon stays before the first state's stamp.
                return max(p.smoother_lag_s, since + p.marginalize_every_s)
            self._heading_held = False
            self.heading_hold_end_s = time_s
        return p.smoother_lag_s

    def _stamp(self, time_s: float) -> float:
        """The smoother's time stamp of a state at ``time_s`` (s): the end of
        its ``marginalize_every_s`` bucket (its own time with 0)."""
        every = self.params.marginalize_every_s
        if every <= 0.0:
            return time_s
        return (math.floor(time_s / every) + 1.0) * every

    def _add_multipath(self, graph, initial, stamps, time_s, sigma, previous_position, predicted) -> np.ndarray:
        """The epoch's multipath state ``M(k)`` (``multipath = "states"``) and
        its Gauss-Markov link to ``M(k-1)``; returns its prediction ``phi m_{k-1}``.

        ``sigma`` (3,): the row's total 1-sigma of range (m) and of the
        direction's two tangent components (rad); the correlated share is
        ``sqrt(1 - f^2)`` of it. Correlation ``phi = exp(-|dp| / d - dt / tau)``
        over the IMU-predicted displacement ``dp`` and the time ``dt`` since
        the previous epoch (the model of docs/marvel.md section 9).
        """
        p = self.params
        k = self._key
        correlated = np.asarray(sigma, dtype=float) * math.sqrt(1.0 - p.multipath_white_fraction**2)
        predicted_error = np.zeros(3)
        if self._multipath_chain and self._last_epoch_time is not None and previous_position is not None:
            moved = float(np.linalg.norm(np.asarray(predicted.position(), dtype=float) - previous_position))
            elapsed = time_s - self._last_epoch_time
            if p.correlation_distance_m > 0.0 and p.correlation_time_s > 0.0:
                phi = math.exp(-moved / p.correlation_distance_m - elapsed / p.correlation_time_s)
            else:
                phi = 0.0
            decay = np.full(3, phi)
            # Var M(k) = phi^2 Var M(k-1) + Var w = correlated^2 when the
            # row's sigma grows; when it shrinks (phi sigma_(k-1) > sigma_k)
            # the walk keeps its stationary share (1 - phi^2) sigma_k^2 and
            # M(k) stays a little wider than its row. Scaling M(k-1) by
            # sigma_k / sigma_(k-1) instead would blow M up when a row's
            # sigma jumps by orders of magnitude (an unsettled fringe). The
            # floor keeps the factor finite for a frozen error (phi -> 1).
            variance = np.maximum(
                correlated**2 - (phi * self._multipath_sigma) ** 2, (1.0 - phi * phi) * correlated**2
            )
            walk = np.sqrt(np.maximum(variance, 1.0e-6 * correlated**2))
            graph.add(
                factors.gauss_markov_factor(
                    M(self._multipath_key), M(k), decay, gtsam.noiseModel.Diagonal.Sigmas(walk)
                )
            )
            predicted_error = decay * self._multipath
        else:
            graph.add(gtsam.PriorFactorVector(M(k), np.zeros(3), gtsam.noiseModel.Diagonal.Sigmas(correlated)))
            self._multipath_chain = True
        initial.insert(M(k), predicted_error)
        stamps[M(k)] = time_s
        self._multipath_key = k
        self._multipath_sigma = correlated
        return predicted_error

    def _has_range_bias(self) -> bool:
        """Whether the graph has the constant range bias ``W(0)``."""
        return self.params.range_bias_sigma_m > 0.0 and self.params.multipath == "states"

    def _correlation_inflation(self, time_s: float, predicted) -> float:
        """sqrt(rows per decorrelation) >= 1 for this row (see ``correlation_time_s``).

        Rows per decorrelation = interval-rate x the time the drone needs to
        travel ``correlation_distance_m`` at its predicted speed, at most
        ``correlation_time_s``.
        """
        p = self.params
        if p.correlation_distance_m <= 0.0 or p.correlation_time_s <= 0.0 or self._last_epoch_time is None:
            return 1.0
        interval = time_s - self._last_epoch_time
        speed = float(np.linalg.norm(predicted.velocity()))
        decorrelation_s = min(p.correlation_time_s, p.correlation_distance_m / speed) if speed > 0.0 else p.correlation_time_s
        return math.sqrt(max(1.0, decorrelation_s / interval))

    def step(self, measurement) -> Estimate | None:
        """Either an IMU sample ``("imu", time_s, accel, gyro[, baro_z])`` or a
        feature row ``("features", time_s, range_m, azimuth_rad, elevation_rad, ...)``."""
        kind, *rest = measurement
        if kind == "imu":
            self.add_imu(*rest)
            return None
        if kind == "features":
            return self.add_features(*rest)
        raise ValueError(f"unknown measurement kind {kind!r}")

    # --- graph building ----------------------------------------------------

    def _take_off(self, graph, initial, stamps, yaw_rad: float, row=None) -> None:
        """State X(0) at the first IMU sample: at the origin, roll and pitch
        from the averaged accelerometer, yaw from the first yaw feature; the
        velocity near zero if the IMU so far shows rest, else unknown.
        ``row``: this epoch's (range m, azimuth rad, elevation rad, range
        sigma m, angle sigma rad), for a log whose features began before its IMU."""
        p = self.params
        mean_force = self._tilt_sum / self._tilt_count if self._tilt_count else np.array([0.0, 0.0, 1.0])
        roll, pitch = tilt_from_specific_force(mean_force)
        position = np.zeros(3)
        position_sigma = p.prior_position_sigma_m
        provisional = self._provisional_rest()
        # A row before the IMU matters only if the IMU begins in motion: at
        # rest, the drone was where it is now (the origin) all along.
        self._anchor_used = self._anchor_row is not None and row is not None and not provisional
        if self._anchor_used:
            # The IMU starts after the features: the origin is where the drone
            # was at the anchor row, and this state is where this row puts it
            # from there; loose (the controller's prior carries the anchor).
            _, d0, az0, el0, range_sigma0, angle_sigma0 = self._anchor_row
            controller = divergence.controller_from_origin(d0, az0, el0)
            position = divergence.position_from_features(controller, *row[:3])
            # The two rows' spreads together: how far this state can be from
            # where they put it (the barometer's datum is checked against it).
            self._anchor_position_sigma = math.hypot(divergence.feature_position_sigmas(row[0], row[3], row[4]),
                                                     divergence.feature_position_sigmas(d0, range_sigma0, angle_sigma0))
            position_sigma = 10.0 * self._anchor_position_sigma
        pose = gtsam.Pose3(gtsam.Rot3.Ypr(yaw_rad, pitch, roll), position)
        # Pose3 tangent: rotation about body x, y, z then translation.
        pose_sigmas = np.array(
            [p.prior_tilt_sigma_rad, p.prior_tilt_sigma_rad, p.prior_yaw_sigma_rad] + [position_sigma] * 3
        )
        # At rest (so far: the test's window may not be complete) the
        # velocity is near zero; otherwise it is unknown (a lift-off, a log
        # begun in flight): a wide zero-mean prior, the IMU and the rows find it.
        velocity_sigma = p.prior_velocity_sigma_m_s if provisional else p.moving_velocity_sigma_m_s
        velocity_noise = gtsam.noiseModel.Isotropic.Sigma(3, velocity_sigma)
        bias_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([p.accel_bias_sigma] * 3 + [p.gyro_bias_sigma] * 3))
        graph.add(gtsam.PriorFactorPose3(X(0), pose, gtsam.noiseModel.Diagonal.Sigmas(pose_sigmas)))
        graph.add(gtsam.PriorFactorVector(V(0), np.zeros(3), velocity_noise))
        graph.add(gtsam.PriorFactorConstantBias(B(0), gtsam.imuBias.ConstantBias(), bias_noise))
        initial.insert(X(0), pose)
        initial.insert(V(0), np.zeros(3))
        initial.insert(B(0), gtsam.imuBias.ConstantBias())
        for key in (X(0), V(0), B(0)):
            stamps[key] = self._first_imu_time
        self._nav = gtsam.NavState(pose, np.zeros(3))
        self._bias = gtsam.imuBias.ConstantBias()

    def _new_smoother(self):
        """An empty iSAM2 fixed-lag smoother with this estimator's settings."""
        p = self.params
        isam_params = gtsam.ISAM2Params()
        isam_params.setRelinearizeThreshold(p.relinearize_threshold)
        isam_params.relinearizeSkip = p.relinearize_skip
        # QR on the Jacobian instead of Cholesky on J^T J: the bias random
        # walk between 0.1 s epochs (1/sigma ~ 2e5 for the gyroscope) next to
        # metre-level feature noise gives cond(J) ~ 1e6, cond(J^T J) ~ 1e12,
        # where iSAM2's Cholesky reports an indeterminate system.
        isam_params.setFactorization(p.factorization)
        return gtsam.IncrementalFixedLagSmoother(p.smoother_lag_s, isam_params)

    def _add_imu_factor(self, graph, initial, previous: int) -> None:
        k = self._key
        graph.add(gtsam.CombinedImuFactor(X(previous), V(previous), X(k), V(k), B(previous), B(k), self._preintegrated))
        predicted = self._preintegrated.predict(self._nav, self._bias)
        # Prior-free prediction of the new state for the gate and as the
        # initial value: previous estimate pushed through the preintegration.
        dt = self._preintegrated.deltaTij()
        if np.all(np.isfinite(self._cov_position)):
            rotation = self._nav.attitude().matrix()
            preintegrated_cov = np.asarray(self._preintegrated.preintMeasCov())
            # preintMeasCov order: rotation, position, velocity, biases;
            # position in the previous body frame.
            self._cov_position = (
                self._cov_position
                + dt * dt * self._cov_velocity
                + rotation @ preintegrated_cov[3:6, 3:6] @ rotation.T
            )
            self._cov_yaw = self._cov_yaw + preintegrated_cov[2, 2]
        initial.insert(X(k), predicted.pose())
        initial.insert(V(k), predicted.velocity())
        initial.insert(B(k), self._bias)
        self._nav = predicted

    def _add_baro(self, graph, initial, stamps, time_s: float, predicted: gtsam.NavState) -> bool:
        """Barometer: height + offset O(k) = mean of the samples in the window;
        O(k) follows a random walk between epochs. Returns whether a height
        factor was added."""
        p = self.params
        if not p.use_baro:
            return False
        samples = [b for (t, b) in self._baro if time_s - p.baro_window_s < t <= time_s]
        if not samples and not self._baro_chain:
            return False
        k = self._key
        if self._baro_chain:
            dt = max(time_s - self._baro_time, 1e-6)
            walk = gtsam.noiseModel.Isotropic.Sigma(1, p.baro_random_walk * math.sqrt(dt))
            graph.add(gtsam.BetweenFactorDouble(O(self._baro_key), O(k), 0.0, walk))
            initial.insert(O(k), self._baro_offset)
        elif self._anchor_used and self.epochs == 0 and self.divergences == 0 and samples and self._datum_agrees(float(np.mean(samples)), predicted):
            # No take-off pins the height (the IMU began in flight): the
            # barometer's own datum, the take-off point, does, if the
            # features agree with it (a barometer reading height above sea
            # level, or zeroed elsewhere, keeps the loose prior).
            self._baro_offset = 0.0
            datum = gtsam.noiseModel.Isotropic.Sigma(1, p.baro_datum_sigma_m)
            graph.add(gtsam.PriorFactorDouble(O(k), 0.0, datum))
            initial.insert(O(k), 0.0)
            self._baro_chain = True
        else:
            self._baro_offset = float(np.mean(samples)) - predicted.position()[2]
            loose = gtsam.noiseModel.Isotropic.Sigma(1, p.baro_offset_prior_sigma_m)
            graph.add(gtsam.PriorFactorDouble(O(k), self._baro_offset, loose))
            initial.insert(O(k), self._baro_offset)
            self._baro_chain = True
        self._baro_key, self._baro_time = k, time_s
        stamps[O(k)] = time_s
        if not samples:
            return False
        # White noise averages down over the window's samples.
        noise = gtsam.noiseModel.Isotropic.Sigma(1, p.baro_sigma_m / math.sqrt(len(samples)))
        graph.add(factors.height_factor(X(k), O(k), float(np.mean(samples)), noise))
        return True

    def _datum_agrees(self, baro_m: float, predicted) -> bool:
        """Whether a barometer height (m) is within 3 sigmas of the height the
        features put the first state at (its sigma: the anchor row's and the
        first row's spreads and the datum's)."""
        if not self._anchor_used:
            return False
        sigma = math.hypot(self._anchor_position_sigma, self.params.baro_datum_sigma_m)
        return abs(baro_m - float(predicted.position()[2])) <= 3.0 * sigma

    def _noise(self, sigmas: np.ndarray):
        model = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
        if self.params.robust == "huber":
            # Huber: quadratic within huber_k sigma, linear beyond, so a
            # moderate outlier that passed the gate pulls less.
            return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(self.params.huber_k), model)
        return model

    def _innovation_tests(
        self,
        predicted,
        range_m,
        azimuth_rad,
        elevation_rad,
        yaw_rad,
        range_sigma,
        direction_sigma,
        yaw_sigma,
        multipath=(0.0, 0.0, 0.0),
    ) -> tuple[bool, bool, bool]:
        """Normalised innovation squared of each measurement against the
        IMU-predicted state, ``nu^T S^-1 nu`` with ``S = H P H^T + R``, below
        the chi-square gate. ``P`` is the predicted position covariance plus
        the controller's (their cross-covariance is left out: it is positive
        for a drone measured from the controller, so leaving it out widens
        ``S`` and the gate errs on accepting). ``multipath``: the predicted
        multipath errors (range m, direction tangent rad) added to the
        predicted measurements; ``R`` is then the whole feature sigma, as if
        that prediction were no better than the stationary 1-sigma (errs on
        accepting too)."""
        position = predicted.position()
        covariance = np.zeros((3, 3))
        if np.all(np.isfinite(self._cov_position)):
            covariance = covariance + self._cov_position
        if np.all(np.isfinite(self._cov_controller)):
            covariance = covariance + self._cov_controller
        multipath = np.asarray(multipath, dtype=float)
        residual, (h_position, _) = factors.range_residual(position, self._controller, range_m, jacobians=True)
        residual = residual + multipath[0]
        s = float((h_position @ covariance @ h_position.T)[0, 0]) + range_sigma**2
        range_ok = residual[0] ** 2 / s <= self._gate[1]
        residual, (h_position, _) = factors.direction_residual(
            position, self._controller, azimuth_rad, elevation_rad, jacobians=True
        )
        residual = residual + multipath[1:3]
        s = h_position @ covariance @ h_position.T + np.diag(direction_sigma**2)
        direction_ok = float(residual @ np.linalg.solve(s, residual)) <= self._gate[2]
        yaw_ok = True
        if yaw_rad is not None:
            residual = factors.yaw_residual(predicted.attitude().matrix(), yaw_rad)
            residual = factors.wrap_angle(residual + multipath[1] / max(math.cos(elevation_rad), 1e-3))
            s = (self._cov_yaw if math.isfinite(self._cov_yaw) else 0.0) + yaw_sigma**2
            yaw_ok = residual[0] ** 2 / s <= self._gate[1]
        return bool(range_ok), bool(direction_ok), bool(yaw_ok)

    def _read_estimate(self, time_s: float, used: dict) -> Estimate:
        k = self._key
        smoother = self._smoother
        pose = smoother.calculateEstimatePose3(X(k))
        velocity = np.asarray(smoother.calculateEstimateVector(V(k)), dtype=float)
        controller = np.asarray(smoother.calculateEstimatePoint3(CONTROLLER), dtype=float)
        if not (np.all(np.isfinite(pose.matrix())) and np.all(np.isfinite(velocity)) and np.all(np.isfinite(controller))):
            # A solve that overflowed (measured in a reflecting room at IQ
            # level: a position of inf) is a solver failure like a thrown
            # one: the caller declines the row and restarts the smoother.
            raise RuntimeError("non-finite estimate")
        p = self.params
        violation = divergence.physical_violation(
            np.asarray(pose.translation(), dtype=float), velocity, controller,
            max_speed_m_s=p.max_speed_m_s, max_controller_range_m=p.max_controller_range_m, max_position_m=p.max_position_m,
        )
        if violation is not None:
            raise Diverged(violation)
        self._bias = smoother.calculateEstimateConstantBias(B(k))
        self._controller = controller
        if self._baro_chain:
            self._baro_offset = smoother.calculateEstimateDouble(O(self._baro_key))
            if self.epochs < 20 and self.divergences == 0:
                # The datum a restart from the features takes the height from:
                # the offset while the take-off (or the first state's prior) pins it.
                self._baro_datum = float(self._baro_offset)
        if self._multipath_chain:
            self._multipath = np.asarray(smoother.calculateEstimateVector(M(self._multipath_key)), dtype=float)
        if self._has_range_bias():
            self._range_bias = float(smoother.calculateEstimateDouble(RANGE_BIAS))
        self._nav = gtsam.NavState(pose, velocity)
        if self.params.compute_sigma or self._gate is not None:
            pose_cov = np.asarray(smoother.marginalCovariance(X(k)))
            self._cov_position = _world_position_covariance(pose, pose_cov)
            self._cov_yaw = float(pose_cov[2, 2])
            self._cov_velocity = np.asarray(smoother.marginalCovariance(V(k)))
            self._cov_controller = np.asarray(smoother.marginalCovariance(CONTROLLER))
        if self.params.compute_sigma:
            sigma = np.sqrt(np.clip(np.diag(self._cov_position), 0.0, None))
            controller_sigma = np.sqrt(np.clip(np.diag(self._cov_controller), 0.0, None))
        else:
            sigma = np.full(3, np.nan)
            controller_sigma = np.full(3, np.nan)
        return Estimate(
            time_s=time_s,
            position=np.asarray(pose.translation(), dtype=float),
            velocity=velocity,
            orientation=_quaternion(pose),
            sigma=sigma,
            controller=self._controller.copy(),
            controller_sigma=controller_sigma,
            accel_bias=np.asarray(self._bias.accelerometer(), dtype=float),
            gyro_bias=np.asarray(self._bias.gyroscope(), dtype=float),
            used=used,
        )

    def _decline(self, reason: str) -> None:
        """Counts a declined row; returns None, the value add_features gives for it."""
        self.declined[reason] += 1

    # --- reporting ---------------------------------------------------------

    def latency(self) -> Latency | None:
        """The wall time per accepted row as a :class:`~scattertrack.fusion.latency.Latency` (None before any)."""
        return Latency.of(self.wall_times_s)

    def cpu_latency(self) -> Latency | None:
        """The thread CPU time per accepted row as a :class:`~scattertrack.fusion.latency.Latency`."""
        return Latency.of(self.cpu_times_s)

    def latency_ns(self) -> dict[str, float]:
        """Quantiles of the wall time per accepted feature row, ns (``p50``, ``p99``, ``mean``, ``max``)."""
        if not self.wall_times_s:
            return {}
        ns = np.asarray(self.wall_times_s) * 1e9
        return {
            "p50": float(np.percentile(ns, 50)),
            "p99": float(np.percentile(ns, 99)),
            "mean": float(np.mean(ns)),
            "max": float(np.max(ns)),
        }

    @property
    def controller(self) -> np.ndarray | None:
        """Current estimate of the controller position, (3,) m, or None before the first row."""
        return None if self._controller is None else self._controller.copy()

    @property
    def velocity_covariance(self) -> np.ndarray | None:
        """World-frame covariance of the newest smoothed velocity, (3, 3) (m/s)^2, or None before the first row.

        With the yaw still loose (no yaw feature: a rail, a hover) it is about
        ``|v|^2 sigma_yaw^2`` across the velocity: the IMU-integrated velocity's
        direction is only as good as the yaw."""
        if not np.all(np.isfinite(self._cov_velocity)):
            return None
        return self._cov_velocity.copy()

    @property
    def position_covariance(self) -> np.ndarray | None:
        """World-frame covariance of the newest position, (3, 3) m^2, or None before the first row."""
        return self._cov_position.copy() if np.all(np.isfinite(self._cov_position)) else None

    @property
    def range_bias(self) -> float | None:
        """Current estimate of the constant range bias ``W(0)`` (m), or None without that state."""
        return self._range_bias if self._has_range_bias() and self._controller is not None else None

    @property
    def multipath(self) -> np.ndarray | None:
        """The newest epoch's multipath errors (range m, direction tangent rad), or None without them."""
        return self._multipath.copy() if self._multipath_chain else None

    @property
    def controller_covariance(self) -> np.ndarray | None:
        """Covariance of the controller estimate, (3, 3) m^2, or None before the first row."""
        return self._cov_controller.copy() if np.all(np.isfinite(self._cov_controller)) else None
