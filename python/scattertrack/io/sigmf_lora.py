"""LoRa-backscatter recordings of the Marvel controller as SigMF (docs/marvel.md sections 4-6).

A recording holds what the controller's backscatter signal handler samples:
per sensing epoch, per excitation chirp ``j``, per tag ``k`` and per receive
antenna ``m`` one channelised baseband stream of ``N = 2^SF`` samples at
``fs = BW`` (the receiver has mixed tag ``k``'s uplink at ``f_j + s_k`` down
to 0 Hz). In memory that is :class:`LoraRecording`, ``samples`` of shape
``(epochs, J, K, M, N)`` (J = 2 excitation channels, K = 4 tags, M = 3
antennas), complex64, in the simulator's physical units (sqrt(W): ``|y|^2``
is the received power in watts).

Files: ``NAME.sigmf-meta`` (JSON, SigMF 1.2, written with the ``sigmf``
package) + ``NAME.sigmf-data``.

Data layout
    ``core:datatype`` ``ci16_le`` (int16 I, Q; default) or ``cf32_le``
    (float32 I, Q). ``core:num_channels`` = ``K x M`` = 12, interleaved per
    sample; channel ``c = k M + m`` (tag-major: tag 1 antennas 0, 1, 2, then
    tag 2, ...), listed in ``scattertrack:channel_map`` as
    ``{"channel", "tag", "antenna", "tag_shift_hz"}``. ``core:sample_rate``
    = ``BW`` (must equal ``scattertrack:bandwidth_hz``: the dechirp's
    reference chirp is sampled at ``fs = BW``, so any other rate is a
    different chirp). Stored values = ``scattertrack:scale`` x physical
    samples; ``ci16_le`` is scaled so the largest I or Q component sits
    ``headroom_db`` below full scale (nothing clips).
Captures
    One SigMF capture per chirp, in time order, ``N`` samples each:
    ``core:sample_start = (J e + j) N``, ``core:frequency`` = the excitation
    channel's centre ``f_j`` (Hz; channel ``c`` of the capture is the uplink
    at ``f_j + s_k``), ``scattertrack:epoch`` (e), ``scattertrack:excitation``
    (j, index into ``excitation_channels``), ``scattertrack:channel_index``
    (the LoRa channel number ``i`` of ``f_i``) and ``scattertrack:time_s``
    (the chirp's start on the controller clock, s).
Global ``scattertrack:`` keys (extension declared in ``core:extensions``)
    Every entry of :attr:`LoraRecording.metadata` (the simulator's
    :func:`scattertrack.sim.lora.recording_metadata`: ``spreading_factor``,
    ``bandwidth_hz``, ``sample_rate_hz``, ``samples_per_chirp``,
    ``chirp_duration_s``, ``channel_frequencies_hz``, ``excitation_channels``,
    ``excitation_frequencies_hz``, ``tag_shifts_hz``, ``tag_body_positions_m``,
    ``array``, ``array_offsets_m``, ``transmit_offset_m``,
    ``rx_phase_offsets_rad``, ``sensing_rate_hz``, ``epoch_period_s``,
    ``noise_power_w``, ``model``, ``seed``, ...) plus the file's own
    ``scale``, ``layout`` and ``channel_map``.

Contract: :func:`read_lora_sigmf` and :func:`open_lora_sigmf` validate
everything and raise :class:`FormatError` naming the file (``.sigmf-meta``
or ``.sigmf-data``) and the field (``global.core:sample_rate``,
``captures[3].core:sample_start``) or the byte offset: bad JSON, a schema
violation, a missing or malformed key, a sample rate other than the
bandwidth, a channel count other than tags x antennas, captures that do not
tile the data chirp by chirp, a data file missing, truncated (mid-sample or
mid-chirp) or longer than the captures say. :func:`iter_epochs` streams a
recording epoch by epoch from a memory map (bounded memory for long flights);
:func:`read_lora_sigmf` loads it whole.

Units: seconds, hertz, metres, radians; samples in sqrt(W) after dividing by
the scale.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scattertrack.io.sigmf import DATATYPES, NAMESPACE, _base, _global_number, _load_meta
from scattertrack.io.types import FormatError

LORA_LAYOUT = (
    "core:num_channels = tags x antennas channels interleaved per sample, channel = tag * antennas + antenna "
    "(scattertrack:channel_map); one capture per chirp of samples_per_chirp samples, epochs in time order, "
    "excitation chirps in order within an epoch; stored values = scattertrack:scale x physical baseband (sqrt(W))"
)

FILE_KEYS = ("scale", "layout", "channel_map")
"""``scattertrack:`` keys that describe the file, not the recording (not returned in ``metadata``)."""

REQUIRED_METADATA = (
    "spreading_factor",
    "bandwidth_hz",
    "samples_per_chirp",
    "channel_frequencies_hz",
    "excitation_channels",
    "tag_shifts_hz",
    "tag_body_positions_m",
    "array_offsets_m",
    "rx_phase_offsets_rad",
    "sensing_rate_hz",
)
"""Metadata keys the reader requires (the ones the DSP needs to invert the signal model)."""


@dataclass
class LoraRecording:
    """A Marvel controller recording: channelised baseband streams per epoch (docs/marvel.md section 6)."""

    samples: np.ndarray
    """complex64 ``(epochs, J, K, M, N)``: excitation chirp, tag, receive antenna, sample; sqrt(W)."""
    epoch_time_s: np.ndarray
    """``(epochs,)`` start of each epoch's first chirp, s."""
    chirp_start_s: np.ndarray
    """``(epochs, J)`` start ``t_j`` of each excitation chirp, s (sample ``n`` is at ``t_j + n / fs``)."""
    metadata: dict
    """Every parameter the DSP may use (JSON values; keys in the module docstring)."""
    details: dict = field(default_factory=dict)
    """Hidden truth from the simulator (empty when read from a file)."""

    @property
    def n_epochs(self) -> int:
        return int(self.samples.shape[0])


