"""Raw IQ recordings of the SDR localization helper as SigMF: the format, read and written.

A recording is a SigMF pair (``NAME.sigmf-meta`` JSON + ``NAME.sigmf-data``
samples; SigMF specification 1.2, written with the ``sigmf`` package) that
holds only the short windows the helper opens after each reader Query
(thesis sec. 4.3), back to back.

Data layout
    ``core:datatype`` ``ci16_le`` (int16 I, Q) or ``cf32_le`` (float32 I, Q);
    ``core:num_channels`` = number of receive antennas, interleaved per
    sample (sample ``n`` holds one I/Q pair per channel, in the order of
    ``scattertrack:channels``); ``core:sample_rate`` = the OFDM bandwidth B.
    Stored values are ``scattertrack:scale`` times the physical baseband
    (the simulator's channel units), so recordings of different gains can
    share one calibration.
Windows
    One SigMF capture per window: ``core:sample_start`` (in samples of the
    file), ``core:frequency`` (Hz), ``scattertrack:time_s`` (window start on
    the reader/helper clock, s) and ``scattertrack:tx_sample_index`` (index
    of the window's first sample in the transmitter's sample stream: tx and
    rx share one clock, so this is exact). A window runs to the next
    capture (or the end of the data). One annotation per window
    (``core:sample_start``, ``core:sample_count``, ``core:label``) carries
    the tag the reader queried, ``scattertrack:epc``, and
    ``scattertrack:query_end_s``.
Global ``scattertrack:`` keys (extension declared in ``core:extensions``)
    ``bandwidth_hz`` (B), ``subcarriers`` (N, the FFT size), ``centre_hz``,
    ``blf_hz`` (commanded), ``encoding`` (``fm0``, ``miller2|4|8``),
    ``trext``, ``known_symbol`` (N ``[re, im]`` pairs, FFT order, DC 0),
    ``tx_id``, ``channels`` (rx ids, channel order), ``antennas`` (``id``,
    ``position`` m, ``role``), ``layout`` (a sentence), ``scale``,
    ``window_s``, and optionally ``seed``, ``model``, ``generator``,
    ``version``, ``scene`` and, in a calibration recording,
    ``calibration`` = ``{"epc", "tag_position"}`` (m).

Contract: :func:`read_sigmf` validates everything and raises
:class:`FormatError` naming the file (``.sigmf-meta`` or ``.sigmf-data``)
and the field (``global.core:datatype``, ``captures[3].core:sample_start``)
or the byte offset, for bad JSON, a schema violation, a missing or bad key,
an unsupported datatype, a design that breaks ``N < B / (2 BLF)``, an
antenna list that contradicts ``tx_id`` or ``channels``, or a data file
missing or whose length is not a whole number of samples. The DSP that turns a
recording into frames (channel estimation, calibration, the scene's
antennas) is :mod:`scattertrack.dsp.ofdm`: this module knows the format only.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scattertrack.io.sigmf_scene import check_antennas
from scattertrack.io.types import FormatError

NAMESPACE = "scattertrack"
"""The SigMF extension namespace of every scattertrack key."""

DATATYPES = {"ci16_le": 4, "cf32_le": 8}
"""Supported ``core:datatype`` values and their bytes per (complex) sample and channel."""

LAYOUT = (
    "core:num_channels receive channels interleaved per sample in the order of scattertrack:channels; "
    "one capture per recorded window; stored values = scattertrack:scale x physical baseband"
)

REQUIRED_GLOBAL = (
    "core:datatype",
    "core:sample_rate",
    "core:num_channels",
    f"{NAMESPACE}:bandwidth_hz",
    f"{NAMESPACE}:subcarriers",
    f"{NAMESPACE}:centre_hz",
    f"{NAMESPACE}:blf_hz",
    f"{NAMESPACE}:encoding",
    f"{NAMESPACE}:trext",
    f"{NAMESPACE}:known_symbol",
    f"{NAMESPACE}:tx_id",
    f"{NAMESPACE}:channels",
    f"{NAMESPACE}:antennas",
    f"{NAMESPACE}:scale",
)


@dataclass
class Window:
    """One recorded window (a SigMF capture)."""

    index: int
    sample_start: int
    """First sample in the data file."""
    sample_count: int
    time_s: float
    """Window start on the reader/helper clock, s."""
    tx_sample_index: int | None
    """Index of the first sample in the transmitter's stream (None if not recorded)."""
    epc: str | None
    """The tag the reader queried (from the window's annotation)."""


