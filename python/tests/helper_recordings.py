"""Helper recordings shared by the SigMF tests (tests/io: the format; tests/dsp: the channel estimation).

A four-receiver helper around one static tag, simulated at IQ level
(:mod:`scattertrack.sim.iq`) and written as SigMF with its calibration.
"""

import numpy as np

from scattertrack.io.types import Antenna, Reader, Region, Scene
from scattertrack.sim import iq

C = 299_792_458.0
TX = np.array([0.4, 0.4, 0.0])
RX = np.array([[0.0, 0.4, 0.0], [0.8, 0.4, 0.0], [0.4, 0.0, 0.0], [0.4, 0.8, 0.0]])
TAG_POSITION = [0.55, 0.30, 0.60]


def helper_scene() -> Scene:
    antennas = [Antenna(0, TX.copy(), role="tx")] + [Antenna(i + 1, p.copy(), role="rx") for i, p in enumerate(RX)]
    region = Region(np.array([-1.0, -1.0, 0.05]), np.array([2.0, 2.0, 2.0]))
    return Scene("helper", 3, Reader(kind="sdr-helper"), antennas, region=region)


def simulate(tmp_path, name="run", seed=1, duration_s=0.012, **model):
    sim = iq.simulate_iq(helper_scene(), {"E1": {"kind": "static", "position": TAG_POSITION}}, model=model,
                         seed=seed, duration_s=duration_s)
    out = iq.write_iq_simulation(sim, tmp_path / name)
    return sim, out


def written_recording(tmp_path_factory):
    """A written simulation: 4 replies at 0 dB per sample, a calibration at the region's centre."""
    return simulate(tmp_path_factory.mktemp("sigmf"), duration_s=0.014)
