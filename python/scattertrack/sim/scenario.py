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
:func:`simulate` validates again, fills every default and runs the reader;
:func:`write_simulation` writes ``scene.toml``, ``reads.csv``, ``truth.csv``
and ``simulation.json``.
"""

from __future__ import annotations

import copy
import json
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scattertrack.io.frames import Frames
from scattertrack.io.types import (
    Antenna,
    ChannelOffset,
    Features,
    FormatError,
    Imu,
    Reader,
    Reads,
    Region,
    Scene,
    Truth,
)
from scattertrack.sim import cots, drone, lora, marvel, trajectory, wideband
from scattertrack.sim import imu as imu_sim

SCENARIOS_DIR = Path(__file__).resolve().parents[3] / "scenarios"
"""The repository's named scenarios: python/scattertrack/sim/ -> ../../../scenarios."""

PIPELINES = ("glac", "turbotrack", "marvel")
"""What a scenario simulates: a COTS reader (reads.csv), a reader + SDR helper (frames.csv)
or a drone with LoRa-backscatter tags and an IMU (imu.csv, features.csv)."""

MODEL_TABLE = {"glac": "reader_model", "turbotrack": "helper_model"}
"""The table of impairments each pipeline's scenarios use."""

TOP_LEVEL_DEFAULTS = {
    "description": "",
    "duration_s": 20.0,  # s
    "seed": 0,
    "truth_rate_hz": 200.0,  # Hz, ground-truth sampling rate
}


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


