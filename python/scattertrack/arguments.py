"""Command-line argument types and report lines shared by every subcommand.

Numbers on the command line are ASCII decimal, as in the files; tracker
parameters are read by the method's own parameter table.
"""

from __future__ import annotations

import argparse

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
