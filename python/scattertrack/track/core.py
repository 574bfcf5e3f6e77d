"""The core engine's tracker: GLAC and TurboTrack and their variants over the
Rust core (``crates/core/src/track/``), one measurement at a time.

A :class:`CoreTracker` tracks any number of tags (one filter per EPC) and
takes :class:`~scattertrack.track.base.Read` (methods with input ``reads``:
``glac``, ``glac-no-velocity``, ``glac-sync``, ``glac-sync-no-velocity``,
``glac-naive``) or :class:`~scattertrack.track.base.Frame` (input
``frames``: ``turbotrack`` and its comparison variants). The batch runners
are :func:`scattertrack.track.cots.run` and
:func:`scattertrack.track.helper.run_frames`.
"""

from __future__ import annotations

import numpy as np

from scattertrack import _core
from scattertrack.io.types import Scene
from scattertrack.track import base
from scattertrack.track import methods as registry
from scattertrack.track.base import Estimate, Frame, Read


def _engine(method: str, scene: Scene, params: dict) -> _core.Engine:
    from scattertrack.track import helper

    entry = registry.method(method)  # ValueError naming the known methods
    if entry.input == "frames":
        return helper.engine(method, scene, params)
    if entry.estimator != "core":
        raise ValueError(f"method '{method}' is the drone pipeline: use scattertrack.track.marvel (imu + features or a recording)")
    if scene.reader.kind != "cots":
        raise ValueError(f"method '{method}' needs a monostatic reader scene (kind = 'cots'), got '{scene.reader.kind}'")
    # Parameters cross as one dict; the core's table checks every one
    # (ValueError naming the parameter).
    return _core.Engine(_core.Scene(scene), method, dict(params))


class CoreTracker(base.Tracker):
    """A streaming tracker for any number of tags (one per EPC), over one core engine."""

    def __init__(self, method: str, scene: Scene, **params):
        self.method = method
        self.scene = scene
        self.params = params
        self._input = registry.method(method).input
        self._engine = _engine(method, scene, params)
        self._tags: dict[str, int] = {}
        self._antennas = {a.id: i for i, a in enumerate(scene.antennas)}

    def _tag(self, epc: str) -> int:
        return self._tags.setdefault(str(epc), len(self._tags))

    def step(self, measurement, *args) -> Estimate | None:
        """One :class:`Read` (methods with input ``reads``) or :class:`Frame`
        (input ``frames``); ValueError for the other kind.

        The old positional form ``step(time_s, epc, antenna, frequency_hz,
        phase_rad)`` (one read) still works.
        """
        if args or isinstance(measurement, Read):
            if self._input != "reads":
                raise ValueError(f"method '{self.method}' takes wideband frames (Frame), not phase reads")
            if args:  # the old positional form: no Read built on the hot path
                return self.step_read(measurement, *args)
            return self.step_read(measurement.time_s, measurement.epc, measurement.antenna, measurement.frequency_hz, measurement.phase_rad)
        if isinstance(measurement, Frame):
            if self._input != "frames":
                raise ValueError(f"method '{self.method}' takes phase reads (Read), not wideband frames")
            return self.step_frame(measurement.time_s, measurement.epc, measurement.tx, measurement.rx, measurement.frequency_hz, measurement.h)
        raise ValueError(f"method '{self.method}' takes {'Read' if self._input == 'reads' else 'Frame'} measurements, got {type(measurement).__name__}")

    def step_read(self, time_s: float, epc: str, antenna: int, frequency_hz: float, phase_rad: float) -> Estimate | None:
        """One read (``antenna`` is the port id as in the scene)."""
        if antenna not in self._antennas:
            raise ValueError(f"antenna {antenna} is not in the scene")
        out = self._engine.step(self._tag(epc), float(time_s), self._antennas[antenna], float(frequency_hz), float(phase_rad))
        if out is None:
            return None
        t, position, velocity, covariance, hypotheses, weight = out
        return Estimate(t, str(epc), np.array(position), np.array(velocity), np.array(covariance).reshape(6, 6), hypotheses, weight)

    def step_frame(self, time_s: float, epc: str, tx: int, rx, frequency_hz, h) -> Estimate | None:
        """One wideband frame (wideband methods): ``rx`` (n,) receive antenna
        ids, ``frequency_hz`` (n,) and complex ``h`` (n,), sorted by receiver
        then frequency, every receiver with the same subcarriers; ``tx`` is
        the transmit antenna id."""
        rx = np.asarray(rx)
        for antenna in [tx, *np.unique(rx).tolist()]:
            if antenna not in self._antennas:
                raise ValueError(f"antenna {antenna} is not in the scene")
        h = np.asarray(h, dtype=complex)
        out = self._engine.run_frames(
            np.array([self._tag(epc)], dtype=np.int64),
            np.array([float(time_s)]),
            np.array([self._antennas[tx]], dtype=np.int64),
            np.array([0, len(rx)], dtype=np.int64),
            np.array([self._antennas[int(r)] for r in rx], dtype=np.int64),
            np.asarray(frequency_hz, dtype=float),
            np.ascontiguousarray(h.real),
            np.ascontiguousarray(h.imag),
        )
        if len(out["row"]) == 0:
            return None
        return Estimate(
            float(out["time_s"][0]),
            str(epc),
            out["position"][0].copy(),
            out["velocity"][0].copy(),
            out["covariance"][0].reshape(6, 6).copy(),
            int(out["hypotheses"][0]),
            float(out["weight"][0]),
        )

    def stats(self, epc: str | None = None) -> dict:
        """What the tag's tracker did with its reads, by reason (every tag's, by EPC, without ``epc``)."""
        if epc is None:
            return {name: dict(self._engine.stats(i)) for name, i in self._tags.items()}
        return dict(self._engine.stats(self._tags[str(epc)])) if str(epc) in self._tags else {}

    def hypotheses(self, epc: str) -> list[tuple[np.ndarray, float]]:
        """Live candidate trajectories of a tag: (position m, normalised log-likelihood)."""
        if str(epc) not in self._tags:
            return []
        return [(np.array(p), w) for p, w in self._engine.hypotheses(self._tags[str(epc)])]

    def latency(self) -> tuple[int, float, int]:
        """(steps, mean ns, max ns) of the Rust step calls."""
        return self._engine.latency()


Tracker = CoreTracker
"""The core tracker's old name (kept: ``scattertrack.track.Tracker(method, scene)``)."""
