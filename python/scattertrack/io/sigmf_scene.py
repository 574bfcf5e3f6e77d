"""A helper recording against what else describes the same hardware: its own antenna list,
the scene it is tracked in, and the calibration recording that corrects it.

A recording lists the antennas it was made with (``scattertrack:antennas``:
``id``, ``position`` in metres, ``role``); the trackers take positions from
the scene. The two are written by different hands (the recorder, the
user), so they can disagree: an antenna moved after the survey, a scene of
another set-up. A role that contradicts the recording's own ``tx_id`` and
``channels`` is an error (the file is inconsistent); a position more than
:data:`POSITION_TOLERANCE_M` from the scene's, or OFDM numbers other than the
scene's ``[helper]`` table, is valid but suspicious: a warning naming the
file and key. A calibration made with other receive antennas or
subcarriers than the recording cannot correct it: an error naming the
calibration file.
"""

from __future__ import annotations

import math

import numpy as np

from scattertrack.io.types import FormatError, Scene, warn_input

NAMESPACE = "scattertrack"

POSITION_TOLERANCE_M = 0.05
"""A recorded antenna position this far from the scene's, metres, is warned: surveys agree to
about a centimetre, and 5 cm is a sixth of a UHF wavelength, enough to move every lobe."""

HELPER_KEYS = (("centre_frequency_hz", "centre_hz"), ("bandwidth_hz", "bandwidth_hz"),
               ("n_subcarriers", "subcarriers"), ("blf_hz", "blf_hz"))
"""(scene ``[helper]`` key, recording ``scattertrack:`` key) pairs that describe the same OFDM set-up."""


def finite_vector(value) -> bool:
    """Whether a JSON value is 3 finite numbers (a position)."""
    return (isinstance(value, list) and len(value) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value))


def check_antennas(meta_path, g: dict) -> None:
    """Validate ``global.scattertrack:antennas`` against the recording's own ``tx_id`` and ``channels``.

    Each entry: an integer ``id`` (unique), a ``position`` of 3 finite
    numbers (metres) and a ``role`` "tx" or "rx"; ``tx_id`` must be listed
    as the "tx", every channel as an "rx". Raises :class:`FormatError` naming
    the entry's key (``global.scattertrack:antennas[2].role``).
    """
    key = f"global.{NAMESPACE}:antennas"
    antennas = g[f"{NAMESPACE}:antennas"]
    if not isinstance(antennas, list) or not antennas:
        raise FormatError(meta_path, None, key, f"must be a non-empty list of {{id, position, role}}, got {antennas!r}")
    roles = {}
    for i, antenna in enumerate(antennas):
        where = f"{key}[{i}]"
        if not isinstance(antenna, dict):
            raise FormatError(meta_path, None, where, f"must be an object {{id, position, role}}, got {antenna!r}")
        antenna_id = antenna.get("id")
        if isinstance(antenna_id, bool) or not isinstance(antenna_id, int):
            raise FormatError(meta_path, None, f"{where}.id", f"missing or not an integer antenna id: {antenna_id!r}")
        if antenna_id in roles:
            raise FormatError(meta_path, None, f"{where}.id", f"antenna id {antenna_id} is listed twice")
        if not finite_vector(antenna.get("position")):
            raise FormatError(meta_path, None, f"{where}.position",
                              f"missing or not 3 finite numbers (metres): {antenna.get('position')!r}")
        role = antenna.get("role")
        if role not in ("tx", "rx"):
            raise FormatError(meta_path, None, f"{where}.role", f"must be 'tx' or 'rx', got {role!r}")
        roles[antenna_id] = (i, role)
    wanted = [(g[f"{NAMESPACE}:tx_id"], "tx", "tx_id")] + [(c, "rx", "channels") for c in g[f"{NAMESPACE}:channels"]]
    for antenna_id, role, source in wanted:
        if antenna_id not in roles:
            raise FormatError(meta_path, None, key, f"antenna {antenna_id} ({NAMESPACE}:{source}) is not listed")
        index, listed = roles[antenna_id]
        if listed != role:
            raise FormatError(meta_path, None, f"{key}[{index}].role",
                              f"antenna {antenna_id} is listed as {listed!r} but {NAMESPACE}:{source} makes it {role!r}")


