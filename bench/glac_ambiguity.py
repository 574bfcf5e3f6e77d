"""Is "the correct candidate wins within 1 s" reachable? A batch smoother's verdict.

For every seeded run of a GLAC scenario this takes the wrong candidate
trajectories GLAC holds half a second after motion starts and at the deadline
(``--within-s`` after it) and asks a non-causal question no tracker can
beat: with *all* reads up to motion start + ``within_s`` in hand, how much
better does the best smooth trajectory through the truth explain them than
the best smooth trajectory through the wrong candidate?

Both are fitted the same way, a cubic B-spline position p(t) (knots every
``knot_s``) minimising

    Σ_reads (wrap(φ − φ_model(p(t))) / σφ)²  +  ∫ |p''(t)|² dt / q

(the first term is −2 log-likelihood of the phases, wrapped to the reader's
period; the second a white-acceleration prior of intensity q, m²/s³), one
started from the truth, one from the truth shifted by GLAC's error. The
difference Δ = cost(wrong) − cost(truth) is twice the log-likelihood ratio in
favour of the truth. When Δ is small (default < 3, a ratio below e^1.5 ≈ 4.5)
the reads up to that time cannot tell the two trajectories apart: any
tracker, causal or not, picks the wrong one in a good share of such runs.

A fit from a shifted start finds a wrong trajectory at best as good as the
best one, and GLAC proposes the candidates, so the count of indistinguishable
runs is a lower bound. A wrong trajectory that leaves the scene's region
(by more than GLAC's ``region_margin_m``, 5 cm) is not counted: the scene
rules it out for every tracker, as it does for GLAC.

    .venv/bin/python bench/glac_ambiguity.py --scenario glac-3d-arm --seeds 100
    .venv/bin/python bench/glac_ambiguity.py --cell bay/multipath --seeds 20 --first-seed 1000

A cell of ``bench/glac_robustness.py`` (``--cell LAYOUT/CONDITION``) asks
the same of its impairment: under multipath, whether the reads themselves
favour the wrong trajectories the track leaves for (the fits model white
phase noise only, as the tracker's likelihood models no reflection).
"""

from __future__ import annotations

import argparse
import sys
import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import BSpline, make_lsq_spline
from scipy.optimize import least_squares

from scattertrack import track as st_track
from scattertrack.io.types import SPEED_OF_LIGHT, Reflector
from scattertrack.sim import load_scenario, simulate
from scattertrack.physics import round_trip_channel


