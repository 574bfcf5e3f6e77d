"""The API behind each tab, in-process (FastAPI's test client), and the page
for a missing front-end build."""

from __future__ import annotations

import time

import pytest
from fastapi.testclient import TestClient

from scattertrack.server.app import create_app

PAPER_LAYOUT = "glac-3d-arm-paper-layout"


@pytest.fixture(scope="module")
def client():
    with TestClient(create_app()) as client:
        yield client


def finished(client, job_id: str, timeout_s: float = 300.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = client.get(f"/api/jobs/{job_id}").json()
        if job["state"] != "running":
            assert job["state"] == "done", job["error"]
            return job
        time.sleep(0.1)
    pytest.fail(f"job {job_id} did not end within {timeout_s:g} s")


def test_missing_build_is_a_clear_page(tmp_path):
    with TestClient(create_app(web_dir=tmp_path)) as client:
        answer = client.get("/")
        assert answer.status_code == 503
        assert "not built" in answer.text and "make setup" in answer.text
        assert client.get("/api/health").json()["ok"]


def test_with_a_token_the_page_names_its_assets_with_it(tmp_path):
    (tmp_path / "index.html").write_text('<script type="module" src="./assets/index-1.js"></script>'
                                         '<link rel="stylesheet" href="./assets/index-2.css">')
    (tmp_path / "assets").mkdir()
    (tmp_path / "assets" / "index-1.js").write_text("1")
    with TestClient(create_app(token="a&b", web_dir=tmp_path)) as client:
        page = client.get("/?token=a%26b").text
        assert 'src="./assets/index-1.js?token=a%26b"' in page and 'index-2.css?token=a%26b"' in page
        assert client.get("/assets/index-1.js?token=a%26b").status_code == 200
        assert client.get("/assets/index-1.js").status_code == 401


def test_methods_and_scenarios(client):
    names = [m["name"] for m in client.get("/api/methods").json()]
    assert "glac" in names and "turbotrack" not in names
    scenarios = [s["name"] for s in client.get("/api/scenarios").json()]
    assert PAPER_LAYOUT in scenarios and not any(s.startswith("marvel") for s in scenarios)


def test_config_warns_for_three_antennas_on_a_line(client):
    text = client.get("/api/config/scene", params={"scenario": PAPER_LAYOUT}).json()["toml"]
    checked = client.post("/api/config/check", json={"toml": text}).json()
    assert checked["warnings"] >= 1
    assert any(line.startswith("warning:") and "line" in line for line in checked["lines"])
    assert len(checked["scene"]["antennas"]) >= 3


def test_config_names_the_line_of_a_bad_edit(client):
    answer = client.post("/api/config/check", json={"toml": "[reader\nkind = 1\n"})
    assert answer.status_code == 400
    assert "line 1" in answer.json()["detail"]


def test_offline_run_by_path_and_upload(client, tmp_path):
    from scattertrack import sim

    simulation = sim.simulate(sim.load_scenario("glac-3d-arm") | {"duration_s": 4}, seed=3)
    out = sim.write_simulation(simulation, tmp_path)
    by_path = client.post("/api/offline/run", data={
        "method": "glac", "scene_path": str(out / "scene.toml"), "reads_path": str(out / "reads.csv"),
        "truth_path": str(out / "truth.csv")}).json()
    assert by_path["track"]["rows"] > 0
    assert by_path["track"]["rows"] == sum(t["rows"] for t in by_path["track"]["tags"].values())
    assert "converged:" in by_path["report"]["text"]
    with open(out / "scene.toml", "rb") as scene, open(out / "reads.csv", "rb") as reads:
        uploaded = client.post("/api/offline/run", data={"method": "glac"},
                               files={"scene_file": ("scene.toml", scene), "reads_file": ("reads.csv", reads)}).json()
    assert uploaded["track"]["rows"] == by_path["track"]["rows"]
    assert uploaded["report"] is None if "report" in uploaded else True
    missing = client.post("/api/offline/run", data={"scene_path": str(tmp_path / "nope.toml"), "reads_path": "x"})
    assert missing.status_code == 400 and "no such file" in missing.json()["detail"]


def test_simulation_compares_methods(client):
    job = client.post("/api/simulation/run", json={"scenario": "glac-3d-arm", "seed": 1, "duration_s": 3,
                                                    "methods": ["glac", "glac-no-velocity"]}).json()["job"]
    result = finished(client, job)["result"]
    assert [row["method"] for row in result["table"]] == ["glac", "glac-no-velocity"]


def test_batch_over_seeds(client):
    job = client.post("/api/batch/run", json={"scenario": "glac-3d-arm", "seeds": 2, "duration_s": 3}).json()["job"]
    result = finished(client, job)["result"]
    assert [row["seed"] for row in result["rows"]] == [0, 1] and result["summary"]["seeds"] == 2


def test_online_replay_draws_every_estimate(client):
    job = client.post("/api/online/start", json={"scenario": "glac-3d-arm", "speed": 20, "duration_s": 2}).json()["job"]
    finished(client, job)
    state = client.get(f"/api/online/{job}").json()
    assert state["total"] == len(state["points"]) > 0
    assert all(tag["reads"] > 0 and tag["reads_per_s"] > 0 for tag in state["tags"])
    assert client.get(f"/api/online/{job}", params={"since": state["total"]}).json()["points"] == []


def test_online_from_an_llrp_reader(client, tmp_path):
    """The reader emulator on loopback, read through the server's LiveSession."""
    import socket
    import subprocess
    import sys

    from scattertrack import sim

    scenario = "glac-3d-arm"
    out = sim.write_simulation(sim.simulate(sim.load_scenario(scenario)), tmp_path / "session")
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    emulator = subprocess.Popen([sys.executable, "-m", "scattertrack", "emulate-reader", "--scenario", scenario,
                                 "--port", str(port), "--speed", "4"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        job = client.post("/api/online/start", json={
            "source": "llrp", "scene_path": str(out / "scene.toml"), "llrp": f"127.0.0.1:{port}",
            "duration_s": 8, "out_dir": str(tmp_path / "live")}).json()["job"]
        # The session reconnects until the emulator listens; stop it once estimates came.
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            state = client.get(f"/api/online/{job}").json()
            if state.get("total", 0) > 10 or state["state"] != "running":
                break
            time.sleep(0.2)
        client.post(f"/api/jobs/{job}/stop")
        result = finished(client, job)["result"]
    finally:
        emulator.terminate()
        emulator.wait(timeout=20)
    state = client.get(f"/api/online/{job}").json()
    assert state["total"] == len(state["points"]) == result["estimates"] > 10
    assert (tmp_path / "live" / "reads.csv").stat().st_size > 0
    assert state["tags"][0]["reads"] == result["reads"]
