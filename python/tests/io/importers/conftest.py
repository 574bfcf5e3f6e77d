"""Fixtures for the importer tests: the samples (written for these tests) and helpers."""

from pathlib import Path

import pytest

from scattertrack.io import read_scene

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.fixture
def data() -> Path:
    """The folder of sample logs (python/tests/io/data)."""
    return DATA


@pytest.fixture
def scene():
    """A 4-antenna COTS scene without a hop table."""
    return read_scene(DATA / "import_scene.toml")
