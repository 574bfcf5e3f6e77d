"""The scene geometry check over the Rust core (``crates/core/src/geometry/ambiguity.rs``).

A monostatic reader's phase fixes each antenna's range only modulo the
candidate spacing s (lambda/2, or lambda/4 for mod-pi readers). Some layouts
leave these integers free: three antennas on one line, all antennas in one
plane (the mirror image), a flat layout (an all-antennas shift). The core
searches the region for *twin positions* that fit every phase within the
noise; this module words its findings as ``warning:`` / ``note:`` lines that
name the antennas by their scene ids, the size of the ambiguity in cm and the
remedy.

Warnings are exact twin families (layout degeneracies: no amount of reads on
these channels resolves them) and approximate families over half or more of
the region; notes are weak spots (approximate twins over a small share of
the region, which motion through the rest resolves) and layout facts
(collinear / coplanar / coincident antennas) that no warning explains.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scattertrack import _core
from scattertrack.io.types import Reads, Scene

AXES = "xyz"


@dataclass
class Finding:
    """One line of the check."""

    severity: str
    """"warning" or "note"."""
    text: str
    """The line without its ``warning:`` / ``note:`` prefix."""
    details: dict = field(default_factory=dict)
    """The core's record (family or layout finding), antenna indices."""

    def line(self) -> str:
        return f"{self.severity}: {self.text}"


@dataclass
class GeometryCheck:
    """The result of :func:`check_scene`."""

    findings: list[Finding]
    summary: str
    """The last line: whether the layout fixes the position, with the search bounds."""
    report: dict
    """The core's whole report (bounds, frequencies, families, layout)."""

    @property
    def warnings(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == "warning"]

    def lines(self) -> list[str]:
        return [f.line() for f in self.findings] + [self.summary]


def _read_channels(scene: Scene, reads: Reads | None) -> tuple[list[float], float | None]:
    """Read frequencies, most-read first, and the evidence (reads per antenna
    and channel at each of the 2D+1 positions of the persistence test).

    The channels analysed jointly follow ``joint_frequencies`` in the core:
    the calibrated ones read when two or more, else the most-read one; the
    evidence is the median count over those (antenna, channel) pairs."""
    if reads is None or not len(reads):
        return [], None
    if hasattr(reads, "channel_counts"):
        # A streamed recording (scattertrack.track.streaming) keeps only how
        # many reads each (frequency, antenna) pair has: the same figures.
        frequency, antenna, weight = reads.channel_counts
    else:
        frequency, antenna = np.asarray(reads.frequency_hz, dtype=float), np.asarray(reads.antenna)
        weight = np.ones(len(frequency), dtype=np.int64)
    values, inverse = np.unique(np.round(frequency / 1e3), return_inverse=True)
    counts = np.bincount(inverse.reshape(-1), weights=weight, minlength=len(values)).astype(np.int64)
    order = np.argsort(-counts, kind="stable")
    ordered = [float(values[i] * 1e3) for i in order]
    calibrated = [f for f in ordered if any(abs(c.frequency_hz - f) <= 1e3 for c in scene.channel_offsets)]
    joint = calibrated if len(calibrated) >= 2 else ordered[:1]
    per_pair = []
    for f in joint:
        on_channel = np.abs(frequency - f) <= 1e3
        for a in scene.antennas:
            per_pair.append(int(weight[on_channel & (antenna == a.id)].sum()))
    positions = 2 * int(scene.dimensions) + 1
    evidence = max(float(np.median(per_pair)) / positions, 1.0) if per_pair else None
    return ordered, evidence


def _ids(scene: Scene, indices) -> str:
    ids = [str(scene.antennas[i].id) for i in indices]
    if len(ids) <= 1:
        return "".join(ids)
    return ", ".join(ids[:-1]) + " and " + ids[-1] if len(ids) == 2 else ", ".join(ids)


def _antennas(scene: Scene, indices) -> str:
    return ("antenna " if len(indices) == 1 else "antennas ") + _ids(scene, indices)


def _cm(metres: float) -> str:
    return f"{metres * 100:.0f} cm"


def _plane(point, normal) -> str:
    """'z = 0.00 m' for an axis-aligned plane, else its normal and a point."""
    normal = np.asarray(normal, dtype=float)
    axis = int(np.argmax(np.abs(normal)))
    if abs(normal[axis]) > 0.999:
        return f"{AXES[axis]} = {point[axis]:.2f} m"
    n = ", ".join(f"{v:.2f}" for v in normal)
    p = ", ".join(f"{v:.2f}" for v in point)
    return f"normal ({n}) through ({p}) m"


