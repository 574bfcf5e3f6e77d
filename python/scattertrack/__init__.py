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

# Defined before the sub-packages are imported: they read it (simulation records).
__version__ = "0.1.0"

from scattertrack import io
from scattertrack.io.types import FormatError, Reads, Scene, Track, Truth

# After io: sim, track and eval build on its types. eval imports matplotlib
# only when a figure is drawn, so these imports stay cheap.
from scattertrack import eval, sim, track  # noqa: E402

__all__ = ["eval", "io", "sim", "track", "FormatError", "Reads", "Scene", "Track", "Truth", "__version__"]
