"""The streamed reads.csv (io.reads_chunks) reads, checks and words errors as io.read_reads does."""

import numpy as np
import pytest

from scattertrack import io
from scattertrack.io import csvutil
from scattertrack.io import reads_chunks
from scattertrack.io.reads_chunks import NeedsCheckedReader, NeedsWholeFile, ReadsStream
from scattertrack.io.types import FormatError

HEADER = "time_s,epc,antenna,frequency_hz,phase_rad"


@pytest.fixture(params=[True, False], ids=["pyarrow", "checked"])
def fast(request):
    """Both readers of the stream: pyarrow's fast path and the checked one."""
    return request.param


@pytest.fixture
def small_chunks(monkeypatch):
    """Chunks of 50 rows (blocks of 2 kB), so that a file of a few hundred rows spans several."""
    monkeypatch.setattr(csvutil, "CHUNK_ROWS", 50)
    monkeypatch.setattr(reads_chunks, "ARROW_BLOCK_BYTES", 2000)


def rows(n: int, tags: int = 3, step_s: float = 0.01) -> list[str]:
    rng = np.random.default_rng(0)
    return [f"{k * step_s:.6f},E2{k % tags:02X},{1 + k % 4},915250000.0,{rng.uniform(0, 6.28):.6f}" for k in range(n)]


def write(tmp_path, lines, header=HEADER, name="reads.csv", newline="\n", bom=False):
    path = tmp_path / name
    text = newline.join([header, *lines]) + newline
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode())
    return path


def streamed(path, fast=True):
    """The stream's batches joined, read as track.streaming does: fast, then checked if need be."""
    try:
        stream = ReadsStream(path, fast=fast)
        batches = list(stream)
    except NeedsCheckedReader:
        stream = ReadsStream(path, fast=False)
        batches = list(stream)
    columns = {name: np.concatenate([b[name] for b in batches]) for name in batches[0]}
    return stream, columns


def assert_same_as_in_memory(path, fast=True):
    reads = io.read_reads(path)
    stream, columns = streamed(path, fast)
    np.testing.assert_array_equal(columns["time_s"], reads.time_s)
    np.testing.assert_array_equal(np.array(stream.epc_texts, dtype=object)[columns["epc"]], reads.epc)
    np.testing.assert_array_equal(columns["antenna"], reads.antenna)
    np.testing.assert_array_equal(columns["frequency_hz"], reads.frequency_hz)
    np.testing.assert_array_equal(columns["phase_rad"], reads.phase_rad)
    assert stream.rows == len(reads)
    assert stream.reordered == reads.reordered
    assert stream.skipped.counts == reads.skipped.counts
    assert stream.skipped.examples == reads.skipped.examples
    assert stream.epc_texts == reads.epcs()
    return stream


def test_batches_are_the_in_memory_reads(small_chunks, tmp_path, fast):
    assert_same_as_in_memory(write(tmp_path, rows(400)), fast)


def test_optional_columns_are_read_by_the_fast_path(small_chunks, tmp_path):
    lines = [f"{line},-60.5,,{k % 3 + 1 if k % 5 else ''}" for k, line in enumerate(rows(200))]
    path = write(tmp_path, lines, header=HEADER + ",rssi_dbm,doppler_hz,channel_index")
    assert len(list(ReadsStream(path))) >= 1  # no NeedsCheckedReader
    assert_same_as_in_memory(path)


def test_duplicates_and_reorders_within_the_window_across_chunks(small_chunks, tmp_path, fast):
    lines = rows(400)
    lines[120], lines[121] = lines[121], lines[120]  # out of order by one row
    lines.insert(160, lines[100])  # a copy 60 rows (0.6 s) later: another chunk
    lines.insert(49, lines[50])  # a copy across the first chunk boundary
    lines.insert(300, lines[299].replace("E2", "e2"))  # a case twin
    path = write(tmp_path, lines)
    with pytest.warns(io.InputWarning, match="differs from .* only in letter case"):
        stream = assert_same_as_in_memory(path, fast)
    assert stream.reordered >= 1 and stream.skipped.counts["duplicate row"] == 2


