"""The simulation tab: a named scenario simulated once, tracked by several methods, compared."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, Field

from scattertrack.server import payloads
from scattertrack.server.jobs import Job, Jobs
from scattertrack.server.offline import track_and_report


class SimulationRequest(BaseModel):
    scenario: str
    methods: list[str] = Field(default_factory=lambda: ["glac"])
    seed: int | None = Field(None, ge=0)
    duration_s: float | None = Field(None, gt=0, le=3600)


def load(name: str, duration_s: float | None = None) -> dict:
    """A shipped COTS-reader scenario, optionally shortened."""
    from scattertrack import sim

    if name not in sim.list_scenarios("glac"):
        raise ValueError(f"unknown scenario {name!r} (the dashboard runs: {', '.join(sim.list_scenarios('glac'))})")
    scenario = sim.load_scenario(name)
    return scenario | {"duration_s": duration_s} if duration_s is not None else scenario


def comparison_row(method: str, result: dict) -> dict:
    """One line of a comparison table: the accuracy and speed of one method on one run."""
    overall = result["report"]["summary"]["overall"]
    return {
        "method": method,
        "rows": result["track"]["rows"],
        "median_3d_m": overall["median_3d_m"],
        "p90_3d_m": overall["p90_3d_m"],
        "convergence_time_s": overall["convergence_time_s"],
        "wall_s": result["wall_s"],
    }


def router(jobs: Jobs) -> APIRouter:
    api = APIRouter(prefix="/api")

    @api.get("/scenarios")
    def scenarios() -> list[dict]:
        from scattertrack import sim

        return [
            {"name": name, "description": sim.load_scenario(name).get("description", "")}
            for name in sim.list_scenarios("glac")
        ]

    @api.post("/simulation/run")
    def run(request: SimulationRequest) -> dict:
        def work(job: Job) -> dict:
            from scattertrack import sim

            job.update(0.05, f"simulating {request.scenario}")
            simulation = sim.simulate(load(request.scenario, request.duration_s), seed=request.seed)
            results = {}
            for i, method in enumerate(request.methods):
                job.update(0.2 + 0.8 * i / len(request.methods), f"tracking with {method}")
                results[method] = track_and_report(method, simulation.scene, simulation.reads, simulation.truth,
                                                   title=f"{method} on {request.scenario}, seed {simulation.seed}")
            return {
                "scenario": request.scenario,
                "seed": simulation.seed,
                "scene": payloads.scene(simulation.scene),
                "truth": payloads.truth(simulation.truth),
                "results": results,
                "table": [comparison_row(m, r) for m, r in results.items()],
            }

        return {"job": jobs.start("simulation", work).id}

    return api
