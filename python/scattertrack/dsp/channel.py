"""The helper's bistatic wideband channel: the model the DSP calibrates against and the simulators draw.

One transmit antenna, several receive antennas, ``N`` OFDM subcarriers over a
bandwidth ``B`` (thesis ch. 4): :func:`subcarrier_frequencies` (the grid),
:func:`bistatic_path_lengths` (the ellipsoid a channel measures),
:func:`tag_channel` (the paths that touch the tag: what a calibrated
channel estimate is, and the reference :func:`scattertrack.dsp.ofdm.calibrate_sigmf`
divides into) and :func:`static_channel` (direct tx -> rx leakage and static
clutter, which the reflective-minus-non-reflective subtraction removes).
Pure, vectorised numpy.

Channel convention (docs/formats.md section 5)
    After calibration one propagation path of length ``L`` (metres) gives
    ``a * exp(-j 2 pi f L / c)`` with ``a`` real, ``c = 299 792 458 m/s``.
    For the direct path ``L = d1 + d2`` with ``d1 = |tx - tag|`` and
    ``d2 = |tag - rx|`` and the free-space bistatic amplitude
    ``a = d_ref^2 / (d1 d2)``: each leg spreads as ``1 / distance``, and the
    constant (wavelength, antenna gains, the tag's differential cross-section,
    the calibration's gain) is chosen so that a tag ``d_ref = 1 m`` from both
    antennas has ``|h| = 1``. The convention ``exp(-j ...)`` makes the phase
    fall as the path grows: ``-arg h = 2 pi f L / c (mod 2 pi)``.

Multipath (reflectors, the dicts of ``[[reader_model.reflectors]]`` in the
COTS simulator: ``{"kind": "point", "position", "coefficient"}`` or
``{"kind": "plane", "point", "normal", "coefficient"}``)
    A reflector bends one leg: a point scatterer ``P`` turns the leg
    ``A -> B`` into ``A -> P -> B`` of length ``|A - P| + |P - B|``; a plane
    mirror turns it into the image-source path of length
    ``|B - image(A)|`` (only when ``A`` and ``B`` are on the same side).
    The bent leg spreads over its whole unfolded length and is scaled by the
    real amplitude reflection coefficient ``Gamma`` (negative: a phase flip),
    so a tag path bent on the outgoing leg has
    ``a = Gamma d_ref^2 / (g1 d2)`` and length ``g1 + d2``, one bent on the
    return leg ``a = Gamma d_ref^2 / (d1 g2)`` and length ``d1 + g2``.
    Paths with two bounces (``Gamma^2``) are left out.

Units: metres, seconds, hertz, radians.
"""

from __future__ import annotations

import numpy as np

from scattertrack.physics import SPEED_OF_LIGHT

REFERENCE_DISTANCE_M = 1.0
"""d_ref, metres: a tag this far from the transmit and the receive antenna has |h| = 1."""

DIRECT_LEAKAGE = 300.0
"""Default amplitude of the direct tx -> rx path for antennas ``d_ref`` apart,
in the units of :func:`tag_channel` (about 50 dB above a tag 1 m from both).

Why 300: relative to the direct leg, the tag path has a second free-space
leg, ``lambda / (4 pi d)`` = 0.026 at 1 m and 915 MHz, and the tag's
differential reflection (modulation loss, about 0.1-0.3 in amplitude); the
ratio ``4 pi d / (lambda rho)`` is 150-400. This is why the helper must
subtract the non-reflective state: the leakage swamps the tag channel."""



# --------------------------------------------------------------------------
# geometry


def bistatic_path_lengths(tx, rx, tag) -> np.ndarray:
    """Bistatic path length ``|tx - tag| + |tag - rx|``, metres, shape (T, R).

    ``tx``: transmit antenna, (3,) m; ``rx``: receive antennas, (R, 3) m;
    ``tag``: tag positions, (T, 3) m. This is the distance of one ellipsoid
    (foci tx and rx) that a wideband channel measures (thesis sec. 5.2).
    """
    tx = np.asarray(tx, dtype=np.float64).reshape(3)
    rx = np.asarray(rx, dtype=np.float64).reshape(-1, 3)
    tag = np.asarray(tag, dtype=np.float64).reshape(-1, 3)
    outgoing = np.linalg.norm(tag - tx, axis=1)  # (T,)
    returning = np.linalg.norm(tag[:, None, :] - rx[None, :, :], axis=2)  # (T, R)
    return outgoing[:, None] + returning


