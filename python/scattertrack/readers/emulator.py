"""A reader emulator that speaks real LLRP on loopback and serves simulated reads.

llrpkit's :class:`~llrpkit.emulator.LLRPEmulator` implements the protocol
side of an Impinj reader (connection handshake, capabilities, ROSpec
lifecycle, Octane extensions) but reports random phases. This subclass
keeps its protocol and replaces what it reports by a physical simulation
(:mod:`scattertrack.sim`), encoded as an Impinj reader encodes it
(:mod:`scattertrack.readers.impinj`):

* the capabilities announce a **shuffled hop table** (the 50 US channels in
  a seeded random order), and every report carries the 1-based index of
  its carrier in that table, not the frequency;
* phase in 0–4095 units, Doppler in 1/16 Hz, peak RSSI in 1/100 dBm — only
  the fields the client's ROSpec asked for;
* ``FirstSeenTimestampUTC`` = the world's start (Unix µs) + the read's
  simulated time: the emulated reader's clock is the simulated world's.

The world's clock starts when the first ROSpec starts, and runs at
``speed`` × wall time whether or not a client is connected: reads whose
time passes while no ROSpec is active are never sent (a reader that is not
inventorying reads nothing), as after a disconnect, when the reader
deactivates its ROSpecs and the client must add and start them again.
``drop_after_s`` (world seconds) closes the connection once, after
everything written so far has been handed to the socket: a forced
disconnect for tests. Every read sent is recorded in :attr:`sent`.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import random
import time

import numpy as np
from llrpkit.emulator import LLRPEmulator
from llrpkit.protocol import BitStr, impinj, messages, params

from scattertrack.io.hop_table import US_PLAN_HZ
from scattertrack.io.types import Reads
from scattertrack.readers import impinj as encoding

US_CHANNELS_KHZ = [round(f / 1e3) for f in US_PLAN_HZ]
"""The US band plan (FCC part 15.247): 50 channels of 500 kHz, in frequency order, kHz."""

BATCH = 256
"""At most this many tag reports per RO_ACCESS_REPORT message (readers batch too)."""


def shuffled_hop_table(seed: int, channels_khz: list[int] = US_CHANNELS_KHZ) -> list[int]:
    """The band's channels in a seeded random hop order, kHz."""
    table = list(channels_khz)
    random.Random(seed).shuffle(table)
    return table