class _Checker:
    """Validation helpers that raise FormatError(file, key) with a plain message."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, message: str):
        raise FormatError(self.source, None, key, message)

    def table(self, value, key: str) -> dict:
        if not isinstance(value, dict):
            self.fail(key, f"must be a table, got {value!r}")
        return value

    def keys(self, table: dict, allowed, key: str):
        for name in table:
            if name not in allowed:
                prefix = f"{key}." if key else ""
                self.fail(f"{prefix}{name}", f"unknown key (expected one of: {', '.join(sorted(allowed))})")

    def number(self, value, key: str, minimum=None, strict=False, maximum=None) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            self.fail(key, f"must be a finite number, got {value!r}")
        if minimum is not None and (value < minimum or (strict and value == minimum)):
            self.fail(key, f"must be {'>' if strict else '>='} {minimum}, got {value!r}")
        if maximum is not None and value > maximum:
            self.fail(key, f"must be <= {maximum}, got {value!r}")
        return float(value)

    def integer(self, value, key: str, minimum=None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(key, f"must be an integer, got {value!r}")
        if minimum is not None and value < minimum:
            self.fail(key, f"must be >= {minimum}, got {value!r}")
        return int(value)

    def boolean(self, value, key: str) -> bool:
        if not isinstance(value, bool):
            self.fail(key, f"must be true or false, got {value!r}")
        return value

    def choice(self, value, key: str, options) -> str:
        if value not in options:
            self.fail(key, f"must be one of {', '.join(map(repr, options))}, got {value!r}")
        return value

    def point(self, value, key: str) -> list[float]:
        if not isinstance(value, list) or len(value) != 3:
            self.fail(key, f"must be a point [x, y, z] in metres, got {value!r}")
        return [self.number(v, f"{key}[{i}]") for i, v in enumerate(value)]

    def string(self, value, key: str) -> str:
        if not isinstance(value, str):
            self.fail(key, f"must be a string, got {value!r}")
        return value


_SCENE_KEYS = ("name", "dimensions", "plane_z", "reader", "antennas", "region")
_READER_KEYS = ("phase_sign", "phase_period", "phase_noise_rad")
_ANTENNA_KEYS = ("id", "position", "phase_offset_rad")
_TAG_KEYS = ("epc", "trajectory", "phase_offset_rad")
_HELPER_SCENE_KEYS = ("name", "dimensions", "plane_z", "antennas", "region")
_HELPER_ANTENNA_KEYS = ("id", "position", "role")
_HELPER_TAG_KEYS = ("epc", "trajectory")


def resolve_scenario(scenario: dict) -> dict:
    """Validate a scenario dict and return a deep copy with every default filled in.

    Raises :class:`FormatError` (file from ``scenario["source"]``, key as a
    dotted path such as ``tags[1].trajectory.speed``) on the first problem.
    """
    source = str(scenario.get("source", f"<scenario {scenario.get('name', '?')}>"))
    check = _Checker(source)
    data = copy.deepcopy(scenario)
    pipeline = check.choice(data.setdefault("pipeline", "glac"), "pipeline", PIPELINES)
    if pipeline == "marvel":
        return _resolve_marvel(check, data)
    helper = pipeline == "turbotrack"
    for other, table in MODEL_TABLE.items():
        if other != pipeline and table in data:
            check.fail(table, f"is for {other} scenarios; this one has pipeline = {pipeline!r}")
    check.keys(data, ("name", "source", "pipeline", "scene", MODEL_TABLE[pipeline], "tags", *TOP_LEVEL_DEFAULTS), "")
    for key, default in TOP_LEVEL_DEFAULTS.items():
        data.setdefault(key, default)
    if "name" not in data:
        check.fail("name", "missing")
    check.string(data["name"], "name")
    check.string(data["description"], "description")
    data["duration_s"] = check.number(data["duration_s"], "duration_s", 0.0, strict=True)
    data["seed"] = check.integer(data["seed"], "seed", 0)
    data["truth_rate_hz"] = check.number(data["truth_rate_hz"], "truth_rate_hz", 100.0)

    # scene
    if "scene" not in data:
        check.fail("scene", "missing")
    scene = check.table(data["scene"], "scene")
    check.keys(scene, _HELPER_SCENE_KEYS if helper else _SCENE_KEYS, "scene")
    scene.setdefault("name", data["name"])
    check.string(scene["name"], "scene.name")
    if "dimensions" not in scene:
        check.fail("scene.dimensions", "missing")
    if scene["dimensions"] not in (2, 3) or isinstance(scene["dimensions"], bool):
        check.fail("scene.dimensions", f"must be 2 or 3, got {scene['dimensions']!r}")
    if scene["dimensions"] == 2:
        if "plane_z" not in scene:
            check.fail("scene.plane_z", "required when dimensions = 2")
        scene["plane_z"] = check.number(scene["plane_z"], "scene.plane_z")
    elif "plane_z" in scene:
        scene["plane_z"] = check.number(scene["plane_z"], "scene.plane_z")
    if not helper:
        reader = check.table(scene.setdefault("reader", {}), "scene.reader")
        check.keys(reader, _READER_KEYS, "scene.reader")
        reader.setdefault("phase_sign", 1)
        if reader["phase_sign"] not in (1, -1) or isinstance(reader["phase_sign"], bool):
            check.fail("scene.reader.phase_sign", f"must be 1 or -1, got {reader['phase_sign']!r}")
        check.choice(reader.setdefault("phase_period", "2pi"), "scene.reader.phase_period", ("2pi", "pi"))
        if "phase_noise_rad" in reader:
            reader["phase_noise_rad"] = check.number(reader["phase_noise_rad"], "scene.reader.phase_noise_rad", 0.0)
    antennas = scene.get("antennas")
    if not isinstance(antennas, list) or not antennas:
        check.fail("scene.antennas", "must be a non-empty array of tables [[scene.antennas]]")
    seen_ids = set()
    for index, antenna in enumerate(antennas):
        where = f"scene.antennas[{index}]"
        check.table(antenna, where)
        check.keys(antenna, _HELPER_ANTENNA_KEYS if helper else _ANTENNA_KEYS, where)
        for required in ("id", "position", "role") if helper else ("id", "position"):
            if required not in antenna:
                check.fail(f"{where}.{required}", "missing")
        antenna_id = check.integer(antenna["id"], f"{where}.id")
        if antenna_id in seen_ids:
            check.fail(f"{where}.id", f"duplicate antenna id {antenna_id}")
        seen_ids.add(antenna_id)
        antenna["position"] = check.point(antenna["position"], f"{where}.position")
        if "phase_offset_rad" in antenna:
            antenna["phase_offset_rad"] = check.number(antenna["phase_offset_rad"], f"{where}.phase_offset_rad")
        if helper:
            check.choice(antenna["role"], f"{where}.role", ("tx", "rx"))
    if helper:
        roles = [antenna["role"] for antenna in antennas]
        if roles.count("tx") != 1 or roles.count("rx") < 2:
            check.fail(
                "scene.antennas",
                "a helper needs exactly one antenna with role 'tx' and at least two with role 'rx', "
                f"found {roles.count('tx')} and {roles.count('rx')}",
            )
    if "region" in scene:
        _check_region(check, scene)

    if helper:
        data["helper_model"] = resolve_helper_model(
            check.table(data.get("helper_model", {}), "helper_model"), source, "helper_model."
        )
    else:
        data["reader_model"] = _resolve_reader_model(
            check, check.table(data.get("reader_model", {}), "reader_model"), seen_ids, reader["phase_period"]
        )
        if "phase_noise_rad" not in reader:
            model = data["reader_model"]
            reader["phase_noise_rad"] = float(np.hypot(model["white_noise_rad"], model["wander_rad"]))

    # tags
    tags = data.get("tags")
    if not isinstance(tags, list) or not tags:
        check.fail("tags", "must be a non-empty array of tables [[tags]]")
    seen_epcs = set()
    for index, tag in enumerate(tags):
        where = f"tags[{index}]"
        check.table(tag, where)
        check.keys(tag, _HELPER_TAG_KEYS if helper else _TAG_KEYS, where)
        for required in ("epc", "trajectory"):
            if required not in tag:
                check.fail(f"{where}.{required}", "missing")
        epc = check.string(tag["epc"], f"{where}.epc")
        if not re.fullmatch(r"[0-9A-Fa-f]+", epc):
            check.fail(f"{where}.epc", f"must be a hex string such as 'E2000A01', got {epc!r}")
        if epc.upper() in seen_epcs:
            check.fail(f"{where}.epc", f"duplicate epc {epc!r}")
        seen_epcs.add(epc.upper())
        if "phase_offset_rad" in tag:
            tag["phase_offset_rad"] = check.number(tag["phase_offset_rad"], f"{where}.phase_offset_rad")
        _check_trajectory(check, check.table(tag["trajectory"], f"{where}.trajectory"), f"{where}.trajectory", data)
    return data


_MARVEL_TOP_LEVEL = (
    "name",
    "source",
    "pipeline",
    "scene",
    "controller",
    "flight",
    "imu_model",
    "feature_model",
    "lora_model",
    *TOP_LEVEL_DEFAULTS,
)
_MARVEL_SCENE_KEYS = ("name", "region")
_CONTROLLER_KEYS = ("position", "array", "walls")
"""The keys of ``[controller]``, as :func:`scattertrack.sim.lora.resolve_controller` takes them."""
MARVEL_TRUTH_RATE_HZ = 100.0
"""Default truth rate of a marvel scenario, Hz: the IMU's rate, so truth and IMU share their times."""


