"""The SDR helper at frame level: channel physics checked against hand-computed paths,
the frame simulator's schedule, subcarriers, noise and impairments, and the
turbotrack scenarios."""

import cmath
import math

import numpy as np
import pytest

from scattertrack.io import Antenna, FormatError, Reader, Region, Scene, read_frames, read_scene, read_truth
from scattertrack.sim import (
    HELPER_MODEL_DEFAULTS,
    bistatic_path_lengths,
    helper_geometry,
    list_scenarios,
    load_scenario,
    resolve_helper_model,
    simulate,
    simulate_frames,
    static_channel,
    subcarrier_frequencies,
    tag_channel,
    write_simulation,
)
from scattertrack.sim.trajectory import positions_velocities
from scattertrack.sim import wideband
from scattertrack.sim.wideband import bent_leg_lengths, frames_from_truth, helper_streams

C = 299792458.0
TX = [0.4, 0.4, 0.0]
RX = [[0.0, 0.4, 0.0], [0.8, 0.4, 0.0], [0.4, 0.0, 0.0], [0.4, 0.8, 0.0]]
TAGS = [[0.5, 0.6, 0.7], [0.3, 0.25, 0.45], [-0.4, 1.1, 1.3]]

# A model with every impairment off: frames are the exact tag channel.
NOISELESS = {
    "snr_db": 400.0,
    "calibration_phase_error_rad": 0.0,
    "calibration_delay_error_s": 0.0,
    "outlier_probability": 0.0,
    "rx_miss_probability": 0.0,
    "miss_probability": 0.0,
}


def helper_scene(dimensions: int = 3) -> Scene:
    antennas = [Antenna(0, np.array(TX), role="tx")]
    antennas += [Antenna(i + 1, np.array(p), role="rx") for i, p in enumerate(RX)]
    return Scene(
        name="plus",
        dimensions=dimensions,
        reader=Reader(kind="sdr-helper"),
        antennas=antennas,
        plane_z=0.5 if dimensions == 2 else None,
        region=Region(np.array([-1.0, -1.0, 0.05]), np.array([2.0, 2.0, 2.0])),
    )


# --- physics ------------------------------------------------------------------


def test_bistatic_path_lengths_match_a_loop():
    lengths = bistatic_path_lengths(TX, RX, TAGS)
    assert lengths.shape == (3, 4)
    for t, tag in enumerate(TAGS):
        for r, rx in enumerate(RX):
            assert lengths[t, r] == pytest.approx(math.dist(TX, tag) + math.dist(tag, rx), rel=1e-14)


def test_subcarriers_of_the_thesis_helper():
    frequencies = subcarrier_frequencies(915e6, 100e6, 20)
    np.testing.assert_allclose(frequencies, 867.5e6 + 5e6 * np.arange(20), rtol=0, atol=1e-6)
    assert 915e6 not in frequencies  # DC dropped
    odd = subcarrier_frequencies(915e6, 100e6, 5)  # 20 MHz apart; the middle one would be DC
    np.testing.assert_allclose(odd, [875e6, 895e6, 935e6, 955e6])
    with pytest.raises(ValueError):
        subcarrier_frequencies(40e6, 100e6, 20)


def test_noiseless_channel_phase_is_the_path_length():
    """Independent check of docs/formats.md 5: -arg h = 2 pi f d / c (mod 2 pi), |h| = 1 / (d1 d2)."""
    frequencies = subcarrier_frequencies(915e6, 100e6, 20)
    h = tag_channel(TX, RX, TAGS, frequencies)
    assert h.shape == (3, 4, 20) and h.dtype == np.complex128
    for t, tag in enumerate(TAGS):
        for r, rx in enumerate(RX):
            d1, d2 = math.dist(TX, tag), math.dist(tag, rx)
            for k, f in enumerate(frequencies.tolist()):
                expected = cmath.exp(-2j * math.pi * f * (d1 + d2) / C) / (d1 * d2)
                assert abs(h[t, r, k] - expected) < 1e-12 * abs(expected)
    # The phase slope across the band is the time of flight: d = -c/(2 pi) d(arg h)/df.
    slope = np.diff(np.unwrap(np.angle(h), axis=2), axis=2) / np.diff(frequencies)
    lengths = np.broadcast_to(bistatic_path_lengths(TX, RX, TAGS)[..., None], slope.shape)
    np.testing.assert_allclose(-slope * C / (2 * math.pi), lengths, rtol=1e-9)


