"""``scattertrack eval``: a track compared with the ground truth.

    scattertrack eval --truth T --track K [--out DIR] [--json FILE] [--threshold-m 0.02] [--tag EPC]
"""

from __future__ import annotations

from pathlib import Path

from scattertrack.arguments import UsageError, ascii_float, say
from scattertrack.reporting import save_figures, write_json


def add_parser(commands) -> None:
    evaluate = commands.add_parser(
        "eval",
        help="compare a track with ground truth: errors, convergence, plots",
        description="Compare track.csv with truth.csv: median/p90 3D and per-axis error, velocity "
        "error, convergence time; saves error_cdf.png and track.png.",
    )
    evaluate.add_argument("--truth", required=True, help="truth.csv")
    evaluate.add_argument("--track", required=True, help="track.csv")
    evaluate.add_argument("--out", help="folder for the figures (default: the track's folder)")
    evaluate.add_argument("--json", help="also write the report as JSON to this file")
    evaluate.add_argument(
        "--threshold-m",
        type=ascii_float,
        default=0.02,
        help="convergence threshold on the 3D error, metres (default 0.02)",
    )
    evaluate.add_argument("--tag", help="the tag (epc) drawn in track.png (default: the first)")
    evaluate.set_defaults(run=command_eval)


def command_eval(args) -> int:
    from scattertrack import eval as evaluation
    from scattertrack import io

    truth = io.read_truth(args.truth)
    result = io.read_track(args.track)
    if args.tag is not None and args.tag not in set(result.epc.tolist()):
        raise UsageError(f"--tag {args.tag}: {args.track} has no rows for this tag")
    report = evaluation.compare(truth, result, convergence_threshold_m=args.threshold_m)
    say(evaluation.format_report(report, title=f"{args.track} against {args.truth}"))
    out_dir = Path(args.out) if args.out else Path(args.track).parent
    for path in save_figures(report, truth, result, out_dir, tag=args.tag):
        say(f"wrote {path}")
    if args.json:
        write_json(Path(args.json), report, truth=str(args.truth), track=str(args.track))
        say(f"wrote {args.json}")
    return 0
