"""Scenario validation: the checks that raise :class:`FormatError` naming the file and the key.

:class:`Checker` holds the file a scenario came from and raises
``FormatError(file, None, key, message)`` with a plain message (``key`` a
dotted path such as ``tags[0].trajectory.speed``); the functions below
check one shared table each. Scenario resolution
(:mod:`scattertrack.sim.scenario_resolve`) and the helper model
(:func:`scattertrack.sim.wideband.resolve_helper_model`) build on them.
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.scene import REFLECTOR_KEYS
from scattertrack.io.types import FormatError
from scattertrack.sim import trajectory


class Checker:
    """Validation helpers that raise FormatError(file, key) with a plain message."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, message: str):
        raise FormatError(self.source, None, key, message)

    def table(self, value, key: str) -> dict:
        if not isinstance(value, dict):
            self.fail(key, f"must be a table, got {value!r}")
        return value

    def array(self, value, key: str) -> list:
        """A non-empty array of tables ``[[key]]``."""
        if not isinstance(value, list) or not value:
            self.fail(key, f"must be a non-empty array of tables [[{key}]]")
        return value

    def entry(self, value, key: str, allowed, required) -> dict:
        """One table of an array of tables (``[[tags]]``): a table, only ``allowed`` keys, every ``required`` one."""
        self.table(value, key)
        self.keys(value, allowed, key)
        for name in required:
            if name not in value:
                self.fail(f"{key}.{name}", "missing")
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


def check_region(check: Checker, scene: dict) -> None:
    """Validates ``scene.region`` in place: ``min`` and ``max`` points (m), min below max."""
    region = check.table(scene["region"], "scene.region")
    check.keys(region, ("min", "max"), "scene.region")
    for key in ("min", "max"):
        if key not in region:
            check.fail(f"scene.region.{key}", "missing")
        region[key] = check.point(region[key], f"scene.region.{key}")
    if any(lo >= hi for lo, hi in zip(region["min"], region["max"])):
        check.fail("scene.region", "min must be below max on every axis")


def check_reflectors(check: Checker, reflectors, key: str) -> None:
    """Validate ``[[<model>.reflectors]]`` in place (``key`` is the model's prefix, e.g. ``reader_model.``)."""
    if not isinstance(reflectors, list):
        check.fail(key + "reflectors", f"must be an array of tables [[{key}reflectors]]")
    for i, reflector in enumerate(reflectors):
        where = f"{key}reflectors[{i}]"
        check.table(reflector, where)
        kind = check.choice(reflector.get("kind"), where + ".kind", tuple(REFLECTOR_KEYS))
        check.keys(reflector, ("kind", *REFLECTOR_KEYS[kind]), where)
        for name in REFLECTOR_KEYS[kind]:
            if name not in reflector:
                check.fail(f"{where}.{name}", "missing")
        reflector["coefficient"] = check.number(reflector["coefficient"], where + ".coefficient")
        for name in ("point", "normal", "position"):
            if name in reflector:
                reflector[name] = check.point(reflector[name], f"{where}.{name}")
        if kind == "plane" and not any(reflector["normal"]):
            check.fail(where + ".normal", "must be a non-zero vector")


def check_trajectory(check: Checker, params: dict, where: str, data: dict) -> None:
    """Validate a tag's ``trajectory`` table: its keys, and its motion over the session (finite, in the plane of
    a 2D scene, never on an antenna)."""
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