def _resolve_marvel(check: _Checker, data: dict) -> dict:
    """Validate and complete a ``pipeline = "marvel"`` scenario (docs/marvel.md section 9)."""
    for other, table in MODEL_TABLE.items():
        if table in data:
            check.fail(table, f"is for {other} scenarios; this one has pipeline = 'marvel'")
    if "tags" in data:
        check.fail("tags", "a marvel scenario has one drone with four tags (docs/marvel.md section 2): use [flight]")
    check.keys(data, _MARVEL_TOP_LEVEL, "")
    if "name" not in data:
        check.fail("name", "missing")
    data.setdefault("truth_rate_hz", MARVEL_TRUTH_RATE_HZ)
    for key, default in TOP_LEVEL_DEFAULTS.items():
        data.setdefault(key, default)
    check.string(data["name"], "name")
    check.string(data["description"], "description")
    data["duration_s"] = check.number(data["duration_s"], "duration_s", 0.0, strict=True)
    data["seed"] = check.integer(data["seed"], "seed", 0)
    data["truth_rate_hz"] = check.number(data["truth_rate_hz"], "truth_rate_hz", 100.0)

    scene = check.table(data.setdefault("scene", {}), "scene")
    check.keys(scene, _MARVEL_SCENE_KEYS, "scene")
    scene.setdefault("name", data["name"])
    check.string(scene["name"], "scene.name")
    if "region" in scene:
        _check_region(check, scene)

    if "controller" not in data:
        check.fail("controller", "missing (the controller's [controller] position, hidden from the estimator)")
    controller = check.table(data["controller"], "controller")
    check.keys(controller, _CONTROLLER_KEYS, "controller")
    if "position" not in controller:
        check.fail("controller.position", "missing")
    controller["position"] = check.point(controller["position"], "controller.position")
    check.choice(controller.setdefault("array", "triangle"), "controller.array", marvel.ARRAYS)
    controller["walls"] = check.integer(controller.setdefault("walls", 0), "controller.walls", 0)

    if "flight" not in data:
        check.fail("flight", "missing (the drone's [flight] table)")
    try:
        data["flight"] = drone.check_flight(check.table(data["flight"], "flight"), data["duration_s"])
    except drone.ParameterError as error:
        check.fail("flight" if error.key is None else f"flight.{error.key}", error.message)
    for table, resolve in (("imu_model", imu_sim.resolve_imu_model), ("feature_model", marvel.resolve_feature_model)):
        try:
            data[table] = resolve(check.table(data.get(table, {}), table))
        except drone.ParameterError as error:
            check.fail(table if error.key is None else f"{table}.{error.key}", error.message)
    if "lora_model" in data:
        # The IQ-level model (sim/lora.py) is only used by ``simulate --iq``;
        # it is checked here so a typo surfaces at load time, and kept as written.
        table = check.table(data["lora_model"], "lora_model")
        try:
            lora.resolve_lora_model(table)
        except ValueError as error:
            message = str(error)
            named = next((key for key in sorted(table, key=len, reverse=True) if message.startswith(key)), None)
            if named is None and message.startswith("unknown LoRa model key"):
                named = next((key for key in table if key not in lora.LORA_MODEL_DEFAULTS), None)
            check.fail("lora_model" if named is None else f"lora_model.{named}", message)

    # Geometry over the session: the drone never reaches the controller, and
    # stays in front of a planar array (docs/marvel.md section 4), and inside the region.
    times = np.linspace(0.0, data["duration_s"], int(data["duration_s"] * 10) + 2)
    position = drone.flight(data["flight"], times).position
    delta = position - np.asarray(controller["position"])
    distance = np.linalg.norm(delta, axis=1)
    if distance.min() < 0.5:
        check.fail("controller.position", f"the drone passes within {distance.min():.2f} m of the controller")
    if controller["array"] == "triangle" and np.min(delta[:, 1]) <= 0.0:
        worst = float(times[np.argmin(delta[:, 1])])
        check.fail(
            "controller.position",
            f"the drone goes behind the controller's planar array (u_y <= 0 at t = {worst:.1f} s); "
            "the array faces +y (docs/marvel.md section 4)",
        )
    if "region" in scene:
        low, high = np.array(scene["region"]["min"]), np.array(scene["region"]["max"])
        if np.any(position < low) or np.any(position > high):
            check.fail("scene.region", "the flight leaves the region")
    return data


