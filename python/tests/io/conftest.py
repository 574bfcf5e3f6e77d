"""Fixtures for the format reader/writer tests."""

from pathlib import Path

import pytest

REPOSITORY_ROOT = Path(__file__).resolve().parents[3]
EXAMPLES = REPOSITORY_ROOT.parent / "shared" / "examples"
"""Files written by an independent program (docs/formats.md examples), beside the repository."""


@pytest.fixture
def examples() -> Path:
    """The shared examples folder; the test is skipped where it is absent."""
    if not EXAMPLES.is_dir():
        pytest.skip(f"shared examples not found at {EXAMPLES}")
    return EXAMPLES


@pytest.fixture
def write_file(tmp_path):
    """``write_file(name, text)`` writes a file in a temporary folder and returns its path."""

    def write(name: str, text: str, encoding: str = "utf-8") -> Path:
        path = tmp_path / name
        path.write_bytes(text.encode(encoding))
        return path

    return write
