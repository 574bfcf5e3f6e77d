"""Scenarios: a TOML file describing one simulated reader session.

A scenario holds the scene (antennas, reader conventions, region), the reader
model (schedule and impairments, :data:`scattertrack.sim.cots.READER_MODEL_DEFAULTS`)
and the tags with their trajectories (:mod:`scattertrack.sim.trajectory`).
Its ``pipeline`` says which hardware it simulates: ``"glac"`` (the default: a
COTS reader, ``[reader_model]``, output ``reads.csv``), ``"turbotrack"``
(a reader plus SDR localization helper, ``[helper_model]`` with the keys of
:data:`scattertrack.sim.wideband.HELPER_MODEL_DEFAULTS`, antennas with
``role = "tx"``/``"rx"``, output ``frames.csv``) or ``"marvel"`` (a drone
with LoRa-backscatter tags and an IMU, :mod:`scattertrack.sim.marvel`:
``[controller]``, ``[flight]``, ``[imu_model]``, ``[feature_model]``,
output ``imu.csv`` and ``features.csv``; docs/marvel.md section 9; at IQ
level, :func:`scattertrack.sim.marvel.simulate_marvel_iq`, the optional
``[lora_model]`` with the keys of :data:`scattertrack.sim.lora.LORA_MODEL_DEFAULTS`,
output a LoRa SigMF recording instead of ``features.csv``).
The schema, with every key, unit and default, is in ``docs/simulator.md``;
named scenarios live in ``<repo>/scenarios/NAME.toml``.

Flow: :func:`load_scenario` reads and validates a file and returns the plain
dict as written (plus ``source``, the file it came from), so callers can
override keys (``load_scenario(name) | {"duration_s": 2}``);
:func:`simulate` validates again, fills every default
(:func:`scattertrack.sim.scenario_resolve.resolve_scenario`, checks in
:mod:`scattertrack.sim.scenario_checks`) and runs the reader, returning a
:class:`scattertrack.sim.simulation.Simulation`;
:func:`scattertrack.sim.simulation.write_simulation` writes ``scene.toml``,
``reads.csv``, ``truth.csv`` and ``simulation.json``.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numpy as np

from scattertrack.io.types import Antenna, ChannelOffset, FormatError, Reader, Reflector, Region, Scene, Truth
from scattertrack.sim import cots, marvel, wideband
from scattertrack.sim.scenario_resolve import PIPELINES, resolve_scenario  # noqa: F401 - exported by scattertrack.sim
from scattertrack.sim.simulation import Simulation, write_simulation  # noqa: F401 - exported by scattertrack.sim

SCENARIOS_DIR = Path(__file__).resolve().parents[3] / "scenarios"
"""The repository's named scenarios: python/scattertrack/sim/ -> ../../../scenarios."""


# --------------------------------------------------------------------------
# loading


def list_scenarios(pipeline: str = "glac") -> list[str]:
    """Names of the scenarios shipped in ``<repo>/scenarios`` for one pipeline (sorted).

    ``pipeline`` is ``"glac"`` (the default: the COTS reader scenarios, what
    callers written before the turbotrack pipeline expect), ``"turbotrack"``,
    ``"marvel"``, or ``"all"``.
    """
    names = sorted(path.stem for path in SCENARIOS_DIR.glob("*.toml"))
    if pipeline == "all":
        return names
    if pipeline not in PIPELINES:
        raise ValueError(f"unknown pipeline {pipeline!r}; expected one of {', '.join(PIPELINES)} or 'all'")
    return [name for name in names if scenario_pipeline(name) == pipeline]


def scenario_pipeline(name_or_path) -> str:
    """The ``pipeline`` a scenario file declares (``"glac"`` when absent), without validating the rest.

    A file that is not valid TOML reads as ``"glac"`` here; :func:`load_scenario` reports it.
    """
    try:
        with open(scenario_path(name_or_path), "rb") as handle:
            pipeline = tomllib.load(handle).get("pipeline", "glac")
    except tomllib.TOMLDecodeError:
        return "glac"
    return pipeline if isinstance(pipeline, str) else "glac"


def scenario_path(name_or_path) -> Path:
    """The file of a scenario given by name (``scenarios/NAME.toml``) or by path."""
    text = str(name_or_path)
    if isinstance(name_or_path, Path) or text.endswith(".toml") or "/" in text or "\\" in text:
        path = Path(name_or_path)
    else:
        path = SCENARIOS_DIR / f"{text}.toml"
    if not path.is_file():
        known = ", ".join(list_scenarios("all")) or "none"
        raise FormatError(path, None, None, f"no such scenario file (named scenarios: {known})")
    return path