def subcarrier_frequencies(centre_frequency_hz: float, bandwidth_hz: float, n_subcarriers: int) -> np.ndarray:
    """Subcarrier frequencies, hertz, ascending: the helper's OFDM grid with DC dropped.

    ``N`` subcarriers over the bandwidth ``B`` are ``B / N`` apart (the OFDM
    symbol has ``N`` samples at ``B`` samples/s) and sit symmetrically about
    the centre: ``f_k = f_c + (k - (N - 1) / 2) B / N``, ``k = 0 .. N - 1``.
    With ``N`` even no subcarrier falls on the centre (DC) frequency: the
    local oscillator sits half a spacing between the two middle subcarriers.
    With ``N`` odd the middle subcarrier would be DC; it is dropped (the
    helper drops DC, sec. 4.3), leaving ``N - 1``. Example: 915 MHz, 100 MHz,
    20 subcarriers give 867.5, 872.5, ..., 962.5 MHz.
    """
    n = int(n_subcarriers)
    if n < 1 or not (bandwidth_hz > 0.0) or not (centre_frequency_hz > bandwidth_hz / 2.0):
        raise ValueError(
            f"need n_subcarriers >= 1, bandwidth_hz > 0 and centre_frequency_hz > bandwidth_hz / 2, "
            f"got {n_subcarriers}, {bandwidth_hz}, {centre_frequency_hz}"
        )
    offset = np.arange(n) - (n - 1) / 2.0  # in spacings, symmetric about 0
    if n % 2 == 1:
        offset = offset[offset != 0.0]  # the DC subcarrier
    return centre_frequency_hz + offset * (bandwidth_hz / n)


def _unit_normal(reflector: dict) -> np.ndarray:
    normal = np.asarray(reflector["normal"], dtype=np.float64).reshape(3)
    length = np.linalg.norm(normal)
    if not length > 0.0:
        raise ValueError(f"reflector normal must be a non-zero vector, got {reflector['normal']!r}")
    return normal / length


def bent_leg_lengths(start, end, reflector: dict) -> tuple[np.ndarray, np.ndarray]:
    """Unfolded length (m) of the leg ``start -> reflector -> end``, and whether it exists.

    ``start`` and ``end`` are points (..., 3) m that broadcast together.
    A point scatterer gives ``|start - P| + |P - end|`` (always present); a
    plane mirror the image-source length ``|end - image(start)|``, present
    only when both points are strictly on the same side of the plane.
    Returns ``(length, present)`` with the broadcast shape (...).
    """
    start = np.asarray(start, dtype=np.float64)
    end = np.asarray(end, dtype=np.float64)
    kind = reflector.get("kind")
    if kind == "point":
        point = np.asarray(reflector["position"], dtype=np.float64).reshape(3)
        length = np.linalg.norm(start - point, axis=-1) + np.linalg.norm(end - point, axis=-1)
        return length, np.ones(length.shape, dtype=bool)
    if kind == "plane":
        point = np.asarray(reflector["point"], dtype=np.float64).reshape(3)
        normal = _unit_normal(reflector)
        start_side = (start - point) @ normal
        end_side = (end - point) @ normal
        image = start - 2.0 * start_side[..., None] * normal
        length = np.linalg.norm(end - image, axis=-1)
        return length, start_side * end_side > 0.0
    raise ValueError(f"reflector kind must be 'point' or 'plane', got {kind!r}")


# --------------------------------------------------------------------------
# channels


def _add_path(channel: np.ndarray, amplitude: np.ndarray, length_m: np.ndarray, wavenumber: np.ndarray) -> None:
    """``channel += amplitude * exp(-j k L)`` in place; amplitude and length (...), k (F,)."""
    channel += amplitude[..., None] * np.exp(-1j * length_m[..., None] * wavenumber)


