"""bench/live.py runs end to end on a short session and prints its figures."""

import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[3] / "bench" / "live.py"


def test_the_live_bench_runs_and_reports_each_figure():
    done = subprocess.run([sys.executable, str(BENCH), "--duration", "8", "--speed", "8"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    for figure in ("throughput:", "exactly once: emulator sent", "forced disconnect at 4 s", "live vs offline", "median 3D"):
        assert figure in out, out
    sent, held = [int(x.replace(",", "")) for x in out.split("emulator sent ")[1].split(" duplicates")[0].replace("journal holds ", "").split(", ")[:2]]
    assert sent == held > 0


def test_the_live_bench_with_every_output_reads_them_back():
    from robots import MOSQUITTO

    if MOSQUITTO is None:
        import os

        import pytest

        if os.environ.get("CI"):
            pytest.fail("mosquitto is not installed (.ci/run installs it before make test)")
        pytest.skip("mosquitto is not installed (apt-get install -y mosquitto); CI installs it and runs this test")
    done = subprocess.run([sys.executable, str(BENCH), "--duration", "8", "--speed", "8", "--outputs"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "outputs on:" in out and out.count("pose and odom per tag = rows per tag") == 2, out
