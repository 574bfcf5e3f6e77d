"""The Marvel feature model's parameters: ``[feature_model]`` and its checks, the LoRa channel plan.

The tables a marvel scenario is resolved against (docs/marvel.md section 9),
apart from the simulator that uses them (:mod:`scattertrack.sim.marvel`), so
scenario resolution (:mod:`scattertrack.sim.scenario_resolve`) can check a
scenario without importing the simulator, which resolves scenarios itself.
"""

from __future__ import annotations

import math

from scattertrack.sim.drone import ParameterError, with_defaults

CHANNEL_BASE_HZ = 902.1e6
"""LoRa channel 0, hertz (docs/marvel.md section 5)."""
CHANNEL_SPACING_HZ = 2.16e6
"""Spacing of the 13 channels, hertz."""
ARRAYS = ("triangle", "linear")
"""Controller arrays (docs/marvel.md section 4)."""
DEFAULT_REGION = ([-60.0, -60.0, -1.0], [60.0, 60.0, 20.0])
"""The scene's region when a scenario gives none, metres: the paper's 50 m range around the take-off point."""

FEATURE_MODEL_DEFAULTS = {
    # --- sensing schedule
    "rate_hz": 10.0,  # Hz, sensing epochs per second (paper sec. IV-A: ~10 Hz)
    "channels": [0, 12],  # excitation channel indices (docs/marvel.md section 5: the widest aperture)
    "bandwidth_hz": 500e3,  # Hz, LoRa BW (paper sec. III-B)
    "spreading_factor": 12,  # SF (paper sec. III-B): chirp of 2^SF samples, T = 8.192 ms
    "array_side_m": 0.16,  # m, the triangle's side or the linear array's spacing (docs/marvel.md section 4)
    # --- link budget
    "tx_power_dbm": 20.0,  # dBm, USRP UBX-160 maximum output (paper sec. V-A hardware)
    "tx_gain_dbi": 3.0,  # dBi, the data handler's antenna (a 900 MHz dipole/whip)
    "rx_gain_dbi": 3.0,  # dBi, each receive antenna
    "tag_gain_dbi": 0.0,  # dBi, a tag's small antenna, counted twice (receive and re-radiate)
    "backscatter_loss_db": 24.0,  # dB, tag conversion + implementation loss; calibrated (docs section 9)
    "noise_figure_db": 6.0,  # dB, receiver noise figure (UBX-160 class)
    "wall_loss_db": 4.0,  # dB per brick wall per crossing at 915 MHz (ITU-R P.2040, ~10-20 cm brick)
    "snr_ceiling_db": 45.0,  # dB, highest post-dechirp SNR (phase noise / carrier leakage limit)
    "decode_snr_db": -20.0,  # dB per-sample SNR below which a chirp is lost (Semtech SX1276, SF12)
    "shadowing_db": 1.5,  # dB, 1-sigma slow shadowing in the open
    "shadowing_per_wall_db": 0.5,  # dB added to that sigma per wall
    # --- multipath and walls
    "range_multipath_m": 0.6,  # m, 1-sigma multipath range error in the open (paper Fig. 10: ~0.6 m at 1 m)
    "range_multipath_per_wall_m": 0.1,  # m added per wall
    "angle_multipath_rad": 0.05,  # rad, 1-sigma multipath angle error per axis (paper Fig. 10: 1.44 m at 20 m)
    "angle_multipath_per_wall_rad": 0.015,  # rad added per wall
    "doppler_floor_hz": 0.2,  # Hz, multipath/residual floor of the rotational shift (paper Fig. 11: 9.2 deg)
    "doppler_floor_per_wall_hz": 0.1,  # Hz added per wall (paper Fig. 11: 17.6 deg through walls)
    "wall_thickness_m": 0.2,  # m, each brick wall
    "wall_permittivity": 3.75,  # relative permittivity of brick (ITU-R P.2040)
    "multipath_distance_m": 0.5,  # m travelled over which multipath errors decorrelate
    "multipath_time_s": 5.0,  # s over which they decorrelate at rest (people, doors)
    # --- yaw
    "min_yaw_rate": 0.1,  # rad/s: below this |omega_z| no yaw is reported
    "max_yaw_sigma_rad": 0.6,  # rad: a yaw less certain than this is not reported
}
"""The feature model; a scenario's ``[feature_model]`` overrides keys."""

_POSITIVE = (
    "rate_hz",
    "array_side_m",
    "bandwidth_hz",
    "wall_thickness_m",
    "multipath_distance_m",
    "multipath_time_s",
    "max_yaw_sigma_rad",
)
_NON_NEGATIVE = (
    "shadowing_db",
    "shadowing_per_wall_db",
    "range_multipath_m",
    "range_multipath_per_wall_m",
    "angle_multipath_rad",
    "angle_multipath_per_wall_rad",
    "doppler_floor_hz",
    "doppler_floor_per_wall_hz",
    "wall_loss_db",
    "backscatter_loss_db",
    "noise_figure_db",
    "min_yaw_rate",
)
_ANY = ("tx_power_dbm", "tx_gain_dbi", "rx_gain_dbi", "tag_gain_dbi", "snr_ceiling_db", "decode_snr_db")


def resolve_feature_model(given: dict | None = None) -> dict:
    """The feature model with defaults filled in; raises :class:`ParameterError` naming the key."""
    model = with_defaults(given, FEATURE_MODEL_DEFAULTS)
    for key in _POSITIVE + _NON_NEGATIVE + _ANY:
        value = model[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ParameterError(key, f"must be a finite number, got {value!r}")
        if key in _POSITIVE and value <= 0:
            raise ParameterError(key, f"must be > 0, got {value!r}")
        if key in _NON_NEGATIVE and value < 0:
            raise ParameterError(key, f"must be >= 0, got {value!r}")
        model[key] = float(value)
    model["wall_permittivity"] = _number_at_least(model, "wall_permittivity", 1.0)
    sf = model["spreading_factor"]
    if isinstance(sf, bool) or not isinstance(sf, int) or not 7 <= sf <= 12:
        raise ParameterError("spreading_factor", f"must be an integer from 7 to 12, got {sf!r}")
    channels = model["channels"]
    if (
        not isinstance(channels, list)
        or not channels
        or not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 12 for c in channels)
        or len(set(channels)) != len(channels)
    ):
        raise ParameterError("channels", f"must be a list of distinct channel indices 0..12, got {channels!r}")
    return model


def _number_at_least(model: dict, key: str, minimum: float) -> float:
    value = model[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < minimum:
        raise ParameterError(key, f"must be a number >= {minimum}, got {value!r}")
    return float(value)
