"""A monostatic scene as the core's constructors take it (``_core.Engine``,
``_core.analyse_scene``, ``_core.twin_positions``): one place that flattens
:class:`scattertrack.io.Scene` for the Rust boundary."""

from __future__ import annotations

import numpy as np

from scattertrack.io.types import Scene

DEFAULT_PHASE_NOISE_RAD = 0.1
"""The filter's prior when the scene states none (docs/formats.md section 1), radians."""


def scene_arguments(scene: Scene) -> tuple:
    """``(dimensions, plane_z, phase_sign, period_rad, phase_noise_rad,
    antenna positions (n, 3) m, antenna offsets (n,) rad, region (min, max) m
    or None, channel frequencies (k,) Hz, channel offsets (k,) rad)``."""
    positions = np.array([a.position for a in scene.antennas], dtype=float).reshape(-1, 3)
    offsets = np.array([a.phase_offset_rad for a in scene.antennas], dtype=float)
    region = None
    if scene.region is not None:
        region = (np.asarray(scene.region.min, dtype=float), np.asarray(scene.region.max, dtype=float))
    frequencies = np.array([c.frequency_hz for c in scene.channel_offsets], dtype=float)
    channel_offsets = np.array([c.phase_offset_rad for c in scene.channel_offsets], dtype=float)
    noise = scene.reader.phase_noise_rad if scene.reader.phase_noise_rad else DEFAULT_PHASE_NOISE_RAD
    plane_z = scene.plane_z if scene.plane_z is not None else 0.0
    return (
        int(scene.dimensions),
        float(plane_z),
        float(scene.reader.phase_sign),
        float(scene.reader.period_rad),
        float(noise),
        positions,
        offsets,
        region,
        frequencies,
        channel_offsets,
    )
