"""The online tab: a live source tracked as it reads, drawn as estimates come.

Two sources: the simulator replayed in real time (``speed`` times the
recorded timing: each read is handed to a causal tracker,
``scattertrack.track.make(...).step``, when its time comes), or an LLRP
reader (a real one or ``scattertrack emulate-reader``) through
:class:`scattertrack.readers.live.LiveSession`, exactly as
``scattertrack live`` runs it, journal and track files included. The page
polls ``GET /api/online/{job}?since=N`` for the estimates after the N it has.
"""

from __future__ import annotations

import asyncio
import math
import tempfile
import time
from pathlib import Path
from typing import Literal

import numpy as np
from fastapi import APIRouter
from pydantic import BaseModel, Field

from scattertrack.server import payloads
from scattertrack.server.jobs import Job, Jobs
from scattertrack.server.simulation import load


class OnlineRequest(BaseModel):
    source: Literal["replay", "llrp"] = "replay"
    scenario: str = "glac-3d-arm"
    scene_path: str | None = None
    """llrp: the scene.toml whose antenna ids are the reader's ports."""
    llrp: str | None = None
    """llrp: HOST[:PORT] of the reader."""
    out_dir: str | None = None
    """llrp: where the journal (reads.csv) and track.csv go (default: a new temporary folder)."""
    method: str = "glac"
    speed: float = Field(1.0, gt=0, le=1000)
    duration_s: float | None = Field(None, gt=0, le=3600)
    seed: int | None = Field(None, ge=0)


class Replay:
    """The state the page polls: every estimate so far, and per tag its counters."""

    def __init__(self, scene):
        self.scene = payloads.scene(scene)
        self.points: list[list] = []
        """[time s, epc, x, y, z, sigma m] per estimate, in arrival order."""
        self.tags: dict[str, dict] = {}
        self.reads = 0
        self.started = time.monotonic()

    def read(self, epc: str) -> None:
        self.reads += 1
        tag = self.tags.setdefault(epc, {"epc": epc, "reads": 0, "estimates": 0, "sigma_m": None, "position": None})
        tag["reads"] += 1

    def estimate(self, epc: str, estimate) -> None:
        sigma = math.sqrt(max(float(np.trace(estimate.covariance[:3, :3])), 0.0))
        position = [payloads.number(v) for v in estimate.position]
        self.points.append([float(estimate.time_s), epc, *position, payloads.number(sigma)])
        tag = self.tags[epc]
        tag["estimates"] += 1
        tag["sigma_m"], tag["position"] = payloads.number(sigma), position

    def table(self) -> list[dict]:
        """Per tag: reads, reads/s over the wall-clock time since the start, the latest sigma."""
        elapsed = max(time.monotonic() - self.started, 1e-9)
        return [tag | {"reads_per_s": tag["reads"] / elapsed} for tag in self.tags.values()]


def replay(job: Job, request: OnlineRequest) -> dict:
    from scattertrack import sim
    from scattertrack import track as tracking

    simulation = sim.simulate(load(request.scenario, request.duration_s), seed=request.seed)
    reads = simulation.reads
    tracker = tracking.make(request.method, simulation.scene)
    state = Replay(simulation.scene)
    job.context = state
    duration = float(reads.time_s[-1] - reads.time_s[0]) if len(reads) else 0.0
    t0 = float(reads.time_s[0]) if len(reads) else 0.0
    for i in range(len(reads)):
        due = state.started + (float(reads.time_s[i]) - t0) / request.speed
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)  # real time: the read "arrives" now
        job.update((float(reads.time_s[i]) - t0) / duration if duration else 1.0, f"replaying {request.scenario}")
        epc = str(reads.epc[i])
        with job.lock:
            state.read(epc)
        estimate = tracker.step(float(reads.time_s[i]), epc, int(reads.antenna[i]), float(reads.frequency_hz[i]),
                                float(reads.phase_rad[i]))
        if estimate is not None:
            with job.lock:
                state.estimate(epc, estimate)
    return {"reads": state.reads, "estimates": len(state.points)}


class Recording:
    """The tracker handed to a LiveSession: tracks, and tells the page's state each read and estimate."""

    def __init__(self, tracker, state: Replay, job: Job):
        self.tracker, self.state, self.job = tracker, state, job

    def step(self, time_s, epc, antenna, frequency_hz, phase_rad):
        estimate = self.tracker.step(time_s, epc, antenna, frequency_hz, phase_rad)
        with self.job.lock:
            self.state.read(epc)
            if estimate is not None:
                self.state.estimate(epc, estimate)
        return estimate

    def __getattr__(self, name):  # stats() and the rest: the tracker's own
        return getattr(self.tracker, name)


def from_reader(job: Job, request: OnlineRequest) -> dict:
    """``scattertrack live`` inside the server: until ``duration_s`` or the user's stop."""
    from scattertrack import io
    from scattertrack import track as tracking
    from scattertrack.arguments import host_and_port
    from scattertrack.readers.live import LiveSession

    if not request.scene_path or not request.llrp:
        raise ValueError("an LLRP source needs the scene (a path on the server) and the reader's HOST[:PORT]")
    try:
        host, port = host_and_port(request.llrp.strip())
    except Exception as error:  # argparse's error type: the message is what matters
        raise ValueError(str(error)) from None
    scene = io.read_scene(Path(request.scene_path).expanduser())
    out = Path(request.out_dir).expanduser() if request.out_dir else Path(tempfile.mkdtemp(prefix="scattertrack-live-"))
    out.mkdir(parents=True, exist_ok=True)
    state = Replay(scene)
    job.context = state
    tracker = Recording(tracking.make(request.method, scene), state, job)
    session = LiveSession(scene, host, port, out / "reads.csv", out / "track.csv", tracker,
                          duration_s=request.duration_s)

    async def run():
        stop = asyncio.Event()
        watcher = asyncio.create_task(watch(stop))
        try:
            return await session.run(stop)
        finally:
            watcher.cancel()

    async def watch(stop: asyncio.Event):
        # The user's stop (a thread-safe flag) becomes the session's stop event.
        while not job.stopping:
            elapsed = time.monotonic() - state.started
            job.message = f"reading from {host}:{port}"
            if request.duration_s:
                job.progress = min(elapsed / request.duration_s, 1.0)
            await asyncio.sleep(0.2)
        stop.set()

    job.message = f"connecting to {host}:{port}"
    summary = asyncio.run(run())
    return {"reads": summary.reads, "estimates": summary.estimates, "journal": str(out / "reads.csv"),
            "track": str(out / "track.csv"), "declined": dict(summary.declined)}


def router(jobs: Jobs) -> APIRouter:
    api = APIRouter(prefix="/api/online")

    @api.post("/start")
    def start(request: OnlineRequest) -> dict:
        if request.source == "llrp":
            return {"job": jobs.start("online", lambda job: from_reader(job, request)).id}
        load(request.scenario)  # an unknown scenario fails in the request, not later in the job
        return {"job": jobs.start("online", lambda job: replay(job, request)).id}

    @api.get("/{job_id}")
    def poll(job_id: str, since: int = 0) -> dict:
        job = jobs.get(job_id)
        with job.lock:
            state = job.context
            out = {"state": job.state, "message": job.message, "progress": job.progress, "error": job.error}
            if state is not None:
                out |= {"scene": state.scene, "points": state.points[max(since, 0):], "total": len(state.points),
                        "tags": state.table(), "reads": state.reads}
        return out

    return api
