"""The Marvel estimator's work between epochs: the once-a-second updates off the rows' path.

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator`. Three
pieces of the window's bookkeeping cost more than a row's update and do not
change that row's estimate; they run after the row's estimate has been
returned, at the first IMU sample that follows (the idle time before the
next row), else at the start of the next row, timed apart
(``MarvelEstimator.between_epochs_times_s``):

1. relinearisation. iSAM2 checks for it every ``relinearize_skip`` updates
   and then relinearises nearly every variable of the window (the
   controller is in every clique, and the deltas have grown past the
   threshold over the skipped updates): measured on ``marvel-circle-20m``,
   252 of 252 variables, 25-30 ms of thread CPU time against 2-3 ms for a
   row's update, and so the p99 and the maximum of the time per epoch. The
   smoother's ``relinearizeSkip`` is ``relinearize_skip + 1``, and the
   update that relinearises is an empty one between two rows: one
   relinearisation per ``relinearize_skip`` rows, as before;
2. the end of the heading hold (``heading_hold_sigma_rad``): the lag drops
   from the seconds held to ``smoother_lag_s`` and those seconds of states
   leave the window in one update (45-80 ms of thread CPU time on the
   circle, 7 s held, measured);
3. the revised rows read ahead of their bucket's marginalisation
   (:meth:`RevisedTrack._prefetch`, 5-8 ms): read between epochs they are
   the same rows, the smoother being the same.

An empty update leaves iSAM2's batch step without new factors, whose keys
it orders last; its ordering then left the next rows' updates
re-eliminating twice the variables (41-51 against 24 per update,
measured). So these updates carry zero-information priors (sigma
infinite: they change no estimate) on the keys the next row touches,
removed with that row's update. Measurements and what was tried:
docs/notes/marvel-epoch-budget.md.
"""

from __future__ import annotations

import math
import time

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, M, O, V, X

from scattertrack.fusion.keys import CONTROLLER, RANGE_BIAS


class BetweenEpochs:
    """Between-epoch methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _init_between_epochs(self) -> None:
        self.between_epochs_times_s: list[float] = []
        """Wall time of each run of the work between epochs, s (:mod:`scattertrack.fusion.between_epochs`)."""
        self._between_epochs_due = False
        self._prefetch_time: float | None = None  # the epoch (s) whose revised rows are to be read ahead

    def _relinearization_period(self) -> int:
        """iSAM2's ``relinearizeSkip``: ``relinearize_skip`` row updates and the
        one between epochs that relinearises; 1 (every update) stays 1."""
        skip = self.params.relinearize_skip
        return skip + 1 if skip > 1 else 1

    def _relinearization_next(self) -> bool:
        """Whether the smoother's next update is one that relinearises (and can run between epochs)."""
        period = self._relinearization_period()
        return period > 1 and (self._updates + 1) % period == 0

    def _schedule_between_epochs(self, time_s: float) -> None:
        """After the epoch at ``time_s`` (s): what is to run before the next one."""
        self._prefetch_time = time_s
        self._between_epochs_due = True

    def _run_between_epochs(self) -> None:
        """The work due since the last epoch (module docstring): the revised
        rows read ahead, the lag's drop, the relinearisation; then the newest
        state's estimates follow the smoother, as they would have after a
        row's update that did the same. A solve that fails restarts the
        smoother from the newest state (counted in ``restarts``); an estimate
        not finite or beyond the bounds leaves them as they were, and the
        next row's update finds it."""
        self._between_epochs_due = False
        started = time.perf_counter()
        if self._prefetch_time is not None:
            self._prefetch(self._prefetch_time)
            self._prefetch_time = None
        updated = False
        try:
            if self._lag_pending is not None:
                lag, self._lag_pending = self._lag_pending, None
                self._set_lag(lag)
                self._release(self._stamp(self._last_epoch_time) - lag)
                self._anchored_update()
                updated = True
            if self._relinearization_next():
                self._anchored_update()
                updated = True
        except RuntimeError:
            self._release(math.inf, revise=False)
            self._restart(self._key, self._last_epoch_time, self._nav)
            self.restarts += 1
        else:
            if updated:
                try:
                    self._read_state()
                except RuntimeError:
                    pass
        if self._preintegrated.deltaTij() == 0.0:
            self._restart_integration()
        self.between_epochs_times_s.append(time.perf_counter() - started)

    def _anchored_update(self) -> None:
        """An update without rows, carrying :meth:`_ordering_anchors` (removed with the next update)."""
        self._smoother_update(self._ordering_anchors(), gtsam.Values(), {})
        self._pending_removals.extend(int(i) for i in self._smoother.getISAM2Result().getNewFactorsIndices())

    def _ordering_anchors(self) -> gtsam.NonlinearFactorGraph:
        """Zero-information priors (sigma infinite) on the keys the next row's
        update touches: the newest state, the controller, the newest
        multipath and barometer states, the range bias. They change no
        estimate; as new factors they make iSAM2's batch step order these
        keys last (see the module docstring)."""
        k = self._key
        graph = gtsam.NonlinearFactorGraph()
        none = {dim: gtsam.noiseModel.Isotropic.Precision(dim, 0.0) for dim in (1, 3, 6)}
        graph.add(gtsam.PriorFactorPose3(X(k), gtsam.Pose3(), none[6]))
        graph.add(gtsam.PriorFactorVector(V(k), np.zeros(3), none[3]))
        graph.add(gtsam.PriorFactorConstantBias(B(k), gtsam.imuBias.ConstantBias(), none[6]))
        graph.add(gtsam.PriorFactorPoint3(CONTROLLER, np.zeros(3), none[3]))
        if self._multipath_chain:
            graph.add(gtsam.PriorFactorVector(M(self._multipath_key), np.zeros(3), none[3]))
        if self._baro_chain:
            graph.add(gtsam.PriorFactorDouble(O(self._baro_key), 0.0, none[1]))
        if self._has_range_bias():
            graph.add(gtsam.PriorFactorDouble(RANGE_BIAS, 0.0, none[1]))
        return graph


__all__ = ["BetweenEpochs"]
