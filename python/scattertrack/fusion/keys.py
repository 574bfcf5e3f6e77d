"""Graph keys of the Marvel estimator's variables that are not per epoch."""

from gtsam.symbol_shorthand import L, W

CONTROLLER = L(0)
"""Key of the controller's position in the graph."""
RANGE_BIAS = W(0)
"""Key of the constant range bias (``range_bias_sigma_m > 0``)."""
