"""``reads.csv`` to ``track.csv`` as a stream: memory set by the tags, not the recording's length.

The reader (:class:`scattertrack.io.reads_chunks.ReadsStream`) releases
time-ordered batches; each goes through the engine (``tracker._engine.run``,
as :func:`scattertrack.track.run` does it) and its rows are written at once
(:class:`scattertrack.io.track_chunks.TrackWriter`): the same rows, bytes and
skip report as ``track.run`` then ``io.write_track``. The engine and the
writer work on one batch in a second thread (both release the GIL) while
the next batch is parsed, so two cores are busy; batches are handed over
in order, one at a time, so the output does not depend on the timing.

What stays in memory: per-tag counters for the summary (rows, unresolved
rows, the widest sigma) and, for the static-tag check
(:mod:`scattertrack.track.plausibility`), per tag a sample of its track
speeds and per tag and antenna one of its phase-turn speeds, each holding
every value up to :data:`SPEED_SAMPLES` (:data:`TURN_SAMPLES`) and a systematic sample of them
beyond (every 2nd, 4th, ... value): the medians are exact for shorter
tracks and close beyond. The full covariance is not kept: writers that need it
(MCAP, ROS 2) take the in-memory path.
"""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from scattertrack.io.reads_chunks import NeedsCheckedReader, NeedsWholeFile, ReadsStream
from scattertrack.io.track_chunks import TrackWriter
from scattertrack.io.types import Scene, SkipReport
from scattertrack.physics import SPEED_OF_LIGHT
from scattertrack.track import make
from scattertrack.track import parameters, plausibility
from scattertrack.track.columns import READS_DECLINED, declined_skips

__all__ = ["NeedsWholeFile", "StreamedReads", "StreamedTrack", "track_file"]

DECLINED = READS_DECLINED
"""The tracker's counters reported as skipped reads (the same table as ``track.run``'s)."""

SPEED_SAMPLES = 512
"""Track speeds kept per tag for the static-tag check's median (4 kB a tag): every one up to 17 s of 30 rows/s."""

TURN_SAMPLES = 256
"""Phase-turn speeds kept per tag and antenna for that check (2 kB each)."""

PAIR_PERIOD_RAD = 2.0 * math.pi
"""The phase period the static-tag check assumes, as ``track`` calls it (its default)."""


class Samples:
    """Per group, every value up to ``capacity``; then a systematic sample (every 2nd, 4th, ... value).

    When a group's sample is full it keeps its even positions and the stride
    doubles, so the values kept are always those whose index in the group's
    stream is a multiple of the stride: deterministic, and bounded.
    """

    def __init__(self, capacity: int):
        self.capacity = capacity
        self.slot = np.zeros(0, dtype=np.int64)  # group -> row of values, -1 before its first value
        self.values = np.zeros((0, capacity))
        self.count = np.zeros(0, dtype=np.int64)  # values kept, per row
        self.seen = np.zeros(0, dtype=np.int64)  # values offered, per row
        self.stride = np.zeros(0, dtype=np.int64)

    def _slots(self, groups: np.ndarray) -> np.ndarray:
        top = int(groups.max()) + 1
        if top > len(self.slot):
            self.slot = np.concatenate([self.slot, np.full(top - len(self.slot), -1, dtype=np.int64)])
        fresh = np.unique(groups[self.slot[groups] < 0])
        if fresh.size:
            first = len(self.count)
            self.slot[fresh] = np.arange(first, first + fresh.size)
            grow = max(fresh.size, len(self.count))  # amortised: at least double
            if first + fresh.size > len(self.values):
                self.values = np.concatenate([self.values, np.empty((grow, self.capacity))])
            self.count = np.concatenate([self.count, np.zeros(fresh.size, dtype=np.int64)])
            self.seen = np.concatenate([self.seen, np.zeros(fresh.size, dtype=np.int64)])
            self.stride = np.concatenate([self.stride, np.ones(fresh.size, dtype=np.int64)])
        return self.slot[groups]

    def add(self, groups: np.ndarray, values: np.ndarray) -> None:
        """Offer ``values[i]`` to group ``groups[i]``, in stream order."""
        if not len(groups):
            return
        order = np.argsort(groups, kind="stable")
        slots = self._slots(groups[order])
        values = values[order]
        starts = np.flatnonzero(np.concatenate([[True], slots[1:] != slots[:-1]]))
        rank = np.arange(len(slots)) - np.repeat(starts, np.diff(np.concatenate([starts, [len(slots)]])))
        index = self.seen[slots] + rank
        while True:
            keep = index % self.stride[slots] == 0
            kept = np.bincount(slots[keep], minlength=len(self.count))
            full = np.flatnonzero(self.count + kept > self.capacity)
            if not full.size:
                break
            half = self.values[full, 0 : self.capacity : 2]
            self.values[full, : half.shape[1]] = half
            self.count[full] = (self.count[full] + 1) // 2
            self.stride[full] *= 2
        kept_slots = slots[keep]
        starts_kept = np.flatnonzero(np.concatenate([[True], kept_slots[1:] != kept_slots[:-1]])) if kept_slots.size else kept_slots
        if kept_slots.size:
            runs = np.diff(np.concatenate([starts_kept, [len(kept_slots)]]))
            rank_kept = np.arange(len(kept_slots)) - np.repeat(starts_kept, runs)
            self.values[kept_slots, self.count[kept_slots] + rank_kept] = values[keep]
        self.count += kept
        self.seen += np.bincount(slots, minlength=len(self.seen))

    def median(self, group: int) -> float:
        """The median of the group's sample (nan for a group without values)."""
        if group >= len(self.slot) or self.slot[group] < 0:
            return math.nan
        row = self.slot[group]
        return float(np.median(self.values[row, : self.count[row]]))


