"""Marvel LoRa recordings as SigMF (scattertrack.io.sigmf_lora): round trip, streaming, validation."""

import json
import shutil

import numpy as np
import pytest
from scattertrack.io.sigmf_lora import (
    LoraEpoch,
    iter_epochs,
    open_lora_sigmf,
    read_lora_sigmf,
    write_lora_sigmf,
)
from scattertrack.io.types import FormatError
from scattertrack.sim import lora

N = 4096
PER_SAMPLE = 12 * 4  # 12 channels x ci16 I/Q
PER_CHIRP = N * PER_SAMPLE


def hover(t):
    t = np.asarray(t, dtype=float)
    position = np.stack([1.0 + 0.5 * t, 15.0 + 0 * t, 2.0 + 0 * t], axis=1)
    yaw = 0.3 + 0.8 * t
    return position, np.stack([np.cos(yaw / 2), 0 * t, 0 * t, np.sin(yaw / 2)], axis=1)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A 3-epoch noisy recording behind one wall, written as ci16 (default) and cf32."""
    rec = lora.simulate_lora_iq(hover, {"position": [0.0, 0.0, 1.0], "walls": 1}, None, 0.3, seed=11)
    folder = tmp_path_factory.mktemp("lora")
    ci16 = write_lora_sigmf(folder / "recording", rec)
    cf32 = write_lora_sigmf(folder / "float.sigmf-meta", rec, datatype="cf32_le")
    return rec, ci16, cf32


def test_round_trip_within_ci16_quantisation(written):
    rec, (meta, data), _ = written
    assert meta.name == "recording.sigmf-meta" and data.stat().st_size == 3 * 2 * PER_CHIRP
    read = read_lora_sigmf(meta)
    assert read.samples.shape == rec.samples.shape == (3, 2, 4, 3, N) and read.samples.dtype == np.complex64
    scale = json.loads(meta.read_text())["global"]["scattertrack:scale"]
    # Rounding to integers: at most half a step per component.
    error = np.abs(read.samples - rec.samples)
    assert error.max() <= (np.sqrt(0.5) + 1e-3) / scale
    # The step is far below the noise: quantisation costs nothing measurable.
    noise_rms = np.sqrt(rec.metadata["noise_power_w"])
    assert 1 / scale < 0.01 * noise_rms
    assert read.metadata == json.loads(json.dumps(rec.metadata))
    np.testing.assert_array_equal(read.epoch_time_s, rec.epoch_time_s)
    np.testing.assert_array_equal(read.chirp_start_s, rec.chirp_start_s)
    assert read.details == {}


def test_cf32_is_lossless_and_the_layout_is_documented(written):
    rec, (meta, _), (float_meta, float_data) = written
    read = read_lora_sigmf(float_meta)
    np.testing.assert_array_equal(read.samples, rec.samples)
    document = json.loads(meta.read_text())
    g = document["global"]
    assert g["core:datatype"] == "ci16_le" and g["core:num_channels"] == 12 and g["core:sample_rate"] == 500e3
    assert [c["tag"] for c in g["scattertrack:channel_map"]] == [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3]
    assert [c["antenna"] for c in g["scattertrack:channel_map"]][:4] == [0, 1, 2, 0]
    captures = document["captures"]
    assert len(captures) == 6
    assert [c["core:sample_start"] for c in captures] == [i * N for i in range(6)]
    assert [c["core:frequency"] for c in captures[:2]] == pytest.approx([902.1e6, 902.1e6 + 12 * 2.16e6])
    assert [c["scattertrack:channel_index"] for c in captures[:2]] == [0, 12]
    assert captures[3]["scattertrack:time_s"] == pytest.approx(0.1 + N / 500e3)
    # Channel c = k * 3 + m of chirp (e, j): sample n of the file's block.
    raw = np.fromfile(float_data, dtype="<c8").reshape(6, N, 12)
    np.testing.assert_array_equal(raw[3, :, 2 * 3 + 1], rec.samples[1, 1, 2, 1])
    # The sigmf package reads it too.
    import sigmf

    handle = sigmf.fromfile(str(meta))
    assert handle.get_global_field(sigmf.NUM_CHANNELS_KEY) == 12
    assert handle.read_samples(start_index=N, count=4).shape == (4, 12)


def test_epochs_stream_from_a_memory_map(written):
    rec, (meta, _), _ = written
    opened = open_lora_sigmf(meta)
    assert len(opened) == 3 and isinstance(opened._data, np.memmap)
    epochs = list(iter_epochs(meta))
    assert [e.index for e in epochs] == [0, 1, 2] and all(isinstance(e, LoraEpoch) for e in epochs)
    whole = read_lora_sigmf(meta)
    for epoch in epochs:
        assert epoch.samples.shape == (2, 4, 3, N)
        np.testing.assert_array_equal(epoch.samples, whole.samples[epoch.index])
        assert epoch.time_s == rec.epoch_time_s[epoch.index]
        np.testing.assert_array_equal(epoch.chirp_start_s, rec.chirp_start_s[epoch.index])
    with pytest.raises(IndexError):
        opened.epoch(3)


# --------------------------------------------------------------------------
# bad files: each a FormatError naming the file and the field or byte offset


@pytest.fixture
def copy(written, tmp_path):
    _, (meta, data), _ = written
    meta_copy, data_copy = tmp_path / "r.sigmf-meta", tmp_path / "r.sigmf-data"
    shutil.copy(meta, meta_copy)
    shutil.copy(data, data_copy)
    return meta_copy, data_copy


def edit(meta, change):
    document = json.loads(meta.read_text())
    change(document)
    meta.write_text(json.dumps(document))


def test_bad_json(copy):
    meta, _ = copy
    meta.write_text(meta.read_text()[:300])
    with pytest.raises(FormatError, match="not valid JSON") as error:
        read_lora_sigmf(meta)
    assert error.value.path == str(meta) and error.value.line is not None


@pytest.mark.parametrize(
    "key",
    ["core:sample_rate", "scattertrack:tag_shifts_hz", "scattertrack:array_offsets_m", "scattertrack:rx_phase_offsets_rad",
     "scattertrack:channel_frequencies_hz", "scattertrack:scale", "scattertrack:spreading_factor"],
)
def test_missing_fields(copy, key):
    meta, _ = copy
    edit(meta, lambda d: d["global"].pop(key))
    with pytest.raises(FormatError, match="missing required key") as error:
        read_lora_sigmf(meta)
    assert error.value.path == str(meta) and error.value.column == f"global.{key}"
    assert "r.sigmf-meta" in str(error.value) and key in str(error.value)


@pytest.mark.parametrize(
    "key, value, match",
    [
        ("scattertrack:tag_shifts_hz", "1 MHz", "tag_shifts_hz"),
        ("scattertrack:rx_phase_offsets_rad", [[0.0, 1.0]], r"shape \(2, 4, 3\)"),
        ("scattertrack:tag_body_positions_m", [[0.0, 0.0, "x"]] * 4, "tag_body_positions_m"),
        ("scattertrack:excitation_channels", [0, 13], "excitation_channels"),
        ("scattertrack:spreading_factor", 13, "6..12"),
        ("scattertrack:samples_per_chirp", 2048, "2\\^spreading_factor"),
        ("scattertrack:scale", -1.0, "positive"),
        ("core:num_channels", 8, "num_channels"),
        ("core:datatype", "ci8", "unsupported datatype"),
    ],
)
def test_corrupt_fields(copy, key, value, match):
    meta, _ = copy
    edit(meta, lambda d: d["global"].__setitem__(key, value))
    with pytest.raises(FormatError, match=match) as error:
        read_lora_sigmf(meta)
    assert error.value.path == str(meta) and error.value.column == f"global.{key}"


def test_wrong_sample_rate(copy):
    meta, _ = copy
    edit(meta, lambda d: d["global"].__setitem__("core:sample_rate", 1e6))
    with pytest.raises(FormatError, match="fs = BW") as error:
        read_lora_sigmf(meta)
    assert error.value.path == str(meta) and error.value.column == "global.core:sample_rate"
    assert "500000.0 Hz" in str(error.value) and "1000000.0" in str(error.value)


@pytest.mark.parametrize(
    "index, key, value, match",
    [
        (3, "core:sample_start", 3 * N + 1, "must be 12288"),
        (1, "core:frequency", 902.1e6, "excitation channel 12"),
        (4, "scattertrack:time_s", None, "finite number"),
        (2, "scattertrack:epoch", 0, "must be 1"),
    ],
)
def test_bad_captures(copy, index, key, value, match):
    meta, _ = copy
    edit(meta, lambda d: d["captures"][index].__setitem__(key, value))
    with pytest.raises(FormatError, match=match) as error:
        read_lora_sigmf(meta)
    assert error.value.path == str(meta) and error.value.column == f"captures[{index}].{key}"


def test_data_longer_than_the_captures(copy):
    _, data = copy
    with open(data, "ab") as handle:
        handle.write(b"\0" * PER_SAMPLE * 10)
    with pytest.raises(FormatError, match=f"size does not match.*byte offset {6 * PER_CHIRP}") as error:
        read_lora_sigmf(data)
    assert error.value.path == str(data) and "r.sigmf-data" in str(error.value)


def test_truncated_mid_chirp(copy):
    meta, data = copy
    size = 4 * PER_CHIRP + 100 * PER_SAMPLE  # 2 epochs and 100 samples of the fifth chirp
    with open(data, "r+b") as handle:
        handle.truncate(size)
    with pytest.raises(FormatError, match=f"truncated: the data ends at byte offset {size} inside chirp 4 \\(epoch 2\\)") as error:
        read_lora_sigmf(meta)
    assert error.value.path == str(data) and error.value.column == "captures[4]"


def test_truncated_mid_sample(copy):
    meta, data = copy
    size = data.stat().st_size
    with open(data, "r+b") as handle:
        handle.truncate(size - 7)
    with pytest.raises(FormatError, match=f"byte offset {size - PER_SAMPLE}") as error:
        list(iter_epochs(meta))
    assert error.value.path == str(data)


def test_missing_data_and_metadata_files(copy):
    meta, data = copy
    data.unlink()
    with pytest.raises(FormatError, match="data file not found") as error:
        read_lora_sigmf(meta)
    assert error.value.path == str(data)
    meta.unlink()
    with pytest.raises(FormatError, match="metadata file not found") as error:
        read_lora_sigmf(meta)
    assert error.value.path == str(meta)


def test_writer_rejects_a_bad_recording(written, tmp_path):
    rec, _, _ = written
    with pytest.raises(ValueError, match="datatype"):
        write_lora_sigmf(tmp_path / "x", rec, datatype="ci8")
    broken = lora.LoraRecording(rec.samples[..., :100], rec.epoch_time_s, rec.chirp_start_s, rec.metadata)
    with pytest.raises(ValueError, match="samples per chirp"):
        write_lora_sigmf(tmp_path / "x", broken)