def test_reflectors_add_one_path_per_bent_leg():
    frequencies = np.array([900e6, 930e6])
    scatterer = {"kind": "point", "position": [1.5, 0.4, 0.5], "coefficient": -0.5}
    direct = tag_channel(TX, RX, TAGS, frequencies)
    extra = tag_channel(TX, RX, TAGS, frequencies, [scatterer]) - direct
    P = scatterer["position"]
    for t, tag in enumerate(TAGS):
        for r, rx in enumerate(RX):
            d1, d2 = math.dist(TX, tag), math.dist(tag, rx)
            g1 = math.dist(TX, P) + math.dist(P, tag)  # tx -> scatterer -> tag
            g2 = math.dist(tag, P) + math.dist(P, rx)  # tag -> scatterer -> rx
            for k, f in enumerate(frequencies.tolist()):
                expected = -0.5 * cmath.exp(-2j * math.pi * f * (g1 + d2) / C) / (g1 * d2)
                expected += -0.5 * cmath.exp(-2j * math.pi * f * (d1 + g2) / C) / (d1 * g2)
                assert abs(extra[t, r, k] - expected) < 1e-12
    # A floor mirror: the image-source length; no path to points on the other side.
    floor = {"kind": "plane", "point": [0.0, 0.0, -0.5], "normal": [0.0, 0.0, 2.0], "coefficient": 0.3}
    length, present = bent_leg_lengths(np.array(TX), np.array(TAGS[0]), floor)
    assert present and length == pytest.approx(math.dist([0.4, 0.4, -1.0], TAGS[0]))
    length, present = bent_leg_lengths(np.array(TX), np.array([0.5, 0.5, -1.0]), floor)
    assert not present
    below = tag_channel(TX, RX, [[0.5, 0.5, -1.0]], frequencies, [floor])
    np.testing.assert_allclose(below, tag_channel(TX, RX, [[0.5, 0.5, -1.0]], frequencies))


def test_static_channel_is_leakage_and_clutter():
    frequencies = subcarrier_frequencies(915e6, 100e6, 20)
    direct = static_channel(TX, RX, frequencies, leakage=300.0)
    assert direct.shape == (4, 20)
    for r, rx in enumerate(RX):
        d0 = math.dist(TX, rx)
        expected = 300.0 / d0 * np.exp(-2j * np.pi * frequencies * d0 / C)
        np.testing.assert_allclose(direct[r], expected, rtol=1e-12)
    wall = {"kind": "plane", "point": [2.0, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0], "coefficient": 0.4}
    clutter = static_channel(TX, RX, frequencies, [wall], leakage=300.0) - direct
    g = math.dist([3.6, 0.4, 0.0], RX[0])  # image of tx in the wall x = 2
    np.testing.assert_allclose(clutter[0], 300.0 * 0.4 / g * np.exp(-2j * np.pi * frequencies * g / C), rtol=1e-12)
    # The tag channel is what reflective minus non-reflective leaves: the static part cancels.
    tag = tag_channel(TX, RX, TAGS[:1], frequencies, [wall])[0]
    reflective, non_reflective = direct + clutter + tag, direct + clutter
    np.testing.assert_allclose(reflective - non_reflective, tag, atol=1e-10)
    # The leakage is far stronger than a tag 1 m away: why the helper subtracts.
    assert np.abs(direct).min() > 100 * np.abs(tag_channel(TX, RX, [[0.4, 0.4, 1.0]], frequencies)).max()


# --- the frame simulator ------------------------------------------------------------


ARM = {"kind": "pick-and-place", "peak_speed": 0.25, "pick": [0.3, 0.3, 0.45], "place": [0.6, 0.5, 0.45], "lift_m": 0.3}