MAX_SHARDS = 4
"""Engines a stream splits its tags over, at most (one per core)."""


class Shards:
    """Tags split over engines (tag code modulo the count), each run in its own thread; rows merged in input order.

    Each tag's tracker lives in one engine and sees its reads in the same
    order as in a single engine, and every read gives at most one row, so
    the merged rows are those of one engine, whatever the timing.
    """

    def __init__(self, method: str, scene: Scene, params: dict, count: int | None = None):
        count = count or max(1, min(os.cpu_count() or 1, MAX_SHARDS))
        self.engines = [make(method, scene, **params)._engine for _ in range(count)]
        self.pool = ThreadPoolExecutor(max_workers=count) if count > 1 else None

    def run(self, tag: np.ndarray, time_s: np.ndarray, antenna: np.ndarray, frequency_hz: np.ndarray,
            phase_rad: np.ndarray) -> dict:
        """``Engine.run``'s columns for these reads (``row`` indexes them), with ``sigma`` (n, 3) for the covariance."""
        count = len(self.engines)
        if count == 1:
            return self.engines[0].run(tag, time_s, antenna, frequency_hz, phase_rad, covariance=False)
        shard = tag % count
        picks = [np.flatnonzero(shard == k) for k in range(count)]
        jobs = [self.pool.submit(engine.run, tag[rows], time_s[rows], antenna[rows], frequency_hz[rows], phase_rad[rows],
                                 covariance=False)
                for engine, rows in zip(self.engines, picks)]
        outs = [job.result() for job in jobs]
        rows = np.concatenate([rows[out["row"]] for rows, out in zip(picks, outs)])
        order = np.argsort(rows, kind="stable")
        merged = {name: np.concatenate([out[name] for out in outs])[order] for name in outs[0] if name != "row"}
        merged["row"] = rows[order]
        return merged

    def stats(self, tag: int) -> dict:
        return dict(self.engines[tag % len(self.engines)].stats(tag))

    def latency(self) -> tuple[int, float, int]:
        """(steps, mean ns, max ns) over every engine."""
        parts = [engine.latency() for engine in self.engines]
        steps = sum(p[0] for p in parts)
        mean = sum(p[0] * p[1] for p in parts) / steps if steps else 0.0
        return steps, mean, max(p[2] for p in parts)

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()


