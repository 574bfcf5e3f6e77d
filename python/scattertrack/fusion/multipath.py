"""Multipath in the Marvel estimator: Gauss-Markov states ``M(k)``, the range bias, or inflation.

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator` (the
model: docs/marvel.md section 9). A reflection's error in a row's range and
direction persists while the drone moves less than ``correlation_distance_m``
and for less than ``correlation_time_s``. With ``multipath = "states"`` each
epoch carries ``M(k)`` (range m, direction's two tangent components rad),
linked to ``M(k-1)`` by ``phi = exp(-|dp| / d - dt / tau)``, and (with
``range_bias_sigma_m > 0``) one constant range bias ``W(0)``; otherwise the
rows' sigmas are inflated by ``sqrt(rows per decorrelation)``.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from gtsam.symbol_shorthand import M

from scattertrack.fusion import factors
from scattertrack.fusion.feature_correlation import FeatureCorrelationMeter
from scattertrack.fusion.keys import RANGE_BIAS

WHITE_FRACTION_BOUNDS = (0.2, 0.95)
"""The white share ``f`` of a feature's sigma as measured is kept within these:
below 0.2 the white variance is under 4 %, which a few hundred rows cannot
tell from none; above 0.95 the correlated states keep 10 % of the variance
(their factors stay finite, and a room that changes is not ruled out)."""
MEASURE_EVERY_EPOCHS = 10
"""The features' correlation is measured again after this many epochs (1 s at 10 Hz)."""


class Multipath:
    """Multipath methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _init_multipath(self) -> None:
        self._range_bias = 0.0  # estimate of the constant range bias, m
        self._multipath_chain = False  # M(k) exists for the newest state
        self._multipath_key = -1  # index k of the newest M(k)
        self._multipath = np.zeros(3)  # its estimate: range m, direction tangent rad
        self._multipath_sigma = np.ones(3)  # its stationary 1-sigma
        self._white_fraction = np.full(3, self.params.multipath_white_fraction)
        """(range, direction tangent 1, tangent 2) white share ``f`` in use: the
        stated one until the features show theirs (feature_correlation.py)."""
        self._feature_meter = FeatureCorrelationMeter()
        self._last_phi = math.nan  # the Gauss-Markov correlation of the newest link
        self._epochs_observed = 0
        self.multipath_measured: tuple[float, float, int] | None = None
        """The newest measured correlated shares of the variance (range, direction)
        and the long differences they rest on; None before enough epochs."""

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
        correlated = np.asarray(sigma, dtype=float) * np.sqrt(1.0 - self._white_fraction**2)
        self._last_phi = math.nan
        predicted_error = np.zeros(3)
        if self._multipath_chain and self._last_epoch_time is not None and previous_position is not None:
            moved = float(np.linalg.norm(np.asarray(predicted.position(), dtype=float) - previous_position))
            elapsed = time_s - self._last_epoch_time
            if p.correlation_distance_m > 0.0 and p.correlation_time_s > 0.0:
                phi = math.exp(-moved / p.correlation_distance_m - elapsed / p.correlation_time_s)
            else:
                phi = 0.0
            decay = np.full(3, phi)
            self._last_phi = phi
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

    def _observe_features(self, row, previous_position, predicted) -> None:
        """The row's features join the correlation measurement (with the IMU's
        displacement since the previous posterior and the link's ``phi``); once
        every :data:`MEASURE_EVERY_EPOCHS` the white shares in use are set from
        it (``multipath_from_data``; docs/marvel.md section 8)."""
        p = self.params
        if not (p.multipath_from_data and p.multipath == "states"):
            return
        if previous_position is None or not math.isfinite(self._last_phi):
            self._feature_meter.break_chain()
            return
        step = np.asarray(predicted.position(), dtype=float) - previous_position
        self._feature_meter.add((row.range_m, row.azimuth_rad, row.elevation_rad), previous_position, step, self._last_phi)
        self._epochs_observed += 1
        if self._epochs_observed % MEASURE_EVERY_EPOCHS:
            return
        measured = self._feature_meter.correlated_shares(self._controller)
        if measured is None or not all(math.isfinite(v) for v in measured[:2]):
            return
        self.multipath_measured = measured
        low, high = WHITE_FRACTION_BOUNDS
        range_f, direction_f = (min(max(math.sqrt(1.0 - share), low), high) for share in measured[:2])
        self._white_fraction = np.array([range_f, direction_f, direction_f])

    def _read_multipath(self, smoother) -> None:
        """After an update: the newest multipath state's and the range bias's estimates."""
        if self._multipath_chain:
            self._multipath = np.asarray(smoother.calculateEstimateVector(M(self._multipath_key)), dtype=float)
        if self._has_range_bias():
            self._range_bias = float(smoother.calculateEstimateDouble(RANGE_BIAS))


__all__ = ["Multipath"]
