"""Signal processing: recordings in, frames and features out.

Contract
--------
This layer sits between the formats and the simulators
(python/pyproject.toml, ``[tool.importlinter]``): it builds on
:mod:`scattertrack.io` (which reads and writes the recordings and the
frames, and knows formats only) and on the Rust DSP
(``scattertrack._core``); :mod:`scattertrack.sim` builds on it, never the
reverse. One module per concept:

:mod:`scattertrack.dsp.channel`
    The helper's bistatic wideband channel model (``tag_channel``,
    ``static_channel``, ``bistatic_path_lengths``, ``subcarrier_frequencies``):
    what a calibrated estimate is, and what the simulators draw.
:mod:`scattertrack.dsp.ofdm`
    ``estimate_sigmf(path, scene, calibration=None, **options) -> SigmfEstimate``,
    ``read_sigmf_frames(...) -> Frames`` (docs/formats.md section 5) and
    ``calibrate_sigmf(path, scene, tag_position=None) -> SigmfCalibration``:
    the one-shot OFDM channel estimation of a SigMF helper recording
    (docs/dsp.md). Windows declined are counted in ``Frames.skipped``,
    never dropped silently; a bad recording raises
    :class:`scattertrack.io.types.FormatError`.
:mod:`scattertrack.dsp.lora_sensing`
    ``sense_epochs(recording, fusion, options) -> Iterator[SensedEpoch]``:
    Marvel's pose sensing of a LoRa recording (docs/marvel.md sections
    5-8), epoch by epoch, with the fusion alongside reached through the
    ``Fusion`` protocol the runner passes in (this layer imports neither
    :mod:`scattertrack.fusion` nor :mod:`scattertrack.track`).
"""

from scattertrack.dsp.ofdm import (
    SKIP_NO_CLEAN,
    SKIP_NO_PREAMBLE,
    SKIP_NON_FINITE,
    SKIP_RX,
    SKIP_TOO_SHORT,
    SigmfCalibration,
    SigmfEstimate,
    calibrate_sigmf,
    estimate_sigmf,
    read_sigmf_frames,
)

__all__ = [
    "SKIP_NO_CLEAN",
    "SKIP_NO_PREAMBLE",
    "SKIP_NON_FINITE",
    "SKIP_RX",
    "SKIP_TOO_SHORT",
    "SigmfCalibration",
    "SigmfEstimate",
    "calibrate_sigmf",
    "estimate_sigmf",
    "read_sigmf_frames",
]
