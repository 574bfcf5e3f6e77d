"""Each tab in a real browser: Debian's headless Chromium driven by Playwright.

Playwright's pip package brings its own driver but no browser here: it
launches /usr/bin/chromium (``apt-get install chromium``; .ci/run installs
it). Outside CI (``CI`` unset) the tests skip when that browser or the
front-end build is missing; in CI they run.

Each test saves a screenshot of its tab: under pytest's tmp_path, or into
``$SCATTERTRACK_SCREENSHOTS`` when set (``SCATTERTRACK_SCREENSHOTS=docs/images``
renews the pictures docs/dashboard.md shows).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from scattertrack.server.app import default_web_dir

CHROMIUM = Path("/usr/bin/chromium")
TIMEOUT_MS = 120_000
"""Per wait on the page: generous, a busy 2-core machine simulates and tracks in it."""


def _missing() -> str | None:
    if not CHROMIUM.is_file():
        return f"{CHROMIUM} is missing (apt-get install -y chromium chromium-driver)"
    if not (default_web_dir() / "index.html").is_file():
        return f"the front end is not built ({default_web_dir()}): run make setup"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "playwright is not installed (make setup)"
    return None


if _missing() and not os.environ.get("CI"):
    pytest.skip(_missing(), allow_module_level=True)


@pytest.fixture(scope="module")
def server(serve):
    with serve() as url:
        yield url


@pytest.fixture(scope="module")
def browser():
    problem = _missing()
    if problem:  # in CI: fail, do not skip
        pytest.fail(problem)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
        yield browser
        browser.close()


@pytest.fixture
def page(browser):
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    page.set_default_timeout(TIMEOUT_MS)
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    yield page
    page.close()
    assert not errors, f"the page raised: {errors}"


def submit(page, tab: str) -> None:
    """Submit the tab's form once it is ready (enabled when its lists are loaded)."""
    page.locator("form button[type=submit]:enabled").click()


def finished(page, tab: str, done: str = "[data-done]") -> None:
    """Wait until the tab's status says done or shows an error; fail with the error."""
    status = page.locator(f"[data-testid={tab}-status]")
    page.locator(f"[data-testid={tab}-status]{done}, [data-testid={tab}-status].error").wait_for()
    assert "error" not in (status.get_attribute("class") or ""), status.inner_text()


def screenshot(page, tab: str, tmp_path: Path) -> Path:
    folder = Path(os.environ.get("SCATTERTRACK_SCREENSHOTS") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"dashboard-{tab}.png"
    page.screenshot(path=str(path), full_page=True)
    assert path.stat().st_size > 10_000
    return path


def test_config_shows_the_warning_of_three_antennas_on_a_line(server, page, tmp_path):
    page.goto(f"{server}/#config")
    status = page.locator("[data-testid=config-status]")
    status.wait_for()
    assert int(status.get_attribute("data-warnings")) >= 1
    warnings = page.locator("pre.warning").all_inner_texts()
    assert any(w.startswith("warning:") and "line" in w for w in warnings)
    assert "glac-3d-arm-paper-layout" == page.locator("select[name=scenario]").input_value()
    antennas = page.locator("path.antenna").count()
    assert antennas >= 3
    screenshot(page, "config", tmp_path)


def test_offline_draws_every_estimate_of_the_track(server, page, tmp_path):
    from scattertrack import io, sim
    from scattertrack import track as st_track

    simulation = sim.simulate(sim.load_scenario("glac-3d-arm") | {"duration_s": 6}, seed=2)
    out = sim.write_simulation(simulation, tmp_path / "run")
    page.goto(f"{server}/#offline")
    page.fill("input[name=scene_path]", str(out / "scene.toml"))
    page.fill("input[name=reads_path]", str(out / "reads.csv"))
    page.fill("input[name=truth_path]", str(out / "truth.csv"))
    page.locator("select[name=method] option[value=glac]").wait_for(state="attached")
    submit(page, "offline")
    finished(page, "offline", "[data-rows]")
    scene = io.read_scene(out / "scene.toml")
    expected = len(st_track.run("glac", scene, io.read_reads(out / "reads.csv", scene)))
    status = page.locator("[data-testid=offline-status]")
    assert int(status.get_attribute("data-rows")) == expected > 0
    assert page.locator("circle.estimate").count() == expected  # one drawn point per track row
    assert "converged:" in page.locator("[data-testid=report]").inner_text()
    assert page.locator("path.antenna").count() == len(scene.antennas)
    assert page.locator("path.truth").count() == 1  # one tag's true trajectory
    screenshot(page, "offline", tmp_path)


def test_simulation_compares_two_methods(server, page, tmp_path):
    page.goto(f"{server}/#simulation")
    page.locator(".methods input[value=glac]").wait_for()
    page.fill("input[name=duration]", "6")
    submit(page, "simulation")
    finished(page, "simulation")
    rows = page.locator("[data-testid=simulation-table] tbody tr")
    assert rows.count() == 2
    assert rows.nth(0).locator("td").first.inner_text() == "glac"
    assert page.locator("circle.estimate").count() > 0
    screenshot(page, "simulation", tmp_path)


def test_batch_summarises_the_seeds(server, page, tmp_path):
    page.goto(f"{server}/#batch")
    page.locator("select[name=method] option[value=glac]").wait_for(state="attached")
    page.fill("input[name=seeds]", "3")
    page.fill("input[name=duration]", "4")
    submit(page, "batch")
    finished(page, "batch")
    assert page.locator("[data-testid=batch-rows] tbody tr").count() == 3
    assert page.locator("[data-testid=batch-summary] tbody td").first.inner_text() == "3"
    assert page.locator("progress").get_attribute("value") == "1"
    screenshot(page, "batch", tmp_path)


def test_online_draws_estimates_as_they_come(server, page, tmp_path):
    page.goto(f"{server}/#online")
    page.locator("select[name=scenario] option[value=glac-3d-arm]").wait_for(state="attached")
    page.fill("input[name=speed]", "4")
    page.fill("input[name=duration]", "8")
    submit(page, "online")
    status = page.locator("[data-testid=online-status]")
    # While it runs: some estimates drawn already, the table filled.
    page.wait_for_function("document.querySelector('[data-testid=online-status]')?.dataset.estimates > 0")
    finished(page, "online", "[data-state=done]")
    estimates = int(status.get_attribute("data-estimates"))
    assert page.locator("circle.estimate").count() == estimates > 0
    tags = page.locator("[data-testid=online-tags] tbody tr")
    assert tags.count() >= 1
    cells = tags.nth(0).locator("td").all_inner_texts()
    assert int(cells[1]) > 0 and float(cells[2]) > 0  # reads, reads/s
    assert cells[4] != "-"  # sigma
    screenshot(page, "online", tmp_path)


def test_with_a_token_the_page_opened_with_it_works(serve, browser, tmp_path):
    token = "br0wser-t0ken"
    with serve("--token", token, token=token) as url:
        page = browser.new_page()
        page.set_default_timeout(TIMEOUT_MS)
        assert page.goto(f"{url}/#config").status == 401
        page.goto(f"{url}/?token={token}#config")  # assets and API requests carry it too
        page.locator("[data-testid=config-status]").wait_for()
        assert int(page.locator("[data-testid=config-status]").get_attribute("data-warnings")) >= 1
        page.close()
