"""``scattertrack dashboard``: serve the web dashboard (docs/dashboard.md).

    scattertrack dashboard [--host 127.0.0.1] [--port 8050] [--token T]

Binds loopback by default. Any other address needs a token (``--token`` or
``SCATTERTRACK_TOKEN``): without one the command exits 1 at once.
"""

from __future__ import annotations

import os
import sys

from scattertrack.arguments import ascii_int, say

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8050


def add_parser(commands) -> None:
    dashboard = commands.add_parser(
        "dashboard",
        help="a web dashboard: live tracks, offline runs, simulations, batches, scene checks",
        description="Serve the dashboard's web page (tabs online, offline, simulation, batch, config) on "
        "http://HOST:PORT/. Binds 127.0.0.1 by default; another host needs --token (or SCATTERTRACK_TOKEN), "
        "and with a token every request must carry 'Authorization: Bearer T' or '?token=T'.",
    )
    dashboard.add_argument("--host", default=DEFAULT_HOST, help=f"address to listen on (default {DEFAULT_HOST})")
    dashboard.add_argument("--port", type=ascii_int, default=DEFAULT_PORT, help=f"port (default {DEFAULT_PORT})")
    dashboard.add_argument("--token", help="require this token on every request (default: $SCATTERTRACK_TOKEN)")
    dashboard.set_defaults(run=command_dashboard)


def command_dashboard(args) -> int:
    from scattertrack.server import auth

    token = args.token if args.token is not None else os.environ.get(auth.TOKEN_ENV)
    problem = auth.refusal(args.host, token)
    if problem is not None:
        # Exit 1 before anything listens: refusing is the point, not an input error (2).
        print(f"scattertrack: dashboard refused: {problem}", file=sys.stderr)
        return 1
    if not 0 < args.port < 65536:
        raise ValueError(f"--port must be from 1 to 65535, got {args.port}")

    import uvicorn

    from scattertrack.server.app import create_app, default_web_dir

    web_dir = default_web_dir()
    if not (web_dir / "index.html").is_file():
        print(f"scattertrack: warning: the front end is not built ({web_dir}): run 'make setup'; "
              "the page will say so", file=sys.stderr)
    host = f"[{args.host}]" if ":" in args.host else args.host
    say(f"scattertrack dashboard on http://{host}:{args.port}/" + ("?token=..." if token else ""))
    uvicorn.run(create_app(token=token), host=args.host, port=args.port, log_level="warning")
    return 0