def test_same_seed_same_frames_other_seed_other_frames():
    a, truth_a = simulate_frames(helper_scene(), {"E2FF0001": ARM}, seed=5, duration_s=1.0)
    b, truth_b = simulate_frames(helper_scene(), {"E2FF0001": ARM}, seed=5, duration_s=1.0)
    c, _ = simulate_frames(helper_scene(), {"E2FF0001": ARM}, seed=6, duration_s=1.0)
    np.testing.assert_array_equal(a.time_s, b.time_s)
    np.testing.assert_array_equal(a.h, b.h)
    np.testing.assert_array_equal(truth_a.position, truth_b.position)
    assert len(c.time_s) != len(a.time_s) or not np.array_equal(c.h, a.h)


def test_frame_rate_subcarriers_and_shared_budget():
    frames, truth = simulate_frames(helper_scene(), {"E2FF0001": ARM}, seed=1, duration_s=4.0)
    times = frames.frame_time_s
    assert 270 <= frames.n_frames / 4.0 <= 310  # about 300 frames/s (thesis sec. 7.1)
    gaps = np.diff(times)
    assert np.all(gaps > 0) and gaps.std() > 0.1 * gaps.mean()  # random gaps
    assert np.all(times == np.round(times, 6)) and times.max() < 4.0
    expected = subcarrier_frequencies(915e6, 100e6, 20)
    rx_ids, frequencies, grid = frames.frame_grid(0)
    np.testing.assert_array_equal(frequencies, expected)
    assert set(frames.tx.tolist()) == {0} and set(frames.rx.tolist()) == {1, 2, 3, 4}
    counts = np.diff(frames.frame_start)
    assert set(counts.tolist()) <= {20 * n for n in (1, 2, 3, 4)}
    assert np.mean(counts == 80) > 0.9  # a few frames miss one rx
    assert truth.time_s[-1] == 4.0 and len(truth) == 801
    three = {f"E2FF000{i}": ARM | {"time_offset_s": i} for i in range(3)}
    shared, _ = simulate_frames(helper_scene(), three, seed=1, duration_s=4.0)
    per_tag = [np.sum(shared.frame_epc == epc) / 4.0 for epc in three]
    assert all(85 <= rate <= 115 for rate in per_tag), per_tag


def test_noiseless_frames_are_the_tag_channel_at_the_true_position():
    frames, _ = simulate_frames(helper_scene(), {"E1": ARM}, NOISELESS, seed=2, duration_s=0.5)
    scene = helper_scene()
    _, tx, rx_ids, rx = helper_geometry(scene)
    for k in range(0, frames.n_frames, 17):
        ids, frequencies, grid = frames.frame_grid(k)
        position = positions_velocities(ARM, [frames.frame_time_s[k]])[0]
        np.testing.assert_allclose(grid, tag_channel(tx, rx, position, frequencies)[0], rtol=1e-9)


def test_noise_calibration_and_outliers_follow_the_model():
    scene = helper_scene()
    static = {"kind": "static", "position": [0.4, 0.4, 1.0]}  # d1 = 1 m
    _, tx, _, rx = helper_geometry(scene)
    frequencies = subcarrier_frequencies(915e6, 100e6, 20)
    clean = tag_channel(tx, rx, [[0.4, 0.4, 1.0]], frequencies)[0]

    noisy, _ = simulate_frames(scene, {"E1": static}, NOISELESS | {"snr_db": 20.0}, seed=3, duration_s=2.0)
    residual = np.stack([noisy.frame_grid(k)[2] - clean for k in range(noisy.n_frames)])
    assert np.sqrt(np.mean(np.abs(residual) ** 2)) == pytest.approx(0.1, rel=0.05)  # sigma = 10^(-20/20)

    model = NOISELESS | {"calibration_phase_error_rad": 0.1, "calibration_delay_error_s": 3e-11}
    rngs = helper_streams(4)
    from scattertrack.io.types import Truth

    truth = Truth(np.array([0.0, 1.0]), np.array(["E1", "E1"]), np.array([[0.4, 0.4, 1.0]] * 2), np.zeros((2, 3)))
    frames, _, details = frames_from_truth(scene, truth, model, rngs)
    assert 0.0 <= frames.frame_time_s.min() and frames.frame_time_s.max() <= 1.0
    phase = np.array(list(details["true_calibration_phase_error_rad"].values()))
    delay = np.array(list(details["true_calibration_delay_error_s"].values()))
    assert np.all(phase != 0.0) and np.all(delay != 0.0)
    expected = clean * np.exp(-1j * (phase[:, None] + 2 * np.pi * frequencies * delay[:, None]))
    np.testing.assert_allclose(frames.frame_grid(0)[2], expected, rtol=1e-9)

    hit, _ = simulate_frames(scene, {"E1": static}, NOISELESS | {"outlier_probability": 1.0}, seed=3, duration_s=1.0)
    burst = np.stack([hit.frame_grid(k)[2] - clean for k in range(hit.n_frames)])
    power_db = 10 * np.log10(np.mean(np.abs(burst) ** 2))
    assert power_db == pytest.approx(HELPER_MODEL_DEFAULTS["outlier_power_db"], abs=0.3)


