"""A simulated reader on loopback, in a thread of its own, for the live tests."""

from __future__ import annotations

import asyncio
import contextlib
import threading

import pytest

from scattertrack.readers.emulator import SimulatedReader
from scattertrack.sim import load_scenario, simulate


@pytest.fixture(scope="module")
def walls_simulation():
    """6 s of the two-walls layout (one tag, about 30 reads/s)."""
    scenario = load_scenario("glac-3d-walls")
    scenario["duration_s"] = 6.0
    return simulate(scenario, seed=3)


@contextlib.contextmanager
def emulator_thread(reads, **options):
    """A :class:`SimulatedReader` serving ``reads`` on 127.0.0.1 from a background
    thread; yields it (its ``port`` is set) and stops it on exit (at most 5 s)."""
    ready = threading.Event()
    box = {}

    def serve() -> None:
        loop = asyncio.new_event_loop()
        box["loop"] = loop
        emulator = SimulatedReader(reads, **options)
        loop.run_until_complete(emulator.start())
        box["emulator"] = emulator
        ready.set()
        loop.run_forever()
        loop.run_until_complete(emulator.stop())
        loop.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    assert ready.wait(5.0), "the emulator did not start"
    try:
        yield box["emulator"]
    finally:
        box["loop"].call_soon_threadsafe(box["loop"].stop)
        thread.join(5.0)


@pytest.fixture
def serve_reads():
    """``with serve_reads(reads, **options) as emulator:`` (see :func:`emulator_thread`)."""
    return emulator_thread
