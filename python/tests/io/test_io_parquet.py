"""Parquet twins: every format round-trips through .parquet, and tracking a
Parquet reads file gives the CSV's track."""

from __future__ import annotations

import numpy as np
import pytest

from scattertrack import io, track
from scattertrack.io.types import FormatError
from scattertrack.sim import load_scenario, simulate


@pytest.fixture(scope="module")
def cots():
    return simulate(load_scenario("glac-3d-walls") | {"duration_s": 3.0}, seed=1)


@pytest.fixture(scope="module")
def helper():
    return simulate(load_scenario("turbotrack-static") | {"duration_s": 0.2}, seed=1)


@pytest.fixture(scope="module")
def drone():
    return simulate(load_scenario("marvel-hover") | {"duration_s": 3.0}, seed=1)


def _same(a, b, names):
    for name in names:
        x, y = getattr(a, name), getattr(b, name)
        if np.asarray(x).dtype.kind in "fc":
            assert np.allclose(x, y, equal_nan=True, atol=1e-6), name
        else:
            assert np.array_equal(np.asarray(x).astype(str), np.asarray(y).astype(str)), name


@pytest.mark.parametrize(
    "fixture, writer, reader, names",
    [
        ("cots", io.write_reads, io.read_reads, ["time_s", "epc", "antenna", "frequency_hz", "phase_rad", "rssi_dbm"]),
        ("cots", io.write_truth, io.read_truth, ["time_s", "epc", "position"]),
        ("helper", io.write_frames, io.read_frames, ["time_s", "epc"]),
        ("drone", io.write_imu, io.read_imu, ["time_s"]),
        ("drone", io.write_features, io.read_features, ["time_s", "range_m"]),
    ],
)
def test_every_format_round_trips_through_parquet(request, tmp_path, fixture, writer, reader, names):
    sim = request.getfixturevalue(fixture)
    data = {io.write_reads: sim.reads, io.write_truth: sim.truth, io.write_frames: getattr(sim, "frames", None), io.write_imu: getattr(sim, "imu", None), io.write_features: getattr(sim, "features", None)}[writer]
    writer(tmp_path / "a.csv", data)
    writer(tmp_path / "a.parquet", data)
    from_csv, from_parquet = reader(tmp_path / "a.csv"), reader(tmp_path / "a.parquet")
    assert len(from_csv) == len(from_parquet) > 0
    _same(from_csv, from_parquet, names)


def test_tracking_a_parquet_reads_file_gives_the_csv_track(cots, tmp_path):
    io.write_reads(tmp_path / "reads.csv", cots.reads)
    io.write_reads(tmp_path / "reads.parquet", cots.reads)
    a = track.run("glac", cots.scene, io.read_reads(tmp_path / "reads.csv"))
    b = track.run("glac", cots.scene, io.read_reads(tmp_path / "reads.parquet"))
    assert np.array_equal(a.position, b.position) and np.array_equal(a.time_s, b.time_s)
    io.write_track(tmp_path / "track.parquet", a)
    back = io.read_track(tmp_path / "track.parquet")
    assert np.abs(back.position - a.position).max() < 1e-6 and back.sigma is not None


def test_a_broken_or_incomplete_parquet_is_refused_with_its_name(tmp_path):
    (tmp_path / "bad.parquet").write_bytes(b"not parquet at all")
    with pytest.raises(FormatError, match=r"bad.parquet: not a readable Parquet file"):
        io.read_reads(tmp_path / "bad.parquet")
    import pyarrow
    import pyarrow.parquet

    pyarrow.parquet.write_table(pyarrow.table({"time_s": [0.0], "epc": ["E2"]}), tmp_path / "short.parquet")
    with pytest.raises(FormatError, match=r"short.parquet:1: line 1, column 'antenna': missing required column"):
        io.read_reads(tmp_path / "short.parquet")
