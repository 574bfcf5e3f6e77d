"""Every benchmark, run in turn; their printed figures rendered into a results page.

    .venv/bin/python bench/results.py                      # make bench: out/bench/results.md
    .venv/bin/python bench/results.py --write docs/results.md   # make results
    .venv/bin/python bench/results.py --only marvel --write docs/results.md
    .venv/bin/python bench/results.py --render-only --write docs/results.md

The list of benchmarks lives here (``BENCHMARKS``), once: the Makefile's
``bench`` and ``results`` targets call this script. Each benchmark's
output is shown as it runs and kept in ``out/bench/<key>.txt``; the page
is ``bench/results.md.in`` with every ``{{key}}`` replaced by that output,
under a header naming the version, the commit, the date and the machine.
No figure on the page is typed by hand: the prose in the template says
what a block measures and how to read it, the blocks carry the numbers.
``--only`` re-runs some benchmarks and renders the page from the kept
outputs of the others (each block says when and at which commit it ran).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PY = sys.executable

BENCHMARKS: list[tuple[str, list[str]]] = [
    ("criterion-core", ["cargo", "bench", "-q", "-p", "scattertrack-core", "--bench", "glac", "--bench", "turbotrack", "--", "--quick"]),
    ("criterion-dsp", ["cargo", "bench", "-q", "-p", "scattertrack-dsp", "--bench", "dsp", "--", "--quick"]),
    ("glac", [PY, "bench/run.py"]),
    ("read-cost", [PY, "bench/read_cost.py"]),
    ("glac-ambiguity", [PY, "bench/glac_ambiguity.py", "--seeds", "100"]),
    ("glac-ambiguity-modpi", [PY, "bench/glac_ambiguity.py", "--scenario", "glac-2d-40cms-modpi", "--seeds", "100", "--q", "2"]),
    ("glac-robustness", [PY, "bench/glac_robustness.py", "--seeds", "100", "--json", "out/bench/glac_robustness.json"]),
    ("glac-ambiguity-raised", [PY, "bench/glac_ambiguity.py", "--scenario", "glac-3d-raised", "--seeds", "100"]),
    ("glac-ambiguity-workcell", [PY, "bench/glac_ambiguity.py", "--scenario", "glac-3d-workcell", "--seeds", "100"]),
    ("glac-ambiguity-overhead", [PY, "bench/glac_ambiguity.py", "--scenario", "glac-3d-overhead", "--seeds", "100"]),
    ("glac-impairments", [PY, "bench/glac_impairments.py", "--seeds", "100"]),
    ("turbotrack", [PY, "bench/turbotrack.py"]),
    ("marvel", [PY, "bench/marvel.py"]),
    ("live", [PY, "bench/live.py"]),
    ("calibration", [PY, "bench/calibration.py"]),
    ("batch", [PY, "bench/batch.py"]),
    ("many-tags", [PY, "bench/many_tags.py"]),
]
"""(key, command): run from the repository root, in this order."""

OUT = ROOT / "out" / "bench"
TEMPLATE = ROOT / "bench" / "results.md.in"
CRITERION_LINE = re.compile(r"^\S.*time:\s+\[")


def machine() -> str:
    """CPU model, cores, memory and OS, as this machine reports them."""
    from bench_machine import cpu_model

    model = cpu_model(platform.processor() or platform.machine())
    memory = ""
    try:
        kib = int(next(line for line in Path("/proc/meminfo").read_text().splitlines() if line.startswith("MemTotal")).split()[1])
        memory = f", {kib / 2**20:.0f} GiB"
    except (OSError, StopIteration, ValueError):
        pass
    return f"{model}, {os.cpu_count()} cores{memory}, {platform.system()} {platform.release()}"


def commit() -> str:
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True).stdout.strip()

    head = git("rev-parse", "--short", "HEAD") or "unknown"
    return head + (" (with uncommitted changes)" if git("status", "--porcelain", "--untracked-files=no") else "")


def version() -> str:
    text = (ROOT / "python" / "pyproject.toml").read_text()
    found = re.search(r'^version\s*=\s*"([^"]+)"', text, re.M)
    return found.group(1) if found else "unknown"


def run(key: str, command: list[str]) -> dict:
    """Runs one benchmark, echoing its output; keeps it in out/bench/<key>.txt."""
    print(f"bench: {key}: {' '.join(Path(c).name if c == PY else c for c in command)}", flush=True)
    start = time.perf_counter()
    lines = []
    with subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1) as process:
        for line in process.stdout:
            sys.stdout.write(line)
            lines.append(line.rstrip("\n"))
    record = {
        "key": key,
        "command": " ".join(".venv/bin/python" if c == PY else c for c in command),
        "exit": process.returncode,
        "wall_s": round(time.perf_counter() - start, 1),
        "when": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": commit(),
    }
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"{key}.txt").write_text("\n".join(lines) + "\n")
    (OUT / f"{key}.json").write_text(json.dumps(record, indent=1) + "\n")
    return record


def block(key: str) -> str:
    """The kept output of one benchmark as a fenced block, with its command and run."""
    text_path, record_path = OUT / f"{key}.txt", OUT / f"{key}.json"
    if not text_path.exists() or not record_path.exists():
        return f"*`{key}` has not been run yet: `.venv/bin/python bench/results.py --only {key}`.*"
    record = json.loads(record_path.read_text())
    lines = text_path.read_text().splitlines()
    if key.startswith("criterion"):
        # criterion's report: the benchmark names and their time lines, not its progress chatter.
        kept = []
        for i, line in enumerate(lines):
            if CRITERION_LINE.match(line) or (line.strip().startswith("time:") and i and lines[i - 1].strip()):
                kept.append(line if CRITERION_LINE.match(line) else f"{lines[i - 1].strip()}  {line.strip()}")
        lines = kept or lines
    status = "" if record["exit"] == 0 else f", **exit status {record['exit']}**"
    return (f"`{record['command']}` ({record['when']}, commit {record['commit']}, {record['wall_s']:.0f} s{status}):\n\n"
            "```text\n" + "\n".join(lines).strip("\n") + "\n```")


def render(write: Path) -> None:
    template = TEMPLATE.read_text()
    keys = {key for key, _ in BENCHMARKS}
    unknown = set(re.findall(r"\{\{([\w-]+)\}\}", template)) - keys - {"header"}
    if unknown:
        raise SystemExit(f"{TEMPLATE}: unknown benchmark(s) {', '.join(sorted(unknown))}")
    header = (
        "<!-- Generated by `.venv/bin/python bench/results.py --write docs/results.md` (make results) "
        "from bench/results.md.in and the benchmarks' printed output: do not edit by hand. -->\n\n"
        f"*scattertrack {version()}, rendered {dt.datetime.now(dt.timezone.utc):%Y-%m-%d %H:%M UTC} at commit {commit()}; "
        f"machine: {machine()}. Seeds are those each command states (accuracy on seeds 0–N−1, defaults chosen on seeds ≥ 1000).*\n"
    )
    page = template.replace("{{header}}", header)
    page = re.sub(r"\{\{([\w-]+)\}\}", lambda m: block(m.group(1)), page)
    write.parent.mkdir(parents=True, exist_ok=True)
    write.write_text(page)
    print(f"bench: wrote {write.relative_to(ROOT) if write.is_relative_to(ROOT) else write}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", type=Path, default=OUT / "results.md", help="the page to render (default out/bench/results.md)")
    parser.add_argument("--only", action="append", default=[], help="run only this benchmark (repeatable); the others' kept outputs are used")
    parser.add_argument("--render-only", action="store_true", help="run nothing; render from the kept outputs")
    parser.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    args = parser.parse_args()
    if args.list:
        for key, command in BENCHMARKS:
            print(f"{key:22s} {' '.join('.venv/bin/python' if c == PY else c for c in command)}")
        return 0
    keys = [key for key, _ in BENCHMARKS]
    for key in args.only:
        if key not in keys:
            parser.error(f"unknown benchmark {key!r} (known: {', '.join(keys)})")
    failed = []
    if not args.render_only:
        for key, command in BENCHMARKS:
            if not args.only or key in args.only:
                if run(key, command)["exit"] != 0:
                    failed.append(key)
    render(args.write if args.write.is_absolute() else Path.cwd() / args.write)
    if failed:
        print(f"bench: failed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
