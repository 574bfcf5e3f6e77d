"""The dashboard's one security rule: a token, or loopback only.

Without a token the server may only listen on a loopback address, where
only this machine's users reach it. With a token every request must carry
it, from loopback too (another local user, or a page in the browser
forging requests to localhost, is not to be trusted either).
"""

from __future__ import annotations

import hmac
import ipaddress

from starlette.middleware.base import BaseHTTPMiddleware
from starlette.requests import Request
from starlette.responses import PlainTextResponse

TOKEN_ENV = "SCATTERTRACK_TOKEN"


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address) only listens on this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False  # any other name may resolve to a public address


def refusal(host: str, token: str | None) -> str | None:
    """Why the server must not start on ``host`` with ``token``; None when it may."""
    if token is not None and not token.strip():
        return "the token is empty: give a non-empty --token (or SCATTERTRACK_TOKEN)"
    if token is None and not is_loopback(host):
        return (
            f"--host {host} is reachable from other machines: give --token T (or set {TOKEN_ENV}) "
            "so that every request must carry it, or bind 127.0.0.1"
        )
    return None


def presented_token(request: Request) -> str | None:
    """The token a request carries: ``Authorization: Bearer T`` or ``?token=T``."""
    header = request.headers.get("authorization", "")
    scheme, _, value = header.partition(" ")
    if scheme.lower() == "bearer" and value:
        return value.strip()
    return request.query_params.get("token")


class TokenMiddleware(BaseHTTPMiddleware):
    """401 for every request without the token (pages, assets and API alike)."""

    def __init__(self, app, token: str):
        super().__init__(app)
        self.token = token.encode()

    async def dispatch(self, request: Request, call_next):
        given = presented_token(request)
        # compare_digest: the time taken does not tell how much of a guess was right.
        if given is None or not hmac.compare_digest(given.encode(), self.token):
            return PlainTextResponse(
                "401 unauthorized: give the dashboard's token as 'Authorization: Bearer T' or '?token=T'\n",
                status_code=401,
                headers={"WWW-Authenticate": "Bearer"},
            )
        return await call_next(request)