def _resolve_reader_model(check: _Checker, given: dict, antenna_ids: set, phase_period: str) -> dict:
    defaults = cots.READER_MODEL_DEFAULTS
    check.keys(given, defaults, "reader_model")
    model = {key: copy.deepcopy(given.get(key, default)) for key, default in defaults.items()}
    key = "reader_model."
    if model["antenna_order"] is not None:
        order = model["antenna_order"]
        if not isinstance(order, list) or not order:
            check.fail(key + "antenna_order", "must be a non-empty list of antenna ids")
        for i, antenna_id in enumerate(order):
            check.integer(antenna_id, f"{key}antenna_order[{i}]")
            if antenna_id not in antenna_ids:
                check.fail(f"{key}antenna_order[{i}]", f"antenna {antenna_id} is not in scene.antennas")
    model["rounds_per_antenna"] = check.integer(model["rounds_per_antenna"], key + "rounds_per_antenna", 1)
    for name in ("round_overhead_s", "round_jitter_cv", "dropout_burst_rate_hz"):
        model[name] = check.number(model[name], key + name, 0.0)
    for name in ("slot_s", "dropout_burst_mean_s", "frequency_hz", "hop_dwell_s"):
        model[name] = check.number(model[name], key + name, 0.0, strict=True)
    model["miss_probability"] = check.number(model["miss_probability"], key + "miss_probability", 0.0, maximum=0.99)
    model["outlier_probability"] = check.number(
        model["outlier_probability"], key + "outlier_probability", 0.0, maximum=1.0
    )
    check.choice(model["dropout_burst_scope"], key + "dropout_burst_scope", ("tag", "link"))
    windows = model["dropout_windows"]
    if not isinstance(windows, list):
        check.fail(key + "dropout_windows", "must be a list of [start_s, end_s] pairs")
    for i, window in enumerate(windows):
        where = f"{key}dropout_windows[{i}]"
        if not isinstance(window, list) or len(window) != 2:
            check.fail(where, f"must be a pair [start_s, end_s] in seconds, got {window!r}")
        start_s, end_s = (check.number(v, where, 0.0) for v in window)
        if end_s <= start_s:
            check.fail(where, f"must end after it starts, got {window!r}")
        windows[i] = [start_s, end_s]
    for name in ("hopping", "write_channel_offsets", "write_antenna_offsets", "report_rssi", "report_doppler", "report_channel_index", "log_frequency"):
        check.boolean(model[name], key + name)
    if model["channels_hz"] is not None:
        channels = model["channels_hz"]
        if not isinstance(channels, list) or not channels:
            check.fail(key + "channels_hz", "must be a non-empty list of frequencies in Hz")
        model["channels_hz"] = [
            check.number(f, f"{key}channels_hz[{i}]", 0.0, strict=True) for i, f in enumerate(channels)
        ]
    elif model["hopping"]:
        model["channels_hz"] = [float(f) for f in cots.US_CHANNELS_HZ]
    check.choice(model["antenna_phase_offsets"], key + "antenna_phase_offsets", ("random", "zero"))
    check.choice(model["channel_phase_offsets"], key + "channel_phase_offsets", ("random", "zero"))
    for name in (
        "antenna_offset_calibration_error_rad",
        "channel_offset_calibration_error_rad",
        "rssi_noise_db",
        "rssi_step_db",
        "doppler_noise_hz",
        "doppler_step_hz",
        "tag_gain_spread_db",
    ):
        model[name] = check.number(model[name], key + name, 0.0)
    if model["tag_phase_offset_rad"] != "random":
        model["tag_phase_offset_rad"] = check.number(model["tag_phase_offset_rad"], key + "tag_phase_offset_rad")
    check.choice(model["noise_profile"], key + "noise_profile", tuple(cots.NOISE_PROFILES))
    model = cots.resolve_noise(model)
    model["white_noise_rad"] = check.number(model["white_noise_rad"], key + "white_noise_rad", 0.0)
    model["wander_rad"] = check.number(model["wander_rad"], key + "wander_rad", 0.0)
    model["wander_time_s"] = check.number(model["wander_time_s"], key + "wander_time_s", 0.0, strict=True)
    check.choice(model["wander_scope"], key + "wander_scope", ("antenna", "link"))
    units = check.integer(model["phase_step_units"], key + "phase_step_units", 0)
    steps_per_period = 2048 if phase_period == "pi" else 4096
    if units and steps_per_period % units:
        check.fail(
            key + "phase_step_units",
            f"must divide {steps_per_period} (a whole number of steps per phase period), got {units}",
        )
    for name in ("tx_power_dbm", "antenna_gain_dbi", "tag_gain_dbi", "backscatter_loss_db"):
        model[name] = check.number(model[name], key + name)
    _check_reflectors(check, model["reflectors"], key)
    return model