def test_bom_crlf_quotes_and_extra_columns(small_chunks, tmp_path, fast):
    lines = [f'{line},"x, y"' for line in rows(120)]
    path = write(tmp_path, lines, header=HEADER + ",note", newline="\r\n", bom=True)
    assert_same_as_in_memory(path, fast)


def test_a_clock_jump_back_needs_the_whole_file(small_chunks, tmp_path, fast):
    lines = rows(300)
    lines.insert(250, lines[10])
    with pytest.raises(NeedsWholeFile):
        streamed(write(tmp_path, lines), fast)


def test_a_forward_gap_is_warned_as_the_in_memory_reader_does(small_chunks, tmp_path, fast):
    lines = rows(200)
    shifted = [f"{float(l.split(',')[0]) + 100:.6f}," + l.split(",", 1)[1] for l in lines[120:]]
    path = write(tmp_path, lines[:120] + shifted)
    with pytest.warns(io.InputWarning) as in_memory:
        io.read_reads(path)
    with pytest.warns(io.InputWarning) as stream:
        streamed(path, fast)
    assert [str(w.message) for w in stream] == [str(w.message) for w in in_memory]


@pytest.mark.parametrize("row, bad", [
    (170, lambda l: l.replace("915250000.0", "915.25")),  # MHz
    (171, lambda l: l.rsplit(",", 1)[0] + ",200.0"),  # degrees
    (172, lambda l: l.replace(",E2", ",XYZ", 1)),  # not hex
    (173, lambda l: l.replace(",915", ",,915", 1)),  # a field too many
    (174, lambda l: l.split(",")[0] + ",E201,9,915250000.0,1.0"),  # antenna not in the scene
])
def test_an_error_in_a_later_chunk_names_its_true_line(small_chunks, tmp_path, row, bad):
    lines = rows(300)
    lines[row] = bad(lines[row])
    path = write(tmp_path, lines)
    scene = _scene(tmp_path)
    with pytest.raises(FormatError) as in_memory:
        io.read_reads(path, scene)
    with pytest.raises(NeedsCheckedReader):
        list(ReadsStream(path, scene))  # pyarrow's fast path leaves the wording to the checked reader
    with pytest.raises(FormatError) as stream:
        list(ReadsStream(path, scene, fast=False))
    assert str(stream.value) == str(in_memory.value)
    assert stream.value.line == row + 2


@pytest.mark.parametrize("cell", ["nan", "inf", "-inf", "NaN", " 0.07", "0.07 ", "\t0.07", "0.0_7", "0.0\uff17", "0x10",
                                  "1e400", "+0.07", ".07", "7e-2", "7E-2", "0.070", "", "0,07", "0.07.1", "7e-2e"])
def test_the_fast_path_takes_a_cell_only_as_the_checked_reader_does(tmp_path, cell):
    lines = rows(20)
    fields = lines[7].split(",")
    fields[0] = f'"{cell}"' if "," in cell else cell
    lines[7] = ",".join(fields)
    path = write(tmp_path, lines)
    try:
        in_memory = io.read_reads(path)
    except FormatError:
        in_memory = None
    try:
        stream = ReadsStream(path)
        batches = list(stream)
        fast_columns = np.concatenate([b["time_s"] for b in batches])
    except (NeedsCheckedReader, NeedsWholeFile):
        return  # left to the checked reader
    except FormatError:
        pytest.fail("the fast path must not word errors itself")
    assert in_memory is not None, f"the fast path took {cell!r}, which read_reads rejects"
    np.testing.assert_array_equal(fast_columns, in_memory.time_s)


def _scene(tmp_path):
    from scattertrack.cli import main

    folder = tmp_path / "session"
    assert main(["simulate", "--scenario", "glac-2d-10cms", "--out", str(folder), "--duration", "1"]) == 0
    return io.read_scene(folder / "scene.toml")
