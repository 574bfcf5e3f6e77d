"""One tracker interface for every pipeline (track/base.py): every registered
method through ``st.track.make`` and ``step``, ``run`` as a loop over ``step``,
and a clear error when a method is given the wrong kind of input.

Seeds 7100+ (no scoring data reused).
"""

import numpy as np
import pytest

import scattertrack as st
from scattertrack.fusion import MarvelEstimator, MarvelParams, run_marvel
from scattertrack.sim import load_scenario, simulate
from scattertrack.sim.marvel import simulate_marvel_iq
from scattertrack.track import base, marvel


@pytest.fixture(scope="module")
def reads_sim():
    return simulate(load_scenario("glac-2d-10cms") | {"duration_s": 2.0}, seed=7101)


@pytest.fixture(scope="module")
def frames_sim():
    return simulate(load_scenario("turbotrack-3d-arm") | {"duration_s": 1.0}, seed=7102)


@pytest.fixture(scope="module")
def drone_sim():
    return simulate(load_scenario("marvel-hover") | {"duration_s": 6.0}, seed=7103)


def reads_of(data):
    r = data.reads
    return [st.track.Read(r.time_s[i], r.epc[i], int(r.antenna[i]), r.frequency_hz[i], r.phase_rad[i]) for i in range(len(r))]


def frames_of(data, n=None):
    frames = data.frames
    out = []
    for k in range(frames.n_frames if n is None else min(n, frames.n_frames)):
        rx, f, h = frames.frame(k)
        tx = int(frames.tx[frames.frame_start[k]])
        out.append(st.track.Frame(frames.frame_time_s[k], frames.frame_epc[k], tx, rx, f, h))
    return out


def drone_steps(imu, features):
    """IMU samples and feature rows in the causal order of ``run``: the samples
    at or before each row's time, then the row; none after the last row."""
    given = 0
    for row in np.argsort(features.time_s, kind="stable"):
        end = int(np.searchsorted(imu.time_s, features.time_s[row], side="right"))
        for i in range(given, end):
            yield st.track.ImuSample(imu.time_s[i], imu.accel[i], imu.gyro[i], imu.baro_z[i])
        given = max(given, end)
        yield st.track.Feature(
            features.time_s[row], features.range_m[row], features.azimuth_rad[row], features.elevation_rad[row],
            features.yaw_rad[row], features.range_sigma_m[row], features.angle_sigma_rad[row], features.yaw_sigma_rad[row],
        )


def test_every_input_kind_has_its_measurements():
    kinds = {"reads", "frames", "features+imu", "sigmf+imu"}
    assert {m.input for m in st.track.REGISTRY.values()} <= kinds
    assert st.track.WIDEBAND_METHODS == st.track.HELPER_METHODS
    assert set(st.track.METHODS) == set(st.track.REGISTRY)


@pytest.mark.parametrize("method", list(st.track.REGISTRY))
def test_every_method_is_reachable_through_make(method, reads_sim, frames_sim, drone_sim):
    entry = st.track.REGISTRY[method]
    if entry.input == "reads":
        # Unpruned inference (glac-naive) grows with every read: a few are enough here.
        scene, steps = reads_sim.scene, reads_of(reads_sim)[: 12 if method == "glac-naive" else None]
    elif entry.input == "frames":
        scene, steps = frames_sim.scene, frames_of(frames_sim, 60)
    else:
        scene, steps = drone_sim.scene, list(drone_steps(drone_sim.imu, drone_sim.features))
    tracker = st.track.make(method, scene)
    assert isinstance(tracker, base.Tracker) and tracker.method == method
    estimates = [e for e in map(tracker.step, steps) if e is not None]
    for e in estimates:
        assert isinstance(e, st.track.Estimate)
        assert e.position.shape == (3,) and e.velocity.shape == (3,) and e.covariance.shape == (6, 6)
    assert tracker.stats()
    if entry.pipeline == "drone":
        assert estimates and estimates[-1].epc == "drone" and estimates[-1].orientation.shape == (4,)
    elif method in ("glac", "glac-naive", "turbotrack"):
        assert estimates


