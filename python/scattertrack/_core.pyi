"""Type stubs of the Rust extension (thin bindings over scattertrack-core)."""

from typing import Any

import numpy as np
import numpy.typing as npt

EstimateTuple = tuple[float, list[float], list[float], list[float], int, float]

class Engine:
    """Per-tag trackers of one method over one scene (core ``engine::Engine``)."""

    def __init__(
        self,
        dimensions: int,
        plane_z: float,
        phase_sign: float,
        phase_period: float,
        phase_noise_rad: float,
        antenna_positions: npt.NDArray[np.float64],
        antenna_offsets: npt.NDArray[np.float64],
        region: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None,
        channel_frequencies: npt.NDArray[np.float64],
        channel_offsets: npt.NDArray[np.float64],
        method: str,
        params: dict[str, Any] | None = None,
        roles: list[str] | None = None,
    ) -> None:
        """``roles``: one of "txrx", "tx", "rx" per antenna (default all "txrx")."""
    def step(
        self, tag: int, time_s: float, antenna: int, frequency_hz: float, phase_rad: float
    ) -> EstimateTuple | None:
        """One measurement; antenna is an index into the scene's antennas."""
    def run(
        self,
        tag: npt.NDArray[np.int64],
        time_s: npt.NDArray[np.float64],
        antenna: npt.NDArray[np.int64],
        frequency_hz: npt.NDArray[np.float64],
        phase_rad: npt.NDArray[np.float64],
    ) -> dict[str, np.ndarray]:
        """Columns row, time_s, position (n,3), velocity (n,3), covariance (n,36), hypotheses, weight."""
    def run_frames(
        self,
        tag: npt.NDArray[np.int64],
        time_s: npt.NDArray[np.float64],
        tx: npt.NDArray[np.int64],
        frame_start: npt.NDArray[np.int64],
        rx: npt.NDArray[np.int64],
        frequency_hz: npt.NDArray[np.float64],
        h_re: npt.NDArray[np.float64],
        h_im: npt.NDArray[np.float64],
    ) -> dict[str, np.ndarray]:
        """Wideband frames: per frame tag, time, tx index and row offsets; per row
        rx index, subcarrier Hz and channel (sorted by rx, then frequency).
        Same columns as ``run``; ``row`` is the frame index."""
    def run_stream(
        self,
        tag: npt.NDArray[np.int64],
        time_s: npt.NDArray[np.float64],
        tx_phase: npt.NDArray[np.int64],
        dsp: OfdmDsp,
        tx: int,
        rx: list[int],
        windows: npt.NDArray[np.complex64] | None = None,
        file: tuple[str, str, int, float, int, npt.NDArray[np.int64]] | None = None,
        timing_reference: list[int] | None = None,
        correction: npt.NDArray[np.complex128] | None = None,
        ema_alpha: float | None = None,
        workers: int | None = None,
        shared: bool = False,
        queue_depth: int = 64,
        speed: float | None = None,
    ) -> dict[str, Any]:
        """Helper IQ through the real-time runtime, from exactly one of
        ``windows`` (K, R, S) in memory or ``file`` = (path, "ci16_le" |
        "cf32_le", channels, scale, window_len, start_sample (K,)), read
        one reply at a time; tx_phase -1 where unknown; correction (R, F);
        speed None = as fast as possible. Returns the columns of ``run``
        plus latency_ns (K,), receivers (K,), stage_ns (K, 5), stages,
        wall_s, no_channel, unreadable and declined {reason: count}."""
    def trajectory(self, tag: int) -> list[tuple[float, list[float]]]:
        """Backtracked MAP trajectory (TurboTrack): (time_s, position m) pairs."""
    def stats(self, tag: int) -> dict[str, int]: ...
    def hypotheses(self, tag: int) -> list[tuple[list[float], float]]:
        """Live hypotheses: (position m, normalised log-likelihood)."""
    def latency(self) -> tuple[int, float, int]:
        """(count, mean_ns, max_ns) of step calls."""
    def latency_percentiles(self, quantiles: list[float]) -> list[float]:
        """Quantiles (0-1) of the per-step cost, ns."""

