"""Long work (a simulation, a batch of seeds, a real-time replay) in a background thread.

A request starts a :class:`Job` and returns its id at once; the page polls
``GET /api/jobs/{id}`` for the progress and, at the end, the result or the
error. Jobs live in memory for the server's lifetime (a dashboard is one
user's tool, not a queue): the oldest finished ones are forgotten beyond
``KEEP``.
"""

from __future__ import annotations

import itertools
import threading
import time
import traceback
from collections import OrderedDict
from typing import Any, Callable

from fastapi import APIRouter, HTTPException

KEEP = 50
"""Finished jobs kept for polling."""


class Cancelled(Exception):
    """Raised inside a job's work when the user stopped it."""


class Job:
    """One piece of work: progress in [0, 1], a message, then a result or an error."""

    def __init__(self, job_id: str, kind: str):
        self.id, self.kind = job_id, kind
        self.progress = 0.0
        self.message = "queued"
        self.state = "running"  # running | done | error | cancelled
        self.result: Any = None
        self.error: str | None = None
        self.live: dict = {}
        """What a running job shows before its end, as JSON (the batch tab's rows so far)."""
        self.context: Any = None
        """A router's own state of the job, not sent by ``GET /api/jobs`` (the online tab's replay)."""
        self.started = time.time()
        self._stop = threading.Event()
        self.lock = threading.Lock()

    def update(self, progress: float | None = None, message: str | None = None) -> None:
        """Report progress; raises :class:`Cancelled` once the user stopped the job."""
        if self._stop.is_set():
            raise Cancelled()
        if progress is not None:
            self.progress = min(max(float(progress), 0.0), 1.0)
        if message is not None:
            self.message = message

    def stop(self) -> None:
        self._stop.set()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    def to_json(self) -> dict:
        with self.lock:
            return {
                "id": self.id,
                "kind": self.kind,
                "state": self.state,
                "progress": self.progress,
                "message": self.message,
                "result": self.result,
                "error": self.error,
                "live": self.live,
            }


class Jobs:
    """The server's jobs, by id."""

    def __init__(self):
        self._jobs: OrderedDict[str, Job] = OrderedDict()
        self._ids = itertools.count(1)
        self._lock = threading.Lock()

    def start(self, kind: str, work: Callable[[Job], Any]) -> Job:
        """Run ``work(job)`` in a daemon thread; its return value becomes the result."""
        with self._lock:
            job = Job(f"{kind}-{next(self._ids)}", kind)
            self._jobs[job.id] = job
            self._forget_old()

        def target():
            try:
                result = work(job)
                with job.lock:
                    job.result, job.state, job.progress = result, "done", 1.0
                    job.message = "done"
            except Cancelled:
                job.state, job.message = "cancelled", "stopped"
            except (ValueError, KeyError, OSError) as error:
                # The user's input (a bad file, an unknown method): the message is enough.
                job.state, job.error = "error", str(error.args[0] if isinstance(error, KeyError) and error.args else error)
            except Exception:  # a bug: show it rather than lose it in a thread
                job.state, job.error = "error", traceback.format_exc(limit=5)

        threading.Thread(target=target, name=job.id, daemon=True).start()
        return job

    def get(self, job_id: str) -> Job:
        with self._lock:
            job = self._jobs.get(job_id)
        if job is None:
            raise HTTPException(404, f"no job {job_id}")
        return job

    def _forget_old(self) -> None:
        finished = [j for j in self._jobs.values() if j.state != "running"]
        for job in finished[: max(0, len(finished) - KEEP)]:
            del self._jobs[job.id]


def router(jobs: Jobs) -> APIRouter:
    api = APIRouter(prefix="/api/jobs")

    @api.get("/{job_id}")
    def poll(job_id: str) -> dict:
        return jobs.get(job_id).to_json()

    @api.post("/{job_id}/stop")
    def stop(job_id: str) -> dict:
        job = jobs.get(job_id)
        job.stop()
        return job.to_json()

    return api
