"""The revised (fixed-lag smoothed) track of the Marvel estimator.

A mixin of :class:`scattertrack.fusion.estimator.MarvelEstimator`: each
state is read once more before it leaves the window (half a bucket ahead of
its group's marginalisation, docs/marvel.md section 8) and kept in
``revised``; a state whose smoother failed keeps its causal row.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from gtsam.symbol_shorthand import V, X

from scattertrack.fusion.estimate import Estimate


def _quaternion(pose) -> np.ndarray:
    """A Pose3's rotation as ``(qw, qx, qy, qz)`` with ``qw >= 0`` (one of the two equal quaternions)."""
    quaternion = pose.rotation().toQuaternion()
    q = np.array([quaternion.w(), quaternion.x(), quaternion.y(), quaternion.z()])
    return -q if q[0] < 0.0 else q


def _world_position_covariance(pose, pose_covariance) -> np.ndarray:
    """The world-frame position covariance (3, 3) m^2 of a Pose3 marginal:
    GTSAM's Pose3 tangent is [rotation, translation] in the body frame."""
    rotation = pose.rotation().matrix()
    return rotation @ np.asarray(pose_covariance)[3:, 3:] @ rotation.T


class RevisedTrack:
    """Revised-track methods of :class:`~scattertrack.fusion.estimator.MarvelEstimator`."""

    def _init_revised(self) -> None:
        # The states in the smoother's window: key -> (time stamp s, causal Estimate).
        self._window: dict[int, tuple[float, Estimate]] = {}
        # Revised rows read ahead of their bucket's marginalisation (see _prefetch).
        self._prefetched: dict[int, Estimate] = {}
        self.revised: list[Estimate] = []
        """Each accepted epoch's state as last revised before it left the
        window (fixed-lag smoothed, delayed by ``smoother_lag_s``), in time order."""
        self.revised_fallbacks = 0
        """Revised rows that are the causal estimate: the smoother failed (and
        restarted) while the state was in its window."""

    def finish(self) -> None:
        """End of the stream: the states still in the window join :attr:`revised`
        as the smoother holds them now. Rows added later continue the track."""
        self._release(math.inf)

    def _prefetch(self, time_s: float) -> None:
        """Reads the revised rows of the bucket that leaves at the next bucket
        boundary, at the first epoch past the middle of the current bucket
        (after its update).

        Why: the first marginal covariance read after an update walks iSAM2's
        tree from the oldest clique (8-10 ms at a 6 s lag), the following ones
        reuse its cache; read just before the marginalising update, as
        before, that walk fell on the same epoch as the marginalisation
        (18 ms) next to the relinearisation epoch (30 ms). Half a bucket
        earlier each row misses the last ``marginalize_every_s / 2`` of rows
        (its lag is ``smoother_lag_s - T/2`` to ``smoother_lag_s + T/2``).
        While the heading is held the horizon is before every state: nothing
        is read ahead (the hold's end releases them as before)."""
        every = self.params.marginalize_every_s
        if every <= 0.0:
            return
        bucket_start = self._stamp(time_s) - every
        if time_s - bucket_start < 0.5 * every:
            return
        horizon = self._stamp(time_s) + every - self._lag
        for key in sorted(j for j, (stamp, _) in self._window.items() if stamp < horizon and j not in self._prefetched):
            row = self._revise(key, self._window[key][1])
            if row is not None:
                self._prefetched[key] = row

    def _release(self, before_s: float, revise: bool = True) -> None:
        """Moves the window's states stamped before ``before_s`` (s) to
        :attr:`revised`: the row read ahead (:meth:`_prefetch`) if there is
        one, else read from the smoother when ``revise``, else (or when the
        smoother no longer holds one) their causal estimate."""
        for key in sorted(j for j, (stamp, _) in self._window.items() if stamp < before_s):
            _, causal = self._window.pop(key)
            row = self._prefetched.pop(key, None)
            if row is None and revise:
                row = self._revise(key, causal)
            if row is None:
                self.revised_fallbacks += 1
                row = causal
            self.revised.append(row)

    def _revise(self, k: int, causal: Estimate) -> Estimate | None:
        """State ``k`` as the smoother holds it now: the causal row with its
        position, velocity, orientation and (with ``compute_sigma``) 1-sigma
        position replaced; None if the smoother cannot give it."""
        smoother = self._smoother
        try:
            pose = smoother.calculateEstimatePose3(X(k))
            velocity = np.asarray(smoother.calculateEstimateVector(V(k)), dtype=float)
            sigma = causal.sigma
            if self.params.compute_sigma:
                cov = _world_position_covariance(pose, smoother.marginalCovariance(X(k)))
                sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        except (RuntimeError, IndexError):
            return None
        position = np.asarray(pose.translation(), dtype=float)
        if not (np.all(np.isfinite(position)) and np.all(np.isfinite(velocity))):
            return None
        return replace(causal, position=position, velocity=velocity, orientation=_quaternion(pose), sigma=sigma)
