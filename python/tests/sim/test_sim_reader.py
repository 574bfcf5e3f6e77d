"""The COTS reader model: schedule, phase model and impairments."""

import numpy as np
import pytest

from scattertrack.io.types import SPEED_OF_LIGHT
from scattertrack.sim import simulate
from scattertrack.sim.cots import PHASE_UNIT_RAD, US_CHANNELS_HZ, quantise_phase
from scattertrack.sim.trajectory import positions_velocities

ANTENNAS = [
    {"id": 1, "position": [0.0, 0.0, 0.0]},
    {"id": 2, "position": [0.0, 0.3, 0.0]},
    {"id": 3, "position": [0.0, 0.8, 0.0]},
    {"id": 4, "position": [0.8, 0.8, 0.0]},
]
CIRCLE = {"kind": "circle", "centre": [0.7, 0.3, 0.0], "radius": 0.25, "speed": 0.4}
ARM = {
    "kind": "pick-and-place",
    "pick": [0.3, 0.2, 0.45],
    "place": [0.7, 0.6, 0.5],
    "lift_m": 0.3,
    "peak_speed": 0.25,
}
QUIET = {  # no noise, no misses, no outliers: the bare phase model
    "noise_profile": "paper",
    "white_noise_rad": 0.0,
    "wander_rad": 0.0,
    "miss_probability": 0.0,
}


def scenario(*, reader_model=None, tags=None, dimensions=3, duration_s=20.0, reader=None, seed=5):
    """A 4-antenna GLAC-like scenario with overridable parts."""
    scene = {"dimensions": dimensions, "antennas": ANTENNAS, "reader": reader or {}}
    if dimensions == 2:
        scene["plane_z"] = 0.0
    return {
        "name": "test",
        "duration_s": duration_s,
        "seed": seed,
        "scene": scene,
        "reader_model": reader_model or {},
        "tags": tags or [{"epc": "E2000A01", "trajectory": CIRCLE}],
    }


def model_phase(sim, include_multipath=False):
    """(phase_sign 4 pi f d / c + offsets) mod P from the ground-truth trajectories and the written scene."""
    reads, scene = sim.reads, sim.scene
    positions = np.empty((len(reads), 3))
    for tag in sim.scenario["tags"]:
        rows = reads.epc == tag["epc"]
        positions[rows], _ = positions_velocities(tag["trajectory"], reads.time_s[rows])
    antennas = np.array([scene.antennas[scene.antenna_index(a)].position for a in reads.antenna])
    distance = np.linalg.norm(positions - antennas, axis=1)
    offsets = np.array([scene.antennas[scene.antenna_index(a)].phase_offset_rad for a in reads.antenna])
    offsets += np.array([scene.channel_offset(f) for f in reads.frequency_hz])
    tag_offsets = sim.details["true_tag_phase_offsets_rad"]
    offsets += np.array([tag_offsets[str(e)] for e in reads.epc])
    phase = scene.reader.phase_sign * 4.0 * np.pi * reads.frequency_hz * distance / SPEED_OF_LIGHT + offsets
    return np.mod(phase, scene.reader.period_rad)


def circular_difference(a, b, period):
    return np.abs((a - b + period / 2.0) % period - period / 2.0)


def test_same_seed_same_output_and_other_seed_differs():
    base = scenario(reader_model={"hopping": True, "outlier_probability": 0.01, "dropout_burst_rate_hz": 0.5})
    first, second = simulate(base), simulate(base)
    for name in ("time_s", "epc", "antenna", "frequency_hz", "phase_rad", "rssi_dbm", "doppler_hz"):
        np.testing.assert_array_equal(getattr(first.reads, name), getattr(second.reads, name))
    np.testing.assert_array_equal(first.truth.position, second.truth.position)
    assert [a.phase_offset_rad for a in first.scene.antennas] == [a.phase_offset_rad for a in second.scene.antennas]
    other = simulate(base, seed=6)
    assert other.seed == 6 and other.scenario["seed"] == 6
    assert len(other.reads) != len(first.reads) or not np.array_equal(other.reads.phase_rad, first.reads.phase_rad)