@dataclass
class TagFigures:
    """What the summary needs of the track, per tag code (arrays grown as tags appear)."""

    first_row: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    unresolved_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    last_unresolved: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    widest: np.ndarray = field(default_factory=lambda: np.zeros(0))
    finite_speed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    speeds: Samples = field(default_factory=lambda: Samples(SPEED_SAMPLES))

    def grow(self, tags: int) -> None:
        extra = tags - len(self.rows)
        if extra > 0:
            self.first_row = np.concatenate([self.first_row, np.full(extra, np.iinfo(np.int64).max)])
            self.rows = np.concatenate([self.rows, np.zeros(extra, dtype=np.int64)])
            self.unresolved_rows = np.concatenate([self.unresolved_rows, np.zeros(extra, dtype=np.int64)])
            self.last_unresolved = np.concatenate([self.last_unresolved, np.zeros(extra, dtype=bool)])
            self.widest = np.concatenate([self.widest, np.full(extra, -np.inf)])
            self.finite_speed = np.concatenate([self.finite_speed, np.zeros(extra, dtype=bool)])

    def add(self, first_row: int, tag: np.ndarray, sigma: np.ndarray, velocity: np.ndarray, unresolved_sigma_m: float) -> None:
        """One batch of track rows (global row numbers from ``first_row``)."""
        if not len(tag):
            return
        self.grow(int(tag.max()) + 1)
        with np.errstate(invalid="ignore"):
            largest = np.nanmax(sigma, axis=1) if sigma.shape[0] else np.zeros(0)
        unresolved = largest > unresolved_sigma_m
        rows = first_row + np.arange(len(tag))
        np.minimum.at(self.first_row, tag, rows)
        self.rows += np.bincount(tag, minlength=len(self.rows))
        self.unresolved_rows += np.bincount(tag, weights=unresolved, minlength=len(self.rows)).astype(np.int64)
        np.maximum.at(self.widest, tag, largest)
        reversed_tag = tag[::-1]
        last_tags, last_index = np.unique(reversed_tag, return_index=True)
        self.last_unresolved[last_tags] = unresolved[::-1][last_index]
        speed = np.linalg.norm(velocity, axis=1)
        finite = np.isfinite(speed)
        self.finite_speed[tag[finite]] = True
        present = ~np.isnan(speed)
        self.speeds.add(tag[present], speed[present])


class TurnEvidence:
    """Phase-turn speeds between close reads of one tag, antenna and channel (:func:`plausibility.radial_speed_bound`).

    A pair is two reads of one tag and antenna, consecutive in (channel, time)
    order, less than :data:`plausibility.PAIR_GAP_S` apart: a batch is paired
    with the reads of the previous batches that are that close (the tail).
    """

    def __init__(self, antennas: int):
        self.antennas = antennas
        self.tail = None
        self.pairs = np.zeros(0, dtype=np.int64)  # per tag*antennas + antenna
        self.samples = Samples(TURN_SAMPLES)

    def add(self, batch: dict, antenna_index: np.ndarray) -> None:
        columns = {"tag": batch["epc"], "antenna": antenna_index, "time_s": batch["time_s"],
                   "frequency_hz": batch["frequency_hz"], "phase_rad": batch["phase_rad"]}
        fresh = len(columns["tag"])
        if self.tail is not None:
            columns = {n: np.concatenate([self.tail[n], values]) for n, values in columns.items()}
        t, f, phase = columns["time_s"], columns["frequency_hz"], columns["phase_rad"]
        new = np.arange(len(t)) >= len(t) - fresh
        channel = np.round(f)
        order = np.lexsort((t, channel, columns["antenna"], columns["tag"]))
        tag, antenna, channel = columns["tag"][order], columns["antenna"][order], channel[order]
        t, f, phase, new = t[order], f[order], phase[order], new[order]
        dt = np.diff(t)
        same = ((tag[1:] == tag[:-1]) & (antenna[1:] == antenna[:-1]) & (np.abs(np.diff(f)) < 1e3)
                & (dt > 0) & (dt < plausibility.PAIR_GAP_S) & new[1:])
        if same.any():
            # The arithmetic of plausibility.radial_speed_bound, term for term.
            period = PAIR_PERIOD_RAD
            turn = np.diff(phase)[same]
            turn = np.abs((turn + 0.5 * period) % period - 0.5 * period)
            wavelength = SPEED_OF_LIGHT / f[1:][same]
            scale = 2.0 * np.pi / period
            speed = turn * wavelength / (4.0 * np.pi * scale * dt[same])
            group = tag[1:][same] * self.antennas + antenna[1:][same]
            # Group order within a batch is (tag, antenna, channel, time); within
            # each group the stream order the sample needs is (channel, time) too.
            top = int(group.max()) + 1
            if top > len(self.pairs):
                self.pairs = np.concatenate([self.pairs, np.zeros(top - len(self.pairs), dtype=np.int64)])
            self.pairs += np.bincount(group, minlength=len(self.pairs))
            self.samples.add(group, speed)
        # What a later read can pair with: the latest read of each tag,
        # antenna and channel, if recent enough (a read's predecessor in this
        # order is a new read or the last old read of some such group). Not
        # every read of the last 0.5 s: that tail was twice the batch.
        latest = float(batch["time_s"].max())
        last = np.ones(len(t), dtype=bool)
        last[:-1] = (tag[1:] != tag[:-1]) | (antenna[1:] != antenna[:-1]) | (channel[1:] != channel[:-1])
        keep = last & (t > latest - plausibility.PAIR_GAP_S)
        self.tail = {"tag": tag[keep], "antenna": antenna[keep], "time_s": t[keep], "frequency_hz": f[keep],
                     "phase_rad": phase[keep]}

    def bound(self, tag: int) -> float:
        """The largest per-antenna median radial speed (m/s); nan without enough pairs."""
        bounds = []
        for a in range(self.antennas):
            group = tag * self.antennas + a
            if group < len(self.pairs) and self.pairs[group] >= plausibility.MIN_PAIRS:
                bounds.append(self.samples.median(group))
        return max(bounds) if bounds else float("nan")