def tag_channel(
    tx,
    rx,
    tag_positions,
    frequencies_hz,
    reflectors: list[dict] | None = None,
    *,
    reference_distance_m: float = REFERENCE_DISTANCE_M,
) -> np.ndarray:
    """Calibrated tag channel, complex, shape (T, R, F): the paths that touch the tag.

    ``tx``: transmit antenna (3,) m; ``rx``: receive antennas (R, 3) m;
    ``tag_positions``: (T, 3) m; ``frequencies_hz``: subcarriers (F,) Hz;
    ``reflectors``: multipath (module docstring), none by default.

    ``h(f) = sum_p a_p exp(-j 2 pi f L_p / c)``: the direct path
    (``L = d1 + d2``, ``a = d_ref^2 / (d1 d2)``) plus, per reflector, the path
    bent on the outgoing leg (tx -> reflector -> tag -> rx) and the one bent
    on the return leg (tx -> tag -> reflector -> rx), each scaled by the
    reflector's coefficient. Dimensionless; ``|h| = 1`` for a tag at
    ``reference_distance_m`` from both antennas without multipath.
    """
    tx = np.asarray(tx, dtype=np.float64).reshape(3)
    rx = np.asarray(rx, dtype=np.float64).reshape(-1, 3)
    tag = np.asarray(tag_positions, dtype=np.float64).reshape(-1, 3)
    wavenumber = 2.0 * np.pi * np.asarray(frequencies_hz, dtype=np.float64).reshape(-1) / SPEED_OF_LIGHT  # rad/m
    scale = reference_distance_m**2
    outgoing = np.linalg.norm(tag - tx, axis=1)[:, None]  # d1, (T, 1)
    returning = np.linalg.norm(tag[:, None, :] - rx[None, :, :], axis=2)  # d2, (T, R)
    channel = np.zeros((len(tag), len(rx), len(wavenumber)), dtype=np.complex128)
    _add_path(channel, scale / (outgoing * returning), outgoing + returning, wavenumber)
    for reflector in reflectors or ():
        coefficient = float(reflector["coefficient"])
        # Outgoing leg bent: tx -> reflector -> tag (one length per tag), then tag -> rx.
        bent, present = bent_leg_lengths(tx[None, :], tag, reflector)
        bent, present = bent[:, None], present[:, None]
        amplitude = np.where(present, coefficient * scale / (bent * returning), 0.0)
        _add_path(channel, amplitude, bent + returning, wavenumber)
        # Return leg bent: tx -> tag, then tag -> reflector -> rx (one per tag and rx).
        bent, present = bent_leg_lengths(tag[:, None, :], rx[None, :, :], reflector)
        amplitude = np.where(present, coefficient * scale / (outgoing * bent), 0.0)
        _add_path(channel, amplitude, outgoing + bent, wavenumber)
    return channel


def static_channel(
    tx,
    rx,
    frequencies_hz,
    reflectors: list[dict] | None = None,
    leakage: float = DIRECT_LEAKAGE,
    *,
    reference_distance_m: float = REFERENCE_DISTANCE_M,
) -> np.ndarray:
    """The paths that do not touch the tag, complex, shape (R, F), in :func:`tag_channel`'s units.

    The direct tx -> rx leakage, ``leakage * (d_ref / d0) exp(-j 2 pi f d0 / c)``
    with ``d0 = |tx - rx|`` (one free-space leg), plus static clutter: per
    reflector the bent leg tx -> reflector -> rx, ``leakage * Gamma * d_ref / g``
    with ``g`` its unfolded length. The tag's non-reflective state sees this
    channel alone and the reflective state this plus the tag channel, so the
    helper's reflective-minus-non-reflective subtraction removes it
    (thesis sec. 4.3 (c)). ``leakage`` is the direct path's amplitude for
    antennas ``d_ref`` apart (:data:`DIRECT_LEAKAGE`, about 50 dB above a tag
    at 1 m); the IQ simulator adds this to every symbol.
    """
    tx = np.asarray(tx, dtype=np.float64).reshape(3)
    rx = np.asarray(rx, dtype=np.float64).reshape(-1, 3)
    wavenumber = 2.0 * np.pi * np.asarray(frequencies_hz, dtype=np.float64).reshape(-1) / SPEED_OF_LIGHT
    direct = np.linalg.norm(rx - tx, axis=1)  # d0, (R,)
    if not np.all(direct > 0.0):
        raise ValueError("a receive antenna sits on the transmit antenna (d0 = 0)")
    channel = np.zeros((len(rx), len(wavenumber)), dtype=np.complex128)
    _add_path(channel, leakage * reference_distance_m / direct, direct, wavenumber)
    for reflector in reflectors or ():
        bent, present = bent_leg_lengths(tx[None, :], rx, reflector)
        amplitude = np.where(present, leakage * float(reflector["coefficient"]) * reference_distance_m / bent, 0.0)
        _add_path(channel, amplitude, bent, wavenumber)
    return channel
