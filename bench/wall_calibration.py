"""The walls a user would give GLAC: ``scattertrack calibrate`` on a reference sweep in the same room.

A scenario with a wall (``[[reader_model.reflectors]]``, hidden from the
tracker) gets a calibration recording of its own: the same scene, reader
and room, and instead of its tags one reference tag carried along a known
random path through the scene's region (a robot can sweep a reference tag
along a path it knows) for ``SWEEP_S``. Its scene declares each wall as a
tape measure would: ``DECLARED_OFFSET_M`` from where it is, towards the
antennas, with coefficient ``DECLARED_COEFFICIENT`` of the right sign.
``calibrate`` refines them (or leaves them out); the tracked recording's
scene then gets the walls it kept, and nothing else from the calibration:
the simulator draws each seed's antenna and channel offsets afresh, which
on real hardware would be the same.

Used by ``bench/glac_robustness.py`` (the ``multipath-calibrated`` cells and
realistic-3d-arm with its wall calibrated).
"""

from __future__ import annotations

import copy

import numpy as np

from scattertrack.calibrate import calibrate
from scattertrack.io.types import Reflector
from scattertrack.sim import simulate

SWEEP_S = 60.0
"""Length of the calibration sweep, s."""
SWEEP_SPEED_M_S = 0.2
"""Mean speed of the reference tag on its random path, m/s."""
DECLARED_OFFSET_M = 0.04
"""How far from the true plane the scene declares each wall (towards the antennas), m."""
DECLARED_COEFFICIENT = 0.5
"""The declared coefficient's magnitude (the sign is the true one)."""
SEED_OFFSET = 700_000
"""The calibration recording of seed s is simulated with seed s + SEED_OFFSET."""
REFERENCE_EPC = "CA11B000"


def declared(wall: dict) -> dict:
    """A wall as a tape measure states it: moved DECLARED_OFFSET_M along its normal, coefficient DECLARED_COEFFICIENT."""
    normal = np.asarray(wall["normal"], dtype=float)
    normal = normal / np.linalg.norm(normal)
    return {
        "kind": "plane",
        "point": list(np.asarray(wall["point"], dtype=float) + DECLARED_OFFSET_M * normal),
        "normal": list(normal),
        "coefficient": float(np.sign(wall["coefficient"]) * DECLARED_COEFFICIENT),
    }


def calibration_scenario(scenario: dict) -> dict:
    """The reference sweep in ``scenario``'s room (its planes declared in the scene, as a tape measure would)."""
    sweep = copy.deepcopy(scenario)
    walls = [r for r in sweep["reader_model"].get("reflectors", []) if r["kind"] == "plane"]
    sweep["scene"]["reflectors"] = [declared(w) for w in walls]
    region = sweep["scene"]["region"]
    sweep["duration_s"] = SWEEP_S
    sweep["tags"] = [
        {
            "epc": REFERENCE_EPC,
            "trajectory": {"kind": "random", "box_min": list(region["min"]), "box_max": list(region["max"]), "mean_speed": SWEEP_SPEED_M_S},
        }
    ]
    sweep["name"] = f"{scenario.get('name', 'scenario')}+wall-calibration"
    # A dropout window of the tracked recording (the dropout cell's) is not the sweep's.
    sweep["reader_model"].pop("dropout_windows", None)
    return sweep


def calibrated_walls(scenario: dict, seed: int):
    """(the reflectors calibrate kept, its ReflectorFit list) for ``scenario``'s room, sweep seed ``seed + SEED_OFFSET``."""
    sim = simulate(calibration_scenario(scenario), seed=seed + SEED_OFFSET)
    result = calibrate(sim.scene, sim.reads, truth=sim.truth)
    kept = [Reflector.from_dict(f.reflector) for f in result.reflectors if f.kept]
    return kept, result.reflectors


def with_walls(scene, walls: list):
    """``scene`` with ``walls`` as its reflectors, marked as calibrated (a copy)."""
    scene = copy.deepcopy(scene)
    scene.reflectors = list(walls)
    table = dict(scene.extra.get("calibration") or {})
    table["calibrated"] = sorted(set(table.get("calibrated", [])) | {"reflectors"})
    table["reflectors"] = [{"reflector": i, "kept": True} for i in range(len(walls))]
    scene.extra["calibration"] = table
    return scene
