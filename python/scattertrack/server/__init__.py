"""``scattertrack dashboard``: a web page over the Python API (docs/dashboard.md).

One module per concept: :mod:`.app` assembles the FastAPI application and
serves the built front end (``web/dist``), :mod:`.auth` is the token rule,
:mod:`.jobs` runs long work in background threads with progress,
:mod:`.payloads` turns tracks, reports and scenes into JSON, and one router
per tab (:mod:`.online`, :mod:`.offline`, :mod:`.simulation`,
:mod:`.batch`, :mod:`.config`). :mod:`.command` is the CLI entry.

Nothing is imported here: the CLI imports :mod:`.command` at every start,
and FastAPI loads only when the dashboard runs.
"""
