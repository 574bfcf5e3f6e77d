"""Simulators. This package: the commercial (COTS, LLRP) RFID reader.

Contract
--------
``load_scenario(name_or_path) -> dict``
    A scenario by name (``<repo>/scenarios/NAME.toml``) or by path, validated;
    returned as written (plus ``source``: the file) so keys can be overridden,
    e.g. ``load_scenario("glac-2d-10cms") | {"duration_s": 2}``. Invalid files
    raise :class:`scattertrack.io.types.FormatError` naming the file and the
    key (``tags[0].trajectory.speed``).
``simulate(scenario, seed=None) -> Simulation``
    Runs the scenario. ``Simulation`` has ``scene`` (as a user would have
    calibrated it: written offsets include any calibration error), ``reads``
    (all tags interleaved, sorted by time), ``truth`` (every tag at
    ``truth_rate_hz``, default 200 Hz, with exact velocities), ``scenario``
    (resolved: every default filled in, ``seed`` = the seed used), ``seed`` and
    ``details`` (hidden truth: true offsets, hop table; counts). Every random
    draw comes from ``numpy.random.default_rng(seed)``: the same scenario and
    seed give identical output on the same numpy.
``write_simulation(sim, out_dir)``
    Writes ``scene.toml``, ``reads.csv``, ``truth.csv`` (docs/formats.md 1-3) and
    ``simulation.json`` (seed, resolved scenario, package version, details).
``list_scenarios(pipeline="glac") -> list[str]``
    The named scenarios shipped in ``<repo>/scenarios`` for one pipeline
    (``"glac"``, ``"turbotrack"``, ``"marvel"``, or ``"all"``).

Scenarios with ``pipeline = "turbotrack"`` simulate a reader plus SDR
localization helper instead (:mod:`scattertrack.sim.wideband`): their
``Simulation`` has ``frames`` (docs/formats.md section 5) and ``reads = None``,
and ``write_simulation`` writes ``frames.csv`` instead of ``reads.csv``.
``list_scenarios("turbotrack")`` lists them. The helper's channel physics
(``tag_channel``, ``static_channel``, ``bistatic_path_lengths``,
``subcarrier_frequencies``) and the frame-level simulator
(``simulate_frames(scene, tags, model, seed) -> (Frames, Truth)``) are
exported here too.

Scenarios with ``pipeline = "marvel"`` simulate a drone with four
LoRa-backscatter tags and an IMU at the feature level
(:mod:`scattertrack.sim.marvel`, docs/marvel.md section 9): their
``Simulation`` has ``imu`` and ``features`` (docs/formats.md sections 6-7),
``truth`` with orientation and ``reads = None``; ``write_simulation`` writes
``imu.csv`` and ``features.csv``. The drone's flights
(``flight(params, t) -> FlightTruth``, ``tag_positions``, ``DEFAULT_TAGS``),
the IMU (``simulate_imu``, ``IMU_MODEL_DEFAULTS``) and the feature model
(``simulate_marvel``, ``FEATURE_MODEL_DEFAULTS``) and the same flight at IQ
level (``simulate_marvel_iq``: a LoRa recording instead of features) are exported here;
quaternion helpers are in :mod:`scattertrack.sim.rotation`.

The reads follow docs/formats.md's monostatic phase model
``phase = (phase_sign 4 pi f d / c + antenna offset + channel offset(f)
+ tag offset + noise) mod P`` with the impairments of
:mod:`scattertrack.sim.cots`; trajectories are in
:mod:`scattertrack.sim.trajectory`. Units are SI (m, s, Hz, rad, dBm). The
user guide, with the scenario schema and every default, is
``docs/simulator.md``.
"""

from scattertrack.sim.scenario import SCENARIOS_DIR, list_scenarios, load_scenario, simulate
from scattertrack.sim.scenario_resolve import PIPELINES, resolve_scenario
from scattertrack.sim.simulation import Simulation, write_simulation
from scattertrack.sim.trajectory import positions_velocities
from scattertrack.sim.scenario import scenario_pipeline
from scattertrack.sim.iq import IQ_MODEL_DEFAULTS, IqSimulation, simulate_iq, simulate_iq_scenario, write_iq_simulation
from scattertrack.sim.drone import DEFAULT_TAGS, FlightError, FlightTruth, TagLayout, flight, tag_positions
from scattertrack.sim.imu import IMU_MODEL_DEFAULTS, simulate_imu
from scattertrack.sim.marvel import FEATURE_MODEL_DEFAULTS, simulate_marvel, simulate_marvel_iq
from scattertrack.sim.wideband import (
    HELPER_MODEL_DEFAULTS,
    bistatic_path_lengths,
    resolve_helper_model,
    helper_geometry,
    simulate_frames,
    static_channel,
    subcarrier_frequencies,
    tag_channel,
)

__all__ = [
    "DEFAULT_TAGS",
    "FEATURE_MODEL_DEFAULTS",
    "FlightError",
    "FlightTruth",
    "IMU_MODEL_DEFAULTS",
    "TagLayout",
    "flight",
    "simulate_imu",
    "simulate_marvel",
    "simulate_marvel_iq",
    "tag_positions",
    "HELPER_MODEL_DEFAULTS",
    "IQ_MODEL_DEFAULTS",
    "IqSimulation",
    "simulate_iq",
    "simulate_iq_scenario",
    "write_iq_simulation",
    "PIPELINES",
    "bistatic_path_lengths",
    "helper_geometry",
    "resolve_helper_model",
    "scenario_pipeline",
    "simulate_frames",
    "static_channel",
    "subcarrier_frequencies",
    "tag_channel",
    "SCENARIOS_DIR",
    "Simulation",
    "list_scenarios",
    "load_scenario",
    "positions_velocities",
    "resolve_scenario",
    "simulate",
    "write_simulation",
]
