"""Command-line argument types, checks and report lines shared by every subcommand.

Numbers on the command line are ASCII decimal, as in the files; tracker
parameters are read by the method's own parameter table. A numeric option
outside its range, or a combination the tracker would refuse, is a
:class:`UsageError` before any input is read.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

LLRP_PORT = 5084
"""The IANA port of LLRP (5085 with TLS)."""


def host_and_port(text: str, default_port: int = LLRP_PORT) -> tuple[str, int]:
    """``HOST[:PORT]`` (an IPv6 address in brackets: ``[::1]:5084``)."""
    host, port = text, default_port
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        if rest.startswith(":"):
            port = ascii_int(rest[1:])
    elif text.count(":") == 1:
        host, _, number = text.partition(":")
        port = ascii_int(number)
    if not host or not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"expected HOST[:PORT] with a port from 1 to 65535, got {text!r}")
    return host, port


def ascii_float(text: str) -> float:
    """An option's number, ASCII decimal only (as in the files: ``float()``
    alone would take ``1_0`` or a full-width ``１``)."""
    from scattertrack.io.cells import INFINITY_WORD, NAN_WORD, NUMBER

    # nan / inf pass here so that check_options names the option's range.
    if not (NUMBER.fullmatch(text) or NAN_WORD.fullmatch(text) or INFINITY_WORD.fullmatch(text)):
        raise argparse.ArgumentTypeError(f"not an ASCII decimal number: {text!r}")
    return float(text)


def ascii_int(text: str) -> int:
    """An option's integer, ASCII digits only."""
    from scattertrack.io.cells import INTEGER

    if not INTEGER.fullmatch(text):
        raise argparse.ArgumentTypeError(f"not an ASCII integer: {text!r}")
    return int(text)


def parse_parameter(text: str) -> tuple[str, str]:
    """One ``--param name=value`` as (name, text); the method's parameter
    table reads the text (:func:`tracker_parameters`), once the method is known."""
    name, equals, value = text.partition("=")
    name = name.strip()
    if not equals or not name:
        raise argparse.ArgumentTypeError(f"expected name=value, got {text!r}")
    return name, value.strip()


def add_parameter_option(parser, help: str = "tracker parameter, repeatable") -> None:
    """``--param NAME=VALUE``, repeatable, on a command that tracks (:func:`tracker_parameters` reads it)."""
    parser.add_argument("--param", action="append", type=parse_parameter, metavar="NAME=VALUE", help=help)


def tracker_parameters(method: str, pairs) -> dict:
    """``--param`` pairs read by ``method``'s table: typed values, or a ValueError naming the
    parameter and what it must be (an unknown name lists the close matches)."""
    from scattertrack.track import parameters

    return parameters.parse(method, pairs or [])


def say(text: str = "") -> None:
    """Print one line of the command's report on stdout."""
    print(text, flush=True)


def plural(count: int, word: str) -> str:
    """'1 tag', '3 tags'."""
    return f"{count} {word}" if count == 1 else f"{count} {word}s"


class UsageError(ValueError):
    """Bad command-line input that is not about a file (reported like any ValueError)."""


SEED_MAX = 2**63 - 1
"""Seeds must fit in a signed 64-bit integer (numpy's generators take any non-negative one)."""


OPTION_RANGES = {
    "duration": (lambda v: v > 0, "> 0 (seconds)"),
    "seed": (lambda v: 0 <= v <= SEED_MAX, f"an integer from 0 to {SEED_MAX}"),
    "speed": (lambda v: v > 0, "> 0 (a multiple of the recorded timing)"),
    "workers": (lambda v: 1 <= v <= 1024, "from 1 to 1024"),
    "prewake_us": (lambda v: 0 <= v <= 1e6, "in [0, 1e6] (microseconds)"),
    "ema_alpha": (lambda v: 0 < v <= 1, "in (0, 1]"),
    "threshold_m": (lambda v: v > 0, "> 0 (metres)"),
}
"""Allowed values of the numeric options, by argparse destination: checked for every command
before it runs (cli.main, with the live commands' own), so a bad value never reaches a scenario
file or the Rust core."""


def check_options(args, ranges: dict) -> None:
    """Refuse a numeric option outside its range in ``ranges`` (as :data:`OPTION_RANGES`),
    or a non-finite one (UsageError naming the option)."""
    for name, (allowed, description) in ranges.items():
        value = getattr(args, name, None)
        if value is None:
            continue
        finite = math.isfinite(value) if isinstance(value, float) else True
        if not finite or not allowed(value):
            raise UsageError(f"--{name.replace('_', '-')} must be {description}, got {value}")


def show_progress(args) -> bool:
    """Progress bars only on a terminal: they would clutter logs and captured output."""
    return not getattr(args, "no_progress", False) and sys.stderr.isatty()


def check_parameters(method: str, scene, params: dict, scene_path=None) -> None:
    """Refuse parameters the tracker would refuse, before any input is read.

    ``params`` are already typed and in range (:func:`tracker_parameters`);
    building the tracker once more checks what one row cannot: combinations
    (likelihood=paper needs manoeuvre_q=none) and the scene's fitness. Its
    errors name the parameter.
    """
    from scattertrack import track

    try:
        track.make(method, scene, **params)
    except ValueError as error:
        # The core words what the scene lacks; the file it came from is ours to name.
        if scene_path is not None and str(error).startswith("invalid scene:"):
            raise ValueError(f"{scene_path}: {error}") from None
        raise


def calibration_for(args) -> Path:
    """The calibration recording of ``--sigmf``: ``--calibration``, else a
    ``calibration.sigmf-meta`` beside the recording (as ``simulate --iq``
    writes it); without either a UsageError (uncalibrated channels carry the
    hardware response, which no tracker can use)."""
    if getattr(args, "calibration", None):
        return Path(args.calibration)
    beside = Path(args.sigmf).with_name("calibration.sigmf-meta")
    if beside.is_file() and beside.resolve() != Path(args.sigmf).resolve():
        say(f"  calibration: {beside}")
        return beside
    raise UsageError("give --calibration: a recording of a tag at rest at a known position (SigMF)")