def _direction(vector) -> str:
    vector = np.asarray(vector, dtype=float)
    axis = int(np.argmax(np.abs(vector)))
    if abs(vector[axis]) > 0.999:
        return f"along {'+' if vector[axis] > 0 else '-'}{AXES[axis]}"
    return "along (" + ", ".join(f"{v:.2f}" for v in vector) + ")"


def _frequencies(report: dict) -> str:
    f = report["frequencies_hz"]
    if len(f) == 1:
        return f"{f[0] / 1e6:.2f} MHz"
    return f"{len(f)} calibrated channels {min(f) / 1e6:.2f}-{max(f) / 1e6:.2f} MHz"


def _size(family: dict, report: dict) -> str:
    where = "the region" if report["region_given"] else "the searched box (no [region])"
    return (
        f"twin positions {family['min_m'] * 100:.0f}-{_cm(family['max_m'])} away (median {_cm(family['median_m'])}) "
        f"fit every phase over {family['share'] * 100:.0f}% of {where} ({_frequencies(report)})"
    )


def _move(scene: Scene, family: dict, what: str) -> str | None:
    antenna = family["move_antenna"]
    if antenna is None:
        return None
    who = f"antenna {scene.antennas[antenna].id}"
    if family["offset_m"] is None:
        return f"moving {who} {what} by up to 50 cm does not remove it"
    return f"move {who} {what} by >= {family['offset_m'] * 100:.0f} cm ({_direction(family['direction'])})"


def _remedies(scene: Scene, family: dict, report: dict, what: str) -> str:
    parts = []
    if family["kind"] == "mirror":
        parts.append(_mirror_region(family, report))
    move = _move(scene, family, what)
    if move:
        parts.append(move)
    if family["hopping_breaks"]:
        parts.append("enable hopping with calibrated channel offsets ([[channel_offsets]])")
    elif family["hopping_breaks"] is False:
        parts.append("(hopping over the 50 US channels would not remove it)")
    elif family["kind"] != "mirror" and len(report["frequencies_hz"]) > 1:
        parts.append(f"(hopping over the {len(report['frequencies_hz'])} calibrated channels read does not remove it)")
    if family["kind"] == "too-few-antennas":
        parts.append("add antennas")
    return "remedy: " + ", or ".join(p for p in parts if p) if parts else "remedy: none found within the search"


def _mirror_region(family: dict, report: dict) -> str:
    plane = family["region_plane"]
    if plane is None:
        return "add a [region] that excludes the mirror side"
    point, normal = plane
    normal = np.asarray(normal, dtype=float)
    axis = int(np.argmax(np.abs(normal)))
    verb = "shrink the [region] to one side" if report["region_given"] else "add a [region] that excludes the mirror side"
    if abs(normal[axis]) > 0.999:
        c = point[axis]
        return f"{verb} ({AXES[axis]} >= {c + 0.05:.2f} or {AXES[axis]} <= {c - 0.05:.2f}, whichever holds the tag)"
    return f"{verb} of the plane {_plane(point, normal)}"


def _family_text(scene: Scene, family: dict, report: dict) -> str:
    kind = family["kind"]
    size = _size(family, report)
    if kind == "line":
        line = family["line"]
        text = (
            f"{_antennas(scene, line)} lie on one line: they fix only the position along it and the distance "
            f"from it, so the integer of {_antennas(scene, family['free'])} is free; {size}"
        )
        return text + "; " + _remedies(scene, family, report, f"off the line through {_antennas(scene, line)}")
    if kind == "mirror":
        every = list(range(len(scene.antennas)))
        if scene.dimensions == 3:
            planes = [f["plane"] for f in report["layout"] if f["kind"] == "coplanar" and f["plane"]]
            where = f" ({_plane(*planes[0])})" if planes else ""
            text = f"{_antennas(scene, every)} lie in one plane{where}: the mirror image through it fits every phase; {size}"
        else:
            text = f"{_antennas(scene, every)} lie on one line in the tag's plane: the mirror image across it fits every phase; {size}"
        return text + "; " + _remedies(scene, family, report, "off the plane")
    if kind == "all-antennas":
        text = (
            f"an all-antennas shift (every range + k s) of {_antennas(scene, family['free'])} is matched within "
            f"the noise by moving the tag radially; {size}"
        )
        return text + "; " + _remedies(scene, family, report, "off the others' plane")
    if kind == "too-few-antennas":
        text = (
            f"{len(scene.antennas)} antennas cannot fix a {scene.dimensions}D position: the integer of "
            f"{_antennas(scene, family['free'])} is free; {size}"
        )
        return text + "; " + _remedies(scene, family, report, "")
    text = f"the integers of {_antennas(scene, family['free'])} are free together; {size}"
    return text + "; " + _remedies(scene, family, report, "")


