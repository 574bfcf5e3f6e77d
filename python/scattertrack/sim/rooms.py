"""Rooms of static tags: a layout's antennas, tags at random positions in its region.

For the static-tag path (``scattertrack locate``, ``calibrate``): the tags
do not move, so only frequency diversity (hopping) and RSSI can tell where
they are. Positions are uniform in the scenario's region, 10 cm inside it.
"""

from __future__ import annotations

import copy

import numpy as np

from scattertrack.sim.scenario import Simulation, load_scenario, simulate


def static_tags(
    layout: str, count: int, duration_s: float, seed: int, hopping: bool = True, extra_tags: dict | None = None,
    reflectors: list[dict] | None = None,
) -> tuple[Simulation, dict]:
    """``count`` static tags (EPCs ``E200D000``…) in ``layout``'s antennas and region,
    read for ``duration_s``, 50-channel hopping unless ``hopping`` is False;
    ``extra_tags`` (EPC -> position) join them; ``reflectors`` (the
    ``[[reader_model.reflectors]]`` form) are the room's walls, which the
    simulated reads carry and the scene does not declare. Returns the
    simulation and every tag's position (m)."""
    scenario = copy.deepcopy(load_scenario(layout))
    scenario["duration_s"] = float(duration_s)
    if reflectors:
        scenario["reader_model"]["reflectors"] = copy.deepcopy(list(reflectors))
    if hopping:
        scenario["reader_model"]["hopping"] = True
        scenario["reader_model"].pop("frequency_hz", None)
    rng = np.random.default_rng(seed)
    low, high = np.array(scenario["scene"]["region"]["min"], float), np.array(scenario["scene"]["region"]["max"], float)
    positions = {f"E200D{i:03d}": p for i, p in enumerate(rng.uniform(low + 0.1, high - 0.1, size=(count, 3)))}
    positions.update({epc: np.asarray(p, float) for epc, p in (extra_tags or {}).items()})
    scenario["tags"] = [{"epc": epc, "trajectory": {"kind": "static", "position": p.tolist()}} for epc, p in positions.items()]
    return simulate(scenario, seed=seed), positions
