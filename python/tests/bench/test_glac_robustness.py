"""bench/glac_robustness.py: each condition simulates what it says, the
beyond-3-sigma and gap figures count what they say, and the block runs end
to end (two seeds) into a table and a JSON file, outside cases included."""

import importlib.util
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from scattertrack.io.types import Track, Truth
from scattertrack.sim import simulate, write_simulation

BENCH = Path(__file__).resolve().parents[3] / "bench"


@pytest.fixture(scope="module")
def robustness():
    spec = importlib.util.spec_from_file_location("scattertrack_bench_robustness", BENCH / "glac_robustness.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # the worker processes find run_one through it
    spec.loader.exec_module(module)
    return module


def _sim(robustness, condition, layout="walls"):
    return simulate(robustness.cell_scenario(layout, condition), seed=1)


def test_each_condition_simulates_its_impairment(robustness):
    base = _sim(robustness, "baseline")
    assert len(np.unique(base.reads.frequency_hz)) == 1 and base.scene.reader.phase_period == "2pi"
    assert len(np.unique(_sim(robustness, "hopping").reads.frequency_hz)) == 50
    assert len(_sim(robustness, "hopping").scene.channel_offsets) == 50
    mod_pi = _sim(robustness, "mod-pi")
    assert mod_pi.scene.reader.phase_period == "pi" and mod_pi.reads.phase_rad.max() < np.pi
    assert len(_sim(robustness, "5-tags").reads.epcs()) == 5
    dropout = _sim(robustness, "dropout-10s")
    t = dropout.reads.time_s
    assert not np.any((t >= 5.0) & (t < 15.0)) and np.any(t >= 15.0) and np.any(t < 5.0)
    multipath = _sim(robustness, "multipath")
    assert multipath.scene.reader.phase_sign == -1
    assert multipath.scenario["reader_model"]["reflectors"][0]["coefficient"] == 0.3
    assert multipath.details["counts"]["outliers"] > 0
    base_speed = np.linalg.norm(base.truth.velocity, axis=1).max()
    fast_speed = np.linalg.norm(_sim(robustness, "50cms").truth.velocity, axis=1).max()
    assert fast_speed == pytest.approx(2.0 * base_speed, rel=1e-3) and fast_speed == pytest.approx(0.5, rel=1e-3)


def test_the_stop_is_8_s_at_rest_from_a_pause_with_reads_going_on(robustness):
    sim = _sim(robustness, "stop-8s")
    trajectory = sim.scenario["tags"][0]["trajectory"]
    start = trajectory["hold_at_s"]
    assert 6.0 <= start < 9.0
    speed = np.linalg.norm(sim.truth.velocity, axis=1)
    during = (sim.truth.time_s >= start) & (sim.truth.time_s < start + 8.0)
    assert np.all(speed[during] == 0.0)
    # It stops as a move ends (minimum jerk: slowing to 0) and moves again
    # soon after: no jump in velocity.
    just_before = (sim.truth.time_s > start - 0.02) & (sim.truth.time_s < start)
    assert just_before.any() and speed[just_before].max() < 1e-3
    after = (sim.truth.time_s > start + 8.0) & (sim.truth.time_s < start + 9.0)
    assert speed[after].max() > 0.1
    reads = sim.reads.time_s
    assert np.sum((reads >= start) & (reads < start + 8.0)) > 8.0 * 20.0


def test_beyond_three_sigma_counts_rows_from_2_s_on_any_axis(robustness):
    times = np.arange(0.0, 4.0, 0.5)  # 8 rows, 4 of them from 2 s on
    truth = Truth(times, np.full(8, "E1"), np.zeros((8, 3)), np.zeros((8, 3)))
    position = np.zeros((8, 3))
    position[:, 2] = 0.02  # 2 cm off in z everywhere
    sigma = np.full((8, 3), 0.01)
    sigma[5, 2] = 0.001  # row at 2.5 s: 20 sigma in z
    sigma[6, 2] = 0.006  # row at 3.0 s: 3.3 sigma in z
    track = Track(times, np.full(8, "E1"), position, np.zeros((8, 3)), sigma=sigma)
    assert robustness.beyond_three_sigma(truth, track) == (4, 2)
    assert robustness.beyond_three_sigma(truth, track, from_s=0.0) == (8, 2)


def test_beyond_three_sigma_counts_each_tag_against_its_own_truth(robustness):
    # bench/turbotrack.py scores its accuracy block with it too (3-tags).
    truth = Truth(
        np.array([0.0, 1.0, 0.0, 1.0]),
        np.array(["A", "A", "B", "B"]),
        np.array([[0.0, 0, 0], [1.0, 0, 0], [5.0, 0, 0], [5.0, 0, 0]]),
        np.full((4, 3), np.nan),
    )
    track = Track(
        np.array([0.5, 0.5, 0.75]),
        np.array(["A", "B", "B"]),
        np.array([[0.5, 0.0, 0.0], [5.0, 0.0, 0.1], [5.0, 0.0, 0.0]]),
        np.full((3, 3), np.nan),
        sigma=np.full((3, 3), 0.01),
    )
    # A on its truth; B once 10 sigma off in z, once on it; from 0.6 s on one row is left.
    assert robustness.beyond_three_sigma(truth, track, from_s=0.0) == (3, 1)
    assert robustness.beyond_three_sigma(truth, track, from_s=0.6) == (1, 0)


def test_the_largest_gap_leaves_out_read_outages(robustness):
    reads = np.r_[np.arange(0.0, 12.0, 0.03), np.arange(18.0, 20.0, 0.03)]
    # Estimates at every read, except none for the first second after the outage.
    estimates = reads[(reads < 12.0) | (reads >= 19.0)]
    assert robustness.largest_estimate_gap_s(estimates, reads) == pytest.approx(1.0, abs=0.04)
    # A tracker silent for 0.6 s while reads come in.
    silent = reads[(reads < 5.0) | (reads >= 5.6)]
    assert robustness.largest_estimate_gap_s(silent, reads) == pytest.approx(0.63, abs=0.02)


def test_the_wall_calibration_sweeps_a_reference_in_the_same_room(robustness):
    calibration = robustness.wall_calibration
    scenario = robustness.cell_scenario("bay", "multipath")
    scenario["reader_model"]["dropout_windows"] = [[5.0, 15.0]]
    sweep = calibration.calibration_scenario(scenario)
    (wall,) = scenario["reader_model"]["reflectors"]
    (declared,) = sweep["scene"]["reflectors"]
    # Declared 4 cm nearer the antennas (along the normal), with a rough coefficient of the right sign.
    assert np.allclose(np.asarray(declared["point"]) - np.asarray(wall["point"]), [-calibration.DECLARED_OFFSET_M, 0.0, 0.0])
    assert declared["coefficient"] == calibration.DECLARED_COEFFICIENT * np.sign(wall["coefficient"])
    assert sweep["reader_model"]["reflectors"] == scenario["reader_model"]["reflectors"] and "dropout_windows" not in sweep["reader_model"]
    assert [t["trajectory"]["kind"] for t in sweep["tags"]] == ["random"] and sweep["duration_s"] == calibration.SWEEP_S
    assert sweep["scene"]["antennas"] == scenario["scene"]["antennas"] and "reflectors" not in scenario["scene"]


def test_the_block_runs_into_a_table_and_json(robustness, tmp_path, capsys):
    outside = tmp_path / "outside"
    sim = simulate(robustness.cell_scenario("workcell", "baseline", duration_s=4.0), seed=3)
    write_simulation(sim, outside / "cots-simulated")
    # A scene the reader rejects: reported by its error line, not tracked.
    shutil.copytree(outside / "cots-simulated", outside / "cots-broken")
    scene = outside / "cots-broken" / "scene.toml"
    scene.write_text(scene.read_text().replace("dimensions = 3", "dimensions = 7"))
    out = tmp_path / "result.json"
    args = ["--seeds", "2", "--layouts", "walls", "--conditions", "baseline,dropout-10s,multipath-calibrated", "--duration", "16"]
    assert robustness.main(args + ["--outside", str(outside), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "seeds 0..1 (2 per cell)" in text and f"scattertrack {robustness.scattertrack.__version__}" in text
    assert "walls / baseline" in text and "walls / dropout-10s" in text and "walls / multipath-calibrated" in text
    assert "realistic-3d-arm (defaults, the wall unknown), 2 runs" in text
    assert "realistic-3d-arm (defaults, the wall calibrated), 2 runs" in text and "walls kept 2 of 2" in text
    assert "Layouts meeting every target of every condition run (multipath: the wall calibrated): " in text
    assert "cots-broken: rejected: " in text and "dimensions" in text
    assert "cots-simulated: median 3D" in text
    result = json.loads(out.read_text())
    assert [(c["layout"], c["condition"], c["runs"]) for c in result["cells"]] == [
        ("walls", "baseline", 2),
        ("walls", "dropout-10s", 2),
        ("walls", "multipath-calibrated", 2),
    ]
    for cell in result["cells"]:
        assert 0.0 <= cell["candidate_wins_within_1s"] <= 1.0 and 0.0 <= cell["beyond_3_sigma"] <= 1.0
        assert cell["median_3d_mm"] > 0.0 and set(cell["meets"]) == {"wins_within_1s", "median", "beyond_3_sigma"}
    # The issue sets the wins-within-1-s target on the baseline only.
    assert result["cells"][0]["meets"]["wins_within_1s"] in (True, False)
    assert result["cells"][1]["meets"]["wins_within_1s"] is None
    assert "Baseline cells meeting every target: " in text
    assert result["cells"][0]["back_within_1s_of_resume"] is None  # only the stop and the dropout have one
    assert result["realistic_3d_arm"]["runs"] == 2 and result["realistic_3d_arm"]["calibrated_wall"]["walls_kept"] == 2
    low, high = result["cells"][2]["wall_x_range_m"]
    assert 1.595 < low <= high < 1.605  # the calibrated wall, where the simulator put it
    simulated = next(c for c in result["outside"] if c["case"] == "cots-simulated")
    assert simulated["median_3d_mm"] > 0.0 and simulated["largest_gap_s"] > 0.0 and simulated["warnings"] >= 0
    assert "error" in next(c for c in result["outside"] if c["case"] == "cots-broken")


def test_unknown_names_are_refused(robustness):
    with pytest.raises(SystemExit, match="unknown condition"):
        robustness.main(["--seeds", "1", "--conditions", "earthquake"])


def test_wide_sigma_counts_right_rows_whose_sigma_is_decimetres(robustness):
    times = np.arange(0.0, 4.0, 0.5)  # 8 rows, 4 of them from 2 s on
    truth = Truth(times, np.full(8, "E1"), np.zeros((8, 3)), np.zeros((8, 3)))
    position = np.zeros((8, 3))
    position[4, 0] = 0.5  # row at 2.0 s: wrong by 50 cm (not a right row)
    sigma = np.full((8, 3), 0.005)
    sigma[4] = 0.3
    sigma[5] = 0.1  # row at 2.5 s: right, 17 cm of 3D sigma
    sigma[0] = 0.2  # before 2 s: not counted
    track = Track(times, np.full(8, "E1"), position, np.zeros((8, 3)), sigma=sigma)
    assert robustness.wide_sigma(truth, track) == (3, 1)
