"""The command's process settings (scattertrack.process)."""

import subprocess
import sys

import pytest

from scattertrack.process import prefer_small_pages

PR_GET_THP_DISABLE = 42


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl is Linux's")
def test_small_pages_are_set_for_the_process_that_asks():
    # In a child, so the test process keeps its own setting.
    code = (
        "import ctypes; from scattertrack.process import prefer_small_pages; "
        "libc = ctypes.CDLL(None); before = libc.prctl(42, 0, 0, 0, 0); "
        "ok = prefer_small_pages(); print(before, ok, libc.prctl(42, 0, 0, 0, 0))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out[1:] == ["True", "1"], out


def test_it_never_raises(monkeypatch):
    monkeypatch.setattr(sys, "platform", "darwin")
    assert prefer_small_pages() is False
