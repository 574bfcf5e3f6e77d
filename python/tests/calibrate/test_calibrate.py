"""Calibration from reference tags (scattertrack.calibrate) on simulated rooms
whose offsets, sign, period and hop table the calibration is not told."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scattertrack import track
from scattertrack.calibrate import calibrate
from scattertrack.calibrate.hop_table import assign_carriers
from scattertrack.calibrate.path_loss import fit_path_loss
from scattertrack.calibrate.phase import fit_offsets, looks_mod_pi
from scattertrack.eval import compare
from scattertrack.readers.emulator import shuffled_hop_table

from calibration_rooms import FAR, NEAR, reference_epcs, room, uncalibrated


def offset_sum_errors(calibration, true_scene) -> np.ndarray:
    """Per antenna and channel: estimated minus true offset sum, wrapped, rad."""
    errors = []
    for antenna in true_scene.antennas:
        for channel in true_scene.channel_offsets:
            truth = antenna.phase_offset_rad + channel.phase_offset_rad
            estimate = calibration.antenna_offsets_rad[antenna.id] + calibration.channel_offsets_rad[channel.frequency_hz]
            errors.append(np.angle(np.exp(1j * (estimate - truth))))
    return np.array(errors)


def test_offset_sums_and_sign_from_four_references(near_room):
    sim = near_room
    result = calibrate(uncalibrated(sim.scene), sim.reads, reference_epcs(NEAR))
    assert result.phase_sign == sim.scene.reader.phase_sign and result.phase_period == "2pi"
    errors = offset_sum_errors(result, sim.scene)
    assert errors.size == 4 * 50 and np.abs(errors).max() < 0.05
    assert result.phase_usable and result.coherence > 0.95 > 5 * result.chance
    assert all(0.08 < r < 0.12 for r in result.residual_rad.values())  # the 0.1 rad noise, not more
    assert not result.warnings


def test_the_calibrated_scene_tracks_like_the_true_one():
    sim = room(40.0, NEAR, seed=6, moving=True)
    result = calibrate(uncalibrated(sim.scene), sim.reads, reference_epcs(NEAR))
    mover = sim.reads.select(sim.reads.epc == "E2000A01")
    medians = [compare(sim.truth, track.run("glac", scene, mover)).overall.median_3d_m for scene in (sim.scene, result.scene())]
    assert medians[1] < 1.5 * medians[0]


def test_a_mod_pi_reader_is_recognised(near_room):
    sim = near_room
    scene = dataclasses.replace(sim.scene, reader=dataclasses.replace(sim.scene.reader, phase_period="pi"))
    reads = dataclasses.replace(sim.reads, phase_rad=np.mod(sim.reads.phase_rad, np.pi))
    result = calibrate(uncalibrated(scene), reads, reference_epcs(NEAR))
    assert result.phase_period == "pi" and result.phase_sign == sim.scene.reader.phase_sign
    errors = offset_sum_errors(result, sim.scene)
    # Mod pi the sums are known mod pi.
    assert np.abs(np.angle(np.exp(2j * errors)) / 2).max() < 0.05
    assert all(0.0 <= o < np.pi for o in result.antenna_offsets_rad.values())


def test_the_hop_table_is_recovered_from_references_spread_over_metres():
    sim = room(120.0, FAR, seed=8)
    table = shuffled_hop_table(7)
    index_of = {khz: i for i, khz in enumerate(table, start=1)}
    channel_index = np.array([index_of[round(f / 1e3)] for f in sim.reads.frequency_hz])
    # As an importer without the table writes them: the plan in index order.
    reads = dataclasses.replace(sim.reads, frequency_hz=902.75e6 + 0.5e6 * (channel_index - 1), channel_index=channel_index)
    result = calibrate(uncalibrated(sim.scene), reads, reference_epcs(FAR))
    assert {i: f for i, f in result.hop_table_hz.items()} == {i: 1e3 * table[i - 1] for i in range(1, 51)}
    assert result.scene().hop_table[1] == 1e3 * table[0]


def test_references_bunched_together_leave_channels_open_and_say_so(near_room):
    sim = room(20.0, [[0.5, 0.5, 0.5], [0.7, 0.6, 0.6]], seed=9)
    channel_index = np.rint((sim.reads.frequency_hz - 902.75e6) / 0.5e6).astype(int) + 1
    reads = dataclasses.replace(sim.reads, channel_index=channel_index)
    result = calibrate(uncalibrated(sim.scene), reads, reference_epcs([[0.5, 0.5, 0.5], [0.7, 0.6, 0.6]]))
    assert any("cannot tell" in w and "channel indices" in w for w in result.warnings)


def test_random_phases_are_not_usable_and_say_so(near_room):
    sim = near_room
    rng = np.random.default_rng(1)
    reads = dataclasses.replace(sim.reads, phase_rad=rng.uniform(0, 2 * np.pi, len(sim.reads)))
    result = calibrate(uncalibrated(sim.scene), reads, reference_epcs(NEAR))
    assert not result.phase_usable and result.table()["phase_usable"] is False
    assert any(w.startswith("phase is not usable in this room") for w in result.warnings)


def test_path_loss_recovers_the_simulated_exponent(near_room):
    result = calibrate(uncalibrated(near_room.scene), near_room.reads, reference_epcs(NEAR))
    for loss in result.path_loss.values():
        assert loss.fitted_exponent and abs(loss.exponent - 4.0) < 0.1 and 0.8 < loss.sigma_db < 1.3


def test_one_distance_keeps_the_free_space_exponent():
    loss = fit_path_loss(np.array([-50.0, -51.0, -49.0, -50.5]), np.full(4, 2.0))
    assert not loss.fitted_exponent and loss.exponent == 4.0
    assert loss.reference_dbm == pytest.approx(-50.125 + 40 * np.log10(2.0))
    assert fit_path_loss(np.array([np.nan, np.nan]), np.array([1.0, 2.0])) is None


def test_offset_fit_is_exact_on_noiseless_sums():
    rng = np.random.default_rng(3)
    antenna, channel, tag = rng.integers(0, 3, 400), rng.integers(0, 5, 400), rng.integers(0, 2, 400)
    theta_a, theta_c, theta_t = rng.uniform(-3, 3, 3), rng.uniform(-3, 3, 5), np.array([0.0, 1.2])
    fit = fit_offsets(theta_a[antenna] + theta_c[channel] + theta_t[tag], antenna, channel, tag, (3, 5, 2))
    assert fit.coherence == pytest.approx(1.0)
    sums = np.angle(np.exp(1j * (fit.antenna[antenna] + fit.channel[channel] + fit.tag[tag] - (theta_a[antenna] + theta_c[channel] + theta_t[tag]))))
    assert np.abs(sums).max() < 1e-9 and abs(fit.tag[1] - 1.2) < 1e-9


def test_mod_pi_needs_enough_reads():
    assert looks_mod_pi(np.full(60, 1.0)) and not looks_mod_pi(np.full(10, 1.0))
    assert not looks_mod_pi(np.r_[np.full(59, 1.0), 4.0])


def test_carriers_are_assigned_one_to_one():
    distance = np.repeat([1.0, 3.0, 5.0], 40)
    channel = np.tile(np.arange(2), 60)
    truth = np.array([915.25e6, 903.25e6])
    phase = np.mod(4 * np.pi * truth[channel] * distance / 299792458.0 + np.array([0.3, 2.0])[channel], 2 * np.pi)
    fit = assign_carriers(phase, distance, channel, 2, np.zeros(len(phase)), 1, 1, 902.75e6 + 0.5e6 * np.arange(50))
    assert fit.frequency_hz.tolist() == truth.tolist() and np.all(fit.margin > 0)
