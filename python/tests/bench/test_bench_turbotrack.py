"""The TurboTrack benchmark harness (bench/turbotrack.py): a smoke run of
every block on one seed and short simulations, and its pooling helper."""

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

from scattertrack.sim import list_scenarios

BENCH = Path(__file__).resolve().parents[3] / "bench"


def _bench_turbotrack():
    """bench/turbotrack.py as a module (under a name that cannot clash)."""
    spec = importlib.util.spec_from_file_location("scattertrack_bench_turbotrack", BENCH / "turbotrack.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


bench = _bench_turbotrack()

ARGV = [
    "--seeds", "1", "--duration-s", "4", "--particles", "10,100", "--throughput-duration-s", "1",
    "--runtime-duration-s", "0.2", "--lobe-starts", "2", "--far-seeds", "2", "--no-progress",
]


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    """One full run of the harness (1 seed, 4 s simulations): (stdout, JSON result)."""
    import contextlib
    import io

    out = tmp_path_factory.mktemp("bench-turbotrack")
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        assert bench.main(ARGV + ["--out", str(out)]) == 0
    result = json.loads((out / "latest.json").read_text())
    assert (out / "latest.md").read_text().startswith("# TurboTrack benchmark")
    return stdout.getvalue(), result


def _finite(*values):
    return all(v is not None and isinstance(v, (int, float)) and math.isfinite(v) for v in values)


def test_every_table_is_printed_under_its_command(smoke):
    text, result = smoke
    for number in (1, 2, 3, 4, 5, 6, 7, 9):
        assert f"\n{number}. " in text
    assert "\n8b. " in text
    # Every table is headed by the command that produced it (8a only where the outside recordings are).
    tables = 9 + (1 if result["lobes"]["outside"] else 0)
    assert text.count(f"$ {result['command']}") == tables
    assert "bench/turbotrack.py" in result["command"] and "--seeds 1" in result["command"]
    assert "\nSummary\n" in text


def test_json_holds_seeds_version_and_commit(smoke):
    _, result = smoke
    assert result["settings"]["seeds"] == [0]
    assert result["settings"]["particle_seeds"] == [0]
    assert result["settings"]["skip_first_s"] == bench.SKIP_FIRST_S
    assert result["environment"]["scattertrack"]
    assert "commit" in result["environment"]["git"]
    assert set(result["settings"]["default_params"]) >= {"turbotrack", "uniform-pf", "rfind"}


def test_accuracy_rows_cover_every_scenario_with_finite_numbers(smoke):
    _, result = smoke
    rows = result["accuracy"]
    assert [r["scenario"] for r in rows] == list_scenarios("turbotrack")
    for r in rows:
        keys = ["median_3d_mm", "p90_3d_mm"] + [f"{q}_{a}_mm" for q in ("median", "p90") for a in "xyz"]
        assert _finite(*(r[k] for k in keys)), r["scenario"]
        assert r["p90_3d_mm"] >= r["median_3d_mm"] > 0
        assert 0.0 <= r["seeds_below_1cm"] <= 1.0
        assert 0.0 <= r["beyond_3sigma"] <= 1.0, r["scenario"]
        assert r["runs"] == 1 and r["rows"] > 0
        assert r["paper_target"] in ("meets", "misses")


def test_static_speed_and_decomposition_tables(smoke):
    _, result = smoke
    assert [r["method"] for r in result["static"]] == list(bench.STATIC_METHODS)
    for r in result["static"]:
        if r["method"] != "rfind":  # rfind waits for a full pooling window before its first estimate
            assert _finite(r["median_cm"], r["p90_cm"]) and r["median_cm"] > 0
            # The calibration floor: a few mm, and every method near it (a tag at rest).
            assert _finite(r["floor_median_cm"], r["floor_p90_cm"], r["above_floor_mm"])
            assert 0 < r["floor_median_cm"] <= r["floor_p90_cm"] < 5
            assert abs(r["above_floor_mm"]) < 3
    speeds = [r["speed_cm_s"] for r in result["speed"]]
    assert len(speeds) == 6 and speeds == sorted(speeds)
    for r in result["speed"]:
        assert _finite(r["turbotrack:p10_cm"], r["turbotrack:median_cm"], r["turbotrack:p90_cm"])
        assert r["turbotrack:p10_cm"] <= r["turbotrack:median_cm"] <= r["turbotrack:p90_cm"]
    assert [r["method"] for r in result["decomposition"]] == list(bench.DECOMPOSITION_METHODS)
    for r in result["decomposition"]:
        assert _finite(r["p10_cm"], r["median_cm"], r["p90_cm"])
        cdf = [r["cdf_mm"][f"p{round(q * 100)}"] for q in bench.QUANTILES]
        assert np.all(np.diff(cdf) >= 0)


def test_particles_and_throughput(smoke):
    _, result = smoke
    assert [r["particles"] for r in result["particles"]] == [10, 100]
    for r in result["particles"]:
        for method in bench.PARTICLE_METHODS:
            assert _finite(r[f"{method}:median_mm"], r[f"{method}:step_ns"])
            assert r[f"{method}:step_ns"] > 0
    t = result["throughput"]
    assert t["receivers"] == 4 and t["frames"] > 0
    assert _finite(t["frames_per_s"], t["step_mean_us"], t["step_max_us"], t["step_p99_us"])
    assert t["step_max_us"] >= t["step_mean_us"] > 0


def test_lobe_block_counts_lock_ins_per_case_and_cell(smoke):
    stdout, result = smoke
    lobes = result["lobes"]
    assert "8b. Lobe lock-in on our simulator" in stdout
    assert [(r["snr_db"], r["motion"], r["layout"]) for r in lobes["sweep"]] == [
        (float(snr), motion, layout) for snr in bench.lobes.QUICK_SNR_DB for motion in ("static", "moving") for layout in ("plus", "inline")
    ]
    for r in lobes["sweep"] + lobes["outside"]:
        assert r["starts"] == 2 and 0 <= r["lock_ins"] <= r["starts"]
        assert _finite(r["median_cm"], r["beyond_3sigma"]) and r["lobe_switches"] >= 0
    if bench.lobes.helper_cases():
        assert "8a. Lobe lock-in on the outside helper recordings" in stdout
        assert {r["case"] for r in lobes["outside"]} >= {"helper-3d-multipath-4db"}


def test_far_static_block_summarises_random_positions(smoke):
    stdout, result = smoke
    assert "9. Static tags at random positions on the in-line layout" in stdout
    (row,) = result["far_static"]
    assert row["runs"] == 2 and 0 <= row["lock_ins"] <= 2 and 0 <= row["runs_beyond_5pct"] <= 2
    assert _finite(row["median_of_medians_cm"], row["worst_median_cm"], row["beyond_3sigma"])
    # The positions are drawn per seed, reproducibly, inside the stated box.
    p = bench.lobes.far_static_position(bench.lobes.FAR_STATIC_FIRST_SEED)
    assert p == bench.lobes.far_static_position(bench.lobes.FAR_STATIC_FIRST_SEED)
    assert all(lo <= v <= hi for v, (lo, hi) in zip(p, bench.lobes.FAR_STATIC_BOX_M))
    assert any("Far static tags" in line for line in result["summary"])


def test_lock_in_rule_start_offsets_and_dropped_frames():
    lobes = bench.lobes
    # Locked: the last half's median above 5 cm, whatever the first half did.
    assert lobes.locked_in(np.r_[np.full(10, 0.005), np.full(10, 0.17)])
    assert not lobes.locked_in(np.r_[np.full(10, 0.5), np.full(10, 0.004)])
    assert lobes.locked_in(np.zeros(0))
    offsets = lobes.start_offsets(300, 40)
    assert len(offsets) == 40 and offsets[0] == 0 and max(offsets) < 150
    from scattertrack.sim import simulate

    data = simulate(lobes.sweep_scenario("static", 8.0, "inline", duration_s=0.1), seed=0)
    later = lobes.drop_frames(data.frames, 5)
    assert later.n_frames == data.frames.n_frames - 5
    assert later.frame_time_s[0] == data.frames.frame_time_s[5]
    roles = [a.role for a in data.scene.antennas]
    assert roles.count("tx") == 1 and roles.count("rx") == 4
    tx = next(a for a in data.scene.antennas if a.role == "tx")
    in_line = [a for a in data.scene.antennas if a.role == "rx" and a.position[1] == tx.position[1]]
    assert len(in_line) == 3


def test_pool_pools_rows_over_seeds():
    rng = np.random.default_rng(4)
    runs = []
    for seed, scale in enumerate((0.004, 0.03)):
        axis = np.abs(rng.normal(0.0, scale, size=(50, 3)))
        errors = np.linalg.norm(axis, axis=1)
        runs.append(
            {
                "seed": seed,
                "frames": 60,
                "estimates": 50,
                "wall_s": 0.5,
                "median_3d_m": float(np.median(errors)),
                "errors_3d_m": errors,
                "errors_axis_m": axis,
                "latency": {"steps": 60, "mean_ns": 1000.0 * (seed + 1), "max_ns": 5000.0},
            }
        )
    pooled = bench.pool(runs)
    errors = np.concatenate([r["errors_3d_m"] for r in runs])
    axis = np.concatenate([r["errors_axis_m"] for r in runs])
    assert pooled["rows"] == 100
    assert pooled["median_3d_mm"] == pytest.approx(np.median(errors) * 1e3)
    assert pooled["p90_3d_mm"] == pytest.approx(np.percentile(errors, 90) * 1e3)
    assert pooled["median_y_mm"] == pytest.approx(np.median(axis[:, 1]) * 1e3)
    # Only the first seed's median is below 1 cm.
    assert pooled["seeds_below_1cm"] == pytest.approx(0.5)
    assert pooled["coverage"] == pytest.approx(100 / 120)
    assert pooled["step_mean_ns"] == pytest.approx(1500.0)
    assert pooled["frames_per_s"] == pytest.approx(120.0)


def test_a_seed_without_estimates_counts_as_not_below_1cm():
    empty = {
        "seed": 0,
        "frames": 10,
        "estimates": 0,
        "wall_s": 0.1,
        "median_3d_m": math.nan,
        "errors_3d_m": np.zeros(0),
        "errors_axis_m": np.zeros((0, 3)),
        "latency": {"steps": 10, "mean_ns": 100.0, "max_ns": 200.0},
    }
    pooled = bench.pool([empty])
    assert pooled["seeds_below_1cm"] == 0.0
    assert math.isnan(pooled["median_3d_mm"])


def test_unknown_blocks_and_bad_particle_counts_are_refused():
    with pytest.raises(SystemExit):
        bench.parse_args(["--skip", "accuracy,nonsense"])
    with pytest.raises(SystemExit):
        bench.parse_args(["--particles", "10,many"])
    assert bench.parse_args(["--skip", "static, particles"]).particle_counts == list(bench.PARTICLE_COUNTS)


def test_runtime_block_streams_iq_and_reports_latency(smoke):
    _, result = smoke
    r = result["runtime"]
    assert r["replies"] == 60 and r["receivers"] == 4
    assert _finite(r["fast_frames_per_s"], r["latency_p50_us"], r["latency_p99_us"], r["median_3d_mm"])
    assert 0 < r["latency_p50_us"] <= r["latency_p99_us"] <= r["latency_max_us"]
    assert r["stages"] == ["dispatch", "antenna", "hand-off", "fusion", "tracker"]
    assert isinstance(r["target_met"], bool)

