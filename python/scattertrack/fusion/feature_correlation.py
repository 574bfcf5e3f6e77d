"""How correlated the features' errors really are, measured from the features (issue 16).

The multipath model (:mod:`scattertrack.fusion.multipath`, docs/marvel.md
section 8) splits each feature's sigma into a white share ``f`` and a
Gauss-Markov share ``sqrt(1 - f^2)`` whose correlation from one epoch to the
next is ``phi = exp(-|dp| / d - dt / tau)``. ``f`` (``multipath_white_fraction``)
is a guess about the room: too small where the errors are white, and the
smoother averages too few rows (a metre-scale error stays); too large where
they are correlated, and the sigmas are too small.

The features tell the two apart once the drone's own motion is taken out.
Over ``L`` epochs the feature changes by the motion plus ``e_k - e_(k-L)``;
the motion comes from the IMU: the displacement each epoch's preintegration
predicted from the previous posterior, chained, is the relative path
without any feature in it (accurate to centimetres over seconds), and the
measurement function of that path from the controller estimate gives the
feature's change (a controller error cancels to first order). So

    δ_L(k) = z_k - z_(k-L) - [h(p_(k-L) + Σ dp) - h(p_(k-L))],   Var δ_L = 2 σ² (1 - r_L)

with ``r_L = s Φ_L`` for the model (``s = 1 - f²`` the correlated share of the
variance, ``Φ_L`` the product of the ``phi`` over the L steps). The ratio
``R = Var δ_L / Var δ_1 = (1 - s Φ_L) / (1 - s Φ_1)`` does not depend on the
sigma, which the features may misstate, and gives

    s = (R - 1) / (R Φ_1 - Φ_L).

White errors give ``R ≈ 1``, ``s ≈ 0``; the default model (``f = 0.5``) at
1.2 m/s gives ``R ≈ 2.2`` at ``L = 10`` (1 s at 10 Hz). The variances are
trimmed at 5 robust sigmas (outliers, gated rows). The estimate errs on the
correlated side: ``R`` is taken at its upper 2-sigma bound
``R (1 + 2 sqrt(2.4 / n))`` for ``n`` pairs (:data:`RATIO_VARIANCE`), so a
short log keeps more of the correlated share: white errors over 35 s (350
epochs) give ``f`` of about 0.85, not 1.
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.fusion.imu_noise import MAD_TO_SIGMA

LAG_EPOCHS = 10
"""L: epochs over which the long differences are taken (1 s at 10 Hz: the default model has nearly
decorrelated at 1 m/s, Φ_L ≈ 0.1, and the IMU path over it is good to a few cm)."""
WINDOW_EPOCHS = 400
"""Epochs kept (the newest): 40 s at 10 Hz."""
MIN_PAIRS = 60
"""Long differences needed before a measurement is given (about 8 s at 10 Hz)."""
RATIO_VARIANCE = 2.4
"""n Var(R) for white errors: 2.0 measured (3,000 simulated series of 100 and 350
epochs, lags 5 and 10: the standard deviation of R is sqrt(2 / n)), 20 % more
for the trimming's lost efficiency."""
TRIM_SIGMAS = 5.0
"""Differences beyond this many robust sigmas are left out of the variances."""


def measurement_function(position: np.ndarray, controller: np.ndarray) -> np.ndarray:
    """(range m, azimuth rad, elevation rad) of ``position`` seen from ``controller``
    (docs/formats.md section 7), for (n, 3) positions."""
    d = np.atleast_2d(position) - controller
    r = np.linalg.norm(d, axis=1)
    return np.stack([r, np.arctan2(d[:, 1], d[:, 0]), np.arcsin(np.clip(d[:, 2] / np.maximum(r, 1e-9), -1.0, 1.0))], 1)


