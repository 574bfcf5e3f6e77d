"""Trackers: every method behind one causal interface (DESIGN.md, Python API).

Contract: ``make(method, scene, **params)`` builds a :class:`Tracker`;
``tracker.step(...)`` takes one read and returns an :class:`Estimate` or
``None`` (causal: only reads at or before that time are used); ``run`` is
the batch helper, a loop over ``step`` done in Rust, for many interleaved
tags. Reads a tracker declines (gated outliers, out-of-order, invalid) are
counted and reported in ``Track.skipped``, never dropped silently.
"""

from scattertrack.track.glac import METHODS, Estimate, Tracker, default_params, make, run

__all__ = ["METHODS", "Estimate", "Tracker", "default_params", "make", "run"]
