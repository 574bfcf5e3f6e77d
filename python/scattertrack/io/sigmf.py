"""Raw IQ recordings of the SDR localization helper as SigMF, and their channel estimation.

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
missing or whose length is not a whole number of samples. Tracked in a
scene, a recording whose antenna positions differ from the scene's by more
than 5 cm is warned (:mod:`scattertrack.io.sigmf_scene`). :func:`read_sigmf_frames` runs the Rust
DSP (``scattertrack._core.OfdmDsp``) over every window and returns
:class:`Frames` (docs/formats.md section 5); windows without a detectable
preamble, all-NaN windows and failed receive antennas are skipped and
counted in ``Frames.skipped`` (examples: 0-based window indices).
"""

from __future__ import annotations

import hashlib
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scattertrack.io.frames import Frames, make_frames
from scattertrack.io.sigmf_scene import finite_vector, check_antennas, check_calibration, warn_scene_disagreement
from scattertrack.io.types import FormatError, Scene, SkipReport

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

SKIP_NO_PREAMBLE = "no preamble"
SKIP_NON_FINITE = "non-finite window"
SKIP_TOO_SHORT = "window too short"
SKIP_NO_CLEAN = "no clean symbols"
SKIP_RX = "receive antenna failed"
"""Reasons counted in ``Frames.skipped`` (the last per receive antenna of a reply)."""

_SKIP_BY_KIND = {
    "no-preamble": SKIP_NO_PREAMBLE,
    "non-finite": SKIP_NON_FINITE,
    "too-short": SKIP_TOO_SHORT,
    "no-clean-symbols": SKIP_NO_CLEAN,
}


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


# --------------------------------------------------------------------------
# channel estimation


@dataclass
class SigmfCalibration:
    """Per-(rx, subcarrier) correction from a tag at a known position (thesis sec. 4.3)."""

    correction: np.ndarray
    """C (R, F) complex128: calibrated = C x measured."""
    rx_ids: list[int]
    frequencies_hz: np.ndarray
    """Active subcarriers (F,), Hz, ascending."""
    timing_reference: list[int] | None
    """Per-rx symbol timing reference learnt on the calibration windows (see the DSP's ``process``)."""
    tag_position: np.ndarray
    replies: int
    """Replies averaged."""
    source: str


@dataclass
class SigmfEstimate:
    """What :func:`estimate_sigmf` found: the frames and per-reply diagnostics."""

    frames: Frames
    """docs/formats.md section 5 frames; ``frames.skipped`` counts what was declined."""
    window: np.ndarray
    """Window index of each frame (n_frames,), in the order of the recording."""
    score: np.ndarray
    """Normalised preamble correlation of each frame."""
    blf_hz: np.ndarray
    """Estimated tag BLF of each frame, Hz."""
    variance: np.ndarray
    """Variance of each channel estimate, (n_frames, R, F), in calibrated units."""
    symbols_used: np.ndarray
    """Reflective + non-reflective symbols averaged per frame (first rx that worked)."""
    symbols_edge: np.ndarray
    """Symbols discarded by edge-flip elimination per frame."""

    @property
    def skipped(self) -> SkipReport:
        return self.frames.skipped


def _dsp(recording: Recording, options: dict):
    from scattertrack import _core

    return _core.OfdmDsp(
        recording.bandwidth_hz, recording.subcarriers, recording.centre_hz, recording.blf_hz,
        recording.known_symbol, encoding=recording.encoding, trext=recording.trext, **options,
    )


def _positions(scene: Scene, recording: Recording) -> tuple[np.ndarray, np.ndarray]:
    """tx position (3,) and rx positions (R, 3) from the scene, checking ids and roles; warns where
    the scene disagrees with the recording's metadata (:mod:`scattertrack.io.sigmf_scene`)."""
    where = str(recording.path) if recording.path is not None else "<recording>"
    warn_scene_disagreement(where, scene, recording.meta["global"])
    roles = {int(a.id): a for a in scene.antennas}
    tx = roles.get(recording.tx_id)
    if tx is None or tx.role != "tx":
        raise FormatError(where, None, f"global.{NAMESPACE}:tx_id", f"antenna {recording.tx_id} is not a 'tx' antenna of scene {scene.name!r}")
    rx = []
    for rx_id in recording.channels:
        antenna = roles.get(rx_id)
        if antenna is None or antenna.role != "rx":
            raise FormatError(where, None, f"global.{NAMESPACE}:channels", f"antenna {rx_id} is not an 'rx' antenna of scene {scene.name!r}")
        rx.append(np.asarray(antenna.position, dtype=np.float64))
    return np.asarray(tx.position, dtype=np.float64), np.array(rx)


