"""The barometer in the Marvel estimator's graph: height factors and the offset chain ``O(k)``.

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator`. Each
epoch's height is the mean of the barometer's samples over the last
``baro_window_s`` (white noise averages down over them) plus the offset
``O(k)``, a random walk between epochs. The chain's first offset gets a
loose prior, or, when no take-off pins the height (a log begun in flight),
the barometer's own datum if the features agree with it.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from gtsam.symbol_shorthand import O, X

from scattertrack.fusion import factors


class Barometer:
    """Barometer methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _init_barometer(self) -> None:
        self._baro_chain = False  # O(k) exists for the newest state
        self._baro_key = -1  # index k of the newest O(k)
        self._baro_time = float("nan")
        self._baro_offset = 0.0
        self._baro_datum = float("nan")  # the barometer offset over the first seconds, m

    def _baro_samples(self, time_s: float) -> list[float]:
        """The barometer's heights (m) in the window ``(time_s - baro_window_s, time_s]``."""
        window_s = self.params.baro_window_s
        return [b for (t, b) in self._baro if time_s - window_s < t <= time_s]

    def _add_baro(self, graph, initial, stamps, time_s: float, predicted: gtsam.NavState) -> bool:
        """Barometer: height + offset O(k) = mean of the samples in the window;
        O(k) follows a random walk between epochs. Returns whether a height
        factor was added."""
        p = self.params
        if not p.use_baro:
            return False
        samples = self._baro_samples(time_s)
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

    def _read_baro(self, smoother) -> None:
        """After an update: the newest offset's estimate, and while the take-off
        (or the first state's prior) pins it, the datum a restart from the
        features takes the height from."""
        if self._baro_chain:
            self._baro_offset = smoother.calculateEstimateDouble(O(self._baro_key))
            if self.epochs < 20 and self.divergences == 0:
                self._baro_datum = float(self._baro_offset)


__all__ = ["Barometer"]