def methods() -> list[str]: ...
def default_params(method: str = "glac") -> dict[str, Any]:
    """The parameters ``method`` accepts, with their defaults."""

# --------------------------------------------------------------------------
# scattertrack-dsp: the helper's one-shot wideband channel estimation (python/src/dsp.rs)

class DspError(ValueError):
    """A DSP error; the message starts with its kind: 'no-preamble', 'non-finite',
    'too-short', 'no-clean-symbols', 'bad-config', 'shape' or 'bad-calibration'."""

class OfdmDsp:
    """One reply's processing over all rx antennas (crates/dsp ``reply::ReplyProcessor``):
    symbol timing, per-symbol FFT, preamble detection, edge-flip elimination, tag channel."""

    def __init__(
        self,
        bandwidth_hz: float,
        subcarriers: int,
        centre_hz: float,
        blf_hz: float,
        symbol: npt.NDArray[np.complex128],
        encoding: str = "fm0",
        trext: bool = False,
        threshold: float = 0.5,
        blf_tolerance: float = 0.05,
        guard_symbols: float = 1.0,
        feature: str = "projection",
        use_payload: bool = True,
        payload_bits: int = 17,
        decision_margin: float = 0.5,
    ) -> None:
        """``symbol``: X (N,) FFT order, DC 0, unit magnitude. Raises DspError ('bad-config')
        for N >= B/(2 BLF) and other bad values."""
    def subcarrier_frequencies(self) -> npt.NDArray[np.float64]:
        """Active subcarriers (N - 1), Hz, ascending: centre + k' B/N, k' != 0."""
    timing_reference: list[int] | None
    """Per-rx symbol timing reference (learnt from the first window processed with a tx_phase)."""
    def process(self, windows: npt.NDArray[np.complex64], tx_phase: int | None = None) -> dict[str, Any]:
        """One reply: ``windows`` (R, L) complex64; ``tx_phase`` = tx stream index of the first
        sample mod N. Returns ``tag_channel`` (R, F) complex128 (NaN rows for failed antennas),
        ``variance`` (R, F), ``antenna_errors`` (list of 'kind: message' or None),
        ``start_sample`` (preamble start in window samples), ``start_symbol``, ``chip_symbols``,
        ``blf_hz``, ``score``, ``correlations`` (per rx), ``first_samples`` (per rx),
        ``payload_chips``, ``symbols``, ``states`` (R, symbols) uint8 (0 outside, 1 edge,
        2 invalid, 3 low, 4 high) and ``counts`` (dict of per-rx lists: high, low, edge,
        outside, invalid). Raises DspError for a reply-level failure."""

class DspEma:
    """Exponential moving average across replies with polarity alignment (``estimate::Ema``)."""

    def __init__(self, alpha: float) -> None: ...
    def update(self, h: npt.NDArray[np.complex128]) -> npt.NDArray[np.complex128]:
        """Adds one reply's channel (R, F); returns the smoothed state (R, F)."""
    @property
    def updates(self) -> int: ...
    @property
    def flips(self) -> int: ...

def dsp_known_symbol(subcarriers: int, seed: int) -> npt.NDArray[np.complex128]:
    """X (N,), FFT order, DC 0, unit magnitude, deterministic from ``seed``."""

def dsp_subcarrier_frequencies(
    bandwidth_hz: float, subcarriers: int, centre_hz: float, blf_hz: float
) -> npt.NDArray[np.float64]:
    """Validates the design (N < B/(2 BLF)) and returns the active subcarriers, Hz."""

def dsp_reply_chips(encoding: str, trext: bool, bits: list[int] | None = None) -> npt.NDArray[np.uint8]:
    """Gen2 chip levels (one per half BLF period): the preamble, or a whole reply with ``bits``."""

def dsp_calibration(
    measured: npt.NDArray[np.complex128], reference: npt.NDArray[np.complex128]
) -> npt.NDArray[np.complex128]:
    """Correction C (R, F) from measured tag channels (K, R, F) and the reference (R, F)."""
