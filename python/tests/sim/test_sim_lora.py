"""The Marvel LoRa-backscatter IQ simulator (scattertrack.sim.lora; docs/marvel.md section 6).

Each physics check measures the dechirped tone with a plain numpy FFT plus a
refined search of the DTFT magnitude, and compares it with a prediction
computed here from the analytic flight (not from the simulator's details,
except for its hidden random draws: the clock error, the tags' phase and
the receive chains' phases).
"""

import math

import numpy as np
import pytest
from scattertrack.sim import lora

C0 = 299_792_458.0
BW = 500e3
N = 4096
T = N / BW
SLOPE = BW / T  # Hz/s
F = lora.channel_frequencies(lora.resolve_lora_model())[[0, 12]]  # excitation f_j, Hz
S = np.array([1e6, 2e6, 3e6, 4e6])  # tag shifts s_k, Hz
CARRIER = F[:, None] + S[None, :] / 2.0  # (J, K) Hz
BODY = lora.tag_body_positions(lora.resolve_lora_model())  # (K, 3) m
QUIET = {"add_noise": False}


# --------------------------------------------------------------------------
# analytic flights


def yaw_quaternion(yaw):
    yaw = np.asarray(yaw, dtype=float)
    return np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=-1)


def constant_velocity(start, velocity, yaw=0.0, yaw_rate=0.0):
    """``pose_at`` of a drone at ``start + velocity t`` turning at ``yaw_rate`` (rad/s) about z."""
    start, velocity = np.asarray(start, float), np.asarray(velocity, float)

    def pose_at(t):
        t = np.asarray(t, dtype=float)
        return start + velocity * t[:, None], yaw_quaternion(yaw + yaw_rate * t)

    return pose_at


def tag_kinematics(start, velocity, yaw, yaw_rate, t):
    """World position (K, 3) and velocity (K, 3) of every tag at time t (level flight, yaw only)."""
    angle = yaw + yaw_rate * t
    c, s = math.cos(angle), math.sin(angle)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    arm = BODY @ rotation.T
    omega = np.array([0.0, 0.0, yaw_rate])
    return np.asarray(start) + np.asarray(velocity) * t + arm, np.asarray(velocity) + np.cross(omega, arm)