def test_default_snr_gives_the_documented_phase_noise():
    """Phase noise 1/sqrt(2 SNR): 0.05 rad per subcarrier at d1 = d2 = 1 m, growing as d1 d2."""
    scene = helper_scene()
    model = {"outlier_probability": 0.0}
    for height in (1.0, 2.0):
        tag = [0.4, 0.4, height]  # above the transmitter: d1 = height
        frames, _ = simulate_frames(scene, {"E1": {"kind": "static", "position": tag}}, model, seed=8, duration_s=1.0)
        rows = frames.rx == 3  # the receiver at (0.4, 0, 0)
        d1, d2 = math.dist(TX, tag), math.dist(tag, RX[2])
        h = (frames.h[rows] * np.exp(2j * np.pi * frames.frequency_hz[rows] * (d1 + d2) / C)).reshape(-1, 20)
        # The calibration residual turns every frame alike: measure the spread about the mean.
        spread = np.angle(h * np.exp(-1j * np.angle(h.mean(axis=0))))
        sigma = 10 ** (-HELPER_MODEL_DEFAULTS["snr_db"] / 20) / math.sqrt(2)
        assert sigma == pytest.approx(0.05, abs=0.001)
        assert np.std(spread) == pytest.approx(sigma * d1 * d2, rel=0.1)


def test_truth_input_and_two_dimensions():
    scene = helper_scene(dimensions=2)
    path = {"kind": "circle", "centre": [0.4, 0.4, 0.5], "radius": 0.2, "speed": 0.3}
    frames, truth = simulate_frames(scene, {"E1": path}, NOISELESS, seed=9, duration_s=1.0)
    again, same_truth = simulate_frames(scene, truth, NOISELESS, seed=9)
    assert same_truth is truth
    # Linear interpolation of a 200 Hz truth: channels agree with the exact path to ~1e-3.
    _, tx, _, rx = helper_geometry(scene)
    k = again.n_frames // 2
    ids, frequencies, grid = again.frame_grid(k)
    exact = tag_channel(tx, rx, positions_velocities(path, [again.frame_time_s[k]])[0], frequencies)[0]
    assert np.max(np.abs(grid - exact) / np.abs(exact)) < 1e-3


def test_model_is_validated():
    with pytest.raises(FormatError, match=r"N < B / \(2 BLF\)") as caught:
        resolve_helper_model({"n_subcarriers": 1300}, "x.toml", "helper_model.")
    assert caught.value.column == "helper_model.n_subcarriers" and caught.value.path == "x.toml"
    with pytest.raises(FormatError) as caught:
        simulate_frames(helper_scene(), {"E1": ARM}, {"snr": 20})
    assert caught.value.column == "snr" and "unknown key" in caught.value.message
    with pytest.raises(FormatError, match="reflectors"):
        resolve_helper_model({"reflectors": [{"kind": "mirror"}]})
    with pytest.raises(ValueError, match="exactly one antenna with role 'tx'"):
        scene = helper_scene()
        scene.antennas[1].role = "tx"
        simulate_frames(scene, {"E1": ARM})