@dataclass
class Recording:
    """A SigMF recording: metadata and samples (memory-mapped when read from a file)."""

    path: Path | None
    """The ``.sigmf-meta`` file (None in memory)."""
    data_path: Path | None
    meta: dict
    """The whole metadata: ``global``, ``captures``, ``annotations``."""
    data: np.ndarray
    """``ci16_le``: int16 (samples, channels, 2); ``cf32_le``: complex64 (samples, channels)."""
    datatype: str
    windows: list[Window] = field(default_factory=list)
    """Filled by :func:`read_sigmf`."""

    def _g(self, key: str):
        return self.meta["global"][f"{NAMESPACE}:{key}"]

    @property
    def bandwidth_hz(self) -> float:
        return float(self._g("bandwidth_hz"))

    @property
    def subcarriers(self) -> int:
        """N, the FFT size (N - 1 active subcarriers)."""
        return int(self._g("subcarriers"))

    @property
    def centre_hz(self) -> float:
        return float(self._g("centre_hz"))

    @property
    def blf_hz(self) -> float:
        return float(self._g("blf_hz"))

    @property
    def encoding(self) -> str:
        return str(self._g("encoding"))

    @property
    def trext(self) -> bool:
        return bool(self._g("trext"))

    @property
    def known_symbol(self) -> np.ndarray:
        """X[k], complex128 (N,), FFT order."""
        pairs = np.asarray(self._g("known_symbol"), dtype=np.float64)
        return pairs[:, 0] + 1j * pairs[:, 1]

    @property
    def tx_id(self) -> int:
        return int(self._g("tx_id"))

    @property
    def channels(self) -> list[int]:
        """Receive antenna id of each channel, in channel order."""
        return [int(c) for c in self._g("channels")]

    @property
    def scale(self) -> float:
        return float(self._g("scale"))

    @property
    def calibration(self) -> dict | None:
        """``{"epc", "tag_position"}`` of a calibration recording, else None."""
        return self.meta["global"].get(f"{NAMESPACE}:calibration")

    @property
    def n_samples(self) -> int:
        return int(self.data.shape[0])

    def window_samples(self, k: int) -> np.ndarray:
        """Window ``k`` as complex64 (channels, samples) in physical units (stored / scale)."""
        w = self.windows[k]
        block = self.data[w.sample_start : w.sample_start + w.sample_count]
        if self.datatype == "ci16_le":
            values = block[..., 0].astype(np.float32) + 1j * block[..., 1].astype(np.float32)
        else:
            values = np.asarray(block)
        return np.ascontiguousarray((values / np.float32(self.scale)).T, dtype=np.complex64)


# --------------------------------------------------------------------------
# writing


def make_recording_metadata(
    *,
    datatype: str,
    bandwidth_hz: float,
    subcarriers: int,
    centre_hz: float,
    blf_hz: float,
    encoding: str,
    trext: bool,
    known_symbol,
    tx_id: int,
    channels: list[int],
    antennas: list[dict],
    scale: float,
    window_s: float,
    extra: dict | None = None,
) -> dict:
    """The ``global`` object of a helper recording (keys in the module docstring).

    ``known_symbol``: N complex values, FFT order. ``extra``: more
    ``scattertrack:`` keys (``seed``, ``model``, ...).
    """
    import sigmf

    symbol = np.asarray(known_symbol, dtype=np.complex128)
    out = {
        sigmf.DATATYPE_KEY: datatype,
        sigmf.SAMPLE_RATE_KEY: float(bandwidth_hz),
        sigmf.NUM_CHANNELS_KEY: len(channels),
        sigmf.DESCRIPTION_KEY: "SDR localization helper windows (scattertrack, TurboTrack thesis ch. 4)",
        sigmf.EXTENSIONS_KEY: [{"name": NAMESPACE, "version": "0.1.0", "optional": False}],
        f"{NAMESPACE}:bandwidth_hz": float(bandwidth_hz),
        f"{NAMESPACE}:subcarriers": int(subcarriers),
        f"{NAMESPACE}:centre_hz": float(centre_hz),
        f"{NAMESPACE}:blf_hz": float(blf_hz),
        f"{NAMESPACE}:encoding": str(encoding),
        f"{NAMESPACE}:trext": bool(trext),
        f"{NAMESPACE}:known_symbol": [[float(v.real), float(v.imag)] for v in symbol],
        f"{NAMESPACE}:tx_id": int(tx_id),
        f"{NAMESPACE}:channels": [int(c) for c in channels],
        f"{NAMESPACE}:antennas": antennas,
        f"{NAMESPACE}:layout": LAYOUT,
        f"{NAMESPACE}:scale": float(scale),
        f"{NAMESPACE}:window_s": float(window_s),
    }
    for key, value in (extra or {}).items():
        out[f"{NAMESPACE}:{key}"] = value
    return out


