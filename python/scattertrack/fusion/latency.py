"""The typed latency record of a fusion run: time per sensing epoch.

Two clocks per accepted epoch (:meth:`MarvelEstimator.add_features`): the
wall clock (``time.perf_counter``), what a 100 ms sensing budget is about,
and the calling thread's CPU time (``time.thread_time``), the estimator's
own cost, which other processes on a shared machine do not inflate (on the
2-core VM the wall-clock p99 of the same run moved by 2x with the load).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Latency:
    """Quantiles of the time per accepted epoch, ns; ``count`` epochs."""

    count: int
    p50_ns: float
    p99_ns: float
    mean_ns: float
    max_ns: float

    @classmethod
    def of(cls, seconds) -> Latency | None:
        """The record of per-epoch times in seconds (non-finite ones left out); None for none."""
        values = np.asarray([s for s in seconds if np.isfinite(s)], dtype=float) * 1e9
        if not values.size:
            return None
        return cls(
            count=int(values.size),
            p50_ns=float(np.percentile(values, 50)),
            p99_ns=float(np.percentile(values, 99)),
            mean_ns=float(np.mean(values)),
            max_ns=float(np.max(values)),
        )

    def quantiles(self) -> dict[str, float]:
        """``{"p50": .., "p99": ..}`` ns, the form of ``Track.latency_quantiles_ns``."""
        return {"p50": self.p50_ns, "p99": self.p99_ns}

    def as_tuple(self) -> tuple[int, float, float]:
        """``(epochs, mean ns, max ns)``, the form of ``Track.latency``."""
        return (self.count, self.mean_ns, self.max_ns)

    def as_dict(self) -> dict:
        return asdict(self)


__all__ = ["Latency"]