# --- turbotrack scenarios -------------------------------------------------------------


TURBOTRACK = [
    "turbotrack-3d-arm",
    "turbotrack-static",
    "turbotrack-3d-multipath",
    "turbotrack-3d-3tags",
    *[f"turbotrack-2d-speed-{v}" for v in ("05", "10", "20", "30", "40", "50")],
]


def test_turbotrack_scenarios_are_listed_by_pipeline():
    assert sorted(TURBOTRACK) == list_scenarios("turbotrack")
    assert not set(TURBOTRACK) & set(list_scenarios("glac"))
    assert list_scenarios() == list_scenarios("glac")  # the default, as before the helper existed
    assert set(list_scenarios("all")) == set(list_scenarios("glac")) | set(TURBOTRACK) | set(list_scenarios("marvel"))
    with pytest.raises(ValueError, match="unknown pipeline"):
        list_scenarios("tagoram")


@pytest.mark.parametrize("name", TURBOTRACK)
def test_turbotrack_scenario_geometry(name):
    scenario = load_scenario(name)
    assert scenario["pipeline"] == "turbotrack" and scenario["description"]
    scene = scenario["scene"]
    tx = [a["position"] for a in scene["antennas"] if a["role"] == "tx"]
    rx = np.array([a["position"] for a in scene["antennas"] if a["role"] == "rx"])
    assert len(tx) == 1 and len(rx) == 4
    antennas = np.vstack([tx, rx])
    assert np.all(antennas[:, 2] == 0.0)
    # Adjacent antennas 40 cm apart (thesis ch. 6); the receivers are not collinear.
    spacing = np.linalg.norm(rx - np.array(tx[0]), axis=1)
    np.testing.assert_allclose(spacing, 0.4)
    assert np.linalg.matrix_rank(rx[1:] - rx[0], tol=1e-6) == 2
    model = resolve_helper_model(scenario.get("helper_model", {}))
    assert (model["bandwidth_hz"], model["n_subcarriers"], model["blf_hz"]) == (100e6, 20, 40e3)
    low, high = np.array(scene["region"]["min"]), np.array(scene["region"]["max"])
    assert low[2] >= 0.05
    times = np.linspace(0.0, scenario["duration_s"], 2001)
    for tag in scenario["tags"]:
        position, velocity = positions_velocities(tag["trajectory"], times)
        assert np.all(position >= low) and np.all(position <= high)
        assert np.linalg.norm(position[:, None] - antennas[None], axis=2).max() < 6.0
        assert np.linalg.norm(position[:, None] - antennas[None], axis=2).min() > 0.25
        speed = np.linalg.norm(velocity, axis=1)
        if scene["dimensions"] == 2:
            assert np.all(position[:, 2] == scene["plane_z"]) and scene["plane_z"] > 0
            assert speed.max() == pytest.approx(int(name[-2:]) / 100, rel=1e-6)
        elif "static" in name:
            assert speed.max() == 0.0
        else:
            assert 0.1 <= speed.max() <= 0.3


def test_turbotrack_simulation_writes_frames(tmp_path):
    sim = simulate(load_scenario("turbotrack-3d-multipath") | {"duration_s": 1.0}, seed=11)
    assert sim.pipeline == "turbotrack" and sim.reads is None
    assert len(sim.scenario["helper_model"]["reflectors"]) == 3
    out = write_simulation(sim, tmp_path / "run")
    assert sorted(p.name for p in out.iterdir()) == ["frames.csv", "scene.toml", "simulation.json", "truth.csv"]
    scene = read_scene(out / "scene.toml")
    assert scene.reader.kind == "sdr-helper"
    assert scene.extra["helper"] == {
        "centre_frequency_hz": 915e6,
        "bandwidth_hz": 100e6,
        "n_subcarriers": 20,
        "blf_hz": 40e3,
    }
    frames = read_frames(out / "frames.csv", scene)
    assert frames.n_frames == sim.frames.n_frames and frames.skipped.total == 0
    np.testing.assert_allclose(frames.h, sim.frames.h, rtol=1e-8)
    truth = read_truth(out / "truth.csv")
    assert truth.time_s[-1] == 1.0
    # The scenario's seed, and the recorded scenario replays the same frames.
    import json

    record = json.loads((out / "simulation.json").read_text())
    assert record["seed"] == 11 and record["details"]["counts"]["frames"] == frames.n_frames
    np.testing.assert_array_equal(simulate(record["scenario"]).frames.h, sim.frames.h)