def _check_region(check: _Checker, scene: dict) -> None:
    """Validates ``scene.region`` in place: ``min`` and ``max`` points (m), min below max."""
    region = check.table(scene["region"], "scene.region")
    check.keys(region, ("min", "max"), "scene.region")
    for key in ("min", "max"):
        if key not in region:
            check.fail(f"scene.region.{key}", "missing")
        region[key] = check.point(region[key], f"scene.region.{key}")
    if any(lo >= hi for lo, hi in zip(region["min"], region["max"])):
        check.fail("scene.region", "min must be below max on every axis")


def _check_reflectors(check: _Checker, reflectors, key: str) -> None:
    """Validate ``[[<model>.reflectors]]`` in place (``key`` is the model's prefix, e.g. ``reader_model.``)."""
    if not isinstance(reflectors, list):
        check.fail(key + "reflectors", f"must be an array of tables [[{key}reflectors]]")
    for i, reflector in enumerate(reflectors):
        where = f"{key}reflectors[{i}]"
        check.table(reflector, where)
        kind = check.choice(reflector.get("kind"), where + ".kind", tuple(cots.REFLECTOR_KEYS))
        check.keys(reflector, ("kind", *cots.REFLECTOR_KEYS[kind]), where)
        for name in cots.REFLECTOR_KEYS[kind]:
            if name not in reflector:
                check.fail(f"{where}.{name}", "missing")
        reflector["coefficient"] = check.number(reflector["coefficient"], where + ".coefficient")
        for name in ("point", "normal", "position"):
            if name in reflector:
                reflector[name] = check.point(reflector[name], f"{where}.{name}")
        if kind == "plane" and not any(reflector["normal"]):
            check.fail(where + ".normal", "must be a non-zero vector")