def _trimmed_variance(x: np.ndarray) -> float:
    """Variance about zero of the values within TRIM_SIGMAS robust sigmas."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan
    scale = MAD_TO_SIGMA * float(np.median(np.abs(x)))
    kept = x[np.abs(x) <= TRIM_SIGMAS * scale] if scale > 0.0 else x
    return float(np.mean(kept**2)) if kept.size else math.nan


def correlated_share(ratio: float, phi_1: float, phi_l: float) -> float:
    """``s = (R - 1) / (R Φ_1 - Φ_L)``, clipped to [0, 1] (1 where the model cannot
    reach R: more correlated than any share of it)."""
    if not math.isfinite(ratio):
        return math.nan
    denominator = ratio * phi_1 - phi_l
    if denominator <= 0.0:
        return 1.0
    return float(min(max((ratio - 1.0) / denominator, 0.0), 1.0))


class FeatureCorrelationMeter:
    """The newest :data:`WINDOW_EPOCHS` epochs' features, IMU displacements and
    correlations (flat ring arrays); :meth:`correlated_shares` measures ``s`` for
    the range and for the direction."""

    def __init__(self, window: int = WINDOW_EPOCHS, lag: int = LAG_EPOCHS):
        self._window, self._lag = int(window), int(lag)
        self._features = np.full((self._window, 3), np.nan)  # range, azimuth, elevation
        self._anchor = np.full((self._window, 3), np.nan)  # posterior position of the previous epoch
        self._step = np.full((self._window, 3), np.nan)  # IMU-predicted displacement since it
        self._log_phi = np.full(self._window, np.nan)  # log of the model's correlation over the step
        self._count = 0
        self._chain_start = 0  # first epoch index whose step joins the one before

    def add(self, features, anchor, step, phi: float) -> None:
        """One epoch: its (range, azimuth, elevation), the previous epoch's
        posterior position ``anchor`` (m), the IMU-predicted displacement
        ``step`` (m) from it to this epoch and the model's ``phi`` for it."""
        slot = self._count % self._window
        self._features[slot] = features
        self._anchor[slot] = anchor
        self._step[slot] = step
        # A link that decorrelates fully (phi = 0) counts as e^-50: sums of logs stay finite.
        self._log_phi[slot] = max(math.log(phi), -50.0) if phi > 0.0 else -50.0
        self._count += 1

    def break_chain(self) -> None:
        """The next epoch does not follow the last (a restart): no difference spans the break."""
        self._chain_start = self._count

    def _ordered(self):
        n = min(self._count - self._chain_start, self._window)
        start = self._count - n
        index = np.arange(start, self._count) % self._window
        return self._features[index], self._anchor[index], self._step[index], self._log_phi[index]

    @staticmethod
    def _variances(z, anchor, path, controller, span: int) -> tuple[float, float]:
        """Trimmed variances of the range's and of the direction's ``δ_span``."""
        k = np.arange(span, len(z))
        j = k - span
        start = anchor[j + 1]  # the posterior at epoch j
        end = start + path[k] - path[j]
        delta = z[k] - z[j] - (measurement_function(end, controller) - measurement_function(start, controller))
        delta[:, 1:] = np.angle(np.exp(1j * delta[:, 1:]))
        # Azimuth as the tangent component, so both angles weigh alike.
        tangent = delta[:, 1] * np.cos(z[k, 2])
        return _trimmed_variance(delta[:, 0]), _trimmed_variance(np.concatenate([tangent, delta[:, 2]]))

    def correlated_shares(self, controller: np.ndarray) -> tuple[float, float, int] | None:
        """(range s, direction s, pairs) at their conservative bound, or None before
        :data:`MIN_PAIRS` long differences (or without a controller estimate)."""
        if controller is None or not np.all(np.isfinite(controller)):
            return None
        z, anchor, step, log_phi = self._ordered()
        n, lag = len(z), self._lag
        pairs = n - lag
        if pairs < MIN_PAIRS:
            return None
        path = np.cumsum(step, axis=0)  # path[k] - path[j] = displacement from epoch j to epoch k
        cumulative_log_phi = np.cumsum(log_phi)
        # (range, direction) variances of the short and the long differences.
        short, long = (self._variances(z, anchor, path, controller, span) for span in (1, lag))
        k = np.arange(lag, n)
        phi_1 = float(np.exp(np.median(log_phi[1:])))
        phi_l = float(np.exp(np.median(cumulative_log_phi[k] - cumulative_log_phi[k - lag])))
        bound = 1.0 + 2.0 * math.sqrt(RATIO_VARIANCE / pairs)
        shares = [
            correlated_share(long[kind] / short[kind] * bound if short[kind] > 0.0 else math.nan, phi_1, phi_l)
            for kind in (0, 1)
        ]
        return shares[0], shares[1], pairs


__all__ = ["FeatureCorrelationMeter", "correlated_share", "measurement_function"]
