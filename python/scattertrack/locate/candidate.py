"""What ``locate`` answers: a tag's :class:`Location`, its :class:`Candidate` positions best first."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Candidate:
    position: np.ndarray
    covariance: np.ndarray
    """3×3, m²."""
    weight: float
    cue: str
    """"phase", "phase+rssi", "rssi" or "region" (no usable cue)."""
    coherence: float = math.nan


@dataclass
class Location:
    epc: str
    reads: int
    candidates: list = field(default_factory=list)
    """Best first; the first one's covariance covers the others."""
    note: str = ""
    """Why the phase was not used, when it was not."""
