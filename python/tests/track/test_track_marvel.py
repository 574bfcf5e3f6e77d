"""Marvel pose sensing from a LoRa recording, fused with the IMU (dsp/lora_sensing.py, track/marvel.py, docs/marvel.md sections 5-8).

One short IQ flight is simulated once (``simulate --iq``: the rail of paper
Fig. 9 at 3 m/s, 3 s at rest then two passes) and shared read-only; the
tolerances below were set from seeds 1001-1003 (measured: range error 5 cm
at most, the DSP's constant -4 cm to the gear centre included; angle 0.25
deg; clock error 0.004 ppm; fused mean 0.04 m) with a margin of about 3.
"""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from scattertrack.cli import main
from scattertrack.io import read_imu, read_scene, read_truth
from scattertrack.io.sigmf_lora import LoraRecording, read_lora_sigmf
from scattertrack.io.types import FormatError
from scattertrack.sim import load_scenario, simulate
from scattertrack.sim.drone import flight as flight_at
from scattertrack.sim.marvel import simulate_marvel_iq
from scattertrack.sim.rotation import wrap_angle
from scattertrack.dsp import lora_sensing
from scattertrack.track import marvel

SEED = 1001
DURATION_S = 6.0


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """``simulate --scenario marvel-rail --iq``: recording (ci16), scene, IMU, truth, simulation.json."""
    folder = tmp_path_factory.mktemp("rail-iq")
    code = main(["simulate", "--scenario", "marvel-rail", "--iq", "--out", str(folder),
                 "--duration", str(DURATION_S), "--seed", str(SEED)])
    assert code == 0
    return folder


@pytest.fixture(scope="module")
def sensed(recorded):
    """Both methods on the recording read back from SigMF (through the file: ci16 and all)."""
    imu = read_imu(recorded / "imu.csv")
    scene = read_scene(recorded / "scene.toml")
    meta = recorded / "recording.sigmf-meta"
    return {method: marvel.run_sigmf(method, scene, meta, imu) for method in marvel.MARVEL_METHODS}


def truth_of(recorded: Path):
    record = json.loads((recorded / "simulation.json").read_text())
    return record, np.asarray(record["details"]["controller_position_m"], dtype=float)


def feature_errors(recorded: Path, features):
    """Per sensed row: range error (m) and angle error (rad) of the body origin against the true controller."""
    record, rho = truth_of(recorded)
    state = flight_at(record["scenario"]["flight"], features.time_s)
    offset = state.position - rho
    distance = np.linalg.norm(offset, axis=1)
    el, az = features.elevation_rad, features.azimuth_rad
    u = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    angle = np.arccos(np.clip(np.sum(u * offset, axis=1) / distance, -1.0, 1.0))
    return features.range_m - distance, angle, np.linalg.norm(state.velocity, axis=1)


def test_iq_simulation_has_the_feature_level_flight_and_imu():
    scenario = load_scenario("marvel-hover") | {"duration_s": 1.0}
    sim, recording = simulate_marvel_iq(scenario, seed=3)
    reference = simulate(scenario, seed=3)
    np.testing.assert_array_equal(sim.imu.accel, reference.imu.accel)
    np.testing.assert_array_equal(sim.imu.gyro, reference.imu.gyro)
    np.testing.assert_array_equal(sim.truth.position, reference.truth.position)
    assert sim.features is None and recording.n_epochs == 10
    assert recording.samples.shape == (10, 2, 4, 3, 4096)
    np.testing.assert_allclose(recording.details["controller_position_m"], scenario["controller"]["position"])
    # The recording's hidden truth is the flight's pose at each epoch start.
    state = flight_at(sim.scenario["flight"], recording.epoch_time_s)
    np.testing.assert_allclose(recording.details["position_m"], state.position, atol=1e-12)
    _, repeated = simulate_marvel_iq(scenario, seed=3)
    np.testing.assert_array_equal(repeated.samples, recording.samples)
    other = simulate_marvel_iq(scenario, seed=4)[1]
    assert not np.array_equal(other.samples, recording.samples)


