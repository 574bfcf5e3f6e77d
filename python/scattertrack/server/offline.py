"""The offline tab: a scene and reads (paths on the server's disk, or uploaded), any method, the report.

Tracking runs in Rust and takes well under a second for a typical
recording, so the request answers with the whole result (no job).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

from fastapi import APIRouter, Form, HTTPException, UploadFile

from scattertrack.server import payloads


def reads_methods() -> list[dict]:
    """The methods that track a COTS reader's phase reads (what this tab and the simulation tab run)."""
    from scattertrack.track import methods

    return [
        {"name": m.name, "description": m.description, "input": m.input_files}
        for m in methods.REGISTRY.values()
        if takes_reads(m.name)
    ]


def takes_reads(method: str) -> bool:
    from scattertrack.track import WIDEBAND_METHODS, methods

    return method not in WIDEBAND_METHODS and "reads" in methods.method(method).input_files


def track_and_report(method: str, scene, reads, truth=None, title: str = "") -> dict:
    """One method on one recording: the track, and the report against ``truth`` when given."""
    from scattertrack import eval as evaluation
    from scattertrack import track as tracking

    if not takes_reads(method):
        raise ValueError(f"method '{method}' does not take reads.csv; the dashboard runs: "
                         + ", ".join(m["name"] for m in reads_methods()))
    start = time.perf_counter()
    result = tracking.run(method, scene, reads, progress=False)
    wall_s = time.perf_counter() - start
    out = {"method": method, "track": payloads.track(result), "wall_s": wall_s, "reads": int(len(reads))}
    if truth is not None:
        out["report"] = payloads.report(evaluation.compare(truth, result), title or f"{method} against the truth")
    return out


def _saved(upload: UploadFile | None, folder: Path, name: str) -> Path | None:
    """An uploaded file written under ``folder`` (the readers take paths; the suffix picks CSV or Parquet)."""
    if upload is None or not upload.filename:
        return None
    path = folder / (name + Path(upload.filename).suffix)
    with open(path, "wb") as handle:
        shutil.copyfileobj(upload.file, handle)
    return path


def _given(path: str | None) -> Path | None:
    if path is None or not path.strip():
        return None
    given = Path(path.strip()).expanduser()
    if not given.is_file():
        raise HTTPException(400, f"{given}: no such file on the server")
    return given


def router() -> APIRouter:
    api = APIRouter(prefix="/api")

    @api.get("/methods")
    def methods() -> list[dict]:
        return reads_methods()

    @api.post("/offline/run")
    def run(
        method: str = Form("glac"),
        scene_path: str | None = Form(None),
        reads_path: str | None = Form(None),
        truth_path: str | None = Form(None),
        scene_file: UploadFile | None = None,
        reads_file: UploadFile | None = None,
        truth_file: UploadFile | None = None,
    ) -> dict:
        from scattertrack import io

        with tempfile.TemporaryDirectory(prefix="scattertrack-dashboard-") as folder:
            folder = Path(folder)
            scene_at = _saved(scene_file, folder, "scene") or _given(scene_path)
            reads_at = _saved(reads_file, folder, "reads") or _given(reads_path)
            truth_at = _saved(truth_file, folder, "truth") or _given(truth_path)
            if scene_at is None or reads_at is None:
                raise HTTPException(400, "give a scene and reads: paths on the server or uploaded files")
            try:
                scene = io.read_scene(scene_at)
                reads = io.read_reads(reads_at, scene)
                truth = io.read_truth(truth_at) if truth_at else None
                out = track_and_report(method, scene, reads, truth, title=f"{method} on {reads_path or 'the upload'}")
            except (ValueError, KeyError, OSError) as error:
                raise HTTPException(400, str(error)) from None
        out["scene"] = payloads.scene(scene)
        out["truth"] = payloads.truth(truth) if truth is not None else None
        return out

    return api
