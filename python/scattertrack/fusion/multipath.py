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
from scattertrack.fusion.keys import RANGE_BIAS


class Multipath:
    """Multipath methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _init_multipath(self) -> None:
        self._range_bias = 0.0  # estimate of the constant range bias, m
        self._multipath_chain = False  # M(k) exists for the newest state
        self._multipath_key = -1  # index k of the newest M(k)
        self._multipath = np.zeros(3)  # its estimate: range m, direction tangent rad
        self._multipath_sigma = np.ones(3)  # its stationary 1-sigma

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

    def _read_multipath(self, smoother) -> None:
        """After an update: the newest multipath state's and the range bias's estimates."""
        if self._multipath_chain:
            self._multipath = np.asarray(smoother.calculateEstimateVector(M(self._multipath_key)), dtype=float)
        if self._has_range_bias():
            self._range_bias = float(smoother.calculateEstimateDouble(RANGE_BIAS))


__all__ = ["Multipath"]
