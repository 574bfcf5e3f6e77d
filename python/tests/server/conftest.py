"""A real dashboard server for the tests: ``scattertrack dashboard`` in a
subprocess on a free loopback port, bounded in time, stopped afterwards."""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request

import pytest

START_TIMEOUT_S = 90.0
"""Generous: importing numpy, FastAPI and the Rust core on a busy 2-core machine."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def request(url: str, token: str | None = None, timeout: float = 30.0) -> tuple[int, str]:
    """(status, body) of a GET; an HTTP error status is returned, not raised."""
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers), timeout=timeout) as answer:
            return answer.status, answer.read().decode()
    except urllib.error.HTTPError as error:
        return error.code, error.read().decode()


@contextlib.contextmanager
def dashboard(*args: str, token: str | None = None, env: dict | None = None):
    """Run ``scattertrack dashboard --port P ARGS``; yields its base URL once it answers."""
    port = free_port()
    environment = {k: v for k, v in os.environ.items() if k != "SCATTERTRACK_TOKEN"} | (env or {})
    command = [sys.executable, "-m", "scattertrack", "dashboard", "--port", str(port), *args]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=environment)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            if process.poll() is not None:
                pytest.fail(f"the dashboard exited with {process.returncode}: {process.stdout.read()}")
            try:
                status, _ = request(f"{url}/api/health", token=token, timeout=2)
                if status == 200:
                    break
            except OSError:
                pass
            if time.monotonic() > deadline:
                pytest.fail(f"the dashboard did not answer within {START_TIMEOUT_S:g} s")
            time.sleep(0.2)
        yield url
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


@pytest.fixture(scope="session")
def serve():
    """``with serve(*args, token=..., env=...) as url``: a dashboard for one test."""
    return dashboard


@pytest.fixture
def get():
    """``get(url, token=None) -> (status, body)``."""
    return request
