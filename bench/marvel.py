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
   as last revised, ``smoother_lag_s`` = 6 s to 7 s later).
2. sensing (IQ level; needs the LoRa DSP): snapshot position error of the
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

BLOCKS = ("fusion", "sensing")
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
    controller = np.asarray(track.stats["drone"]["controller"], dtype=float)
    truth_controller = np.asarray(sim.details["controller_position_m"], dtype=float)
    return {
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
        "wall_s": wall,
        "duration_s": float(sim.scenario["duration_s"]),
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
                "real_time_factor": float(sum(r["duration_s"] for r in runs) / sum(r["wall_s"] for r in runs)),
                "paper_mean_m": paper_m,
                "paper_deg": paper_deg,
            }
        )
    return rows


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
               "ctrl err m", "declined", "epoch p50 ms", "p99 ms", "x real time", "paper m / deg"]
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
            f"{r['epoch_p50_ms']:.1f}",
            f"{r['epoch_p99_ms']:.1f}",
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
        help="the fusion block's smoother_lag_s (default: the estimator's, 6 s); a longer lag improves the revised track and costs time per epoch",
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
