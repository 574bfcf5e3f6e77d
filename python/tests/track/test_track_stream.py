"""The real-time runtime over a simulated helper recording: every reply comes
out, positions are right, latency is recorded, and bad input is refused or
counted (never a crash)."""

import numpy as np
import pytest

from scattertrack import eval as evaluation
from scattertrack import io
from scattertrack.dsp import calibrate_sigmf, read_sigmf_frames
from scattertrack.io.sigmf import read_sigmf
from scattertrack.io.types import Antenna, Reader, Region, Scene
from scattertrack.sim import iq
from scattertrack.track import run
from scattertrack.track.stream import stream_sigmf

TX = np.array([0.4, 0.4, 0.0])
RX = np.array([[0.0, 0.4, 0.0], [0.8, 0.4, 0.0], [0.4, 0.0, 0.0], [0.4, 0.8, 0.0]])


def helper_scene() -> Scene:
    antennas = [Antenna(0, TX.copy(), role="tx")] + [Antenna(i + 1, p.copy(), role="rx") for i, p in enumerate(RX)]
    region = Region(np.array([-1.0, -1.0, 0.05]), np.array([2.0, 2.0, 2.0]))
    return Scene("helper", 3, Reader(kind="sdr-helper"), antennas, region=region)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """0.25 s of a tag moving on a line at 20 cm/s (75 replies), 5 % missed replies."""
    trajectory = {"kind": "line", "start": [0.3, 0.3, 0.6], "end": [0.7, 0.5, 0.7], "speed": 0.2}
    sim = iq.simulate_iq(helper_scene(), {"E1": trajectory}, model={"miss_probability": 0.05}, seed=4, duration_s=0.25)
    out = iq.write_iq_simulation(sim, tmp_path_factory.mktemp("stream"))
    return sim, out


def test_every_reply_comes_out_with_its_latency_and_positions_are_sub_centimetre(session):
    sim, out = session
    scene = io.read_scene(out / "scene.toml")
    result = stream_sigmf(out / "recording.sigmf-meta", scene, out / "calibration.sigmf-meta")
    replies = len(read_sigmf(out / "recording.sigmf-meta").windows)
    assert result.replies == replies == result.latency_ns.size
    assert (result.latency_ns > 0).all() and result.stage_ns.shape == (replies, len(result.stages))
    # Missed replies are declined by the DSP and counted, never silently dropped.
    missed = int(np.sum(~np.array(sim.details["answered"])))
    assert missed > 0 and sum(result.declined.values()) == missed
    assert result.track.skipped.total >= missed
    report = evaluation.compare(sim.truth, result.track, skip_first_s=0.05)
    assert report.overall.n > 30
    assert report.overall.median_3d_m < 0.01, report.overall


def test_streaming_gives_what_the_offline_path_gives(session):
    """Same DSP, same tracker: the runtime's positions match read_sigmf_frames + track.run."""
    _, out = session
    scene = io.read_scene(out / "scene.toml")
    calibration = calibrate_sigmf(out / "calibration.sigmf-meta", scene)
    streamed = stream_sigmf(out / "recording.sigmf-meta", scene, calibration, speed=None)
    frames = read_sigmf_frames(out / "recording.sigmf-meta", scene, calibration)
    offline = run("turbotrack", scene, frames)
    assert len(streamed.track) == len(offline)
    # Frame times differ by the preamble's offset in the window (tens of µs), so
    # positions agree to well under a millimetre, not bit for bit.
    gap = np.linalg.norm(streamed.track.position - offline.position, axis=1)
    assert np.median(gap) < 1e-3, np.median(gap)


def test_every_thread_layout_gives_the_same_track(session):
    """The team (default), the thesis's per-antenna pools and one shared
    pool run the same DSP and tracker in reply order: same positions, paced
    (with and without the pre-wake) or as fast as possible."""
    _, out = session
    scene = io.read_scene(out / "scene.toml")
    calibration = calibrate_sigmf(out / "calibration.sigmf-meta", scene)
    runs = [
        stream_sigmf(out / "recording.sigmf-meta", scene, calibration, speed=speed, layout=layout, prewake_s=prewake)
        for layout, speed, prewake in [
            ("team", 1.0, 5e-4), ("team", 1.0, 0.0), ("team", None, 5e-4), ("per-antenna", None, 5e-4), ("shared", 1.0, 5e-4),
        ]
    ]
    for other in runs[1:]:
        np.testing.assert_array_equal(other.track.position, runs[0].track.position)
        assert other.declined == runs[0].declined
    # Paced: the run takes the recording's time.
    assert runs[0].wall_s >= 0.9 * (runs[0].track.time_s[-1] - runs[0].track.time_s[0])