def _layout_text(scene: Scene, finding: dict, tolerance_m: float) -> str:
    antennas = _antennas(scene, finding["antennas"])
    within = f"within {_cm(tolerance_m)}"
    if finding["kind"] == "coincident":
        return f"{antennas} are {within} of each other: together they add no more geometry than one"
    if finding["kind"] == "collinear":
        return f"{antennas} lie {within} of one line (largest offset {finding['deviation_m'] * 1000:.1f} mm)"
    where = f" ({_plane(*finding['plane'])})" if finding["plane"] else ""
    return f"{antennas} lie {within} of one plane{where}; no mirror twin in the region"


def _explained(finding: dict, families: list[dict]) -> bool:
    """Whether a warning already names this layout fact."""
    for family in families:
        if finding["kind"] == "collinear" and family["kind"] == "line" and set(finding["antennas"]) <= set(family["line"]):
            return True
        if finding["kind"] == "coplanar" and family["kind"] == "mirror":
            return True
    return False


def check_scene(scene: Scene, reads: Reads | None = None, *, remedies: bool = True) -> GeometryCheck:
    """Whether the layout of a COTS ``scene`` fixes a tag's position, with
    the frequencies and read counts of ``reads`` when given (a hopping
    recording with calibrated channel offsets is analysed on all its
    calibrated channels together). ``remedies=False`` skips working out the
    antenna offsets (faster). ValueError for a scene the core rejects."""
    if scene.reader.kind != "cots":
        raise ValueError(f"the geometry check is for monostatic reader scenes (kind = 'cots'), not {scene.reader.kind!r}")
    frequencies, evidence = _read_channels(scene, reads)
    report = _core.analyse_scene(_core.Scene(scene), frequencies, evidence, remedies)
    families = report["families"]
    findings = []
    for family in families:
        text = _family_text(scene, family, report)
        if family["warning"]:
            findings.append(Finding("warning", text, family))
        else:
            findings.append(Finding("note", f"weak spot, within the noise only (residual {family['residual_sigma']:.2f} sigma per read): {text}", family))
    warned = [f for f in families if f["warning"]]
    for layout in report["layout"]:
        if layout["kind"] == "coplanar" and scene.dimensions == 2:
            continue  # the tag is in a plane: the antennas' plane has no mirror to offer
        if not _explained(layout, families):
            findings.append(Finding("note", _layout_text(scene, layout, report["layout_tolerance_m"]), layout))
    findings.sort(key=lambda f: f.severity != "warning")
    bounds = (
        f"{report['samples']} region samples, {report['shifts_tried']} shift vectors "
        f"(|n| <= 1 on every antenna combination, <= {report['max_single_shift']} singly and all together), "
        f"chi-square <= {report['sigma_multiple']:g}^2 over {report['evidence_reads']:.0f} reads per antenna and channel "
        f"at each position and its neighbours {_cm(report['persistence_step_m'])} away; {_frequencies(report)}"
    )
    if report["inconclusive"]:
        summary = f"the geometry check is inconclusive: {report['inconclusive']}"
    elif warned:
        summary = f"the layout does not fix a {scene.dimensions}D position everywhere ({len(warned)} twin {'family' if len(warned) == 1 else 'families'}; searched {bounds})"
    else:
        summary = f"the layout fixes a {scene.dimensions}D position: no twin family within {bounds}"
    return GeometryCheck(findings, summary, report)


def twin_positions(scene: Scene, position, frequencies=None, evidence_reads: float | None = None) -> list[tuple[np.ndarray, list[int], float]]:
    """Twins of one tag ``position`` (m): ``[(position, shift per antenna, chi_square)]``,
    nearest first, on ``frequencies`` (Hz, analysed jointly; default one channel)."""
    twins = _core.twin_positions(
        _core.Scene(scene),
        [float(v) for v in np.asarray(position, dtype=float).reshape(3)],
        [float(f) for f in (frequencies or [])],
        evidence_reads,
    )
    return [(np.array(p), list(shift), chi) for p, shift, chi in twins]
