"""Readers and writers of the public formats (docs/formats.md sections 1-7).

Contract: every reader validates and raises :class:`FormatError` naming the
file, the 1-based line and the column for a malformed file; suspicious but
valid input (a clock jump, an implausible prior) issues an
:class:`InputWarning`; rows it declines (duplicates) are counted in the
returned object's ``skipped`` report, never dropped silently; rows out of
time order are sorted (and counted in ``reordered``). Writers produce files the readers (and outside programs)
accept.

The DSP that turns a SigMF recording into frames (``read_sigmf_frames``,
``estimate_sigmf``, ``calibrate_sigmf``) is :mod:`scattertrack.dsp`, one
layer up: this package knows formats only and imports nothing above it
(python/pyproject.toml, ``[tool.importlinter]``).
"""

from scattertrack.io.types import (
    Antenna,
    ChannelOffset,
    Features,
    FormatError,
    Imu,
    InputWarning,
    Reader,
    Reads,
    Reflector,
    Region,
    Scene,
    SkipReport,
    Track,
    Truth,
)
from scattertrack.io.reads import read_reads, write_reads
from scattertrack.io.frames import Frames, make_frames, read_frames, write_frames
from scattertrack.io.scene import read_scene, write_scene
from scattertrack.io.sigmf import Recording, read_sigmf, write_sigmf
from scattertrack.io.track import read_track, write_track
from scattertrack.io.imu import read_imu, write_imu
from scattertrack.io.features import read_features, write_features
from scattertrack.io.truth import read_truth, write_truth

__all__ = [
    "Antenna",
    "ChannelOffset",
    "Features",
    "FormatError",
    "Imu",
    "InputWarning",
    "Frames",
    "Reader",
    "Reads",
    "Recording",
    "Reflector",
    "Region",
    "Scene",
    "SkipReport",
    "Track",
    "Truth",
    "make_frames",
    "read_features",
    "read_frames",
    "read_imu",
    "read_reads",
    "read_scene",
    "read_sigmf",
    "read_track",
    "read_truth",
    "write_features",
    "write_frames",
    "write_imu",
    "write_reads",
    "write_scene",
    "write_sigmf",
    "write_track",
    "write_truth",
]