def test_lora_model_table_is_used_and_checked(tmp_path):
    scenario = load_scenario("marvel-hover") | {"duration_s": 0.5, "lora_model": {"tag_clock_ppm": 0.0}}
    sim, recording = simulate_marvel_iq(scenario, seed=1)
    assert recording.details["clock_error"] == 0.0 and sim.details["lora"]["clock_error"] == 0.0
    bad = tmp_path / "bad.toml"
    text = Path(load_scenario("marvel-hover")["source"]).read_text()
    bad.write_text(text + "\n[lora_model]\nspreading_factor = 13\n")
    with pytest.raises(FormatError, match=r"lora_model\.spreading_factor"):
        load_scenario(bad)
    bad.write_text(text + "\n[lora_model]\nno_such_key = 1\n")
    with pytest.raises(FormatError, match=r"lora_model\.no_such_key"):
        load_scenario(bad)


def test_simulate_iq_writes_a_marvel_recording(recorded):
    names = {p.name for p in recorded.iterdir()}
    assert {"recording.sigmf-meta", "recording.sigmf-data", "scene.toml", "imu.csv", "truth.csv",
            "simulation.json"} <= names
    assert "features.csv" not in names  # the pose sensing makes them from the recording
    meta = json.loads((recorded / "recording.sigmf-meta").read_text())
    assert meta["global"]["core:datatype"] == "ci16_le"
    recording = read_lora_sigmf(recorded / "recording.sigmf-meta")
    assert recording.n_epochs == round(DURATION_S * 10)
    truth = read_truth(recorded / "truth.csv")
    assert len(truth) == len(read_imu(recorded / "imu.csv")) == round(DURATION_S * 100)
    assert read_scene(recorded / "scene.toml").reader.kind == "lora-backscatter"


def test_marvel_senses_range_and_angle_and_fuses(recorded, sensed):
    track = sensed["marvel"]
    stats = track.stats["drone"]
    assert stats["epochs"] == stats["rows"] == round(DURATION_S * 10)  # every epoch sensed at 5 m
    declined = dict(stats["sensing_declined"])
    assert declined.pop("clock_unsettled") <= 5 and not any(declined.values())
    range_error, angle_error, _ = feature_errors(recorded, stats["features"])
    assert np.max(np.abs(range_error)) < 0.15, range_error
    assert np.degrees(np.max(angle_error)) < 1.0
    # The tags' clock error from the rest epochs before the rail starts.
    record, _ = truth_of(recorded)
    assert stats["clock"]["source"] == "rest" and stats["clock"]["rest_epochs"] >= 20
    assert abs(stats["clock"]["clock_error"] - record["details"]["lora"]["clock_error"]) < 0.05e-6
    # The fused track (body origin, take-off frame).
    truth = read_truth(recorded / "truth.csv")
    position = np.column_stack([np.interp(track.time_s, truth.time_s, truth.position[:, a]) for a in range(3)])
    error = np.linalg.norm(track.position - position, axis=1)
    assert len(track) >= stats["rows"] - 5
    assert np.mean(error) < 0.2 and np.max(error) < 0.6
    assert np.linalg.norm(np.asarray(stats["controller"]) - truth_of(recorded)[1]) < 0.5
    assert track.orientation is not None and track.sigma is not None
    assert stats["dsp_time_ns_p50"] > 0 and stats["time_ns_p50"] > 0 and len(stats["epoch_times_ns"]) == len(track)
    # From a recording too, the revised track: every fused row, as last revised.
    assert stats["revised_fallbacks"] == 0
    assert "heading_hold_end_s" in stats  # as from features
    assert np.array_equal(track.revised.time_s, track.time_s)
    revised_error = np.linalg.norm(track.revised.position - position, axis=1)
    assert np.mean(revised_error) < 0.2 and np.max(revised_error) < 0.6