def resolve_helper_model(given: dict, source: str = "<helper_model>", key: str = "") -> dict:
    """A helper model with every default of :data:`wideband.HELPER_MODEL_DEFAULTS` filled in, validated.

    Raises :class:`FormatError` naming ``source`` and the key (prefixed by
    ``key``, e.g. ``"helper_model."``) for an unknown key or a bad value,
    including OFDM symbols too long for the tag's switching: the thesis's
    rule ``N < B / (2 BLF)`` (sec. 4.2).
    """
    check = _Checker(source)
    defaults = wideband.HELPER_MODEL_DEFAULTS
    check.table(given, key.rstrip(".") or "helper_model")
    check.keys(given, defaults, key.rstrip("."))
    model = {name: copy.deepcopy(given.get(name, default)) for name, default in defaults.items()}
    for name in ("centre_frequency_hz", "bandwidth_hz", "blf_hz", "slot_s", "dropout_burst_mean_s"):
        model[name] = check.number(model[name], key + name, 0.0, strict=True)
    for name in (
        "round_overhead_s",
        "round_jitter_cv",
        "dropout_burst_rate_hz",
        "calibration_phase_error_rad",
        "calibration_delay_error_s",
    ):
        model[name] = check.number(model[name], key + name, 0.0)
    for name in ("miss_probability", "rx_miss_probability"):
        model[name] = check.number(model[name], key + name, 0.0, maximum=0.99)
    model["outlier_probability"] = check.number(
        model["outlier_probability"], key + "outlier_probability", 0.0, maximum=1.0
    )
    for name in ("snr_db", "outlier_power_db"):
        model[name] = check.number(model[name], key + name)
    model["n_subcarriers"] = check.integer(model["n_subcarriers"], key + "n_subcarriers", 1)
    if model["centre_frequency_hz"] <= model["bandwidth_hz"] / 2.0:
        check.fail(key + "centre_frequency_hz", "must exceed half the bandwidth (every subcarrier above 0 Hz)")
    longest = model["bandwidth_hz"] / (2.0 * model["blf_hz"])
    if not model["n_subcarriers"] < longest:
        check.fail(
            key + "n_subcarriers",
            f"an OFDM symbol of {model['n_subcarriers']} samples at {model['bandwidth_hz']:g} samples/s is longer "
            f"than half the tag's switching period 1 / (2 BLF): need N < B / (2 BLF) = {longest:g}",
        )
    _check_reflectors(check, model["reflectors"], key)
    return model