@dataclass
class LoraEpoch:
    """One sensing epoch, as :func:`iter_epochs` yields it."""

    index: int
    time_s: float
    """Start of the epoch's first chirp, s."""
    chirp_start_s: np.ndarray
    """``(J,)`` chirp starts, s."""
    samples: np.ndarray
    """complex64 ``(J, K, M, N)``, sqrt(W)."""


# --------------------------------------------------------------------------
# writing


def channel_map(metadata: dict) -> list[dict]:
    """The SigMF channel order: ``{"channel", "tag", "antenna", "tag_shift_hz"}`` (tag-major)."""
    shifts = metadata["tag_shifts_hz"]
    antennas = len(metadata["array_offsets_m"])
    return [
        {"channel": k * antennas + m, "tag": k, "antenna": m, "tag_shift_hz": float(shifts[k])}
        for k in range(len(shifts))
        for m in range(antennas)
    ]


def write_lora_sigmf(
    path,
    recording: LoraRecording,
    *,
    datatype: str = "ci16_le",
    scale: float | None = None,
    headroom_db: float = 1.0,
) -> tuple[Path, Path]:
    """Write ``PATH.sigmf-data`` and ``PATH.sigmf-meta`` (validated, with the data's SHA-512).

    ``datatype``: ``ci16_le`` (4 bytes per sample and channel) or
    ``cf32_le`` (8 bytes, lossless for complex64). ``scale``: stored =
    scale x physical; default for ``ci16_le`` puts the largest I/Q component
    ``headroom_db`` below 32767 (so nothing clips and the quantisation step
    is as fine as the recording allows), for ``cf32_le`` 1. The data is
    written one epoch at a time. Returns ``(meta, data)`` paths.
    """
    import sigmf

    if datatype not in DATATYPES:
        raise ValueError(f"datatype must be one of {sorted(DATATYPES)}, got {datatype!r}")
    samples = recording.samples
    if samples.ndim != 5:
        raise ValueError(f"samples must be (epochs, J, K, M, N), got shape {samples.shape}")
    epochs, n_excitation, n_tags, n_antennas, n = samples.shape
    metadata = recording.metadata
    if n != int(metadata["samples_per_chirp"]):
        raise ValueError(f"samples hold {n} samples per chirp but metadata says {metadata['samples_per_chirp']}")
    if scale is None:
        if datatype == "ci16_le":
            # The largest component over the whole recording, one epoch at a time (bounded memory).
            peak = max((float(np.abs(samples[e].view(np.float32)).max()) for e in range(epochs)), default=0.0)
            scale = 32767.0 * 10.0 ** (-headroom_db / 20.0) / peak if peak > 0 else 1.0
        else:
            scale = 1.0
    scale = float(scale)
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a positive number, got {scale!r}")

    base = _base(path)
    meta_path, data_path = Path(f"{base}.sigmf-meta"), Path(f"{base}.sigmf-data")
    meta_path.parent.mkdir(parents=True, exist_ok=True)
    channels = n_tags * n_antennas
    with open(data_path, "wb") as handle:
        for e in range(epochs):
            # (J, K, M, N) -> (J, N, K, M) -> (J N, K M): sample-major, channel = k M + m.
            block = np.ascontiguousarray(np.transpose(samples[e], (0, 3, 1, 2))).reshape(n_excitation * n, channels)
            stored = block * np.float32(scale)
            if datatype == "ci16_le":
                parts = np.stack([stored.real, stored.imag], axis=-1)
                out = np.clip(np.rint(parts), -32768, 32767).astype("<i2")
            else:
                out = stored.astype("<c8")
            out.tofile(handle)

    frequencies = metadata["channel_frequencies_hz"]
    excitation = metadata["excitation_channels"]
    captures = []
    for e in range(epochs):
        for j in range(n_excitation):
            captures.append({
                "core:sample_start": (e * n_excitation + j) * n,
                "core:frequency": float(frequencies[int(excitation[j])]),
                f"{NAMESPACE}:epoch": e,
                f"{NAMESPACE}:excitation": j,
                f"{NAMESPACE}:channel_index": int(excitation[j]),
                f"{NAMESPACE}:time_s": float(recording.chirp_start_s[e, j]),
            })
    global_info = {
        sigmf.DATATYPE_KEY: datatype,
        sigmf.SAMPLE_RATE_KEY: float(metadata.get("sample_rate_hz", metadata["bandwidth_hz"])),
        sigmf.NUM_CHANNELS_KEY: channels,
        sigmf.DESCRIPTION_KEY: "Marvel LoRa-backscatter controller: channelised tag x antenna streams (scattertrack)",
        sigmf.EXTENSIONS_KEY: [{"name": NAMESPACE, "version": "0.1.0", "optional": False}],
    }
    for key, value in metadata.items():
        global_info[f"{NAMESPACE}:{key}"] = value
    global_info[f"{NAMESPACE}:scale"] = scale
    global_info[f"{NAMESPACE}:layout"] = LORA_LAYOUT
    global_info[f"{NAMESPACE}:channel_map"] = channel_map(metadata)
    handle = sigmf.SigMFFile(global_info=global_info)
    handle.set_data_file(data_path)
    # Set directly: add_capture recounts the samples on every call.
    handle._metadata["captures"] = captures
    handle._metadata["annotations"] = []
    handle.tofile(base, overwrite=True)
    return meta_path, data_path


