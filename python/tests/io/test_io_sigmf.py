"""SigMF recordings of the helper: writing, reading and validation (the channel estimation: tests/dsp)."""

import json
import shutil

import numpy as np
import pytest

from helper_recordings import written_recording
from scattertrack import io
from scattertrack.io import FormatError


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    return written_recording(tmp_path_factory)


def test_round_trip_of_metadata_and_samples(recording):
    sim, out = recording
    read = io.read_sigmf(out / "recording.sigmf-meta", verify_checksum=True)
    assert read.channels == [1, 2, 3, 4] and read.tx_id == 0
    assert (read.bandwidth_hz, read.subcarriers, read.blf_hz, read.encoding) == (100e6, 20, 40e3, "fm0")
    assert len(read.windows) == 4 and all(w.epc == "E1" for w in read.windows)
    assert isinstance(read.data, np.memmap)
    np.testing.assert_array_equal(read.data, sim.recording.data)
    symbol = read.known_symbol
    assert abs(symbol[0]) == 0 and np.allclose(np.abs(symbol[1:]), 1.0)
    w = read.window_samples(1)
    assert w.shape == (4, 30_000) and w.dtype == np.complex64
    assert io.read_sigmf(out / "calibration").calibration["tag_position"] == pytest.approx(
        sim.details["calibration_position"])
    # The sigmf package reads it too.
    import sigmf

    handle = sigmf.fromfile(str(out / "recording.sigmf-meta"))
    assert handle.get_global_field(sigmf.NUM_CHANNELS_KEY) == 4


# --------------------------------------------------------------------------
# corrupt and truncated recordings: each a FormatError naming the file


@pytest.fixture
def copy(recording, tmp_path):
    """A fresh copy of the recording's two files; returns (meta, data) paths."""
    _, out = recording
    meta, data = tmp_path / "r.sigmf-meta", tmp_path / "r.sigmf-data"
    shutil.copy(out / "recording.sigmf-meta", meta)
    shutil.copy(out / "recording.sigmf-data", data)
    return meta, data


def edit_meta(meta, change):
    document = json.loads(meta.read_text())
    change(document)
    meta.write_text(json.dumps(document))


def test_bad_json(copy):
    meta, _ = copy
    meta.write_text(meta.read_text()[:500])
    with pytest.raises(FormatError, match="not valid JSON") as error:
        io.read_sigmf(meta)
    assert error.value.path == str(meta) and error.value.line is not None


@pytest.mark.parametrize(
    "key",
    ["scattertrack:blf_hz", "scattertrack:known_symbol", "scattertrack:channels", "core:num_channels"],
)
def test_missing_keys(copy, key):
    meta, _ = copy
    edit_meta(meta, lambda d: d["global"].pop(key))
    with pytest.raises(FormatError) as error:
        io.read_sigmf(meta)
    assert error.value.path == str(meta) and key in str(error.value)


@pytest.mark.parametrize(
    "field, value, match",
    [
        ("core:datatype", "ci8", "unsupported datatype"),
        ("core:datatype", "cf64_le", "unsupported datatype"),
        ("scattertrack:subcarriers", 2000, r"N < B/\(2 BLF\)"),
        ("scattertrack:known_symbol", [[0.0, 0.0], [1.0, 0.0]], "known_symbol"),
        ("scattertrack:encoding", "manchester", "encoding"),
        ("core:num_channels", 3, "num_channels"),
        ("core:sample_rate", "fast", "schema"),
    ],
)
def test_bad_values(copy, field, value, match):
    meta, _ = copy
    edit_meta(meta, lambda d: d["global"].__setitem__(field, value))
    with pytest.raises(FormatError, match=match) as error:
        io.read_sigmf(meta)
    assert error.value.path == str(meta)


def test_truncated_data_mid_sample(copy):
    _, data = copy
    size = data.stat().st_size
    with open(data, "r+b") as handle:
        handle.truncate(size - 7)
    with pytest.raises(FormatError, match="byte offset") as error:
        io.read_sigmf(data)
    assert error.value.path == str(data)


def test_truncated_data_missing_windows(copy):
    meta, data = copy
    with open(data, "r+b") as handle:
        handle.truncate(16 * 30_000 * 2 + 16 * 100)  # 2 windows and 100 samples of the third
    with pytest.raises(FormatError, match="truncated") as error:
        io.read_sigmf(meta)
    assert error.value.path == str(data) and "annotations[2]" in str(error.value)


def test_missing_and_corrupt_data_file(copy):
    meta, data = copy
    with open(data, "r+b") as handle:
        handle.seek(1000)
        handle.write(b"\x55\x55")
    with pytest.raises(FormatError, match="SHA-512"):
        io.read_sigmf(meta, verify_checksum=True)
    data.unlink()
    with pytest.raises(FormatError, match="not found") as error:
        io.read_sigmf(meta)
    assert error.value.path == str(data)


def test_capture_errors(copy):
    meta, _ = copy
    edit_meta(meta, lambda d: d["captures"][1].pop("scattertrack:time_s"))
    with pytest.raises(FormatError, match="time_s") as error:
        io.read_sigmf(meta)
    assert error.value.column == "captures[1].scattertrack:time_s"