def _check_trajectory(check: _Checker, params: dict, where: str, data: dict):
    kind = check.choice(params.get("kind"), where + ".kind", trajectory.KINDS)
    allowed = (*trajectory.COMMON_KEYS, *trajectory.REQUIRED_KEYS[kind], *trajectory.OPTIONAL_KEYS[kind])
    check.keys(params, allowed, where)
    for name in trajectory.REQUIRED_KEYS[kind]:
        if name not in params:
            check.fail(f"{where}.{name}", "missing")
    # Evaluate on a coarse grid over the whole session: catches malformed
    # parameters and, in 2D scenes, motion that leaves the plane.
    times = np.linspace(0.0, data["duration_s"], int(data["duration_s"] * 20) + 2)
    try:
        positions, velocities = trajectory.positions_velocities(params, times)
    except (ValueError, TypeError, KeyError) as error:
        check.fail(where, str(error))
    if not (np.all(np.isfinite(positions)) and np.all(np.isfinite(velocities))):
        check.fail(where, "gives non-finite positions or velocities")
    scene = data["scene"]
    if scene["dimensions"] == 2 and np.max(np.abs(positions[:, 2] - scene["plane_z"])) > 1e-9:
        check.fail(where, f"leaves the plane z = {scene['plane_z']} of this 2D scene")
    antennas = np.array([a["position"] for a in scene["antennas"]])
    closest = np.min(np.linalg.norm(positions[:, None, :] - antennas[None], axis=2))
    if closest < 0.01:
        check.fail(where, f"passes within {closest:.4f} m of an antenna (the phase model needs d > 0)")


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
    for tag in tags:
        trajectory_seed = int(rngs["trajectories"].integers(2**31))
        if tag["trajectory"]["kind"] == "random":
            tag["trajectory"].setdefault("seed", trajectory_seed)
    epcs = [tag["epc"] for tag in tags]
    trajectories = [tag["trajectory"] for tag in tags]

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
    for tag in tags:
        trajectory_seed = int(rngs["trajectories"].integers(2**31))
        if tag["trajectory"]["kind"] == "random":
            tag["trajectory"].setdefault("seed", trajectory_seed)
    epcs = [tag["epc"] for tag in tags]
    trajectories = [tag["trajectory"] for tag in tags]
    frames, details = wideband.frames_from_trajectories(scene, epcs, trajectories, data["duration_s"], model, rngs)
    truth = _truth(epcs, trajectories, data["duration_s"], data["truth_rate_hz"])
    return Simulation(scene=scene, reads=None, truth=truth, scenario=data, seed=seed, details=details, frames=frames)


def _truth(epcs: list[str], trajectories: list[dict], duration_s: float, rate_hz: float) -> Truth:
    """Positions and velocities of every tag on a regular grid over [0, duration_s], time-major."""
    return wideband.truth_grid(epcs, trajectories, duration_s, rate_hz)


# --------------------------------------------------------------------------
# output


def write_simulation(sim: Simulation, out_dir) -> Path:
    """Write ``scene.toml``, ``reads.csv`` (``frames.csv`` for a turbotrack
    scenario; ``imu.csv`` and ``features.csv`` for a marvel one),
    ``truth.csv`` and ``simulation.json`` into ``out_dir``.

    ``simulation.json`` records the seed, the resolved scenario, the package
    version and the hidden truth (true offsets, hop table, counts), so a run
    can be reproduced and audited. Returns the folder.
    """
    from scattertrack import __version__
    from scattertrack.io import write_features, write_frames, write_imu, write_reads, write_scene, write_truth

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
    record = {
        "generator": "scattertrack.sim",
        "version": __version__,
        "seed": sim.seed,
        "scenario": sim.scenario,
        "details": _json_ready(sim.details),
    }
    (out / "simulation.json").write_text(json.dumps(record, indent=2) + "\n")
    return out


def _json_ready(value):
    """Dict keys to strings and numpy scalars to Python numbers, recursively."""
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value
