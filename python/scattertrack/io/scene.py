"""Scenes, ``scene.toml`` (docs/formats.md section 1).

A scene describes the hardware: the reader (kind, phase sign and period),
its antennas (ids, positions in metres, calibrated phase offsets in
radians), an optional region where tags can be (metres), optional
per-channel phase offsets (hertz, radians) and the reader's optional hop
table (``[[hop_table]]``: 1-based ``channel_index`` -> ``frequency_hz``, hertz,
what LLRP readers' channel indices in reads.csv stand for).

A helper scene (``kind = "sdr-helper"``, docs/formats.md section 5) has exactly
one antenna with ``role = "tx"`` and at least two with ``role = "rx"`` (no
``"txrx"``); its optional ``[helper]`` table records the OFDM set-up
(``centre_frequency_hz``, ``bandwidth_hz`` in hertz, ``n_subcarriers``,
``blf_hz`` in hertz) and is kept in ``Scene.extra["helper"]``.

A ``cots`` scene may declare known reflectors (``[[reflectors]]``, kept in
``Scene.reflectors``): walls (``kind = "plane"``: a ``point`` on it and its
``normal``, stored unit length) and point scatterers (``kind = "point"``: its
``position``), each with an amplitude reflection ``coefficient`` in [-1, 1],
the keys of the simulator's ``[[reader_model.reflectors]]``; trackers that
model multipath add their phase excess (docs/formats.md section 1).

Errors name the key path as the "column" (``antennas[2].position``, list
indices 0-based as in ``Scene.antennas``) and the 1-based line where that key
is written, found by scanning the text (tomllib does not report positions).
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scattertrack.io import units
from scattertrack.io.cells import INT64_MAX, INT64_MIN
from scattertrack.io.errors import FormatError, warn_input
from scattertrack.io.scene_toml import write_scene

READER_KINDS = ("cots", "sdr-helper", "lora-backscatter")
KINDS_WITH_ANTENNAS = ("cots", "sdr-helper")
"""Reader kinds whose phase model needs antenna positions."""
ROLES = ("txrx", "tx", "rx")
HELPER_ROLES = ("tx", "rx")
"""Roles an ``sdr-helper`` scene's antennas may have (bistatic: no "txrx")."""
HELPER_NUMBERS = ("centre_frequency_hz", "bandwidth_hz", "blf_hz")
"""Positive numbers (hertz) of a helper scene's ``[helper]`` table; ``n_subcarriers`` is a positive integer."""
PERIODS = ("2pi", "pi")
REFLECTOR_KEYS = {"plane": ("point", "normal", "coefficient"), "point": ("position", "coefficient")}
"""Keys of each reflector kind besides ``kind`` (all required); the simulator's
``[[reader_model.reflectors]]`` take the same."""
REFLECTOR_VECTORS = ("point", "normal", "position")
"""The vector keys (3 numbers each) of the reflector kinds."""
REFLECTOR_READER_KINDS = ("cots",)
"""Reader kinds whose scenes may declare ``[[reflectors]]`` (the monostatic multipath model)."""
ON_PLANE_M = 1e-3
"""An antenna within this distance of a plane reflector, metres, is warned (valid but suspicious)."""
KNOWN_KEYS = {
    "reader": ("kind", "phase_sign", "phase_period", "phase_noise_rad"),
    "antennas": ("id", "position", "phase_offset_rad", "role"),
    "region": ("min", "max"),
    "channel_offsets": ("frequency_hz", "phase_offset_rad"),
    "helper": ("centre_frequency_hz", "bandwidth_hz", "n_subcarriers", "blf_hz"),
    "hop_table": ("channel_index", "frequency_hz"),
    "reflectors": ("kind", "point", "normal", "position", "coefficient"),
}
"""Keys of the known tables; another key there is accepted with a warning (it is likely a typo
whose setting would otherwise be lost without a word)."""
NOISE_PRIOR_RANGE_RAD = (0.001, 1.0)
"""A ``phase_noise_rad`` at or below the first or above the second, radians, is implausible
(warned): COTS readers measure about 0.01-0.2 rad; a filter given 1e-4 rad rejects every read
as an outlier, one given > 1 rad learns nothing from phase."""
KNOWN_TOP_LEVEL = (
    "name",
    "dimensions",
    "plane_z",
    "reader",
    "antennas",
    "region",
    "channel_offsets",
    "hop_table",
    "reflectors",
)