def test_core_run_equals_a_loop_over_step(reads_sim):
    batch = st.track.run("glac", reads_sim.scene, reads_sim.reads)
    tracker = st.track.make("glac", reads_sim.scene)
    streamed = [e for e in map(tracker.step, reads_of(reads_sim)) if e is not None]
    np.testing.assert_array_equal(np.array([e.position for e in streamed]), batch.position)
    np.testing.assert_array_equal(np.array([e.time_s for e in streamed]), batch.time_s)
    # The old positional form is the same step.
    old = st.track.Tracker("glac", reads_sim.scene)
    r = reads_sim.reads
    first = [old.step(r.time_s[i], r.epc[i], int(r.antenna[i]), r.frequency_hz[i], r.phase_rad[i]) for i in range(len(r) // 2)]
    again = [e for e in first if e is not None]
    np.testing.assert_array_equal(np.array([e.position for e in again]), batch.position[: len(again)])


def test_helper_run_equals_a_loop_over_step(frames_sim):
    batch = st.track.run("turbotrack", frames_sim.scene, frames_sim.frames)
    tracker = st.track.make("turbotrack", frames_sim.scene)
    streamed = [e for e in map(tracker.step, frames_of(frames_sim)) if e is not None]
    np.testing.assert_array_equal(np.array([e.position for e in streamed]), batch.position)


def test_marvel_run_equals_a_loop_over_step(drone_sim):
    imu, features = drone_sim.imu, drone_sim.features
    batch = st.track.run("marvel", drone_sim.scene, st.track.DroneData(imu, features))
    tracker = st.track.make("marvel", drone_sim.scene)
    assert isinstance(tracker, st.track.MarvelTracker)
    streamed = [e for e in map(tracker.step, drone_steps(imu, features)) if e is not None]
    assert len(batch) == len(streamed) > 10
    np.testing.assert_array_equal(np.array([e.position for e in streamed]), batch.position)
    np.testing.assert_array_equal(np.array([e.orientation for e in streamed]), batch.orientation)
    np.testing.assert_array_equal(np.array([e.sigma for e in streamed]), batch.sigma)
    # The same run as the fusion's own loop and as the old entry point.
    for other in (run_marvel(imu, features, drone_sim.scene), marvel.run_features("marvel", drone_sim.scene, imu, features)):
        np.testing.assert_array_equal(other.position, batch.position)
        np.testing.assert_array_equal(other.revised.position, batch.revised.position)
        assert other.skipped.counts == batch.skipped.counts


def test_marvel_recording_run_equals_the_sensing_loop():
    scenario = load_scenario("marvel-rail") | {"duration_s": 4.5}
    data, recording = simulate_marvel_iq(scenario, seed=7104)
    batch = st.track.run("marvel", data.scene, st.track.DroneData(data.imu, recording=recording))
    # The sensing generator driving a bare estimator (no tracker in between).
    estimator = MarvelEstimator(MarvelParams.from_kwargs(multipath="inflation"))
    fused = [e.estimate for e in marvel.sense_epochs("marvel", recording, data.imu, estimator) if e.estimate is not None]
    assert len(fused) == batch.stats["drone"]["fused"] > 0
    np.testing.assert_array_equal(np.array([e.position for e in fused]).reshape(-1, 3)[: len(batch)], batch.position)
    again = marvel.run_sigmf("marvel", data.scene, recording, data.imu)
    np.testing.assert_array_equal(again.position, batch.position)
    assert again.skipped.counts == batch.skipped.counts


def test_a_mismatched_input_is_a_clear_error(reads_sim, frames_sim, drone_sim):
    drone = st.track.DroneData(drone_sim.imu, drone_sim.features)
    with pytest.raises(ValueError, match="takes wideband frames"):
        st.track.run("turbotrack", frames_sim.scene, reads_sim.reads)
    with pytest.raises(ValueError, match="takes phase reads"):
        st.track.run("glac", reads_sim.scene, frames_sim.frames)
    with pytest.raises(ValueError, match="DroneData.*not phase reads"):
        st.track.run("marvel", drone_sim.scene, reads_sim.reads)
    with pytest.raises(ValueError, match="takes phase reads.*not the drone"):
        st.track.run("glac", reads_sim.scene, drone)
    with pytest.raises(ValueError, match="unknown method"):
        st.track.run("no-such-method", reads_sim.scene, reads_sim.reads)
    with pytest.raises(ValueError, match="Frame"):
        st.track.make("turbotrack", frames_sim.scene).step(reads_of(reads_sim)[0])
    with pytest.raises(ValueError, match="Read"):
        st.track.make("glac", reads_sim.scene).step(frames_of(frames_sim, 1)[0])
    with pytest.raises(ValueError, match="ImuSample and Feature"):
        st.track.make("marvel", drone_sim.scene).step(reads_of(reads_sim)[0])
    with pytest.raises(ValueError, match="exactly one"):
        st.track.DroneData(drone_sim.imu)
    with pytest.raises(ValueError, match="pose sensing"):
        st.track.run("marvel", drone_sim.scene, drone, min_snr_db=-10.0)
