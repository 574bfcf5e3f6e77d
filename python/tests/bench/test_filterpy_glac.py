"""The benchmark's filterpy GLAC baseline (bench/filterpy_glac.py) and the
helpers of the benchmark harness (bench/run.py), on tiny inputs."""

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("filterpy")

BENCH = Path(__file__).resolve().parents[3] / "bench"
sys.path.insert(0, str(BENCH))

import filterpy_glac  # noqa: E402

from scattertrack import track as st_track  # noqa: E402
from scattertrack.eval import compare  # noqa: E402
from scattertrack.sim import load_scenario, simulate  # noqa: E402


def _bench_run():
    """bench/run.py as a module (under a name that cannot clash)."""
    spec = importlib.util.spec_from_file_location("scattertrack_bench_run", BENCH / "run.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def short_2d():
    return simulate(load_scenario("glac-2d-10cms") | {"duration_s": 5.0}, seed=0)


def test_filterpy_glac_tracks_a_short_2d_run(short_2d):
    track = filterpy_glac.run_filterpy_glac(short_2d.scene, short_2d.reads)
    assert len(track) > 100
    assert np.all(np.diff(track.time_s) >= 0)
    report = compare(short_2d.truth, track)
    assert report.overall.median_3d_m < 0.02, report.overall.median_3d_m
    assert np.isfinite(report.overall.median_velocity_m_s)
    stats = next(iter(track.stats.values()))
    assert stats.measurements == len(short_2d.reads)
    # It is the same algorithm: accuracy close to the Rust tracker's on the same reads.
    rust = compare(short_2d.truth, st_track.run("glac", short_2d.scene, short_2d.reads))
    assert abs(report.overall.median_3d_m - rust.overall.median_3d_m) < 0.005


def test_initial_hypotheses_contain_the_truth_2d(short_2d):
    model = filterpy_glac.SceneModel(short_2d.scene)
    index = {a.id: i for i, a in enumerate(short_2d.scene.antennas)}
    r = short_2d.reads
    window = [
        (float(r.time_s[k]), index[int(r.antenna[k])], float(r.frequency_hz[k]), float(r.phase_rad[k]))
        for k in range(len(r))
        if r.time_s[k] < 0.4
    ]
    settings = filterpy_glac.GlacSettings()
    t_x, hypotheses = filterpy_glac.initial_hypotheses(model, window, settings, 0.0026)
    truth = np.array([np.interp(t_x, short_2d.truth.time_s, short_2d.truth.position[:, k]) for k in range(3)])
    nearest = min(np.linalg.norm(state[:3] - truth) for state, _ in hypotheses)
    assert nearest < 0.02


def test_bench_helpers_smoke(tmp_path):
    bench = _bench_run()
    rows = bench.accuracy_table(["glac-2d-10cms"], [0], duration_s=3.0, progress=False)
    assert len(rows) == 1 and rows[0]["runs"] == 1
    assert rows[0]["median_3d_mm"] < 20 and rows[0]["reads_per_s"] > 0
    variants = bench.variants_table(["glac-2d-10cms"], [0], duration_s=2.0, methods=[("glac", "glac", {}), ("glac-sync", "glac-sync", {})], progress=False)
    assert [v["method"] for v in variants] == ["glac", "glac-sync"]
    speed = bench.speed_comparison("glac-2d-10cms", 0, duration_s=3.0, repeats=1)
    assert speed["reads"] > 50
    assert speed["filterpy"]["ns_per_read"] > 0 and speed["ratio"]["filterpy_over_run"] > 1
    assert speed["accuracy"]["filterpy"]["median_3d_mm"] < 20
    budget = bench.budget_table("glac-2d-10cms", 0, 3.0, budgets_ms=(1, 5), methods=("glac", "glac-naive"), max_hypotheses=500)
    assert {(b["method"], b["budget_ms"]) for b in budget} == {(m, b) for m in ("glac", "glac-naive") for b in (1, 5)}
    assert all(b["reads"] >= 0 for b in budget)
    cost, side, accuracy = bench.speed_rows([speed])
    headers, cells = bench.table(bench.SIDE_COLUMNS, side)
    assert len(cells) == 1 and len(cells[0]) == len(headers)
    assert "filterpy ns/read" in bench.text_table(headers, cells)
    assert bench.markdown_table(headers, cells).startswith("| scenario |")
    # main() writes both outputs even with every slow section skipped.
    out = tmp_path / "bench"
    assert bench.main(["--out", str(out), "--skip", "speed,accuracy,variants,budget", "--no-progress"]) == 0
    result = json.loads((out / "latest.json").read_text())
    assert result["settings"]["seeds"] == [0, 1, 2, 3, 4]
    # The prior block runs each phase-noise prior on the same realistic runs.
    assert [r["method"] for r in result["priors"]] == [label for label, _, _ in bench.PRIORS]
    assert len({r["median_3d_mm"] for r in result["priors"]}) == len(bench.PRIORS)
    assert "The phase-noise prior on realistic reads" in (out / "latest.md").read_text()
    assert (out / "latest.md").read_text().startswith("# scattertrack benchmark")
