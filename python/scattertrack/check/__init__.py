"""Checks a scene before tracking: :mod:`scattertrack.check.geometry` tells
when a monostatic antenna layout cannot fix a tag's position (twin positions
that fit every phase) and what would fix it; :mod:`scattertrack.check.helper`
does the same for a localization helper's receivers in line with its
transmitter."""

from scattertrack.check.geometry import GeometryCheck, Finding, check_scene, twin_positions
from scattertrack.check.helper import check_helper_scene

__all__ = ["GeometryCheck", "Finding", "check_helper_scene", "check_scene", "twin_positions"]
