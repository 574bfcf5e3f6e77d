"""The helper's channel estimation over SigMF recordings (scattertrack.dsp.ofdm), end to end."""

import numpy as np
import pytest

from helper_recordings import C, RX, TAG_POSITION, TX, helper_scene, simulate, written_recording
from scattertrack import dsp
from scattertrack.dsp.channel import bistatic_path_lengths, tag_channel
from scattertrack.dsp.ofdm import SKIP_NO_PREAMBLE, SKIP_NON_FINITE, SKIP_RX
from scattertrack.io import FormatError


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    return written_recording(tmp_path_factory)


def test_channels_match_the_true_tag_channel_within_the_noise(recording):
    sim, out = recording
    estimate = dsp.estimate_sigmf(out / "recording", sim.scene, calibration=out / "calibration")
    frames = estimate.frames
    assert frames.n_frames == 4 and frames.skipped.total == 0
    assert np.all(estimate.score > 0.8)
    assert np.allclose(estimate.blf_hz, sim.details["recording"]["blf_hz"], rtol=0.01)
    for k in range(frames.n_frames):
        rx_ids, frequencies, h = frames.frame_grid(k)
        truth = tag_channel(TX, RX, np.array([TAG_POSITION]), frequencies)[0]
        # Phase error per subcarrier, against the reported noise (the
        # calibration's own noise, 4 replies averaged, adds up to 1/4 more).
        sigma = np.sqrt(estimate.variance[k] * 1.25 / 2.0) / np.abs(truth)
        error = np.angle(h * truth.conj())
        assert np.all(np.abs(error) < 5 * sigma), np.abs(error / sigma).max()
        assert np.sqrt(np.mean(error**2)) < 0.1
        # The path length implied by the phase slope over the band, per rx
        # (least squares; 1 sigma about 1.5 cm at this SNR: the slope is the
        # coarse range, the carrier phase the fine one).
        phase = np.unwrap(np.angle(h), axis=1)
        slope = np.polyfit(frequencies - frequencies.mean(), phase.T, 1)[0]
        implied = -slope * C / (2 * np.pi)
        distance = bistatic_path_lengths(TX, RX, np.array([TAG_POSITION]))[0]
        np.testing.assert_allclose(implied, distance, atol=0.05)
    # Frame times: the preamble start (reply start) of each window.
    np.testing.assert_allclose(frames.frame_time_s, sim.details["recording"]["reply_start_s"], atol=1e-6)


def test_replies_without_preamble_are_counted(tmp_path):
    sim, out = simulate(tmp_path, seed=3, duration_s=0.03, miss_probability=0.4)
    answered = np.array(sim.details["answered"])
    assert 0 < answered.sum() < len(answered)
    frames = dsp.read_sigmf_frames(out / "recording", sim.scene, calibration=out / "calibration")
    assert frames.skipped.counts == {SKIP_NO_PREAMBLE: int((~answered).sum())}
    assert frames.n_frames == answered.sum()
    assert frames.skipped.examples[SKIP_NO_PREAMBLE][:3] == np.flatnonzero(~answered)[:3].tolist()


def test_non_finite_windows_and_antennas_are_counted(tmp_path):
    sim, out = simulate(tmp_path, duration_s=0.014, datatype="cf32_le")
    assert len(sim.recording.meta["captures"]) == 4
    data = np.memmap(out / "recording.sigmf-data", dtype="<c8", mode="r+", shape=(4 * 30_000, 4))
    data[30_000:60_000] = np.nan  # window 1: every antenna
    data[60_000:90_000, 2] = np.nan  # window 2: rx id 3 only
    data.flush()
    del data
    frames = dsp.read_sigmf_frames(out / "recording", sim.scene, calibration=out / "calibration")
    assert frames.skipped.counts == {SKIP_NON_FINITE: 1, SKIP_RX: 1}
    assert frames.n_frames == 3
    rx_ids, _, _ = frames.frame_grid(1)
    assert rx_ids.tolist() == [1, 2, 4]
    assert np.isfinite(frames.h).all()


def test_ema_and_uncalibrated_runs(recording):
    sim, out = recording
    raw = dsp.read_sigmf_frames(out / "recording", sim.scene)
    smooth = dsp.read_sigmf_frames(out / "recording", sim.scene, calibration=out / "calibration", ema_alpha=0.5)
    assert raw.n_frames == smooth.n_frames == 4
    truth = tag_channel(TX, RX, np.array([TAG_POSITION]), smooth.frame_grid(0)[1])[0]
    # Uncalibrated channels carry the hardware response: far from the truth.
    assert np.abs(np.angle(raw.frame_grid(0)[2] * truth.conj())).mean() > 0.3


def test_a_scene_without_the_recorded_antennas_is_rejected(recording):
    sim, out = recording
    scene = helper_scene()
    scene.antennas[2].role = "tx"
    with pytest.raises(FormatError, match="scattertrack:channels"):
        dsp.read_sigmf_frames(out / "recording", scene)
