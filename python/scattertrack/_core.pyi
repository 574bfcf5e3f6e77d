"""Type stubs of the Rust extension (thin bindings over scattertrack-core)."""

from typing import Any

import numpy as np
import numpy.typing as npt

EstimateTuple = tuple[float, list[float], list[float], list[float], int, float]

class Engine:
    """Per-tag trackers of one method over one scene (core ``engine::Engine``)."""

    def __init__(
        self,
        dimensions: int,
        plane_z: float,
        phase_sign: float,
        phase_period: float,
        phase_noise_rad: float,
        antenna_positions: npt.NDArray[np.float64],
        antenna_offsets: npt.NDArray[np.float64],
        region: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None,
        channel_frequencies: npt.NDArray[np.float64],
        channel_offsets: npt.NDArray[np.float64],
        method: str,
        params: dict[str, Any] | None = None,
        roles: list[str] | None = None,
    ) -> None:
        """``roles``: one of "txrx", "tx", "rx" per antenna (default all "txrx")."""
    def step(
        self, tag: int, time_s: float, antenna: int, frequency_hz: float, phase_rad: float
    ) -> EstimateTuple | None:
        """One measurement; antenna is an index into the scene's antennas."""
    def run(
        self,
        tag: npt.NDArray[np.int64],
        time_s: npt.NDArray[np.float64],
        antenna: npt.NDArray[np.int64],
        frequency_hz: npt.NDArray[np.float64],
        phase_rad: npt.NDArray[np.float64],
    ) -> dict[str, np.ndarray]:
        """Columns row, time_s, position (n,3), velocity (n,3), covariance (n,36), hypotheses, weight."""
    def run_frames(
        self,
        tag: npt.NDArray[np.int64],
        time_s: npt.NDArray[np.float64],
        tx: npt.NDArray[np.int64],
        frame_start: npt.NDArray[np.int64],
        rx: npt.NDArray[np.int64],
        frequency_hz: npt.NDArray[np.float64],
        h_re: npt.NDArray[np.float64],
        h_im: npt.NDArray[np.float64],
    ) -> dict[str, np.ndarray]:
        """Wideband frames: per frame tag, time, tx index and row offsets; per row
        rx index, subcarrier Hz and channel (sorted by rx, then frequency).
        Same columns as ``run``; ``row`` is the frame index."""
    def trajectory(self, tag: int) -> list[tuple[float, list[float]]]:
        """Backtracked MAP trajectory (TurboTrack): (time_s, position m) pairs."""
    def stats(self, tag: int) -> dict[str, int]: ...
    def hypotheses(self, tag: int) -> list[tuple[list[float], float]]:
        """Live hypotheses: (position m, normalised log-likelihood)."""
    def latency(self) -> tuple[int, float, int]:
        """(count, mean_ns, max_ns) of step calls."""
    def latency_percentiles(self, quantiles: list[float]) -> list[float]:
        """Quantiles (0-1) of the per-step cost, ns."""

def methods() -> list[str]: ...
def default_params(method: str = "glac") -> dict[str, Any]:
    """The parameters ``method`` accepts, with their defaults."""
