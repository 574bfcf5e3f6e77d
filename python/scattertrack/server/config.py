"""The config tab: a scene's TOML edited in the page, its geometry check and its antennas."""

from __future__ import annotations

import tempfile
from pathlib import Path

from fastapi import APIRouter, HTTPException
from pydantic import BaseModel

from scattertrack.server import payloads
from scattertrack.server.simulation import load


class SceneText(BaseModel):
    toml: str


def scene_text(scenario: str) -> str:
    """The scene a scenario simulates, as the TOML a user would write (a 0.1 s run gives it)."""
    from scattertrack import sim

    simulation = sim.simulate(load(scenario, 0.1))
    with tempfile.TemporaryDirectory(prefix="scattertrack-dashboard-") as folder:
        path = Path(folder) / "scene.toml"
        simulation.scene.save(path)
        return path.read_text()


def check(text: str) -> dict:
    """The lines of ``scattertrack check-scene``, calibration first, then the geometry."""
    from scattertrack import check, io
    from scattertrack.check.calibration import calibration_lines

    with tempfile.TemporaryDirectory(prefix="scattertrack-dashboard-") as folder:
        path = Path(folder) / "scene.toml"
        path.write_text(text)
        scene = io.read_scene(path)  # a FormatError names the line and column of the edit
    if scene.reader.kind == "sdr-helper":
        lines = check.check_helper_scene(scene).lines()
    elif scene.reader.kind == "cots":
        lines = list(calibration_lines(scene)) + list(check.check_scene(scene, None).lines())
    else:
        lines = [f"note: the geometry check covers reader scenes, not {scene.reader.kind!r}"]
    return {"scene": payloads.scene(scene), "lines": lines,
            "warnings": sum(line.startswith("warning:") for line in lines)}


def router() -> APIRouter:
    api = APIRouter(prefix="/api/config")

    @api.get("/scene")
    def scene(scenario: str = "glac-3d-arm") -> dict:
        try:
            return {"scenario": scenario, "toml": scene_text(scenario)}
        except (ValueError, KeyError, OSError) as error:
            raise HTTPException(400, str(error)) from None

    @api.post("/check")
    def run_check(body: SceneText) -> dict:
        try:
            return check(body.toml)
        except (ValueError, KeyError, OSError) as error:
            raise HTTPException(400, str(error).replace(tempfile.gettempdir(), "<edited>")) from None

    return api