def test_turbotrack_scenario_errors(tmp_path):
    base = load_scenario("turbotrack-static")
    with pytest.raises(FormatError) as caught:
        simulate(base | {"reader_model": {}})
    assert caught.value.column == "reader_model" and "glac scenarios" in caught.value.message
    antennas = [dict(a) for a in base["scene"]["antennas"]]
    antennas[1]["role"] = "tx"
    with pytest.raises(FormatError) as caught:
        simulate(base | {"scene": base["scene"] | {"antennas": antennas}})
    assert caught.value.column == "scene.antennas" and "exactly one antenna with role 'tx'" in caught.value.message
    del antennas[2]["role"]
    with pytest.raises(FormatError) as caught:
        simulate(base | {"scene": base["scene"] | {"antennas": antennas}})
    assert caught.value.column == "scene.antennas[2].role"
    with pytest.raises(FormatError) as caught:
        simulate(base | {"pipeline": "tagoram"})
    assert caught.value.column == "pipeline"
    with pytest.raises(FormatError) as caught:
        simulate(base | {"helper_model": {"blf_hz": 5e6}})
    assert caught.value.column == "helper_model.n_subcarriers"


def test_calibration_path_errors_are_the_least_squares_distance_of_the_residual():
    """A pure delay adds c tau of path; a pure phase about phi lambda / 2 pi;
    both together what fitting 2 pi f dL / c to the residual phase over the
    subcarriers gives (least squares through the origin)."""
    f = subcarrier_frequencies(915e6, 100e6, 20)
    assert wideband.calibration_path_errors_m(f, [0.0], [1e-11])[0] == pytest.approx(C * 1e-11, rel=1e-12)
    wavelength = C / 915e6
    assert wideband.calibration_path_errors_m(f, [0.05], [0.0])[0] == pytest.approx(0.05 * wavelength / (2 * math.pi), rel=0.01)
    phase, delay = np.array([0.05, -0.03, 0.0]), np.array([-4e-12, 7e-12, 1e-11])
    errors = wideband.calibration_path_errors_m(f, phase, delay)
    for r in range(3):
        design = (2 * math.pi * f / C)[:, None]
        fitted = np.linalg.lstsq(design, phase[r] + 2 * math.pi * f * delay[r], rcond=None)[0][0]
        assert errors[r] == pytest.approx(fitted, rel=1e-9)


def test_calibration_shift_matches_the_biased_path_lengths():
    tx, rx = np.array(TX), np.array(RX)
    tag = np.array(TAGS[0])
    assert np.allclose(wideband.calibration_shift_m(tx, rx, tag, np.zeros(4)), 0.0)
    # Three receivers in 3D: the shifted position has exactly the biased lengths.
    errors = np.array([0.004, -0.003, 0.002])
    shift = wideband.calibration_shift_m(tx, rx[:3], tag, errors)
    lengths = bistatic_path_lengths(tx, rx[:3], tag + shift)[0]
    assert np.allclose(lengths, bistatic_path_lengths(tx, rx[:3], tag)[0] + errors, atol=1e-12)
    assert 1e-3 < np.linalg.norm(shift) < 0.1
    # Four receivers, errors that a position change explains: that change comes back.
    move = np.array([0.002, -0.001, 0.003])
    consistent = bistatic_path_lengths(tx, rx, tag + move)[0] - bistatic_path_lengths(tx, rx, tag)[0]
    assert np.allclose(wideband.calibration_shift_m(tx, rx, tag, consistent), move, atol=1e-10)
