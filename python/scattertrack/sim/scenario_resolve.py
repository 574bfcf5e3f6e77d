"""Scenario resolution: a scenario dict as written in, validated and with every default filled in out.

:func:`resolve_scenario` dispatches on ``pipeline`` and runs named steps
(top level, scene, antennas, region, the pipeline's model, tags; a marvel
scenario: top level, scene, controller, flight, the IMU, feature and LoRa
models, then the session's geometry), each checking its tables with
:mod:`scattertrack.sim.scenario_checks`. The schema, with every key, unit and
default, is ``docs/simulator.md``.
"""

from __future__ import annotations

import copy
import re

import numpy as np

from scattertrack.sim import cots, drone, lora, marvel_model, wideband
from scattertrack.sim import imu as imu_sim
from scattertrack.sim.scenario_checks import Checker, check_reflectors, check_region, check_trajectory

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

_SCENE_KEYS = ("name", "dimensions", "plane_z", "reader", "antennas", "region", "reflectors")
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
    The steps run in the order below, so the first problem in file order is
    the one named.
    """
    source = str(scenario.get("source", f"<scenario {scenario.get('name', '?')}>"))
    check = Checker(source)
    data = copy.deepcopy(scenario)
    pipeline = check.choice(data.setdefault("pipeline", "glac"), "pipeline", PIPELINES)
    if pipeline == "marvel":
        return _resolve_marvel(check, data)
    helper = pipeline == "turbotrack"
    _resolve_top_level(check, data, pipeline)
    scene = _resolve_scene(check, data, helper)
    seen_ids = _resolve_antennas(check, scene, helper)
    if "region" in scene:
        check_region(check, scene)
    if helper:
        data["helper_model"] = wideband.resolve_helper_model(
            check.table(data.get("helper_model", {}), "helper_model"), source, "helper_model."
        )
    else:
        reader = scene["reader"]
        data["reader_model"] = _resolve_reader_model(
            check, check.table(data.get("reader_model", {}), "reader_model"), seen_ids, reader["phase_period"]
        )
        if "phase_noise_rad" not in reader:
            model = data["reader_model"]
            reader["phase_noise_rad"] = float(np.hypot(model["white_noise_rad"], model["wander_rad"]))
    _resolve_tags(check, data, helper)
    return data


def _resolve_top_level(check: Checker, data: dict, pipeline: str) -> None:
    """The top-level keys of a glac or turbotrack scenario, in place: no other pipeline's model, the defaults."""
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


def _resolve_scene(check: Checker, data: dict, helper: bool) -> dict:
    """``[scene]`` in place: its keys, dimensions and plane, and a COTS reader's conventions. Returns the table."""
    if "scene" not in data:
        check.fail("scene", "missing")
    scene = check.table(data["scene"], "scene")
    if helper and "reflectors" in scene:
        _no_declared_reflectors(check, "turbotrack")
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
        if "reflectors" in scene:
            _resolve_declared_reflectors(check, scene["reflectors"])
    return scene


def _resolve_declared_reflectors(check: Checker, reflectors) -> None:
    """``[[scene.reflectors]]`` in place: the reflectors the user declares, copied to scene.toml as
    ``[[reflectors]]`` (docs/formats.md section 1). They tell the tracker; they do not change the
    simulated reads, which only ``[[reader_model.reflectors]]`` bend."""
    check_reflectors(check, reflectors, "scene.")
    for i, reflector in enumerate(reflectors):
        check.number(reflector["coefficient"], f"scene.reflectors[{i}].coefficient", -1.0, maximum=1.0)


def _no_declared_reflectors(check: Checker, pipeline: str) -> None:
    """A scene of a pipeline other than glac declares reflectors: only cots scenes take them."""
    check.fail(
        "scene.reflectors",
        f"only COTS-reader (glac) scenes declare reflectors for now; this is a {pipeline} scenario"
        + (" (its multipath is [[helper_model.reflectors]])" if pipeline == "turbotrack" else ""),
    )


def _resolve_antennas(check: Checker, scene: dict, helper: bool) -> set:
    """``[[scene.antennas]]`` in place (a helper: one ``tx``, two or more ``rx``). Returns the antenna ids."""
    antennas = check.array(scene.get("antennas"), "scene.antennas")
    seen_ids = set()
    for index, antenna in enumerate(antennas):
        where = f"scene.antennas[{index}]"
        required = ("id", "position", "role") if helper else ("id", "position")
        check.entry(antenna, where, _HELPER_ANTENNA_KEYS if helper else _ANTENNA_KEYS, required)
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
    return seen_ids


def _resolve_tags(check: Checker, data: dict, helper: bool) -> None:
    """``[[tags]]`` in place: unique hex EPCs, offsets, and trajectories valid over the session."""
    tags = check.array(data.get("tags"), "tags")
    seen_epcs = set()
    for index, tag in enumerate(tags):
        where = f"tags[{index}]"
        check.entry(tag, where, _HELPER_TAG_KEYS if helper else _TAG_KEYS, ("epc", "trajectory"))
        epc = check.string(tag["epc"], f"{where}.epc")
        if not re.fullmatch(r"[0-9A-Fa-f]+", epc):
            check.fail(f"{where}.epc", f"must be a hex string such as 'E2000A01', got {epc!r}")
        if epc.upper() in seen_epcs:
            check.fail(f"{where}.epc", f"duplicate epc {epc!r}")
        seen_epcs.add(epc.upper())
        if "phase_offset_rad" in tag:
            tag["phase_offset_rad"] = check.number(tag["phase_offset_rad"], f"{where}.phase_offset_rad")
        check_trajectory(check, check.table(tag["trajectory"], f"{where}.trajectory"), f"{where}.trajectory", data)


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


def _resolve_marvel(check: Checker, data: dict) -> dict:
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
    if "reflectors" in scene:
        _no_declared_reflectors(check, "marvel")
    check.keys(scene, _MARVEL_SCENE_KEYS, "scene")
    scene.setdefault("name", data["name"])
    check.string(scene["name"], "scene.name")
    if "region" in scene:
        check_region(check, scene)

    if "controller" not in data:
        check.fail("controller", "missing (the controller's [controller] position, hidden from the estimator)")
    controller = check.table(data["controller"], "controller")
    check.keys(controller, _CONTROLLER_KEYS, "controller")
    if "position" not in controller:
        check.fail("controller.position", "missing")
    controller["position"] = check.point(controller["position"], "controller.position")
    check.choice(controller.setdefault("array", "triangle"), "controller.array", marvel_model.ARRAYS)
    controller["walls"] = check.integer(controller.setdefault("walls", 0), "controller.walls", 0)

    if "flight" not in data:
        check.fail("flight", "missing (the drone's [flight] table)")
    try:
        data["flight"] = drone.check_flight(check.table(data["flight"], "flight"), data["duration_s"])
    except drone.ParameterError as error:
        check.fail("flight" if error.key is None else f"flight.{error.key}", error.message)
    for table, resolve in (("imu_model", imu_sim.resolve_imu_model), ("feature_model", marvel_model.resolve_feature_model)):
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


def _resolve_reader_model(check: Checker, given: dict, antenna_ids: set, phase_period: str) -> dict:
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
    check_reflectors(check, model["reflectors"], key)
    return model
