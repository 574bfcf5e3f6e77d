"""The Marvel estimator's window: the fixed-lag smoother, its time stamps and its lag.

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator`. An
``IncrementalFixedLagSmoother`` (iSAM2 that marginalises the states older
than the lag) solves eq. 10 of the paper (sec. IV-D). Each state's stamp is
the end of its ``marginalize_every_s`` bucket, so states leave in groups,
once per bucket; the lag is ``smoother_lag_s``, longer while the heading is
held (``heading_hold_sigma_rad``). The revised rows read before a state
leaves are :mod:`scattertrack.fusion.revised`; the updates that run between
epochs (relinearisation, the end of the heading hold) are
:mod:`scattertrack.fusion.between_epochs`.
"""

from __future__ import annotations

import math

import gtsam


class Window:
    """Window methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _init_window(self) -> None:
        p = self.params
        self._smoother = self._new_smoother()
        self._lag = p.smoother_lag_s  # the smoother's lag now (longer while the heading is held)
        self._heading_held = p.heading_hold_sigma_rad > 0.0
        self._first_epoch_time: float | None = None
        self.heading_hold_end_s = float("nan")
        """Time (s) of the first update after the heading hold
        (``heading_hold_sigma_rad``) ended; nan while held or without a hold."""

    def _new_smoother(self):
        """An empty iSAM2 fixed-lag smoother with this estimator's settings."""
        p = self.params
        isam_params = gtsam.ISAM2Params()
        isam_params.setRelinearizeThreshold(p.relinearize_threshold)
        isam_params.relinearizeSkip = self._relinearization_period()
        # QR on the Jacobian instead of Cholesky on J^T J: the bias random
        # walk between 0.1 s epochs (1/sigma ~ 2e5 for the gyroscope) next to
        # metre-level feature noise gives cond(J) ~ 1e6, cond(J^T J) ~ 1e12,
        # where iSAM2's Cholesky reports an indeterminate system.
        isam_params.setFactorization(p.factorization)
        self._updates = 0  # updates of this smoother (iSAM2's update count)
        self._lag_pending: float | None = None  # a shorter lag, applied between epochs
        return gtsam.IncrementalFixedLagSmoother(p.smoother_lag_s, isam_params)

    def _smoother_update(self, *arguments) -> None:
        """One update of the smoother (its arguments), counted."""
        self._updates += 1
        self._smoother.update(*arguments)

    def _stamp(self, time_s: float) -> float:
        """The smoother's time stamp of a state at ``time_s`` (s): the end of
        its ``marginalize_every_s`` bucket (its own time with 0)."""
        every = self.params.marginalize_every_s
        if every <= 0.0:
            return time_s
        return (math.floor(time_s / every) + 1.0) * every

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

    def _set_lag(self, lag: float) -> None:
        if lag != self._lag:
            self._smoother.setSmootherLag(lag)
            self._lag = lag

    def _update_window(self, graph, initial, stamps: dict[int, float], time_s: float) -> dict[int, float]:
        """Adds this epoch's ``graph`` and ``initial`` values to the smoother,
        with the states' times ``stamps`` (s) turned into their bucket stamps
        (returned), and the ground factors that are to go removed.

        The update marginalises the states stamped before now - lag (a whole
        bucket at once: see ``marginalize_every_s``): their last revision is
        the smoother's estimate now, before the update. A shorter lag (the
        heading hold's end: seconds of states at once) waits for the update
        between this epoch and the next. Raises what the smoother raises
        (RuntimeError for an indeterminate system)."""
        stamps = {key: self._stamp(t) for key, t in stamps.items()}
        lag = self._lag_for(time_s)
        if lag < self._lag:
            self._lag_pending = lag
        else:
            self._set_lag(lag)
        self._release(self._stamp(time_s) - self._lag)
        removals, self._pending_removals = self._pending_removals, []
        self._smoother_update(graph, initial, stamps, removals)
        return stamps


__all__ = ["Window"]
