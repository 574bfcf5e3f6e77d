"""TurboTrack and its variants through the Python API and the CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scattertrack import eval as evaluation
from scattertrack import io, sim, track
from scattertrack.cli import main
from scattertrack.io.frames import make_frames

EXAMPLE = Path(__file__).resolve().parents[3] / ".." / "shared" / "examples" / "helper-3d-arm"


@pytest.fixture(scope="module")
def arm():
    scenario = sim.load_scenario("turbotrack-3d-arm")
    scenario["duration_s"] = 3.0
    return sim.simulate(scenario, seed=5)


def test_turbotrack_tracks_the_arm_to_millimetres(arm):
    result = track.run("turbotrack", arm.scene, arm.frames)
    report = evaluation.compare(arm.truth, result, skip_first_s=0.5)
    assert report.overall.median_3d_m < 0.01
    assert np.all(report.overall.p90_axis_m < 0.02)
    # Every frame is accounted for: an estimate, or a counted decline.
    stats = result.stats[arm.frames.epcs()[0]]
    assert stats["measurements"] == arm.frames.n_frames
    assert len(result) + stats["invalid"] + stats["out_of_order"] + stats["initialising"] - 1 <= arm.frames.n_frames
    # The backtracked MAP trajectory covers the recent frames.
    times, positions = result.smoothed[arm.frames.epcs()[0]]
    assert len(times) > 100 and positions.shape == (len(times), 3)


def test_variants_are_selectable_and_worse():
    # The thesis's Fig. 7-4 comparison on the same frames (2D, 20 cm/s).
    scenario = sim.load_scenario("turbotrack-2d-speed-20")
    scenario["duration_s"] = 3.0
    data = sim.simulate(scenario, seed=11)
    def median(method):
        result = track.run(method, data.scene, data.frames)
        return evaluation.compare(data.truth, result, skip_first_s=0.5).overall.median_3d_m
    full = median("turbotrack")
    assert full < 0.01
    for method in ("ellipse-intersection", "gaussian-pf"):
        assert median(method) > full, method


def _calibration_floor_m(data) -> float:
    """How far the simulator's drawn calibration residual alone moves the static tag, metres."""
    return float(np.linalg.norm(sim.wideband.drawn_calibration_shift_m(data.scene, data.details, data.truth.position[0])))


@pytest.mark.parametrize("seed", [1003, 1006])
def test_a_static_tag_sits_on_the_calibration_floor(seed):
    """A static tag's error is the bias of the calibration residual (a few
    mm, which no number of frames averages away) plus under a millimetre
    from the tracker; without the residual it is about a millimetre."""
    scenario = sim.load_scenario("turbotrack-static") | {"duration_s": 3.0}
    data = sim.simulate(scenario, seed=seed)
    floor = _calibration_floor_m(data)
    result = track.run("turbotrack", data.scene, data.frames, seed=seed)
    median = evaluation.compare(data.truth, result, skip_first_s=0.5).overall.median_3d_m
    assert floor > 0.004
    assert abs(median - floor) < 0.001
    exact = sim.simulate(
        scenario | {"helper_model": scenario["helper_model"] | {"calibration_phase_error_rad": 0.0, "calibration_delay_error_s": 0.0}},
        seed=seed,
    )
    assert _calibration_floor_m(exact) == 0.0
    result = track.run("turbotrack", exact.scene, exact.frames, seed=seed)
    assert evaluation.compare(exact.truth, result, skip_first_s=0.5).overall.median_3d_m < 0.002


def _inline_static(snr_db: float, duration_s: float):
    """turbotrack-static with three rx in line with tx and one off the line
    (the layout whose neighbouring lobes fit every receiver's phase), the
    tag 0.6 m from the line, at ``snr_db`` per subcarrier."""
    scenario = sim.load_scenario("turbotrack-static")
    antennas = [(0, (0.6, 0.0, 0.0), "tx"), (1, (0.0, 0.0, 0.0), "rx"), (2, (0.4, 0.0, 0.0), "rx"), (3, (0.8, 0.0, 0.0), "rx"), (4, (0.6, 0.4, 0.0), "rx")]
    scene = scenario["scene"] | {
        "antennas": [{"id": i, "position": list(p), "role": r} for i, p, r in antennas],
        "region": {"min": [-1.0, -0.5, 0.05], "max": [2.0, 3.0, 2.0]},
    }
    tags = [scenario["tags"][0] | {"trajectory": {"kind": "static", "position": [0.55, 0.9, 0.7]}}]
    return scenario | {"scene": scene, "tags": tags, "duration_s": duration_s, "helper_model": scenario["helper_model"] | {"snr_db": snr_db}}