def write_sigmf(path, recording: Recording) -> tuple[Path, Path]:
    """Write ``PATH.sigmf-data`` (the samples) and ``PATH.sigmf-meta`` (validated, with its SHA-512).

    ``path`` without or with either extension. Returns ``(meta, data)`` paths.
    """
    import sigmf

    base = _base(path)
    meta_path, data_path = Path(f"{base}.sigmf-meta"), Path(f"{base}.sigmf-data")
    meta_path.parent.mkdir(parents=True, exist_ok=True)
    np.ascontiguousarray(recording.data).tofile(data_path)
    handle = sigmf.SigMFFile(global_info=dict(recording.meta["global"]))
    handle.set_global_field(sigmf.DATATYPE_KEY, recording.datatype)
    handle.set_data_file(data_path)
    # Set directly: add_capture / add_annotation recount the samples on every call.
    handle._metadata["captures"] = [dict(c) for c in recording.meta["captures"]]
    handle._metadata["annotations"] = [dict(a) for a in recording.meta["annotations"]]
    handle.tofile(base, overwrite=True)
    return meta_path, data_path


def _base(path) -> str:
    text = str(path)
    for suffix in (".sigmf-meta", ".sigmf-data"):
        if text.endswith(suffix):
            return text[: -len(suffix)]
    return text


# --------------------------------------------------------------------------
# reading


def read_sigmf(path, verify_checksum: bool = False) -> Recording:
    """Read and validate a helper recording; the samples are memory-mapped.

    ``path``: ``NAME``, ``NAME.sigmf-meta`` or ``NAME.sigmf-data``. With
    ``verify_checksum`` the data's SHA-512 is checked against ``core:sha512``.
    Raises :class:`FormatError` naming the file and the field or byte offset
    (module docstring).
    """
    base = _base(path)
    meta_path, data_path = Path(f"{base}.sigmf-meta"), Path(f"{base}.sigmf-data")
    meta = _load_meta(meta_path)
    g = meta["global"]
    for key in REQUIRED_GLOBAL:
        if key not in g:
            raise FormatError(meta_path, None, f"global.{key}", "missing required key")
    datatype = g["core:datatype"]
    if datatype not in DATATYPES:
        raise FormatError(
            meta_path, None, "global.core:datatype", f"unsupported datatype {datatype!r} (supported: {', '.join(DATATYPES)})"
        )
    if "core:dataset" in g or any("core:header_bytes" in c for c in meta["captures"]):
        raise FormatError(meta_path, None, "global.core:dataset", "non-conforming datasets are not supported")
    channels = _check_header(meta_path, g)
    check_antennas(meta_path, g)

    if not data_path.is_file():
        raise FormatError(data_path, None, None, "data file not found")
    size = data_path.stat().st_size
    per_sample = DATATYPES[datatype] * channels
    if size == 0:
        raise FormatError(data_path, None, None, "empty data file")
    if size % per_sample:
        whole = size // per_sample
        raise FormatError(
            data_path, None, None,
            f"{size} bytes is not a whole number of samples ({per_sample} bytes each: {channels} channels x "
            f"{datatype}); truncated? the last whole sample ends at byte offset {whole * per_sample}",
        )
    n_samples = size // per_sample
    if verify_checksum and "core:sha512" in g:
        digest = hashlib.sha512(data_path.read_bytes()).hexdigest()
        if digest != g["core:sha512"]:
            raise FormatError(data_path, None, None, "SHA-512 does not match global.core:sha512 (corrupt data)")
    if datatype == "ci16_le":
        data = np.memmap(data_path, dtype="<i2", mode="r", shape=(n_samples, channels, 2))
    else:
        data = np.memmap(data_path, dtype="<c8", mode="r", shape=(n_samples, channels))
    windows = _windows(meta_path, data_path, meta, n_samples)
    return Recording(meta_path, data_path, meta, data, datatype, windows)