def calibrate_sigmf(path, scene: Scene, tag_position=None, **options) -> SigmfCalibration:
    """A calibration from a recording of one tag at rest at a known position.

    ``tag_position`` (m) defaults to the recording's
    ``scattertrack:calibration.tag_position``. Every window is processed
    (with the transmitter sample index, so the timing reference is learnt
    too); the replies found are averaged and divided into the reference
    channel ``sim.wideband.tag_channel`` (direct path, no reflectors: what
    the user knows of the geometry) at that position. ``options``: the DSP
    options of :func:`estimate_sigmf`. Raises ValueError when no reply is
    found, :class:`FormatError` for a bad recording.
    """
    from scattertrack import _core
    from scattertrack.sim.wideband import tag_channel

    recording = path if isinstance(path, Recording) else read_sigmf(path)
    if tag_position is None:
        recorded = recording.calibration
        key = f"global.{NAMESPACE}:calibration.tag_position"
        if not isinstance(recorded, dict) or "tag_position" not in recorded:
            raise FormatError(recording.path, None, key, "missing: a calibration recording names the known position "
                                                         "of its tag at rest (metres)")
        tag_position = recorded["tag_position"]
        if not finite_vector(tag_position):
            raise FormatError(recording.path, None, key, f"must be 3 finite numbers (metres), got {tag_position!r}")
    tag_position = np.asarray(tag_position, dtype=np.float64).reshape(3)
    tx, rx = _positions(scene, recording)
    dsp = _dsp(recording, options)
    n = recording.subcarriers
    measured = []
    for k, window in enumerate(recording.windows):
        phase = None if window.tx_sample_index is None else window.tx_sample_index % n
        try:
            out = dsp.process(recording.window_samples(k), phase)
        except _core.DspError:
            continue
        if np.isfinite(out["tag_channel"]).all():
            measured.append(out["tag_channel"])
    if not measured:
        raise ValueError(f"{recording.path}: no calibration reply found in {len(recording.windows)} windows")
    frequencies = dsp.subcarrier_frequencies()
    reference = tag_channel(tx, rx, tag_position[None, :], frequencies)[0]
    correction = _core.dsp_calibration(np.array(measured), reference)
    return SigmfCalibration(
        correction, recording.channels, frequencies, dsp.timing_reference, tag_position, len(measured), str(recording.path)
    )