def load_scenario(name_or_path) -> dict:
    """Read and validate a scenario; returns the dict as written plus ``source`` (its path).

    ``name_or_path`` is a scenario name (``<repo>/scenarios/NAME.toml``) or a
    path to a TOML file. Raises :class:`FormatError` naming the file and the
    key for an invalid scenario.
    """
    path = scenario_path(name_or_path)
    try:
        with open(path, "rb") as handle:
            data = tomllib.load(handle)
    except tomllib.TOMLDecodeError as error:
        match = re.search(r"line (\d+)", str(error))
        raise FormatError(path, int(match.group(1)) if match else None, None, f"not valid TOML: {error}") from None
    data.setdefault("name", path.stem)
    data["source"] = str(path)
    resolve_scenario(data)  # validate now so errors surface at load time
    return data


# --------------------------------------------------------------------------
# validation


# --------------------------------------------------------------------------
# simulation


def simulate(scenario: dict, seed: int | None = None) -> Simulation:
    """Run a scenario: the reads of a COTS reader, the ground truth and the calibrated scene.

    ``seed`` (non-negative integer) overrides the scenario's ``seed``; every
    random draw comes from ``numpy.random.default_rng(seed)`` (split into one
    independent stream per impairment), so the same scenario and seed give
    identical output.
    """
    if seed is not None:
        scenario = {**scenario, "seed": seed}
    data = resolve_scenario(scenario)
    seed = data["seed"]
    if data["pipeline"] == "turbotrack":
        return _simulate_helper(data)
    if data["pipeline"] == "marvel":
        return marvel.simulate_marvel(data)
    root = np.random.default_rng(seed)
    names = (*cots.STREAMS, "trajectories")
    rngs = dict(zip(names, root.spawn(len(names))))

    scene_spec, model = data["scene"], data["reader_model"]
    reader_spec = scene_spec["reader"]
    period = np.pi if reader_spec["phase_period"] == "pi" else 2.0 * np.pi
    two_pi = 2.0 * np.pi

    # Antenna offsets: true values (drawn for every antenna, so that fixing
    # one leaves the others' draws alone) and the calibrated values a user
    # would write, with calibration error.
    offsets_rng = rngs["offsets"]
    antennas = scene_spec["antennas"]
    antenna_ids = np.array([a["id"] for a in antennas], dtype=np.int64)
    antenna_positions = np.array([a["position"] for a in antennas], dtype=float)
    drawn = offsets_rng.uniform(0.0, two_pi, size=len(antennas))
    if model["antenna_phase_offsets"] == "zero":
        drawn[:] = 0.0
    antenna_true = np.array([a.get("phase_offset_rad", d) for a, d in zip(antennas, drawn)], dtype=float)
    antenna_written = np.mod(
        antenna_true + model["antenna_offset_calibration_error_rad"] * offsets_rng.standard_normal(len(antennas)),
        two_pi,
    )

    # Channels: the hop table and each channel's offset. With one fixed
    # channel its offset is indistinguishable from the antenna offsets, so it
    # is 0 and nothing is written.
    channels, hop_clock = cots.hop_table(model, rngs["hopping"])
    n_channels = len(channels)
    drawn = offsets_rng.uniform(0.0, two_pi, size=n_channels)
    channel_true = drawn if (model["hopping"] and model["channel_phase_offsets"] == "random") else np.zeros(n_channels)
    channel_written = np.mod(
        channel_true + model["channel_offset_calibration_error_rad"] * offsets_rng.standard_normal(n_channels),
        two_pi,
    )

    # Tags: offsets and trajectories (random ones get a seed from the scenario seed).
    tags = data["tags"]
    drawn = offsets_rng.uniform(0.0, two_pi, size=len(tags))
    default_tag_offset = model["tag_phase_offset_rad"]
    tag_true = np.array(
        [
            tag.get("phase_offset_rad", d if default_tag_offset == "random" else default_tag_offset)
            for tag, d in zip(tags, drawn)
        ],
        dtype=float,
    )
    epcs, trajectories = _tag_trajectories(tags, rngs["trajectories"])

    reads, counts = cots.generate_reads(
        duration_s=data["duration_s"],
        antenna_ids=antenna_ids,
        antenna_positions=antenna_positions,
        antenna_offsets_rad=antenna_true,
        epcs=epcs,
        trajectories=trajectories,
        tag_offsets_rad=tag_true,
        channels_hz=channels,
        channel_offsets_rad=channel_true,
        hop_clock_offset_s=hop_clock,
        phase_sign=int(reader_spec["phase_sign"]),
        period_rad=period,
        model=model,
        rngs=rngs,
    )

    truth = _truth(epcs, trajectories, data["duration_s"], data["truth_rate_hz"])

    region = scene_spec.get("region")
    written_channels = []
    if model["hopping"] and model["write_channel_offsets"]:
        order = np.argsort(channels)
        written_channels = [ChannelOffset(float(channels[i]), float(channel_written[i])) for i in order]
    scene = Scene(
        name=scene_spec["name"],
        dimensions=int(scene_spec["dimensions"]),
        reader=Reader(
            kind="cots",
            phase_sign=int(reader_spec["phase_sign"]),
            phase_period=reader_spec["phase_period"],
            phase_noise_rad=float(reader_spec["phase_noise_rad"]),
        ),
        antennas=[
            Antenna(id=int(i), position=p.copy(), phase_offset_rad=float(o))
            for i, p, o in zip(antenna_ids, antenna_positions, antenna_written if model["write_antenna_offsets"] else np.zeros(len(antenna_ids)))
        ],
        plane_z=scene_spec.get("plane_z") if scene_spec["dimensions"] == 2 else None,
        region=Region(np.array(region["min"], float), np.array(region["max"], float)) if region else None,
        channel_offsets=written_channels,
        # What the user declares ([[scene.reflectors]]), never the simulated [[reader_model.reflectors]].
        reflectors=[Reflector.from_dict(table) for table in scene_spec.get("reflectors", [])],
    )
    details = {
        "true_antenna_phase_offsets_rad": {int(i): float(o) for i, o in zip(antenna_ids, antenna_true)},
        "true_tag_phase_offsets_rad": {epc: float(o) for epc, o in zip(epcs, tag_true)},
        "hop_table_hz": [float(f) for f in channels],
        "true_channel_phase_offsets_rad": {float(f): float(o) for f, o in zip(channels, channel_true)},
        "hop_clock_offset_s": float(hop_clock),
        "counts": counts,
    }
    return Simulation(scene=scene, reads=reads, truth=truth, scenario=data, seed=seed, details=details)