@dataclass
class Antenna:
    """One reader or helper antenna port."""

    id: int
    """Port number as the reader reports it."""
    position: np.ndarray
    """Phase centre in the world frame, metres, shape (3,)."""
    phase_offset_rad: float = 0.0
    """Calibrated cable/port phase offset, radians."""
    role: str = "txrx"
    """"txrx" (monostatic), "tx" or "rx" (bistatic helper)."""


@dataclass
class Reader:
    kind: str = "cots"
    """"cots", "sdr-helper" or "lora-backscatter"."""
    phase_sign: int = 1
    """+1: phase grows with distance; -1: it shrinks."""
    phase_period: str = "2pi"
    """"2pi", or "pi" for readers that report phase mod pi."""
    phase_noise_rad: float | None = None
    """Optional 1-sigma phase noise prior for filters, radians."""

    @property
    def period_rad(self) -> float:
        """The phase period P in radians: 2*pi or pi."""
        return np.pi if self.phase_period == "pi" else 2.0 * np.pi


@dataclass
class Region:
    """Axis-aligned box where tags can be, metres."""

    min: np.ndarray
    max: np.ndarray


@dataclass
class ChannelOffset:
    frequency_hz: float
    phase_offset_rad: float


NEAR_FIELD_M = 0.16
"""A point scatterer closer than this to an antenna (half a wavelength at 915 MHz) is in its near field."""


def point_near_antennas(position, antennas) -> list[str]:
    """What is odd about a point scatterer at ``position`` (m) for these
    antennas: one within :data:`NEAR_FIELD_M`, where the ray model of a
    reflected path (amplitude Γ / L) does not describe the coupling, and a
    strong one can cancel the direct path outright."""
    position = np.asarray(position, dtype=float)
    near = [int(a.id) for a in antennas if float(np.linalg.norm(np.asarray(a.position, dtype=float) - position)) < NEAR_FIELD_M]
    if not near:
        return []
    return [f"point scatterer within {NEAR_FIELD_M * 100:g} cm (half a wavelength) of antenna{'s' if len(near) > 1 else ''} "
            f"{', '.join(map(str, near))}: in the near field the reflected-path model does not hold "
            "(check its position; a mount or cable belongs in the antenna's calibration, not here)"]


def plane_side_problems(point, normal, antennas) -> list[str]:
    """What is odd about a plane reflector (``point`` m, unit ``normal``) for
    these antennas: one (nearly) on it, or antennas on both sides of it."""
    point, normal = np.asarray(point, dtype=float), np.asarray(normal, dtype=float)
    sides = {int(a.id): float((np.asarray(a.position, dtype=float) - point) @ normal) for a in antennas}
    problems = []
    on = [i for i, side in sides.items() if abs(side) <= ON_PLANE_M]
    if on:
        problems.append(f"antenna{'s' if len(on) > 1 else ''} {', '.join(map(str, on))} within "
                        f"{ON_PLANE_M * 1e3:g} mm of this plane reflector: a mirror reflects only between points "
                        "on the same side of it, so its path is unreliable there (check point and normal)")
    front = [i for i, side in sides.items() if side > ON_PLANE_M]
    back = [i for i, side in sides.items() if side < -ON_PLANE_M]
    if front and back:
        problems.append(f"antennas on both sides of this plane reflector (in front: {', '.join(map(str, front))}; "
                        f"behind: {', '.join(map(str, back))}): a wall between antennas is unusual "
                        "(check point and normal)")
    return problems


