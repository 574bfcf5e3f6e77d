"""The ``scattertrack`` command: a thin layer over the Python API.

Subcommands::

    scattertrack simulate --scenario NAME|FILE --out DIR [--seed N] [--duration S] [--pipeline glac|turbotrack|marvel] [--iq]
    scattertrack scenarios
    scattertrack methods
    scattertrack track --scene S --reads R|--frames F|--sigmf R [--calibration C] [--method glac] --out T [--param name=value ...]
    scattertrack stream --scene S --sigmf R [--calibration C] [--method turbotrack] --out T [--speed X | --fast]
    scattertrack check-scene SCENE [--reads R]
    scattertrack import sllurp-csv|impinj-iot|iq-phasors FILE... --scene S --out R
    scattertrack eval --truth T --track K [--out DIR] [--json FILE] [--threshold-m 0.02]
    scattertrack demo [--out DIR] [--scenario NAME] [--seed N]
    scattertrack live --scene S --llrp HOST[:PORT] --out T --journal R [--duration S] [reader settings]
    scattertrack emulate-reader --scenario NAME [--port P] [--speed X] [--drop-after S]
    scattertrack calibrate --scene S --reads R --reference EPC=x,y,z [...] [--truth T] --out C
    scattertrack locate --scene S --reads R --out positions.csv
    scattertrack dashboard [--host 127.0.0.1] [--port 8050] [--token T]

Each command family is a module of its own (``simulate_command``,
``track_command``, ...: ``add_parser(commands)`` and its command
function; the shared option types and checks in :mod:`scattertrack.arguments`,
the shared report lines in :mod:`scattertrack.reporting`); this module
builds the parser from them and runs one command.

Bad input never ends in a traceback: a malformed file, an unknown method or
parameter, or a missing file prints ``scattertrack: error: <message>`` on
stderr (the message names the file, line and column where it can) and
returns exit code 2. Output is plain ASCII so that it survives any terminal
encoding and log file.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings

from scattertrack import arguments
from scattertrack import (
    batch_command,
    calibrate_command,
    demo_command,
    evaluate_command,
    import_command,
    live_command,
    locate_command,
    methods_command,
    simulate_command,
    stream_command,
    track_command,
)
from scattertrack.server import command as dashboard_command

# Names this module held before the commands had their own (kept for callers).
from scattertrack.arguments import UsageError, tracker_parameters  # noqa: F401
from scattertrack.demo_command import DEMO_OUT, DEMO_SCENARIO  # noqa: F401
from scattertrack.track_command import MAX_TAGS_LISTED, UNRESOLVED_SIGMA_M, unresolved_warnings  # noqa: F401

OPTION_RANGES = arguments.OPTION_RANGES | live_command.OPTION_RANGES
"""Allowed values of every command's numeric options, by argparse destination
(:data:`scattertrack.arguments.OPTION_RANGES` and the live commands' own)."""


def check_options(args) -> None:
    """Refuse a numeric option outside its range, or a non-finite one (UsageError naming the option)."""
    arguments.check_options(args, OPTION_RANGES)


def print_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Input warnings as one ``warning: ...`` line on stderr; other warnings as Python shows them."""
    from scattertrack.io import InputWarning

    if issubclass(category, InputWarning):
        print(f"warning: {message}", file=sys.stderr, flush=True)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def build_parser() -> argparse.ArgumentParser:
    from scattertrack import __version__

    parser = argparse.ArgumentParser(
        prog="scattertrack",
        description="Track RF backscatter (RFID) tags in 3D: simulate, track, evaluate.",
    )
    parser.add_argument("--version", action="version", version=f"scattertrack {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    # In this order in --help.
    simulate_command.add_parser(commands)
    methods_command.add_parsers(commands)  # scenarios, methods
    track_command.add_parser(commands)
    stream_command.add_parser(commands)
    track_command.add_check_scene_parser(commands)
    import_command.add_parser(commands)
    evaluate_command.add_parser(commands)
    live_command.add_parsers(commands)  # live, emulate-reader
    calibrate_command.add_parser(commands)
    locate_command.add_parser(commands)
    batch_command.add_parser(commands)
    dashboard_command.add_parser(commands)
    demo_command.add_parser(commands)
    return parser


def error_message(error: BaseException) -> str:
    """The text after 'scattertrack: error:' for an error caused by the user's input."""
    if isinstance(error, OSError) and error.filename is not None:
        reason = error.strerror or str(error)
        return f"{error.filename}: {reason[0].lower() + reason[1:] if reason else reason}"
    if isinstance(error, KeyError) and error.args:
        return str(error.args[0])  # str(KeyError) would add quotes
    return str(error)


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    if argv is None:
        # Run as the command (not called in-process): the process is ours to set up.
        from scattertrack.process import prefer_small_pages

        prefer_small_pages()
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit:
        # argparse exits for --help (0) and usage errors (2); return the code so
        # that main() can be called in-process.
        return exit.code if isinstance(exit.code, int) else 2
    from scattertrack.io import InputWarning

    try:
        check_options(args)
        with warnings.catch_warnings():
            # Every input warning is shown, each on its own line (Python's default shows a text once).
            warnings.simplefilter("always", category=InputWarning)
            warnings.showwarning = print_warning
            return args.run(args)
    except BrokenPipeError:
        # The reader of our output went away (`scattertrack ... | head`): not an error of ours.
        sys.stdout = open(os.devnull, "w")
        return 0
    except (ValueError, KeyError, OSError) as error:
        # FormatError is a ValueError: its message already names file, line and column.
        print(f"scattertrack: error: {error_message(error)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("scattertrack: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
