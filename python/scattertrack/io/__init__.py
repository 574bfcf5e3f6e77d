"""Readers and writers of the public formats (FORMATS.md sections 1-4).

Contract: every reader validates and raises :class:`FormatError` naming the
file, the 1-based line and the column for a malformed file; rows it declines
(duplicates) are counted in the returned object's ``skipped`` report, never
dropped silently; rows out of time order are sorted (and counted in
``reordered``). Writers produce files the readers (and outside programs)
accept.
"""

from scattertrack.io.types import (
    Antenna,
    ChannelOffset,
    FormatError,
    Reader,
    Reads,
    Region,
    Scene,
    SkipReport,
    Track,
    Truth,
)
from scattertrack.io.reads import read_reads, write_reads
from scattertrack.io.frames import Frames, make_frames, read_frames, write_frames
from scattertrack.io.scene import read_scene, write_scene
from scattertrack.io.sigmf import (
    Recording,
    SigmfCalibration,
    SigmfEstimate,
    calibrate_sigmf,
    estimate_sigmf,
    read_sigmf,
    read_sigmf_frames,
    write_sigmf,
)
from scattertrack.io.track import read_track, write_track
from scattertrack.io.truth import read_truth, write_truth

__all__ = [
    "Antenna",
    "ChannelOffset",
    "FormatError",
    "Frames",
    "Reader",
    "Reads",
    "Recording",
    "Region",
    "Scene",
    "SigmfCalibration",
    "SigmfEstimate",
    "SkipReport",
    "Track",
    "Truth",
    "calibrate_sigmf",
    "estimate_sigmf",
    "make_frames",
    "read_frames",
    "read_reads",
    "read_scene",
    "read_sigmf",
    "read_sigmf_frames",
    "read_track",
    "read_truth",
    "write_frames",
    "write_reads",
    "write_scene",
    "write_sigmf",
    "write_track",
    "write_truth",
]