@dataclass
class StreamedReads:
    """What the summary and the geometry check read of the reads, without the reads."""

    count: int
    tags: list[str]
    """Every tag, in order of first appearance."""
    reordered: int
    channel_counts: tuple[np.ndarray, np.ndarray, np.ndarray]
    """(frequency Hz, antenna id, reads) per distinct pair (:func:`scattertrack.check.check_scene` takes them)."""

    def __len__(self) -> int:
        return self.count


@dataclass
class StreamedTrack:
    """What ``track`` reports of a streamed run, in place of the Track (its length: the rows written)."""

    rows: int
    tracked_tags: int
    skipped: SkipReport
    stats: dict
    """Per tag, by EPC in sorted order, as ``track.run`` gives them."""
    latency: tuple
    summary_warnings: list[str]
    """The unresolved and implausible-speed ``warning:`` lines, in the order ``track`` prints them."""
    reads: StreamedReads
    wall_s: float

    def __len__(self) -> int:
        return self.rows


def track_file(method: str, scene: Scene, reads_path, out_path, params: dict, *,
               unresolved_sigma_m: float, shards: int | None = None) -> StreamedTrack:
    """Track ``reads_path`` (reads.csv) into ``out_path`` (track.csv) as a stream.

    Raises :class:`NeedsWholeFile` before writing anything for a file the
    stream cannot take as the in-memory reader would (see
    :mod:`scattertrack.io.reads_chunks`); FormatError as ``io.read_reads`` does.
    ``unresolved_sigma_m``: the sigma above which a row counts as unresolved;
    ``shards``: engines the tags are split over (default: one per core, at most
    :data:`MAX_SHARDS`).
    """
    start = time.perf_counter()
    try:
        result = _track_stream(method, scene, reads_path, out_path, params, unresolved_sigma_m, shards, fast=True)
    except NeedsCheckedReader:
        # A cell pyarrow's fast path leaves to the checked reader: start over with it.
        result = _track_stream(method, scene, reads_path, out_path, params, unresolved_sigma_m, shards, fast=False)
    result.wall_s = time.perf_counter() - start
    return result


