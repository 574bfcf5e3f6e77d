"""The batch tab: one scenario over many seeds, one method, a summary table with progress."""

from __future__ import annotations

import math
import statistics

from fastapi import APIRouter
from pydantic import BaseModel, Field

from scattertrack.server.jobs import Job, Jobs
from scattertrack.server.offline import track_and_report
from scattertrack.server.simulation import comparison_row, load


class BatchRequest(BaseModel):
    scenario: str
    method: str = "glac"
    seeds: int = Field(10, ge=1, le=1000)
    first_seed: int = Field(0, ge=0)
    duration_s: float | None = Field(None, gt=0, le=3600)


def summary(rows: list[dict]) -> dict:
    """Medians over the seeds; convergence as the share of seeds that converged."""
    def median(key):
        values = [r[key] for r in rows if r[key] is not None and math.isfinite(r[key])]
        return statistics.median(values) if values else None

    converged = [r for r in rows if r["convergence_time_s"] is not None]
    return {
        "seeds": len(rows),
        "median_3d_m": median("median_3d_m"),
        "p90_3d_m": median("p90_3d_m"),
        "convergence_time_s": median("convergence_time_s"),
        "converged_share": len(converged) / len(rows) if rows else None,
    }


def router(jobs: Jobs) -> APIRouter:
    api = APIRouter(prefix="/api")

    @api.post("/batch/run")
    def run(request: BatchRequest) -> dict:
        def work(job: Job) -> dict:
            from scattertrack import sim

            scenario = load(request.scenario, request.duration_s)
            rows = []
            for i in range(request.seeds):
                seed = request.first_seed + i
                job.update(i / request.seeds, f"seed {seed} ({i + 1} of {request.seeds})")
                simulation = sim.simulate(scenario, seed=seed)
                result = track_and_report(request.method, simulation.scene, simulation.reads, simulation.truth)
                rows.append({"seed": seed} | comparison_row(request.method, result))
                with job.lock:
                    job.live = {"rows": list(rows)}  # the table grows while it runs
            return {"scenario": request.scenario, "method": request.method, "rows": rows, "summary": summary(rows)}

        return {"job": jobs.start("batch", work).id}

    return api
