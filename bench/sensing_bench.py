"""Marvel benchmark, block 2: the pose sensing on IQ-level simulations (paper sec. V-B, Figs. 9-11).

Imported by ``bench/marvel.py`` (``sensing_block``, ``print_sensing``); it can
also run on its own: ``.venv/bin/python bench/sensing_bench.py [--seeds N]``.

Every point simulates the controller's LoRa recording of a short flight
(:func:`scattertrack.sim.marvel.simulate_marvel_iq`) and runs the pose
sensing with the fusion alongside (:func:`scattertrack.track.marvel.run_sigmf`),
everything at its defaults (chosen on seeds >= 1000; these scoring runs use
seeds ``0 .. min(N, 3) - 1``). Scores:

- **snapshot position error** of each sensed epoch against the truth,
  relative to the TRUE controller: ``|r u - (p - rho)|`` with the sensed
  range ``r`` and direction ``u`` of the body origin, the true body origin
  ``p`` at the epoch's time and the true controller ``rho`` — what the
  paper's Figs. 9-10 plot (one epoch's sensing, no fusion, no controller
  estimate);
- the **fraction of epochs decoded** (not declined by the sensing);
- the **fused track's** mean 3D error (take-off frame), which comes with the run;
- **heading**: mean absolute error of the sensed yaw (Fig. 11) and the
  fraction of epochs that report one.

Points (durations are short so the block runs in minutes; the speeds and
distances are the paper's):

- Fig. 9: ``marvel-rail`` with ``flight.speed`` 0.5-3 m/s, 10 s (3 s at
  rest, then the rail), scored on the epochs at >= 90 % of the speed;
  0 m/s is the same controller with the drone at rest at the rail's start
  (``flight = {kind = "hover", altitude = 0}``), all epochs. Marvel and the
  Doppler-blind mu-locate baseline (``ulocate``).
- Fig. 10: ``marvel-distance`` (rail at 3 m/s) with the controller at
  ``[2, -N, 1]`` for N = 1-50 m in the open, and 0-3 walls at 10 m; 10 s,
  scored on the epochs at >= 90 % of the speed; Marvel.
- Fig. 11: ``marvel-turntable`` with the 0.2 -> 1.5 -> 0.2 rad/s sweep over
  26 s (the paper's sweep at twice its pace, to cover every rate in a 30 s
  run) in the open and through 3 walls; Marvel.

Units: metres, degrees where named, seconds.
"""

from __future__ import annotations

import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

SCORING_SEEDS_MAX = 3
"""At most this many scoring seeds per point (IQ simulation costs ~0.3 s per simulated second)."""
DURATION_S = 10.0
"""Seconds simulated per point of Figs. 9-10."""
SPEEDS = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
"""Fig. 9 rail speeds, m/s."""
DISTANCES = (1.0, 5.0, 10.0, 20.0, 30.0, 40.0, 50.0)
"""Fig. 10 controller distances in the open, m."""
WALLS = (0, 1, 2, 3)
"""Fig. 10 wall counts at :data:`WALL_DISTANCE_M`."""
WALL_DISTANCE_M = 10.0
FLIGHTS = {"marvel-circle-20m": (0.3366, 4.99), "marvel-circle-20m+ground": (0.3366, 4.99),
           "marvel-square-walls": (0.5256, 6.64), "marvel-square-room": (0.5256, 6.64)}
"""The paper's two flights (Figs. 12, 13) at IQ level: scenario -> (mean position error m, orientation deg).
``marvel-square-room`` is the square inside a reflecting room (docs/marvel.md section 11): the
multipath that the other IQ scenarios lack, and the paper's indoor setting."""
GROUND_DISTANCES = (1.0, 5.0, 20.0, 50.0)
"""Fig. 10 distances repeated with the ground reflection (multipath) of :data:`GROUND_REFLECTOR`."""
GROUND_REFLECTOR = {"kind": "plane", "point": [0.0, 0.0, -0.35], "normal": [0.0, 0.0, 1.0], "coefficient": -0.6}
"""The open field's ground for the multipath rows of Fig. 10 (``kind = "ground"``)."""
TURNTABLE_SWEEP_S = 26.0
TURNTABLE_DURATION_S = 30.0
AT_SPEED = 0.9
"""An epoch counts as "at speed" when the true speed is at least this fraction of the rail's speed."""