class SimulatedReader(LLRPEmulator):
    """An Impinj-like LLRP reader on ``host:port`` whose tag reports are ``reads``.

    ``reads``: simulated reads (time-ordered; antenna ids are the reader's
    ports, 1-based; frequencies must be channels of ``hop_table_khz``).
    ``speed``: world seconds per wall second (1 = real time).
    """

    def __init__(
        self,
        reads: Reads,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        hop_table_khz: list[int] | None = None,
        speed: float = 1.0,
        drop_after_s: float | None = None,
        epoch_us: int | None = None,
        seed: int = 1,
    ) -> None:
        if not speed > 0.0:
            raise ValueError(f"speed must be positive, got {speed}")
        antennas = np.asarray(reads.antenna, dtype=np.int64)
        super().__init__(host=host, port=port, tags=[], antenna_count=max(1, int(antennas.max(initial=1))), seed=seed)
        self.hop_table_khz = list(hop_table_khz) if hop_table_khz is not None else shuffled_hop_table(seed)
        index_of_khz = {khz: i for i, khz in enumerate(self.hop_table_khz, start=1)}
        khz = np.rint(np.asarray(reads.frequency_hz, dtype=np.float64) / 1e3).astype(np.int64)
        missing = sorted({int(k) for k in khz if int(k) not in index_of_khz})
        if missing:
            raise ValueError(f"reads on {len(missing)} carriers outside the hop table, e.g. {missing[0]} kHz")
        order = np.argsort(reads.time_s, kind="stable")
        self._time_s = np.asarray(reads.time_s, dtype=np.float64)[order]
        self._epc = [bytes.fromhex(str(e)) for e in np.asarray(reads.epc)[order]]
        self._antenna = antennas[order]
        self._channel = np.array([index_of_khz[int(k)] for k in khz[order]], dtype=np.int64)
        self._phase_units = np.array([encoding.phase_units(p) for p in np.asarray(reads.phase_rad)[order]], dtype=np.int64)
        self._rssi = np.asarray(reads.rssi_dbm, dtype=np.float64)[order]
        self._doppler = np.asarray(reads.doppler_hz, dtype=np.float64)[order]
        self.speed = float(speed)
        self.drop_after_s = drop_after_s
        self.epoch_us = int(time.time() * 1e6) if epoch_us is None else int(epoch_us)
        self.sent: list[int] = []
        """Indices (into the time-ordered reads) of every read sent, in order."""
        self.unsent = 0
        """Reads whose time passed while no ROSpec was active (or whose antenna was not asked for)."""
        self.drops = 0
        self._next = 0
        self._world_start: float | None = None

    async def stop(self) -> None:
        """Hang up on the client first, so that its handler ends before the server closes."""
        writer = self._writer
        if writer is not None:
            with contextlib.suppress(Exception):
                writer.close()
                await writer.wait_closed()
            await asyncio.sleep(0.05)
        await super().stop()

    @property
    def finished(self) -> bool:
        """Whether the world's clock has passed the last read."""
        return self._next >= len(self._time_s)

    def sent_first_seen_us(self) -> list[int]:
        """The FirstSeenTimestampUTC of every read sent, in order."""
        return [self.epoch_us + round(self._time_s[i] * 1e6) for i in self.sent]

    def world_time_s(self) -> float:
        """Seconds of simulated time since the first ROSpec started (0 before)."""
        if self._world_start is None:
            return 0.0
        return (asyncio.get_running_loop().time() - self._world_start) * self.speed

    def _capabilities_response(self) -> messages.GET_READER_CAPABILITIES_RESPONSE:
        response = super()._capabilities_response()
        information = response.regulatory_capabilities.uhf_band_capabilities.frequency_information
        information.hopping = True
        information.frequency_hop_tables = [params.FrequencyHopTable(hop_table_id=1, frequency=self.hop_table_khz)]
        return response

    def _report(self, i: int, content: set[str]) -> params.TagReportData:
        """Read ``i`` as an Impinj tag report with the fields in ``content``."""
        epc = self._epc[i]
        first_seen = params.FirstSeenTimestampUTC(microseconds=self.epoch_us + round(self._time_s[i] * 1e6))
        rssi = self._rssi[i] if math.isfinite(self._rssi[i]) else -60.0
        trd = params.TagReportData(
            epc_parameter=params.EPC_96(epc=epc) if len(epc) == 12 else params.EPCData(epc=BitStr.from_bytes(epc)),
            antenna_id=params.AntennaID(antenna_id=int(self._antenna[i])),
            peak_rssi=params.PeakRSSI(peak_rssi=max(-128, min(127, round(rssi)))),
            channel_index=params.ChannelIndex(channel_index=int(self._channel[i])),
            first_seen_timestamp_utc=first_seen,
            last_seen_timestamp_utc=params.LastSeenTimestampUTC(microseconds=first_seen.microseconds),
            tag_seen_count=params.TagSeenCount(tag_count=1),
        )
        if "rssi" in content:
            trd.custom.append(impinj.ImpinjPeakRSSI(rssi=round(rssi * encoding.RSSI_UNITS_PER_DBM)))
        if "phase" in content:
            trd.custom.append(impinj.ImpinjRFPhaseAngle(phase_angle=int(self._phase_units[i])))
        if "doppler" in content and math.isfinite(self._doppler[i]):
            trd.custom.append(impinj.ImpinjRFDopplerFrequency(doppler_frequency=encoding.doppler_units(self._doppler[i])))
        return trd

    async def _send_batch(self, indices: list[int], content: set[str]) -> bool:
        """Send reads ``indices`` in one report; False (nothing recorded) if the client is gone."""
        writer = self._writer
        if writer is None:
            return False
        message = messages.RO_ACCESS_REPORT(tag_report_datas=[self._report(i, content) for i in indices])
        async with self._send_lock:
            try:
                writer.write(message.to_bytes(message_id=0))
                await writer.drain()
            except (ConnectionError, OSError):
                return False
        self.sent.extend(indices)
        return True

    async def _drop_connection(self) -> None:
        """Close the client's connection after what was written reached the socket."""
        self.drops += 1
        writer = self._writer
        if writer is not None:
            with contextlib.suppress(Exception):
                await writer.drain()
                writer.close()

    async def _report_loop(self) -> None:
        loop = asyncio.get_running_loop()
        if self._world_start is None:
            self._world_start = loop.time()
        # Reads whose time passed while nothing was inventorying were never read.
        while not self.finished and self._time_s[self._next] < self.world_time_s():
            self._next += 1
            self.unsent += 1
        while True:
            now = self.world_time_s()
            if self.drop_after_s is not None and self.drops == 0 and now >= self.drop_after_s:
                await self._drop_connection()
                return
            profile = self._scan_profile()
            batch: list[int] = []
            while not self.finished and self._time_s[self._next] <= now and len(batch) < BATCH:
                i = self._next
                self._next += 1
                if int(self._antenna[i]) in profile.antennas:
                    batch.append(i)
                else:
                    self.unsent += 1
            if batch and not await self._send_batch(batch, profile.content):
                self.unsent += len(batch)
                return
            if len(batch) == BATCH:
                await asyncio.sleep(0)  # more are due: yield, then go on
                continue
            if self.finished:
                await asyncio.sleep(0.05)
                continue
            wait = (self._time_s[self._next] - self.world_time_s()) / self.speed
            await asyncio.sleep(min(max(wait, 0.0), 0.05))
