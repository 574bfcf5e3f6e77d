"""The phase model of a static tag's reads.

The calibrated scene leaves, per read k of one tag, the phasor

    z_k = exp(j m (φ_k − θ_a − θ_ch))  ≈  exp(j m (s 4π f_k d_k(p) / c + θ_tag))

with m = 2π/P and θ_tag the tag's own, unknown offset. With k_k =
m s 4π f_k / c (rad/m), a position p explains the reads as well as their
coherence R(p) = |Σ_k z_k exp(−j k_k d_k(p))| / n says, θ_tag profiled out.
The search over p (hop ranging, the grid, Gauss–Newton refinement), the
candidates' weights and covariances are in the Rust core,
``scattertrack_core::locate`` (``_core.locate_batch``, one threaded call
for every tag); this module keeps the model's constant.
"""

from __future__ import annotations

import numpy as np

from scattertrack.io.types import SPEED_OF_LIGHT

FOUR_PI_OVER_C = 4.0 * np.pi / SPEED_OF_LIGHT