PAPER_FIG9 = {0.0: (0.8, 0.8), 3.0: (0.8, 2.45)}
"""Paper Fig. 9 (m): speed -> (Marvel, mu-locate) mean position error, the values its text gives."""
PAPER_FIG10 = {1.0: 0.58, 5.0: 0.79, 20.0: 1.44, 50.0: 2.66}
"""Paper Fig. 10 (m): distance -> mean position error in the open; through walls up to 1.22 m."""
PAPER_FIG11 = {0: 9.2, 3: 17.6}
"""Paper Fig. 11 (deg): walls -> mean heading error on the turntable."""


# --------------------------------------------------------------------------
# one run


def _scenario(kind: str, value) -> dict:
    """The scenario dict of one point (names in the module docstring)."""
    from scattertrack.sim import load_scenario

    if kind == "speed":
        scenario = load_scenario("marvel-rail") | {"duration_s": DURATION_S}
        if value == 0.0:
            scenario["flight"] = {"kind": "hover", "altitude": 0.0}
        else:
            scenario["flight"] = {**scenario["flight"], "speed": float(value)}
        return scenario
    if kind == "distance":
        scenario = load_scenario("marvel-distance") | {"duration_s": DURATION_S}
        scenario["controller"] = {**scenario["controller"], "position": [2.0, -float(value), 1.0], "walls": 0}
        return scenario
    if kind == "ground":
        # The open field has a ground: a plane 5 cm below the tags at rest
        # (the landing gear's feet), reflection coefficient -0.6 (moist soil
        # or grass at 900 MHz near grazing). Its image path is a few
        # decimetres longer than the direct one: no 26 MHz aperture resolves it.
        scenario = _scenario("distance", value)
        scenario["lora_model"] = {**scenario.get("lora_model", {}), "reflectors": [GROUND_REFLECTOR]}
        return scenario
    if kind == "flight":
        name, _, ground = str(value).partition("+")
        scenario = load_scenario(name)
        if ground:  # "NAME+ground": the same flight over the open field's ground
            scenario["lora_model"] = {**scenario.get("lora_model", {}), "reflectors": [GROUND_REFLECTOR]}
        return scenario
    if kind == "walls":
        scenario = load_scenario("marvel-distance") | {"duration_s": DURATION_S}
        scenario["controller"] = {**scenario["controller"], "position": [2.0, -WALL_DISTANCE_M, 1.0], "walls": int(value)}
        return scenario
    if kind == "turntable":
        scenario = load_scenario("marvel-turntable") | {"duration_s": TURNTABLE_DURATION_S}
        scenario["flight"] = {**scenario["flight"], "sweep_s": TURNTABLE_SWEEP_S}
        scenario["controller"] = {**scenario["controller"], "walls": int(value)}
        return scenario
    raise ValueError(f"unknown point kind {kind!r}")


