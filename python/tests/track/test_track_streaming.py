"""track.streaming: a streamed reads.csv gives track.run's rows, bytes, stats and summary figures."""

import copy

import numpy as np
import pytest

from scattertrack import io, track
from scattertrack.io import csvutil, reads_chunks  # noqa: F401 - io.reads_chunks below
from scattertrack.sim import load_scenario, simulate
from scattertrack.sim.simulation import write_simulation
from scattertrack.track import plausibility, streaming
from scattertrack.track.cots import _DECLINED

UNRESOLVED_SIGMA_M = 0.04


def session(tmp_path, name: str, duration_s: float = 6.0, static: bool = False):
    scenario = copy.deepcopy(load_scenario(name))
    scenario["duration_s"] = duration_s
    if static:
        for tag in scenario["tags"]:
            tag["trajectory"] = {"kind": "static", "position": [0.5, 0.6, 0.7]}
    folder = write_simulation(simulate(scenario, seed=2), tmp_path / name)
    return io.read_scene(folder / "scene.toml"), folder / "reads.csv"


@pytest.fixture
def small_chunks(monkeypatch):
    """Many batches: chunks of 97 rows for the checked reader, blocks of 3 kB for pyarrow's."""
    monkeypatch.setattr(csvutil, "CHUNK_ROWS", 97)
    monkeypatch.setattr(io.reads_chunks, "ARROW_BLOCK_BYTES", 3000)


@pytest.mark.parametrize("name", ["glac-3d-arm-5tags", "glac-2d-40cms-hopping", "glac-2d-40cms-modpi"])
@pytest.mark.parametrize("shards", [1, 2])
def test_streamed_track_is_the_in_memory_track(small_chunks, tmp_path, name, shards):
    scene, reads_path = session(tmp_path, name)
    reads = io.read_reads(reads_path, scene)
    expected = track.run("glac", scene, reads)
    io.write_track(tmp_path / "memory.csv", expected)
    result = streaming.track_file("glac", scene, reads_path, tmp_path / "stream.csv", {},
                                  unresolved_sigma_m=UNRESOLVED_SIGMA_M, shards=shards)
    assert (tmp_path / "stream.csv").read_bytes() == (tmp_path / "memory.csv").read_bytes()
    assert len(result) == len(expected)
    assert result.stats == expected.stats and list(result.stats) == list(expected.stats)
    assert result.skipped.summary() == expected.skipped.summary()
    assert len(result.reads) == len(reads) and result.reads.tags == reads.epcs()
    assert result.reads.reordered == reads.reordered
    assert result.latency[0] == expected.latency[0]
    from scattertrack.track.plausibility import unresolved_warnings

    in_memory = unresolved_warnings(expected) + plausibility.implausible_speed_warnings(expected, reads)
    assert result.summary_warnings == in_memory


def test_declined_reasons_are_worded_as_track_run_words_them():
    assert streaming.DECLINED == _DECLINED


def test_the_geometry_check_reads_the_same_channels(tmp_path):
    from scattertrack.check import geometry

    scene, reads_path = session(tmp_path, "glac-2d-40cms-hopping")
    reads = io.read_reads(reads_path, scene)
    result = streaming.track_file("glac", scene, reads_path, tmp_path / "stream.csv", {}, unresolved_sigma_m=UNRESOLVED_SIGMA_M)
    assert geometry._read_channels(scene, result.reads) == geometry._read_channels(scene, reads)


def test_static_tag_evidence_is_the_in_memory_check(small_chunks, tmp_path):
    """The turn-speed bound and the track's median speed, per tag, as plausibility works them out."""
    scene, reads_path = session(tmp_path, "glac-3d-walls", duration_s=10.0, static=True)
    reads = io.read_reads(reads_path, scene)
    expected = track.run("glac", scene, reads)
    stream = io.reads_chunks.ReadsStream(reads_path, scene)
    ids = np.array([a.id for a in scene.antennas])
    turns = streaming.TurnEvidence(len(ids))
    for batch in stream:
        turns.add(batch, np.searchsorted(ids, batch["antenna"]))
    for code, epc in enumerate(stream.epc_texts):
        bound = plausibility.radial_speed_bound(reads, np.flatnonzero(reads.epc == epc), 2 * np.pi)
        assert turns.bound(code) == pytest.approx(bound, rel=0, abs=0, nan_ok=True)
    figures = streaming.TagFigures()
    figures.add(0, np.zeros(len(expected), dtype=np.int64), expected.sigma, expected.velocity, UNRESOLVED_SIGMA_M)
    assert figures.speeds.median(0) == np.nanmedian(np.linalg.norm(expected.velocity, axis=1))


def test_samples_are_exact_up_to_capacity_then_a_systematic_sample():
    rng = np.random.default_rng(0)
    samples = streaming.Samples(capacity=64)
    values = rng.normal(size=1000)
    groups = rng.integers(0, 3, size=1000)
    for start in range(0, 1000, 25):
        samples.add(groups[start:start + 25], values[start:start + 25])
    for g in range(3):
        mine = values[groups == g]
        row = samples.slot[g]
        stride = samples.stride[row]
        np.testing.assert_array_equal(samples.values[row, : samples.count[row]], mine[::stride][: samples.count[row]])
        assert samples.count[row] <= 64
    small = streaming.Samples(capacity=64)
    small.add(groups[:100], values[:100])
    for g in range(3):
        assert small.median(g) == np.median(values[:100][groups[:100] == g])


def test_a_malformed_row_leaves_no_track(small_chunks, tmp_path):
    scene, reads_path = session(tmp_path, "glac-2d-40cms-hopping")
    lines = reads_path.read_text().splitlines()
    fields = lines[120].split(",")
    fields[4] = "abc"
    lines[120] = ",".join(fields)
    reads_path.write_text("\n".join(lines) + "\n")
    with pytest.raises(io.FormatError) as error:
        streaming.track_file("glac", scene, reads_path, tmp_path / "stream.csv", {}, unresolved_sigma_m=UNRESOLVED_SIGMA_M)
    assert error.value.line == 121
    assert not (tmp_path / "stream.csv").exists() and not (tmp_path / "stream.csv.partial").exists()