def test_doppler_blind_ulocate_is_worse_in_range_at_speed(recorded, sensed):
    errors = {}
    for method, track in sensed.items():
        range_error, _, speed = feature_errors(recorded, track.stats["drone"]["features"])
        moving = speed > 1.0
        assert moving.sum() >= 10
        errors[method] = float(np.sqrt(np.mean(range_error[moving] ** 2)))
        # At rest there is no Doppler: both are equally good.
        assert np.max(np.abs(range_error[speed == 0.0])) < 0.15
    assert errors["ulocate"] > 1.0 and errors["ulocate"] > 10.0 * errors["marvel"], errors


def test_causal_a_prefix_of_the_recording_gives_the_same_rows(recorded):
    recording = read_lora_sigmf(recorded / "recording.sigmf-meta")
    imu = read_imu(recorded / "imu.csv")
    prefix = LoraRecording(recording.samples[:40], recording.epoch_time_s[:40], recording.chirp_start_s[:40],
                           recording.metadata)
    whole = [e for e in marvel.sense_epochs("marvel", recording, imu) if e.index < 40]
    part = list(marvel.sense_epochs("marvel", prefix, imu))
    assert [e.index for e in whole] == [e.index for e in part]
    for a, b in zip(whole, part):
        values = [(x.range_m, x.azimuth_rad, x.elevation_rad, x.yaw_rad, x.clock_error) for x in (a, b)]
        np.testing.assert_array_equal(*values)  # nan (no yaw) equals nan here
        np.testing.assert_array_equal(a.estimate.position, b.estimate.position)


def test_declined_epochs_are_counted_by_reason(recorded):
    recording = read_lora_sigmf(recorded / "recording.sigmf-meta")
    imu = read_imu(recorded / "imu.csv")
    samples = recording.samples[:50].copy()
    samples[10] = 0.0  # an epoch of all-zero samples (a receiver that sent nothing)
    samples[40, 1, 2, 0, 100] = np.nan  # one bad sample in flight
    rng = np.random.default_rng(0)
    noise = rng.standard_normal(samples[5].shape + (2,)).astype(np.float32).view(np.complex64)[..., 0]
    samples[5] = noise * np.float32(np.sqrt(recording.metadata["noise_power_w"]))  # noise only, at rest: the tags lost
    damaged = LoraRecording(samples, recording.epoch_time_s[:50], recording.chirp_start_s[:50], recording.metadata)
    track = marvel.run_sigmf("marvel", None, damaged, imu)
    stats = track.stats["drone"]
    assert stats["sensing_declined"]["no_signal"] == 1
    assert stats["sensing_declined"]["non_finite_samples"] == 1
    assert stats["sensing_declined"]["low_snr"] == 1
    assert stats["epochs"] == 50 and stats["rows"] == 47 == len(stats["features"])
    assert len(track) <= 47 - stats["sensing_declined"]["clock_unsettled"]
    for reason in ("no_signal", "non_finite_samples", "low_snr"):
        assert track.skipped.counts[marvel.SENSING_DECLINE_REASONS[reason]] == 1
    assert 10 not in set(np.round((stats["features"].time_s - 0.008192) * 10).astype(int))
    # The noise-only epoch at rest did not enter the clock error.
    record, _ = truth_of(recorded)
    assert abs(stats["clock"]["clock_error"] - record["details"]["lora"]["clock_error"]) < 0.05e-6


