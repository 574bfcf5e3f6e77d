"""A live run: an LLRP reader's reports in, a journal and a causal track out.

:class:`LiveSession` connects to a reader with llrpkit, reads its
capabilities (the hop table that turns a report's ``ChannelIndex`` into a
carrier), starts an inventory with the Impinj report fields tracking
needs (RF phase angle, peak RSSI, Doppler), and for every tag report:

1. converts it to a read (:func:`scattertrack.readers.impinj.reported_read`),
   declining and counting the ones it cannot use (no phase, a channel
   outside the hop table, an antenna the scene does not have);
2. drops it if it is one already received (the same EPC, antenna, channel,
   phase and FirstSeenTimestampUTC: readers resend after a reconnect with
   report holding), counted;
3. appends it to the journal (``reads.csv``), flushed, so a crash loses
   nothing and the run can be tracked again offline;
4. steps the tracker (any object with ``step(time_s, epc, antenna,
   frequency_hz, phase_rad) -> Estimate | None``, e.g.
   ``scattertrack.track.make("glac", scene)``: this layer knows no method)
   with the values *as written* to the journal, so ``scattertrack track``
   on the journal gives exactly the live track;
5. appends any estimate to the track (``track.csv``), flushed, and hands
   the row to ``outputs`` (Parquet, MCAP, ROS 2 bag, Foxglove, MQTT:
   :class:`scattertrack.readers.outputs.LiveOutputs`), closed at the end;
6. with a ``read_publisher`` (scale-out), publishes the read as journaled
   to its tag's shard topic (``scattertrack/reads/<K>``,
   :mod:`scattertrack.io.mqtt`), where ``live --mqtt-in … --shard K/N``
   workers (:class:`scattertrack.readers.mqtt_in.MqttReadsSession`) track
   it. Without a tracker (``tracker=None``) a session only journals and
   publishes.

When the connection drops it reconnects with exponential backoff and sets
the reader up again (a reader deactivates its ROSpecs when its client goes:
the inventory is added and started anew); each outage is timed. The run
ends when ``duration_s`` of wall-clock time has passed (a hard stop, also
in the middle of a reconnect) or when ``stop`` is set (Ctrl-C).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field

from llrpkit import LLRPError, Reader

from scattertrack.io.appenders import ReadsAppender, TrackAppender
from scattertrack.io.types import Scene
from scattertrack.readers import impinj

DUPLICATE = "duplicate report (already received)"
NOT_IN_SCENE = "antenna {} is not in the scene"
RECENT_KEYS = 200_000
"""Reports remembered for de-duplication (a few minutes at 1,000 reads/s)."""
STOP_GRACE_S = 1.0
"""At the end, how long the reader gets to stop and delete its ROSpec."""


@dataclass
class ReaderSettings:
    """What the inventory asks of the reader (None: the reader's own default)."""

    antennas: tuple[int, ...] = ()
    """Antenna ports to read (empty: all)."""
    tx_power_dbm: float | None = None
    reader_mode: int | None = None
    """RF mode index (``C1G2RFControl``); Impinj AutoSet modes are 1000+."""
    session: int = 1
    """Gen2 session 0–3."""
    search_mode: int | None = None
    """Impinj inventory search mode (1 single target, 2 dual target, 3 TagFocus...)."""


@dataclass
class LiveSummary:
    """What a live run received, declined and wrote."""

    reads: int = 0
    """Reads journaled (and tracked)."""
    estimates: int = 0
    declined: Counter = field(default_factory=Counter)
    """Reports not journaled, by reason (duplicates included)."""
    tags: dict = field(default_factory=dict)
    """EPC -> reads journaled."""
    connections: int = 0
    outages_s: list = field(default_factory=list)
    """Per reconnect: seconds from losing the reader to its inventory running again."""
    errors: list = field(default_factory=list)
    """Why each connection ended or failed (text)."""
    hop_table_hz: dict = field(default_factory=dict)
    reader: str = ""
    wall_s: float = 0.0
    first_read_s: float = math.nan
    last_read_s: float = math.nan
    """When the first and the latest read were journaled, s since the run started."""
    stopped_by: str = ""
    """"duration", "stop" (Ctrl-C) or "" while running."""

    @property
    def reads_per_s(self) -> float:
        """Reads journaled per second of the run."""
        return self.reads / self.wall_s if self.wall_s > 0 else math.nan

    @property
    def throughput_reads_per_s(self) -> float:
        """Reads per second between the first and the latest read: the
        rate the path sustained while reports were coming in."""
        span = self.last_read_s - self.first_read_s
        return (self.reads - 1) / span if self.reads > 1 and span > 0 else math.nan


class LiveSession:
    """One live run (see the module docstring)."""

    def __init__(
        self,
        scene: Scene,
        host: str,
        port: int,
        journal_path,
        track_path,
        tracker,
        *,
        settings: ReaderSettings | None = None,
        duration_s: float | None = None,
        connect_timeout_s: float = 5.0,
        backoff_s: tuple[float, float] = (0.1, 5.0),
        progress: Callable[["LiveSession"], None] | None = None,
        progress_interval_s: float = 1.0,
        outputs=None,
        read_publisher=None,
        shards: int = 1,
    ) -> None:
        self.scene = scene
        self.host, self.port = host, int(port)
        self.settings = settings or ReaderSettings()
        self.duration_s = duration_s
        self.connect_timeout_s = connect_timeout_s
        self.backoff_s = backoff_s
        self.progress = progress
        self.progress_interval_s = progress_interval_s
        self.tracker = tracker
        self.antenna_ids = {a.id for a in scene.antennas}
        self.journal = ReadsAppender(journal_path)
        self.track = TrackAppender(track_path) if tracker is not None else None
        self.outputs = outputs
        """Anything with ``add(epc, cells, covariance)`` and ``close()``, or None."""
        self.read_publisher = read_publisher
        """Anything with ``publish_read(read, shards)`` and ``close()`` (``io.mqtt.MqttPublisher``), or None."""
        self.shards = shards
        self.summary = LiveSummary()
        self.last_estimate: dict = {}
        """EPC -> its latest :class:`~scattertrack.track.base.Estimate`."""
        self._recent: deque = deque()
        self._recent_keys: set = set()
        self._started = math.nan
        self._lost_at: float | None = None
        """When the reader was lost (monotonic s), until its next report."""

    # -- one report ---------------------------------------------------------

    def handle(self, report, hop_table: dict[int, float]) -> None:
        """Journal, track and write one llrpkit ``TagReport``."""
        read = impinj.reported_read(
            epc=report.epc,
            antenna=report.antenna,
            channel_index=report.channel_index,
            first_seen_us=report.first_seen_us,
            phase_deg=report.phase_deg,
            rssi=report.rssi_dbm,
            doppler=report.doppler_hz,
            hop_table=hop_table,
        )
        if isinstance(read, str):
            self.summary.declined[read] += 1
            return
        key = (read.first_seen_us, read.epc, read.antenna, read.channel_index, round(read.phase_rad * 1e6))
        self.accept(read.time_s, read.epc, read.antenna, read.frequency_hz, read.phase_rad, read.rssi_dbm, read.doppler_hz, read.channel_index, key)

    def accept(self, time_s, epc, antenna, frequency_hz, phase_rad, rssi_dbm, doppler_hz, channel_index, key) -> None:
        """Journal, publish, track and write one read (``key``: its identity, for de-duplication)."""
        if antenna not in self.antenna_ids:
            self.summary.declined[NOT_IN_SCENE.format(antenna)] += 1
            return
        if key in self._recent_keys:
            self.summary.declined[DUPLICATE] += 1
            return
        self._remember(key)
        time_s, phase_rad = self.journal.append(time_s, epc, antenna, frequency_hz, phase_rad, rssi_dbm, doppler_hz, channel_index)
        self.journal.flush()
        if self.read_publisher is not None:
            # The values as journaled, so a worker's journal is this one's rows of its tags.
            self.read_publisher.publish_read(
                {"time_s": time_s, "epc": epc, "antenna": antenna, "frequency_hz": frequency_hz, "phase_rad": phase_rad,
                 "rssi_dbm": rssi_dbm, "doppler_hz": doppler_hz, "channel_index": channel_index},
                self.shards,
            )
        self.summary.reads += 1
        now = time.monotonic() - self._started
        if self.summary.reads == 1:
            self.summary.first_read_s = now
        self.summary.last_read_s = now
        self.summary.tags[epc] = self.summary.tags.get(epc, 0) + 1
        if self.tracker is None:
            return
        estimate = self.tracker.step(time_s, epc, antenna, frequency_hz, phase_rad)
        if estimate is not None:
            sigma = [math.sqrt(max(estimate.covariance[k, k], 0.0)) for k in range(3)]
            cells = self.track.append(estimate.time_s, epc, estimate.position, estimate.velocity, sigma)
            self.track.flush()
            if self.outputs is not None:
                self.outputs.add(epc, cells, estimate.covariance)
            self.summary.estimates += 1
            self.last_estimate[epc] = estimate

    def _remember(self, key) -> None:
        self._recent.append(key)
        self._recent_keys.add(key)
        if len(self._recent) > RECENT_KEYS:
            self._recent_keys.discard(self._recent.popleft())

    # -- the connection ------------------------------------------------------

    async def _inventory(self, reader: Reader) -> None:
        """Set the reader up and handle its reports until the connection ends."""
        capabilities = reader.capabilities
        frequency = capabilities.raw.regulatory_capabilities.uhf_band_capabilities.frequency_information
        tables = frequency.frequency_hop_tables
        if tables:
            hop_table = impinj.hop_table_hz(tables[0].frequency)
        else:
            hop_table = impinj.hop_table_hz(capabilities.fixed_frequencies)
        self.summary.hop_table_hz = hop_table
        self.summary.reader = f"manufacturer {capabilities.manufacturer}, model {capabilities.model_number}, firmware {capabilities.firmware}"
        s = self.settings
        stream = reader.inventory(
            antennas=s.antennas,
            session=s.session,
            search_mode=s.search_mode,
            mode_index=s.reader_mode,
            tx_power_dbm=s.tx_power_dbm,
            include_phase=True,
            include_doppler=True,
        )
        async with contextlib.aclosing(stream):
            async for report in stream:
                if self._lost_at is not None:
                    # The first report after an outage: the reader is back.
                    self.summary.outages_s.append(time.monotonic() - self._lost_at)
                    self._lost_at = None
                self.handle(report, hop_table)

    async def _connect_and_read(self) -> None:
        reader = Reader(self.host, self.port, connect_timeout=self.connect_timeout_s, response_timeout=self.connect_timeout_s)
        try:
            await reader.connect()
            self.summary.connections += 1
            await self._inventory(reader)
        finally:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(reader.close(), STOP_GRACE_S)

    async def _run_forever(self) -> None:
        delay = self.backoff_s[0]
        while True:
            reads_before = self.summary.reads
            try:
                await self._connect_and_read()
                self.summary.errors.append("the reader ended the inventory")
            except (LLRPError, OSError, ConnectionError, TimeoutError) as error:
                self.summary.errors.append(f"{type(error).__name__}: {error}")
            if self.summary.reads > reads_before:
                delay = self.backoff_s[0]  # it was working: retry soon
            if self._lost_at is None and self.summary.connections:
                self._lost_at = time.monotonic()
            await asyncio.sleep(delay)
            delay = min(2.0 * delay, self.backoff_s[1])

    async def _report_progress(self) -> None:
        while True:
            await asyncio.sleep(self.progress_interval_s)
            self.summary.wall_s = time.monotonic() - self._started
            if self.progress is not None:
                self.progress(self)

    async def run(self, stop: asyncio.Event | None = None) -> LiveSummary:
        """Run until ``duration_s`` or ``stop``; always flushes and returns the summary."""
        stop = stop or asyncio.Event()
        self._started = time.monotonic()
        worker = asyncio.create_task(self._run_forever())
        ticker = asyncio.create_task(self._report_progress())
        stopper = asyncio.create_task(stop.wait())
        try:
            done, _ = await asyncio.wait({worker, stopper}, timeout=self.duration_s, return_when=asyncio.FIRST_COMPLETED)
            self.summary.stopped_by = "stop" if stopper in done else "duration"
            if worker in done:
                worker.result()  # an unexpected error: raise it
        finally:
            for task in (worker, ticker, stopper):
                task.cancel()
            # A hard stop: the inventory's clean-up (STOP/DELETE_ROSPEC) gets
            # a short grace period, then the connection is simply dropped.
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await asyncio.wait_for(asyncio.gather(worker, ticker, stopper, return_exceptions=True), STOP_GRACE_S)
            self.journal.close()
            if self.track is not None:
                self.track.close()
            if self.outputs is not None:
                self.outputs.close()
            if self.read_publisher is not None:
                self.read_publisher.close()
            self.summary.wall_s = time.monotonic() - self._started
        return self.summary
