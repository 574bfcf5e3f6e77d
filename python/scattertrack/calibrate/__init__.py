"""Calibration from reference tags: what a reader and its room add to the phase.

:func:`calibrate` ``(scene, reads, references=None, truth=None) -> Calibration``
takes reads of reference tags whose positions are known (static:
``references`` maps an EPC to its position, m; moving: ``truth`` rows
for the EPC). It estimates, from those reads alone:

* the **phase period**: π when no phase reaches π (a mod-π reader), else 2π;
* the **phase sign** s: the one under which the references' phases follow
  their ranges more coherently;
* the **offsets**: per antenna and per channel, identifiable only as their
  sums (:mod:`~scattertrack.calibrate.phase`): the channel offsets are
  stated with circular mean 0 and the antennas carry the rest;
* the **hop table**, when the reads carry channel indices and the scene
  has none (:mod:`~scattertrack.calibrate.hop_table`);
* the **RSSI path loss** per antenna (:mod:`~scattertrack.calibrate.path_loss`);
* the scene's declared **reflectors**, refined: each plane's offset along
  its normal and each coefficient, or left out with a ``warning:`` when the
  references cannot pin them down (:mod:`~scattertrack.calibrate.reflectors`).

It reports the **phase coherence** R of the calibrated model on the
references (1: every phase explained; the same fit on random phases
reaches R₀, also reported) and the residuals per antenna and channel.
When R is not clearly above R₀ (R < max(0.8, 2 R₀)) the phase is not
usable in this room: the result says so, and ``calibrate`` prints a
``warning:`` line. The calibrated scene (:meth:`Calibration.scene`) holds
the estimates and a ``[calibration]`` table stating what was calibrated
and how well.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from scattertrack.calibrate.hop_table import assign_carriers
from scattertrack.calibrate.path_loss import PathLoss, fit_path_loss
from scattertrack.calibrate.phase import chance_coherence, fit_offsets, looks_mod_pi, round_trip_phase
from scattertrack.calibrate.reflectors import (
    DISCOVERY_REACH_M,
    SEARCH_M,
    ReflectorFit,
    discover_walls,
    reference_reads,
    refine_reflectors,
)
from scattertrack.io.hop_table import US_PLAN_HZ
from scattertrack.io.scene import plane_side_problems
from scattertrack.io.types import Reflector
from scattertrack.physics import round_trip_channel
from scattertrack.io.types import ChannelOffset, Reads, Scene, Truth

COHERENCE_USABLE = 0.8
"""Below this phase coherence (or below twice chance), phase is not usable for ranging here."""
ROUNDS = 3
"""Sign/offset fits alternated with the hop-table assignment."""


@dataclass
class Calibration:
    """What :func:`calibrate` found, and how well it explains the references."""

    phase_sign: int
    phase_period: str
    antenna_offsets_rad: dict
    """Antenna id -> offset, radians in [0, P)."""
    channel_offsets_rad: dict
    """Carrier (Hz) -> offset, radians in [0, P)."""
    hop_table_hz: dict
    """Channel index -> carrier (Hz): estimated when the reads have indices and the scene had no table."""
    hop_table_margin: dict
    """Channel index -> its coherence margin over the next-best carrier (> 0: clear)."""
    coherence: float
    chance: float
    """The coherence the same fit reaches on random phases."""
    other_sign_coherence: float
    residual_rad: dict
    """Antenna id -> RMS of its references' phase residuals, radians."""
    channel_residual_rad: dict
    """Carrier (Hz) -> RMS residual, radians."""
    path_loss: dict
    """Antenna id -> :class:`PathLoss` (absent without RSSI)."""
    reads: int
    references: list
    base_scene: Scene = field(repr=False)
    warnings: list = field(default_factory=list)
    reflectors: list[ReflectorFit] = field(default_factory=list)
    """One fit per reflector the scene declared, in its order."""

    @property
    def phase_usable(self) -> bool:
        return self.coherence >= max(COHERENCE_USABLE, 2.0 * self.chance)

    def scene(self) -> Scene:
        """The base scene with every estimate in it, and a ``[calibration]`` table."""
        base = self.base_scene
        antennas = [
            dataclasses.replace(a, phase_offset_rad=float(self.antenna_offsets_rad.get(a.id, a.phase_offset_rad))) for a in base.antennas
        ]
        reader = dataclasses.replace(base.reader, phase_sign=self.phase_sign, phase_period=self.phase_period)
        channels = [ChannelOffset(float(f), float(o)) for f, o in sorted(self.channel_offsets_rad.items())]
        extra = dict(base.extra)
        extra["calibration"] = self.table()
        hop_table = {int(i): float(f) for i, f in sorted(self.hop_table_hz.items())} if self.hop_table_hz else dict(base.hop_table)
        changes = dict(reader=reader, antennas=antennas, channel_offsets=channels, extra=extra, hop_table=hop_table)
        if self.reflectors:
            changes["reflectors"] = [Reflector.from_dict(f.reflector) for f in self.reflectors if f.kept]
        return dataclasses.replace(base, **changes)

    def table(self) -> dict:
        """The ``[calibration]`` table of the calibrated scene (plain TOML values)."""
        table = {
            "references": len(self.references),
            "reads": int(self.reads),
            "phase_coherence": round(float(self.coherence), 4),
            "chance_coherence": round(float(self.chance), 4),
            "phase_usable": bool(self.phase_usable),
            "calibrated": ["phase_sign", "phase_period", "antenna_offsets", "channel_offsets"]
            + (["hop_table"] if self.hop_table_hz else [])
            + (["path_loss"] if self.path_loss else [])
            + (["reflectors"] if self.reflectors else []),
            "antenna_residual_rad": [{"antenna": int(a), "rms": round(float(r), 4)} for a, r in sorted(self.residual_rad.items())],
        }
        if self.reflectors:
            table["reflectors"] = [
                {
                    "reflector": f.index,
                    "kept": f.kept,
                    "discovered": f.discovered,
                    "shift_m": round(f.shift_m, 4),
                    "interval_m": [round(v, 4) for v in f.interval_m],
                    "coefficient": round(f.coefficient, 3),
                    "gain_nats": round(f.gain_nats, 1),
                }
                for f in self.reflectors
            ]
        if self.path_loss:
            table["path_loss"] = [
                {"antenna": int(a), "reference_dbm": round(p.reference_dbm, 3), "exponent": round(p.exponent, 4), "sigma_db": round(p.sigma_db, 3), "fitted_exponent": p.fitted_exponent}
                for a, p in sorted(self.path_loss.items())
            ]
        return table


