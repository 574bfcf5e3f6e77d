"""A simulation's outcome (:class:`Simulation`) and its files (:func:`write_simulation`).

Every pipeline's simulator returns a :class:`Simulation`: what a real session
would give (scene, reads or frames or IMU and features, truth) plus the
record (the resolved scenario, the seed, the hidden truth).
:func:`write_simulation` writes it in the public formats (docs/formats.md)
with ``simulation.json``, so a run can be reproduced and audited.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scattertrack.io.features import write_features
from scattertrack.io.frames import Frames, write_frames
from scattertrack.io.imu import write_imu
from scattertrack.io.reads import write_reads
from scattertrack.io.scene import write_scene
from scattertrack.io.truth import write_truth
from scattertrack.io.types import Features, Imu, Reads, Scene, Truth


@dataclass
class Simulation:
    """The outcome of :func:`simulate`: what a real session would give, plus the record."""

    scene: Scene
    """The scene as a user would have calibrated it (written offsets include calibration error)."""
    reads: Reads | None
    """Reads sorted by time, all tags interleaved (None for a turbotrack scenario)."""
    truth: Truth
    """True positions and velocities of every tag at ``truth_rate_hz``."""
    scenario: dict
    """The fully resolved scenario (every default filled in; ``seed`` is the seed used)."""
    seed: int
    details: dict = field(default_factory=dict)
    """Hidden truth (true offsets, hop table) and counts (attempts, misses, outliers)."""
    frames: Frames | None = None
    """Wideband channel frames of a turbotrack scenario (None for glac)."""
    imu: Imu | None = None
    """IMU samples of a marvel scenario (None otherwise)."""
    features: Features | None = None
    """Backscatter pose features of a marvel scenario (None otherwise)."""

    @property
    def pipeline(self) -> str:
        """``"glac"``, ``"turbotrack"`` or ``"marvel"``: which scenario kind produced this."""
        return self.scenario.get("pipeline", "glac")


def write_simulation(sim: Simulation, out_dir) -> Path:
    """Write ``scene.toml``, ``reads.csv`` (``frames.csv`` for a turbotrack
    scenario; ``imu.csv`` and ``features.csv`` for a marvel one),
    ``truth.csv`` and ``simulation.json`` into ``out_dir``.

    ``simulation.json`` records the seed, the resolved scenario, the package
    version and the hidden truth (true offsets, hop table, counts), so a run
    can be reproduced and audited. Returns the folder.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_scene(out / "scene.toml", sim.scene)
    if sim.frames is not None:
        write_frames(out / "frames.csv", sim.frames)
    elif sim.imu is not None:
        # A marvel scenario; at IQ level (simulate --iq) it has no features:
        # the recording beside these files is what the pose sensing reads.
        write_imu(out / "imu.csv", sim.imu)
        if sim.features is not None:
            write_features(out / "features.csv", sim.features)
    else:
        write_reads(out / "reads.csv", sim.reads)
    write_truth(out / "truth.csv", sim.truth)
    write_record(out, "scattertrack.sim", sim.seed, scenario=sim.scenario, details=_json_ready(sim.details))
    return out


def write_record(out: Path, generator: str, seed: int, **fields) -> None:
    """``simulation.json`` in ``out``: the generator, the package version, the seed, then ``fields``."""
    from scattertrack import __version__

    record = {"generator": generator, "version": __version__, "seed": seed, **fields}
    (out / "simulation.json").write_text(json.dumps(record, indent=2) + "\n")


def _json_ready(value):
    """Dict keys to strings and numpy scalars to Python numbers, recursively."""
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value
