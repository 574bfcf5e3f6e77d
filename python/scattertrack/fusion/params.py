"""The Marvel fusion's parameters (:class:`MarvelParams`) and their table.

Why the table is in Python, not the Rust core: the estimator that reads
these fields is Python (a GTSAM factor graph), so each field is declared
once, here, with its default, range, unit and one-line description
(:func:`scattertrack.parameter_rows.parameter`); the rows go to the core's
checker (``_core.ParameterTable``) once, so values are parsed and refused
exactly as the core's own tables do it (bool spellings, ranges, errors
naming the parameter). The method registry (Rust, ``track/registry.rs``)
lists ``marvel`` and ``ulocate`` with their table here.

Adding a parameter: one field below, declared with ``parameter(...)``;
docs/parameters.md is regenerated from it.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cache

from scattertrack.parameter_rows import parameter, rows_of

GRAVITY_M_S2 = 9.80665
"""Standard gravity, m/s^2; the world's gravity is ``(0, 0, -g)`` (docs/marvel.md section 1)."""


@dataclass
class MarvelParams:
    """Tuning of :class:`MarvelEstimator`; SI units. IMU defaults: docs/marvel.md section 3."""

    smoother_lag_s: float = parameter(4.0, "> 0", "s", "states older than this behind the newest epoch are marginalised (the revised track's lag)")
    """States older than this behind the newest epoch are marginalised, s.
    The causal rows barely depend on it; the revised track does, and the
    time per epoch grows with it: the once-a-second relinearisation
    (``relinearize_skip``) relinearises the whole window in iSAM2's batch
    step, the slowest epoch of each second and so the p99 (it runs between
    epochs: fusion/between_epochs.py). 4 s keeps the p99 within the 30 ms
    budget on a 2-core machine at nearly the same errors as a longer lag
    (the measurements: docs/notes/marvel-experiments.md)."""
    marginalize_every_s: float = parameter(1.0, ">= 0", "s", "states leave the window in groups spanning this long (<= smoother_lag_s; 0: each alone)")
    """States leave the window in groups spanning this long, s: each state's
    time stamp in the smoother is the end of its bucket ``[n T, (n + 1) T)``,
    so the states of one bucket are marginalised together, once per bucket,
    and each stays ``smoother_lag_s`` to ``smoother_lag_s + T`` in the window.
    Why: marginalising re-eliminates iSAM2's Bayes tree from the oldest
    clique to the root, which is the whole window (the controller is in every
    clique), and when most variables are affected iSAM2 relinearises every
    factor (its batch step); done each epoch, that was most of the time per
    epoch. The revised rows of a group are read together just before it
    leaves: the first marginal covariance walks the tree, the next ones reuse
    its cached separator marginals (a small fraction of its cost).
    0: each state stamped with its own time, marginalised alone."""
    gravity_m_s2: float = parameter(GRAVITY_M_S2, "> 0", "m/s^2", "magnitude of gravity; the world's gravity is (0, 0, -g)")
    accel_noise_density: float = parameter(1.0e-3, "> 0", "m/s^2/sqrt(Hz)", "accelerometer white noise")
    """Accelerometer white noise, m/s^2/sqrt(Hz)."""
    gyro_noise_density: float = parameter(8.7e-5, "> 0", "rad/s/sqrt(Hz)", "gyroscope white noise")
    """Gyroscope white noise, rad/s/sqrt(Hz)."""
    accel_bias_random_walk: float = parameter(1.0e-4, "> 0", "m/s^3/sqrt(Hz)", "accelerometer bias random walk")
    """Accelerometer bias random walk, m/s^3/sqrt(Hz)."""
    gyro_bias_random_walk: float = parameter(2.0e-5, "> 0", "rad/s^2/sqrt(Hz)", "gyroscope bias random walk")
    """Gyroscope bias random walk, rad/s^2/sqrt(Hz)."""
    accel_bias_sigma: float = parameter(0.02, "> 0", "m/s^2", "1-sigma of the accelerometer bias at take-off")
    """1-sigma of the accelerometer bias at take-off, m/s^2."""
    gyro_bias_sigma: float = parameter(0.002, "> 0", "rad/s", "1-sigma of the gyroscope bias at take-off")
    """1-sigma of the gyroscope bias at take-off, rad/s."""
    integration_sigma: float = parameter(1.0e-4, "> 0", "m/sqrt(Hz)", "position integration noise of the preintegration (sample-and-hold error)")
    """Position integration noise of the preintegration, m/sqrt(Hz): covers
    the sample-and-hold error of integrating discrete samples."""
    imu_noise_scale: float = parameter(1.0, "> 0", "", "multiplies the two white-noise densities (a margin for unmodelled vibration)")
    """Multiplies the two white-noise densities (a margin for unmodelled vibration)."""
    imu_noise_from_data: bool = parameter(True, "any", "", "measure the IMU's white noise from its samples and use it where it exceeds the stated densities")
    """Measure the accelerometer's and gyroscope's white-noise densities from
    the IMU's own samples (second differences, :mod:`scattertrack.fusion.imu_noise`)
    and preintegrate with the measured density wherever it exceeds the stated
    one by more than ``imu_noise_agreement``; the stated densities stay the
    floor. Why: a stated density below the real one makes the dead reckoning
    overconfident, the features are bent to it and the sigmas shrink
    (measurements: docs/marvel.md section 8)."""
    imu_noise_agreement: float = parameter(1.2, ">= 1", "", "a measured density up to this factor above the stated one counts as agreeing (the stated one is used)")
    """A measured density up to this factor above the stated one counts as
    agreeing and the stated one is used: the measurement's own spread over
    0.5 s of samples is about 6 % (1 sigma), and a well-stated IMU keeps the
    figures it was characterised with."""

    range_sigma_m: float = parameter(0.5, "> 0", "m", "1-sigma of a range when the features give none")
    """1-sigma of a range when the features give none, m."""
    angle_sigma_rad: float = parameter(0.05, "> 0", "rad", "1-sigma of azimuth and elevation when the features give none")
    """1-sigma of azimuth and elevation when the features give none, rad."""
    yaw_sigma_rad: float = parameter(0.15, "> 0", "rad", "1-sigma of a yaw when the features give none")
    """1-sigma of a yaw when the features give none, rad."""
    use_yaw: bool = parameter(True, "any", "", "yaw factors from the features' yaw column")

    correlation_distance_m: float = parameter(1.0, ">= 0", "m", "distance travelled, as the IMU predicts it, over which the features' multipath errors decorrelate; 0: every row independent")
    """Distance travelled over which the features' multipath errors
    decorrelate, m (a few wavelengths at 915 MHz), measured along the
    IMU-predicted displacements; 0: treat every row as independent. See
    ``correlation_time_s`` and ``multipath``.

    Twice the 0.5 m at which our simulator decorrelates them, because the
    travel the estimator sees is longer than the drone's: each epoch's
    displacement comes from the previous posterior's velocity, whose error
    adds length in every direction (measured on a lift-off: 2.2 m seen
    against 1.4 m flown in the climb, 0.3 m per second of hover). With 0.5 m
    the lift-off flights' sigmas were too small (rows beyond 3 sigma 4-6 %
    on dev seeds, 57 % on the worst); docs/marvel.md section 9."""
    correlation_time_s: float = parameter(5.0, "> 0", "s", "time over which they decorrelate at rest (people, doors)")
    """Time over which they decorrelate at rest (people, doors), s. Rows
    closer together than one decorrelation carry one measurement's worth of
    information between them, not one each. Without accounting for it the
    take-off rows, whose multipath error is one and the same, would pin the
    controller (and with it the whole trajectory: range and angle do not see
    a common shift) to that one error with a far too small covariance."""
    multipath: str = parameter("states", "any", "", "correlated errors as graph states (Gauss-Markov) or by inflating the feature sigmas", choices=("states", "inflation"))
    """How the correlation is accounted for. ``"states"``: the range and
    direction errors are states ``M(k)`` of the graph, a first-order
    Gauss-Markov process with correlation ``exp(-|dp| / correlation_distance_m
    - dt / correlation_time_s)`` between epochs (``|dp|`` the IMU-predicted
    displacement); a hovering drone's rows then inform the frozen error, not
    its position. ``"inflation"``: the feature sigmas are multiplied by
    sqrt(rows per decorrelation) and the rows treated as independent (the
    cheaper approximation; a long hover still adds up to a pull towards its
    one error). The yaw is always inflated."""
    white_floor_range_m: float = parameter(0.02, ">= 0", "m", "least white 1-sigma of a range with multipath=states")
    """Least white 1-sigma of a range with ``multipath = "states"``, m: a
    stiffer factor makes the (nonlinear) range, linearised where iSAM2 last
    relinearised, pull harder than its linearisation error allows."""
    white_floor_angle_rad: float = parameter(0.002, ">= 0", "rad", "least white 1-sigma of each direction component with multipath=states")
    """Least white 1-sigma of each direction component, rad (same reason)."""
    range_bias_sigma_m: float = parameter(0.5, ">= 0", "m", "1-sigma prior of a constant range bias state (walls' excess path); 0: no such state")
    """1-sigma prior of a constant range bias state ``W(0)`` (m, with
    ``multipath = "states"``): the excess path of walls between the
    controller and the drone, which the pose sensing cannot tell from range
    (brick: ``(sqrt(eps_r) - 1) t`` = 0.19 m per 20 cm wall, docs/marvel.md
    section 9; three walls 0.56 m). It is observable because the line of
    sight turns as the drone flies while a controller shift would move
    every range differently. 0: no such state."""
    multipath_white_fraction: float = parameter(0.5, "(0, 1)", "", "with multipath=states, the white share of each feature sigma; the rest is correlated")
    """With ``multipath = "states"``: the share of each feature sigma that is
    white (thermal) noise; the rest, ``sqrt(1 - f^2)``, is the correlated
    multipath error's 1-sigma (docs/marvel.md section 9: thermal errors are
    millimetres to centimetres, multipath decimetres)."""
    multipath_from_data: bool = parameter(True, "any", "", "with multipath=states, measure the features' white share from the features (IMU-corrected differences) instead of keeping multipath_white_fraction")
    """With ``multipath = "states"``: measure how much of the features' error
    is white from the features themselves, once 8 s of epochs are in
    (:mod:`scattertrack.fusion.feature_correlation`: the variance of 1 s
    differences over that of one-epoch differences, the drone's motion taken
    out with the IMU), separately for the range and the direction, and use
    it instead of ``multipath_white_fraction`` (kept within 0.2-0.95, erring
    on the correlated side). Why: white errors modelled as correlated leave
    a metre-scale error unaveraged; correlated errors modelled as white make
    the sigmas too small (measurements: docs/marvel.md section 8)."""
    use_ground: bool = parameter(True, "any", "", "zero-velocity and zero-rotation factors at the origin until the IMU first shows motion")
    """Before take-off the drone sits at rest at the origin: every epoch until
    the IMU first shows motion gets "still at the origin, not moving, not
    turning" factors (zero-velocity and zero-rotation updates, standard in
    inertial navigation). The zero rotation makes the gyroscope bias
    observable at rest; without it the bias is free to absorb the features'
    correlated errors, and the tilt it integrates drags the trajectory away
    by metres within seconds."""
    rest_gyro_threshold_rad_s: float = parameter(0.05, "> 0", "rad/s", "an IMU sample with a larger angular rate means the drone has left the ground")
    """An IMU sample with a larger angular rate means the drone has left the ground, rad/s."""
    rest_accel_threshold_m_s2: float = parameter(0.3, "> 0", "m/s^2", "... or with a specific force whose magnitude differs from g by more")
    """... or with a specific force whose magnitude differs from g by more, m/s^2."""
    rest_force_tolerance_m_s2: float = parameter(0.1, "> 0", "m/s^2", "rest test: | |mean specific force| - g | at most this over tilt_window_s")
    """Rest test (:mod:`scattertrack.fusion.rest`): the mean specific force's
    magnitude differs from g by at most this, m/s^2. Why 0.1: the
    accelerometer bias's 1-sigma is 0.02 per axis (3 sigma 0.06); a
    minimum-jerk lift-off to 2 m at 1 m/s accelerates by 0.3-0.8 m/s^2 in its
    first half second."""
    rest_accel_rms_m_s2: float = parameter(0.05, "> 0", "m/s^2", "rest test: RMS of the specific force about its mean at most this")
    """Rest test: RMS of the specific force about its window mean, m/s^2 (white
    noise alone: 0.017 at 1e-3 m/s^2/sqrt(Hz) and 100 Hz)."""
    rest_gyro_rms_rad_s: float = parameter(0.02, "> 0", "rad/s", "rest test: RMS angular rate at most this (bias included)")
    """Rest test: RMS angular rate over the window, bias included, rad/s (3
    bias sigmas of 0.002 rad/s per axis and the noise: about 0.011)."""
    rest_baro_rate_m_s: float = parameter(0.3, "> 0", "m/s", "rest test: |least-squares slope of baro_z| at most this")
    """Rest test: the barometer's least-squares slope over the window, m/s
    (3 sigma of the slope of 50 samples of 0.1 m noise over 0.5 s)."""
    ground_baro_rise_m: float = parameter(0.3, "> 0", "m", "on the ground: a barometer window mean this far from the rest window's ends the ground phase")
    """On the ground: a barometer window mean this far (m) from the rest
    window's mean contradicts "on the ground"; the ground phase ends and the
    last ``ground_release_s`` of ground factors are dropped (3 sigma of the
    difference of two window means plus the offset's walk over seconds)."""
    ground_release_s: float = parameter(0.3, ">= 0", "s", "ground factors of the epochs this long before the barometer contradicts the ground are removed")
    """When the barometer contradicts the ground (a climb the IMU's
    take-off detector missed), the ground factors of the epochs in the last
    this many seconds are removed from the graph, not obeyed (the window
    mean lags the rise). When the IMU ends the ground phase nothing is
    removed: every sample before was within the rest thresholds, so those
    factors are right (docs/notes/marvel-experiments.md)."""
    moving_velocity_sigma_m_s: float = parameter(2.0, "> 0", "m/s", "velocity prior of a log that does not start at rest, and of a restart after divergence")
    """1-sigma (m/s, per axis, zero mean) of the first state's velocity when
    the rest test has not passed (a log that starts in flight or while lifting
    off), and of the state a divergence restarts from."""
    ground_position_sigma_m: float = parameter(0.02, "> 0", "m", "1-sigma of 'at the origin' on the ground")
    """1-sigma of "at the origin" on the ground (the detector lags take-off by a few mm), m."""
    ground_velocity_sigma_m_s: float = parameter(0.01, "> 0", "m/s", "1-sigma of 'not moving' on the ground")
    """1-sigma of "not moving" on the ground, m/s."""
    ground_rotation_sigma_rad: float = parameter(1.0e-4, "> 0", "rad", "1-sigma of 'not turning' between two ground epochs")
    """1-sigma of "not turning" between two ground epochs, rad."""

    prior_position_sigma_m: float = parameter(0.05, "> 0", "m", "take-off prior at rest at the origin, 1-sigma per axis")
    """Take-off prior: at rest at the origin, 1-sigma per axis, m."""
    prior_velocity_sigma_m_s: float = parameter(0.1, "> 0", "m/s", "take-off prior on the velocity, 1-sigma per axis")
    prior_tilt_sigma_rad: float = parameter(0.05, "> 0", "rad", "1-sigma of roll and pitch from the averaged accelerometer")
    """1-sigma of roll and pitch from the averaged accelerometer, rad."""
    prior_yaw_sigma_rad: float = parameter(1.0, "> 0", "rad", "loose take-off yaw prior (the value comes from the first yaw feature)")
    """Loose take-off yaw prior, rad: the yaw's value comes from the first
    yaw feature when there is one (0 otherwise), its information from the
    yaw factors."""
    tilt_window_s: float = parameter(0.5, "> 0", "s", "the first IMU samples of the rest test (and averaged for roll and pitch at take-off)")
    """The first IMU samples over this span (s) are the rest test's window
    (:mod:`scattertrack.fusion.rest`) and, at rest, are averaged for roll
    and pitch at take-off. Ground factors begin only once it passed."""

    use_baro: bool = parameter(True, "any", "", "barometer factors when the IMU has baro_z")
    """Barometer factors when ``baro_z`` is given."""
    baro_sigma_m: float = parameter(0.1, "> 0", "m", "white noise of one barometer sample")
    """White noise of one barometer sample, m."""
    baro_random_walk: float = parameter(0.02, "> 0", "m/sqrt(s)", "random walk of the barometer's offset")
    """Random walk of the barometer's offset, m/sqrt(s)."""
    baro_window_s: float = parameter(0.05, "> 0", "s", "barometer samples in (t_k - window, t_k] are averaged for epoch k")
    """Barometer samples in (t_k - window, t_k] are averaged for epoch k, s;
    short, because their mean lags the epoch by about window / 2."""
    baro_offset_prior_sigma_m: float = parameter(100.0, "> 0", "m", "loose prior on the barometer's offset (an arbitrary datum)")
    """Loose prior on the offset (the barometer reads an arbitrary datum), m."""

    baro_datum_sigma_m: float = parameter(0.3, "> 0", "m", "1-sigma of the barometer reading height above the take-off point, used when no take-off pins the height")
    """1-sigma (m) of "the barometer reads height above the take-off point"
    (a flight controller zeroes it on the ground), used instead of the loose
    ``baro_offset_prior_sigma_m`` when no take-off state pins the height: a
    log whose IMU (and barometer) begin in flight, after its features. 0.3
    m: the offset's random walk (``baro_random_walk``, 0.02 m/sqrt(s) in the
    simulator) over five minutes between zeroing and take-off."""
    gate_probability: float = parameter(0.999, "[0, 1)", "", "chi-square gate on each measurement's normalised innovation; 0: no gate")
    """Chi-square gate on each measurement's normalised innovation (0: no gate)."""
    min_epoch_interval_s: float = parameter(1.0e-3, ">= 0", "s", "rows closer than this to the previous epoch are declined")
    """Rows closer than this to the previous epoch are declined: a
    preintegration over a vanishing interval has a near-singular covariance."""
    max_declined_epochs: int = parameter(5, ">= 0", "epochs", "after this many consecutive fully gated epochs the next row is taken ungated")
    """After this many consecutive epochs with every measurement gated, the
    next row is taken ungated (recovery from a wrong state instead of lock-out)."""
    robust: str | None = parameter(None, "any", "", "a Huber kernel on the feature factors, or none", choices=("huber",), optional=True)
    """None, or "huber": a Huber kernel on the feature factors."""
    huber_k: float = parameter(1.345, "> 0", "sigma", "threshold of the Huber kernel")

    max_speed_m_s: float = parameter(30.0, "> 0", "m/s", "a solve with the drone faster than this has diverged (row declined, smoother restarted)")
    """A solve with the drone faster than this has diverged, m/s (ten times
    the paper's fastest flight). Why a bound: behind reflecting walls at IQ
    level the closed loop of features and fusion ran away (a controller at
    1e108 m); the row is declined and the smoother restarts from the IMU's
    prediction, like a failed solve."""
    max_controller_range_m: float = parameter(1000.0, "> 0", "m", "a solve with the controller farther than this from the drone has diverged")
    """A solve with the controller farther than this from the drone has
    diverged, m (LoRa backscatter reaches tens of metres; paper: 50 m)."""

    max_position_m: float = parameter(1000.0, "> 0", "m", "a solve with the drone farther than this from the take-off point has diverged")
    """A solve with the drone farther than this from the take-off point has
    diverged, m (a drone at -49169 m was once printed as a result)."""
    divergence_window_epochs: int = parameter(20, ">= 0", "epochs", "epochs over which persistent gating is judged; 0: no such test")
    """Epochs over which persistent gating is judged (:mod:`scattertrack.fusion.divergence`); 0: none."""
    divergence_gated_fraction: float = parameter(0.8, "(0, 1]", "", "range or direction gated on this share of those epochs: diverged, restart from the features")
    """Range or direction gated on at least this share of the last
    ``divergence_window_epochs`` epochs means the state, not the rows, is
    wrong: the smoother restarts from the features and the barometer."""
    recovery_epochs: int = parameter(30, ">= 1", "epochs", "a divergence counts as recovered after this many epochs without another")
    """A divergence counts as recovered after this many accepted epochs in a
    row without another (3 s at 10 Hz)."""
    compute_sigma: bool = parameter(True, "any", "", "1-sigma position and controller in the output (marginal covariances; always with the gate on)")
    """1-sigma position and controller in the output, from iSAM2's marginal
    covariances of the newest pose, velocity and controller (about 0.4 ms of
    the 2-3 ms per epoch, p50). The gate needs them too, so they are computed
    whenever the gate is on; off with the gate off, the output sigmas are nan."""
    heading_hold_sigma_rad: float = parameter(0.2, ">= 0", "rad", "no state leaves the window while the heading's 1-sigma exceeds this; 0: no hold")
    """While the newest heading's marginal 1-sigma exceeds this (rad), no
    state leaves the window (up to ``heading_hold_max_s`` after the first
    epoch). Before the drone turns or accelerates sideways nothing observes
    its heading (no magnetometer): the take-off heading is a guess. A state
    marginalised then leaves a prior on the window linearised at that guess,
    which can be tens of degrees off, and the error stays in the window's
    prior after the heading has been found. Held, the first states are
    revised with the heading once the first turn or leg reveals it. 0: no hold."""
    heading_hold_max_s: float = parameter(20.0, ">= 0", "s", "longest heading hold after the first epoch")
    """Longest hold of ``heading_hold_sigma_rad`` after the first epoch, s: the
    window, and the time per update with it, stays bounded."""
    relinearize_threshold: float = parameter(0.01, ">= 0", "", "iSAM2 relinearises a variable whose update exceeds this (tangent units: rad, m, m/s)")
    """iSAM2 relinearises a variable whose update exceeds this (tangent units:
    rad, m, m/s)."""
    relinearize_skip: int = parameter(10, ">= 1", "epochs", "iSAM2 checks for relinearisation once every this many epochs (between epochs when > 1)")
    """iSAM2 checks for relinearisation once every this many epochs: once per
    ``marginalize_every_s`` at 10 epochs/s. Above 1 that check runs in an
    update of its own between two epochs (fusion/between_epochs.py). The controller is in every
    range and direction factor, so relinearising it (or any state deep in
    the window) re-eliminates the whole window; checked on every update
    with the 0.01 threshold, that happened on nearly every one (p50 32 ms
    per epoch against 2-3 ms). Other thresholds and skips give the same
    errors within a few millimetres (docs/notes/marvel-experiments.md)."""
    factorization: str = parameter("QR", "any", "", "iSAM2 factorization", choices=("QR", "CHOLESKY"))
    """iSAM2 factorization, "QR" or "CHOLESKY" (see the note in the constructor)."""
    extra_iterations: int = parameter(0, ">= 0", "", "additional iSAM2 updates per epoch (more Gauss-Newton steps)")
    """Additional iSAM2 updates per epoch (more Gauss-Newton steps)."""

    @classmethod
    def from_kwargs(cls, **kwargs) -> MarvelParams:
        """Params with the given fields changed (ValueError for unknown names)."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(kwargs) - names)
        if unknown:
            raise ValueError(f"unknown Marvel parameter(s): {', '.join(unknown)}")
        return cls(**kwargs)

    def __post_init__(self):
        # Every field through its row once: the types and ranges that
        # docs/parameters.md shows, text read as the command line reads it
        # ("false" is False), an int given for a float made a float.
        checked = fusion_table().check({f.name: getattr(self, f.name) for f in fields(self)})
        for name, value in checked.items():
            object.__setattr__(self, name, value)
        # What one row cannot say: a group of states must fit in the window.
        if not self.marginalize_every_s <= self.smoother_lag_s:
            raise ValueError("marginalize_every_s must be in [0, smoother_lag_s] (seconds)")


@cache
def fusion_table():
    """The table of :class:`MarvelParams` alone (the pose sensing's is added per method
    in :mod:`scattertrack.track.marvel_params`)."""
    from scattertrack import _core

    return _core.ParameterTable("marvel", rows_of(MarvelParams))
