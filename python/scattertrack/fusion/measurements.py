"""A feature row's measurement factors in the Marvel estimator's graph (paper sec. IV-C, eq. 12).

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator`: the
row's sigmas for this epoch (inflated for the correlated multipath unless
it has its own states, :mod:`scattertrack.fusion.multipath`), and its range,
direction and yaw factors (:mod:`scattertrack.fusion.factors`), each only
when it passed the gate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gtsam
import numpy as np
from gtsam.symbol_shorthand import M, X

from scattertrack.fusion import factors
from scattertrack.fusion.keys import CONTROLLER, RANGE_BIAS


@dataclass(frozen=True)
class RowSigmas:
    """One row's 1-sigmas as they enter this epoch's factors and gate."""

    range_m: float
    direction_rad: np.ndarray
    """The direction's two tangent components, (2,) rad."""
    yaw_rad: float
    inflation: float
    """The correlation inflation ``sqrt(rows per decorrelation)`` applied (>= 1)."""


class FeatureFactors:
    """Measurement-factor methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _row_sigmas(self, row, predicted) -> RowSigmas:
        """The sigmas of ``row`` (a :class:`FeatureRow`) at this epoch: with
        multipath states the range's and the direction's are the row's (the
        states carry the correlated share), else inflated; the yaw's always."""
        inflation = self._correlation_inflation(row.time_s, predicted)
        range_sigma, angle_sigma = row.range_sigma_m, row.angle_sigma_rad
        if self.params.multipath != "states":
            range_sigma *= inflation
            angle_sigma *= inflation
        yaw_sigma = row.yaw_sigma_rad * inflation
        return RowSigmas(range_sigma, factors.direction_sigmas(row.elevation_rad, angle_sigma), yaw_sigma, inflation)

    def _noise(self, sigmas: np.ndarray):
        model = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
        if self.params.robust == "huber":
            # Huber: quadratic within huber_k sigma, linear beyond, so a
            # moderate outlier that passed the gate pulls less.
            return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(self.params.huber_k), model)
        return model

    def _add_feature_factors(self, graph, k: int, row, sigmas: RowSigmas, used: dict) -> None:
        """The range, direction and yaw factors of ``row`` on state ``k`` that ``used`` allows."""
        if self.params.multipath == "states":
            self._add_multipath_factors(graph, k, row, sigmas, used)
            return
        if used["range"]:
            graph.add(factors.range_factor(X(k), CONTROLLER, row.range_m, self._noise(np.array([sigmas.range_m]))))
        if used["direction"]:
            graph.add(
                factors.direction_factor(
                    X(k), CONTROLLER, row.azimuth_rad, row.elevation_rad, self._noise(sigmas.direction_rad)
                )
            )
        if used["yaw"]:
            graph.add(factors.yaw_factor(X(k), float(row.yaw_rad), self._noise(np.array([sigmas.yaw_rad]))))

    def _add_multipath_factors(self, graph, k: int, row, sigmas: RowSigmas, used: dict) -> None:
        """The same with the multipath state ``M(k)``: each factor keeps the
        white (thermal) share of its sigma, the rest is in ``M(k)``."""
        p = self.params
        white = self._white_fraction  # (range, direction tangents): stated, or measured
        range_white = max(white[0] * sigmas.range_m, p.white_floor_range_m)
        direction_white = np.maximum(white[1:] * sigmas.direction_rad, p.white_floor_angle_rad)
        if used["range"]:
            graph.add(
                factors.range_factor_multipath(
                    X(k), CONTROLLER, M(k), row.range_m, self._noise(np.array([range_white])),
                    RANGE_BIAS if self._has_range_bias() else None,
                )
            )
        if used["direction"]:
            graph.add(
                factors.direction_factor_multipath(
                    X(k), CONTROLLER, M(k), row.azimuth_rad, row.elevation_rad, self._noise(direction_white)
                )
            )
        if used["yaw"]:
            # The yaw's azimuth share is M(k)'s; what is left is the
            # rotational Doppler's own error (inflated: not in M). The
            # features give one yaw sigma, so the split is a guess: the
            # own share is kept at half the whole or more, lest a row
            # whose sigma is mostly azimuth pin the heading to M(k).
            yaw_sigma = sigmas.yaw_rad
            azimuth_sigma = sigmas.direction_rad[0] / max(math.cos(row.elevation_rad), 1e-3)
            own = math.sqrt(max(yaw_sigma**2 - (sigmas.inflation * azimuth_sigma) ** 2, (0.5 * yaw_sigma) ** 2))
            graph.add(factors.yaw_factor_multipath(X(k), M(k), float(row.yaw_rad), row.elevation_rad, self._noise(np.array([own]))))


__all__ = ["FeatureFactors", "RowSigmas"]
