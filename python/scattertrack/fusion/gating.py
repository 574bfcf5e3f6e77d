"""Innovation gating of a feature row against the IMU-predicted state (pure).

Each measurement's normalised innovation squared ``nu^T S^-1 nu``, with
``S = H P H^T + R``, is compared with the chi-square quantile of the gate
probability (``MarvelParams.gate_probability``) for its degrees of freedom:
1 for the range and the yaw, 2 for the direction. Closed-form quantiles, no
scipy. The estimator's own bookkeeping of gated rows (runs of declines,
persistent gating) is the :class:`Gating` mixin of
:class:`scattertrack.fusion.estimator.MarvelEstimator`.
"""

from __future__ import annotations

import math
import statistics

import numpy as np

from scattertrack.fusion import divergence, factors


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


def gate_thresholds(probability: float | None) -> dict[int, float] | None:
    """The gate's chi-square bounds by degrees of freedom ``{1: .., 2: ..}``;
    None (no gating) for a probability that is 0 or None."""
    if not (probability and probability > 0.0):
        return None
    return {1: chi_square_gate(probability, 1), 2: chi_square_gate(probability, 2)}


def innovation_tests(
    gate: dict[int, float],
    predicted,
    controller: np.ndarray,
    cov_position: np.ndarray,
    cov_controller: np.ndarray,
    cov_yaw: float,
    range_m,
    azimuth_rad,
    elevation_rad,
    yaw_rad,
    range_sigma,
    direction_sigma,
    yaw_sigma,
    multipath=(0.0, 0.0, 0.0),
) -> tuple[bool, bool, bool]:
    """Whether the range, the direction and the yaw (None: not tested) each
    pass the ``gate`` (:func:`gate_thresholds`) against ``predicted`` (a
    gtsam NavState) and the ``controller`` position (m).

    ``P`` is the predicted position covariance ``cov_position`` (m^2, world)
    plus the controller's ``cov_controller`` (non-finite ones count as 0;
    their cross-covariance is left out: it is positive for a drone measured
    from the controller, so leaving it out widens ``S`` and the gate errs on
    accepting); ``cov_yaw`` rad^2. ``multipath``: the predicted multipath
    errors (range m, direction tangent rad) added to the predicted
    measurements; ``R`` is then the whole feature sigma, as if that
    prediction were no better than the stationary 1-sigma (errs on
    accepting too).
    """
    position = predicted.position()
    covariance = np.zeros((3, 3))
    if np.all(np.isfinite(cov_position)):
        covariance = covariance + cov_position
    if np.all(np.isfinite(cov_controller)):
        covariance = covariance + cov_controller
    multipath = np.asarray(multipath, dtype=float)
    residual, (h_position, _) = factors.range_residual(position, controller, range_m, jacobians=True)
    residual = residual + multipath[0]
    s = float((h_position @ covariance @ h_position.T)[0, 0]) + range_sigma**2
    range_ok = residual[0] ** 2 / s <= gate[1]
    residual, (h_position, _) = factors.direction_residual(position, controller, azimuth_rad, elevation_rad, jacobians=True)
    residual = residual + multipath[1:3]
    s = h_position @ covariance @ h_position.T + np.diag(direction_sigma**2)
    direction_ok = float(residual @ np.linalg.solve(s, residual)) <= gate[2]
    yaw_ok = True
    if yaw_rad is not None:
        residual = factors.yaw_residual(predicted.attitude().matrix(), yaw_rad)
        residual = factors.wrap_angle(residual + multipath[1] / max(math.cos(elevation_rad), 1e-3))
        s = (cov_yaw if math.isfinite(cov_yaw) else 0.0) + yaw_sigma**2
        yaw_ok = residual[0] ** 2 / s <= gate[1]
    return bool(range_ok), bool(direction_ok), bool(yaw_ok)



class Gating:
    """Gating methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`:
    the tests above on each row, the runs of declined rows, persistent gating."""

    def _init_gating(self) -> None:
        p = self.params
        self._gate = gate_thresholds(p.gate_probability)
        self._declined_run = 0
        self._range_declined_run = 0
        self._gate_monitor = divergence.GateMonitor(p.divergence_window_epochs, p.divergence_gated_fraction)

    def _gating_on(self) -> bool:
        """Whether this epoch's row is gated: a controller to gate against, a
        gate, fewer than ``max_declined_epochs`` declined rows in a row, and
        not on the ground (there the controller is placed by the rest rows
        together, a least-squares mean, not by whichever row came first)."""
        return (
            self._controller is not None
            and self._gate is not None
            and self._declined_run < self.params.max_declined_epochs
            and not self.on_ground
        )

    def _gate_row(self, row, predicted, sigmas, multipath_predicted, used: dict) -> bool:
        """Gates ``row`` (a :class:`FeatureRow`) against ``predicted``, setting
        ``used``'s range, direction and yaw and counting the declines; returns
        whether the gating is persistent (the state is wrong, not the rows)."""
        p = self.params
        has_yaw = row.yaw_rad is not None
        bias = np.array([self._range_bias if self._has_range_bias() else 0.0, 0.0, 0.0])
        used["range"], used["direction"], yaw_ok = innovation_tests(
            self._gate, predicted, self._controller, self._cov_position, self._cov_controller, self._cov_yaw,
            row.range_m, row.azimuth_rad, row.elevation_rad, row.yaw_rad,
            sigmas.range_m, sigmas.direction_rad, sigmas.yaw_rad, multipath_predicted + bias,
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
        return self._gate_monitor.add(not (used["range"] and used["direction"]))


__all__ = ["Gating", "chi_square_gate", "gate_thresholds", "innovation_tests"]
