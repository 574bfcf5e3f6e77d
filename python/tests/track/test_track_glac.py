"""GLAC through the Python API on simulated data: accuracy, variants,
several tags, declined reads, consistency, errors.

Seeds 7000+ are used here; the benchmark scores seeds 0..N-1 and the
defaults were chosen on seeds 1000+, so no test reuses scoring data.
"""

import numpy as np
import pytest

from scattertrack.eval import compare
from scattertrack.sim import load_scenario, simulate
from scattertrack.track import METHODS, default_params, make, run


def _sim(name, seed, duration=8.0):
    return simulate(load_scenario(name) | {"duration_s": duration}, seed=seed)


def _errors_after(sim, track, start_s):
    truth = sim.truth
    keep = track.time_s > start_s
    true = np.stack([np.interp(track.time_s, truth.time_s, truth.position[:, k]) for k in range(3)], axis=1)
    return np.linalg.norm(track.position - true, axis=1)[keep], (track.position - true)[keep]


@pytest.mark.parametrize(
    "scenario",
    ["glac-2d-10cms", "glac-2d-40cms", "glac-2d-40cms-hopping", "glac-2d-40cms-negsign", "glac-2d-40cms-modpi"],
)
def test_2d_millimetre_accuracy(scenario):
    sim = _sim(scenario, 7001)
    track = run("glac", sim.scene, sim.reads)
    report = compare(sim.truth, track, convergence_threshold_m=0.05)
    assert report.overall.median_3d_m < 0.01
    errors, _ = _errors_after(sim, track, 2.0)
    assert np.percentile(errors, 90) < 0.025


def test_3d_arm_accuracy_and_velocity():
    sim = _sim("glac-3d-arm", 7002, duration=10.0)
    track = run("glac", sim.scene, sim.reads)
    errors, _ = _errors_after(sim, track, 3.0)
    assert np.median(errors) < 0.012
    report = compare(sim.truth, track, skip_first_s=3.0)
    assert report.overall.median_velocity_m_s < 0.06


def test_estimates_are_causal_and_time_ordered():
    sim = _sim("glac-2d-10cms", 7003, duration=3.0)
    track = run("glac", sim.scene, sim.reads)
    assert np.all(np.diff(track.time_s) >= 0)
    # Every estimate is stamped with the time of a read that produced it.
    assert np.isin(track.time_s, sim.reads.time_s).all()
    # Streaming one read at a time gives exactly the batch result.
    tracker = make("glac", sim.scene)
    streamed = [
        tracker.step(t, e, int(a), f, p)
        for t, e, a, f, p in zip(sim.reads.time_s, sim.reads.epc, sim.reads.antenna, sim.reads.frequency_hz, sim.reads.phase_rad)
    ]
    positions = np.array([s.position for s in streamed if s is not None])
    np.testing.assert_array_equal(positions, track.position)


def test_filter_is_consistent_after_convergence():
    """NEES per degree of freedom near 1 (median; IMM makes it a little conservative)."""
    sim = _sim("glac-2d-40cms", 7004, duration=12.0)
    track = run("glac", sim.scene, sim.reads)
    _, error = _errors_after(sim, track, 3.0)
    sigma = track.sigma[track.time_s > 3.0]
    nees = ((error[:, :2] / sigma[:, :2]) ** 2).sum(axis=1) / 2.0
    assert 0.2 < np.median(nees) < 2.0


def test_five_tags_tracked_separately():
    sim = _sim("glac-3d-arm-5tags", 7005, duration=10.0)
    track = run("glac", sim.scene, sim.reads)
    assert set(track.epc) == set(sim.reads.epc)
    report = compare(sim.truth, track, skip_first_s=4.0)
    for metrics in report.per_tag.values():
        assert metrics.median_3d_m < 0.02


@pytest.mark.parametrize("method", ["glac-no-velocity", "glac-sync", "glac-sync-no-velocity", "glac-naive"])
def test_variants_run_and_report(method):
    sim = _sim("glac-2d-10cms", 7006, duration=2.0)
    params = {"max_hypotheses": 20_000} if method == "glac-naive" else {}
    track = run(method, sim.scene, sim.reads, **params)
    assert len(track) > 0
    assert np.isfinite(track.position).all()
    if "no-velocity" in method:
        assert np.isnan(track.velocity).all()
    if method == "glac-naive":
        assert track.stats["E2000A01"]["max_hypotheses"] <= 20_000


