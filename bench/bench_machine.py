"""The machine a benchmark ran on, as the reports name it."""

from __future__ import annotations

from pathlib import Path


def cpu_model(default: str) -> str:
    """The CPU's model name as /proc/cpuinfo gives it; ``default`` where it gives none."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return default