def test_antennas_take_turns_one_read_each_per_round():
    sim = simulate(scenario(reader_model={"miss_probability": 0.0}))
    antennas = sim.reads.antenna
    start = list(antennas[:4]).index(1)
    sequence = antennas[start:]
    np.testing.assert_array_equal(sequence, np.tile([1, 2, 3, 4], len(sequence) // 4 + 1)[: len(sequence)])
    assert np.all(np.diff(sim.reads.time_s) > 0.0)
    # LLRP time stamps have 1 us resolution.
    np.testing.assert_allclose(sim.reads.time_s * 1e6, np.round(sim.reads.time_s * 1e6), atol=1e-6)


def test_custom_antenna_order_and_rounds_per_antenna():
    sim = simulate(
        scenario(reader_model={"miss_probability": 0.0, "antenna_order": [4, 2], "rounds_per_antenna": 2})
    )
    antennas = sim.reads.antenna
    assert set(antennas) == {2, 4}
    # Two rounds (one tag: two reads) on each antenna before switching.
    runs = np.diff(np.flatnonzero(np.diff(antennas) != 0))
    assert np.all(runs == 2)
    assert antennas[0] == 4


def test_one_tag_gets_about_30_reads_per_second():
    sim = simulate(scenario())
    rate = len(sim.reads) / 20.0
    assert 24.0 <= rate <= 36.0
    assert 28.0 <= rate <= 31.0  # the defaults are tuned to ~29.4/s


def test_five_tags_share_the_read_budget():
    tags = [{"epc": f"E2000A0{i}", "trajectory": ARM | {"time_offset_s": 2.0 * i}} for i in range(1, 6)]
    sim = simulate(scenario(tags=tags, reader_model={"miss_probability": 0.0}))
    counts = {epc: np.sum(sim.reads.epc == epc) for epc in sim.reads.epcs()}
    assert len(counts) == 5
    for count in counts.values():
        rate = count / 20.0
        assert 14.0 <= rate <= 21.0  # 1 / (0.027 + 5 * 0.006) = 17.5 rounds/s
    # Every round reads each tag once on one antenna.
    antennas, epcs = sim.reads.antenna, sim.reads.epc
    first_full_round = next(
        i for i in range(5) if len(set(epcs[i : i + 5])) == 5 and len(set(antennas[i : i + 5])) == 1
    )
    for start in range(first_full_round, len(epcs) - 5, 5):
        assert len(set(epcs[start : start + 5])) == 5
        assert len(set(antennas[start : start + 5])) == 1


@pytest.mark.parametrize("sign", [1, -1])
@pytest.mark.parametrize("period", ["2pi", "pi"])
@pytest.mark.parametrize("hopping", [False, True])
def test_phase_follows_the_model_to_quantisation(sign, period, hopping):
    sim = simulate(
        scenario(
            reader={"phase_sign": sign, "phase_period": period},
            reader_model=QUIET | {"hopping": hopping, "tag_phase_offset_rad": "random"},
            duration_s=5.0,
        )
    )
    period_rad = sim.scene.reader.period_rad
    assert np.all(sim.reads.phase_rad >= 0.0) and np.all(sim.reads.phase_rad < period_rad)
    error = circular_difference(sim.reads.phase_rad, model_phase(sim), period_rad)
    assert error.max() <= PHASE_UNIT_RAD / 2.0 + 1e-9
    # Reported values are whole phase units.
    units = sim.reads.phase_rad / PHASE_UNIT_RAD
    np.testing.assert_allclose(units, np.round(units), atol=1e-9)


def test_mod_pi_reader_reports_values_in_zero_to_pi():
    sim = simulate(scenario(reader={"phase_period": "pi"}))
    assert sim.scene.reader.phase_period == "pi"
    assert sim.reads.phase_rad.min() >= 0.0 and sim.reads.phase_rad.max() < np.pi
    assert sim.reads.phase_rad.max() > 3.0  # the whole range is used


def test_coarse_quantisation_steps():
    sim = simulate(scenario(reader_model={"phase_step_units": 4}, duration_s=3.0))
    units = sim.reads.phase_rad / (4 * PHASE_UNIT_RAD)
    np.testing.assert_allclose(units, np.round(units), atol=1e-9)
    assert quantise_phase(np.array([2.0 * np.pi - 1e-12, -1e-12]), 2.0 * np.pi, 1).tolist() == [0.0, 0.0]
    assert quantise_phase(np.array([-1e-300]), np.pi, 0)[0] < np.pi


def test_hopping_uses_the_50_us_channels_and_writes_their_offsets():
    sim = simulate(scenario(reader_model={"hopping": True}))
    frequencies = np.unique(sim.reads.frequency_hz)
    np.testing.assert_allclose(frequencies, US_CHANNELS_HZ)
    written = {c.frequency_hz: c.phase_offset_rad for c in sim.scene.channel_offsets}
    assert len(written) == 50
    true = sim.details["true_channel_phase_offsets_rad"]
    for frequency, offset in written.items():
        assert offset == pytest.approx(true[frequency], abs=1e-12)
    # The channel stays put for a dwell time: at most one change within any 0.2 s.
    changes = sim.reads.time_s[1:][np.diff(sim.reads.frequency_hz) != 0]
    assert np.all(np.diff(changes) > 0.2 - 0.07)
    assert 80 <= len(changes) <= 101


def test_channel_offsets_can_be_omitted_or_carry_calibration_error():
    omitted = simulate(scenario(reader_model={"hopping": True, "write_channel_offsets": False}))
    assert omitted.scene.channel_offsets == []
    noisy = simulate(
        scenario(
            reader_model={
                "hopping": True,
                "channel_offset_calibration_error_rad": 0.1,
                "antenna_offset_calibration_error_rad": 0.1,
            }
        )
    )
    true = noisy.details["true_channel_phase_offsets_rad"]
    error = [
        circular_difference(c.phase_offset_rad, true[c.frequency_hz], 2 * np.pi) for c in noisy.scene.channel_offsets
    ]
    assert 0.05 < np.sqrt(np.mean(np.square(error))) < 0.15


def test_fixed_channel_writes_no_channel_offsets():
    sim = simulate(scenario(reader_model={"frequency_hz": 920.25e6}, duration_s=2.0))
    assert np.all(sim.reads.frequency_hz == 920.25e6)
    assert sim.scene.channel_offsets == []


def test_truth_is_sampled_at_200_hz_with_velocities():
    tags = [{"epc": "E2000A01", "trajectory": CIRCLE}, {"epc": "E2000A02", "trajectory": ARM}]
    sim = simulate(scenario(tags=tags, duration_s=3.0))
    for epc in ("E2000A01", "E2000A02"):
        rows = sim.truth.epc == epc
        times = sim.truth.time_s[rows]
        assert times[0] == 0.0 and times[-1] == pytest.approx(3.0)
        np.testing.assert_allclose(np.diff(times), 0.005)
        assert np.all(np.isfinite(sim.truth.velocity[rows]))


def test_multipath_matches_the_two_path_formula():
    static = {"kind": "static", "position": [0.5, 0.4, 0.6]}
    wall = {"kind": "plane", "point": [1.2, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0], "coefficient": 0.5}
    base = scenario(
        reader_model=QUIET | {"phase_step_units": 0}, tags=[{"epc": "AB", "trajectory": static}], duration_s=2.0
    )
    clean = simulate(base)
    with_wall = simulate(base | {"reader_model": base["reader_model"] | {"reflectors": [wall]}})
    np.testing.assert_array_equal(clean.reads.time_s, with_wall.reads.time_s)
    tag = np.array(static["position"])
    for antenna in clean.scene.antennas:
        rows = clean.reads.antenna == antenna.id
        direct = np.linalg.norm(tag - antenna.position)
        image = antenna.position.copy()
        image[0] = 2.4 - image[0]
        reflected = np.linalg.norm(tag - image)
        wavenumber = 2.0 * np.pi * 915.25e6 / SPEED_OF_LIGHT
        one_way = 1.0 + 0.5 * direct / reflected * np.exp(-1j * wavenumber * (reflected - direct))
        excess = -np.angle(one_way**2)  # extra delay of the round trip, rad
        shift = with_wall.reads.phase_rad[rows] - clean.reads.phase_rad[rows]
        np.testing.assert_allclose(circular_difference(shift, excess, 2 * np.pi), 0.0, atol=1e-9)
        assert abs(excess) > 0.01  # the wall matters at this distance
        # RSSI changes by the two-path amplitude (rssi noise is drawn identically).
        gain = 20.0 * np.log10(np.abs(one_way) ** 2)
        difference = with_wall.reads.rssi_dbm[rows] - clean.reads.rssi_dbm[rows]
        assert np.all(np.abs(difference - gain) <= 0.5 + 1e-9)


def test_plane_reflector_needs_both_ends_on_its_side_and_point_scatterer_counts():
    static = {"kind": "static", "position": [0.5, 0.4, 0.6]}
    base = scenario(reader_model=QUIET, tags=[{"epc": "AB", "trajectory": static}], duration_s=2.0)
    clean = simulate(base)
    # A ceiling at z = 0.7 facing down: the antennas (z = 0) are below it, a
    # tag at z = 0.8 above it, so there is no reflected path.
    ceiling = {"kind": "plane", "point": [0.0, 0.0, 0.7], "normal": [0.0, 0.0, 1.0], "coefficient": 0.9}
    above = scenario(
        reader_model=QUIET | {"reflectors": [ceiling]},
        tags=[{"epc": "AB", "trajectory": {"kind": "static", "position": [0.5, 0.4, 0.8]}}],
        duration_s=2.0,
    )
    above_clean = simulate(above | {"reader_model": QUIET})
    np.testing.assert_array_equal(simulate(above).reads.phase_rad, above_clean.reads.phase_rad)
    # Below the ceiling (z = 0.6) the reflection is there.
    below = simulate(base | {"reader_model": QUIET | {"reflectors": [ceiling]}})
    assert np.max(circular_difference(below.reads.phase_rad, clean.reads.phase_rad, 2 * np.pi)) > 0.05
    scatterer = {"kind": "point", "position": [0.6, 0.6, 0.3], "coefficient": 0.5}
    scattered = simulate(base | {"reader_model": QUIET | {"reflectors": [scatterer]}})
    assert np.max(circular_difference(scattered.reads.phase_rad, clean.reads.phase_rad, 2 * np.pi)) > 0.05


def test_outlier_fraction_is_as_configured():
    sim = simulate(scenario(reader_model=QUIET | {"outlier_probability": 0.2}, duration_s=20.0))
    error = circular_difference(sim.reads.phase_rad, model_phase(sim), 2 * np.pi)
    fraction = np.mean(error > 3 * PHASE_UNIT_RAD)
    n = len(sim.reads)
    assert abs(fraction - 0.2) < 4 * np.sqrt(0.2 * 0.8 / n)
    assert sim.details["counts"]["outliers"] == pytest.approx(0.2 * n, rel=0.25)


def test_white_noise_and_wander_have_the_configured_size():
    static = {"kind": "static", "position": [0.5, 0.4, 0.6]}
    tags = [{"epc": "AB", "trajectory": static}]
    white = simulate(
        scenario(reader_model=QUIET | {"white_noise_rad": 0.1, "phase_step_units": 0}, tags=tags, duration_s=30.0)
    )
    residual = (white.reads.phase_rad - model_phase(white) + np.pi) % (2 * np.pi) - np.pi
    assert np.std(residual) == pytest.approx(0.1, rel=0.1)
    measured = simulate(
        scenario(
            reader_model={"noise_profile": "measured", "miss_probability": 0.0, "phase_step_units": 0},
            tags=tags,
            duration_s=60.0,
            seed=9,
        )
    )
    assert measured.scenario["reader_model"]["white_noise_rad"] == 0.015
    assert measured.scenario["reader_model"]["wander_rad"] == 0.07
    residual = (measured.reads.phase_rad - model_phase(measured) + np.pi) % (2 * np.pi) - np.pi
    for antenna in (1, 2, 3, 4):
        series = residual[measured.reads.antenna == antenna]
        # Read-to-read steps (~0.13 s apart) are small; the wander is larger.
        steps = np.diff(series)
        assert np.std(steps) < 0.06
        assert 0.035 < np.std(series) < 0.12


def test_misses_and_dropout_bursts_remove_reads():
    full = simulate(scenario(reader_model={"miss_probability": 0.0}))
    missed = simulate(scenario(reader_model={"miss_probability": 0.3}))
    assert len(missed.reads) / len(full.reads) == pytest.approx(0.7, abs=0.05)
    bursts = simulate(
        scenario(reader_model={"miss_probability": 0.0, "dropout_burst_rate_hz": 0.5, "dropout_burst_mean_s": 1.0})
    )
    gaps = np.diff(bursts.reads.time_s)
    assert gaps.max() > 0.5 and len(bursts.reads) < 0.9 * len(full.reads)
    link = simulate(
        scenario(
            reader_model={
                "miss_probability": 0.0,
                "dropout_burst_rate_hz": 0.5,
                "dropout_burst_mean_s": 1.0,
                "dropout_burst_scope": "link",
            }
        )
    )
    # A link burst silences one antenna while the others still read the tag.
    times = link.reads.time_s[link.reads.antenna == 1]
    longest = np.argmax(np.diff(times))
    begin, end = times[longest], times[longest + 1]
    assert end - begin > 0.5
    others = link.reads.time_s[link.reads.antenna != 1]
    assert np.sum((others > begin) & (others < end)) > 3


def test_a_dropout_window_removes_every_read_inside_it_and_no_other():
    full = simulate(scenario(reader_model={"miss_probability": 0.0}))
    cut = simulate(scenario(reader_model={"miss_probability": 0.0, "dropout_windows": [[5.0, 15.0]]}))
    inside = (full.reads.time_s >= 5.0) & (full.reads.time_s < 15.0)
    assert inside.sum() > 200
    assert not np.any((cut.reads.time_s >= 5.0) & (cut.reads.time_s < 15.0))
    # The same schedule outside the window (the noise draws follow the read count).
    np.testing.assert_array_equal(cut.reads.time_s, full.reads.time_s[~inside])


@pytest.mark.parametrize("windows", [[[5.0]], [[3.0, 2.0]], [[-1.0, 2.0]], "5-15"])
def test_a_malformed_dropout_window_is_refused(windows):
    from scattertrack.io.types import FormatError

    with pytest.raises(FormatError, match="dropout_windows"):
        simulate(scenario(reader_model={"dropout_windows": windows}))


def test_doppler_sign_and_rssi_trend():
    # Moving straight away from antenna 1 along its line of sight.
    away = {"kind": "line", "start": [0.3, 0.3, 0.3], "direction": [1.0, 1.0, 1.0], "speed": 0.5}
    sim = simulate(
        scenario(
            reader_model=QUIET
            | {"doppler_noise_hz": 0.0, "doppler_step_hz": 0.0, "rssi_noise_db": 0.0, "antenna_order": [1]},
            tags=[{"epc": "AB", "trajectory": away}],
            duration_s=2.0,
        )
    )
    expected = -2.0 * 0.5 * 915.25e6 / SPEED_OF_LIGHT  # receding: negative
    np.testing.assert_allclose(sim.reads.doppler_hz, expected, rtol=1e-9)
    assert np.all(np.diff(sim.reads.rssi_dbm) <= 0.0)  # further away, weaker
    distance = np.linalg.norm(np.array([0.3, 0.3, 0.3])) + 0.5 * sim.reads.time_s
    slope = np.polyfit(np.log10(distance), sim.reads.rssi_dbm, 1)[0]
    assert slope == pytest.approx(-40.0, abs=1.5)
