"""In-memory forms of the public formats (``docs/formats.md`` sections 1-4).

Plain dataclasses and columnar numpy arrays: one array per column, one row
per index. Readers in :mod:`scattertrack.io` build them from files and
validate them; writers turn them back into files. Nothing here does I/O.

The scene's types (:class:`Scene` and its parts) are defined with their
format in :mod:`scattertrack.io.scene`, so that ``Scene.load`` and
``Scene.save`` and the TOML reader need no import cycle; they are
re-exported here, with :class:`FormatError` (:mod:`scattertrack.io.errors`).

Units are SI: metres, seconds, radians, hertz, dBm.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scattertrack.physics import SPEED_OF_LIGHT  # noqa: F401 - a public name of io.types (its home is physics)


from scattertrack.io.errors import FormatError, InputWarning, warn_input  # noqa: F401 - the io contract's names
from scattertrack.io.scene import Antenna, ChannelOffset, Reader, Reflector, Region, Scene  # noqa: F401 - with its format


@dataclass
class SkipReport:
    """Rows a reader or tracker declined, counted by reason (never silent)."""

    counts: dict[str, int] = field(default_factory=dict)
    examples: dict[str, list[int]] = field(default_factory=dict)
    """Up to a few 1-based file line numbers per reason, for messages."""

    def add(self, reason: str, line: int | None = None, n: int = 1) -> None:
        self.counts[reason] = self.counts.get(reason, 0) + n
        if line is not None:
            ex = self.examples.setdefault(reason, [])
            if len(ex) < 5:
                ex.append(line)

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def summary(self) -> str:
        if not self.counts:
            return "no rows skipped"
        parts = []
        for reason, n in sorted(self.counts.items()):
            ex = self.examples.get(reason)
            lines = f" (lines {', '.join(map(str, ex))}{', ...' if n > len(ex) else ''})" if ex else ""
            parts.append(f"{n} {reason}{lines}")
        return "skipped " + "; ".join(parts)


@dataclass
class Reads:
    """Tag reads (``reads.csv``), columnar, sorted by time (stable)."""

    time_s: np.ndarray  # float64
    epc: np.ndarray  # str; from read_reads an object array whose rows share one str per distinct EPC
    antenna: np.ndarray  # int64, antenna id as in the scene
    frequency_hz: np.ndarray  # float64
    phase_rad: np.ndarray  # float64 in [0, P)
    rssi_dbm: np.ndarray  # float64, nan where absent
    doppler_hz: np.ndarray  # float64, nan where absent
    skipped: SkipReport = field(default_factory=SkipReport)
    reordered: int = 0
    """How many rows were out of time order in the file (sorted, not dropped)."""
    channel_index: np.ndarray | None = None
    """int64: the reader's own 1-based channel index as reported (LLRP ``ChannelIndex``),
    -1 where a row has none; None when the source has no such column."""

    def __len__(self) -> int:
        return len(self.time_s)

    def select(self, mask_or_index) -> "Reads":
        """A new Reads with the rows picked by a boolean mask or index array."""
        return Reads(
            self.time_s[mask_or_index],
            self.epc[mask_or_index],
            self.antenna[mask_or_index],
            self.frequency_hz[mask_or_index],
            self.phase_rad[mask_or_index],
            self.rssi_dbm[mask_or_index],
            self.doppler_hz[mask_or_index],
            channel_index=None if self.channel_index is None else self.channel_index[mask_or_index],
        )

    def epcs(self) -> list[str]:
        """Distinct tags in order of first appearance."""
        _, first = np.unique(self.epc, return_index=True)
        return [str(self.epc[i]) for i in sorted(first)]


@dataclass
class Truth:
    """Ground truth (``truth.csv``); velocity columns are nan when absent."""

    time_s: np.ndarray
    epc: np.ndarray
    position: np.ndarray  # (n, 3) metres
    velocity: np.ndarray  # (n, 3) m/s, nan where absent
    orientation: np.ndarray | None = None  # (n, 4) qw, qx, qy, qz (world_T_body), when given

    def __len__(self) -> int:
        return len(self.time_s)


@dataclass
class Track:
    """Tracker output (``track.csv``)."""

    time_s: np.ndarray
    epc: np.ndarray
    position: np.ndarray  # (n, 3) metres
    velocity: np.ndarray  # (n, 3) m/s, nan if the method has none
    sigma: np.ndarray | None = None  # (n, 3) 1-sigma position, metres
    orientation: np.ndarray | None = None  # (n, 4) qw, qx, qy, qz
    skipped: SkipReport = field(default_factory=SkipReport)
    """Reads the tracker declined (outliers, duplicates...), by reason."""
    stats: dict = field(default_factory=dict)
    """Per-tag tracker counters (reads, initialising, reinitialisations,
    hypotheses...), filled by :func:`scattertrack.track.run`; empty when read
    from a file."""
    latency: tuple | None = None
    """(steps, mean ns, max ns) of the Rust tracker steps, when tracked here."""
    latency_quantiles_ns: dict = field(default_factory=dict)
    """Per-step cost quantiles of the Rust tracker, ns (``{"p50": .., "p99": ..}``), when tracked here."""
    smoothed: dict = field(default_factory=dict)
    """Methods that revise the past (TurboTrack's backtracked MAP trajectory,
    Marvel's fixed-lag smoothed states):
    ``epc -> (times s (n,), positions m (n, 3))``; empty otherwise."""
    revised: Track | None = None
    """Marvel: the whole revised track (every column, each state as last
    revised before it left the smoother's window); None for other methods."""
    covariance: np.ndarray | None = None
    """(n, 6, 6) covariance of [p, v] (m², m²/s, m²/s²) per row, kept only
    when an output needs it (``st.track.run(..., covariance=True)``: the
    ROS 2 writers); not in ``track.csv``."""

    def __len__(self) -> int:
        return len(self.time_s)


@dataclass
class Imu:
    """Inertial samples (``imu.csv``, docs/formats.md section 6), sorted by time.

    Body frame x forward, y left, z up; at rest ``accel`` reads about
    (0, 0, +9.81) m/s^2 (specific force).
    """

    time_s: np.ndarray  # (n,) seconds, strictly increasing after reading
    accel: np.ndarray  # (n, 3) specific force, body frame, m/s^2
    gyro: np.ndarray  # (n, 3) angular rate, body frame, rad/s
    baro_z: np.ndarray  # (n,) barometric height, metres; nan where absent
    skipped: SkipReport = field(default_factory=SkipReport)
    """Samples declined on reading (a time repeated after sorting), by reason."""
    gaps: int = 0
    """Gaps longer than 3 nominal sample periods (counted and reported, not filled)."""
    reordered: int = 0
    """How many rows were out of time order in the file (sorted, not dropped)."""

    def __len__(self) -> int:
        return len(self.time_s)


@dataclass
class Features:
    """Backscatter pose features (``features.csv``, docs/formats.md section 7), sorted by time.

    ``azimuth_rad``/``elevation_rad``: direction from the controller's array
    to the drone, world frame; ``yaw_rad``: heading of body x about +z, nan
    where the row has none. Sigmas are nan where the file gives none.
    """

    time_s: np.ndarray  # (n,) seconds, same clock as the IMU
    range_m: np.ndarray  # (n,) controller-to-drone distance, metres
    azimuth_rad: np.ndarray  # (n,)
    elevation_rad: np.ndarray  # (n,)
    yaw_rad: np.ndarray  # (n,) nan where absent
    range_sigma_m: np.ndarray  # (n,) nan where absent
    angle_sigma_rad: np.ndarray  # (n,) nan where absent
    yaw_sigma_rad: np.ndarray  # (n,) nan where absent
    skipped: SkipReport = field(default_factory=SkipReport)
    reordered: int = 0
    line: np.ndarray | None = None
    """1-based file line of each row (int64 (n,)), for messages; None when not read from a file."""

    def __len__(self) -> int:
        return len(self.time_s)