def _global_number(meta_path, global_info: dict, key: str, positive: bool = True) -> float:
    """A finite (and, if ``positive``, > 0) number of the metadata's ``global`` object; a
    FormatError naming the file and ``global.KEY`` otherwise."""
    value = global_info[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise FormatError(meta_path, None, f"global.{key}", f"must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise FormatError(meta_path, None, f"global.{key}", f"must be positive, got {value!r}")
    return float(value)


def _load_meta(meta_path: Path) -> dict:
    """The metadata JSON, checked against the SigMF schema."""
    import jsonschema
    import sigmf.validate

    if not meta_path.is_file():
        raise FormatError(meta_path, None, None, "metadata file not found")
    try:
        text = meta_path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise FormatError(meta_path, None, None, f"not UTF-8 text: {error}") from None
    try:
        meta = json.loads(text)
    except json.JSONDecodeError as error:
        raise FormatError(meta_path, error.lineno, None, f"not valid JSON: {error.msg} (column {error.colno})") from None
    if not isinstance(meta, dict):
        raise FormatError(meta_path, None, None, "the metadata must be a JSON object")
    for key, kind in (("global", dict), ("captures", list), ("annotations", list)):
        if not isinstance(meta.get(key), kind):
            raise FormatError(meta_path, None, key, f"missing or not a JSON {'object' if kind is dict else 'array'}")
    _check_capture_order(meta_path, meta["captures"])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sigmf.validate.validate(meta)
    except jsonschema.ValidationError as error:
        where = ".".join(str(p) for p in error.absolute_path) or None
        raise FormatError(meta_path, None, where, f"violates the SigMF schema: {error.message}") from None
    return meta


def _check_capture_order(meta_path: Path, captures: list) -> None:
    """Name the first capture whose ``core:sample_start`` is not after the previous one's (the
    SigMF schema check says only that the order is wrong, not where)."""
    previous = None
    for i, capture in enumerate(captures):
        start = capture.get("core:sample_start") if isinstance(capture, dict) else None
        if isinstance(start, bool) or not isinstance(start, int):
            continue  # the schema names a missing or non-integer start
        if previous is not None and start <= previous:
            raise FormatError(meta_path, None, f"captures[{i}].core:sample_start",
                              f"captures must start at increasing samples: {start} after {previous}")
        previous = start


def _check_header(meta_path: Path, g: dict) -> int:
    """Validate the helper's global keys; returns the number of channels."""
    from scattertrack import _core

    def fail(key, message):
        raise FormatError(meta_path, None, f"global.{key}", message)

    def number(key, positive=True):
        return _global_number(meta_path, g, key, positive)

    ns = NAMESPACE
    bandwidth = number(f"{ns}:bandwidth_hz")
    if abs(number("core:sample_rate") - bandwidth) > 1e-6 * bandwidth:
        fail("core:sample_rate", f"must equal {ns}:bandwidth_hz ({bandwidth} Hz), got {g['core:sample_rate']!r}")
    n = g[f"{ns}:subcarriers"]
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        fail(f"{ns}:subcarriers", f"must be an integer >= 2, got {n!r}")
    centre, blf = number(f"{ns}:centre_hz"), number(f"{ns}:blf_hz")
    number(f"{ns}:scale")
    if g[f"{ns}:encoding"] not in ("fm0", "miller2", "miller4", "miller8"):
        fail(f"{ns}:encoding", f"must be fm0, miller2, miller4 or miller8, got {g[f'{ns}:encoding']!r}")
    if not isinstance(g[f"{ns}:trext"], bool):
        fail(f"{ns}:trext", f"must be true or false, got {g[f'{ns}:trext']!r}")
    try:
        _core.dsp_subcarrier_frequencies(bandwidth, n, centre, blf)
    except ValueError as error:
        fail(f"{ns}:subcarriers", str(error))
    symbol = g[f"{ns}:known_symbol"]
    try:
        pairs = np.asarray(symbol, dtype=np.float64)
    except (TypeError, ValueError):
        pairs = None
    if pairs is None or pairs.shape != (n, 2) or not np.isfinite(pairs).all():
        fail(f"{ns}:known_symbol", f"must be {n} finite [re, im] pairs")
    magnitude = np.hypot(pairs[:, 0], pairs[:, 1])
    if magnitude[0] > 1e-9 or np.any(np.abs(magnitude[1:] - 1.0) > 1e-6):
        fail(f"{ns}:known_symbol", "bin 0 (DC) must be 0 and every other bin of unit magnitude")
    channels = g[f"{ns}:channels"]
    if not isinstance(channels, list) or not channels or not all(isinstance(c, int) for c in channels):
        fail(f"{ns}:channels", f"must be a non-empty list of antenna ids, got {channels!r}")
    if len(set(channels)) != len(channels):
        fail(f"{ns}:channels", f"antenna ids repeat: {channels}")
    if g["core:num_channels"] != len(channels):
        fail("core:num_channels", f"is {g['core:num_channels']!r} but {ns}:channels lists {len(channels)} antennas")
    if not isinstance(g[f"{ns}:tx_id"], int):
        fail(f"{ns}:tx_id", f"must be an integer antenna id, got {g[f'{ns}:tx_id']!r}")
    return len(channels)


def _windows(meta_path: Path, data_path: Path, meta: dict, n_samples: int) -> list[Window]:
    """The windows (captures) with their annotations' tags; checks sample ranges against the data."""
    ns = NAMESPACE
    captures = meta["captures"]
    if not captures:
        raise FormatError(meta_path, None, "captures", "no capture: a recording needs one per window")
    epc_at = {}
    for i, annotation in enumerate(meta["annotations"]):
        start = annotation["core:sample_start"]
        count = annotation.get("core:sample_count", 0)
        if start + count > n_samples:
            raise FormatError(
                data_path, None, f"annotations[{i}]",
                f"ends at sample {start + count} but the data holds {n_samples} samples (truncated at byte offset "
                f"{data_path.stat().st_size})",
            )
        if f"{ns}:epc" in annotation:
            epc_at[start] = str(annotation[f"{ns}:epc"])
    windows = []
    for i, capture in enumerate(captures):
        start = capture["core:sample_start"]
        end = captures[i + 1]["core:sample_start"] if i + 1 < len(captures) else n_samples
        if start >= n_samples:
            raise FormatError(
                data_path, None, f"captures[{i}].core:sample_start",
                f"window starts at sample {start} but the data holds {n_samples} samples (truncated at byte offset "
                f"{data_path.stat().st_size})",
            )
        if end <= start:
            raise FormatError(meta_path, None, f"captures[{i + 1}].core:sample_start", "captures must start at increasing samples")
        time_s = capture.get(f"{ns}:time_s")
        if isinstance(time_s, bool) or not isinstance(time_s, (int, float)) or not np.isfinite(time_s):
            raise FormatError(meta_path, None, f"captures[{i}].{ns}:time_s", f"missing or not a finite number: {time_s!r}")
        tx_index = capture.get(f"{ns}:tx_sample_index")
        if tx_index is not None and (isinstance(tx_index, bool) or not isinstance(tx_index, int) or tx_index < 0):
            raise FormatError(meta_path, None, f"captures[{i}].{ns}:tx_sample_index", f"must be a non-negative integer, got {tx_index!r}")
        windows.append(Window(i, int(start), int(end - start), float(time_s), tx_index, epc_at.get(start)))
    return windows