def predicted(rec, start, velocity, yaw=0.0, yaw_rate=0.0):
    """Peak frequency (E, J, K, M) Hz and mid-chirp phase (E, J, K, M) rad from the geometry (module docstring of sim.lora)."""
    d = rec.details
    rho = d["controller_position_m"]
    rx = rho + np.array(rec.metadata["array_offsets_m"])
    epochs = rec.samples.shape[0]
    frequency = np.empty((epochs, 2, 4, 3))
    phase = np.empty((epochs, 2, 4, 3))
    for e in range(epochs):
        for j in range(2):
            t_mid = rec.chirp_start_s[e, j] + (N // 2) / BW
            p, v = tag_kinematics(start, velocity, yaw, yaw_rate, t_mid)
            down = np.linalg.norm(p - rho, axis=1)  # (K,)
            up = np.linalg.norm(p[:, None] - rx[None], axis=2)  # (K, M)
            rate = ((p - rho) / down[:, None] * v).sum(1)[:, None] + (((p[:, None] - rx[None]) / up[..., None]) * v[:, None]).sum(2)
            tau = (down[:, None] + up) / C0
            doppler = -CARRIER[j][:, None] * rate / C0
            frequency[e, j] = d["cfo_hz"][:, None] + doppler - SLOPE * tau
            phase[e, j] = (-2 * np.pi * CARRIER[j][:, None] * tau + 2 * np.pi * d["cfo_hz"][:, None] * t_mid
                           + d["tag_phase_rad"] + d["rx_phase_offsets_true_rad"][j])
    return frequency, phase


# --------------------------------------------------------------------------
# a plain dechirp + FFT + refined DTFT peak


def dechirp(samples):
    return samples.astype(np.complex128) * np.conj(lora.upchirp(np.arange(N) / BW, lora.resolve_lora_model()))


def dtft(d, frequencies):
    n = np.arange(len(d)) - len(d) // 2  # phase referenced to mid-chirp
    return np.exp(-2j * np.pi * np.outer(frequencies, n) / BW) @ d


def tone(samples):
    """(frequency Hz, phase at mid-chirp rad, |peak|) of the strongest tone of a dechirped chirp."""
    d = dechirp(samples)
    pad = 8
    spectrum = np.abs(np.fft.fft(d, pad * N))
    k = int(np.argmax(spectrum))
    frequency = np.fft.fftfreq(pad * N, 1 / BW)[k]
    # Refine: a parabola through |DTFT| at f - delta, f, f + delta, with ever smaller delta
    # (the peak of a tone's Dirichlet kernel is locally quadratic).
    for delta in (BW / (pad * N), 1.0, 0.05, 0.002):
        low, middle, high = np.abs(dtft(d, [frequency - delta, frequency, frequency + delta]))
        frequency += 0.5 * delta * (low - high) / (low - 2 * middle + high)
    value = dtft(d, [frequency])[0]
    return frequency, float(np.angle(value)), float(np.abs(value))


def measure(rec):
    epochs = rec.samples.shape[0]
    frequency = np.empty((epochs, 2, 4, 3))
    phase = np.empty_like(frequency)
    for index in np.ndindex(frequency.shape):
        frequency[index], phase[index], _ = tone(rec.samples[index])
    return frequency, phase


def wrapped(a):
    return np.angle(np.exp(1j * np.asarray(a)))


# --------------------------------------------------------------------------
# physics


def test_static_drone_peak_frequency_and_phase_follow_the_time_of_flight():
    start = [3.0, 25.0, 4.0]
    rec = lora.simulate_lora_iq(constant_velocity(start, [0, 0, 0]), {"position": [0.0, 0.0, 1.0]}, QUIET, 0.2, seed=4)
    assert rec.samples.shape == (2, 2, 4, 3, N) and rec.samples.dtype == np.complex64
    frequency, phase = measure(rec)
    expected_frequency, expected_phase = predicted(rec, start, [0, 0, 0])
    # At rest the tone is cfo_k - (BW/T) tau: tens of hertz from the clock, 3-4 Hz from the 50 m path.
    assert np.all(np.abs(SLOPE * 2 * 25.5 / C0 - (rec.details["cfo_hz"][:, None] - expected_frequency[0, 0])) < 0.3)
    np.testing.assert_allclose(frequency, expected_frequency, atol=1e-3)
    np.testing.assert_allclose(wrapped(phase - expected_phase), 0.0, atol=1e-3)
    # The simulator's own truth agrees with the independent prediction.
    np.testing.assert_allclose(rec.details["peak_frequency_hz"], expected_frequency, atol=1e-6)
    np.testing.assert_allclose(wrapped(rec.details["peak_phase_rad"] - expected_phase), 0.0, atol=1e-5)  # + pi (BW/T) tau^2
    # Static: the phase changes between epochs only by the tag clock, 2 pi cfo_k x 0.1 s.
    step = wrapped(phase[1] - phase[0])
    np.testing.assert_allclose(wrapped(step - 2 * np.pi * rec.details["cfo_hz"][None, :, None] * 0.1), 0.0, atol=2e-3)


def test_moving_drone_doppler_and_phase_advance_across_epochs():
    start, velocity = np.array([1.0, 12.0, 3.0]), np.array([0.3, 2.0, 0.1])
    rec = lora.simulate_lora_iq(constant_velocity(start, velocity), {"position": [0.0, 0.0, 1.0]}, QUIET, 0.4, seed=9)
    frequency, phase = measure(rec)
    expected_frequency, expected_phase = predicted(rec, start, velocity)
    # Moving away at ~2 m/s: the round trip's Doppler is about -2 v f / c0 = -12.5 Hz.
    doppler = rec.details["doppler_hz"]
    assert np.all((doppler < -11.0) & (doppler > -13.5))
    np.testing.assert_allclose(frequency, expected_frequency, atol=1e-3)
    np.testing.assert_allclose(wrapped(phase - expected_phase), 0.0, atol=1e-3)
    # Epoch to epoch the mid-chirp phase advances by -4 pi Delta r / lambda (+ the clock's 2 pi cfo dt),
    # with r = path / 2 and lambda = c0 / (f_j + s_k / 2).
    path = rec.details["path_m"]  # (E, J, K, M) at mid-chirp
    wavelength = C0 / CARRIER[None, :, :, None]
    for e in range(3):
        delta_r = (path[e + 1] - path[e]) / 2.0
        assert np.all(np.abs(delta_r - 0.2) < 0.02)  # 2 m/s x 0.1 s, mostly radial
        expected = -4 * np.pi * delta_r / wavelength[0] + 2 * np.pi * rec.details["cfo_hz"][None, :, None] * 0.1
        np.testing.assert_allclose(wrapped(phase[e + 1] - phase[e] - expected), 0.0, atol=2e-3)


def test_spinning_drone_opposing_tags_shift_equal_and_opposite():
    start, yaw_rate = np.array([4.0, 8.0, 2.5]), 1.5
    yaw = math.atan2(8.0, 4.0) + math.pi / 4  # both pairs see about 0.7 of the largest shift
    rec = lora.simulate_lora_iq(constant_velocity(start, [0, 0, 0], yaw, yaw_rate), {"position": [0.0, 0.0, 1.0]},
                                QUIET, 0.3, seed=2)
    frequency, _ = measure(rec)
    expected_frequency, _ = predicted(rec, start, [0, 0, 0], yaw, yaw_rate)
    np.testing.assert_allclose(frequency, expected_frequency, atol=1e-3)
    # Remove the clock and the time of flight: what is left is the rotational shift f_r of each tag.
    rotational = frequency - rec.details["cfo_hz"][None, None, :, None] + SLOPE * rec.details["path_m"] / C0
    for pair in ((0, 1), (2, 3)):
        a, b = rotational[:, :, pair[0]], rotational[:, :, pair[1]]
        assert np.all(np.abs(a) > 1.2)  # 2 f omega (D/2) / c0 = 3.1 Hz at most
        # Equal and opposite (eq. 2) up to the near-field term: the two tags see the controller along
        # directions D / r apart, so the sum is at most about (D / r) x the largest shift.
        near_field = 0.66 / rec.details["range_m"].min()
        np.testing.assert_allclose(a + b, 0.0, atol=near_field * np.abs(a).max())
        assert np.all(np.abs(a + b) < 0.1 * np.abs(a))
    # Eq. 7-8 in 3D (docs/marvel.md section 7.6): half the pair's difference is
    # f_r = (2 f / c0) u_p . (omega x r_tag), u_p from the drone to the controller (the
    # near-field terms cancel in the difference up to (D / r)^2).
    for e in range(rec.samples.shape[0]):
        t_mid = rec.chirp_start_s[e, 0] + T / 2
        _, v = tag_kinematics(start, [0, 0, 0], yaw, yaw_rate, t_mid)
        u_p = (rec.details["controller_position_m"] - start) / np.linalg.norm(rec.details["controller_position_m"] - start)
        for j in range(2):
            formula = 2 * CARRIER[j] / C0 * (v @ u_p)
            half_difference = (rotational[e, j, [0, 2], 1] - rotational[e, j, [1, 3], 1]) / 2
            np.testing.assert_allclose(half_difference, formula[[0, 2]], rtol=0.03)


def test_snr_falls_with_distance_and_walls_as_the_link_budget_says():
    def snr(distance, walls, **model):
        pose = constant_velocity([0.0, distance, 0.3], [0, 0, 0])  # tags at z = 0, the array centre at z = 0
        rec = lora.simulate_lora_iq(pose, {"position": [0.0, 0.0, 0.0], "walls": walls}, {**QUIET, **model}, 0.1, seed=1)
        return rec.details["snr_db"][0]  # (K, M)

    near, far = snr(10.0, 0), snr(20.0, 0)
    # Round trip 1/r^4: 12 dB per doubling (tags 1 and 2 sit at the nominal distance; 3 and 4 0.33 m nearer/farther).
    np.testing.assert_allclose(near[:2] - far[:2], 40 * np.log10(2.0), atol=0.01)
    for walls in (1, 2, 3):
        np.testing.assert_allclose(near - snr(10.0, walls), 2 * lora.LORA_MODEL_DEFAULTS["wall_loss_db"] * walls, atol=1e-9)  # each wall crossed twice
    np.testing.assert_allclose(snr(10.0, 1, wall_loss_db=9.0), near - 18.0, atol=1e-9)
    # The closed-form budget (monostatic legs) matches the simulator's direct path within the array's geometry.
    # (the simulator's SNR is the power mean over the epoch's two chirps, 902.1 and 928.0 MHz: 0.5 dB apart).
    both = [10 ** (lora.link_budget_snr_db(10.0, frequency_hz=f, shift_hz=s) / 10) for f in F for s in S[:2]]
    assert abs(10 * np.log10(np.mean(both)) - near[:2].mean()) < 0.02
    table = lora.link_budget_snr_db(np.array([1.0, 5.0, 10.0, 20.0, 50.0]))
    assert table[0] > 45 and abs(table[3]) < 3 and table[4] < -10  # docs: below 0 dB at tens of metres


def test_measured_snr_matches_the_link_budget():
    # 12 m behind one wall: about -3 dB per sample, 33 dB after the dechirp.
    pose = constant_velocity([0.0, 12.0, 0.3], [0, 0, 0])
    rec = lora.simulate_lora_iq(pose, {"position": [0.0, 0.0, 0.0], "walls": 1}, None, 0.2, seed=8)
    noise = rec.metadata["noise_power_w"]
    for e, j, k, m in [(0, 0, 0, 0), (1, 1, 3, 2), (0, 1, 2, 1)]:
        d = dechirp(rec.samples[e, j, k, m])
        _, _, peak = tone(rec.samples[e, j, k, m])
        spectrum = np.abs(np.fft.fft(d)) ** 2
        noise_bin = np.median(spectrum) / math.log(2.0)  # exponential: mean = median / ln 2
        np.testing.assert_allclose(noise_bin / N, noise, rtol=0.1)
        signal = (peak**2 - noise_bin) / N**2  # per-sample signal power, W
        snr_db = 10 * math.log10(signal / noise)
        assert abs(snr_db - rec.details["snr_db"][e, k, m]) < 0.5, (snr_db, rec.details["snr_db"][e, k, m])


def test_plane_reflector_adds_the_image_path():
    # Linear array: receive antenna 1 sits at the transmitter, so both bent paths have the image length.
    start = np.array([2.0, 15.0, 3.0])
    wall = {"kind": "plane", "point": [8.0, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0], "coefficient": -0.5}
    controller = {"position": [0.0, 0.0, 1.0], "array": "linear"}
    pose = constant_velocity(start, [0, 0, 0])
    clean = lora.simulate_lora_iq(pose, controller, QUIET, 0.1, seed=3)
    echoed = lora.simulate_lora_iq(pose, controller, {**QUIET, "reflectors": [wall]}, 0.1, seed=3)
    reflected = echoed.samples.astype(np.complex128) - clean.samples
    rho = np.array(controller["position"])
    image = rho * [-1, 1, 1] + [16.0, 0, 0]  # the transmitter mirrored in x = 8
    for k in range(4):
        tag = start + BODY[k]
        direct, bent = np.linalg.norm(tag - rho), np.linalg.norm(tag - image)
        frequency, _, _ = tone(reflected[0, 0, k, 1])
        expected = clean.details["cfo_hz"][k] - SLOPE * (direct + bent) / C0
        assert abs(frequency - expected) < 1e-3
        # Two bent paths, each Gamma a / (bent direct), in phase.
        magnitude = np.abs(reflected[0, 0, k, 1, 1:]).mean()
        direct_magnitude = np.abs(clean.samples[0, 0, k, 1, 1:]).mean()
        np.testing.assert_allclose(magnitude / direct_magnitude, 2 * 0.5 * direct / bent, rtol=1e-3)


def test_same_seed_same_recording_and_metadata():
    pose = constant_velocity([1.0, 10.0, 2.0], [0.5, 0.0, 0.0], 0.3, 0.4)
    calls = []

    def counted(t):
        calls.append(len(t))
        return pose(t)

    a = lora.simulate_lora_iq(counted, {"position": [0.0, 0.0, 1.0]}, None, 0.3, seed=5)
    b = lora.simulate_lora_iq(pose, {"position": [0.0, 0.0, 1.0]}, None, 0.3, seed=5)
    c = lora.simulate_lora_iq(pose, {"position": [0.0, 0.0, 1.0]}, None, 0.3, seed=6)
    assert calls == [2 * N] * 3  # one vectorised call per epoch
    np.testing.assert_array_equal(a.samples, b.samples)
    assert not np.array_equal(a.samples, c.samples)
    assert a.details["clock_error"] != c.details["clock_error"]
    assert abs(a.details["clock_error"]) <= 10e-6
    np.testing.assert_allclose(a.details["cfo_hz"], a.details["clock_error"] * S)
    np.testing.assert_allclose(a.epoch_time_s, [0.0, 0.1, 0.2])
    np.testing.assert_allclose(a.chirp_start_s[:, 1] - a.chirp_start_s[:, 0], T)
    meta = a.metadata
    assert (meta["spreading_factor"], meta["bandwidth_hz"], meta["sample_rate_hz"], meta["samples_per_chirp"]) == (12, 500e3, 500e3, N)
    np.testing.assert_allclose(meta["channel_frequencies_hz"], 902.1e6 + 2.16e6 * np.arange(13))
    assert meta["excitation_channels"] == [0, 12] and meta["tag_shifts_hz"] == S.tolist()
    np.testing.assert_allclose(meta["tag_body_positions_m"], [[0.33, 0, -0.3], [-0.33, 0, -0.3], [0, 0.33, -0.3], [0, -0.33, -0.3]])
    offsets = np.array(meta["array_offsets_m"])
    np.testing.assert_allclose(np.linalg.norm(offsets[[0, 1, 2]] - offsets[[1, 2, 0]], axis=1), 0.16)  # equilateral
    np.testing.assert_allclose(offsets.mean(axis=0), 0.0, atol=1e-12)
    assert np.all(offsets[:, 1] == 0.0)  # the vertical xz-plane
    # A perfect calibration by default; a residual when asked.
    np.testing.assert_allclose(meta["rx_phase_offsets_rad"], a.details["rx_phase_offsets_true_rad"])
    d = lora.simulate_lora_iq(pose, {"position": [0.0, 0.0, 1.0]}, {"calibration_residual_rad": 0.05}, 0.1, seed=5)
    residual = wrapped(d.details["rx_phase_offsets_true_rad"] - np.array(d.metadata["rx_phase_offsets_rad"]))
    assert 0.02 < residual.std() < 0.1
    # Truth: range and angles from the array centre to the body origin.
    offset = np.array([1.0, 10.0, 2.0]) - [0.0, 0.0, 1.0]
    assert a.details["range_m"][0] == pytest.approx(np.linalg.norm(offset))
    assert a.details["azimuth_rad"][0] == pytest.approx(math.atan2(10.0, 1.0))
    assert a.details["elevation_rad"][0] == pytest.approx(math.asin(1.0 / np.linalg.norm(offset)))


def test_bad_inputs_are_rejected():
    pose = constant_velocity([1.0, 10.0, 2.0], [0, 0, 0])
    with pytest.raises(ValueError, match="unknown LoRa model key"):
        lora.resolve_lora_model({"sf": 7})
    with pytest.raises(ValueError, match="spreading_factor"):
        lora.resolve_lora_model({"spreading_factor": 13})
    with pytest.raises(ValueError, match="excitation_channels"):
        lora.resolve_lora_model({"excitation_channels": [0, 13]})
    with pytest.raises(ValueError, match="array"):
        lora.simulate_lora_iq(pose, {"position": [0, 0, 0], "array": "circle"}, None, 0.1, 0)
    with pytest.raises(ValueError, match="position"):
        lora.simulate_lora_iq(pose, {"walls": 1}, None, 0.1, 0)
    with pytest.raises(ValueError, match="walls"):
        lora.simulate_lora_iq(pose, {"position": [0, 0, 0], "walls": -1}, None, 0.1, 0)
    with pytest.raises(ValueError, match="shorter than one sensing period"):
        lora.simulate_lora_iq(pose, {"position": [0, 0, 0]}, None, 0.05, 0)
    with pytest.raises(ValueError, match=r"expected \(8192, 3\)"):
        lora.simulate_lora_iq(lambda t: (np.zeros((len(t), 2)), yaw_quaternion(0 * t)), {"position": [0, 0, 0]}, None, 0.1, 0)
