"""Marvel's LoRa-backscatter IQ: what the controller's three receive antennas sample (docs/marvel.md 2, 4-6).

The controller (at ``rho``, world frame; its transmit antenna at the array
centre) sends one LoRa upchirp on each excitation channel ``f_j``, back to
back; each of the four tags on the drone's landing gear backscatters it
shifted by ``s_k``; the receiver mixes the uplink at ``f_j + s_k`` to 0 Hz on
each receive antenna ``m`` and samples it at ``fs = BW``. The output
(:class:`LoraRecording`) holds those channelised streams,
``samples[epoch, j, k, m, n]``.

Signal model (docs/marvel.md section 6, implemented as written)
    For sample ``n`` of chirp ``j`` (``t = t_j + n / fs``)::

        y[n] = sum over paths  a(t) exp(i psi(t)) c(t - t_j - tau(t))  +  w[n]
        c(u)   = exp(i 2 pi (-BW/2 u + BW/(2T) u^2))  for 0 <= u < T, else 0
        tau    = (|p_k(t) - rho_tx| + |p_k(t) - rho_m|) / c0            (direct path)
        psi    = -2 pi (f_j + s_k/2) tau + 2 pi cfo_k t + phi_tag + theta_jkm

    ``p_k(t) = R(q(t)) b_k + x(t)`` is tag ``k``'s world position from the
    flight's pose **at every sample time** (``pose_at`` is called with the
    chirp's 2 x 4096 sample times at once): the time of flight, the
    translational and the rotational Doppler all follow from the geometry,
    nothing is linearised. (The contract evaluates the tag at the receive
    time ``t`` rather than at the reflection time ``t - d_up / c0``; the
    difference is ``v d_up / c0``, 0.3 um at 3 m/s and 30 m.)

Why the carrier phase uses ``f_j + s_k / 2``
    The downlink travels ``d_down = |p_k - rho_tx|`` at ``f_j`` (phase
    ``-2 pi f_j d_down / c0``); the tag multiplies by its shift
    ``exp(i 2 pi s_k t)``, so the uplink travels ``d_up = |p_k - rho_m|`` at
    ``f_j + s_k`` (phase ``-2 pi (f_j + s_k) d_up / c0``). The sum is
    ``-2 pi f_j (d_down + d_up) / c0 - 2 pi s_k d_up / c0``; with the
    transmit antenna at the array centre ``d_up ~ d_down ~ path / 2``, so
    the round trip behaves as one path ``d_down + d_up`` at the mean
    frequency ``f_j + s_k / 2``: ``psi = -2 pi (f_j + s_k/2) tau`` (the
    contract; the per-leg form differs by ``pi s_k (d_down - d_up) / c0``,
    at most 7 mrad for ``s_k`` = 4 MHz and the 9 cm array offsets, and it is
    constant across epochs). The phase falls as the path grows: at a fixed
    frequency ``f`` it advances ``-4 pi Delta r / lambda`` per one-way
    range change ``Delta r`` (``lambda = c0 / f``).
Tag clock
    One FPGA clocks all tags (paper sec. V-A): a clock error ``eps``
    (dimensionless, drawn ``U(-tag_clock_ppm, tag_clock_ppm) 1e-6`` per
    seed) makes tag ``k`` shift by ``s_k (1 + eps)`` instead of ``s_k``, so
    the receiver, mixing with the nominal ``s_k``, sees a carrier frequency
    offset ``cfo_k = eps s_k`` (Hz, constant, different per tag); the
    switching waveforms share one phase ``phi_tag`` (``U(0, 2 pi)``).
Receive chains
    ``theta_jkm = phi_m - 2 pi (f_j + s_k) delay_m`` (a random phase per
    antenna ``U(0, 2 pi)`` and a cable delay ``U(0, rx_delay_max_s)``
    applied as a phase only, as the contract's ``theta_m(f)``). The
    metadata carries the calibrated values ``theta_jkm - residual`` with a
    residual ``N(0, calibration_residual_rad)`` (0 by default: a perfect
    calibration), so the DSP subtracts them.
The dechirped tone
    Dechirping with the reference ``c(n / fs)`` (the chirp at the start of
    its window) gives, for one path, the phase
    ``2 pi [BW/2 tau - (BW/T) u' tau + BW/(2T) tau^2] + psi(t)`` with
    ``u' = n / fs``, a tone whose instantaneous frequency is
    ``-(BW/T) tau - (f_j + s_k/2) dtau/dt + cfo_k`` (the terms in
    ``dtau/dt`` times ``BW/2 - (BW/T) u'`` cancel at mid-chirp). So the FFT
    peak sits at ``f_peak = cfo_k + f_D - (BW/T) tau`` with the Doppler
    ``f_D = -((f_j + s_k/2) / c0) d(path)/dt`` (both legs change: a drone
    moving away, path growing, gives a negative shift), both evaluated at
    mid-chirp ``n = N/2``; there the dechirped phase is
    ``psi(t_mid) + pi (BW/T) tau^2`` (the ``BW/2 tau`` terms cancel, and
    the last term is 6e-6 rad at a 50 m path). ``(BW/T) tau`` is 6.1e7 Hz/s x
    tau: 12 Hz at a 60 m path, against a bin of ``BW / 2^SF`` = 122 Hz.
    The first sample of each chirp (``u < 0`` while the echo is still in
    flight, tau < 1/fs) is 0, as ``c`` is.
Link budget (radar equation, both legs spread)
    ``P_rx = P_tx G_tx G_tag (lambda_down / (4 pi d_down))^2 L_bs
    G_tag G_rx (lambda_up / (4 pi d_up))^2 L_impl L_wall^(2 walls)`` W, with
    ``lambda_down = c0 / f_j``, ``lambda_up = c0 / (f_j + s_k)``, ``L_bs``
    the tag's backscatter (switch and sideband conversion) loss, ``L_impl``
    the implementation loss (polarisation mismatch, cables, the airframe
    detuning the tag antenna), ``L_wall`` the one-way loss of each wall
    between the controller and the drone (crossed twice). Samples are in
    sqrt(W): ``a = sqrt(P_rx)``. Noise: complex white Gaussian of power
    ``k T BW F`` (thermal over the bandwidth times the noise figure) per
    sample. At the defaults a tag 1 m from the controller has a per-sample
    SNR of about 52 dB, 20 m about 0 dB, 50 m about -16 dB (the dechirp adds
    ``10 log10(2^SF)`` = 36 dB; the paper loses the tags beyond about
    50 m); each wall costs 12 dB (:func:`link_budget_snr_db`).
Multipath (``reflectors``, the dicts of :mod:`scattertrack.sim.wideband`)
    ``{"kind": "plane", "point", "normal", "coefficient"}`` (a specular
    wall, image method, present only when both ends are on the same side)
    or ``{"kind": "point", "position", "coefficient"}`` (a point scatterer).
    Per reflector two extra paths per tag and antenna: the downlink bent
    (``rho_tx -> reflector -> tag -> rho_m``) and the uplink bent
    (``rho_tx -> tag -> reflector -> rho_m``), of the same form with the
    longer delay, the bent leg spreading over its unfolded length and scaled
    by the real amplitude coefficient (negative: a phase flip); two bounces
    are left out. Walls attenuate every path alike. Not modelled: the
    excitation's leakage and static clutter (at ``f_j``, not ``f_j + s_k``:
    the channeliser rejects them, which is why the tags shift), the
    images of the square-wave shift at ``f_j - s_k`` and its harmonics,
    antenna patterns.
Timing
    Epoch ``e`` starts at ``start_time_s + e / sensing_rate_hz``; its chirp
    ``j`` at ``+ j T``; ``floor(duration_s sensing_rate_hz)`` epochs.

Every random draw comes from ``numpy.random.default_rng(seed)``, split into
independent streams (:data:`STREAMS`); the same inputs and seed give the same
recording. Units: SI (m, s, Hz, rad, W), dB and dBm where named.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from scattertrack.dsp.channel import bent_leg_lengths
from scattertrack.io.sigmf_lora import LoraRecording
from scattertrack.physics import SPEED_OF_LIGHT, wrap_angle
from scattertrack.sim.rotation import quat_to_matrix

BOLTZMANN = 1.380649e-23
"""Boltzmann constant, J/K."""

LORA_MODEL_DEFAULTS = {
    # LoRa CSS (paper sec. III-A; docs/marvel.md section 5)
    "spreading_factor": 12,  # SF: N = 2^SF samples per chirp
    "bandwidth_hz": 500e3,  # Hz, BW = sample rate fs; T = 2^SF / BW = 8.192 ms
    "channel_base_hz": 902.1e6,  # Hz, f_0
    "channel_spacing_hz": 2.16e6,  # Hz, f_i = f_0 + i spacing
    "n_channels": 13,  # channels i = 0 .. 12
    "excitation_channels": [0, 12],  # i of the excitation chirps, sent back to back (widest aperture)
    "sensing_rate_hz": 10.0,  # Hz, epochs per second
    "start_time_s": 0.0,  # s, start of epoch 0
    # tags (docs/marvel.md section 2)
    "tag_shifts_hz": [1e6, 2e6, 3e6, 4e6],  # Hz, s_k of tags 1, 1', 3, 3'
    "gear_diameter_m": 0.66,  # m, D (DJI M100 landing gear)
    "gear_height_m": -0.30,  # m, h_gear: tags' body z
    "tag_body_positions_m": None,  # (K, 3) m; None: (+-D/2, 0, h), (0, +-D/2, h) as section 2
    "tag_clock_ppm": 10.0,  # ppm, eps ~ U(-x, x) 1e-6 per seed; cfo_k = eps s_k
    # array and receive chains (docs/marvel.md section 4)
    "array": "triangle",  # "triangle" (xz-plane, facing +y) or "linear" (on x)
    "array_side_m": 0.16,  # m, triangle side d; linear spacing
    "rx_delay_max_s": 3e-9,  # s, per-antenna cable delay U(0, x), applied as a phase
    "calibration_residual_rad": 0.0,  # rad, 1-sigma error of the calibrated theta_jkm
    # link budget
    "tx_power_dbm": 20.0,  # dBm, excitation power (USRP UBX class)
    "tx_gain_dbi": 3.0,  # dBi, controller transmit antenna (same link budget as sim.marvel)
    "rx_gain_dbi": 3.0,  # dBi, each receive antenna
    "tag_gain_dbi": 0.0,  # dBi, tag antenna (counts on both legs)
    "backscatter_loss_db": 16.0,  # dB, RF switch and single-sideband conversion; with the implementation loss, the 24 dB of sim.marvel (docs/marvel.md section 9)
    "implementation_loss_db": 8.0,  # dB, polarisation mismatch, cables, airframe detuning
    "wall_loss_db": 4.0,  # dB, one-way loss per wall (brick at 915 MHz, ITU-R P.2040); crossed twice
    "noise_figure_db": 6.0,  # dB, receiver (UBX-160 class)
    "temperature_k": 290.0,  # K, noise temperature of kTB
    "add_noise": True,  # False: noiseless samples (physics checks)
    # multipath
    "reflectors": [],  # plane mirrors and point scatterers (module docstring)
}
"""Every LoRa model key with its default (units in the comments; derivations in the module docstring)."""

STREAMS = ("clock", "tag_phase", "receiver", "calibration", "noise")
"""Independent random streams (switching one process off leaves the others' draws unchanged)."""

ARRAYS = ("triangle", "linear")

CONTROLLER_KEYS = ("position", "array", "walls")
"""Keys of the ``controller`` dict: ``position`` (m, required), ``array`` (default the model's), ``walls`` (default 0)."""

PoseAt = Callable[[np.ndarray], tuple]
"""``pose_at(t) -> (position (n, 3) m, orientation (n, 4) qw, qx, qy, qz world_T_body)`` for times ``t`` (n,) s."""


# --------------------------------------------------------------------------
# model


def resolve_lora_model(model: dict | None = None) -> dict:
    """Defaults of :data:`LORA_MODEL_DEFAULTS` updated by ``model``, validated (ValueError naming the key)."""
    given = dict(model or {})
    unknown = sorted(set(given) - set(LORA_MODEL_DEFAULTS))
    if unknown:
        raise ValueError(f"unknown LoRa model key(s) {unknown} (known: {', '.join(sorted(LORA_MODEL_DEFAULTS))})")
    m = {**LORA_MODEL_DEFAULTS, **given}
    sf = m["spreading_factor"]
    if isinstance(sf, bool) or not isinstance(sf, (int, np.integer)) or not 6 <= sf <= 12:
        raise ValueError(f"spreading_factor must be an integer 6..12, got {sf!r}")
    m["spreading_factor"] = int(sf)
    for key in ("bandwidth_hz", "channel_base_hz", "channel_spacing_hz", "sensing_rate_hz", "array_side_m", "temperature_k"):
        if not (np.isfinite(m[key]) and m[key] > 0):
            raise ValueError(f"{key} must be a positive number, got {m[key]!r}")
    for key in ("rx_delay_max_s", "calibration_residual_rad", "tag_clock_ppm", "wall_loss_db"):
        if not (np.isfinite(m[key]) and m[key] >= 0):
            raise ValueError(f"{key} must be a non-negative number, got {m[key]!r}")
    n_channels = int(m["n_channels"])
    excitation = [int(i) for i in m["excitation_channels"]]
    if not excitation or any(not 0 <= i < n_channels for i in excitation):
        raise ValueError(f"excitation_channels must be channel numbers 0..{n_channels - 1}, got {m['excitation_channels']!r}")
    m["excitation_channels"] = excitation
    shifts = [float(s) for s in m["tag_shifts_hz"]]
    if not shifts or any(not (np.isfinite(s) and s > 0) for s in shifts):
        raise ValueError(f"tag_shifts_hz must be positive frequencies, got {m['tag_shifts_hz']!r}")
    if any(abs(a - b) < m["bandwidth_hz"] for i, a in enumerate(shifts) for b in shifts[i + 1 :]):
        raise ValueError(f"tag_shifts_hz must be at least one bandwidth apart (the uplinks would overlap), got {shifts}")
    m["tag_shifts_hz"] = shifts
    if m["tag_body_positions_m"] is not None:
        body = np.asarray(m["tag_body_positions_m"], dtype=np.float64)
        if body.shape != (len(shifts), 3) or not np.isfinite(body).all():
            raise ValueError(f"tag_body_positions_m must be {len(shifts)} finite [x, y, z], got {m['tag_body_positions_m']!r}")
        m["tag_body_positions_m"] = body.tolist()
    elif len(shifts) != 4:
        raise ValueError("the section 2 layout has 4 tags: give tag_body_positions_m for another number of tags")
    if m["array"] not in ARRAYS:
        raise ValueError(f"array must be one of {ARRAYS}, got {m['array']!r}")
    period = 1.0 / m["sensing_rate_hz"]
    if period < len(excitation) * chirp_duration_s(m):
        raise ValueError(f"sensing_rate_hz {m['sensing_rate_hz']} leaves less than the {len(excitation)} chirps of an epoch")
    for i, reflector in enumerate(m["reflectors"]):
        if reflector.get("kind") not in ("plane", "point"):
            raise ValueError(f"reflectors[{i}].kind must be 'plane' or 'point', got {reflector.get('kind')!r}")
        if not -1.0 <= float(reflector.get("coefficient", np.nan)) <= 1.0:
            raise ValueError(f"reflectors[{i}].coefficient must be in [-1, 1], got {reflector.get('coefficient')!r}")
    m["reflectors"] = [dict(r) for r in m["reflectors"]]
    m["add_noise"] = bool(m["add_noise"])
    return m


def resolve_controller(controller: dict, model: dict) -> dict:
    """``{"position": (3,) m, "array": str, "walls": int}`` with the model's array as default."""
    unknown = sorted(set(controller) - set(CONTROLLER_KEYS))
    if unknown:
        raise ValueError(f"unknown controller key(s) {unknown} (known: {', '.join(CONTROLLER_KEYS)})")
    if "position" not in controller:
        raise ValueError("controller needs a position [x, y, z] (m)")
    position = np.asarray(controller["position"], dtype=np.float64).reshape(-1)
    if position.shape != (3,) or not np.isfinite(position).all():
        raise ValueError(f"controller position must be 3 finite numbers, got {controller['position']!r}")
    array = controller.get("array", model["array"])
    if array not in ARRAYS:
        raise ValueError(f"controller array must be one of {ARRAYS}, got {array!r}")
    walls = controller.get("walls", 0)
    if isinstance(walls, bool) or not isinstance(walls, (int, np.integer)) or walls < 0:
        raise ValueError(f"controller walls must be a non-negative integer, got {walls!r}")
    return {"position": position, "array": array, "walls": int(walls)}


def chirp_duration_s(model: dict) -> float:
    """``T = 2^SF / BW``, s."""
    return 2 ** int(model["spreading_factor"]) / float(model["bandwidth_hz"])


def channel_frequencies(model: dict) -> np.ndarray:
    """The LoRa channel plan ``f_i = channel_base_hz + i channel_spacing_hz``, Hz, ``(n_channels,)``."""
    return model["channel_base_hz"] + model["channel_spacing_hz"] * np.arange(int(model["n_channels"]))


def tag_body_positions(model: dict) -> np.ndarray:
    """Tag positions in the body frame ``(K, 3)`` m (docs/marvel.md section 2 unless the model gives them)."""
    if model.get("tag_body_positions_m") is not None:
        return np.asarray(model["tag_body_positions_m"], dtype=np.float64)
    r, h = model["gear_diameter_m"] / 2.0, model["gear_height_m"]
    return np.array([[r, 0.0, h], [-r, 0.0, h], [0.0, r, h], [0.0, -r, h]])


def array_offsets(array: str, side_m: float) -> np.ndarray:
    """Receive element offsets from the array centre ``(3, 3)`` m, world frame (docs/marvel.md section 4).

    ``triangle``: equilateral, side ``d``, in the xz-plane (centroid at the
    centre); ``linear``: on x, ``d`` apart.
    """
    d = float(side_m)
    if array == "triangle":
        low = -d / (2.0 * math.sqrt(3.0))
        return np.array([[-d / 2.0, 0.0, low], [d / 2.0, 0.0, low], [0.0, 0.0, d / math.sqrt(3.0)]])
    if array == "linear":
        return np.array([[-d, 0.0, 0.0], [0.0, 0.0, 0.0], [d, 0.0, 0.0]])
    raise ValueError(f"array must be one of {ARRAYS}, got {array!r}")


def upchirp(u_s, model: dict) -> np.ndarray:
    """The reference upchirp ``c(u) = exp(i 2 pi (-BW/2 u + BW/(2T) u^2))`` at times ``u`` (s) from its start.

    Its frequency sweeps ``-BW/2 .. +BW/2`` over ``T``; sampled at
    ``fs = BW`` the sweep wraps at Nyquist as LoRa's does. Not windowed: the
    dechirp reference is ``upchirp(n / fs)``.
    """
    bandwidth, duration = float(model["bandwidth_hz"]), chirp_duration_s(model)
    u = np.asarray(u_s, dtype=np.float64)
    return np.exp(2j * np.pi * (-bandwidth / 2.0 * u + bandwidth / (2.0 * duration) * u * u))


def noise_power_w(model: dict) -> float:
    """Thermal noise per complex sample ``k T BW F``, W (``F`` the noise figure as a ratio)."""
    return BOLTZMANN * model["temperature_k"] * model["bandwidth_hz"] * 10.0 ** (model["noise_figure_db"] / 10.0)


def _db(value_db: float) -> float:
    return 10.0 ** (value_db / 10.0)


def _budget_constant(model: dict, walls: int) -> float:
    """``P_tx G_tx G_rx G_tag^2 L_bs L_impl L_wall^(2 walls)`` (W): the radar equation without wavelengths and distances."""
    return (
        1e-3 * _db(model["tx_power_dbm"]) * _db(model["tx_gain_dbi"]) * _db(model["rx_gain_dbi"])
        * _db(2.0 * model["tag_gain_dbi"]) * _db(-model["backscatter_loss_db"]) * _db(-model["implementation_loss_db"])
        * _db(-2.0 * walls * model["wall_loss_db"])
    )


def link_budget_snr_db(distance_m, walls: int = 0, model: dict | None = None, *, frequency_hz: float | None = None,
                       shift_hz: float | None = None, down_m=None) -> np.ndarray:
    """Per-sample SNR (dB) of the direct path of a tag ``distance_m`` from the receive antenna.

    ``down_m``: the transmit leg (default = ``distance_m``, the monostatic
    case); ``frequency_hz``: the excitation (default the first excitation
    channel); ``shift_hz``: the tag's shift (default the first tag's). Add
    ``10 log10(2^SF)`` for the SNR of the dechirped peak.
    """
    model = resolve_lora_model(model)
    up = np.asarray(distance_m, dtype=np.float64)
    down = up if down_m is None else np.asarray(down_m, dtype=np.float64)
    f = channel_frequencies(model)[model["excitation_channels"][0]] if frequency_hz is None else float(frequency_hz)
    s = model["tag_shifts_hz"][0] if shift_hz is None else float(shift_hz)
    wavelengths = (SPEED_OF_LIGHT / f) * (SPEED_OF_LIGHT / (f + s))
    power = _budget_constant(model, walls) * (wavelengths / (4.0 * np.pi) ** 2) ** 2 / (down * up) ** 2
    return 10.0 * np.log10(power / noise_power_w(model))


# --------------------------------------------------------------------------
# the simulator


class _Simulator:
    """The fixed quantities of one run and the per-epoch signal (module docstring)."""

    def __init__(self, pose_at: PoseAt, controller: dict, model: dict, seed: int):
        self.pose_at = pose_at
        self.model = model
        streams = dict(zip(STREAMS, np.random.default_rng(seed).spawn(len(STREAMS))))
        self.noise_rng = streams["noise"]
        self.bandwidth = float(model["bandwidth_hz"])
        self.n = 2 ** model["spreading_factor"]
        self.duration = chirp_duration_s(model)
        plan = channel_frequencies(model)
        self.excitation = plan[model["excitation_channels"]]  # f_j (J,) Hz
        self.shifts = np.asarray(model["tag_shifts_hz"], dtype=np.float64)  # s_k (K,) Hz
        self.body = tag_body_positions(model)  # (K, 3) m
        self.rho = controller["position"]
        self.offsets = array_offsets(controller["array"], model["array_side_m"])  # (M, 3) m
        self.tx = self.rho.copy()  # the data handler's antenna at the array centre
        self.rx = self.rho[None, :] + self.offsets
        self.walls = controller["walls"]
        j, k, m = len(self.excitation), len(self.shifts), len(self.offsets)
        self.shape = (j, k, m, self.n)

        # Tag clock (paper sec. III-B: one constant CFO per tag from one clock).
        self.eps = float(streams["clock"].uniform(-1.0, 1.0) * model["tag_clock_ppm"] * 1e-6)
        self.cfo = self.eps * self.shifts  # (K,) Hz
        self.phi_tag = float(streams["tag_phase"].uniform(0.0, 2.0 * np.pi))
        # Receive chains: a phase per antenna plus a cable delay seen as a phase at the uplink frequency.
        uplink = self.excitation[:, None] + self.shifts[None, :]  # f_j + s_k (J, K) Hz
        phase_m = streams["receiver"].uniform(0.0, 2.0 * np.pi, m)
        delay_m = streams["receiver"].uniform(0.0, model["rx_delay_max_s"], m)
        self.theta = wrap_angle(phase_m[None, None, :] - 2.0 * np.pi * uplink[:, :, None] * delay_m[None, None, :])  # (J, K, M)
        residual = streams["calibration"].normal(0.0, 1.0, self.theta.shape) * model["calibration_residual_rad"]
        self.theta_calibrated = wrap_angle(self.theta - residual)

        # Carrier of the round trip (the mean of downlink and uplink frequencies) and link constants.
        self.carrier = self.excitation[:, None] + self.shifts[None, :] / 2.0  # (J, K) Hz
        wavelengths = (SPEED_OF_LIGHT / self.excitation[:, None]) * (SPEED_OF_LIGHT / uplink)  # lambda_down lambda_up, m^2
        # a = sqrt(P_rx) = amplitude / (d_down d_up), sqrt(W) m^2
        self.amplitude = np.sqrt(_budget_constant(model, self.walls)) * wavelengths / (4.0 * np.pi) ** 2  # (J, K)
        self.noise_power = noise_power_w(model)
        self.sample_time = np.arange(self.n) / self.bandwidth  # u' = n / fs, s
        self.reflectors = model["reflectors"]

    def pose(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out = self.pose_at(t)
        if not isinstance(out, tuple) or len(out) != 2:
            raise ValueError("pose_at(t) must return (position (n, 3), orientation (n, 4))")
        position = np.asarray(out[0], dtype=np.float64)
        orientation = np.asarray(out[1], dtype=np.float64)
        if position.shape != (len(t), 3) or orientation.shape != (len(t), 4):
            raise ValueError(
                f"pose_at(t) for {len(t)} times returned position {position.shape} and orientation "
                f"{orientation.shape}; expected ({len(t)}, 3) and ({len(t)}, 4)"
            )
        if not (np.isfinite(position).all() and np.isfinite(orientation).all()):
            raise ValueError("pose_at(t) returned non-finite values")
        return position, orientation

    def epoch(self, chirp_start: np.ndarray) -> tuple[np.ndarray, dict]:
        """Samples ``(J, K, M, N)`` complex64 of one epoch and its truth (direct path, mid-chirp)."""
        jj, kk, mm, n = self.shape
        t = chirp_start[:, None] + self.sample_time[None, :]  # (J, N) s
        position, orientation = self.pose(t.ravel())
        rotation = quat_to_matrix(orientation)
        tags = position[:, None, :] + np.swapaxes(rotation @ self.body.T, 1, 2)  # p_k = R b_k + x, (J N, K, 3) m
        down = np.linalg.norm(tags - self.tx, axis=-1)  # (J N, K) m
        up = np.linalg.norm(tags[:, :, None, :] - self.rx[None, None, :, :], axis=-1)  # (J N, K, M) m

        # Phase common to every path: the tag clock, its switching phase, the receive chain.
        common = (2.0 * np.pi * self.cfo[None, :, None, None] * t[:, None, None, :]
                  + self.phi_tag + self.theta[..., None])  # (J, K, M, N)
        signal = np.zeros(self.shape, dtype=np.complex128)
        direct_path = self._add_path(signal, common, down[..., None] + up, 1.0 / (down[..., None] * up))
        for reflector in self.reflectors:
            coefficient = float(reflector["coefficient"])
            bent, present = bent_leg_lengths(self.tx[None, :], tags, reflector)  # downlink bent (J N, K)
            self._add_path(signal, common, bent[..., None] + up, coefficient / (bent[..., None] * up), present[..., None])
            bent, present = bent_leg_lengths(tags[:, :, None, :], self.rx[None, None, :, :], reflector)  # uplink bent
            self._add_path(signal, common, down[..., None] + bent, coefficient / (down[..., None] * bent), present)

        direct_power = (self.amplitude[:, :, None, None] / self._grid(down[..., None] * up)) ** 2  # W
        snr = np.mean(direct_power, axis=(0, 3)) / self.noise_power  # (K, M)
        if self.model["add_noise"]:
            noise = self.noise_rng.standard_normal((jj, kk, mm, n, 2), dtype=np.float32)
            noise *= np.float32(math.sqrt(self.noise_power / 2.0))
            signal += noise.view(np.complex64)[..., 0]
        truth = self._truth(t, position, orientation, direct_path, snr)
        return signal.astype(np.complex64), truth

    def _grid(self, values: np.ndarray) -> np.ndarray:
        """Per-sample values ``(J N, K, M)`` as ``(J, K, M, N)``."""
        jj, kk, mm, n = self.shape
        return np.broadcast_to(values, (jj * n, kk, mm)).reshape(jj, n, kk, mm).transpose(0, 2, 3, 1)

    def _add_path(self, signal, common, path_m, spread, present=None) -> np.ndarray:
        """``signal += a exp(i psi) c(u' - tau)`` for one propagation path; returns the path length ``(J, K, M, N)`` m.

        ``path_m``: unfolded length per sample ``(J N, K, M)``; ``spread``:
        ``1 / (leg x leg)`` (1/m^2, times the reflection coefficient);
        ``present``: where the path exists (image method).
        """
        path = self._grid(path_m)
        tau = path / SPEED_OF_LIGHT  # s
        u = self.sample_time - tau  # t - t_j - tau, s
        duration, bandwidth = self.duration, self.bandwidth
        phase = (common - 2.0 * np.pi * self.carrier[:, :, None, None] * tau
                 + 2.0 * np.pi * (-bandwidth / 2.0 * u + bandwidth / (2.0 * duration) * u * u))
        weight = self.amplitude[:, :, None, None] * self._grid(spread)
        inside = (u >= 0.0) & (u < duration)  # c(u) is zero outside its chirp
        if present is not None:
            inside &= self._grid(present)
        signal += np.where(inside, weight, 0.0) * np.exp(1j * phase)
        return path

    def _truth(self, t, position, orientation, path, snr) -> dict:
        """Truth of one epoch: pose at its start, and per (j, k, m) the direct path's dechirped tone (module docstring)."""
        mid = self.n // 2
        path_mid = path[..., mid]  # (J, K, M) m
        # Mean path rate over the chirp (least squares): the Doppler the FFT peak averages.
        centred = self.sample_time - self.sample_time.mean()
        rate = np.sum((path - path.mean(axis=-1, keepdims=True)) * centred, axis=-1) / np.sum(centred**2)  # m/s
        carrier = self.carrier[:, :, None]
        tau = path_mid / SPEED_OF_LIGHT
        doppler = -carrier * rate / SPEED_OF_LIGHT  # Hz
        slope = self.bandwidth / self.duration  # BW / T, Hz/s
        t_mid = t[:, mid][:, None, None]
        peak_frequency = self.cfo[None, :, None] + doppler - slope * tau
        peak_phase = wrap_angle(-2.0 * np.pi * carrier * tau + 2.0 * np.pi * self.cfo[None, :, None] * t_mid
                           + self.phi_tag + self.theta + np.pi * slope * tau**2)
        offset = position[0] - self.rho
        horizontal = math.hypot(offset[0], offset[1])
        return {
            "position_m": position[0], "orientation": orientation[0],
            "range_m": float(np.linalg.norm(offset)),
            "azimuth_rad": math.atan2(offset[1], offset[0]),
            "elevation_rad": math.atan2(offset[2], horizontal),
            "snr_db": 10.0 * np.log10(snr),
            "path_m": path_mid, "path_rate_m_s": rate, "doppler_hz": doppler,
            "peak_frequency_hz": peak_frequency, "peak_phase_rad": peak_phase,
        }


def recording_metadata(model: dict, controller: dict, simulator: _Simulator, n_epochs: int, seed: int) -> dict:
    """The recording's metadata: every parameter the DSP may use (JSON values; the SigMF ``scattertrack:`` keys)."""
    from scattertrack import __version__

    return {
        "generator": "scattertrack.sim.lora",
        "version": __version__,
        "seed": int(seed),
        "spreading_factor": int(model["spreading_factor"]),
        "bandwidth_hz": float(model["bandwidth_hz"]),
        "sample_rate_hz": float(model["bandwidth_hz"]),
        "samples_per_chirp": int(simulator.n),
        "chirp_duration_s": float(simulator.duration),
        "channel_frequencies_hz": channel_frequencies(model).tolist(),
        "excitation_channels": list(model["excitation_channels"]),
        "excitation_frequencies_hz": simulator.excitation.tolist(),
        "tag_shifts_hz": simulator.shifts.tolist(),
        "tag_names": ["1", "1'", "3", "3'"] if len(simulator.shifts) == 4 else [str(k + 1) for k in range(len(simulator.shifts))],
        "tag_body_positions_m": simulator.body.tolist(),
        "array": controller["array"],
        "array_offsets_m": simulator.offsets.tolist(),
        "transmit_offset_m": [0.0, 0.0, 0.0],
        "rx_phase_offsets_rad": simulator.theta_calibrated.tolist(),
        "sensing_rate_hz": float(model["sensing_rate_hz"]),
        "epoch_period_s": 1.0 / float(model["sensing_rate_hz"]),
        "noise_power_w": float(simulator.noise_power),
        "n_epochs": int(n_epochs),
        "sample_units": "sqrt(W): |y|^2 is the received power in watts",
        "stream_order": "samples[epoch, excitation j, tag k, receive antenna m, sample n]",
        "model": {key: value for key, value in model.items()},
    }


def simulate_lora_iq(pose_at: PoseAt, controller: dict, model: dict | None, duration_s: float, seed: int) -> LoraRecording:
    """Simulate the controller's channelised streams over a flight: :class:`LoraRecording`.

    ``pose_at(t)``: the flight, ``t`` (n,) s -> ``(position (n, 3) m,
    orientation (n, 4) qw, qx, qy, qz world_T_body)``; called once per epoch
    with all of its sample times (2 x 4096 at the defaults). ``controller``:
    ``{"position": [x, y, z] m, "array": "triangle" | "linear", "walls": int}``.
    ``model``: keys of :data:`LORA_MODEL_DEFAULTS`. ``duration_s``: the
    flight time covered (``floor(duration_s sensing_rate_hz)`` epochs).

    ``samples``: complex64 ``(epochs, J, K, M, N)`` in sqrt(W); ``metadata``:
    :func:`recording_metadata`; ``details`` (hidden truth, numpy arrays):
    ``controller_position_m``, ``walls``, ``clock_error`` (eps), ``cfo_hz``
    (K,), ``tag_phase_rad`` (phi_tag), ``rx_phase_offsets_true_rad`` (J, K,
    M), ``noise_power_w``, and per epoch ``position_m`` (E, 3) and
    ``orientation`` (E, 4) at the epoch start, ``range_m``, ``azimuth_rad``,
    ``elevation_rad`` (E,) from the array centre to the body origin,
    ``snr_db`` (E, K, M) the direct path's per-sample SNR, and per (E, J, K,
    M) at mid-chirp the direct ``path_m``, ``path_rate_m_s``,
    ``doppler_hz``, the predicted dechirped ``peak_frequency_hz`` and
    ``peak_phase_rad`` (module docstring). Same inputs and seed: identical
    output.
    """
    model = resolve_lora_model(model)
    controller = resolve_controller(controller, model)
    count = math.floor(float(duration_s) * model["sensing_rate_hz"] + 1e-9)
    if count < 1:
        raise ValueError(f"duration_s = {duration_s} s is shorter than one sensing period ({1.0 / model['sensing_rate_hz']} s)")
    simulator = _Simulator(pose_at, controller, model, int(seed))
    jj = len(simulator.excitation)
    epoch_time = model["start_time_s"] + np.arange(count) / model["sensing_rate_hz"]
    chirp_start = epoch_time[:, None] + np.arange(jj)[None, :] * simulator.duration
    samples = np.empty((count,) + simulator.shape, dtype=np.complex64)
    per_epoch = []
    for e in range(count):
        samples[e], truth = simulator.epoch(chirp_start[e])
        per_epoch.append(truth)
    details = {
        "seed": int(seed),
        "controller_position_m": controller["position"].copy(),
        "array": controller["array"],
        "walls": controller["walls"],
        "clock_error": simulator.eps,
        "cfo_hz": simulator.cfo.copy(),
        "tag_phase_rad": simulator.phi_tag,
        "rx_phase_offsets_true_rad": simulator.theta.copy(),
        "noise_power_w": simulator.noise_power,
        "time_s": epoch_time.copy(),
    }
    for key in per_epoch[0]:
        details[key] = np.array([truth[key] for truth in per_epoch])
    metadata = recording_metadata(model, controller, simulator, count, int(seed))
    return LoraRecording(samples, epoch_time, chirp_start, metadata, details)
