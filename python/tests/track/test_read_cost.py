"""GLAC's per-read work budget (issue 21): the engine's counters show that no
read expands more than ``read_budget`` hypotheses and initial candidates,
mod-π 3D included, and that the work is carried, not dropped. Counts, not
times: the bound does not depend on the machine's speed."""

import copy

import numpy as np
import pytest

from scattertrack.sim import load_scenario, simulate
from scattertrack.track import default_params, run


def _mod_pi(name, duration_s):
    scenario = copy.deepcopy(load_scenario(name)) | {"duration_s": duration_s}
    scenario["scene"]["reader"]["phase_period"] = "pi"
    return simulate(scenario, seed=7101)


@pytest.mark.parametrize("name", ["glac-2d-40cms-modpi", "glac-3d-arm"])
def test_no_read_expands_more_than_the_budget(name):
    sim = _mod_pi(name, 8.0)
    budget = 1_000
    bounded = run("glac", sim.scene, sim.reads, read_budget=budget)
    free = run("glac", sim.scene, sim.reads, read_budget=10**12)
    epc = next(iter(bounded.stats))
    assert 0 < bounded.stats[epc]["max_expanded_per_read"] <= budget
    # Unlimited, the search or a replay takes more than a budget in one read.
    assert free.stats[epc]["max_expanded_per_read"] > budget
    # The work is carried, not dropped: the tracker commits, catches up and
    # reports most reads (fewer than unlimited: none while work is queued).
    assert 0.3 * len(free) < len(bounded) <= len(free)
    late = bounded.time_s > 6.0
    assert late.any() and np.isin(bounded.time_s[late], free.time_s).all()


def test_read_budget_is_a_parameter():
    assert default_params("glac")["read_budget"] == 2_000
    with pytest.raises(ValueError, match="read_budget"):
        run("glac", _mod_pi("glac-2d-40cms-modpi", 1.0).scene, _mod_pi("glac-2d-40cms-modpi", 1.0).reads, read_budget=0)


def test_offline_runs_do_deferred_work_at_once():
    """``run`` (offline) leaves ``read_budget`` unbounded unless it is given;
    a tracker stepped read by read (``make``, as live input is) keeps the
    table's default, and its mod-π 3D tag reports later."""
    from scattertrack.track import make, parameters

    assert parameters.offline("glac", {})["read_budget"] == parameters.OFFLINE_READ_BUDGET
    assert parameters.offline("glac", {"read_budget": 500}) == {"read_budget": 500}
    assert "read_budget" not in parameters.offline("turbotrack", {})
    sim = _mod_pi("glac-3d-arm", 4.0)
    offline = run("glac", sim.scene, sim.reads)
    epc = next(iter(offline.stats))
    assert offline.stats[epc]["max_expanded_per_read"] > default_params("glac")["read_budget"]
    tracker = make("glac", sim.scene)
    r = sim.reads
    stepped = [t for t, e, a, f, p in zip(r.time_s, r.epc, r.antenna, r.frequency_hz, r.phase_rad)
               if tracker.step_read(t, e, int(a), f, p) is not None]
    assert len(offline) and (not stepped or stepped[0] > offline.time_s[0])