def score_run(task: tuple) -> dict:
    """One (kind, value, seed, methods[, params]) point: simulate at IQ level, sense, score (module docstring).

    ``params``: tracker parameters for diagnosis runs (the block itself uses the defaults).
    """
    kind, value, seed, methods = task[:4]
    params = task[4] if len(task) > 4 else {}
    from scattertrack.sim.drone import flight
    from scattertrack.sim.marvel import simulate_marvel_iq
    from scattertrack.sim.rotation import wrap_angle, yaw_of_quat
    from scattertrack.track import marvel

    started = time.perf_counter()
    simulation, recording = simulate_marvel_iq(_scenario(kind, value), seed=seed)
    simulate_s = time.perf_counter() - started
    rho = np.asarray(simulation.details["controller_position_m"], dtype=float)
    flight_params = simulation.scenario["flight"]
    nominal = float(flight_params.get("speed", 0.0)) if flight_params["kind"] == "rail" else 0.0
    out = {"kind": kind, "value": value, "seed": seed, "epochs": recording.n_epochs, "simulate_s": simulate_s,
           "snr_db_median": float(simulation.details["snr_db"]["median"]), "methods": {}}
    for method in methods:
        started = time.perf_counter()
        track = marvel.run_sigmf(method, simulation.scene, recording, simulation.imu, **params)
        wall = time.perf_counter() - started
        stats = track.stats["drone"]
        features = stats["features"]
        state = flight(flight_params, features.time_s)
        offset = state.position - rho
        el, az = features.elevation_rad, features.azimuth_rad
        sensed = features.range_m[:, None] * np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        snapshot = np.linalg.norm(sensed - offset, axis=1)
        range_error = features.range_m - np.linalg.norm(offset, axis=1)
        speed = np.linalg.norm(state.velocity, axis=1)
        scored = speed >= AT_SPEED * nominal if nominal > 0 else np.ones(len(speed), dtype=bool)
        # Epochs at speed among all the recording's epochs (declined ones included), for the decoded fraction.
        # The epochs' reference times (the mean chirp centre, as the sensing stamps its rows).
        chirp_s = float(recording.metadata["chirp_duration_s"])
        all_times = recording.chirp_start_s.mean(axis=1) + chirp_s / 2.0
        all_speed = np.linalg.norm(flight(flight_params, all_times).velocity, axis=1)
        candidates = int(np.count_nonzero(all_speed >= AT_SPEED * nominal)) if nominal > 0 else recording.n_epochs
        has_yaw = np.isfinite(features.yaw_rad)
        yaw_error = np.abs(wrap_angle(features.yaw_rad[has_yaw] - yaw_of_quat(state.orientation[has_yaw])))
        # The fused track against the truth (take-off frame).
        truth = simulation.truth
        if len(track):
            position = np.column_stack([np.interp(track.time_s, truth.time_s, truth.position[:, a]) for a in range(3)])
            fused = np.linalg.norm(track.position - position, axis=1)
        else:
            fused = np.zeros(0)
        from scattertrack.eval import compare

        report = compare(truth, track).overall if len(track) else None
        rotation_deg = float(report.mean_orientation_deg) if report is not None else float("nan")
        revised = track.revised if track.revised is not None and len(track.revised) else None
        revised_m = float(compare(truth, revised).overall.mean_3d_m) if revised is not None else float("nan")
        out["methods"][method] = {
            "snapshot_m": snapshot[scored],
            "range_error_m": range_error[scored],
            "scored": int(np.count_nonzero(scored)),
            "candidates": candidates,
            "declined": {k: v for k, v in stats["sensing_declined"].items() if v},
            "yaw_error_deg": np.degrees(yaw_error),
            "yaw_rows": int(np.count_nonzero(has_yaw)),
            "rows": len(features),
            "fused_m": fused,
            "rotation_deg": rotation_deg,
            "revised_mean_3d_m": revised_m,
            "dsp_ns": float(stats["dsp_time_ns_p50"]),
            "dsp_ns_p99": float(stats["dsp_time_ns_p99"]),
            "fusion_ns": float(stats["time_ns_p50"]),
            "fusion_ns_p99": float(stats["time_ns_p99"]),
            "wall_s": wall,
        }
    return out


# --------------------------------------------------------------------------
# the block


def _mean(values) -> float:
    values = np.concatenate([np.atleast_1d(np.asarray(v, dtype=float)) for v in values]) if values else np.zeros(0)
    return float(np.mean(values)) if values.size else float("nan")