# --------------------------------------------------------------------------
# reading


class LoraSigmf:
    """An open, validated recording: metadata, chirp times and a memory map of the samples.

    ``epoch(e)`` converts one epoch to complex64 ``(J, K, M, N)`` in physical
    units; iterating yields :class:`LoraEpoch` one at a time, so a long
    recording streams in the memory of one epoch (2 x 12 x 4096 samples =
    0.8 MB at the defaults).
    """

    def __init__(self, path):
        base = _base(path)
        self.meta_path = Path(f"{base}.sigmf-meta")
        self.data_path = Path(f"{base}.sigmf-data")
        self.meta = _load_meta(self.meta_path)
        g = self.meta["global"]
        self.metadata = {
            key[len(NAMESPACE) + 1 :]: value
            for key, value in g.items()
            if key.startswith(f"{NAMESPACE}:") and key[len(NAMESPACE) + 1 :] not in FILE_KEYS
        }
        self.datatype, self.scale, shape = _check_global(self.meta_path, g)
        self.n_excitation, self.n_tags, self.n_antennas, self.samples_per_chirp = shape
        self.chirp_start_s = _check_captures(self.meta_path, self.meta["captures"], g, shape)
        self.n_epochs = self.chirp_start_s.shape[0]
        self._data = _map_data(self.data_path, self.datatype, self.n_epochs, shape)

    def __len__(self) -> int:
        return self.n_epochs

    @property
    def epoch_time_s(self) -> np.ndarray:
        return self.chirp_start_s[:, 0].copy()

    def epoch(self, e: int) -> np.ndarray:
        """Epoch ``e`` as complex64 ``(J, K, M, N)``, physical units (stored / scale)."""
        if not 0 <= e < self.n_epochs:
            raise IndexError(f"epoch {e} out of range (0..{self.n_epochs - 1})")
        block = self._data[e]  # (J, N, K, M[, 2])
        if self.datatype == "ci16_le":
            values = block[..., 0].astype(np.float32) + 1j * block[..., 1].astype(np.float32)
        else:
            values = np.asarray(block)
        values = np.transpose(values, (0, 2, 3, 1)) / np.float32(self.scale)
        return np.ascontiguousarray(values, dtype=np.complex64)

    def __iter__(self) -> Iterator[LoraEpoch]:
        for e in range(self.n_epochs):
            yield LoraEpoch(e, float(self.chirp_start_s[e, 0]), self.chirp_start_s[e].copy(), self.epoch(e))

    def read(self) -> LoraRecording:
        """The whole recording in memory (``epochs x 0.8 MB`` at the defaults)."""
        samples = np.empty(
            (self.n_epochs, self.n_excitation, self.n_tags, self.n_antennas, self.samples_per_chirp), dtype=np.complex64
        )
        for e in range(self.n_epochs):
            samples[e] = self.epoch(e)
        return LoraRecording(samples, self.epoch_time_s, self.chirp_start_s.copy(), dict(self.metadata), {})


