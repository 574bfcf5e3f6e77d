"""The ground phase of the Marvel estimator: rest tested, ground factors, their removal.

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator` (its state
lives there, set up in ``__init__``): the rest test's window and verdict
(:mod:`scattertrack.fusion.rest`), the take-off watch, the ground factors
("at the origin, not moving, not turning", docs/marvel.md section 8) added
only after a positive verdict, and their removal when the barometer
contradicts them.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from gtsam.symbol_shorthand import V, X

from scattertrack.fusion import rest


class GroundPhase:
    """Ground-phase methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _init_ground(self) -> None:
        # The first tilt_window_s of IMU samples are tested; until the
        # verdict the state is "pending", then "rest" or "moving". Ground
        # factors only while "rest" and not left.
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

    @property
    def on_ground(self) -> bool:
        """Whether the drone is (still) known to rest on the ground: the rest
        test has not failed and no IMU sample or barometer window has shown
        motion since. While the test is pending: whether the samples so far pass it."""
        if self._rest_state == "pending":
            return self._first_imu_time is None or self._provisional_rest()
        return self._rest_state == "rest" and not self._left_ground

    @property
    def rest_state(self) -> str:
        """``"pending"`` (the rest test's window is not complete), ``"rest"`` or ``"moving"``."""
        return self._rest_state

    def _collect_rest(self, time_s: float, accel: np.ndarray, gyro: np.ndarray, baro_z) -> None:
        """Gathers the rest test's window (the first ``tilt_window_s`` of IMU
        samples) and gives the verdict at the first sample past it."""
        p = self.params
        first = self._rest_samples[0][0] if self._rest_samples else time_s
        if time_s <= first + p.tilt_window_s:
            self._rest_samples.append((time_s, accel, gyro))
            if baro_z is not None and math.isfinite(baro_z):
                self._rest_baro.append((time_s, float(baro_z)))
            return
        accel_window = np.array([a for _, a, _ in self._rest_samples])
        gyro_window = np.array([g for _, _, g in self._rest_samples])
        thresholds = rest.RestThresholds(
            p.gravity_m_s2, p.rest_force_tolerance_m_s2, p.rest_accel_rms_m_s2, p.rest_gyro_rms_rad_s, p.rest_baro_rate_m_s
        )
        baro_t = [t for t, _ in self._rest_baro]
        baro_z_window = [z for _, z in self._rest_baro]
        self.rest_test = rest.rest_test(accel_window, gyro_window, thresholds, baro_t, baro_z_window)
        # The anchor row placed the origin (the IMU began in motion, after the
        # features): "at the origin" cannot hold then.
        at_rest = self.rest_test.at_rest and not self._anchor_used
        self._rest_samples = []
        if at_rest:
            self._rest_state = "rest"
            self._rest_reference = self.rest_test.mean_force
            self._rest_baro_mean = float(np.mean(baro_z_window)) if baro_z_window else float("nan")
            self._watch_take_off(time_s, accel, gyro)
        else:
            self._rest_state = "moving"
            self._left_ground = True
            self.ground_end_reason = "not_at_rest"
            self._ground_backlog = []

    def _watch_take_off(self, time_s: float, accel: np.ndarray, gyro: np.ndarray) -> None:
        """Ends the ground phase at the first sample that shows motion.

        Motion: an angular rate above ``rest_gyro_threshold_rad_s``, or a
        specific force that differs, as a VECTOR, from the mean of the rest
        test's window (gravity seen at rest) by more than
        ``rest_accel_threshold_m_s2``. Not the magnitude: a level body
        accelerated horizontally (the paper's rail, sec. V-B) changes
        ``|f| = sqrt(g^2 + a^2)`` only to second order (0.045 m/s^2 for
        0.94 m/s^2), so a magnitude test would keep it "at the origin" for the
        whole run.
        """
        p = self.params
        if np.linalg.norm(gyro) > p.rest_gyro_threshold_rad_s or np.linalg.norm(accel - self._rest_reference) > p.rest_accel_threshold_m_s2:
            # Each sample before this one was within the rest thresholds: the
            # IMU contradicts the ground from now on, not before.
            self._end_ground(time_s, "imu", 0.0)

    def _end_ground(self, time_s: float, reason: str, release_s: float) -> None:
        """The ground phase ends (IMU motion or the barometer at ``time_s``, s):
        the ground factors of the epochs after ``time_s - release_s`` are
        removed with the next update (dropped, not obeyed)."""
        self._left_ground = True
        self.ground_end_reason = reason
        cut = time_s - release_s
        for t, k in self._ground_epochs:
            if t > cut:
                indices = self._ground_factor_indices.pop(k, [])
                self._pending_removals.extend(indices)
                self.ground_factors_dropped += len(indices)
        self._ground_epochs = []

    def _provisional_rest(self) -> bool:
        """Whether the IMU samples so far pass the rest test (the verdict when it
        is in, else the test on the part of its window received)."""
        if self._rest_state != "pending":
            return self._rest_state == "rest"
        p = self.params
        thresholds = rest.RestThresholds(
            p.gravity_m_s2, p.rest_force_tolerance_m_s2, p.rest_accel_rms_m_s2, p.rest_gyro_rms_rad_s, p.rest_baro_rate_m_s
        )
        accel = np.array([a for _, a, _ in self._rest_samples]).reshape(-1, 3)
        gyro = np.array([g for _, _, g in self._rest_samples]).reshape(-1, 3)
        return rest.rest_test(accel, gyro, thresholds, min_samples=1).at_rest

    def _ground_for_epoch(self, graph, k: int, time_s: float) -> list:
        """The ground factors of epoch ``k`` at ``time_s`` (s), added to ``graph``
        only once the rest test has passed and while nothing contradicts it
        (:mod:`scattertrack.fusion.rest`); epochs before the verdict get theirs
        with the first epoch after it. Returns ``[(j, t_j, slots)]``: the
        epochs given ground factors and their positions in ``graph``."""
        p = self.params
        if self._rest_state == "pending":
            self._ground_backlog.append((k, time_s))
            return []
        if self._rest_state != "rest" or self._left_ground:
            self._ground_backlog = []
            return []
        samples = self._baro_samples(time_s)
        if p.use_baro and samples and rest.baro_contradicts_ground(float(np.mean(samples)), self._rest_baro_mean, p.ground_baro_rise_m):
            # The barometer's window mean lags its rise, and the IMU missed
            # it: the last ground_release_s of ground factors are suspect.
            self._end_ground(time_s, "barometer", p.ground_release_s)
            self._ground_backlog = []
            return []
        if not p.use_ground:
            self._ground_backlog = []
            return []
        added = []
        for j, t_j in [*self._ground_backlog, (k, time_s)]:
            first = graph.size()
            self._add_ground(graph, j)
            added.append((j, t_j, list(range(first, graph.size()))))
        self._ground_backlog = []
        return added

    def _record_ground(self, k: int, time_s: float, added) -> None:
        """After the update that added them: the smoother's indices of the
        ground factors in ``added`` (from :meth:`_ground_for_epoch`), so a
        later contradiction can remove them; older than 2 ``ground_release_s``
        (and 1 s) they are never removed and are forgotten."""
        indices = list(self._smoother.getISAM2Result().getNewFactorsIndices())
        for j, t_j, slots in added:
            self._ground_factor_indices[j] = [int(indices[i]) for i in slots]
            self._ground_epochs.append((t_j, j))
        keep = time_s - max(2.0 * self.params.ground_release_s, 1.0)
        for t_j, j in [e for e in self._ground_epochs if e[0] < keep]:
            self._ground_factor_indices.pop(j, None)
        self._ground_epochs = [e for e in self._ground_epochs if e[0] >= keep]

    def _add_ground(self, graph, k: int) -> None:
        """At rest at the origin before take-off: position, zero velocity and,
        from the previous epoch, zero rotation (which pins the gyroscope bias)."""
        p = self.params
        # Pose3 tangent order is (rotation, translation): the position prior
        # leaves the rotation free (its sigma is effectively infinite).
        position_sigmas = np.array([1.0e3] * 3 + [p.ground_position_sigma_m] * 3)
        graph.add(gtsam.PriorFactorPose3(X(k), gtsam.Pose3(), gtsam.noiseModel.Diagonal.Sigmas(position_sigmas)))
        graph.add(gtsam.PriorFactorVector(V(k), np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, p.ground_velocity_sigma_m_s)))
        if k > 0:
            rotation_sigmas = np.array([p.ground_rotation_sigma_rad] * 3 + [1.0e3] * 3)
            graph.add(
                gtsam.BetweenFactorPose3(X(k - 1), X(k), gtsam.Pose3(), gtsam.noiseModel.Diagonal.Sigmas(rotation_sigmas))
            )