def test_outliers_are_counted_not_silent():
    sim = _sim("glac-2d-10cms", 7007, duration=6.0)
    rng = np.random.default_rng(1)
    rows = rng.choice(np.arange(60, len(sim.reads)), size=25, replace=False)
    sim.reads.phase_rad[rows] = (sim.reads.phase_rad[rows] + np.pi) % (2 * np.pi)
    track = run("glac", sim.scene, sim.reads)
    declined = sum(n for reason, n in track.skipped.counts.items() if "outlier" in reason)
    assert declined >= 10
    errors, _ = _errors_after(sim, track, 2.0)
    assert np.median(errors) < 0.01


def test_out_of_order_and_invalid_reads_are_declined_and_counted():
    sim = _sim("glac-2d-10cms", 7008, duration=2.0)
    tracker = make("glac", sim.scene)
    r = sim.reads
    for i in range(len(r)):
        tracker.step(r.time_s[i], r.epc[i], int(r.antenna[i]), r.frequency_hz[i], r.phase_rad[i])
    tracker.step(r.time_s[5], r.epc[5], int(r.antenna[5]), r.frequency_hz[5], r.phase_rad[5])
    tracker.step(r.time_s[-1] + 0.01, r.epc[0], int(r.antenna[0]), float("nan"), 1.0)
    stats = tracker.stats(r.epc[0])
    assert stats["out_of_order"] == 1
    assert stats["invalid"] == 1
    with pytest.raises(ValueError, match="antenna 99"):
        tracker.step(r.time_s[-1] + 0.02, r.epc[0], 99, 915e6, 1.0)


def test_reinitialises_after_a_read_gap():
    sim = _sim("glac-2d-10cms", 7009, duration=8.0)
    keep = (sim.reads.time_s < 3.0) | (sim.reads.time_s > 4.5)
    track = run("glac", sim.scene, sim.reads.select(keep))
    assert track.stats["E2000A01"]["reinitialisations"] >= 1
    errors, _ = _errors_after(sim, track, 5.5)
    assert np.median(errors) < 0.01


def test_unknown_method_and_parameter_are_errors():
    sim = _sim("glac-2d-10cms", 7010, duration=1.0)
    with pytest.raises(ValueError, match="unknown method"):
        run("kalman-magic", sim.scene, sim.reads)
    with pytest.raises(ValueError, match="unknown parameter 'qq' for method 'glac'"):
        run("glac", sim.scene, sim.reads, qq=1.0)
    with pytest.raises(ValueError, match="q"):
        run("glac", sim.scene, sim.reads, q=-1.0)


def test_methods_and_defaults_are_listed():
    assert "glac" in METHODS and "glac-naive" in METHODS
    params = default_params()
    assert params["gate_sigmas"] == 2.5 and params["q"] > 0


def test_paper_likelihood_needs_the_single_model():
    sim = _sim("glac-2d-10cms", 7011, duration=4.0)
    with pytest.raises(ValueError, match="manoeuvre_q"):
        run("glac", sim.scene, sim.reads, likelihood="paper")
    track = run("glac", sim.scene, sim.reads, likelihood="paper", manoeuvre_q=None)
    errors, _ = _errors_after(sim, track, 1.0)
    assert np.median(errors) < 0.01


def test_correlated_phase_error_is_a_parameter():
    params = default_params()
    assert params["phase_wander_rad"] == 0.0 and params["phase_wander_s"] == 0.5
    sim = _sim("realistic-3d-arm", 7012, duration=6.0)
    plain = run("glac", sim.scene, sim.reads)
    told = run("glac", sim.scene, sim.reads, phase_noise_rad=0.015, phase_wander_rad=0.12)
    # Same reads, same rows; the correlated share changes R and so the track.
    assert len(told.time_s) > 0 and not np.allclose(plain.position[: len(told.position)], told.position[: len(plain.position)])
    with pytest.raises(ValueError, match="phase_wander_rad"):
        run("glac", sim.scene, sim.reads, phase_wander_rad=-0.1)
    with pytest.raises(ValueError, match="phase_wander_s"):
        run("glac", sim.scene, sim.reads, phase_wander_s=0.0)
