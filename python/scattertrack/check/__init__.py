"""Checks a scene before tracking: :mod:`scattertrack.check.geometry` tells
when an antenna layout cannot fix a tag's position (twin positions that fit
every phase) and what would fix it."""

from scattertrack.check.geometry import GeometryCheck, Finding, check_scene, twin_positions

__all__ = ["GeometryCheck", "Finding", "check_scene", "twin_positions"]