def open_lora_sigmf(path) -> LoraSigmf:
    """Open and validate a recording (``NAME``, ``NAME.sigmf-meta`` or ``NAME.sigmf-data``); samples stay on disk."""
    return LoraSigmf(path)


def read_lora_sigmf(meta_path) -> LoraRecording:
    """Read and validate a whole recording into a :class:`LoraRecording` (``details`` empty).

    Raises :class:`FormatError` naming the file and the field or byte offset
    (module docstring).
    """
    return LoraSigmf(meta_path).read()


def iter_epochs(meta_path) -> Iterator[LoraEpoch]:
    """Stream a recording epoch by epoch from a memory map (validated first, like :func:`read_lora_sigmf`)."""
    return iter(LoraSigmf(meta_path))


def _check_global(meta_path: Path, g: dict) -> tuple[str, float, tuple[int, int, int, int]]:
    """Validate the global keys; returns ``(datatype, scale, (J, K, M, N))``."""
    ns = NAMESPACE

    def fail(key, message):
        raise FormatError(meta_path, None, f"global.{key}", message)

    for key in ("core:datatype", "core:sample_rate", "core:num_channels", f"{ns}:scale") + tuple(
        f"{ns}:{k}" for k in REQUIRED_METADATA
    ):
        if key not in g:
            fail(key, "missing required key")

    def number(key, positive=True):
        return _global_number(meta_path, g, key, positive)

    def integer(key, low):
        value = g[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            fail(key, f"must be an integer >= {low}, got {value!r}")
        return int(value)

    def array(key, shape):
        try:
            values = np.asarray(g[key], dtype=np.float64)
        except (TypeError, ValueError):
            values = None
        if values is None:
            fail(key, f"must be numbers of shape {shape}, got {g[key]!r}")
        if values.shape != shape:
            fail(key, f"must have shape {shape}, got {values.shape}")
        if not np.isfinite(values).all():
            fail(key, "must be finite numbers")
        return values

    datatype = g["core:datatype"]
    if datatype not in DATATYPES:
        fail("core:datatype", f"unsupported datatype {datatype!r} (supported: {', '.join(DATATYPES)})")
    if "core:dataset" in g:
        fail("core:dataset", "non-conforming datasets are not supported")
    bandwidth = number(f"{ns}:bandwidth_hz")
    rate = number("core:sample_rate")
    if abs(rate - bandwidth) > 1e-9 * bandwidth:
        fail("core:sample_rate", f"must equal {ns}:bandwidth_hz ({bandwidth} Hz): the dechirp needs fs = BW; got {rate!r} Hz")
    sf = integer(f"{ns}:spreading_factor", 6)
    if sf > 12:
        fail(f"{ns}:spreading_factor", f"must be 6..12, got {sf}")
    n = integer(f"{ns}:samples_per_chirp", 1)
    if n != 2**sf:
        fail(f"{ns}:samples_per_chirp", f"must be 2^spreading_factor = {2**sf}, got {n}")
    frequencies = g[f"{ns}:channel_frequencies_hz"]
    if not isinstance(frequencies, list) or not frequencies:
        fail(f"{ns}:channel_frequencies_hz", f"must be a non-empty list of frequencies, got {frequencies!r}")
    frequencies = array(f"{ns}:channel_frequencies_hz", (len(frequencies),))
    if np.any(frequencies <= 0):
        fail(f"{ns}:channel_frequencies_hz", "must be positive")
    excitation = g[f"{ns}:excitation_channels"]
    if (not isinstance(excitation, list) or not excitation
            or not all(isinstance(i, int) and not isinstance(i, bool) and 0 <= i < len(frequencies) for i in excitation)):
        fail(f"{ns}:excitation_channels", f"must be a non-empty list of channel numbers 0..{len(frequencies) - 1}, got {excitation!r}")
    shifts = g[f"{ns}:tag_shifts_hz"]
    if not isinstance(shifts, list) or not shifts:
        fail(f"{ns}:tag_shifts_hz", f"must be a non-empty list of frequencies, got {shifts!r}")
    array(f"{ns}:tag_shifts_hz", (len(shifts),))
    n_tags = len(shifts)
    array(f"{ns}:tag_body_positions_m", (n_tags, 3))
    offsets = g[f"{ns}:array_offsets_m"]
    if not isinstance(offsets, list) or not offsets:
        fail(f"{ns}:array_offsets_m", f"must be a non-empty list of [x, y, z], got {offsets!r}")
    n_antennas = len(offsets)
    array(f"{ns}:array_offsets_m", (n_antennas, 3))
    array(f"{ns}:rx_phase_offsets_rad", (len(excitation), n_tags, n_antennas))
    number(f"{ns}:sensing_rate_hz")
    scale = number(f"{ns}:scale")
    channels = g["core:num_channels"]
    if channels != n_tags * n_antennas:
        fail("core:num_channels", f"is {channels!r} but {ns}:tag_shifts_hz x {ns}:array_offsets_m gives {n_tags} x {n_antennas}")
    return datatype, scale, (len(excitation), n_tags, n_antennas, n)


def _check_captures(meta_path: Path, captures: list, g: dict, shape) -> np.ndarray:
    """Validate that the captures tile the data chirp by chirp; returns chirp starts ``(epochs, J)``, s."""
    ns = NAMESPACE
    n_excitation, _, _, n = shape
    if not captures:
        raise FormatError(meta_path, None, "captures", "no capture: a recording needs one per chirp")
    if len(captures) % n_excitation:
        raise FormatError(
            meta_path, None, "captures",
            f"{len(captures)} captures is not a whole number of epochs ({n_excitation} chirps each)",
        )
    frequencies = g[f"{ns}:channel_frequencies_hz"]
    excitation = g[f"{ns}:excitation_channels"]
    times = np.empty(len(captures))

    def fail(i, key, message):
        raise FormatError(meta_path, None, f"captures[{i}].{key}", message)

    for i, capture in enumerate(captures):
        e, j = divmod(i, n_excitation)
        if capture.get("core:sample_start") != i * n:
            fail(i, "core:sample_start", f"must be {i * n} (chirp {i} of {n} samples), got {capture.get('core:sample_start')!r}")
        frequency = capture.get("core:frequency")
        expected = float(frequencies[excitation[j]])
        if isinstance(frequency, bool) or not isinstance(frequency, (int, float)) or abs(frequency - expected) > 1e-6 * expected:
            fail(i, "core:frequency", f"must be excitation channel {excitation[j]}'s {expected} Hz, got {frequency!r}")
        if capture.get(f"{ns}:epoch") != e:
            fail(i, f"{ns}:epoch", f"must be {e}, got {capture.get(f'{ns}:epoch')!r}")
        if capture.get(f"{ns}:excitation") != j:
            fail(i, f"{ns}:excitation", f"must be {j}, got {capture.get(f'{ns}:excitation')!r}")
        time_s = capture.get(f"{ns}:time_s")
        if isinstance(time_s, bool) or not isinstance(time_s, (int, float)) or not np.isfinite(time_s):
            fail(i, f"{ns}:time_s", f"missing or not a finite number: {time_s!r}")
        if i and time_s <= times[i - 1]:
            fail(i, f"{ns}:time_s", f"chirps must start at increasing times ({time_s} after {times[i - 1]})")
        times[i] = time_s
    return times.reshape(-1, n_excitation)


def _map_data(data_path: Path, datatype: str, epochs: int, shape) -> np.memmap:
    """Memory map of the data as ``(epochs, J, N, K, M[, 2])``; checks the file's size byte by byte."""
    n_excitation, n_tags, n_antennas, n = shape
    if not data_path.is_file():
        raise FormatError(data_path, None, None, "data file not found")
    size = data_path.stat().st_size
    per_sample = DATATYPES[datatype] * n_tags * n_antennas
    per_chirp = per_sample * n
    expected = per_chirp * n_excitation * epochs
    if size % per_sample:
        whole = size // per_sample * per_sample
        raise FormatError(
            data_path, None, None,
            f"{size} bytes is not a whole number of samples ({per_sample} bytes each: {n_tags * n_antennas} channels x "
            f"{datatype}); truncated? the last whole sample ends at byte offset {whole}",
        )
    if size < expected:
        chirp = size // per_chirp
        raise FormatError(
            data_path, None, f"captures[{chirp}]",
            f"truncated: the data ends at byte offset {size} inside chirp {chirp} (epoch {chirp // n_excitation}), "
            f"which runs from byte offset {chirp * per_chirp} to {(chirp + 1) * per_chirp}; the captures need {expected} bytes",
        )
    if size > expected:
        raise FormatError(
            data_path, None, None,
            f"size does not match the captures: {size} bytes, expected {expected} ({epochs} epochs x "
            f"{n_excitation} chirps x {n} samples x {per_sample} bytes); extra bytes from byte offset {expected}",
        )
    if datatype == "ci16_le":
        return np.memmap(data_path, dtype="<i2", mode="r", shape=(epochs, n_excitation, n, n_tags, n_antennas, 2))
    return np.memmap(data_path, dtype="<c8", mode="r", shape=(epochs, n_excitation, n, n_tags, n_antennas))
