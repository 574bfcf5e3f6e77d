"""The IQ simulator of the SDR localization helper (scattertrack.sim.iq)."""

import numpy as np
import pytest

from scattertrack import _core
from scattertrack.io.types import Antenna, Reader, Region, Scene
from scattertrack.sim import iq

TAG = {"E1": {"kind": "static", "position": [0.55, 0.30, 0.60]}}


def helper_scene() -> Scene:
    antennas = [Antenna(0, np.array([0.4, 0.4, 0.0]), role="tx")]
    for i, p in enumerate([[0.0, 0.4, 0.0], [0.8, 0.4, 0.0], [0.4, 0.0, 0.0], [0.4, 0.8, 0.0]]):
        antennas.append(Antenna(i + 1, np.array(p), role="rx"))
    region = Region(np.array([-1.0, -1.0, 0.05]), np.array([2.0, 2.0, 2.0]))
    return Scene("helper", 3, Reader(kind="sdr-helper"), antennas, region=region)


@pytest.mark.parametrize("encoding", iq.ENCODINGS)
@pytest.mark.parametrize("trext", [False, True])
def test_encoder_agrees_with_the_dsp_crate(encoding, trext):
    bits = np.random.default_rng(3).integers(0, 2, 40).tolist()
    ours = iq.reply_chips(encoding, trext, bits)
    theirs = _core.dsp_reply_chips(encoding, trext, bits)
    np.testing.assert_array_equal(ours, theirs)


def test_fm0_preamble_and_transitions():
    chips = iq.reply_chips("fm0", False, [0, 1])
    np.testing.assert_array_equal(chips[:12], [1, 1, 0, 1, 0, 0, 1, 0, 0, 0, 1, 1])
    # Data-0 inverts mid-bit, every bit boundary inverts, then the dummy 1.
    np.testing.assert_array_equal(chips[12:], [0, 1, 0, 0, 1, 1])


def test_design_rule_and_bad_keys_are_rejected():
    with pytest.raises(ValueError, match=r"N < B/\(2 BLF\)"):
        iq.resolve_iq_model({"n_subcarriers": 100, "blf_hz": 500e3})
    with pytest.raises(ValueError, match="unknown IQ model key"):
        iq.resolve_iq_model({"snr": 3})
    with pytest.raises(ValueError, match="encoding"):
        iq.resolve_iq_model({"encoding": "miller3"})


def test_same_seed_same_recording_and_windows_are_described():
    a = iq.simulate_iq(helper_scene(), TAG, seed=5, duration_s=0.01)
    b = iq.simulate_iq(helper_scene(), TAG, seed=5, duration_s=0.01)
    c = iq.simulate_iq(helper_scene(), TAG, seed=6, duration_s=0.01)
    np.testing.assert_array_equal(a.recording.data, b.recording.data)
    assert not np.array_equal(a.recording.data, c.recording.data)
    captures = a.recording.meta["captures"]
    length = int(round(300e-6 * 100e6))
    assert len(captures) == 3 and a.details["recording"]["bytes"] == 3 * length * 4 * 4
    assert [c["core:sample_start"] for c in captures] == [0, length, 2 * length]
    times = [c["scattertrack:time_s"] for c in captures]
    assert np.all(np.diff(times) > 0.002)
    for capture in captures:
        assert capture["scattertrack:tx_sample_index"] == round(capture["scattertrack:time_s"] * 100e6)
    assert {x["scattertrack:epc"] for x in a.recording.meta["annotations"]} == {"E1"}
    # The reply starts after the window opens, within the T1 tolerance.
    starts = np.array(a.details["recording"]["reply_start_s"]) - np.array(times)
    assert np.all((starts > 15e-6) & (starts < 50e-6))
    assert a.calibration.meta["global"]["scattertrack:calibration"]["epc"] == "E1"


def test_noise_level_follows_snr_db():
    # Without a reply the window is the periodic static part plus noise:
    # the difference of samples one symbol apart has variance 2 sigma^2.
    for snr_db in (0.0, 10.0):
        model = {"miss_probability": 1.0, "snr_db": snr_db, "datatype": "cf32_le"}
        sim = iq.simulate_iq(helper_scene(), TAG, model=model, seed=2, duration_s=0.01)
        data = np.asarray(sim.recording.data) / sim.recording.meta["global"]["scattertrack:scale"]
        window = data[:30_000]
        difference = window[20:] - window[:-20]
        sigma = np.sqrt(np.mean(np.abs(difference) ** 2) / 2.0)
        assert sigma == pytest.approx(10 ** (-snr_db / 20), rel=0.03)


def test_tag_modulates_only_inside_its_reply():
    # Noiseless: the symbol-to-symbol change is zero except at tag transitions.
    model = {"snr_db": 200.0, "datatype": "cf32_le", "transition_s": 0.0}
    sim = iq.simulate_iq(helper_scene(), TAG, model=model, seed=4, duration_s=0.004)
    window = np.asarray(sim.recording.data[:30_000, 0]) / sim.recording.meta["global"]["scattertrack:scale"]
    change = np.abs(window[20:] - window[:-20])
    moving = np.flatnonzero(change > 1e-3 * np.abs(window).max())
    start = (sim.details["recording"]["reply_start_s"][0] - sim.recording.meta["captures"][0]["scattertrack:time_s"]) * 100e6
    assert moving.min() >= start - 21
    # Chips of 1250 samples: changes cluster at chip boundaries.
    offsets = (moving + 20 - start) % (100e6 / (2 * sim.details["recording"]["blf_hz"][0]))
    assert np.all((offsets < 25) | (offsets > 1250 * 0.97 - 25))