def unit_normal(normal: np.ndarray) -> np.ndarray:
    """A non-zero ``normal`` at unit length: scaled by its largest component first (huge or
    tiny components neither overflow nor underflow); one already unit within 4 ulp is left as
    it is, so that writing and reading a scene leaves nothing drifting."""
    normal = np.asarray(normal, dtype=np.float64)
    if not 1e-150 < np.linalg.norm(normal) < math.inf:
        normal = normal / np.abs(normal).max()
    length = float(np.linalg.norm(normal))
    return normal if abs(length - 1.0) <= 4.0 * np.finfo(np.float64).eps else normal / length


@dataclass
class Reflector:
    """A known reflector (``[[reflectors]]``): a wall or a point scatterer, docs/formats.md section 1."""

    kind: str
    """"plane" (an infinite mirror) or "point" (a point scatterer)."""
    coefficient: float
    """Amplitude reflection coefficient in [-1, 1] (negative: a phase flip)."""
    point: np.ndarray | None = None
    """A plane's point on it, metres, shape (3,); None for a point scatterer."""
    normal: np.ndarray | None = None
    """A plane's unit normal, shape (3,); None for a point scatterer."""
    position: np.ndarray | None = None
    """A point scatterer's position, metres, shape (3,); None for a plane."""

    def __post_init__(self):
        self.coefficient = float(self.coefficient)
        for name in REFLECTOR_VECTORS:
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, np.asarray(value, dtype=np.float64))

    @classmethod
    def from_dict(cls, values: dict) -> "Reflector":
        """From plain values (a scenario's ``[[scene.reflectors]]``, a calibration's fit): the
        keys of its kind (:data:`REFLECTOR_KEYS`), a plane's normal made unit (:func:`unit_normal`)."""
        vectors = {key: np.asarray(values[key], dtype=np.float64) for key in REFLECTOR_KEYS[values["kind"]] if key != "coefficient"}
        if "normal" in vectors:
            vectors["normal"] = unit_normal(vectors["normal"])
        return cls(kind=values["kind"], coefficient=float(values["coefficient"]), **vectors)

    def as_dict(self) -> dict:
        """Plain values (lists of floats), as :func:`scattertrack.physics.round_trip_channel` takes them."""
        out = {"kind": self.kind, "coefficient": self.coefficient}
        out.update({key: [float(v) for v in getattr(self, key)] for key in REFLECTOR_VECTORS if getattr(self, key) is not None})
        return out


@dataclass
class Scene:
    """A hardware set-up (``scene.toml``)."""

    name: str
    dimensions: int
    """2 (tag moves in the plane z = plane_z) or 3."""
    reader: Reader
    antennas: list[Antenna]
    plane_z: float | None = None
    """Height of the motion plane, metres; required when dimensions == 2."""
    region: Region | None = None
    channel_offsets: list[ChannelOffset] = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    """Unknown top-level tables/keys, kept so that a round trip loses nothing."""
    hop_table: dict[int, float] = field(default_factory=dict)
    """The reader's hop table (``[[hop_table]]``): its 1-based channel index -> carrier, hertz.
    Empty when the scene gives none. LLRP readers report this index, not a frequency."""
    reflectors: list[Reflector] = field(default_factory=list)
    """Known reflectors the user declares (``[[reflectors]]``, cots scenes only); empty when none."""

    def antenna_index(self, antenna_id: int) -> int:
        """Index into ``antennas`` of the antenna with this port id (KeyError if none)."""
        for i, a in enumerate(self.antennas):
            if a.id == antenna_id:
                return i
        raise KeyError(antenna_id)

    def channel_offset(self, frequency_hz: float) -> float:
        """Calibrated offset of the channel matched within 1 kHz; 0 if none (docs/formats.md 1)."""
        for c in self.channel_offsets:
            if abs(c.frequency_hz - frequency_hz) <= 1e3:
                return c.phase_offset_rad
        return 0.0

    @staticmethod
    def load(path) -> "Scene":
        """Read and validate a ``scene.toml`` (see :func:`scattertrack.io.read_scene`)."""
        return read_scene(path)

    def save(self, path) -> None:
        """Write it as ``scene.toml`` (see :func:`scattertrack.io.write_scene`)."""
        write_scene(path, self)


