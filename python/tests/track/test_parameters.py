"""The parameter tables and the method registry, through the bindings."""

import dataclasses
import math

import pytest

from scattertrack import _core, sim
from scattertrack.track import REGISTRY, default_params, make, methods, parameters

# Every name and default before the tables existed (GlacParams /
# TurboTrackParams / MarvelParams / SENSING_DEFAULTS at that commit): they
# must all still be accepted with the same default. New rows may be added.
# Changed on purpose since: init_max_hypotheses 2000 -> 6000 (mod-pi readers
# need about 8x the initial set; docs/notes/glac-noise-adaptation.md).
PREVIOUS_DEFAULTS = {
    "glac": {
        "q": 0.02, "motion": "constant-velocity", "inference": "fast", "likelihood": "innovation",
        "phase_wander_rad": 0.0, "phase_wander_s": 0.5, "init_window_s": 0.3, "init_max_window_s": 1.0,
        "init_position_sigma_m": 0.01, "init_velocity_sigma_m_s": 0.1, "quick_stop": 1e-06, "gate_sigmas": 2.5,
        "max_consecutive_outliers": 8, "reinit_gap_s": 1.0, "region_margin_m": 0.05, "merge_distance_m": 0.002,
        "max_hypotheses": 200000, "manoeuvre_q": 1.0, "model_switch_probability": 0.05, "max_branching_hypotheses": 16,
        "perimeter_threshold_m": 0.06, "residual_threshold_m": 0.015, "interpolation_sigma_m": 0.004,
        "init_max_hypotheses": 6000, "init_max_speed_m_s": 0.6, "init_max_pair_gap_s": 0.3, "phase_noise_rad": None,
    },
    "turbotrack": {
        "particles": 100, "transition_sigma_m": 0.005, "reference_interval_s": 1.0 / 300.0, "resample_threshold": 0.5,
        "perimeter_threshold_m": 0.03, "max_initial_components": 64, "intersection_tolerance_m": 0.02,
        "distance_sigma_m": None, "weight_floor": 0.001, "outlier_chi2": 100.0, "outlier_jump_m": 0.05,
        "max_speed_m_s": 2.0, "max_consecutive_outliers": 30, "reinit_gap_s": 1.0, "region_margin_m": 0.05,
        "history_frames": 3000, "velocity_window_s": 0.1, "seed": 0, "rfind_window_s": 3.0,
        "candidate_min_relative_weight": 0.5, "candidate_max_candidates": 15, "candidate_weight_exponent": 1.0,
        "candidate_likelihood_temper": 1.0, "candidate_weighting": "likelihood", "candidate_min_sigma_m": 0.003,
        "candidate_max_sigma_m": 0.05,
    },
    "marvel": {
        # smoother_lag_s: 6.0 until issue 16 (the per-epoch p99 budget; see MarvelParams).
        "smoother_lag_s": 4.0, "marginalize_every_s": 1.0, "gravity_m_s2": 9.80665, "accel_noise_density": 0.001,
        "gyro_noise_density": 8.7e-05, "accel_bias_random_walk": 0.0001, "gyro_bias_random_walk": 2e-05,
        "accel_bias_sigma": 0.02, "gyro_bias_sigma": 0.002, "integration_sigma": 0.0001, "imu_noise_scale": 1.0,
        "range_sigma_m": 0.5, "angle_sigma_rad": 0.05, "yaw_sigma_rad": 0.15, "use_yaw": True,
        # correlation_distance_m: 0.5 until issue 16 (lift-off sigmas; see MarvelParams).
        "correlation_distance_m": 1.0, "correlation_time_s": 5.0, "multipath": "states", "white_floor_range_m": 0.02,
        "white_floor_angle_rad": 0.002, "range_bias_sigma_m": 0.5, "multipath_white_fraction": 0.5,
        "use_ground": True, "rest_gyro_threshold_rad_s": 0.05, "rest_accel_threshold_m_s2": 0.3,
        "ground_position_sigma_m": 0.02, "ground_velocity_sigma_m_s": 0.01, "ground_rotation_sigma_rad": 0.0001,
        "prior_position_sigma_m": 0.05, "prior_velocity_sigma_m_s": 0.1, "prior_tilt_sigma_rad": 0.05,
        "prior_yaw_sigma_rad": 1.0, "tilt_window_s": 0.5, "use_baro": True, "baro_sigma_m": 0.1,
        "baro_random_walk": 0.02, "baro_window_s": 0.05, "baro_offset_prior_sigma_m": 100.0,
        "gate_probability": 0.999, "min_epoch_interval_s": 0.001, "max_declined_epochs": 5, "robust": None,
        "huber_k": 1.345, "max_speed_m_s": 30.0, "max_controller_range_m": 1000.0, "compute_sigma": True,
        "heading_hold_sigma_rad": 0.2, "heading_hold_max_s": 20.0, "relinearize_threshold": 0.01,
        "relinearize_skip": 10, "factorization": "QR", "extra_iterations": 0, "min_snr_db": -20.0,
        "range_sigma_floor_m": 0.1, "angle_sigma_floor_rad": 0.01, "yaw_sigma_floor_rad": 0.05,
        "doppler_direction": "epoch", "clock_flight_epochs": 20, "clock_settle_m": 0.5, "max_doppler_speed_m_s": 5.0,
        "fringe_consistency_sigmas": math.inf, "consistency_sigmas": True,
    },
}


