#!/usr/bin/env python
"""Marvel benchmark: the paper's figures (sec. V), measured.

The Python half of ``make bench`` for the third pipeline. Every number comes
from this one run on this machine, with every estimator parameter at its
default; the scoring seeds are 0..N-1 (defaults were chosen on seeds >= 1000).

Blocks:

1. fusion: the backscatter-inertial estimator (``marvel``) on feature-level
   simulations of the paper's two flights — ``marvel-circle-20m`` (Fig. 12:
   mean 33.66 cm, 4.99 deg) and ``marvel-square-walls`` (Fig. 13: 52.56 cm,
   6.64 deg): mean 3D position error (absolute, in the take-off frame, and
   after removing the run's mean offset, i.e. relative to the controller),
   mean orientation error, the controller's error, and the time per sensing
   epoch (p50, p99) on this machine; beside the causal estimates (each row
   as the smoother gave it at its own time) the revised track (each state
   as last revised, ``smoother_lag_s`` = 4 s to 5 s later, read half a
   second ahead of their group's marginalisation).
2. starts: the same estimator, every parameter at its default, on flights
   that do not begin at rest: ``marvel-liftoff-circle`` (the log begins in
   the climb), ``marvel-liftoff-circle-imu-late`` (its first 3 s of IMU
   missing; error after 10 s against the full log's),
   ``marvel-liftoff-circle-noisy-imu`` (an IMU noisier than the stated
   densities, measured from its samples), ``marvel-liftoff-square``
   (noisy features, the paper's Fig. 13 level: 0.53 m, 6.6 deg), beside the
   rest start of ``marvel-circle-20m``; and the outside case
   ``/work/shared/outside/drone-liftoff-circle`` (written by an independent
   program; measured, never tuned on), whole and without its first 3 s of
   IMU. Columns: mean 3D and orientation error, rows beyond 3 reported
   sigmas on some axis, divergences (recovered), and the time per epoch.
3. sensing (IQ level; needs the LoRa DSP): snapshot position error of the
   pose sensing against speed 0-3 m/s for Marvel and the Doppler-blind
   mu-locate baseline (Fig. 9), against distance 1-50 m and 0-3 walls
   (Fig. 10), and the heading error on the turntable (Fig. 11).

Output: aligned text on stdout (each table headed by the command that
produced it) and ``latest.json`` in ``--out`` (default ``out/bench-marvel``).

Usage: ``.venv/bin/python bench/marvel.py [--seeds N] [--skip BLOCKS] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

from scattertrack import __version__  # noqa: E402
from scattertrack.eval import compare  # noqa: E402
from scattertrack.fusion import MarvelParams  # noqa: E402
from scattertrack.sim import load_scenario, simulate  # noqa: E402
from scattertrack.track import marvel  # noqa: E402

BLOCKS = ("fusion", "starts", "sensing")
STARTS = (
    # (scenario, what its start is, paper m / deg or None)
    ("marvel-circle-20m", "rest 2 s", None),
    ("marvel-liftoff-circle", "lift-off, no rest", None),
    ("marvel-liftoff-circle-imu-late", "lift-off, first 3 s of IMU missing", None),
    ("marvel-liftoff-circle-noisy-imu", "lift-off, IMU noisier than stated", None),
    ("marvel-liftoff-square", "lift-off, noisy features", (0.5256, 6.64)),
)
OUTSIDE = Path("/work/shared/outside/drone-liftoff-circle")
"""The outside lift-off case (shared/outside/README.md); skipped where absent."""
IMU_LATE_S = 3.0
"""Seconds of IMU removed from the start of the outside case for its second row."""
SCORED_AFTER_S = 10.0
"""The IMU-late rows are scored against the full log after this time (s)."""
FLIGHTS = (
    ("marvel-circle-20m", "Fig. 12", 0.3366, 4.99),
    ("marvel-square-walls", "Fig. 13", 0.5256, 6.64),
)


def progress(enabled: bool, text: str) -> None:
    if enabled:
        print(text, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------
# block 1: fusion on feature-level flights


def fuse_and_score(sim, **params) -> dict:
    """``marvel`` on one simulated flight (``params``: estimator parameters,
    defaults where not given): errors (m, deg) and time per epoch (ns)."""
    start = time.perf_counter()
    track = marvel.run_features("marvel", sim.scene, sim.imu, sim.features, **params)
    wall = time.perf_counter() - start
    report = compare(sim.truth, track).overall
    # Relative to the controller: the same errors after removing the run's
    # mean offset (range and angle cannot see a common shift of the
    # trajectory and the controller; only the take-off anchors it).
    offset = np.zeros(3)
    if len(track):
        truth_position = np.column_stack(
            [np.interp(track.time_s, sim.truth.time_s, sim.truth.position[:, a]) for a in range(3)]
        )
        offset = np.mean(track.position - truth_position, axis=0)
        aligned = np.linalg.norm(track.position - offset - truth_position, axis=1)
    else:
        aligned = np.zeros(0)
    revised = compare(sim.truth, track.revised).overall
    stats = track.stats["drone"]
    controller = np.asarray(stats["controller"] if stats["controller"] is not None else np.full(3, np.nan), dtype=float)
    truth_controller = np.asarray(sim.details["controller_position_m"], dtype=float)
    return {
        **track_scores(sim.truth, track),
        "epochs": len(sim.features),
        "rows": len(track),
        "mean_3d_m": float(report.mean_3d_m),
        "median_3d_m": float(report.median_3d_m),
        "mean_aligned_m": float(np.mean(aligned)) if aligned.size else float("nan"),
        "mean_offset_m": float(np.linalg.norm(offset)),
        "mean_orientation_deg": float(report.mean_orientation_deg),
        "mean_yaw_deg": float(report.mean_yaw_deg),
        "revised_mean_3d_m": float(revised.mean_3d_m),
        "revised_mean_orientation_deg": float(revised.mean_orientation_deg),
        "revised_fallbacks": int(track.stats["drone"]["revised_fallbacks"]),
        "controller_error_m": float(np.linalg.norm(controller - truth_controller)),
        "declined": int(track.skipped.total),
        "epoch_ns": np.asarray(track.stats["drone"].get("epoch_times_ns", []), dtype=float),
        "epoch_p50_ns": float(track.stats["drone"]["time_ns_p50"]),
        "epoch_p99_ns": float(track.stats["drone"]["time_ns_p99"]),
        "epoch_max_ns": float(track.stats["drone"]["time_ns_max"]),
        "cpu_p99_ns": float(track.stats["drone"]["cpu_time_ns_p99"]),
        "cpu_max_ns": float(track.stats["drone"]["cpu_time_ns_max"]),
        "between_max_ns": float(track.stats["drone"]["between_epochs_time_ns_max"]),
        "wall_s": wall,
        "duration_s": float(sim.scenario["duration_s"]),
    }


def track_scores(truth, track, after_s: float = 0.0, stats: dict | None = None) -> dict:
    """Scores of a track against its truth that ``compare`` does not give: the
    share of rows beyond 3 reported sigmas on some axis, the mean 3D error
    (m) of the rows at or after ``after_s`` (s), divergences (and recovered;
    from ``stats``, default the track's own: a revised track has none)."""
    stats = track.stats["drone"] if stats is None else stats
    if not len(track):
        return {"beyond_3_sigma": float("nan"), "mean_3d_after_m": float("nan"), "offset_after_m": float("nan"),
                "divergences": int(stats["divergences"]), "divergences_recovered": int(stats["divergences_recovered"])}
    truth_position = np.column_stack([np.interp(track.time_s, truth.time_s, truth.position[:, a]) for a in range(3)])
    error = track.position - truth_position
    beyond = np.any(np.abs(error) > 3.0 * track.sigma, axis=1)
    after = track.time_s >= after_s
    return {
        "beyond_3_sigma": float(np.mean(beyond)),
        "mean_3d_after_m": float(np.mean(np.linalg.norm(error[after], axis=1))) if np.any(after) else float("nan"),
        # What no later row corrects: the whole track shifted (horizontally; the barometer holds the height).
        "offset_after_m": float(np.linalg.norm(np.mean(error[after, :2], axis=0))) if np.any(after) else float("nan"),
        "divergences": int(stats["divergences"]),
        "divergences_recovered": int(stats["divergences_recovered"]),
    }


def fusion_block(seeds, show=True, params=None) -> list[dict]:
    rows = []
    for name, figure, paper_m, paper_deg in FLIGHTS:
        runs = []
        for seed in seeds:
            sim = simulate(load_scenario(name), seed=seed)
            runs.append(fuse_and_score(sim, **(params or {})))
            progress(show, f"  fusion {name} seed {seed}: {runs[-1]['mean_3d_m']:.3f} m, {runs[-1]['mean_orientation_deg']:.2f} deg")
        p50 = np.array([r["epoch_p50_ns"] for r in runs])
        p99 = np.array([r["epoch_p99_ns"] for r in runs])
        rows.append(
            {
                "scenario": name,
                "figure": figure,
                "seeds": len(runs),
                "mean_3d_m": float(np.mean([r["mean_3d_m"] for r in runs])),
                "worst_seed_mean_3d_m": float(np.max([r["mean_3d_m"] for r in runs])),
                "mean_aligned_m": float(np.mean([r["mean_aligned_m"] for r in runs])),
                "mean_orientation_deg": float(np.nanmean([r["mean_orientation_deg"] for r in runs])),
                "mean_yaw_deg": float(np.nanmean([r["mean_yaw_deg"] for r in runs])),
                "revised_mean_3d_m": float(np.mean([r["revised_mean_3d_m"] for r in runs])),
                "revised_worst_seed_mean_3d_m": float(np.max([r["revised_mean_3d_m"] for r in runs])),
                "revised_mean_orientation_deg": float(np.nanmean([r["revised_mean_orientation_deg"] for r in runs])),
                "revised_fallbacks": int(sum(r["revised_fallbacks"] for r in runs)),
                "controller_error_m": float(np.mean([r["controller_error_m"] for r in runs])),
                "declined": int(sum(r["declined"] for r in runs)),
                "epoch_p50_ms": float(np.median(p50) / 1e6),
                "epoch_p99_ms": float(np.max(p99) / 1e6),
                "epoch_max_ms": float(np.max([r["epoch_max_ns"] for r in runs]) / 1e6),
                "cpu_p99_ms": float(np.max([r["cpu_p99_ns"] for r in runs]) / 1e6),
                "cpu_max_ms": float(np.max([r["cpu_max_ns"] for r in runs]) / 1e6),
                "between_max_ms": float(np.nanmax([r["between_max_ns"] for r in runs]) / 1e6),
                "beyond_3_sigma": float(np.mean([r["beyond_3_sigma"] for r in runs])),
                "worst_seed_beyond_3_sigma": float(np.max([r["beyond_3_sigma"] for r in runs])),
                "divergences": int(sum(r["divergences"] for r in runs)),
                "divergences_recovered": int(sum(r["divergences_recovered"] for r in runs)),
                "real_time_factor": float(sum(r["duration_s"] for r in runs) / sum(r["wall_s"] for r in runs)),
                "paper_mean_m": paper_m,
                "paper_deg": paper_deg,
            }
        )
    return rows


# --------------------------------------------------------------------------
# block 2: starts that are not at rest, ours and the outside case


def drop_first_imu(imu, seconds: float):
    """``imu`` without its samples before ``imu.time_s[0] + seconds`` (a log that lost its first seconds)."""
    from scattertrack.io.types import Imu

    keep = np.asarray(imu.time_s) >= float(imu.time_s[0]) + seconds
    return Imu(
        time_s=np.asarray(imu.time_s)[keep],
        accel=np.asarray(imu.accel)[keep],
        gyro=np.asarray(imu.gyro)[keep],
        baro_z=None if imu.baro_z is None else np.asarray(imu.baro_z)[keep],
        gaps=imu.gaps,
    )


def first_row_error(truth, features, controller) -> float:
    """Horizontal distance (m) between where the log's first feature row puts
    the drone, seen from the true ``controller``, and where it was.

    Why: a log missing its first seconds of IMU has one tie between the
    take-off frame and the controller, that row (the drone is at the origin
    then; its later positions before the IMU are unknown), so its error
    shifts the whole track and no later row corrects it."""
    u = np.array([
        math.cos(features.elevation_rad[0]) * math.cos(features.azimuth_rad[0]),
        math.cos(features.elevation_rad[0]) * math.sin(features.azimuth_rad[0]),
        math.sin(features.elevation_rad[0]),
    ])
    seen = np.asarray(controller, dtype=float) + features.range_m[0] * u
    was = np.array([np.interp(features.time_s[0], truth.time_s, truth.position[:, a]) for a in range(3)])
    return float(np.linalg.norm((seen - was)[:2]))


def score_start(truth, scene, imu, features, after_s: float = SCORED_AFTER_S, controller=None) -> dict:
    """One fused log: mean 3D (m) and orientation (deg) error, the mean 3D error
    after ``after_s``, rows beyond 3 sigmas, divergences, time per epoch; with
    the true ``controller`` position, the first row's error (:func:`first_row_error`)."""
    track = marvel.run_features("marvel", scene, imu, features)
    report = compare(truth, track).overall
    revised = compare(truth, track.revised).overall
    revised_scores = track_scores(truth, track.revised, after_s, stats=track.stats["drone"])
    stats = track.stats["drone"]
    return {
        **track_scores(truth, track, after_s),
        "mean_3d_m": float(report.mean_3d_m),
        "mean_orientation_deg": float(report.mean_orientation_deg),
        "revised_mean_3d_m": float(revised.mean_3d_m),
        "revised_mean_3d_after_m": revised_scores["mean_3d_after_m"],
        "revised_mean_orientation_deg": float(revised.mean_orientation_deg),
        "revised_beyond_3_sigma": revised_scores["beyond_3_sigma"],
        "revised_offset_after_m": revised_scores["offset_after_m"],
        "first_row_m": first_row_error(truth, features, controller) if controller is not None else float("nan"),
        "rest": stats["rest"]["state"],
        "epoch_p99_ms": float(stats["time_ns_p99"]) / 1e6,
        "epoch_max_ms": float(stats["time_ns_max"]) / 1e6,
        "cpu_p99_ms": float(stats["cpu_time_ns_p99"]) / 1e6,
    }


def _pool(runs: list[dict]) -> dict:
    """Seed means of a start's runs (rates as shares; divergences summed; times the worst)."""
    return {
        "seeds": len(runs),
        "mean_3d_m": float(np.mean([r["mean_3d_m"] for r in runs])),
        "worst_seed_mean_3d_m": float(np.max([r["mean_3d_m"] for r in runs])),
        "mean_3d_after_m": float(np.mean([r["mean_3d_after_m"] for r in runs])),
        "mean_orientation_deg": float(np.nanmean([r["mean_orientation_deg"] for r in runs])),
        "beyond_3_sigma": float(np.mean([r["beyond_3_sigma"] for r in runs])),
        "worst_seed_beyond_3_sigma": float(np.max([r["beyond_3_sigma"] for r in runs])),
        "revised_mean_3d_m": float(np.mean([r["revised_mean_3d_m"] for r in runs])),
        "revised_worst_seed_mean_3d_m": float(np.max([r["revised_mean_3d_m"] for r in runs])),
        "revised_mean_3d_after_m": float(np.mean([r["revised_mean_3d_after_m"] for r in runs])),
        "revised_mean_orientation_deg": float(np.nanmean([r["revised_mean_orientation_deg"] for r in runs])),
        "revised_beyond_3_sigma": float(np.mean([r["revised_beyond_3_sigma"] for r in runs])),
        "revised_worst_seed_beyond_3_sigma": float(np.max([r["revised_beyond_3_sigma"] for r in runs])),
        "revised_offset_after_m": float(np.mean([r["revised_offset_after_m"] for r in runs])),
        "first_row_m": float(np.mean([r["first_row_m"] for r in runs])),
        "divergences": int(sum(r["divergences"] for r in runs)),
        "divergences_recovered": int(sum(r["divergences_recovered"] for r in runs)),
        "rest": ",".join(sorted({r["rest"] for r in runs})),
        "epoch_p99_ms": float(np.max([r["epoch_p99_ms"] for r in runs])),
        "epoch_max_ms": float(np.max([r["epoch_max_ms"] for r in runs])),
        "cpu_p99_ms": float(np.max([r["cpu_p99_ms"] for r in runs])),
    }


def starts_block(seeds, show=True) -> list[dict]:
    """Our start conditions (:data:`STARTS`) over ``seeds``, then the outside case whole and IMU-late."""
    rows = []
    for name, start, paper in STARTS:
        runs = []
        for seed in seeds:
            sim = simulate(load_scenario(name), seed=seed)
            runs.append(score_start(sim.truth, sim.scene, sim.imu, sim.features,
                                    controller=sim.details["controller_position_m"]))
            progress(show, f"  start {name} seed {seed}: {runs[-1]['revised_mean_3d_m']:.3f} m (causal "
                           f"{runs[-1]['mean_3d_m']:.3f} m), {runs[-1]['revised_mean_orientation_deg']:.2f} deg")
        rows.append({"case": name, "start": start, "paper": paper, **_pool(runs)})
    if (OUTSIDE / "truth.csv").is_file():
        from scattertrack import io

        scene = io.read_scene(OUTSIDE / "scene.toml")
        imu = io.read_imu(OUTSIDE / "imu.csv")
        features = io.read_features(OUTSIDE / "features.csv")
        truth = io.read_truth(OUTSIDE / "truth.csv")
        for label, log in (("whole", imu), (f"first {IMU_LATE_S:g} s of IMU removed", drop_first_imu(imu, IMU_LATE_S))):
            run = score_start(truth, scene, log, features)
            progress(show, f"  start outside {label}: {run['revised_mean_3d_m']:.3f} m (causal {run['mean_3d_m']:.3f} m)")
            rows.append({"case": "outside/drone-liftoff-circle", "start": label, "paper": (0.3366, 4.99), **_pool([run])})
    # The IMU-late logs against their full logs, after SCORED_AFTER_S.
    by = {(r["case"], r["start"]): r for r in rows}
    for late, full in (
        (("marvel-liftoff-circle-imu-late", STARTS[2][1]), ("marvel-liftoff-circle", STARTS[1][1])),
        (("outside/drone-liftoff-circle", f"first {IMU_LATE_S:g} s of IMU removed"), ("outside/drone-liftoff-circle", "whole")),
    ):
        if late in by and full in by:
            by[late]["after_ratio"] = by[late]["mean_3d_after_m"] / by[full]["mean_3d_after_m"]
            by[late]["revised_after_ratio"] = by[late]["revised_mean_3d_after_m"] / by[full]["revised_mean_3d_after_m"]
    return rows


def print_starts(rows: list[dict], command: str) -> None:
    print(f"\n## 2. starts not at rest (defaults; ours and the outside case)\n$ {command}")
    after = f"after {SCORED_AFTER_S:g} s m"
    headers = ["case", "start", "seeds", "rest test", "track m", "worst seed m", after, "vs full log", "offset m",
               "1st row m", "rot deg", ">3 sigma %", "worst seed %", "causal m", "causal " + after, "vs full log", "causal rot deg",
               "causal >3 sigma %", "worst seed %", "divergences (recovered)", "p99 ms", "max ms", "cpu p99 ms",
               "paper m / deg"]
    ratio = lambda r, key: f"{r[key]:.2f}x" if key in r else "-"  # noqa: E731
    cells = [
        [
            r["case"], r["start"], str(r["seeds"]), r["rest"],
            f"{r['revised_mean_3d_m']:.3f}", f"{r['revised_worst_seed_mean_3d_m']:.3f}", f"{r['revised_mean_3d_after_m']:.3f}",
            ratio(r, "revised_after_ratio"), f"{r['revised_offset_after_m']:.3f}",
            f"{r['first_row_m']:.3f}" if math.isfinite(r["first_row_m"]) else "-", f"{r['revised_mean_orientation_deg']:.2f}",
            f"{100 * r['revised_beyond_3_sigma']:.1f}", f"{100 * r['revised_worst_seed_beyond_3_sigma']:.1f}",
            f"{r['mean_3d_m']:.3f}", f"{r['mean_3d_after_m']:.3f}", ratio(r, "after_ratio"),
            f"{r['mean_orientation_deg']:.2f}", f"{100 * r['beyond_3_sigma']:.1f}", f"{100 * r['worst_seed_beyond_3_sigma']:.1f}",
            f"{r['divergences']} ({r['divergences_recovered']})", f"{r['epoch_p99_ms']:.1f}", f"{r['epoch_max_ms']:.1f}",
            f"{r['cpu_p99_ms']:.1f}", f"{r['paper'][0]:.2f} / {r['paper'][1]:.2f}" if r["paper"] else "-",
        ]
        for r in rows
    ]
    print(text_table(headers, cells))
    print(f"track: the revised rows, what 'scattertrack track' writes (each epoch as the fixed-lag smoother last "
          f"revised it); causal: each row at its own time (--causal-out, what live publishes); rest test: the "
          f"verdict on the first tilt_window_s of IMU; after {SCORED_AFTER_S:g} s: rows at or after it; "
          "vs full log: the IMU-late log's error after that time over the full log's; offset: the length of the "
          "mean horizontal error of the track's rows after that time (a shift of the whole track); 1st row: the "
          "horizontal error of where the log's first feature row puts the drone, seen from the true controller "
          "(an IMU-late log's only tie to the take-off frame); >3 sigma: rows beyond 3 reported "
          "sigmas on some axis; outside: burn-in 0 s (the outside report skips 5 s); its paper column is the circle's Fig. 12")


# --------------------------------------------------------------------------
# output


def text_table(headers: list[str], cells: list[list[str]]) -> str:
    widths = [max(len(h), *(len(row[i]) for row in cells)) for i, h in enumerate(headers)]
    line = lambda values: "  ".join(v.rjust(w) for v, w in zip(values, widths))  # noqa: E731
    return "\n".join([line(headers), line(["-" * w for w in widths]), *(line(row) for row in cells)])


def print_fusion(rows: list[dict], command: str, lag_s: float) -> None:
    print(f"\n## 1. fusion (feature-level flights)\n$ {command}")
    headers = ["scenario", "seeds", "mean 3D m", "worst seed m", "rel. ctrl m", "rot deg", "yaw deg",
               "revised m", "revised worst m", "revised rot deg",
               "ctrl err m", "declined", ">3 sigma %", "div (rec)", "epoch p50 ms", "p99 ms", "max ms", "cpu p99 ms",
               "cpu max ms", "between max ms", "x real time", "paper m / deg"]
    cells = [
        [
            r["scenario"],
            str(r["seeds"]),
            f"{r['mean_3d_m']:.3f}",
            f"{r['worst_seed_mean_3d_m']:.3f}",
            f"{r['mean_aligned_m']:.3f}",
            f"{r['mean_orientation_deg']:.2f}",
            f"{r['mean_yaw_deg']:.2f}",
            f"{r['revised_mean_3d_m']:.3f}",
            f"{r['revised_worst_seed_mean_3d_m']:.3f}",
            f"{r['revised_mean_orientation_deg']:.2f}",
            f"{r['controller_error_m']:.2f}",
            str(r["declined"]),
            f"{100 * r['beyond_3_sigma']:.1f}",
            f"{r['divergences']} ({r['divergences_recovered']})",
            f"{r['epoch_p50_ms']:.1f}",
            f"{r['epoch_p99_ms']:.1f}",
            f"{r['epoch_max_ms']:.1f}",
            f"{r['cpu_p99_ms']:.1f}",
            f"{r['cpu_max_ms']:.1f}",
            f"{r['between_max_ms']:.1f}",
            f"{r['real_time_factor']:.0f}",
            f"{r['paper_mean_m']:.2f} / {r['paper_deg']:.2f} ({r['figure']})",
        ]
        for r in rows
    ]
    print(text_table(headers, cells))
    print("mean 3D: in the take-off frame (truth's); rel. ctrl: after removing each run's mean offset "
          "(the trajectory relative to the controller); revised: the fixed-lag smoothed track, each state "
          f"as last revised {lag_s:g}-{lag_s + MarvelParams().marginalize_every_s:g} s after its time (smoother_lag_s "
          "to smoother_lag_s + marginalize_every_s; the causal columns are each row at its own time); "
          "p99 / max ms: the worst seed's wall-clock time per epoch (p99, max; target 30 / 100 ms); cpu: the same in "
          "thread CPU time, which other processes on a shared machine do not inflate; between max: the longest "
          "run of the work between epochs (relinearisation, the heading hold's end, fusion/between_epochs.py), "
          "after a row's estimate and before the next row; "
          "x real time: simulated s per wall s")


def git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout.strip()
    except OSError:
        return ""


def _json_ready(value):
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10, help="scoring seeds 0..N-1 (default 10)")
    parser.add_argument("--skip", default="", help="comma-separated blocks to skip: " + ", ".join(BLOCKS))
    parser.add_argument(
        "--smoother-lag-s", type=float, default=None,
        help="the fusion block's smoother_lag_s (default: the estimator's, 4 s); a longer lag improves the revised track and costs time per epoch",
    )
    parser.add_argument("--out", type=Path, default=REPO / "out" / "bench-marvel", help="output folder")
    parser.add_argument("--no-progress", action="store_true", help="no progress lines on stderr")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    unknown = skip - set(BLOCKS)
    if unknown:
        print(f"unknown block(s) {sorted(unknown)}; known: {', '.join(BLOCKS)}", file=sys.stderr)
        return 2
    command = "python bench/marvel.py " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    seeds = list(range(args.seeds))
    show = not args.no_progress
    result = {"version": __version__, "commit": git_commit(), "seeds": seeds, "command": command}
    print(f"# Marvel benchmark (scattertrack {__version__}, commit {result['commit']}, seeds 0..{args.seeds - 1})")
    if "fusion" not in skip:
        params = {} if args.smoother_lag_s is None else {"smoother_lag_s": args.smoother_lag_s}
        result["fusion_params"] = params
        result["fusion"] = fusion_block(seeds, show, params)
        print_fusion(result["fusion"], command, params.get("smoother_lag_s", MarvelParams().smoother_lag_s))
    if "starts" not in skip:
        result["starts"] = starts_block(seeds, show)
        print_starts(result["starts"], command)
    if "sensing" not in skip:
        from sensing_bench import sensing_block, print_sensing  # noqa: PLC0415 (bench/ sibling)

        result["sensing"] = sensing_block(seeds, show)
        print_sensing(result["sensing"], command)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "latest.json").write_text(json.dumps(_json_ready(result), indent=1))
    print(f"\nwrote {args.out / 'latest.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
