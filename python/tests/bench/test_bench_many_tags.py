"""bench/many_tags.py runs end to end on a small recording; both paths write the same track."""

import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[3] / "bench" / "many_tags.py"


def test_a_small_run_prints_both_paths_and_identical_tracks():
    result = subprocess.run([sys.executable, str(BENCH), "--tags", "40", "--durations", "3", "--in-memory-up-to", "3"],
                            capture_output=True, text=True, check=True)
    assert "streaming" in result.stdout and "in memory" in result.stdout
    assert "track.csv identical" in result.stdout
