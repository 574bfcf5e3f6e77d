"""Writing ``scene.toml`` (docs/formats.md section 1): a :class:`scattertrack.io.scene.Scene` as TOML.

The writer half of :mod:`scattertrack.io.scene`, which defines the scene and
reads it; ``scene`` is taken by its attributes, so this module needs nothing
of scattertrack and ``Scene.save`` can call it.
"""

from __future__ import annotations

import datetime
import re
from pathlib import Path

import numpy as np


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")
_ESCAPES = {
    '"': '\\"',
    "\\": "\\\\",
    "\b": "\\b",
    "\t": "\\t",
    "\n": "\\n",
    "\f": "\\f",
    "\r": "\\r",
}


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.match(key) else _toml_string(key)


def _toml_string(value: str) -> str:
    """A TOML basic string, escaping quotes, backslashes and control characters."""
    out = []
    for char in value:
        if char in _ESCAPES:
            out.append(_ESCAPES[char])
        elif ord(char) < 0x20 or ord(char) == 0x7F:
            out.append(f"\\u{ord(char):04x}")
        else:
            out.append(char)
    return '"' + "".join(out) + '"'


def _toml_value(value) -> str:
    """One value in TOML syntax; floats with repr() so they read back exactly."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)  # "0.1", "1e-05", "nan", "inf" are all valid TOML floats
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (datetime.datetime, datetime.date, datetime.time)):
        return value.isoformat()
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {value!r} ({type(value).__name__}) to TOML")


def _vector(values) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def write_scene(path, scene) -> None:
    """Write ``scene`` as TOML that :func:`read_scene` reads back to an equal Scene.

    Extra top-level values are written after the known keys; extra tables
    each as their own ``[table]`` (nested values inline).
    """
    lines = [f"name = {_toml_string(scene.name)}", f"dimensions = {int(scene.dimensions)}"]
    if scene.plane_z is not None:
        lines.append(f"plane_z = {float(scene.plane_z)!r}")
    extra_tables = {k: v for k, v in scene.extra.items() if isinstance(v, dict)}
    for key, value in scene.extra.items():
        if key not in extra_tables:
            lines.append(f"{_toml_key(key)} = {_toml_value(value)}")

    reader = scene.reader
    lines += ["", "[reader]", f"kind = {_toml_string(reader.kind)}"]
    lines.append(f"phase_sign = {int(reader.phase_sign)}")
    lines.append(f"phase_period = {_toml_string(reader.phase_period)}")
    if reader.phase_noise_rad is not None:
        lines.append(f"phase_noise_rad = {float(reader.phase_noise_rad)!r}")

    for antenna in scene.antennas:
        lines += ["", "[[antennas]]", f"id = {int(antenna.id)}"]
        lines.append(f"position = {_vector(antenna.position)}")
        lines.append(f"phase_offset_rad = {float(antenna.phase_offset_rad)!r}")
        lines.append(f"role = {_toml_string(antenna.role)}")

    if scene.region is not None:
        lines += ["", "[region]", f"min = {_vector(scene.region.min)}"]
        lines.append(f"max = {_vector(scene.region.max)}")

    for offset in scene.channel_offsets:
        lines += ["", "[[channel_offsets]]"]
        lines.append(f"frequency_hz = {float(offset.frequency_hz)!r}")
        lines.append(f"phase_offset_rad = {float(offset.phase_offset_rad)!r}")

    for index, frequency in sorted(scene.hop_table.items()):
        lines += ["", "[[hop_table]]", f"channel_index = {int(index)}", f"frequency_hz = {float(frequency)!r}"]

    for reflector in scene.reflectors:
        lines += ["", "[[reflectors]]", f"kind = {_toml_string(reflector.kind)}"]
        for key in ("point", "normal", "position"):
            if getattr(reflector, key) is not None:
                lines.append(f"{key} = {_vector(getattr(reflector, key))}")
        lines.append(f"coefficient = {float(reflector.coefficient)!r}")

    for key, table in extra_tables.items():
        lines += ["", f"[{_toml_key(key)}]"]
        lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in table.items()]

    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