def estimate_sigmf(
    path,
    scene: Scene,
    calibration=None,
    *,
    ema_alpha: float | None = None,
    use_tx_index: bool = True,
    **options,
) -> SigmfEstimate:
    """One-shot wideband channel estimation over every window of a recording (thesis sec. 4.3).

    ``calibration``: a :class:`SigmfCalibration`, the path of a calibration
    recording (:func:`calibrate_sigmf` with its recorded tag position), or
    None (uncalibrated channels: the hardware response and the tag's
    modulation phase remain, so the docs/formats.md section 5 convention does
    not hold). ``ema_alpha``: smoothing across each tag's replies
    (``DspEma``; None: off). ``use_tx_index``: use each window's
    transmitter sample index to keep the symbol timing reference fixed
    (recommended; the DSP's ``process`` explains why). ``options``: the
    DSP's keyword options — ``threshold`` (0.5), ``blf_tolerance`` (0.05),
    ``guard_symbols`` (1.0), ``feature`` ("projection" or "magnitude"),
    ``use_payload`` (True), ``payload_bits`` (17), ``decision_margin`` (0.5).

    Windows are skipped and counted in ``frames.skipped`` by reason (no
    preamble, non-finite window, too short, no clean symbols; a failed
    receive antenna drops that antenna's rows). Frame time = the window
    start + the detected preamble start.
    """
    from scattertrack import _core

    recording = path if isinstance(path, Recording) else read_sigmf(path)
    _positions(scene, recording)  # the scene must know the recording's antennas
    if calibration is not None and not isinstance(calibration, SigmfCalibration):
        calibration = calibrate_sigmf(calibration, scene, **options)
    dsp = _dsp(recording, options)
    frequencies = dsp.subcarrier_frequencies()
    if calibration is not None:
        check_calibration(calibration, recording.channels, frequencies)
        if use_tx_index and calibration.timing_reference is not None:
            dsp.timing_reference = calibration.timing_reference
    n = recording.subcarriers
    rx_ids = np.array(recording.channels, dtype=np.int64)
    skipped = SkipReport()
    smoothers: dict[str, object] = {}
    rows = {"time": [], "epc": [], "h": [], "ok": []}
    diagnostics = {"window": [], "score": [], "blf": [], "variance": [], "used": [], "edge": []}
    for k, window in enumerate(recording.windows):
        samples = recording.window_samples(k)
        if not np.isfinite(samples).any():
            skipped.add(SKIP_NON_FINITE, k)
            continue
        phase = window.tx_sample_index % n if (use_tx_index and window.tx_sample_index is not None) else None
        try:
            out = dsp.process(samples, phase)
        except _core.DspError as error:
            kind = str(error).split(":", 1)[0]
            skipped.add(_SKIP_BY_KIND.get(kind, kind), k)
            continue
        h = out["tag_channel"]
        variance = out["variance"]
        if calibration is not None:
            h = h * calibration.correction
            variance = variance * np.abs(calibration.correction) ** 2
        ok = np.isfinite(h).all(axis=1)  # per rx
        if not ok.all():
            skipped.add(SKIP_RX, k, n=int((~ok).sum()))
        if not ok.any():
            continue
        epc = window.epc if window.epc is not None else ""
        if ema_alpha is not None:
            smoother = smoothers.setdefault(epc, _core.DspEma(float(ema_alpha)))
            h = smoother.update(np.ascontiguousarray(h, dtype=np.complex128))
        rows["time"].append(window.time_s + out["start_sample"] / recording.bandwidth_hz)
        rows["epc"].append(epc)
        rows["h"].append(h)
        rows["ok"].append(ok)
        first = int(np.flatnonzero(ok)[0])
        diagnostics["window"].append(k)
        diagnostics["score"].append(out["score"])
        diagnostics["blf"].append(out["blf_hz"])
        diagnostics["variance"].append(variance)
        diagnostics["used"].append(out["counts"]["high"][first] + out["counts"]["low"][first])
        diagnostics["edge"].append(out["counts"]["edge"][first])
    r, f = len(rx_ids), len(frequencies)
    count = len(rows["time"])
    if count:
        ok = np.array(rows["ok"])  # (K, R)
        mask = np.broadcast_to(ok[:, :, None], (count, r, f))
        shape = (count, r, f)
        frames = make_frames(
            time_s=np.broadcast_to(np.array(rows["time"])[:, None, None], shape)[mask],
            epc=np.broadcast_to(np.array(rows["epc"], dtype=str)[:, None, None], shape)[mask],
            tx=np.full(int(mask.sum()), recording.tx_id, dtype=np.int64),
            rx=np.broadcast_to(rx_ids[None, :, None], shape)[mask],
            frequency_hz=np.broadcast_to(frequencies[None, None, :], shape)[mask],
            h=np.array(rows["h"])[mask],
        )
    else:
        empty = np.array([], dtype=np.float64)
        frames = make_frames(empty, np.array([], dtype=str), empty, empty, empty, np.array([], dtype=np.complex128))
    frames.skipped = skipped
    order = np.argsort(np.array(rows["time"]), kind="stable") if count else np.array([], dtype=np.int64)
    return SigmfEstimate(
        frames=frames,
        window=np.array(diagnostics["window"], dtype=np.int64)[order],
        score=np.array(diagnostics["score"], dtype=np.float64)[order],
        blf_hz=np.array(diagnostics["blf"], dtype=np.float64)[order],
        variance=np.array(diagnostics["variance"]).reshape(-1, r, f)[order],
        symbols_used=np.array(diagnostics["used"], dtype=np.int64)[order],
        symbols_edge=np.array(diagnostics["edge"], dtype=np.int64)[order],
    )


def read_sigmf_frames(path, scene: Scene, calibration=None, **options) -> Frames:
    """The wideband frames (docs/formats.md section 5) of a helper recording: :func:`estimate_sigmf`'s ``frames``."""
    return estimate_sigmf(path, scene, calibration, **options).frames
