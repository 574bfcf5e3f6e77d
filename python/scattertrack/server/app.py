"""The FastAPI application: the API routers, the token rule and the built front end."""

from __future__ import annotations

import html
import os
import re
import urllib.parse
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

from scattertrack.server import auth, batch, config, jobs, offline, online, simulation

WEB_DIR_ENV = "SCATTERTRACK_WEB_DIR"


def default_web_dir() -> Path:
    """``web/dist`` of the repository (the package is installed editable from ``python/``);
    ``SCATTERTRACK_WEB_DIR`` overrides it."""
    given = os.environ.get(WEB_DIR_ENV)
    if given:
        return Path(given)
    return Path(__file__).resolve().parents[3] / "web" / "dist"


MISSING_BUILD = """<!doctype html>
<html><head><meta charset="utf-8"><title>scattertrack dashboard: front end not built</title></head>
<body style="font-family: sans-serif; max-width: 40em; margin: 3em auto">
<h1>The dashboard's front end is not built</h1>
<p>The server found no <code>index.html</code> in <code>{web_dir}</code>.</p>
<p>Build it from the repository root with <code>make setup</code>
(or <code>cd web &amp;&amp; npm ci &amp;&amp; npm run build</code>), then reload this page.
The API under <code>/api/</code> works without it.</p>
</body></html>
"""


ASSET = re.compile(r'((?:src|href)=")(\./assets/[^"?]+)"')


def with_token(page: str, token: str) -> str:
    """``index.html`` with ``?token=T`` on each of its assets."""
    query = html.escape(urllib.parse.urlencode({"token": token}))
    return ASSET.sub(lambda m: f'{m.group(1)}{m.group(2)}?{query}"', page)


def create_app(token: str | None = None, web_dir: Path | None = None) -> FastAPI:
    """The dashboard; with ``token`` every request must carry it (:mod:`.auth`)."""
    app = FastAPI(title="scattertrack dashboard", docs_url=None, redoc_url=None, openapi_url=None)
    if token is not None:
        app.add_middleware(auth.TokenMiddleware, token=token)
    store = jobs.Jobs()
    app.state.jobs = store

    @app.get("/api/health")
    def health() -> dict:
        from scattertrack import __version__

        return {"ok": True, "version": __version__}

    app.include_router(jobs.router(store))
    app.include_router(offline.router())
    app.include_router(simulation.router(store))
    app.include_router(batch.router(store))
    app.include_router(online.router(store))
    app.include_router(config.router())

    web_dir = Path(web_dir) if web_dir is not None else default_web_dir()
    if (web_dir / "index.html").is_file():
        if token is not None:
            # The browser fetches the page's script and style without the
            # token it was opened with (?token=T): the page names them with it.
            @app.get("/", include_in_schema=False)
            @app.get("/index.html", include_in_schema=False)
            def index(request: Request) -> HTMLResponse:
                return HTMLResponse(with_token((web_dir / "index.html").read_text(), token))

        app.mount("/", StaticFiles(directory=web_dir, html=True), name="web")
    else:
        # Checked at start: a build made later needs a restart, and the page says what to run.
        @app.get("/{path:path}", include_in_schema=False)
        def missing(path: str) -> HTMLResponse:
            return HTMLResponse(MISSING_BUILD.format(web_dir=web_dir), status_code=503)

    return app
