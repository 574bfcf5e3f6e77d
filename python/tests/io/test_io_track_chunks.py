"""The incremental track.csv writer (io.track_chunks) writes io.write_track's bytes."""

import numpy as np
import pytest

from scattertrack import io
from scattertrack.io import track_chunks
from scattertrack.io.track_chunks import TrackWriter
from scattertrack.io.types import Track


def awkward_values(n: int, rng) -> np.ndarray:
    """Floats whose 6-decimal text is easy to get wrong: halfway ties, -0, rounding carries, large and tiny."""
    values = rng.normal(scale=3.0, size=n)
    special = np.array([0.0078125, -0.0078125, 0.5e-6, 2.5e-6, 1.0000005, 0.9999995, -0.0, -1e-9, 1e-7,
                        123456789.123456789, 1e15 + 0.25, 2.0 ** -20, 3.0 * 2.0 ** -21, 0.1 + 0.2, 1.2345675])
    values[: len(special)] = special
    return values


@pytest.mark.parametrize("parallel_rows", [None, 8], ids=["one-thread", "halves-on-two-threads"])
def test_rows_written_in_chunks_are_write_track_bytes(tmp_path, monkeypatch, parallel_rows):
    if parallel_rows is not None:
        # Chunks of 37 rows are then formatted in two halves (18 + 19) at once.
        monkeypatch.setattr(track_chunks, "PARALLEL_ROWS", parallel_rows)
    rng = np.random.default_rng(3)
    n = 500
    epcs = np.array(["E200", "a,b", 'say "hi"', "E201"], dtype=object)
    code = rng.integers(0, len(epcs), size=n)
    track = Track(
        time_s=np.sort(np.abs(awkward_values(n, rng))),
        epc=epcs[code],
        position=np.column_stack([awkward_values(n, rng) for _ in range(3)]),
        velocity=np.column_stack([awkward_values(n, rng) for _ in range(3)]),
        sigma=np.abs(np.column_stack([awkward_values(n, rng) for _ in range(3)])),
    )
    track.velocity[::7] = np.nan
    track.sigma[::11, 1] = np.nan
    io.write_track(tmp_path / "whole.csv", track)
    with TrackWriter(tmp_path / "chunked.csv") as writer:
        for start in range(0, n, 37):
            s = slice(start, start + 37)
            writer.write(track.time_s[s], code[s], list(epcs), track.position[s], track.velocity[s], track.sigma[s])
    assert (tmp_path / "chunked.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()
    assert not (tmp_path / "chunked.csv.partial").exists()


def test_an_empty_track_is_the_header_alone(tmp_path):
    empty = Track(time_s=np.zeros(0), epc=np.zeros(0, dtype=object), position=np.zeros((0, 3)),
                  velocity=np.zeros((0, 3)), sigma=np.zeros((0, 3)))
    io.write_track(tmp_path / "whole.csv", empty)
    with TrackWriter(tmp_path / "chunked.csv"):
        pass
    assert (tmp_path / "chunked.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()


def test_a_failed_run_leaves_no_file(tmp_path):
    try:
        with TrackWriter(tmp_path / "track.csv") as writer:
            writer.write(np.array([1.0]), np.array([0]), ["E2"], np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3)))
            raise RuntimeError("stop")
    except RuntimeError:
        pass
    assert list(tmp_path.iterdir()) == []


def test_six_decimals_are_python_percent_f_for_every_kind_of_value():
    """The fast integer path and the exact fallback together give "%.6f"'s text, value by value."""
    from scattertrack import _core

    rng = np.random.default_rng(11)
    n = 200_000
    ties = (rng.integers(-10**9, 10**9, size=n) + 0.5) / 1e6  # within an ulp of a 6th-decimal tie
    nudged = ties + rng.choice([-1, 0, 1], size=n) * np.spacing(ties)
    values = np.concatenate([
        rng.normal(scale=3.0, size=n),
        rng.uniform(-1e9, 1e9, size=n),
        1.7e9 + rng.uniform(0, 1e5, size=n),  # Unix-epoch seconds
        10.0 ** rng.uniform(-12, 12, size=n) * rng.choice([-1, 1], size=n),
        ties, nudged, np.round(rng.normal(size=n), 6),
        [0.0, -0.0, -1e-9, 5e-7, -5e-7, 1.5e-6, 2.5e-6, 999999.9999995, 1e9 - 5e-7, 1e9, np.inf, -np.inf, np.nan],
    ])
    cells = ["E2"]
    text = _core.Engine.format_track_rows(values, np.zeros(len(values), dtype=np.int64), cells, np.zeros((len(values), 0)))
    got = [line.split(",")[0] for line in text.decode().splitlines()]
    assert got == ["%.6f" % v for v in values]