def _aggregate(runs: list[dict], method: str) -> dict:
    results = [r["methods"][method] for r in runs]
    scored = sum(m["scored"] for m in results)
    candidates = sum(m["candidates"] for m in results)
    declined: dict[str, int] = {}
    for m in results:
        for key, n in m["declined"].items():
            declined[key] = declined.get(key, 0) + n
    return {
        "snapshot_mean_m": _mean([m["snapshot_m"] for m in results]),
        "snapshot_median_m": float(np.median(np.concatenate([m["snapshot_m"] for m in results])))
        if scored else float("nan"),
        "range_rms_m": float(np.sqrt(_mean([np.square(m["range_error_m"]) for m in results]))),
        "decoded_fraction": scored / candidates if candidates else float("nan"),
        "epochs_scored": scored,
        "declined": declined,
        "yaw_mean_deg": _mean([m["yaw_error_deg"] for m in results]),
        "yaw_fraction": sum(m["yaw_rows"] for m in results) / max(sum(r["epochs"] for r in runs), 1),
        # Per run the mean 3D error of the fused track; over runs the median
        # and the worst (a diverged run would swamp a mean over runs).
        "fused_mean_m": float(np.median([_mean([m["fused_m"]]) for m in results])),
        "fused_worst_m": float(np.max([_mean([m["fused_m"]]) for m in results])),
        "snr_db_median": float(np.median([r["snr_db_median"] for r in runs])),
    }


def sensing_block(seeds, show: bool = True, workers: int | None = None) -> dict:
    """Figs. 9-11 at IQ level over seeds ``0 .. min(len(seeds), 3) - 1`` (module docstring); a dict of tables.

    ``workers``: processes (default: the CPUs, at most 2). Prints progress
    on stderr when ``show``. Every number is measured in this call.
    """
    seeds = list(seeds)[:SCORING_SEEDS_MAX]
    tasks = []
    for speed in SPEEDS:
        tasks += [("speed", speed, seed, ("marvel", "ulocate")) for seed in seeds]
    for distance in DISTANCES:
        tasks += [("distance", distance, seed, ("marvel",)) for seed in seeds]
    for walls in WALLS:
        tasks += [("walls", walls, seed, ("marvel",)) for seed in seeds]
    for distance in GROUND_DISTANCES:
        tasks += [("ground", distance, seed, ("marvel",)) for seed in seeds]
    for walls in (0, 3):
        tasks += [("turntable", walls, seed, ("marvel",)) for seed in seeds]
    for name in FLIGHTS:
        tasks += [("flight", name, seed, ("marvel",)) for seed in seeds]
    workers = workers or max(1, min(2, os.cpu_count() or 1))
    started = time.perf_counter()
    runs = []
    # Longest first, so the pool does not end on one long run.
    order = sorted(range(len(tasks)), key=lambda i: tasks[i][0] != "turntable")
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for run in pool.map(score_run, [tasks[i] for i in order]):
                runs.append(run)
                _progress(show, run, started)
    else:
        for i in order:
            runs.append(score_run(tasks[i]))
            _progress(show, runs[-1], started)
    wall = time.perf_counter() - started

    def group(kind, value):
        return [r for r in runs if r["kind"] == kind and r["value"] == value]

    fig9 = [{"speed_m_s": v, "marvel": _aggregate(group("speed", v), "marvel"),
             "ulocate": _aggregate(group("speed", v), "ulocate"), "paper": PAPER_FIG9.get(v)} for v in SPEEDS]
    fig10 = [{"setting": f"{v:g} m, open", "distance_m": v, "walls": 0, "marvel": _aggregate(group("distance", v), "marvel"),
              "paper": PAPER_FIG10.get(v)} for v in DISTANCES]
    fig10 += [{"setting": f"{WALL_DISTANCE_M:g} m, {w} wall{'s' if w != 1 else ''}", "distance_m": WALL_DISTANCE_M,
               "walls": w, "marvel": _aggregate(group("walls", w), "marvel"), "paper": None} for w in WALLS]
    fig10 += [{"setting": f"{v:g} m, ground", "distance_m": v, "walls": 0, "marvel": _aggregate(group("ground", v), "marvel"),
               "paper": PAPER_FIG10.get(v)} for v in GROUND_DISTANCES]
    fig11 = [{"walls": w, "marvel": _aggregate(group("turntable", w), "marvel"), "paper_deg": PAPER_FIG11[w]}
             for w in (0, 3)]
    flights = []
    for name in FLIGHTS:
        group_runs = [r["methods"]["marvel"] for r in group("flight", name)]
        flights.append({"scenario": name, "runs": len(group_runs),
                        "mean_3d_m": float(np.mean([np.mean(m["fused_m"]) for m in group_runs])),
                        "worst_seed_m": float(np.max([np.mean(m["fused_m"]) for m in group_runs])),
                        "rotation_deg": float(np.nanmean([m["rotation_deg"] for m in group_runs])),
                        "revised_mean_3d_m": float(np.nanmean([m["revised_mean_3d_m"] for m in group_runs])),
                        "snapshot_mean_m": _mean([m["snapshot_m"] for m in group_runs]),
                        "paper": FLIGHTS[name]})
    timing = [m for r in runs for m in r["methods"].values()]
    return {
        "seeds": seeds,
        "workers": workers,
        "wall_s": wall,
        "simulate_s": float(sum(r["simulate_s"] for r in runs)),
        "fig9": fig9,
        "fig10": fig10,
        "fig11": fig11,
        "flights": flights,
        "dsp_ms_p50": float(np.median([m["dsp_ns"] for m in timing]) / 1e6),
        "dsp_ms_p99": float(np.max([m["dsp_ns_p99"] for m in timing]) / 1e6),
        "fusion_ms_p50": float(np.nanmedian([m["fusion_ns"] for m in timing]) / 1e6),
        "fusion_ms_p99": float(np.nanmax([m["fusion_ns_p99"] for m in timing]) / 1e6),
    }


