"""The method registry, as Python sees it: read once from the Rust core
(``crates/core/src/track/registry.rs``, the one list of methods), so a
method's name, pipeline, input and description are written in one place.
"""

from __future__ import annotations

from dataclasses import dataclass

from scattertrack import _core


@dataclass(frozen=True)
class Method:
    """One registered method."""

    name: str
    pipeline: str
    """``cots`` (RFID reader), ``helper`` (reader + SDR helper) or ``drone``."""
    input: str
    """``reads``, ``frames``, ``features+imu`` or ``sigmf+imu``."""
    input_files: str
    """The files it takes, for listings."""
    estimator: str
    """``core`` (Rust) or ``python`` (Marvel's factor graph)."""
    description: str


REGISTRY: dict[str, Method] = {row["name"]: Method(**row) for row in _core.methods()}
"""Every method by name, in listing order."""

METHODS: tuple[str, ...] = tuple(REGISTRY)
"""Every registered method name."""

READ_METHODS: tuple[str, ...] = tuple(m.name for m in REGISTRY.values() if m.input == "reads")
"""Methods that track phase reads (GLAC and its variants)."""

HELPER_METHODS: tuple[str, ...] = tuple(m.name for m in REGISTRY.values() if m.input == "frames")
"""Methods that track a localization helper's wideband frames (TurboTrack and its variants)."""

WIDEBAND_METHODS: tuple[str, ...] = HELPER_METHODS
"""The helper pipeline's methods under their old name."""

DRONE_METHODS: tuple[str, ...] = tuple(m.name for m in REGISTRY.values() if m.pipeline == "drone")
"""Methods that track the drone (Marvel and mu-locate: IMU plus features or a LoRa recording)."""


def method(name: str) -> Method:
    """The registered method ``name``; ValueError naming the known ones otherwise."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown method '{name}' (known: {', '.join(METHODS)})") from None