def _metres(position) -> str:
    return "(" + ", ".join(f"{float(v):.3f}" for v in position) + ") m"


def warn_scene_disagreement(where, scene: Scene, g: dict) -> None:
    """Warn (:class:`InputWarning`) where the recording's metadata ``g`` and the ``scene`` disagree.

    Antenna positions more than :data:`POSITION_TOLERANCE_M` apart (the
    trackers use the scene's), roles that differ (for the antennas the
    recording uses that is an error of ``sigmf._positions``; this covers the
    others it lists), and OFDM numbers other than the scene's ``[helper]``
    table (the recording's are used: they are what was transmitted).
    """
    by_id = {int(a.id): a for a in scene.antennas}
    used = {g.get(f"{NAMESPACE}:tx_id"), *(g.get(f"{NAMESPACE}:channels") or [])}
    for i, antenna in enumerate(g.get(f"{NAMESPACE}:antennas") or []):
        known = by_id.get(antenna["id"])
        if known is None:
            continue
        recorded = np.asarray(antenna["position"], dtype=float)
        apart = float(np.linalg.norm(recorded - np.asarray(known.position, dtype=float)))
        if apart > POSITION_TOLERANCE_M:
            warn_input(
                where, None, f"global.{NAMESPACE}:antennas[{i}].position",
                f"antenna {antenna['id']} is at {_metres(recorded)} in the recording but at {_metres(known.position)} "
                f"in scene {scene.name!r}, {apart * 100:.1f} cm apart (warned beyond {POSITION_TOLERANCE_M * 100:g} cm): "
                "the trackers use the scene's position; check which is right",
            )
        if antenna["role"] != known.role and antenna["id"] not in used:
            warn_input(where, None, f"global.{NAMESPACE}:antennas[{i}].role",
                       f"antenna {antenna['id']} is {antenna['role']!r} in the recording but {known.role!r} in scene "
                       f"{scene.name!r}")
    helper = scene.extra.get("helper")
    if not isinstance(helper, dict):
        return
    for scene_key, key in HELPER_KEYS:
        recorded = g.get(f"{NAMESPACE}:{key}")
        if scene_key in helper and recorded is not None and not math.isclose(float(helper[scene_key]), float(recorded),
                                                                            rel_tol=1e-9):
            warn_input(where, None, f"global.{NAMESPACE}:{key}",
                       f"is {recorded!r} but scene {scene.name!r} has [helper] {scene_key} = {helper[scene_key]!r}: "
                       "the recording's value is used (it is what was transmitted)")


def check_calibration(calibration, channels: list[int], frequencies_hz: np.ndarray) -> None:
    """Refuse a calibration (``SigmfCalibration``) made with other receive antennas or subcarriers
    than the recording's: :class:`FormatError` naming the calibration's file and key."""
    if list(calibration.rx_ids) != list(channels):
        raise FormatError(calibration.source, None, f"global.{NAMESPACE}:channels",
                          f"the calibration's receive antennas {list(calibration.rx_ids)} differ from the "
                          f"recording's {list(channels)}: it was made with another set-up")
    ours = np.asarray(calibration.frequencies_hz, dtype=float)
    if ours.shape != frequencies_hz.shape or not np.allclose(ours, frequencies_hz):
        raise FormatError(calibration.source, None, f"global.{NAMESPACE}:subcarriers",
                          f"the calibration's {len(ours)} subcarriers ({ours.min() / 1e6:.3f} to {ours.max() / 1e6:.3f} "
                          f"MHz) differ from the recording's {len(frequencies_hz)} ({frequencies_hz.min() / 1e6:.3f} to "
                          f"{frequencies_hz.max() / 1e6:.3f} MHz): it was made with another set-up")