def test_bad_input_is_refused(session, tmp_path):
    _, out = session
    scene = io.read_scene(out / "scene.toml")
    with pytest.raises(ValueError, match="calibration"):
        stream_sigmf(out / "recording.sigmf-meta", scene, None)
    with pytest.raises(ValueError, match="does not track helper recordings"):
        stream_sigmf(out / "recording.sigmf-meta", scene, out / "calibration.sigmf-meta", method="glac")
    other = helper_scene()
    other.antennas = other.antennas[:3]
    with pytest.raises(io.FormatError, match="not an 'rx' antenna"):
        stream_sigmf(out / "recording.sigmf-meta", other, out / "calibration.sigmf-meta")
    with pytest.raises(ValueError, match="layout 'pools' is not one of"):
        stream_sigmf(out / "recording.sigmf-meta", scene, out / "calibration.sigmf-meta", layout="pools")
    with pytest.raises(ValueError, match="prewake_s"):
        stream_sigmf(out / "recording.sigmf-meta", scene, out / "calibration.sigmf-meta", prewake_s=-1.0)


def test_an_all_nan_window_is_counted(session, tmp_path):
    _, out = session
    scene = io.read_scene(out / "scene.toml")
    recording = read_sigmf(out / "recording.sigmf-meta")
    # As float samples (ci16 cannot hold NaN), one window all NaN.
    data = (recording.data[..., 0] + 1j * recording.data[..., 1]).astype(np.complex64)
    w = recording.windows[3]
    data[w.sample_start : w.sample_start + w.sample_count] = np.nan
    recording.data, recording.datatype = data, "cf32_le"
    result = stream_sigmf(recording, scene, out / "calibration.sigmf-meta")
    assert result.replies == len(recording.windows)
    assert sum(result.declined.values()) >= 1


def test_file_capture_and_in_memory_capture_agree(session):
    """A recording read from disk is streamed from its data file; the same
    samples from memory give the same track."""
    _, out = session
    scene = io.read_scene(out / "scene.toml")
    calibration = calibrate_sigmf(out / "calibration.sigmf-meta", scene)
    recording = read_sigmf(out / "recording.sigmf-meta")
    from_file = stream_sigmf(recording, scene, calibration)
    recording.data = np.array(recording.data)  # no longer a memory map: the array path
    from_memory = stream_sigmf(recording, scene, calibration)
    np.testing.assert_array_equal(from_file.track.position, from_memory.track.position)
    assert from_file.declined == from_memory.declined


def test_a_window_that_cannot_be_read_is_counted(session, tmp_path):
    """A data file cut after it was validated (e.g. a recording being rotated):
    the windows past its end are counted, not a crash."""
    import shutil

    _, out = session
    scene = io.read_scene(out / "scene.toml")
    calibration = calibrate_sigmf(out / "calibration.sigmf-meta", scene)
    for suffix in ("sigmf-meta", "sigmf-data"):
        shutil.copy(out / f"recording.{suffix}", tmp_path / f"recording.{suffix}")
    recording = read_sigmf(tmp_path / "recording.sigmf-meta")
    data = tmp_path / "recording.sigmf-data"
    last = recording.windows[-1]
    per_sample = data.stat().st_size // recording.n_samples
    with open(data, "r+b") as handle:
        handle.truncate(last.sample_start * per_sample)
    result = stream_sigmf(recording, scene, calibration)
    assert result.replies == len(recording.windows)
    assert result.track.skipped.counts.get("reply window that could not be read from the data file") == 1


def test_the_binding_wants_exactly_one_source(session):
    from scattertrack.dsp.ofdm import ofdm_dsp as _dsp
    from scattertrack.track import helper

    _, out = session
    scene = io.read_scene(out / "scene.toml")
    recording = read_sigmf(out / "recording.sigmf-meta")
    core = helper.engine("turbotrack", scene, {})
    empty = np.zeros(0, dtype=np.int64)
    with pytest.raises(ValueError, match="exactly one of windows and file"):
        core.run_stream(empty, np.zeros(0), empty, _dsp(recording, {}), 0, [1, 2, 3, 4])
