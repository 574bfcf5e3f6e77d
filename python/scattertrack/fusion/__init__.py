"""Backscatter-inertial fusion of the Marvel pipeline (paper sec. IV, docs/marvel.md section 8).

Contract
--------
In: the drone's IMU samples (:class:`scattertrack.io.types.Imu`, docs/formats.md
section 6: specific force m/s^2 and angular rate rad/s in the body frame x
forward, y left, z up; optional barometric height m) and the backscatter
pose features (:class:`scattertrack.io.types.Features`, docs/formats.md section 7:
range m, azimuth and elevation rad of the drone seen from the controller,
optional yaw rad, optional 1-sigmas), on one clock in seconds.

Out: one estimate per accepted feature row (sensing epoch, ~10 Hz), in the
world frame (origin at take-off, z up, x along the controller's array):
body position m, velocity m/s, orientation world_T_body quaternion
``(qw, qx, qy, qz)``, 1-sigma position m (from the smoother's marginal
covariance), the controller's position ``rho`` m (unknown, estimated with
the trajectory) and the wall time spent on the row s. In batch form
(:func:`run_marvel`) a :class:`scattertrack.io.types.Track` with ``epc =
"drone"`` and the declined rows counted by reason in ``skipped``.

Causality: the estimate of a row uses only IMU samples and rows at or before
its time; it is the smoother's estimate of the newest state just after that
row, never a later smoothed value, so appending data cannot change it.

Assumptions: the drone starts at the world origin (at rest only if the rest
test says so; or, when the features begin before the IMU, the origin is
where the first feature row saw it); gravity is 9.80665 m/s^2 along -z;
the IMU sits at the body origin.

Modules (layers point one way, each file one concept): the pure ones,
:mod:`.factors` (measurement models with Jacobians, and their GTSAM
factors), :mod:`.rest` (the rest test), :mod:`.divergence` (physical
bounds, persistent gating, positions from the features), :mod:`.gating`
(the chi-square innovation gate, then its mixin); the records
:mod:`.estimate` (``Estimate``, ``FeatureRow``), :mod:`.declines`,
:mod:`.keys`, :mod:`.params` (the typed parameters), :mod:`.latency` (the
typed latency record); :mod:`.estimator`, the causal fixed-lag smoother,
a short orchestration of named steps whose mixins hold one concept each:
:mod:`.imu` (IMU stream, preintegration), :mod:`.take_off` (first state,
anchor row, controller), :mod:`.ground` (the ground phase),
:mod:`.multipath`, :mod:`.measurements` (the rows' factors),
:mod:`.barometer`, :mod:`.window` (smoother, stamps, lag),
:mod:`.between_epochs` (the once-a-second work off the rows' path),
:mod:`.readout`, :mod:`.restart` (after a failed solve or a divergence),
:mod:`.revised` (the revised track); and :mod:`.run`, the run helper
behind both entry points.
"""

from scattertrack.fusion.declines import DECLINE_REASONS, IMU_DECLINE_REASONS
from scattertrack.fusion.estimate import Estimate
from scattertrack.fusion.estimator import MarvelEstimator
from scattertrack.fusion.gating import chi_square_gate
from scattertrack.fusion.imu import tilt_from_specific_force
from scattertrack.fusion.params import MarvelParams
from scattertrack.fusion.run import run_marvel

__all__ = [
    "DECLINE_REASONS",
    "IMU_DECLINE_REASONS",
    "Estimate",
    "MarvelEstimator",
    "MarvelParams",
    "chi_square_gate",
    "run_marvel",
    "tilt_from_specific_force",
]
