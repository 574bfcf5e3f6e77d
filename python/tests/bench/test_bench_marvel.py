"""Smoke tests of bench/marvel.py and bench/sensing_bench.py: one short point each, every number finite."""

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[3] / "bench"


def _load(name: str, file: str):
    sys.path.insert(0, str(BENCH))  # bench/marvel.py imports its sibling sensing_bench
    try:
        spec = importlib.util.spec_from_file_location(name, BENCH / file)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCH))
    return module


@pytest.fixture(scope="module")
def marvel_bench():
    return _load("scattertrack_bench_marvel", "marvel.py")


@pytest.fixture(scope="module")
def sensing_bench():
    return _load("scattertrack_bench_sensing", "sensing_bench.py")


def test_fusion_scores_a_short_flight(marvel_bench):
    from scattertrack.sim import load_scenario, simulate

    sim = simulate(load_scenario("marvel-circle-20m") | {"duration_s": 8.0}, seed=1000)
    run = marvel_bench.fuse_and_score(sim)
    assert run["rows"] > 50
    for key in ("mean_3d_m", "mean_aligned_m", "mean_orientation_deg", "controller_error_m", "epoch_p50_ns",
                "revised_mean_3d_m", "revised_mean_orientation_deg"):
        assert math.isfinite(run[key]) and run[key] >= 0.0, key
    assert run["revised_fallbacks"] == 0


def test_sensing_scores_one_iq_point_for_both_methods(sensing_bench):
    run = sensing_bench.score_run(("speed", 3.0, 1000, ("marvel", "ulocate")))
    marvel, ulocate = run["methods"]["marvel"], run["methods"]["ulocate"]
    assert marvel["scored"] > 0 and ulocate["scored"] > 0
    assert np.all(np.isfinite(marvel["snapshot_m"]))
    assert math.isfinite(marvel["revised_mean_3d_m"]) and marvel["revised_mean_3d_m"] >= 0.0
    # The Doppler-blind baseline is measurably worse at 3 m/s (paper Fig. 9).
    assert np.mean(ulocate["snapshot_m"]) > 5.0 * np.mean(marvel["snapshot_m"])


def test_sensing_progress_names_numeric_points_and_flights(sensing_bench, capsys):
    """The progress line of every kind of point (a flight's value is a scenario
    name: formatting it as a number crashed `make bench` after 200 s of runs)."""
    methods = {"marvel": {"snapshot_m": np.array([0.04, 0.06])}}
    sensing_bench._progress(True, {"kind": "speed", "value": 1.5, "seed": 0, "methods": methods}, 0.0)
    sensing_bench._progress(True, {"kind": "flight", "value": "marvel-circle-20m", "seed": 2, "methods": methods}, 0.0)
    err = capsys.readouterr().err
    assert "sensing speed 1.5 seed 0: marvel 0.05 m" in err
    assert "sensing flight marvel-circle-20m seed 2: marvel 0.05 m" in err


def test_the_fusion_block_takes_another_lag(marvel_bench):
    assert marvel_bench.parse_args([]).smoother_lag_s is None
    assert marvel_bench.parse_args(["--smoother-lag-s", "6"]).smoother_lag_s == 6.0
    from scattertrack.sim import load_scenario, simulate

    sim = simulate(load_scenario("marvel-circle-20m") | {"duration_s": 6.0}, seed=1000)
    # No heading hold: it keeps every state of so short a flight in the window, whatever the lag.
    default = marvel_bench.fuse_and_score(sim, heading_hold_sigma_rad=0.0)
    shorter = marvel_bench.fuse_and_score(sim, smoother_lag_s=3.0, heading_hold_sigma_rad=0.0)
    # The same rows; the revised ones see 3 s after each state instead of 6.
    assert default["rows"] == shorter["rows"]
    assert shorter["revised_mean_3d_m"] != default["revised_mean_3d_m"]


def test_a_start_is_scored_on_the_rows_track_writes_and_the_causal_ones(marvel_bench):
    from scattertrack.sim import load_scenario, simulate

    sim = simulate(load_scenario("marvel-liftoff-circle") | {"duration_s": 12.0}, seed=1000)
    run = marvel_bench.score_start(sim.truth, sim.scene, sim.imu, sim.features, after_s=8.0,
                                   controller=sim.details["controller_position_m"])
    for key in ("mean_3d_m", "mean_3d_after_m", "revised_mean_3d_m", "revised_mean_3d_after_m",
                "revised_mean_orientation_deg", "beyond_3_sigma", "revised_beyond_3_sigma",
                "revised_offset_after_m", "first_row_m"):
        assert math.isfinite(run[key]) and run[key] >= 0.0, key
    # Two readings of one run: the revised rows are not the causal ones.
    assert run["revised_mean_3d_m"] != run["mean_3d_m"]
    pooled = marvel_bench._pool([run, run])
    assert pooled["revised_worst_seed_mean_3d_m"] == run["revised_mean_3d_m"]


def test_the_first_rows_error_is_where_it_puts_the_drone(marvel_bench):
    """A row that sees the drone 0.3 m east of where it was (range along x) is 0.3 m off."""
    from types import SimpleNamespace

    truth = SimpleNamespace(time_s=np.array([0.0, 1.0]), position=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    features = SimpleNamespace(time_s=np.array([0.5]), range_m=np.array([10.3]), azimuth_rad=np.array([0.0]),
                               elevation_rad=np.array([0.0]))
    controller = [-10.0, 0.0, 0.5]
    assert marvel_bench.first_row_error(truth, features, controller) == pytest.approx(0.3)