def _progress(show: bool, run: dict, started: float) -> None:
    if not show:
        return
    parts = [f"{method} {_mean([m['snapshot_m']]):.2f} m" for method, m in run["methods"].items()]
    # A flight's value is its scenario's name; the other kinds' are numbers.
    value = run["value"] if isinstance(run["value"], str) else f"{run['value']:g}"
    print(f"  sensing {run['kind']} {value} seed {run['seed']}: {', '.join(parts)} "
          f"({time.perf_counter() - started:.0f} s)", file=sys.stderr, flush=True)


# --------------------------------------------------------------------------
# output


def _table(headers: list[str], cells: list[list[str]]) -> str:
    widths = [max(len(h), *(len(row[i]) for row in cells)) for i, h in enumerate(headers)]

    def line(values):
        return "  ".join(v.rjust(w) for v, w in zip(values, widths))

    return "\n".join([line(headers), line(["-" * w for w in widths]), *(line(row) for row in cells)])


def _f(value: float, digits: int = 2) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:.{digits}f}" if abs(value) < 1e4 else f"{value:.1e}"  # a diverged run stays readable


def print_sensing(result: dict, command: str) -> None:
    """Three aligned tables (Figs. 9, 10, 11), each headed by ``command``, then the timing."""
    seeds = result["seeds"]
    seed_text = f"seeds {seeds[0]}..{seeds[-1]}" if seeds else "no seeds"

    print(f"\n## 2a. sensing vs speed (paper Fig. 9; IQ level, marvel-rail, {seed_text})\n$ {command}")
    headers = ["speed m/s", "epochs", "Marvel m", "mu-locate m", "Marvel range rms m", "mu-locate range rms m",
               "fused m Marvel / mu-locate", "paper Marvel / mu-locate m"]
    cells = []
    for row in result["fig9"]:
        m, u = row["marvel"], row["ulocate"]
        paper = "{:.2f} / {:.2f}".format(*row["paper"]) if row["paper"] else "-"
        cells.append([f"{row['speed_m_s']:g}", str(m["epochs_scored"]), _f(m["snapshot_mean_m"]),
                      _f(u["snapshot_mean_m"]), _f(m["range_rms_m"]), _f(u["range_rms_m"]),
                      f"{_f(m['fused_mean_m'])} / {_f(u['fused_mean_m'])}", paper])
    print(_table(headers, cells))
    print("mean snapshot position error |r u - (p - rho)| of the sensed epochs at >= 90 % of the speed, "
          "against the true controller (0 m/s: all epochs at rest); fused: the track's mean 3D error, "
          "median over the seeds")

    print(f"\n## 2b. sensing vs distance and walls (paper Fig. 10; IQ level, marvel-distance at 3 m/s, {seed_text})\n$ {command}")
    headers = ["setting", "SNR dB", "decoded", "snapshot mean m", "median m", "range rms m", "fused m (worst)",
               "declined", "paper m"]
    cells = []
    for row in result["fig10"]:
        m = row["marvel"]
        declined = ", ".join(f"{k} {v}" for k, v in sorted(m["declined"].items())) or "-"
        cells.append([row["setting"], _f(m["snr_db_median"], 1), _f(100 * m["decoded_fraction"], 0) + " %",
                      _f(m["snapshot_mean_m"]), _f(m["snapshot_median_m"]), _f(m["range_rms_m"]),
                      f"{_f(m['fused_mean_m'])} ({_f(m['fused_worst_m'])})", declined,
                      _f(row["paper"]) if row["paper"] else "-"])
    print(_table(headers, cells))
    print("SNR: median per-sample SNR of the direct path (the dechirp adds 36 dB); decoded: epochs at speed "
          "the sensing did not decline; fused: the track's mean 3D error, median (worst) over the seeds; "
          "paper through walls: up to 1.22 m; ground: the open-field rows again with a ground reflection "
          "(plane 5 cm below the tags at rest, coefficient -0.6)")

    print(f"\n## 2c. heading on the turntable (paper Fig. 11; IQ level, 0.2-1.5 rad/s over {TURNTABLE_SWEEP_S:g} s, "
          f"{seed_text})\n$ {command}")
    headers = ["setting", "SNR dB", "epochs with yaw", "yaw mean abs deg", "fused m", "paper deg"]
    cells = []
    for row in result["fig11"]:
        m = row["marvel"]
        setting = "5 m, open" if row["walls"] == 0 else f"5 m, {row['walls']} walls"
        cells.append([setting, _f(m["snr_db_median"], 1), _f(100 * m["yaw_fraction"], 0) + " %",
                      _f(m["yaw_mean_deg"]), _f(m["fused_mean_m"]), _f(row["paper_deg"], 1)])
    print(_table(headers, cells))
    print(f"\n## 2d. fused flights from raw IQ (paper Figs. 12-13, {seed_text})\n$ {command}")
    headers = ["scenario", "runs", "snapshot mean m", "mean 3D m", "worst seed m", "rot mean deg", "revised m",
               "paper m / deg"]
    cells = [[row["scenario"], str(row["runs"]), _f(row["snapshot_mean_m"]), _f(row["mean_3d_m"]),
              _f(row["worst_seed_m"]), _f(row["rotation_deg"]), _f(row["revised_mean_3d_m"]),
              "{:.2f} / {:.2f}".format(*row["paper"])] for row in result["flights"]]
    print(_table(headers, cells))
    print("the whole chain: LoRa IQ -> pose sensing -> fusion, errors in the take-off frame; no reflectors but "
          "the scenario's walls, except +ground (the open field's ground) and marvel-square-room (a reflecting "
          "room); snapshot: |r u - (p - rho)| of each sensed epoch; mean 3D: the causal track; revised: the "
          "fixed-lag smoothed one")
    print(f"\nper epoch: DSP {result['dsp_ms_p50']:.1f} ms p50 ({result['dsp_ms_p99']:.1f} ms p99 worst run), "
          f"fusion {result['fusion_ms_p50']:.1f} ms p50 ({result['fusion_ms_p99']:.1f} ms p99 worst run); "
          f"block wall time {result['wall_s']:.0f} s on {result['workers']} process(es), "
          f"of which IQ simulation {result['simulate_s']:.0f} s (summed over runs)")


def main(argv=None) -> int:
    import argparse
    import shlex

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=SCORING_SEEDS_MAX, help="scoring seeds 0..min(N, 3)-1")
    parser.add_argument("--workers", type=int, help="processes (default: CPUs, at most 2)")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    command = "python bench/sensing_bench.py " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    result = sensing_block(range(args.seeds), not args.no_progress, args.workers)
    print_sensing(result, command.strip())
    return 0


if __name__ == "__main__":
    sys.exit(main())
