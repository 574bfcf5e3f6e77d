"""A sibling benchmark script as a module: ``load("run")`` is bench/run.py
(its scoring, tables and JSON helpers), under a module name that cannot
clash with another ``run`` (``scattertrack_bench_run``)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent


def load(name: str):
    """bench/<name>.py, executed as the module ``scattertrack_bench_<name>``
    (once: a second call returns the same module). The module is in
    ``sys.modules`` while it runs, as an import would put it, so that
    dataclasses and pickling can find it by name."""
    module_name = f"scattertrack_bench_{name}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    spec = importlib.util.spec_from_file_location(module_name, BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[module_name]
        raise
    return module