def read_scene(path) -> Scene:
    """Read and validate a ``scene.toml``.

    Unknown top-level keys and tables are kept in ``Scene.extra``; unknown
    keys inside the known tables are ignored. Without a ``name``, the scene
    is named after the folder that holds the file. Raises :class:`FormatError`
    with the key path as the column and the line where the key is written.
    """
    try:
        text = Path(path).read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise FormatError(path, None, None, f"not UTF-8 text: {error}") from None
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise _syntax_error(path, text, error) from None
    return _SceneChecker(path, text).scene(document)


def _syntax_error(path, text: str, error: tomllib.TOMLDecodeError) -> FormatError:
    """A FormatError at the line and column tomllib's message gives."""
    message = str(error)
    found = re.search(r"\(at line (\d+), column (\d+)\)$", message)
    if found:
        line, column = int(found.group(1)), found.group(2)
        message = message[: found.start()].rstrip()
    else:
        # "(at end of document)": the fault is at the last line.
        line, column = max(1, len(text.splitlines())), None
        message = re.sub(r"\s*\(at end of document\)$", "", message) + " (at end of document)"
    return FormatError(path, line, column, f"TOML syntax error: {message}")


# --- locating keys in the text ----------------------------------------------

_ARRAY_HEADER = re.compile(r"^\s*\[\[\s*([^\[\]]+?)\s*\]\]\s*(#.*)?$")
_TABLE_HEADER = re.compile(r"^\s*\[\s*([^\[\]]+?)\s*\]\s*(#.*)?$")
_TABLE_NAME = re.compile(r"^[A-Za-z0-9_\-.\"' ]+$")


def _sections(text: str) -> list[tuple[str, int, int, int]]:
    """Tables of the text as (name, header line, first body line, end line), 1-based.

    The top level is the section named "" with header line 0. An array of
    tables gives one section per ``[[name]]`` header.
    """
    lines = text.split("\n")
    sections = []
    name, header = "", 0
    for number, line in enumerate(lines, start=1):
        found = _ARRAY_HEADER.match(line) or _TABLE_HEADER.match(line)
        if found and _TABLE_NAME.match(found.group(1)):
            sections.append((name, header, header + 1, number))
            name = re.sub(r"\s*\.\s*", ".", found.group(1).replace('"', "").replace("'", ""))
            header = number
    sections.append((name, header, header + 1, len(lines) + 1))
    return sections


def _line_of_key(text: str, key_path: str) -> int | None:
    """Best-effort 1-based line where ``key_path`` (e.g. ``antennas[2].position``) is written.

    A missing key inside a table gives the table's header line; a key that
    cannot be found at all gives None.
    """
    found = re.fullmatch(r"([^.\[]+)(?:\[(\d+)\])?(?:\.(.+))?", key_path)
    if not found:
        return None
    first, index, rest = found.group(1), found.group(2), found.group(3)
    lines = text.split("\n")
    sections = _sections(text)
    # A top-level key: "dimensions".
    if index is None and rest is None:
        line = _find_assignment(lines, sections[0], first)
        if line is not None:
            return line
        tables = [s for s in sections if s[0] == first]
        return tables[0][1] if tables else None
    # A key in a table or in the N-th table of an array: "reader.kind", "antennas[2].id".
    tables = [s for s in sections if s[0] == first]
    if index is not None:
        tables = tables[int(index) : int(index) + 1]
    if tables:
        if rest is None:
            return tables[0][1]
        line = _find_assignment(lines, tables[0], rest.split(".")[0])
        return line if line is not None else tables[0][1]
    # Written inline or dotted at the top level: "reader = {...}", "reader.kind = ...".
    return _find_assignment(lines, sections[0], first)


