"""scattertrack: tracking engine for RF backscatter tags.

Quick tour::

    import scattertrack as st
    scene = st.Scene.load("scene.toml")
    reads = st.io.read_reads("reads.csv", scene)
    track = st.track.run("glac", scene, reads)
    report = st.eval.compare(truth, track)

Sub-packages, one role each: ``io`` (public formats), ``sim`` (simulators),
``track`` (trackers over the Rust core), ``eval`` (metrics and reports),
``cli`` (the ``scattertrack`` command).
"""

from scattertrack import io
from scattertrack.io.types import FormatError, Reads, Scene, Track, Truth

__version__ = "0.1.0"

__all__ = ["io", "FormatError", "Reads", "Scene", "Track", "Truth", "__version__"]
