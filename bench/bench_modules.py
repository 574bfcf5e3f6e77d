"""A sibling benchmark script as a module: ``load("run")`` is bench/run.py
(its scoring, tables and JSON helpers), under a module name that cannot
clash with another ``run`` (``scattertrack_bench_run``)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

BENCH = Path(__file__).resolve().parent


def load(name: str):
    """bench/<name>.py, executed as the module ``scattertrack_bench_<name>``."""
    spec = importlib.util.spec_from_file_location(f"scattertrack_bench_{name}", BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