def _last_half_median_m(data, result) -> float:
    truth = data.truth.position[0]
    errors = np.linalg.norm(result.position - truth, axis=1)
    return float(np.median(errors[errors.size // 2 :]))


def test_the_lobe_test_recovers_from_a_wrong_start_and_is_counted():
    """At 2 dB on the in-line layout some start frames seed the filter on a
    neighbouring lobe; the lobe test moves it to the right one (counted in
    ``lobe_switches``), and without the test some start stays locked."""
    data = sim.simulate(_inline_static(2.0, 1.0), seed=0)
    n = data.frames.n_frames
    with_test, without, switches = [], [], 0
    for k in range(0, n // 2, n // 20):
        frames = data.frames.select_frames(np.arange(k, n))
        result = track.run("turbotrack", data.scene, frames, seed=k)
        with_test.append(_last_half_median_m(data, result))
        switches += result.stats[frames.epcs()[0]]["lobe_switches"]
        off = track.run("turbotrack", data.scene, frames, seed=k, lobe_switch_nats=float("inf"))
        without.append(_last_half_median_m(data, off))
        assert off.stats[frames.epcs()[0]]["lobe_switches"] == 0
    assert max(with_test) < 0.05, with_test
    assert max(without) > 0.05 and switches >= 1, (without, switches)


def test_unresolved_lobes_widen_the_reported_sigma():
    """Right after the start, while the lobes' evidence is young, the
    reported sigma covers the neighbouring lobes (centimetres); once they are
    resolved it shrinks to the lobe's own spread (millimetres). Without the
    simulator's calibration residual (a bias no sigma can know of) the
    errors stay within 3 sigmas."""
    scenario = _inline_static(8.0, 0.5)
    scenario["helper_model"] |= {"calibration_phase_error_rad": 0.0, "calibration_delay_error_s": 0.0}
    data = sim.simulate(scenario, seed=1)
    result = track.run("turbotrack", data.scene, data.frames, seed=1)
    sigma = np.linalg.norm(result.sigma, axis=1)
    assert sigma[0] > 3 * np.median(sigma[-50:])
    errors = np.linalg.norm(result.position - data.truth.position[0], axis=1)
    assert np.mean(np.any(np.abs(result.position - data.truth.position[0]) > 3 * result.sigma, axis=1)) < 0.05
    assert np.median(errors[-50:]) < 0.05


@pytest.mark.parametrize("seed", [0, 1])
def test_a_resting_tag_is_estimated_from_its_frames_average(seed):
    """At rest the estimate is the fit of the frames' coherent average
    (``static_average_s``), not the particles' mode: on the in-line layout
    at 8 dB (no calibration residual) it is at least twice as close to the
    truth after the first second, and its sigmas still cover the errors."""
    scenario = _inline_static(8.0, 2.0)
    scenario["helper_model"] |= {"calibration_phase_error_rad": 0.0, "calibration_delay_error_s": 0.0}
    data = sim.simulate(scenario, seed=seed)
    truth = data.truth.position[0]
    medians = []
    for params in ({}, {"static_average_s": 0.0}):
        result = track.run("turbotrack", data.scene, data.frames, seed=seed, **params)
        late = result.time_s >= 1.0
        errors = result.position[late] - truth
        medians.append(float(np.median(np.linalg.norm(errors, axis=1))))
        assert np.mean(np.any(np.abs(errors) > 3 * result.sigma[late], axis=1)) < 0.05
    averaged, particles = medians
    assert averaged < 0.003 and averaged < 0.5 * particles, medians


@pytest.mark.parametrize("seed", [1, 2])
def test_a_tag_low_over_the_antennas_plane_is_not_confidently_wrong(seed):
    """A tag 14 cm over the plane of the in-line layout's antennas has a
    lobe 1.35 m away (one tooth on two receivers) that one frame barely
    tells from its own. Without the lobe tests the filter ends there with
    every row beyond 3 sigma; with them (far lobes, lobes decided on the
    resting average) it ends on the truth and its sigmas cover the errors."""
    scenario = _inline_static(8.0, 2.0)
    scenario["tags"][0]["trajectory"]["position"] = [-0.112, 0.959, 0.138]
    scenario["helper_model"] |= {"calibration_phase_error_rad": 0.0, "calibration_delay_error_s": 0.0}
    data = sim.simulate(scenario, seed=seed)
    truth = data.truth.position[0]
    result = track.run("turbotrack", data.scene, data.frames, seed=0)
    beyond = np.mean(np.any(np.abs(result.position - truth) > 3 * result.sigma, axis=1))
    assert _last_half_median_m(data, result) < 0.05 and beyond < 0.05, (_last_half_median_m(data, result), beyond)
    assert result.stats[data.frames.epcs()[0]]["lobe_switches"] >= 1
    off = track.run("turbotrack", data.scene, data.frames, seed=0, lobe_switch_nats=float("inf"))
    assert _last_half_median_m(data, off) > 1.0


def test_reflections_do_not_move_the_cloud_onto_their_lobes():
    """Strong reflections (a wall, a cabinet and the floor at 23 dB) bias
    every frame's envelope the same way while the arm moves past them.
    Frames whose single-path residual is coherent carry no lobe evidence
    (lobes.rs MULTIPATH_COHERENCE); counted, they moved the cloud 0.5-0.7 m
    onto the reflections' lobes on this seed, with centimetre sigmas."""
    scenario = sim.load_scenario("turbotrack-3d-multipath")
    scenario["duration_s"] = 8.0
    data = sim.simulate(scenario, seed=0)
    result = track.run("turbotrack", data.scene, data.frames, seed=0)
    t = np.asarray(result.time_s)
    truth = np.column_stack([np.interp(t, data.truth.time_s, data.truth.position[:, i]) for i in range(3)])
    errors = np.linalg.norm(result.position - truth, axis=1)
    late = t > 0.5
    assert np.mean(errors[late] > 0.1) < 0.02, np.mean(errors[late] > 0.1)
    assert result.stats[data.frames.epcs()[0]]["lobe_switches"] <= 1


def test_step_frame_streams_one_frame_at_a_time(arm):
    tracker = track.make("turbotrack", arm.scene)
    frames = arm.frames
    estimates = []
    for k in range(200):
        rx, f, h = frames.frame(k)
        tx = int(frames.tx[frames.frame_start[k]])
        e = tracker.step_frame(frames.frame_time_s[k], frames.frame_epc[k], tx, rx, f, h)
        if e is not None:
            estimates.append(e)
    assert len(estimates) > 150
    assert estimates[-1].position.shape == (3,)
    assert tracker.stats(frames.frame_epc[0])["measurements"] == 200


def test_all_nan_frame_is_counted_not_fatal(arm):
    f = arm.frames.select_frames(np.arange(60))
    h = f.h.copy()
    h[f.frame_start[30] : f.frame_start[31]] = np.nan
    broken = make_frames(f.time_s, f.epc, f.tx, f.rx, f.frequency_hz, h)
    result = track.run("turbotrack", arm.scene, broken)
    assert result.stats[f.epcs()[0]]["invalid"] == 1
    assert "frame without enough usable receivers (declined by tracker)" in result.skipped.counts


def test_method_and_input_must_match(arm):
    with pytest.raises(ValueError, match="frames"):
        track.run("turbotrack", arm.scene, io.Reads.__new__(io.Reads)) if hasattr(io, "Reads") else None
    with pytest.raises(ValueError, match="phase reads"):
        track.run("glac", arm.scene, arm.frames)


def test_outside_example_tracks():
    if not EXAMPLE.exists():
        pytest.skip("needs ../shared/examples")
    scene = io.read_scene(EXAMPLE / "scene.toml")
    frames = io.read_frames(EXAMPLE / "frames.csv", scene)
    result = track.run("turbotrack", scene, frames)
    assert len(result) > 0.9 * frames.n_frames


def test_cli_track_frames(tmp_path, capsys):
    out = tmp_path / "sim"
    assert main(["simulate", "--scenario", "turbotrack-static", "--out", str(out), "--duration", "1", "--seed", "3"]) == 0
    assert main(["track", "--scene", str(out / "scene.toml"), "--frames", str(out / "frames.csv"), "--method", "turbotrack", "--out", str(tmp_path / "track.csv"), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "frames/s wall clock" in text
    assert io.read_track(tmp_path / "track.csv").time_s.size > 200
    # The wrong input for the method is a usage error, not a crash.
    code = main(["track", "--scene", str(out / "scene.toml"), "--reads", str(out / "frames.csv"), "--method", "turbotrack", "--out", str(tmp_path / "t2.csv")])
    assert code == 2
