"""scattertrack: tracking engine for RF backscatter tags.

Quick tour::

    import scattertrack as st
    scene = st.Scene.load("scene.toml")
    reads = st.io.read_reads("reads.csv", scene)
    track = st.track.run("glac", scene, reads)
    report = st.eval.compare(truth, track)

Sub-packages, one role each, from the bottom layer up (python/pyproject.toml,
``[tool.importlinter]``): ``physics`` (constants, angle wrapping), ``io``
(public formats), ``dsp`` (recordings to frames), ``sim`` (simulators),
``track`` (trackers over the Rust core), ``fusion``, ``locate``,
``calibrate``, ``eval`` (metrics and reports), ``check``, ``readers``,
``server``, ``cli`` (the ``scattertrack`` command).
"""

import importlib

__version__ = "0.1.0"

# Every module imports this package first (``from scattertrack import _core``,
# ``__version__``), so importing the sub-packages here would tie each of
# them to all the others: ``io`` would load ``sim`` and ``track`` and every
# module would sit in one import cycle. The sub-packages and the format
# types are therefore loaded on first use (PEP 562 module ``__getattr__``):
# ``st.io``, ``st.Scene`` work as before, and ``import scattertrack.io``
# loads ``io`` and what it builds on, nothing above it.
_SUBPACKAGES = ("calibrate", "check", "dsp", "eval", "fusion", "io", "locate", "physics", "readers", "server", "sim", "track")
_TYPES = ("FormatError", "Reads", "Scene", "Track", "Truth")

__all__ = ["eval", "io", "sim", "track", *_TYPES, "__version__"]


def __getattr__(name: str):
    if name in _SUBPACKAGES:
        return importlib.import_module(f"scattertrack.{name}")
    if name in _TYPES:
        return getattr(importlib.import_module("scattertrack.io.types"), name)
    raise AttributeError(f"module 'scattertrack' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_SUBPACKAGES, *_TYPES})