def _track_stream(method: str, scene: Scene, reads_path, out_path, params: dict, unresolved_sigma_m: float,
                  shards: int | None, fast: bool) -> StreamedTrack:
    engines = Shards(method, scene, parameters.offline(method, params), shards)
    ids = np.array([a.id for a in scene.antennas], dtype=np.int64)
    by_id = np.argsort(ids)
    stream = ReadsStream(reads_path, scene, fast=fast)
    figures = TagFigures()
    turns = TurnEvidence(len(ids))
    channels: dict[tuple[float, int], int] = {}
    written = [0]

    def track_batch(batch: dict, antenna_index: np.ndarray, texts: list[str], writer: TrackWriter) -> None:
        out = engines.run(batch["epc"], batch["time_s"], antenna_index, batch["frequency_hz"], batch["phase_rad"])
        row = out["row"]
        if not len(row):
            return
        sigma = out["sigma"]
        tag = batch["epc"][row]
        writer.write(out["time_s"], tag, texts, out["position"], out["velocity"], sigma)
        figures.add(written[0], tag, sigma, out["velocity"], unresolved_sigma_m)
        written[0] += len(row)

    writer = TrackWriter(out_path)
    try:
        with ThreadPoolExecutor(max_workers=1) as worker:
            running = None
            for batch in stream:
                antenna_index = by_id[np.searchsorted(ids, batch["antenna"], sorter=by_id)]
                texts = stream.epc_texts
                if running is not None:
                    running.result()
                running = worker.submit(track_batch, batch, antenna_index, texts, writer)
                turns.add(batch, antenna_index)
                _count_channels(channels, batch)
            if running is not None:
                running.result()
    except BaseException:
        writer.discard()
        raise
    finally:
        engines.close()
    writer.close()
    texts = stream.epc_texts
    names = sorted(range(len(texts)), key=texts.__getitem__)
    stats = {texts[code]: engines.stats(code) for code in names}
    skipped = declined_skips(stream.skipped, stats, DECLINED)
    figures.grow(len(texts))
    keys = list(channels)
    counts = (np.array([k[0] for k in keys], dtype=np.float64), np.array([k[1] for k in keys], dtype=np.int64),
              np.array([channels[k] for k in keys], dtype=np.int64))
    return StreamedTrack(
        rows=written[0], tracked_tags=int(np.count_nonzero(figures.rows)), skipped=skipped, stats=stats,
        latency=engines.latency(),
        summary_warnings=_unresolved_lines(figures, texts, unresolved_sigma_m) + _implausible_lines(figures, turns, texts),
        reads=StreamedReads(stream.rows, texts, stream.reordered, counts), wall_s=0.0,
    )


def _count_channels(channels: dict, batch: dict) -> None:
    """Adds the batch's reads per (frequency Hz, antenna id), new pairs in (frequency, antenna) order."""
    # Two 1-D uniques and a bincount: np.unique(axis=0) over the pairs sorts
    # rows as opaque bytes and took as long as parsing the batch.
    frequencies, f = np.unique(batch["frequency_hz"], return_inverse=True)
    antennas, a = np.unique(batch["antenna"], return_inverse=True)
    counts = np.bincount(f * len(antennas) + a, minlength=len(frequencies) * len(antennas))
    for code in np.flatnonzero(counts).tolist():
        key = (float(frequencies[code // len(antennas)]), int(antennas[code % len(antennas)]))
        channels[key] = channels.get(key, 0) + int(counts[code])


def _unresolved_lines(figures: TagFigures, texts: list[str], sigma_m: float) -> list[str]:
    """``cli.unresolved_warnings``'s lines from the per-tag figures (one wording: plausibility.unresolved_line)."""
    lines = []
    tracked = np.flatnonzero(figures.rows > 0)
    for k in tracked[np.argsort(figures.first_row[tracked], kind="stable")].tolist():
        if figures.last_unresolved[k]:
            share = figures.unresolved_rows[k] / figures.rows[k]
            lines.append(plausibility.unresolved_line(texts[k], float(share), float(figures.widest[k]), sigma_m))
    return lines


def _implausible_lines(figures: TagFigures, turns: TurnEvidence, texts: list[str]) -> list[str]:
    """``plausibility.implausible_speed_warnings``'s lines from the samples (one wording: plausibility.static_line)."""
    lines = []
    tracked = np.flatnonzero(figures.rows > 0)
    for k in tracked[np.argsort(figures.first_row[tracked], kind="stable")].tolist():
        if figures.rows[k] < plausibility.MIN_ROWS or not figures.finite_speed[k]:
            continue
        speed = figures.speeds.median(k)
        bound = turns.bound(k)
        if plausibility.implausible(speed, bound):
            lines.append(plausibility.static_line(texts[k], speed, bound))
    return lines