def test_bad_recordings_give_format_errors_on_the_command_line(capsys, recorded, tmp_path):
    def track(meta):
        code = main(["track", "--method", "marvel", "--scene", str(recorded / "scene.toml"), "--sigmf", str(meta),
                     "--imu", str(recorded / "imu.csv"), "--out", str(tmp_path / "t.csv"), "--no-progress"])
        return code, capsys.readouterr().err

    # A sample rate other than the bandwidth: a different chirp.
    wrong = tmp_path / "wrong"
    wrong.mkdir()
    meta = json.loads((recorded / "recording.sigmf-meta").read_text())
    meta["global"]["core:sample_rate"] = 250e3
    (wrong / "recording.sigmf-meta").write_text(json.dumps(meta))
    shutil.copy(recorded / "recording.sigmf-data", wrong / "recording.sigmf-data")
    code, err = track(wrong / "recording.sigmf-meta")
    assert code == 2 and "recording.sigmf-meta" in err and "core:sample_rate" in err and "Traceback" not in err

    # Data cut in the middle of a chirp.
    cut = tmp_path / "cut"
    cut.mkdir()
    shutil.copy(recorded / "recording.sigmf-meta", cut / "recording.sigmf-meta")
    data = (recorded / "recording.sigmf-data").read_bytes()
    (cut / "recording.sigmf-data").write_bytes(data[: len(data) // 2 + 24])
    code, err = track(cut / "recording.sigmf-meta")
    assert code == 2 and "recording.sigmf-data" in err and "truncated" in err


def test_parameters_are_checked(recorded, capsys, tmp_path):
    imu = read_imu(recorded / "imu.csv")
    meta = recorded / "recording.sigmf-meta"
    with pytest.raises(ValueError, match="no_such"):
        marvel.run_sigmf("marvel", None, meta, imu, no_such=1)
    with pytest.raises(ValueError, match="doppler_direction"):
        marvel.run_sigmf("marvel", None, meta, imu, doppler_direction="sideways")
    with pytest.raises(ValueError, match="unknown Marvel method"):
        marvel.run_sigmf("kalman", None, meta, imu)
    # A pose-sensing parameter makes no sense with ready-made features.
    folder = tmp_path / "features"
    assert main(["simulate", "--scenario", "marvel-hover", "--out", str(folder), "--duration", "1"]) == 0
    code = main(["track", "--method", "marvel", "--scene", str(folder / "scene.toml"), "--features",
                 str(folder / "features.csv"), "--imu", str(folder / "imu.csv"), "--out", str(tmp_path / "t.csv"),
                 "--param", "min_snr_db=-10"])
    assert code == 2 and "give --sigmf" in capsys.readouterr().err
    # The sensing parameters are known to the command line with a recording.
    code = main(["track", "--method", "ulocate", "--scene", str(recorded / "scene.toml"), "--sigmf", str(meta),
                 "--imu", str(recorded / "imu.csv"), "--out", str(tmp_path / "u.csv"), "--no-progress",
                 "--param", "min_snr_db=-10"])
    assert code == 0, capsys.readouterr().err


def test_the_yaw_follows_the_turntable():
    scenario = load_scenario("marvel-turntable") | {"duration_s": 6.0}
    sim, recording = simulate_marvel_iq(scenario, seed=SEED)
    track = marvel.run_sigmf("marvel", sim.scene, recording, sim.imu)
    features = track.stats["drone"]["features"]
    has_yaw = np.isfinite(features.yaw_rad)
    assert has_yaw.sum() >= 15  # spinning from 3 s on
    true_yaw = np.array([np.arctan2(r[1, 0], r[0, 0]) for r in _matrices(sim, features.time_s[has_yaw])])
    error = np.abs(wrap_angle(features.yaw_rad[has_yaw] - true_yaw))
    assert np.degrees(np.mean(error)) < 10.0, np.degrees(error)
    assert np.all(features.yaw_sigma_rad[has_yaw] > 0)


def _matrices(sim, times):
    from scattertrack.sim.rotation import quat_to_matrix

    return quat_to_matrix(flight_at(sim.scenario["flight"], times).orientation)


def test_a_level_rail_start_ends_the_ground_phase():
    """The rail accelerates a level body sideways: the specific force's magnitude barely changes
    (0.045 m/s^2 at 0.5 m/s), its direction does. The fusion must leave the ground, or it keeps
    the drone at the origin and predicts no velocity for the Doppler."""
    from scattertrack.fusion import MarvelEstimator

    scenario = load_scenario("marvel-rail") | {"duration_s": 6.0}
    scenario["flight"] = {**scenario["flight"], "speed": 0.5}
    sim, recording = simulate_marvel_iq(scenario, seed=SEED)
    estimator = MarvelEstimator()
    epochs = list(marvel.sense_epochs("marvel", recording, sim.imu, estimator))
    assert not estimator.on_ground
    last = epochs[-1].estimate
    truth = flight_at(sim.scenario["flight"], np.array([epochs[-1].time_s]))
    assert np.linalg.norm(truth.position[0]) > 1.0  # it did move
    assert np.linalg.norm(last.position - truth.position[0]) < 0.3
    assert np.linalg.norm(last.velocity - truth.velocity[0]) < 0.2


def test_the_fringe_is_chosen_with_the_rest_average_and_the_fusions_prediction():
    # Rail across the line of sight at 30 m (-9.5 dB per sample): the yaw is
    # loose on a rail, so the fused velocity along the line of sight is
    # uncertain by |v| sigma_yaw, and the Doppler removed from the chirp
    # timing moves the timing range by ~15 m per m/s of it. Picking the fringe
    # from the timing range alone locked onto a wrong fringe (a steady 11.8 m,
    # two fringes, at 30-50 m); with the rest epochs' average and the fusion's
    # predicted range as a second opinion the ranges stay on the right one.
    scenario = load_scenario("marvel-distance") | {"duration_s": 5.0}
    scenario["controller"] = {**scenario["controller"], "position": [2.0, -30.0, 1.0], "walls": 0}
    sim, recording = simulate_marvel_iq(scenario, seed=1000)
    rho = np.asarray(sim.details["controller_position_m"], dtype=float)
    epochs = [e for e in marvel.sense_epochs("marvel", recording, sim.imu) if e.sensed and e.declined is None]
    state = flight_at(sim.scenario["flight"], np.array([e.time_s for e in epochs]))
    truth = np.linalg.norm(state.position - rho, axis=1)
    errors = np.abs(np.array([e.range_m for e in epochs]) - truth)
    at_speed = np.linalg.norm(state.velocity, axis=1) > 2.0
    assert at_speed.sum() > 3
    assert np.median(errors) < 1.0, np.median(errors)
    assert np.median(errors[at_speed]) < 1.0, errors[at_speed]


def test_a_contradicting_prediction_does_not_pick_the_fringe(recorded, monkeypatch):
    """A diverged fusion predicting the range five fringes (28.9 m) too long with a
    confident sigma: the fringe comes from the epoch's own timing range instead,
    counted, and the ranges stay on the right fringe. Without the check they
    follow the prediction (the runaway measured in a reflecting room). Three
    fringes (17 m) are not caught here: early in flight the timing range's sigma
    (the fused velocity's share, ~15 m per m/s) is over 4 m, so 17 m is no
    4-sigma contradiction."""
    offset_m = 5 * 5.78
    imu = read_imu(recorded / "imu.csv")
    original = marvel._predicted_range

    def wrong(estimator, predicted, centroid):
        prior = original(estimator, predicted, centroid)
        return None if prior is None else (prior[0] + offset_m, 0.1)

    monkeypatch.setattr(marvel, "_predicted_range", wrong)
    errors = {}
    for sigmas in (4.0, 1e9):
        track = marvel.run_sigmf("marvel", None, recorded / "recording.sigmf-meta", imu, fringe_consistency_sigmas=sigmas)
        stats = track.stats["drone"]
        range_error, _, _ = feature_errors(recorded, stats["features"])
        flying = stats["features"].time_s > 3.5  # the rail starts at about 3.1 s
        errors[sigmas] = (np.median(np.abs(range_error[flying])), stats["fringe_from_timing"])
    assert errors[4.0][1] > 0 and errors[1e9][1] == 0
    assert errors[4.0][0] < 1.0
    assert errors[1e9][0] > 5.0


def test_rest_rows_leave_out_faded_peaks():
    """A (channel, antenna) row whose any tag's peak is below the decoding SNR is noise
    (its frequency anywhere in +-250 kHz) and stays out of the clock-error fit."""
    frequency = np.arange(2 * 4 * 3, dtype=float).reshape(2, 4, 3)  # (channel, tag, antenna)
    snr = np.full((2, 4, 3), -8.0)
    snr[1, 3, 0] = -26.0  # channel 1, tag 3, antenna 0 in a fade
    rows = lora_sensing._rest_rows(frequency, snr, -20.0)
    assert rows.shape == (5, 4)
    assert np.array_equal(lora_sensing._rest_rows(frequency), np.transpose(frequency, (0, 2, 1)).reshape(6, 4))
    assert not any(np.array_equal(row, frequency[1, :, 0]) for row in rows)


def test_consistency_spreads_widen_the_row_sigmas(recorded, monkeypatch):
    """The DSP's scatter of the tags' directions and of the (antenna, tag) phase
    ranges enters each row's angle and range sigma in quadrature
    (``consistency_sigmas``, default on): rows whose tags disagree are not
    fused as if their thermal bound held (the reflecting room, docs/marvel.md
    section 11). Off, the sigmas are the thermal bounds and floors alone. The
    DSP's spreads are replaced by known ones (0.2 rad, 1.5 m) to see them pass."""
    from scattertrack.fusion import MarvelEstimator, MarvelParams

    imu = read_imu(recorded / "imu.csv")
    meta = recorded / "recording.sigmf-meta"

    # The real spreads on the open rail: present, small, every tag used.
    estimator = MarvelEstimator(MarvelParams.from_kwargs(multipath="inflation"))
    real = [e for e in marvel.sense_epochs("marvel", meta, imu, estimator, keep_dsp=True) if e.sensed]
    assert len(real) > 20
    assert all(all(e.dsp["tag_used"]) for e in real)
    # A spread needs two opposing pairs (angle) or two phase groups (range).
    angle = [e.dsp["angle_spread_rad"] for e in real if e.dsp["angle_spread_rad"] is not None]
    distance = [e.dsp["range_spread_m"] for e in real if e.dsp["range_spread_m"] is not None]
    assert len(angle) > 0.8 * len(real) and len(distance) > 0.8 * len(real)
    assert np.median(angle) < 0.01 and np.median(distance) < 0.05

    original = lora_sensing._Sensor.processor

    class Injected:
        def __init__(self, inner):
            self.inner = inner
            self.reference_time_s = inner.reference_time_s

        def process(self, samples, **kwargs):
            result = self.inner.process(samples, **kwargs)
            return result | {"angle_spread_rad": 0.2, "range_spread_m": 1.5}

    monkeypatch.setattr(lora_sensing._Sensor, "processor", lambda self, offsets: Injected(original(self, offsets)))
    for flag in (True, False):
        estimator = MarvelEstimator(MarvelParams.from_kwargs(multipath="inflation"))
        rows = [e for e in marvel.sense_epochs("marvel", meta, imu, estimator, consistency_sigmas=flag) if e.sensed]
        assert len(rows) > 20
        angle = np.array([e.angle_sigma_rad for e in rows])
        distance = np.array([e.range_sigma_m for e in rows])
        if flag:
            assert np.all(angle >= 0.2) and np.all(distance >= 1.5)
        else:
            assert np.median(angle) < 0.05 and np.median(distance) < 0.5
    assert lora_sensing._spread(None) == 0.0 and lora_sensing._spread(float("nan")) == 0.0 and lora_sensing._spread(0.2) == 0.2
    with pytest.raises(ValueError, match="consistency_sigmas"):
        marvel._resolve_sensing({"consistency_sigmas": "maybe"})
