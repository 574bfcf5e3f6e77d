"""SigMF recordings of the helper: reading, validation, and channel estimation end to end."""

import json
import shutil

import numpy as np
import pytest

from scattertrack import dsp, io
from scattertrack.io import FormatError
from scattertrack.dsp.ofdm import SKIP_NO_PREAMBLE, SKIP_NON_FINITE, SKIP_RX
from scattertrack.io.types import Antenna, Reader, Region, Scene
from scattertrack.sim import iq
from scattertrack.dsp.channel import bistatic_path_lengths, tag_channel

C = 299_792_458.0
TX = np.array([0.4, 0.4, 0.0])
RX = np.array([[0.0, 0.4, 0.0], [0.8, 0.4, 0.0], [0.4, 0.0, 0.0], [0.4, 0.8, 0.0]])
TAG_POSITION = [0.55, 0.30, 0.60]


def helper_scene() -> Scene:
    antennas = [Antenna(0, TX.copy(), role="tx")] + [Antenna(i + 1, p.copy(), role="rx") for i, p in enumerate(RX)]
    region = Region(np.array([-1.0, -1.0, 0.05]), np.array([2.0, 2.0, 2.0]))
    return Scene("helper", 3, Reader(kind="sdr-helper"), antennas, region=region)


def simulate(tmp_path, name="run", seed=1, duration_s=0.012, **model):
    sim = iq.simulate_iq(helper_scene(), {"E1": {"kind": "static", "position": TAG_POSITION}}, model=model,
                         seed=seed, duration_s=duration_s)
    out = iq.write_iq_simulation(sim, tmp_path / name)
    return sim, out


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A written simulation: 4 replies at 0 dB per sample, a calibration at the region's centre."""
    return simulate(tmp_path_factory.mktemp("sigmf"), duration_s=0.014)


def test_round_trip_of_metadata_and_samples(recording):
    sim, out = recording
    read = io.read_sigmf(out / "recording.sigmf-meta", verify_checksum=True)
    assert read.channels == [1, 2, 3, 4] and read.tx_id == 0
    assert (read.bandwidth_hz, read.subcarriers, read.blf_hz, read.encoding) == (100e6, 20, 40e3, "fm0")
    assert len(read.windows) == 4 and all(w.epc == "E1" for w in read.windows)
    assert isinstance(read.data, np.memmap)
    np.testing.assert_array_equal(read.data, sim.recording.data)
    symbol = read.known_symbol
    assert abs(symbol[0]) == 0 and np.allclose(np.abs(symbol[1:]), 1.0)
    w = read.window_samples(1)
    assert w.shape == (4, 30_000) and w.dtype == np.complex64
    assert io.read_sigmf(out / "calibration").calibration["tag_position"] == pytest.approx(
        sim.details["calibration_position"])
    # The sigmf package reads it too.
    import sigmf

    handle = sigmf.fromfile(str(out / "recording.sigmf-meta"))
    assert handle.get_global_field(sigmf.NUM_CHANNELS_KEY) == 4


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


# --------------------------------------------------------------------------
# corrupt and truncated recordings: each a FormatError naming the file


@pytest.fixture
def copy(recording, tmp_path):
    """A fresh copy of the recording's two files; returns (meta, data) paths."""
    _, out = recording
    meta, data = tmp_path / "r.sigmf-meta", tmp_path / "r.sigmf-data"
    shutil.copy(out / "recording.sigmf-meta", meta)
    shutil.copy(out / "recording.sigmf-data", data)
    return meta, data


def edit_meta(meta, change):
    document = json.loads(meta.read_text())
    change(document)
    meta.write_text(json.dumps(document))


def test_bad_json(copy):
    meta, _ = copy
    meta.write_text(meta.read_text()[:500])
    with pytest.raises(FormatError, match="not valid JSON") as error:
        io.read_sigmf(meta)
    assert error.value.path == str(meta) and error.value.line is not None


@pytest.mark.parametrize(
    "key",
    ["scattertrack:blf_hz", "scattertrack:known_symbol", "scattertrack:channels", "core:num_channels"],
)
def test_missing_keys(copy, key):
    meta, _ = copy
    edit_meta(meta, lambda d: d["global"].pop(key))
    with pytest.raises(FormatError) as error:
        io.read_sigmf(meta)
    assert error.value.path == str(meta) and key in str(error.value)


@pytest.mark.parametrize(
    "field, value, match",
    [
        ("core:datatype", "ci8", "unsupported datatype"),
        ("core:datatype", "cf64_le", "unsupported datatype"),
        ("scattertrack:subcarriers", 2000, r"N < B/\(2 BLF\)"),
        ("scattertrack:known_symbol", [[0.0, 0.0], [1.0, 0.0]], "known_symbol"),
        ("scattertrack:encoding", "manchester", "encoding"),
        ("core:num_channels", 3, "num_channels"),
        ("core:sample_rate", "fast", "schema"),
    ],
)
def test_bad_values(copy, field, value, match):
    meta, _ = copy
    edit_meta(meta, lambda d: d["global"].__setitem__(field, value))
    with pytest.raises(FormatError, match=match) as error:
        io.read_sigmf(meta)
    assert error.value.path == str(meta)


def test_truncated_data_mid_sample(copy):
    _, data = copy
    size = data.stat().st_size
    with open(data, "r+b") as handle:
        handle.truncate(size - 7)
    with pytest.raises(FormatError, match="byte offset") as error:
        io.read_sigmf(data)
    assert error.value.path == str(data)


def test_truncated_data_missing_windows(copy):
    meta, data = copy
    with open(data, "r+b") as handle:
        handle.truncate(16 * 30_000 * 2 + 16 * 100)  # 2 windows and 100 samples of the third
    with pytest.raises(FormatError, match="truncated") as error:
        io.read_sigmf(meta)
    assert error.value.path == str(data) and "annotations[2]" in str(error.value)


def test_missing_and_corrupt_data_file(copy):
    meta, data = copy
    with open(data, "r+b") as handle:
        handle.seek(1000)
        handle.write(b"\x55\x55")
    with pytest.raises(FormatError, match="SHA-512"):
        io.read_sigmf(meta, verify_checksum=True)
    data.unlink()
    with pytest.raises(FormatError, match="not found") as error:
        io.read_sigmf(meta)
    assert error.value.path == str(data)


def test_capture_errors(copy):
    meta, _ = copy
    edit_meta(meta, lambda d: d["captures"][1].pop("scattertrack:time_s"))
    with pytest.raises(FormatError, match="time_s") as error:
        io.read_sigmf(meta)
    assert error.value.column == "captures[1].scattertrack:time_s"