def reference_positions(reads: Reads, references: dict | None, truth: Truth | None) -> tuple[np.ndarray, np.ndarray]:
    """(mask of the reads of reference tags, their positions (n, 3) m):
    static positions from ``references``, moving ones interpolated from
    ``truth`` within its time span."""
    references = references or {}
    epc = np.asarray(reads.epc).astype(str)
    mask = np.zeros(len(reads), dtype=bool)
    positions = np.full((len(reads), 3), np.nan)
    for name, position in references.items():
        rows = epc == name
        mask |= rows
        positions[rows] = np.asarray(position, dtype=np.float64)
    if truth is not None:
        truth_epc = np.asarray(truth.epc).astype(str)
        for name in np.unique(truth_epc):
            if name in references:
                continue
            sel = truth_epc == name
            t, p = np.asarray(truth.time_s)[sel], np.asarray(truth.position)[sel]
            order = np.argsort(t)
            t, p = t[order], p[order]
            rows = (epc == name) & (reads.time_s >= t[0]) & (reads.time_s <= t[-1])
            mask |= rows
            positions[rows] = np.column_stack([np.interp(reads.time_s[rows], t, p[:, k]) for k in range(3)])
    return mask, positions


def _indices(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    keys, index = np.unique(values, return_inverse=True)
    return keys, index


def calibrate(
    scene: Scene,
    reads: Reads,
    references: dict | None = None,
    truth: Truth | None = None,
    reflector_search_m: float = SEARCH_M,
    find_walls: bool = False,
    wall_reach_m: float = DISCOVERY_REACH_M,
) -> Calibration:
    """Calibrate ``scene`` from the reads of reference tags (see the module docstring).

    ``reflector_search_m``: how far (m) from where the scene declares a
    plane reflector its refined offset may be. ``find_walls``: also look
    for walls nobody declared, parallel to the region's faces and up to
    ``wall_reach_m`` beyond the region and the antennas
    (:func:`~scattertrack.calibrate.reflectors.discover_walls`; needs a
    region).

    Raises ValueError when no read belongs to a reference, or the references
    were read by fewer than one antenna."""
    mask, positions = reference_positions(reads, references, truth)
    if not mask.any():
        raise ValueError("no read belongs to a reference tag (check the EPCs given and the truth's)")
    antenna_ids = {a.id: a for a in scene.antennas}
    ref = np.flatnonzero(mask & np.isin(reads.antenna, list(antenna_ids)))
    antenna_id = np.asarray(reads.antenna)[ref]
    anchor = np.array([antenna_ids[int(a)].position for a in antenna_id])
    distance = np.linalg.norm(positions[ref] - anchor, axis=1)
    phase = np.asarray(reads.phase_rad, dtype=np.float64)[ref]
    frequency = np.asarray(reads.frequency_hz, dtype=np.float64)[ref]
    channel_index = reads.channel_index
    hop_known = dict(scene.hop_table)
    estimate_hops = channel_index is not None and np.all(np.asarray(channel_index)[ref] >= 0) and not hop_known
    if channel_index is not None and hop_known and np.all(np.asarray(channel_index)[ref] >= 0):
        frequency = np.array([hop_known.get(int(c), f) for c, f in zip(np.asarray(channel_index)[ref], frequency)])
    channel_keys, channel = _indices(np.asarray(channel_index)[ref] if estimate_hops else np.rint(frequency).astype(np.int64))
    antenna_keys, antenna = _indices(antenna_id)
    tag_keys, tag = _indices(np.asarray(reads.epc).astype(str)[ref])
    counts = (len(antenna_keys), len(channel_keys), len(tag_keys))
    period = "pi" if looks_mod_pi(phase) else ("pi" if scene.reader.phase_period == "pi" and len(phase) < 50 else "2pi")
    m = 2 if period == "pi" else 1
    warnings = []
    if estimate_hops:
        # Start from the band's centre for every index; the channel offsets absorb the rest for now.
        frequency = np.full(len(ref), float(np.mean(US_PLAN_HZ)))
    margins = {}
    for round_ in range(ROUNDS if estimate_hops else 1):
        fits = {}
        for sign in (1, -1):
            fits[sign] = fit_offsets(m * (phase - sign * round_trip_phase(frequency, distance)), antenna, channel, tag, counts)
        sign = 1 if fits[1].coherence >= fits[-1].coherence else -1
        fit, other = fits[sign], fits[-sign]
        if estimate_hops:
            known = fit.antenna[antenna] + fit.tag[tag]
            hops = assign_carriers(phase, distance, channel, counts[1], known, sign, m, US_PLAN_HZ)
            frequency = hops.frequency_hz[channel]
            margins = {int(k): float(v) for k, v in zip(channel_keys, hops.margin)}
    if estimate_hops:
        fit = fit_offsets(m * (phase - sign * round_trip_phase(frequency, distance)), antenna, channel, tag, counts)
        other = fit_offsets(m * (phase + sign * round_trip_phase(frequency, distance)), antenna, channel, tag, counts)
        unclear = [k for k, v in margins.items() if v <= 0.0]
        if unclear:
            warnings.append(
                f"the references cannot tell {len(unclear)} of {len(margins)} channel indices from a neighbouring carrier "
                f"(e.g. index {unclear[0]}): spread the reference tags over a few metres of range, or move one along a known path"
            )
    declared = list(scene.reflectors)
    reflector_fits = []
    if declared or find_walls:
        walls_from = reference_reads(phase, frequency, anchor, positions[ref], antenna, channel, tag, counts, sign, m)
    if declared:
        reflector_fits = refine_reflectors(declared, walls_from, reflector_search_m)
    if find_walls:
        if scene.region is None:
            raise ValueError("finding walls needs the scene's [region]: walls are looked for beyond it")
        known = [f.reflector for f in reflector_fits if f.kept]
        antenna_positions = np.array([a.position for a in scene.antennas], dtype=np.float64)
        reflector_fits += discover_walls(
            known, (scene.region.min, scene.region.max), antenna_positions, walls_from, wall_reach_m, first_index=len(declared)
        )
    if reflector_fits:
        kept = [f.reflector for f in reflector_fits if f.kept]
        for f in reflector_fits:
            if not f.kept:
                warnings.append(f"reflector {f.index} ({f.kind}) left out of the calibrated scene: {f.reason}")
            elif f.kind == "plane":
                # A refined plane can have moved across an antenna: say so now, not when the scene is read back.
                for problem in plane_side_problems(f.reflector["point"], f.reflector["normal"], scene.antennas):
                    warnings.append(f"reflector {f.index} (plane) as refined: {problem}")
        if kept:
            _, excess, _ = round_trip_channel(anchor, positions[ref], frequency, kept)
            geometric = round_trip_phase(frequency, distance) + excess
            fit = fit_offsets(m * (phase - sign * geometric), antenna, channel, tag, counts)
            other = fit_offsets(m * (phase + sign * geometric), antenna, channel, tag, counts)
    chance = chance_coherence(antenna, channel, tag, counts)
    period_rad = math.pi if period == "pi" else 2.0 * math.pi
    to_phase = lambda theta: float(np.mod(theta / m, period_rad))  # noqa: E731 - the m-circle back to reported phase
    carrier_of_channel = {}
    for c in range(counts[1]):
        carrier_of_channel[c] = float(np.median(frequency[channel == c]))
    residual = fit.residual / m
    calibration = Calibration(
        phase_sign=sign,
        phase_period=period,
        antenna_offsets_rad={int(a): to_phase(fit.antenna[i]) for i, a in enumerate(antenna_keys)},
        channel_offsets_rad={carrier_of_channel[c]: to_phase(fit.channel[c]) for c in range(counts[1])} if counts[1] > 1 else {},
        hop_table_hz={int(k): carrier_of_channel[c] for c, k in enumerate(channel_keys)} if estimate_hops else {},
        hop_table_margin=margins,
        coherence=fit.coherence,
        chance=chance,
        other_sign_coherence=other.coherence,
        residual_rad={int(a): float(np.sqrt(np.mean(residual[antenna == i] ** 2))) for i, a in enumerate(antenna_keys)},
        channel_residual_rad={carrier_of_channel[c]: float(np.sqrt(np.mean(residual[channel == c] ** 2))) for c in range(counts[1])},
        path_loss={},
        reads=len(ref),
        references=[str(t) for t in tag_keys],
        base_scene=scene,
        warnings=warnings,
        reflectors=reflector_fits,
    )
    if counts[1] == 1:
        # One channel: its offset and the antennas' are one sum; the antennas carry it.
        calibration.antenna_offsets_rad = {
            int(a): to_phase(fit.antenna[i] + fit.channel[0]) for i, a in enumerate(antenna_keys)
        }
    rssi = np.asarray(reads.rssi_dbm, dtype=np.float64)[ref]
    for i, a in enumerate(antenna_keys):
        loss = fit_path_loss(rssi[antenna == i], distance[antenna == i])
        if loss is not None:
            calibration.path_loss[int(a)] = loss
    if not calibration.phase_usable:
        calibration.warnings.append(
            f"phase is not usable in this room: the calibrated model explains the references' phases with coherence "
            f"{calibration.coherence:.2f} (random phases reach {calibration.chance:.2f}; usable needs >= {max(COHERENCE_USABLE, 2 * calibration.chance):.2f}): "
            "multipath, tag orientation or reference positions off; track and locate should rely on RSSI here"
        )
    if abs(calibration.coherence - calibration.other_sign_coherence) < 0.05 and calibration.phase_usable:
        calibration.warnings.append(
            f"the phase sign is barely decided (coherence {calibration.coherence:.2f} against {calibration.other_sign_coherence:.2f} "
            "for the other sign): the references' ranges vary too little; move a reference tag or add one"
        )
    return calibration


__all__ = ["Calibration", "PathLoss", "calibrate", "reference_positions"]