def _bench(name: str):
    """bench/<name>.py as a module under a name that cannot clash
    (``bench_modules.load``): ``run`` for its ``score``, ``glac_robustness``
    for its cells."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_modules

    return bench_modules.load(name)


@dataclass
class Fit:
    """A smoothed trajectory and what it costs (dimensionless, −2 log-likelihood)."""

    spline: BSpline
    data_cost: float
    prior_cost: float

    @property
    def cost(self) -> float:
        return self.data_cost + self.prior_cost


def motion_start_s(truth, speed_m_s: float = 0.01) -> float:
    """First truth time the tag moves faster than ``speed_m_s`` (as the evaluation counts it), s."""
    speed = np.linalg.norm(truth.velocity, axis=1)
    moving = np.flatnonzero(speed > speed_m_s)
    return float(truth.time_s[moving[0]]) if moving.size else float(truth.time_s[0])


def fit_trajectory(scene, reads, t0: float, t1: float, start, q: float, knot_s: float = 0.15, reflectors=None) -> Fit:
    """Best smooth trajectory over the reads in [t0, t1] near ``start``.

    ``start(t)`` gives (n, 3) positions, m, to start from. Phases follow
    docs/formats.md §1: φ = sign·4π d/λ + θ_antenna + θ_channel (mod the reader's
    period); residuals are wrapped to ±period/2, so the fit stays on the
    candidate trajectory it starts on. 2D scenes keep z at the plane.
    ``reflectors`` (the simulator's ``reader_model.reflectors``): the model
    phase also carries their multipath excess, sign·excess (what a
    likelihood that knew the walls would predict); None: a single path.
    """
    m = (reads.time_s >= t0) & (reads.time_s <= t1)
    t = reads.time_s[m]
    antenna_index = {a.id: i for i, a in enumerate(scene.antennas)}
    idx = np.array([antenna_index[int(a)] for a in reads.antenna[m]])
    anchors = np.array([a.position for a in scene.antennas])[idx]
    offsets = np.array([a.phase_offset_rad for a in scene.antennas])[idx]
    offsets = offsets + np.array([scene.channel_offset(f) for f in reads.frequency_hz[m]])
    wavelength = SPEED_OF_LIGHT / reads.frequency_hz[m]
    phase = reads.phase_rad[m]
    period = scene.reader.period_rad
    sign = scene.reader.phase_sign
    sigma = scene.reader.phase_noise_rad
    axes = 2 if scene.dimensions == 2 else 3
    plane_z = scene.plane_z if scene.plane_z is not None else 0.0
    k = 3
    knots = np.r_[[t0] * k, np.arange(t0, t1, knot_s), [t1] * (k + 1)]
    n_coef = len(knots) - k - 1
    # The prior ∫|p''|² dt / q by the rectangle rule on a fine grid.
    grid = np.linspace(t0, t1, 80)
    prior_weight = np.sqrt((t1 - t0) / len(grid) / q)

    def spline(c):
        coef = c.reshape(n_coef, axes)
        if axes == 2:
            coef = np.column_stack([coef, np.full(n_coef, plane_z)])
        return BSpline(knots, coef, k)

    def residuals(c):
        p = spline(c)
        positions = p(t)
        d = np.linalg.norm(positions - anchors, axis=1)
        model = sign * 4.0 * np.pi * d / wavelength + offsets
        if reflectors:
            _, excess, _ = round_trip_channel(anchors, positions, reads.frequency_hz[m], reflectors)
            model = model + sign * excess
        e = phase - model
        e = (e + period / 2) % period - period / 2
        acc = p.derivative(2)(grid)[:, :axes]
        return np.r_[e / sigma, (acc * prior_weight).ravel()]

    dense = np.linspace(t0, t1, 400)
    c0 = make_lsq_spline(dense, np.asarray(start(dense))[:, :axes], knots, k).c.ravel()
    solution = least_squares(residuals, c0, x_scale=0.01)
    r = solution.fun
    return Fit(spline(solution.x), float(np.sum(r[: len(t)] ** 2)), float(np.sum(r[len(t) :] ** 2)))


REGION_MARGIN_M = float(st_track.default_params("glac")["region_margin_m"])
"""GLAC's ``region_margin_m`` (its default): how far outside the scene's region a hypothesis may stray, m."""


def inside_region(scene, fit: Fit, times) -> bool:
    """Whether the fitted trajectory stays within the scene's region (grown by
    :data:`REGION_MARGIN_M`) at ``times``; True without a region."""
    region = scene.region
    if region is None:
        return True
    p = fit.spline(np.asarray(times, dtype=float))
    axes = 2 if scene.dimensions == 2 else 3
    low = np.asarray(region.min, dtype=float)[:axes] - REGION_MARGIN_M
    high = np.asarray(region.max, dtype=float)[:axes] + REGION_MARGIN_M
    return bool(np.all((p[:, :axes] >= low) & (p[:, :axes] <= high)))


def truth_at(truth, times) -> np.ndarray:
    """Truth positions at ``times`` (linear interpolation), (n, 3) m."""
    return np.column_stack([np.interp(times, truth.time_s, truth.position[:, j]) for j in range(3)])


def follow(scene, reads, t0: float, ends, start, q: float, reflectors=None) -> Fit:
    """fit_trajectory over growing windows [t0, end] for each end in turn,
    each started from the previous fit (held before, extrapolated at its last
    velocity after): a wrong candidate drifts relative to the truth, and a
    fit started from one shift over the whole span would lose it."""
    fit = fit_trajectory(scene, reads, t0, ends[0], start, q, reflectors=reflectors)
    for end in ends[1:]:
        previous = fit.spline
        last = float(previous.t[-1])
        velocity = previous.derivative(1)(last)

        def extended(t, previous=previous, last=last, velocity=velocity):
            t = np.asarray(t, dtype=float)
            inside = previous(np.minimum(t, last))
            return np.where((t > last)[:, None], previous(last) + np.outer(t - last, velocity), inside)

        fit = fit_trajectory(scene, reads, t0, end, extended, q, reflectors=reflectors)
    return fit


def live_candidates(sim, until_s: float, wrong_m: float = 0.05, most: int = 8) -> list[np.ndarray]:
    """GLAC's live wrong candidates at ``until_s``: positions (m) of the
    hypotheses more than ``wrong_m`` from the truth, likeliest first (at most
    ``most``). Only proposals: the verdict comes from the fits."""
    tracker = st_track.make("glac", sim.scene)
    reads = sim.reads
    order = np.argsort(reads.time_s, kind="stable")
    epc = None
    for i in order:
        if reads.time_s[i] > until_s:
            break
        epc = reads.epc[i]
        tracker.step(reads.time_s[i], epc, int(reads.antenna[i]), reads.frequency_hz[i], reads.phase_rad[i])
    if epc is None:
        return []
    here = truth_at(sim.truth, [until_s])[0]
    ranked = sorted(tracker.hypotheses(epc), key=lambda h: -h[1])
    return [p for p, _ in ranked if np.linalg.norm(p - here) > wrong_m][:most]


def verdict(sim, within_s: float = 1.0, q: float = 0.05, proposal_s=(0.5,), reflectors=None) -> dict | None:
    """The smoother's verdict on one run: of the wrong candidates GLAC holds
    at each of ``proposal_s`` after motion starts and at the deadline, the
    one that comes closest to explaining the reads up to the deadline as well
    as the truth. None when GLAC holds no wrong candidate at those times."""
    start = motion_start_s(sim.truth)
    deadline = start + within_s
    t0 = float(sim.reads.time_s.min())
    truth_fit = fit_trajectory(sim.scene, sim.reads, t0, deadline, lambda t: truth_at(sim.truth, t), q, reflectors=reflectors)
    best, proposed = None, 0
    for after_s in sorted({*(s for s in proposal_s if s < within_s), within_s}):
        proposed_at = start + after_s
        there = truth_at(sim.truth, [proposed_at])[0]
        ends = sorted({*np.arange(proposed_at, deadline, 0.25), deadline})
        for p in live_candidates(sim, proposed_at):
            proposed += 1
            # Start from the truth shifted onto the candidate, then follow it.
            shift = p - there
            fit = follow(sim.scene, sim.reads, t0, ends, lambda t, s=shift: truth_at(sim.truth, t) + s, q, reflectors=reflectors)
            if not inside_region(sim.scene, fit, np.linspace(t0, deadline, 50)):
                continue  # the scene's region rules this trajectory out
            if best is None or fit.cost < best.cost:
                best = fit
    if best is None:
        return None
    here = truth_at(sim.truth, [deadline])[0]
    return {
        "reads": int(np.sum((sim.reads.time_s >= t0) & (sim.reads.time_s <= deadline))),
        "candidates": proposed,
        "cost_truth": truth_fit.cost,
        "cost_wrong": best.cost,
        "delta": best.cost - truth_fit.cost,
        "apart_m": float(np.linalg.norm(best.spline(deadline) - here)),
    }


def excursion_verdicts(
    sim, track, after_s: float, q: float, wrong_m: float = 0.05, window_s: float = 1.0, propose=None, reflectors=None
) -> list[dict]:
    """The smoother's verdict on each excursion of the reported track after
    ``after_s`` (absolute, s): rows more than ``wrong_m`` from the truth once
    the track had been on it. At the excursion's first row, the reads of the
    last ``window_s`` are fitted once from the truth and once from each of
    GLAC's wrong candidates then. A wrong branch that leaves the truth only
    just before starts from the truth and ramps onto the candidate over the
    last 0.1 or 0.2 s; a candidate that has competed all along starts from
    the truth shifted onto it over the whole window. A fit that slides back
    onto the truth, or leaves the region, does not count. Δ < 3 means the
    reads so far favour neither: a causal tracker cannot avoid the excursion
    (a smoother, with later reads, can). ``propose(sim, t, wrong_m)`` gives the candidates (default: GLAC's,
    :func:`live_candidates`)."""
    propose = propose or live_candidates
    errors = np.linalg.norm(track.position - truth_at(sim.truth, track.time_s), axis=1)
    wrong = errors > wrong_m
    starts = np.flatnonzero(wrong[1:] & ~wrong[:-1]) + 1
    verdicts = []
    for first in starts[track.time_s[starts] > after_s]:
        te = float(track.time_s[first])
        rows = int(np.argmin(wrong[first:])) if not wrong[first:].all() else len(wrong) - first
        t0 = te - window_s
        truth_fit = fit_trajectory(sim.scene, sim.reads, t0, te, lambda t: truth_at(sim.truth, t), q, reflectors=reflectors)
        here = truth_at(sim.truth, [te])[0]
        best = None
        for p in propose(sim, te, wrong_m):
            # None: the candidate has competed all along (the truth shifted
            # onto it over the whole window), not just branched off.
            for ramp_s in (0.1, 0.2, None):

                def start(t, shift=p - here, ramp_s=ramp_s):
                    if ramp_s is None:
                        return truth_at(sim.truth, t) + shift
                    weight = np.clip((np.asarray(t) - (te - ramp_s)) / ramp_s, 0.0, 1.0)
                    return truth_at(sim.truth, t) + weight[:, None] * shift

                fit = fit_trajectory(sim.scene, sim.reads, t0, te, start, q, reflectors=reflectors)
                if np.linalg.norm(fit.spline(te) - here) <= wrong_m:
                    continue  # the fit slid back onto the truth: not a distinct trajectory
                if not inside_region(sim.scene, fit, np.linspace(t0, te, 50)):
                    continue  # the scene's region rules this trajectory out
                best = fit.cost if best is None else min(best, fit.cost)
        verdicts.append(
            {
                "time_s": te,
                "rows": rows,
                "max_error_m": float(errors[first : first + max(rows, 1)].max()),
                "delta": (best - truth_fit.cost) if best is not None else float("inf"),
            }
        )
    return verdicts


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="glac-3d-arm")
    parser.add_argument(
        "--cell",
        metavar="LAYOUT/CONDITION",
        help="instead of --scenario, a cell of bench/glac_robustness.py (e.g. bay/multipath)",
    )
    parser.add_argument("--seeds", type=int, default=20, help="number of seeds (default 20)")
    parser.add_argument("--first-seed", type=int, default=0, help="first seed (default 0; layouts were compared on 1000+)")
    parser.add_argument(
        "--antenna",
        action="append",
        default=[],
        metavar="ID,X,Y,Z",
        help="move antenna ID to (X, Y, Z) m before simulating (repeatable): try a layout before mounting it",
    )
    parser.add_argument(
        "--model-reflectors",
        action="store_true",
        help="the fits model the scenario's reflectors (its reader_model.reflectors) and the tracker is told of them: would a likelihood that knew the walls tell the trajectories apart?",
    )
    parser.add_argument(
        "--reflector-shift-m",
        type=float,
        default=0.0,
        metavar="M",
        help="with --model-reflectors, move each plane this far along its normal in the model (a wall known to M metres)",
    )
    parser.add_argument("--within-s", type=float, default=1.0, help="deadline after motion starts, s (default 1)")
    parser.add_argument("--q", type=float, default=0.05, help="smoothness prior, m²/s³ (default 0.05)")
    parser.add_argument("--threshold", type=float, default=3.0, help="Δ below which two trajectories are indistinguishable")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    late = late_indistinguishable = indistinguishable = 0
    excursions = unavoidable = 0
    bench_run = _bench("run")
    if args.cell:
        layout, _, condition = args.cell.partition("/")
        robustness = _bench("glac_robustness")
        if layout not in robustness.LAYOUTS or condition not in robustness.CONDITIONS:
            raise SystemExit(
                f"unknown cell {args.cell!r}; layouts {', '.join(robustness.LAYOUTS)}, "
                f"conditions {', '.join(robustness.CONDITIONS)}"
            )
        scenario = robustness.cell_scenario(layout, condition)
        args.scenario = args.cell
    else:
        scenario = load_scenario(args.scenario)
    if len(scenario.get("tags", [])) > 1:
        # The fits compare one tag's reads with one truth trajectory.
        raise SystemExit(f"{args.scenario}: {len(scenario['tags'])} tags; this check takes one-tag scenarios")
    for spec in args.antenna:
        ident, *xyz = spec.split(",")
        for antenna in scenario["scene"]["antennas"]:
            if antenna["id"] == int(ident):
                antenna["position"] = [float(v) for v in xyz]
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    reflectors = None
    if args.model_reflectors:
        reflectors = [dict(r) for r in scenario.get("reader_model", {}).get("reflectors", [])]
        if not reflectors:
            raise SystemExit(f"{args.scenario}: no reflectors to model")
        for r in reflectors:
            if r["kind"] == "plane":
                normal = np.asarray(r["normal"], float)
                r["point"] = list(np.asarray(r["point"], float) + args.reflector_shift_m * normal / np.linalg.norm(normal))
    for seed in seeds:
        sim = simulate(scenario, seed=seed)
        scene = sim.scene
        if reflectors is not None:
            # The tracker is told of the same walls as the fits: its excursions are then those of a
            # tracker that models them.
            scene = dataclasses.replace(scene, reflectors=[Reflector.from_dict(r) for r in reflectors])
        track = st_track.run("glac", scene, sim.reads)
        wins_s = bench_run.score(sim, track)["candidate_wins_s"]
        is_late = not (np.isfinite(wins_s) and wins_s <= args.within_s)
        late += is_late
        if is_late:
            deadline = motion_start_s(sim.truth) + args.within_s
            for e in excursion_verdicts(sim, track, deadline, args.q, reflectors=reflectors):
                excursions += 1
                unavoidable += e["delta"] < args.threshold
                print(
                    f"seed {seed:3d}: excursion at {e['time_s']:6.2f} s, {e['rows']} rows, up to "
                    f"{e['max_error_m'] * 100:5.1f} cm; reads so far: Δ {e['delta']:7.1f}"
                    f"{'  indistinguishable' if e['delta'] < args.threshold else ''}",
                    flush=True,
                )
        v = verdict(sim, args.within_s, args.q, reflectors=reflectors)
        if v is None:
            continue
        same = v["delta"] < args.threshold
        indistinguishable += same
        late_indistinguishable += same and is_late
        if is_late or same:
            print(
                f"seed {seed:3d}: wins at {wins_s:5.2f} s; {v['candidates']} wrong candidates tried, the closest call "
                f"{v['apart_m'] * 100:5.1f} cm away; {v['reads']} reads; cost truth {v['cost_truth']:6.1f}, "
                f"wrong {v['cost_wrong']:8.1f}, Δ {v['delta']:8.1f}{'  indistinguishable' if same else ''}",
                flush=True,
            )
    print(
        f"{args.scenario}{' with ' + ' '.join(args.antenna) if args.antenna else ''}, seeds {seeds[0]}-{seeds[-1]}, q = {args.q:g} m²/s³: the correct candidate wins within "
        f"{args.within_s:g} s of motion in {args.seeds - late}/{args.seeds} runs. In {indistinguishable}/{args.seeds} "
        f"runs ({late_indistinguishable} of the {late} late ones) a wrong trajectory explains every read up to the "
        f"deadline about as well as the truth or better (Δ < {args.threshold:g}): no tracker, causal or not, can be sure of "
        f"the right one there."
    )
    if excursions:
        print(
            f"Late runs also left the truth after the deadline {excursions} times; at {unavoidable} of these "
            f"excursions a wrong branch explains the reads so far about as well as the truth or better (Δ < {args.threshold:g}): "
            f"a causal tracker cannot avoid them."
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
