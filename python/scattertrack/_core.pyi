"""Type stubs of the Rust extension (thin bindings over scattertrack-core)."""

from typing import Any, Literal, TypedDict

import numpy as np
import numpy.typing as npt

EstimateTuple = tuple[float, list[float], list[float], list[float], int, float]

DEFAULT_PHASE_NOISE_RAD: float
"""The filter's prior phase noise when the scene states none (docs/formats.md section 1), radians."""

class Scene:
    """A ``scattertrack.io.Scene`` read once into the core's scene (``python/src/scene.rs``).

    Reads dimensions, plane_z (None: 0), the reader's phase_sign, period_rad,
    phase_noise_rad (None or 0: ``DEFAULT_PHASE_NOISE_RAD``) and kind, each
    antenna's id, position and phase_offset_rad, and the region; a monostatic
    scene also its channel_offsets, an ``sdr-helper`` scene each antenna's
    role. ValueError for a scene the core rejects."""

    def __init__(self, scene: Any) -> None: ...
    @property
    def dimensions(self) -> int: ...
    @property
    def antennas(self) -> int:
        """Number of antennas (trackers index them 0..n in the scene's order)."""
    @property
    def phase_noise_rad(self) -> float:
        """The prior phase noise the trackers use, radians."""

class Engine:
    """Per-tag trackers of one method over one scene (core ``engine::Engine``)."""

    def __init__(self, scene: Scene, method: str, params: dict[str, Any] | None = None) -> None:
        """Trackers of ``method`` over ``scene``; ``params`` checked by the method's table (ValueError)."""
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
        *,
        covariance: bool = True,
    ) -> dict[str, np.ndarray]:
        """Columns row (increasing), time_s, position (n,3), velocity (n,3), covariance (n,36), hypotheses, weight.

        The reads are taken tag by tag (each tag's in order: the estimates of ``step`` in input order).
        ``covariance=False``: a ``sigma`` column (n,3: the x, y, z 1-sigma, m) in place of ``covariance``.
        """
    @staticmethod
    def format_track_rows(
        time_s: npt.NDArray[np.float64],
        epc: npt.NDArray[np.int64],
        epc_cells: list[str],
        values: npt.NDArray[np.float64],
    ) -> bytes:
        """track.csv rows: time, epc_cells[epc], every column of values (n, k); floats as Python's "%.6f", nan as "nan"."""
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
        layout: str = "team",
        queue_depth: int = 64,
        speed: float | None = None,
        prewake_s: float = 1e-3,
    ) -> dict[str, Any]:
        """Helper IQ through the real-time runtime, from exactly one of
        ``windows`` (K, R, S) in memory or ``file`` = (path, "ci16_le" |
        "cf32_le", channels, scale, window_len, start_sample (K,)), read
        one reply at a time; tx_phase -1 where unknown; correction (R, F);
        speed None = as fast as possible; layout "team" | "per-antenna" |
        "shared" (how antenna jobs meet threads); prewake_s how early idle
        team workers are woken to poll for a paced reply. Returns the columns of ``run``
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

# --------------------------------------------------------------------------
# Parameter tables and the method registry (python/src/params.rs)

class MethodRow(TypedDict):
    name: str
    pipeline: Literal["cots", "helper", "drone"]
    input: Literal["reads", "frames", "features+imu", "sigmf+imu"]
    input_files: str
    estimator: Literal["core", "python"]
    description: str

def methods() -> list[MethodRow]:
    """Every registered method (the core's registry), in listing order."""

def default_params(method: str = "glac") -> dict[str, Any]:
    """Defaults of a core method's parameters; ValueError for an unknown or Python-side method."""

ParameterValue = bool | int | float | str | None

class ParameterRow(TypedDict):
    name: str
    type: str
    """As the docs show it: "float", "integer", "bool", "float or none", "fast | naive"."""
    kind: Literal["bool", "integer", "float", "choice"]
    optional: bool
    choices: list[str] | None
    default: ParameterValue
    range: str
    """"> 0", ">= 1", "[0, 1]", "(0, inf]"; "finite" (any finite float) or "-" (not numeric)."""
    unit: str
    description: str

class ParameterTable:
    """One method's parameter table; values are checked by the core's rules."""

    def __init__(self, label: str, rows: list[dict[str, Any]]) -> None:
        """A table from rows written in Python (name, kind, default, and optionally
        optional, choices, range as text, unit, description); every default must pass its row."""
    @staticmethod
    def of_method(method: str) -> ParameterTable:
        """The table of a core method (ValueError for an unknown or Python-side one)."""
    @property
    def label(self) -> str: ...
    def rows(self) -> list[ParameterRow]: ...
    def names(self) -> list[str]: ...
    def defaults(self) -> dict[str, ParameterValue]: ...
    def check(self, params: dict[str, Any]) -> dict[str, ParameterValue]:
        """Values checked and converted to each row's type (text read as :meth:`parse` reads it);
        ValueError naming the parameter, what it must be and the value given."""
    def parse(self, pairs: list[tuple[str, str]]) -> dict[str, ParameterValue]:
        """Command-line ``NAME=TEXT`` pairs as typed values (bools: true/false/yes/no/1/0)."""

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

# --------------------------------------------------------------------------
# scattertrack-dsp lora: Marvel's LoRa-backscatter pose sensing (python/src/lora.rs,
# docs/marvel.md section 7). Shapes: j = 2 excitation channels, k = 4 tags,
# m = receive antennas, N = 2^SF samples; SI units, radians.

class LoraEpochProcessor:
    """One sensing epoch (crates/dsp ``lora::EpochProcessor``): dechirp peaks, MUSIC
    angle per tag, Doppler/CFO, channel phases, chirp-timing and phase range, yaw."""

    def __init__(
        self,
        spreading_factor: int = 12,
        bandwidth_hz: float = 500e3,
        channels_hz: tuple[float, float] | None = None,
        chirp_starts_s: tuple[float, float] | None = None,
        tag_shifts_hz: tuple[float, float, float, float] | list[float] | None = None,
        tag_positions: npt.NDArray[np.float64] | None = None,
        array: str = "triangle",
        array_elements: npt.NDArray[np.float64] | None = None,
        calibration_rad: npt.NDArray[np.float64] | None = None,
        range_min_m: float = 0.0,
        range_max_m: float = 150.0,
        range_threshold: float = 0.5,
        range_coherence: str = "per-tag",
        range_window_m: float | None = None,
        range_full: bool = False,
        magnitude_weights: bool = True,
        angle_combine: str = "harmonic",
        music_grid_deg: float = 3.0,
        music_focus: bool = False,
        min_omega_rad_s: float = 0.05,
        ignore_doppler: bool = False,
        peak_search_hz: float | None = None,
    ) -> None:
        """Defaults: docs/marvel.md (channels 902.1 / 928.02 MHz back to back, shifts 1-4 MHz,
        tags on the 0.66 m gear 0.30 m below the body origin, the 16 cm triangle).
        ``array``: "triangle" | "linear", or ``array_elements`` (M, 3) m; ``tag_positions`` (4, 3)
        body m; ``calibration_rad`` (M, 8) receive offsets per received channel j*4+k;
        ``range_coherence``: "per-tag" | "pair-sums" | "across-tags" (the paper's reading);
        the phase range is the fringe peak nearest the chirp-timing range within
        +- ``range_window_m`` (default one fringe, c0 / (2 df)), or with ``range_full`` the
        first path over [range_min_m, range_max_m]; ``angle_combine``: "harmonic" (paper) |
        "mean-direction"; ``ignore_doppler``: the Doppler-blind mu-locate baseline.
        Raises DspError ('bad-config', 'shape', ...)."""
    @property
    def samples_per_chirp(self) -> int: ...
    @property
    def antennas(self) -> int: ...
    @property
    def reference_time_s(self) -> float:
        """Reference time of the phases from the epoch origin (the mean chirp centre), s."""
    def carriers_hz(self) -> npt.NDArray[np.float64]:
        """Received carriers f_j + s_k/2, Hz, (2, 4)."""
    def process(
        self,
        samples: npt.NDArray[np.complex64],
        clock_error: float = 0.0,
        velocity: npt.NDArray[np.float64] | None = None,
        direction: npt.NDArray[np.float64] | None = None,
        attitude: npt.NDArray[np.float64] | None = None,
        omega_body: npt.NDArray[np.float64] | None = None,
        epoch_time_s: float | None = None,
    ) -> dict[str, Any]:
        """One epoch, ``samples`` (2, 4, M, N) complex64, each chirp from its first sample.
        Corrections: ``clock_error`` eps (cfo_k = eps s_k), ``velocity`` world m/s (None: 0),
        ``direction`` controller->drone unit vector (None: this epoch's angle), ``attitude``
        world_R_body (3, 3) (its roll/pitch feed the yaw), ``omega_body`` rad/s, ``epoch_time_s``
        absolute time of the epoch origin (removes the tags' whole clock phase).
        Returns ``frequency_hz``, ``frequency_sigma_hz``, ``phase_sigma_rad``, ``snr_db`` (per
        sample), ``amplitude`` (centre-referred) and ``amplitude_start`` complex128, ``phase_rad``
        (at reference_time_s) — all (2, 4, M); ``carriers_hz`` (2, 4), ``reference_time_s``,
        ``pair_mean_hz`` and ``rotational_hz`` (2, M, 2), ``translational_hz`` (2, 4),
        ``timing_hz``, ``timing_sigma_hz``, ``timing_range_m``, ``timing_range_sigma_m``,
        ``range_m``, ``range_sigma_m`` (float | None), ``range_peak_m``, ``range_power``,
        ``range_ambiguity``, ``range_resolution_m``, ``antenna_ranges_m`` (M,), ``tag_azimuth``,
        ``tag_elevation``, ``tag_spectrum_db`` (4,), ``azimuth``, ``elevation``, ``direction``
        (3,), ``yaw``, ``yaw_sigma_rad``, ``yaw_condition``, ``yaw_residual_hz`` (None without
        attitude and omega_body or below min_omega_rad_s), ``mean_snr_db``, ``min_snr_db``.
        Raises DspError."""

def lora_chirp(spreading_factor: int = 12, bandwidth_hz: float = 500e3, down: bool = False) -> npt.NDArray[np.complex128]:
    """The sampled LoRa upchirp exp(i 2 pi (-BW/2 t + BW/(2T) t^2)) at fs = BW, (2^SF,); or its conjugate."""

def lora_peak(
    samples: npt.NDArray[np.complex64], spreading_factor: int = 12, bandwidth_hz: float = 500e3, search_hz: float | None = None
) -> dict[str, Any]:
    """Dechirp + FFT + refined peak of one chirp (2^SF,): ``frequency_hz``, ``amplitude`` (at the
    chirp start), ``amplitude_centre`` (at T/2), ``snr`` (per sample, linear), ``noise_power``,
    ``frequency_sigma_hz``, ``phase_sigma_rad`` (Cramer-Rao at the estimated SNR), ``bin``."""

def lora_music(
    phases_rad: npt.NDArray[np.float64],
    frequencies_hz: npt.NDArray[np.float64],
    elements: npt.NDArray[np.float64] | None = None,
    grid_deg: float = 3.0,
    focus: bool = False,
    sources: int = 1,
) -> dict[str, Any]:
    """MUSIC on the virtual measurement matrix: phases (M, N) rad, carriers (N,) Hz, elements
    (M, 3) m (default the 16 cm triangle, front half-space +y). Returns ``azimuth``,
    ``elevation``, ``direction``, ``spectrum_db``, ``eigenvalues``."""

def lora_heading(
    differences_hz: npt.NDArray[np.float64],
    carriers_hz: npt.NDArray[np.float64],
    tags_a: npt.NDArray[np.float64],
    tags_b: npt.NDArray[np.float64],
    sigmas_hz: npt.NDArray[np.float64],
    roll_pitch: npt.NDArray[np.float64],
    omega_body: npt.NDArray[np.float64],
    direction: npt.NDArray[np.float64],
    velocity: npt.NDArray[np.float64] | None = None,
    range_m: float | None = None,
    chirp_rate_hz_per_s: float | None = 500e3 / 8.192e-3,
    min_omega_rad_s: float = 0.05,
) -> dict[str, float] | None:
    """Yaw from pair differences f_a - f_b - (cfo_a - cfo_b) (P,) Hz at their carriers, tag body
    positions (P, 3), R_rp (3, 3), gyro rate, controller->drone direction; optional velocity and
    range add the parallax term. ``yaw``, ``sigma_rad``, ``condition``, ``residual_rms_hz``, or
    None when |omega| < min_omega_rad_s or undefined."""

def lora_clock_error(
    peaks_hz: npt.NDArray[np.float64],
    tag_shifts_hz: tuple[float, float, float, float] | list[float] = ...,
    pairs: tuple[tuple[int, int], tuple[int, int]] | list[tuple[int, int]] = ...,
) -> dict[str, Any]:
    """Tags' clock error eps from peaks at rest (observations, 4) Hz: ``clock_error``,
    ``sigma`` (None with one observation), ``timing_hz``, ``observations``."""

# --- scene geometry check (python/src/geometry.rs) ---------------------------

def analyse_scene(
    scene: Scene,
    read_frequencies: list[float],
    evidence_reads: float | None = None,
    remedies: bool = True,
) -> dict:
    """Layout findings and twin families (dict of lists of dicts; antenna indices, metres)."""

def twin_positions(
    scene: Scene,
    position: list[float],
    frequencies: list[float],
    evidence_reads: float | None = None,
) -> list[tuple[list[float], list[int], float]]:
    """Twins of one position: (position m, shift per antenna, chi-square), nearest first."""

# --- static-tag phase search (python/src/locate.rs) ---------------------------

def locate_batch(
    z_re: np.ndarray,
    z_im: np.ndarray,
    k: np.ndarray,
    time_s: np.ndarray,
    antenna: np.ndarray,
    anchors: np.ndarray,
    bounds: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    axes: int,
    *,
    temperature: float,
    bias_sigma_rad: float,
    correlation_s: float,
    max_candidates: int,
    min_weight: float,
    hopping_spread_hz: float,
    max_points: int = 100_000,
    threads: int = 0,
    scene: object | None = None,
    phase_multiplier: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every tag's phase candidates, tag t in rows ``bounds[t]:bounds[t+1]`` searched in
    ``low[t]..high[t]`` (``antenna`` indexes ``anchors``; ``k`` = m s 4 pi f / c, rad/m), on
    ``threads`` threads (0: every core). ``scene``: an object with ``reflectors`` (a
    ``scattertrack.io.Scene``), whose known reflectors enter the phase model (apparent ranges),
    with ``phase_multiplier`` the m of ``k``. Returns positions (c, 3) m, covariances (c, 3, 3) m²,
    weights (c,), coherences (c,) and candidate_bounds (tags + 1,): tag t's candidates, best
    first, are rows ``candidate_bounds[t]:candidate_bounds[t+1]``."""

def locate_hop_range(z_re: np.ndarray, z_im: np.ndarray, k: np.ndarray, max_range_m: float) -> tuple[float, float] | None:
    """One antenna's range from its reads over several channels: (range m, 1-sigma m), or None."""