def _find_assignment(lines: list[str], section, key: str) -> int | None:
    """Line of ``key = ...`` (or ``key.sub = ...``) within one section, or None."""
    _, _, first_body, end = section
    pattern = re.compile(r"^\s*[\"']?" + re.escape(key) + r"[\"']?\s*[=.]")
    for number in range(first_body, end):
        if pattern.match(lines[number - 1]):
            return number
    return None


# --- validation -------------------------------------------------------------


_NO_DEFAULT = object()
"""Marks a key that has no default."""


def _parent(key_path: str) -> str:
    """The table holding a key: "antennas[2]" for "antennas[2].position"."""
    return key_path.rsplit(".", 1)[0]


def _is_number(value) -> bool:
    """An int or float TOML value (bool is an int in Python, but not a number here)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class _SceneChecker:
    """Validates a parsed document and builds the Scene; knows the text for line numbers."""

    def __init__(self, path, text: str):
        self.path = path
        self.text = text

    def fail(self, key_path: str, message: str, near: str | None = None) -> FormatError:
        """An error at ``key_path``; ``near`` gives the line when that key is absent."""
        line = _line_of_key(self.text, key_path)
        if line is None and near is not None:
            line = _line_of_key(self.text, near)
        return FormatError(self.path, line, key_path, message)

    def warn(self, key_path: str, message: str) -> None:
        """An :class:`InputWarning` at ``key_path`` (valid but suspicious)."""
        warn_input(self.path, _line_of_key(self.text, key_path), key_path, message)

    def warn_unknown_keys(self, table: dict, kind: str, where: str | None = None) -> None:
        """Warn about keys of a known table that the format does not define (the table is still read)."""
        where = where or kind
        for key in table:
            if key not in KNOWN_KEYS[kind]:
                self.warn(f"{where}.{key}", f"unknown key (ignored); [{kind}] keys are {', '.join(KNOWN_KEYS[kind])}")

    def number(self, table: dict, key: str, key_path: str, default=_NO_DEFAULT) -> float | None:
        """A finite number (int or float) from ``table[key]``, or ``default`` if absent."""
        if key not in table:
            if default is _NO_DEFAULT:
                raise self.fail(key_path, "missing required key", near=_parent(key_path))
            return default
        value = table[key]
        if not _is_number(value) or not math.isfinite(value):
            raise self.fail(key_path, f"expected a finite number, found {value!r}")
        return float(value)

    def vector3(self, table: dict, key: str, key_path: str) -> np.ndarray:
        """Three finite numbers from ``table[key]``, metres."""
        if key not in table:
            raise self.fail(key_path, "missing required key", near=_parent(key_path))
        value = table[key]
        if (
            not isinstance(value, list)
            or len(value) != 3
            or not all(_is_number(v) and math.isfinite(v) for v in value)
        ):
            raise self.fail(key_path, f"expected 3 finite numbers, found {value!r}")
        return np.array(value, dtype=np.float64)

    def choice(self, table: dict, key: str, key_path: str, allowed, default=_NO_DEFAULT):
        """``table[key]`` if it is one of ``allowed`` (type included: 1.0 is not 1)."""
        if key not in table:
            if default is _NO_DEFAULT:
                raise self.fail(key_path, "missing required key", near=_parent(key_path))
            return default
        value = table[key]
        if not any(type(value) is type(a) and value == a for a in allowed):
            options = ", ".join(repr(a) for a in allowed)
            raise self.fail(key_path, f"expected one of {options}, found {value!r}")
        return value

    def table(self, document: dict, key: str) -> dict:
        value = document[key]
        if not isinstance(value, dict):
            raise self.fail(key, f"expected a table, found {value!r}")
        return value

    def array_of_tables(self, document: dict, key: str) -> list[dict]:
        value = document.get(key, [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.fail(key, f"expected an array of tables ([[{key}]]), found {value!r}")
        return value

    def scene(self, document: dict) -> Scene:
        name = document.get("name", Path(self.path).resolve().parent.name)
        if not isinstance(name, str):
            raise self.fail("name", f"expected a string, found {name!r}")
        dimensions = self.choice(document, "dimensions", "dimensions", (2, 3))
        plane_z = self.number(document, "plane_z", "plane_z", default=None)
        if dimensions == 2 and plane_z is None:
            raise self.fail("plane_z", "required when dimensions = 2", near="dimensions")
        if "reader" not in document:
            raise self.fail("reader", "missing required table [reader]")
        reader = self.reader(self.table(document, "reader"))
        antennas = self.antennas(document, reader.kind)
        region = None
        if "region" in document:
            region = self.region(self.table(document, "region"), dimensions, plane_z)
        channel_offsets = self.channel_offsets(document)
        hop_table = self.hop_table(document)
        reflectors = self.reflectors(document, reader.kind, antennas)
        extra = {k: v for k, v in document.items() if k not in KNOWN_TOP_LEVEL}
        if reader.kind == "sdr-helper":
            self.helper_roles(antennas)
            if "helper" in document:
                self.helper_table(self.table(document, "helper"))
        return Scene(
            name=name,
            dimensions=dimensions,
            reader=reader,
            antennas=antennas,
            plane_z=plane_z,
            region=region,
            channel_offsets=channel_offsets,
            extra=extra,
            hop_table=hop_table,
            reflectors=reflectors,
        )

    def reader(self, table: dict) -> Reader:
        self.warn_unknown_keys(table, "reader")
        kind = self.choice(table, "kind", "reader.kind", READER_KINDS)
        phase_sign = self.choice(table, "phase_sign", "reader.phase_sign", (1, -1), 1)
        phase_period = self.choice(table, "phase_period", "reader.phase_period", PERIODS, "2pi")
        noise = self.number(table, "phase_noise_rad", "reader.phase_noise_rad", default=None)
        if noise is not None and noise <= 0.0:
            raise self.fail("reader.phase_noise_rad", f"must be positive, found {noise!r}")
        low, high = NOISE_PRIOR_RANGE_RAD
        if noise is not None and not low < noise <= high:
            self.warn("reader.phase_noise_rad", f"implausible phase noise prior {noise!r} rad (1-sigma; "
                      f"readers measure about 0.01-0.2 rad; warned at or below {low:g} and above {high:g})")
        return Reader(kind, phase_sign, phase_period, noise)

    def antennas(self, document: dict, kind: str) -> list[Antenna]:
        tables = self.array_of_tables(document, "antennas")
        if not tables and kind in KINDS_WITH_ANTENNAS:
            raise self.fail(
                "antennas", f"a {kind!r} scene needs [[antennas]]", near="reader.kind"
            )
        antennas = []
        for i, table in enumerate(tables):
            where = f"antennas[{i}]"
            self.warn_unknown_keys(table, "antennas", where)
            antenna_id = table.get("id")
            if antenna_id is None:
                raise self.fail(f"{where}.id", "missing required key", near=where)
            if not isinstance(antenna_id, int) or isinstance(antenna_id, bool):
                raise self.fail(f"{where}.id", f"expected an integer, found {antenna_id!r}")
            if not INT64_MIN <= antenna_id <= INT64_MAX:
                raise self.fail(f"{where}.id", f"antenna id {antenna_id} out of range: ids must fit in a signed "
                                               f"64-bit integer ({INT64_MIN} to {INT64_MAX})")
            if any(a.id == antenna_id for a in antennas):
                raise self.fail(f"{where}.id", f"antenna id {antenna_id} is used twice")
            antennas.append(
                Antenna(
                    id=antenna_id,
                    position=self.vector3(table, "position", f"{where}.position"),
                    phase_offset_rad=self.number(
                        table, "phase_offset_rad", f"{where}.phase_offset_rad", default=0.0
                    ),
                    role=self.choice(table, "role", f"{where}.role", ROLES, "txrx"),
                )
            )
        return antennas

    def helper_roles(self, antennas: list[Antenna]) -> None:
        """An sdr-helper scene: roles "tx"/"rx" only, exactly one tx, at least two rx."""
        for i, antenna in enumerate(antennas):
            if antenna.role not in HELPER_ROLES:
                raise self.fail(
                    f"antennas[{i}].role",
                    f"an 'sdr-helper' antenna needs role 'tx' or 'rx', found {antenna.role!r}",
                    near=f"antennas[{i}]",
                )
        tx = [i for i, a in enumerate(antennas) if a.role == "tx"]
        if len(tx) > 1:
            raise self.fail(
                f"antennas[{tx[1]}].role",
                f"an 'sdr-helper' scene has exactly one 'tx' antenna; antennas[{tx[0]}] is one already",
            )
        if not tx:
            raise self.fail("antennas", "an 'sdr-helper' scene needs one antenna with role 'tx', found none")
        n_rx = sum(a.role == "rx" for a in antennas)
        if n_rx < 2:
            raise self.fail("antennas", f"an 'sdr-helper' scene needs at least 2 antennas with role 'rx', found {n_rx}")

    def helper_table(self, table: dict) -> None:
        """The optional ``[helper]`` table: positive frequencies (Hz), the carrier within 100 MHz to
        10 GHz (with the likely unit), and a positive subcarrier count; other keys are warned."""
        self.warn_unknown_keys(table, "helper")
        for key in HELPER_NUMBERS:
            if key in table:
                value = self.number(table, key, f"helper.{key}")
                if value <= 0.0:
                    raise self.fail(f"helper.{key}", f"must be positive, found {value!r}")
        if "centre_frequency_hz" in table:
            value = float(table["centre_frequency_hz"])
            if units.frequency_outside(np.array([value]))[0]:
                raise self.fail("helper.centre_frequency_hz", units.frequency_message(repr(table["centre_frequency_hz"]), value))
        if "n_subcarriers" in table:
            value = table["n_subcarriers"]
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise self.fail("helper.n_subcarriers", f"expected a positive integer, found {value!r}")

    def region(self, table: dict, dimensions: int, plane_z: float | None) -> Region:
        """The box where tags can be, metres (docs/formats.md 1).

        With ``dimensions = 2`` only x and y bound the tag: z may have zero
        extent (min z = max z = plane_z, the natural way to write a plane)
        or be left out (two values per corner; z is then plane_z).
        """
        self.warn_unknown_keys(table, "region")
        if dimensions == 3:
            low = self.vector3(table, "min", "region.min")
            high = self.vector3(table, "max", "region.max")
            if not (low < high).all():
                raise self.fail("region.max", f"must exceed region.min on every axis: {low} vs {high}")
            return Region(low, high)
        low = self.plane_corner(table, "min", plane_z)
        high = self.plane_corner(table, "max", plane_z)
        if not (low[:2] < high[:2]).all():
            raise self.fail("region.max", f"must exceed region.min in x and y: {low} vs {high}")
        if low[2] > high[2]:
            raise self.fail("region.max", f"z must be at least region.min's z: {low[2]} vs {high[2]}")
        if not low[2] <= plane_z <= high[2]:
            self.warn("region.min", f"the region's z range [{low[2]}, {high[2]}] m does not hold plane_z = {plane_z}: "
                      "z is ignored in 2D, but the numbers disagree")
        return Region(low, high)

    def plane_corner(self, table: dict, key: str, plane_z: float) -> np.ndarray:
        """A corner of a 2D scene's region: [x, y] (z = plane_z) or [x, y, z], metres."""
        value = table.get(key)
        if isinstance(value, list) and len(value) == 2 and all(_is_number(v) and math.isfinite(v) for v in value):
            return np.array([*value, plane_z], dtype=np.float64)
        if isinstance(value, list) and len(value) != 3 and key in table:
            raise self.fail(f"region.{key}", f"expected 2 or 3 finite numbers (dimensions = 2), found {value!r}")
        return self.vector3(table, key, f"region.{key}")

    def channel_offsets(self, document: dict) -> list[ChannelOffset]:
        offsets = []
        for i, table in enumerate(self.array_of_tables(document, "channel_offsets")):
            where = f"channel_offsets[{i}]"
            self.warn_unknown_keys(table, "channel_offsets", where)
            frequency = self.number(table, "frequency_hz", f"{where}.frequency_hz")
            if units.frequency_outside(np.array([frequency]))[0]:
                raise self.fail(f"{where}.frequency_hz", units.frequency_message(repr(table["frequency_hz"]), frequency))
            offset = self.number(table, "phase_offset_rad", f"{where}.phase_offset_rad")
            offsets.append(ChannelOffset(frequency, offset))
        return offsets

    def hop_table(self, document: dict) -> dict[int, float]:
        """The reader's hop table: 1-based channel index -> carrier, hertz (unique indices)."""
        table = {}
        for i, entry in enumerate(self.array_of_tables(document, "hop_table")):
            where = f"hop_table[{i}]"
            self.warn_unknown_keys(entry, "hop_table", where)
            index = entry.get("channel_index")
            if index is None:
                raise self.fail(f"{where}.channel_index", "missing required key", near=where)
            if not isinstance(index, int) or isinstance(index, bool) or not 1 <= index <= INT64_MAX:
                raise self.fail(f"{where}.channel_index",
                                f"expected a positive integer (the reader's 1-based channel index), found {index!r}")
            if index in table:
                raise self.fail(f"{where}.channel_index", f"channel index {index} is given twice")
            frequency = self.number(entry, "frequency_hz", f"{where}.frequency_hz")
            if units.frequency_outside(np.array([frequency]))[0]:
                raise self.fail(f"{where}.frequency_hz", units.frequency_message(repr(entry["frequency_hz"]), frequency))
            table[index] = frequency
        return table

    def reflectors(self, document: dict, kind: str, antennas: list[Antenna]) -> list[Reflector]:
        """Known reflectors (``[[reflectors]]``, cots scenes only): planes and point scatterers."""
        tables = self.array_of_tables(document, "reflectors")
        if tables and kind not in REFLECTOR_READER_KINDS:
            raise self.fail(
                "reflectors",
                f"only 'cots' scenes take [[reflectors]] for now; this one has reader.kind = {kind!r}",
            )
        reflectors = []
        for i, table in enumerate(tables):
            where = f"reflectors[{i}]"
            self.warn_unknown_keys(table, "reflectors", where)
            reflector_kind = self.choice(table, "kind", f"{where}.kind", tuple(REFLECTOR_KEYS))
            for key in table:
                if key != "kind" and key in KNOWN_KEYS["reflectors"] and key not in REFLECTOR_KEYS[reflector_kind]:
                    self.warn(f"{where}.{key}", f"not a key of a {reflector_kind!r} reflector (ignored); its keys are "
                                                f"kind, {', '.join(REFLECTOR_KEYS[reflector_kind])}")
            vectors = {key: self.vector3(table, key, f"{where}.{key}")
                       for key in REFLECTOR_KEYS[reflector_kind] if key != "coefficient"}
            coefficient = self.number(table, "coefficient", f"{where}.coefficient")
            if not -1.0 <= coefficient <= 1.0:
                raise self.fail(f"{where}.coefficient", "expected an amplitude reflection coefficient in [-1, 1], "
                                                        f"found {table['coefficient']!r}")
            if reflector_kind == "plane":
                if not vectors["normal"].any():
                    raise self.fail(f"{where}.normal", f"expected a non-zero vector, found {table['normal']!r}")
                vectors["normal"] = unit_normal(vectors["normal"])
                self.plane_sides(where, vectors["point"], vectors["normal"], antennas)
            else:
                for message in point_near_antennas(vectors["position"], antennas):
                    self.warn(where, message)
            reflectors.append(Reflector(kind=reflector_kind, coefficient=coefficient, **vectors))
        return reflectors

    def plane_sides(self, where: str, point: np.ndarray, normal: np.ndarray, antennas: list[Antenna]) -> None:
        """Warn about a plane with an antenna (nearly) on it, or with antennas on both sides of it."""
        for message in plane_side_problems(point, normal, antennas):
            self.warn(where, message)
