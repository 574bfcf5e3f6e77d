"""Which of `realistic-3d-arm`'s impairments costs GLAC what: each removed, and each alone.

`realistic-3d-arm` stacks a real reader's errors on the `glac-3d-arm`
layout (four antennas in the table's plane): white noise and a wander,
calibration error of the antenna and channel offsets, a reflecting wall,
outliers and dropout bursts, over 50-channel hopping. This runs it at
GLAC's defaults with the whole stack, with one impairment taken out at a
time, and with one impairment alone over the clean reads (0.015 rad white,
hopping with exact offsets), and prints per row:

- median 3D error, pooled over every row of every run, mm;
- rows > 5 cm from 5 s on: the share of rows from 5 s on (the arm has been
  moving for 4 s) whose 3D error exceeds 5 cm (a wrong candidate reported:
  competing candidates are ≈ λ/2 = 16 cm or more apart);
- wrong runs: runs with more than 10 % of such rows;
- beyond 3 sigma: rows from 2 s on with |error| > 3 sigma on some axis;
- wide sigma: of the rows from 2 s on within 2 cm of the truth, those whose
  3D sigma exceeds 5 cm (``glac_robustness.wide_sigma``).

Nothing here tunes the tracker; ``--param`` runs every row with a parameter
changed (dev seeds: ``--first-seed 1000``).

    .venv/bin/python bench/glac_impairments.py [--seeds 100] [--first-seed 0] [--rows alone,all] [--param NAME=VALUE]
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from scattertrack import track as st_track
from scattertrack.sim import load_scenario, simulate
from scattertrack.track import parameters as st_parameters

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_modules  # noqa: E402

robustness = bench_modules.load("glac_robustness")  # truth_at, beyond_three_sigma

SCENARIO = "realistic-3d-arm"
WRONG_AFTER_S = 5.0  # s: rows scored for a wrong candidate from here on
WRONG_M = 0.05  # m: an error this large is a wrong candidate, not noise
WRONG_RUN_SHARE = 0.10  # a run with more such rows than this is a wrong run

IMPAIRMENTS = {
    "wall": {"reflectors": []},
    "wander": {"wander_rad": 0.0},
    "calibration error": {"antenna_offset_calibration_error_rad": 0.0, "channel_offset_calibration_error_rad": 0.0},
    "outliers": {"outlier_probability": 0.0},
    "dropout bursts": {"dropout_burst_rate_hz": 0.0},
}
"""Each impairment, as the `[reader_model]` values that take it out."""


def rows() -> list[tuple[str, dict]]:
    """(label, reader_model overrides): the whole stack, each impairment out, each alone, none."""
    clean = {key: value for change in IMPAIRMENTS.values() for key, value in change.items()}

    def alone(change: dict) -> dict:
        """Every impairment taken out but the one ``change`` takes out."""
        return {k: v for k, v in clean.items() if k not in change}

    table = [("all impairments", {})]
    table += [(f"all but {name}", change) for name, change in IMPAIRMENTS.items()]
    table += [(f"{name} alone", alone(change)) for name, change in IMPAIRMENTS.items()]
    table += [("all but hopping", {"hopping": False}), ("wall alone, one channel", {**alone(IMPAIRMENTS["wall"]), "hopping": False})]
    table.append(("none (0.015 rad white, hopping)", clean))
    return table


def run_one(job: tuple) -> dict:
    """Simulate and track one seed of one row; the counts its summary needs."""
    overrides, seed, params = job
    scenario = copy.deepcopy(load_scenario(SCENARIO))
    scenario["reader_model"].update(overrides)
    sim = simulate(scenario, seed=seed)
    track = st_track.run("glac", sim.scene, sim.reads, **st_parameters.offline("glac", params))
    errors, late = [], []
    for epc in np.unique(track.epc):
        mine = (track.epc == epc) & np.all(np.isfinite(track.position), axis=1)
        error = np.linalg.norm(track.position[mine] - robustness.truth_at(sim.truth, epc, track.time_s[mine]), axis=1)
        errors.append(error)
        late.append(error[track.time_s[mine] >= WRONG_AFTER_S])
    rows_, beyond = robustness.beyond_three_sigma(sim.truth, track)
    right, wide = robustness.wide_sigma(sim.truth, track)
    late = np.concatenate(late) if late else np.zeros(0)
    return {"errors": np.concatenate(errors) if errors else np.zeros(0), "late": late, "sigma_rows": rows_, "beyond_rows": beyond,
            "right_rows": right, "wide_rows": wide}


def summary(runs: list[dict]) -> dict:
    errors = np.concatenate([r["errors"] for r in runs])
    late = np.concatenate([r["late"] for r in runs])
    wrong = sum(1 for r in runs if r["late"].size and np.mean(r["late"] > WRONG_M) > WRONG_RUN_SHARE)
    rows_ = sum(r["sigma_rows"] for r in runs)
    right = sum(r["right_rows"] for r in runs)
    return {
        "median_mm": float(np.median(errors) * 1e3) if errors.size else float("nan"),
        "late_wrong": float(np.mean(late > WRONG_M)) if late.size else float("nan"),
        "wrong_runs": wrong,
        "beyond": sum(r["beyond_rows"] for r in runs) / rows_ if rows_ else float("nan"),
        "wide": sum(r["wide_rows"] for r in runs) / right if right else float("nan"),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=100, help="runs per row (default 100)")
    parser.add_argument("--first-seed", type=int, default=0, help="first seed (defaults were chosen on 1000 and above)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rows", default="", help="only the rows whose label contains one of these comma-separated words")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="a GLAC parameter for every row (repeatable)")
    args = parser.parse_args(argv)
    params = st_parameters.parse("glac", [tuple(p.split("=", 1)) for p in args.param])
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    table = rows()
    if args.rows:
        words = [w.strip() for w in args.rows.split(",") if w.strip()]
        table = [(label, change) for label, change in table if any(w in label for w in words)]
    started = time.perf_counter()
    jobs = [(overrides, seed, params) for _, overrides in table for seed in seeds]
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(run_one, jobs, chunksize=4))
    print(f"{SCENARIO}: each impairment out and alone, glac at its defaults{' with ' + ', '.join(args.param) if args.param else ''}; "
          f"seeds {seeds.start}..{seeds.stop - 1}; wall time {time.perf_counter() - started:.0f} s")
    print(f"{'reads':<34} {'median mm':>9} {'rows > 5 cm from 5 s':>21} {'wrong runs':>10} {'> 3 sigma':>9} {'wide sigma':>10}")
    for k, (label, _) in enumerate(table):
        s = summary(results[k * len(seeds):(k + 1) * len(seeds)])
        print(f"{label:<34} {s['median_mm']:>9.2f} {100 * s['late_wrong']:>20.1f}% {s['wrong_runs']:>10d} {100 * s['beyond']:>8.1f}% {100 * s['wide']:>9.1f}%")
    print(f"rows > 5 cm: share of rows from {WRONG_AFTER_S:g} s on with 3D error > {100 * WRONG_M:g} cm (a wrong candidate); "
          f"wrong runs: runs with more than {100 * WRONG_RUN_SHARE:g} % such rows; > 3 sigma: rows from 2 s on beyond 3 sigma on some axis; "
          "wide sigma: rows from 2 s on within 2 cm of the truth whose 3D sigma exceeds 5 cm.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