@pytest.mark.parametrize("method", ["glac", "turbotrack", "marvel"])
def test_every_previous_name_keeps_its_default(method):
    current = default_params(method)
    for name, value in PREVIOUS_DEFAULTS[method].items():
        assert name in current, name
        assert current[name] == value and type(current[name]) is type(value), (name, current[name], value)


def test_the_reference_in_docs_is_generated_from_the_tables():
    committed = parameters.REFERENCE.read_text(encoding="utf-8")
    assert committed == parameters.markdown(), "docs/parameters.md is stale: scattertrack methods --markdown > docs/parameters.md"


def test_every_registered_method_has_a_table_whose_defaults_pass_it():
    assert set(REGISTRY) == set(methods.METHODS) >= {"glac", "turbotrack", "rfind", "marvel", "ulocate"}
    for name, method in REGISTRY.items():
        table = parameters.table(name)
        rows = table.rows()
        assert rows and {"name", "type", "default", "range", "unit", "description"} <= set(rows[0])
        defaults = table.defaults()
        assert table.check(defaults) == defaults, name
        assert method.pipeline in ("cots", "helper", "drone") and method.description
    assert REGISTRY["marvel"].estimator == "python" and REGISTRY["marvel"].input == "features+imu"
    assert REGISTRY["glac"].input == "reads" and REGISTRY["turbotrack"].input == "frames"
    assert methods.WIDEBAND_METHODS == ("turbotrack", "gaussian-pf", "uniform-pf", "ellipse-intersection", "rfind")


def test_unknown_methods_are_errors_naming_the_known_ones():
    for call in (lambda: default_params("nope"), lambda: _core.default_params("nope"), lambda: parameters.table("nope")):
        with pytest.raises(ValueError, match=r"unknown method 'nope' \(known: glac, .*marvel"):
            call()
    with pytest.raises(ValueError, match="estimated in Python"):
        _core.default_params("marvel")


@pytest.mark.parametrize("method", ["glac", "marvel"])
def test_text_is_read_by_type(method):
    name = "manoeuvre_q" if method == "glac" else "use_baro"
    assert parameters.parse("marvel", [("use_baro", "false")]) == {"use_baro": False}
    assert parameters.parse("marvel", [("use_baro", "No"), ("robust", "none"), ("relinearize_skip", "3")]) == {
        "use_baro": False, "robust": None, "relinearize_skip": 3}
    assert parameters.parse("glac", [("manoeuvre_q", "none"), ("max_hypotheses", "500"), ("q", "1e-3")]) == {
        "manoeuvre_q": None, "max_hypotheses": 500, "q": 0.001}
    assert name in parameters.default_params(method)


@pytest.mark.parametrize(
    "method, name, text, fragments",
    [
        ("glac", "max_hypotheses", "-1", ("'max_hypotheses'", "an integer >= 1", "got -1")),
        ("glac", "model_switch_probability", "2", ("[0, 0.5]", "got 2")),
        ("glac", "motion", "zigzag", ("one of constant-velocity, random-walk", "'zigzag'")),
        ("turbotrack", "seed", "-5", ("'seed'", ">= 0")),
        ("marvel", "baro_sigma_m", "abc", ("'baro_sigma_m'", "a float > 0", "'abc'")),
        ("marvel", "use_baro", "maybe", ("'use_baro'", "true or false")),
        ("marvel", "multipath_white_fraction", "1", ("(0, 1)",)),
        ("ulocate", "clock_flight_epochs", "0", ("'clock_flight_epochs'", ">= 1")),
        ("glac", "max_hypothesis", "5", ("unknown parameter 'max_hypothesis' for method 'glac'", "did you mean max_hypotheses")),
    ],
)
def test_bad_values_are_errors_naming_the_parameter(method, name, text, fragments):
    with pytest.raises(ValueError) as error:
        parameters.parse(method, [(name, text)])
    for fragment in fragments:
        assert fragment in str(error.value), (fragment, str(error.value))


def test_typed_values_cross_once_and_are_checked():
    scene = sim.simulate(sim.load_scenario("glac-2d-10cms") | {"duration_s": 0.5}, seed=1).scene
    make("glac", scene, max_hypotheses=500, q=1, manoeuvre_q=None)  # an int for a float is a float
    for bad, fragment in [({"max_hypotheses": -1}, ">= 1"), ({"max_hypotheses": True}, "got true"), ({"q": "abc"}, "'abc'"),
                          ({"gate_sigmas": math.nan}, "a float > 0"), ({"qq": 1.0}, "did you mean q")]:
        with pytest.raises(ValueError, match="parameter") as error:
            make("glac", scene, **bad)
        assert fragment in str(error.value)


def test_marvel_params_read_text_and_check_ranges():
    from scattertrack.fusion import MarvelParams

    assert MarvelParams(use_baro="false").use_baro is False
    assert isinstance(MarvelParams(smoother_lag_s=3).smoother_lag_s, float)
    with pytest.raises(ValueError, match="baro_sigma_m"):
        MarvelParams(baro_sigma_m="abc")
    assert dataclasses.fields(MarvelParams)[0].metadata["parameter"]["unit"] == "s"


def test_a_table_written_outside_rust_is_checked():
    row = {"name": "gain", "kind": "float", "default": 2.0, "range": "[0, 1]", "unit": "", "description": "a fraction"}
    with pytest.raises(ValueError, match="'gain'.*default"):
        _core.ParameterTable("example", [row])
    with pytest.raises(ValueError, match="range"):
        _core.ParameterTable("example", [row | {"range": "between 0 and 1"}])
    table = _core.ParameterTable("example", [row | {"default": 0.5}])
    assert table.parse([("gain", "1")]) == {"gain": 1.0} and table.label == "example"