def _simulate_helper(data: dict) -> Simulation:
    """Run a resolved turbotrack scenario: frames, truth and the helper's scene."""
    seed = data["seed"]
    rngs = wideband.helper_streams(seed)
    scene_spec, model = data["scene"], data["helper_model"]
    region = scene_spec.get("region")
    scene = Scene(
        name=scene_spec["name"],
        dimensions=int(scene_spec["dimensions"]),
        reader=Reader(kind="sdr-helper", phase_sign=1, phase_period="2pi"),
        antennas=[
            Antenna(id=int(a["id"]), position=np.array(a["position"], dtype=float), role=a["role"])
            for a in scene_spec["antennas"]
        ],
        plane_z=scene_spec.get("plane_z") if scene_spec["dimensions"] == 2 else None,
        region=Region(np.array(region["min"], float), np.array(region["max"], float)) if region else None,
        # What the user's hardware is set to; trackers read the OFDM grid from here.
        extra={"helper": {key: model[key] for key in wideband.OFDM_KEYS}},
    )
    tags = data["tags"]
    epcs, trajectories = _tag_trajectories(tags, rngs["trajectories"])
    frames, details = wideband.frames_from_trajectories(scene, epcs, trajectories, data["duration_s"], model, rngs)
    truth = _truth(epcs, trajectories, data["duration_s"], data["truth_rate_hz"])
    return Simulation(scene=scene, reads=None, truth=truth, scenario=data, seed=seed, details=details, frames=frames)


def _tag_trajectories(tags: list[dict], rng) -> tuple[list[str], list[dict]]:
    """The tags' epcs and trajectories; a random trajectory without its own
    seed gets one from ``rng``. One draw per tag, random or not, so that a
    tag's seed does not depend on the kinds of the tags before it."""
    for tag in tags:
        trajectory_seed = int(rng.integers(2**31))
        if tag["trajectory"]["kind"] == "random":
            tag["trajectory"].setdefault("seed", trajectory_seed)
    return [tag["epc"] for tag in tags], [tag["trajectory"] for tag in tags]


def _truth(epcs: list[str], trajectories: list[dict], duration_s: float, rate_hz: float) -> Truth:
    """Positions and velocities of every tag on a regular grid over [0, duration_s], time-major."""
    return wideband.truth_grid(epcs, trajectories, duration_s, rate_hz)


# --------------------------------------------------------------------------
# output
