"""The LoRa (Marvel) DSP bindings round-trip a synthetic epoch (docs/marvel.md section 6)."""

import numpy as np
import pytest
from scattertrack import _core

C0 = 299_792_458.0
SF, BW = 12, 500e3
N = 2**SF
T = N / BW
D, H = 0.66, -0.30
TAGS = np.array([[D / 2, 0, H], [-D / 2, 0, H], [0, D / 2, H], [0, -D / 2, H]])
SHIFTS = np.array([1e6, 2e6, 3e6, 4e6])
CHANNELS = np.array([902.1e6, 902.1e6 + 12 * 2.16e6])
S3 = np.sqrt(3.0)
ARRAY = 0.16 * np.array([[-0.5, 0, -0.5 / S3], [0.5, 0, -0.5 / S3], [0, 0, 1 / S3]])


def chirp_cycles(t):
    return -BW / 2 * t + BW / (2 * T) * t**2


def epoch(body, eps=0.0, snr_db=0.0, seed=0):
    """A hovering drone (identity attitude) at ``body``; the controller at the origin."""
    rng = np.random.default_rng(seed)
    n = np.arange(N) / BW
    y = np.empty((2, 4, 3, N), np.complex64)
    sigma = np.sqrt(10 ** (-snr_db / 10) / 2)
    for j in range(2):
        for k in range(4):
            p = body + TAGS[k]
            f = CHANNELS[j] + SHIFTS[k] / 2
            for m in range(3):
                tau = (np.linalg.norm(p) + np.linalg.norm(p - ARRAY[m])) / C0
                t = j * T + n
                psi = 2 * np.pi * (-((f * tau) % 1.0) + (eps * SHIFTS[k] * t) % 1.0 + chirp_cycles(n - tau)) + 0.3
                noise = sigma * (rng.standard_normal(N) + 1j * rng.standard_normal(N))
                y[j, k, m] = np.exp(1j * psi) + noise
    return y


def test_chirp_and_peak():
    up = _core.lora_chirp(SF, BW)
    down = _core.lora_chirp(SF, BW, down=True)
    assert up.shape == (N,) and up.dtype == np.complex128
    np.testing.assert_allclose(up * down, 1.0, atol=1e-12)
    tone = (up * np.exp(2j * np.pi * 3.25 * np.arange(N) / BW + 0.4j)).astype(np.complex64)
    p = _core.lora_peak(tone, SF, BW)
    assert abs(p["frequency_hz"] - 3.25) < 1e-3
    assert abs(np.angle(p["amplitude"]) - 0.4) < 1e-3
    with pytest.raises(_core.DspError, match="bad-config"):
        _core.lora_chirp(13, BW)


def test_epoch_round_trip():
    body = np.array([5.0, 18.0, 3.0])
    eps = 1.2e-6
    y = epoch(body, eps=eps, snr_db=0.0)
    proc = _core.LoraEpochProcessor()
    assert proc.samples_per_chirp == N and proc.antennas == 3
    # The clock error from this epoch "at rest", then the features with it.
    rest = proc.process(y)
    peaks = rest["frequency_hz"].transpose(0, 2, 1).reshape(-1, 4)
    clock = _core.lora_clock_error(peaks)
    assert abs(clock["clock_error"] - eps) < 4 * clock["sigma"]
    f = proc.process(y, clock_error=eps, velocity=np.zeros(3))
    centroid = body + TAGS.mean(axis=0)
    r = np.linalg.norm(centroid)
    assert f["frequency_hz"].shape == (2, 4, 3) and f["amplitude"].dtype == np.complex128
    assert f["phase_rad"].shape == (2, 4, 3) and f["pair_mean_hz"].shape == (2, 3, 2)
    assert abs(f["range_m"] - r) < 0.05, (f["range_m"], r)
    assert abs(f["timing_range_m"] - r) < 4 * f["timing_range_sigma_m"] + 0.1
    u = centroid / r
    assert np.degrees(np.arccos(np.clip(np.dot(f["direction"], u), -1, 1))) < 1.5
    assert abs(f["mean_snr_db"]) < 0.5
    assert f["yaw"] is None  # no attitude / gyro given
    with pytest.raises(_core.DspError, match="shape"):
        proc.process(y[:, :, :2])


def test_music_and_heading_functions():
    u = np.array([np.cos(0.2) * np.cos(1.1), np.cos(0.2) * np.sin(1.1), np.sin(0.2)])
    freqs = np.array([902.6e6, 928.5e6])
    phases = 2 * np.pi * np.outer(ARRAY @ u, freqs) / C0 + np.array([0.3, -1.0])
    e = _core.lora_music(phases, freqs)
    assert abs(e["azimuth"] - 1.1) < 1e-3 and abs(e["elevation"] - 0.2) < 1e-3
    # At rest there is no yaw.
    none = _core.lora_heading(
        np.zeros(2), np.full(2, 903e6), TAGS[[0, 2]], TAGS[[1, 3]], np.ones(2), np.eye(3), np.zeros(3), u
    )
    assert none is None
    # Yawing at 1 rad/s with yaw 0.7: differences from the model -(2/c0) u . R (f w x dr).
    yaw = 0.7
    rz = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    w = np.array([0, 0, 1.0])
    dr = TAGS[[0, 2]] - TAGS[[1, 3]]
    d = np.array([-(2 / C0) * u @ rz @ (903e6 * np.cross(w, x)) for x in dr])
    h = _core.lora_heading(
        d, np.full(2, 903e6), TAGS[[0, 2]], TAGS[[1, 3]], np.full(2, 0.1), np.eye(3), w, u, chirp_rate_hz_per_s=None
    )
    assert h is not None and abs(h["yaw"] - yaw) < 1e-6
