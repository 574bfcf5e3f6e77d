"""Where a live run's estimates go besides ``track.csv``: files and robots.

:class:`LiveOutputs` takes every track row as it is written (the cells of
``track.csv`` and the estimate's full 6×6 covariance) and hands it on:

* ``parquet``: ``track.parquet``, written at the end from the whole
  ``track.csv`` (Parquet has no append: a file is whole only once its
  footer is written, so the CSV stays the crash-safe record and the
  Parquet twin is made from it, the same rows to the digit);
* ``mcap`` / ``ros2_bag``: ROS 2 pose and odometry per row, written as
  they come (:mod:`scattertrack.io.ros2`; an MCAP is readable once closed,
  a bag's sqlite file holds every message written so far);
* ``foxglove``: the same messages on a Foxglove WebSocket
  (:mod:`scattertrack.io.foxglove_ws`);
* ``mqtt``: one JSON object per row (:mod:`scattertrack.io.mqtt`).

Positions and velocities are the row's (6 decimals, as in the file), so
every output says what ``track.csv`` says; the covariance is the
estimate's. The antennas' markers go out once, at the first row's stamp.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scattertrack.io import ros2
from scattertrack.io.appenders import TRACK_HEADER, track_cells


@dataclass
class OutputOptions:
    """What to serve and write (None: not that one)."""

    parquet: str | None = None
    mcap: str | None = None
    ros2_bag: str | None = None
    foxglove: tuple[str, int] | None = None
    mqtt: tuple[str, int] | None = None
    frame_id: str = "scattertrack"
    transform: ros2.Transform = ros2.IDENTITY

    @property
    def ros2(self) -> bool:
        return bool(self.mcap or self.ros2_bag or self.foxglove)

    @property
    def any(self) -> bool:
        return bool(self.parquet or self.ros2 or self.mqtt)


class LiveOutputs:
    """The outputs of one run; :meth:`add` per row, :meth:`close` once (always)."""

    def __init__(self, options: OutputOptions, scene=None, track_csv=None) -> None:
        self.options = options
        self.scene = scene
        self.track_csv = track_csv
        """The ``track.csv`` the Parquet twin is made from."""
        self.sinks: list = []
        self.foxglove = self.mqtt = None
        self.topics: dict = {}
        """After :meth:`close`: ROS 2 messages per topic in the files."""
        self.foxglove_published = self.mqtt_published = self.foxglove_port = None
        """After :meth:`close`: messages served on each (None: not served)."""
        self._builder = ros2.Builder(options.frame_id, options.transform) if options.ros2 else None
        self._antennas_sent = False
        try:
            # The servers first: a port in use or a broker that is not there
            # fails before any file is created.
            if options.mqtt:
                from scattertrack.io.mqtt import MqttPublisher

                self.mqtt = MqttPublisher(*options.mqtt)
            if options.foxglove:
                from scattertrack.io.foxglove_ws import FoxgloveServer

                self.foxglove = FoxgloveServer(self._builder, *options.foxglove)
            if options.mcap:
                self.sinks.append(ros2.McapFile(options.mcap, self._builder))
            if options.ros2_bag:
                self.sinks.append(ros2.BagFile(options.ros2_bag, self._builder))
        except BaseException:
            self.close()
            raise

    def add(self, epc: str, cells: list[str], covariance=None, orientation=None) -> None:
        """One track row: its ``track.csv`` cells, the (6, 6) covariance of [p, v]."""
        if self.mqtt is not None:
            self.mqtt.publish(epc, TRACK_HEADER, cells)
        if self._builder is None:
            return
        values = np.array([float(c) for c in cells[2:]])
        time_s, position, velocity, sigma = float(cells[0]), values[0:3], values[3:6], values[6:9]
        if not self._antennas_sent and self.scene is not None:
            self._send(*self._builder.antennas(self.scene, time_s), latch=True)
        self._antennas_sent = True
        for item in self._builder.row(time_s, epc, position, velocity, covariance=covariance, sigma=sigma, orientation=orientation):
            self._send(*item)

    def _send(self, name, msgtype, stamp, message, latch: bool = False) -> None:
        data = self._builder.cdr(message, msgtype)  # once, for every output
        for sink in self.sinks:
            sink.write(name, msgtype, stamp, data)
        if self.foxglove is not None:
            self.foxglove.write(name, msgtype, stamp, data, latch=latch)

    @property
    def messages(self) -> int:
        return sum(self.topics.values())

    def close(self) -> None:
        """Finish the files and stop the servers (each one even if another fails)."""
        errors = []
        if self.sinks:
            self.topics = dict(self.sinks[0].counts)
        if self.foxglove is not None:
            self.foxglove_published, self.foxglove_port = self.foxglove.published, self.foxglove.port
        if self.mqtt is not None:
            self.mqtt_published = self.mqtt.published
        for closer in [*(s.close for s in self.sinks), *(x.close for x in (self.foxglove, self.mqtt) if x is not None)]:
            try:
                closer()
            except Exception as error:  # noqa: BLE001 - close the rest, then raise the first
                errors.append(error)
        self.sinks, self.foxglove, self.mqtt = [], None, None
        if self.options.parquet and self.track_csv is not None:
            from scattertrack.io import read_track, write_track

            write_track(self.options.parquet, read_track(self.track_csv))
            self.track_csv = None
        if errors:
            raise errors[0]



def publish_track(outputs: LiveOutputs, track) -> None:
    """Every row of a finished track, in time order, through ``outputs``
    (``stream``: its runtime hands the track back when the recording ends)."""
    covariance = getattr(track, "covariance", None)
    sigma = track.sigma if track.sigma is not None else np.full((len(track), 3), np.nan)
    for i in np.argsort(np.asarray(track.time_s), kind="stable"):
        epc = str(track.epc[i])
        cells = track_cells(float(track.time_s[i]), epc, track.position[i], track.velocity[i], sigma[i])
        outputs.add(epc, cells, None if covariance is None else covariance[i])
