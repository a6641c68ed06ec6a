"""The recorder and the intake: every raw input, recorded as the engine consumed it.

Two pieces that belong together because replay must take exactly the path live did:

* :class:`Recorder` writes the service's recording (format: :mod:`drivers.recording`):
  every raw chunk of every input with its receive time, a ``tick`` record at each engine
  tick and a ``meta`` record (JSON: config, sources, restored adaptive state) at the start
  of each file. Files rotate at ``rotate_mb``; the oldest are deleted beyond
  ``max_total_mb``; data reaches the disk (``fsync``, in a worker thread so the estimator
  loop never waits on the disk) at most ``flush_interval_s`` after it was received. A
  crash loses at most that interval and leaves at most one torn frame, which the reader
  skips.
* :class:`Intake` is the one gate from raw bytes to the engine: ``chunk()`` records a
  chunk, parses it (:func:`drivers.protocols.parser_for`) and queues its samples in a
  bounded queue (drops counted per source); ``tick(T)`` records the tick, pushes the
  queued samples stamped ``t <= T`` (later ones wait for the next tick, so a pipeline
  never sees a sample from its future) and steps the engine. Parsers with a
  ``poll(t)`` (NMEA: an epoch held past its hold time) are polled at every tick, so
  that too is replayed exactly. When MAVLink signing is verified (``verifier``), each
  MAVLink chunk is recorded after it was parsed, in one write with a ``verdicts`` record
  listing the frames the verifier rejected in it (only when it rejected any), in a
  format-version-2 file (:mod:`drivers.recording`).

:func:`replay_recording` feeds a recording through a fresh :class:`Intake` in file order,
which reproduces the live estimates exactly: same bytes, same parsers, same ticks, same
order of pushes, and the same frames rejected on signing grounds (the recorded verdicts,
:class:`drivers.mavlink_signing.VerdictPlayer`; the replay needs no key). (Replaying with :func:`onboard.engine.run` and the tick times alone is
exact only when no sample arrives after a tick that its time stamp precedes: an NMEA fix
stamped at its first sentence but completed by a later one, or a chunk stamped just
before a tick and processed just after it, would land one tick earlier.)
"""

from __future__ import annotations

import concurrent.futures
import json
import logging
import os
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import msgspec

from drivers.base import ReadStats, StreamParser
from drivers.mavlink_signing import SignatureVerifier, VerdictLog, VerdictPlayer
from drivers.protocols import UnknownProtocol, parser_for
from drivers.recording import (
    VERDICTS_KIND,
    VERDICTS_VERSION,
    RawRecord,
    RecordingWriter,
    Verdicts,
    encode_verdicts,
    read_records,
    with_verdicts,
)
from onboard.core.config import Config
from onboard.core.messages import EstimateRecord, Sample
from onboard.engine import Engine

log = logging.getLogger(__name__)

SUFFIX = ".onbrec"
"""File name suffix of recordings."""
META_FORMAT = 1
"""Version of the JSON in ``meta`` records."""
TICK_SOURCE = "engine"


class Recorder:
    """Crash-safe, rotating, size-capped writer of raw records.

    Parameters:
        directory: where recordings go (created).
        flush_interval_s: longest time (s, on ``clock``) a record waits before it is
            handed to the OS and fsync'ed.
        rotate_mb: start a new file when the current one reaches this size (MB = 1e6 B).
        max_total_mb: delete the oldest recordings in ``directory`` beyond this total.
        meta: JSON-ready metadata written as the first record of every file.
        clock: receive-time clock (s), used for the flush interval.
        fsync: make flushed data durable (off only in tests of throughput).
        version: format version of the files (:mod:`drivers.recording`): 2 when MAVLink
            signatures are verified (``verdicts`` records), else 1, which older readers
            read too. :meth:`write` moves to a version-2 file by itself (a new part) if
            given ``verdicts`` with a lower version.
    """

    def __init__(self, directory: str | Path, *, flush_interval_s: float = 0.5,
                 rotate_mb: float = 64.0, max_total_mb: float = 2048.0,
                 meta: dict[str, Any] | None = None,
                 clock: Callable[[], float] = time.monotonic, fsync: bool = True,
                 version: int = 1) -> None:
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.flush_interval_s = max(0.0, flush_interval_s)
        self.rotate_bytes = max(4096, int(rotate_mb * 1e6))
        self.max_total_bytes = max(self.rotate_bytes, int(max_total_mb * 1e6))
        self.meta = dict(meta or {})
        self.clock = clock
        self.fsync = fsync
        self.version = version
        self.run_id = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime()) + "-" + os.urandom(2).hex()
        """Names this service start: UTC start time and a random suffix."""
        self.part = 0
        self.records = 0
        self.files: list[Path] = []
        self.deleted: list[Path] = []
        self.write_errors = 0
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="recorder")
        self._pending_sync: concurrent.futures.Future[None] | None = None
        self._dirty = False
        self._last_flush = clock()
        self._writer: RecordingWriter | None = None
        self._open()

    @property
    def path(self) -> Path | None:
        """The file being written."""
        return self._writer.path if self._writer is not None else None

    def _open(self) -> None:
        path = self.directory / f"onboard-{self.run_id}-{self.part:04d}{SUFFIX}"
        n = 0
        while path.exists():  # two starts within one second
            n += 1
            path = self.directory / f"onboard-{self.run_id}-{self.part:04d}.{n}{SUFFIX}"
        self._writer = RecordingWriter(path, fsync=self.fsync, version=self.version)
        self.files.append(path)
        meta = dict(self.meta, format=META_FORMAT, part=self.part, run=self.run_id,
                    wall_time=time.time(), clock=self.clock())
        if self.part > 0:
            meta.pop("state", None)  # the adaptive state at start belongs to part 0
        self._writer.write(RawRecord(t=self.clock(), source="recorder", kind="meta",
                                     data=json.dumps(meta, default=str).encode()))
        self._dirty = True
        self._enforce_cap()

    def write(self, rec: RawRecord, *more: RawRecord) -> None:
        """Append one record (and ``more``, in the same write: never split by a flush or
        a rotation); flush when the interval is due; rotate when the file is full.

        A disk error (full, read-only) is counted in ``write_errors`` and logged once per
        file; it never reaches the caller.
        """
        if self.version < VERDICTS_VERSION and (
                rec.kind == VERDICTS_KIND or any(r.kind == VERDICTS_KIND for r in more)):
            self.version = VERDICTS_VERSION
            self.rotate()
        w = self._writer
        if w is None:
            return
        try:
            w.write(rec, *more)
        except OSError as err:
            self.write_errors += 1
            if self.write_errors == 1:
                log.error("recorder: cannot write %s: %s", w.path, err)
            return
        self.records += 1 + len(more)
        self._dirty = True
        if w.bytes_written >= self.rotate_bytes:
            self.rotate()
        else:
            self.poll(self.clock())

    def poll(self, now: float) -> None:
        """Flush if the flush interval has passed since the last flush (call it often)."""
        if self._dirty and now - self._last_flush >= self.flush_interval_s:
            self.flush(now)

    def flush(self, now: float | None = None, wait: bool = False) -> None:
        """Hand buffered records to the OS now and fsync them in the worker thread
        (``wait`` blocks until they are on disk)."""
        w = self._writer
        self._last_flush = self.clock() if now is None else now
        if w is None:
            return
        self._dirty = False
        prev = self._pending_sync
        if prev is not None and not prev.done():
            if not wait:
                self._dirty = True  # the previous sync is still running; try again later
                return
            prev.result()
        try:
            if wait:
                w.flush()
            else:
                self._pending_sync = self._pool.submit(self._sync, w)
        except OSError as err:
            self.write_errors += 1
            log.error("recorder: flush failed on %s: %s", w.path, err)

    def _sync(self, w: RecordingWriter) -> None:
        try:
            w.flush()
        except (OSError, ValueError) as err:  # ValueError: closed meanwhile
            self.write_errors += 1
            log.error("recorder: flush failed on %s: %s", w.path, err)

    def rotate(self) -> None:
        """Close the current file and start the next part."""
        self._close_writer()
        self.part += 1
        self._open()

    def _close_writer(self) -> None:
        w = self._writer
        if w is None:
            return
        if self._pending_sync is not None:
            self._pending_sync.result()
            self._pending_sync = None
        try:
            w.close()
        except OSError as err:
            self.write_errors += 1
            log.error("recorder: close failed on %s: %s", w.path, err)
        self._writer = None

    def _enforce_cap(self) -> None:
        files = sorted(self.directory.glob(f"*{SUFFIX}"), key=lambda p: (p.stat().st_mtime, p.name))
        sizes = {p: p.stat().st_size for p in files}
        total = sum(sizes.values())
        current = self.path
        for p in files:
            if total <= self.max_total_bytes:
                break
            if p == current:
                continue
            try:
                p.unlink()
            except OSError:
                continue
            total -= sizes[p]
            self.deleted.append(p)
            log.info("recorder: deleted %s (size cap %.0f MB)", p.name, self.max_total_bytes / 1e6)

    def close(self) -> None:
        """Flush, fsync and close; idempotent."""
        self._close_writer()
        self._pool.shutdown(wait=True)


# --------------------------------------------------------------------------- the intake


@dataclass
class SourceState:
    """Per-input counters the intake keeps for health."""

    kind: str
    parser: StreamParser
    chunks: int = 0
    bytes: int = 0
    samples: int = 0
    t_last: float | None = None
    parser_errors: int = 0
    verdicts: VerdictLog | VerdictPlayer | None = None
    """The parser's verifier when signing is verified live (a log of its rejections, for
    the recording) or when replaying (the recorded rejections)."""


@dataclass
class Intake:
    """Raw chunks in, samples to the engine at ticks (see the module docstring).

    ``queue_size`` bounds the samples waiting for the next tick; beyond it new samples are
    dropped and counted in ``dropped[source]``.
    """

    engine: Engine
    queue_size: int = 4096
    recorder: Recorder | None = None
    sources: dict[str, SourceState] = field(default_factory=dict)
    dropped: Counter[str] = field(default_factory=Counter)
    pending: deque[Sample] = field(default_factory=deque)
    ticks: int = 0
    on_queued: Callable[[], None] | None = None
    """Called after a chunk queued at least one sample (the service wakes a tick that
    waits for fresh data with it)."""

    verifier: SignatureVerifier | None = None
    """Set (before the sources are added) when MAVLink signing is required: every MAVLink
    input then rejects unsigned, forged and replayed frames (docs/security.md), and the
    rejections are recorded with the chunks."""

    replay: bool = False
    """A replay: MAVLink inputs reject the frames whose recorded verdicts say so
    (:func:`replay_recording` passes them to :meth:`chunk`)."""

    def add_source(self, name: str, kind: str) -> SourceState:
        """Register an input named ``name`` speaking protocol ``kind``."""
        st = self.sources.get(name)
        if st is None or st.kind != kind:
            v: VerdictLog | VerdictPlayer | None = None
            if kind == "mavlink":
                if self.replay:
                    v = VerdictPlayer()
                elif self.verifier is not None:
                    v = VerdictLog(self.verifier)
            st = self.sources[name] = SourceState(kind, parser_for(kind, name, verifier=v),
                                                  verdicts=v)
        return st

    def chunk(self, name: str, kind: str, data: bytes, t_rx: float,
              verdicts: Verdicts | None = None) -> int:
        """Record, parse and queue one raw chunk received at ``t_rx`` (s) on input
        ``name``; return the number of samples queued. Never raises on bad bytes.

        ``verdicts``: in a replay, the chunk's recorded signature verdicts."""
        st = self.sources.get(name)
        if st is None or st.kind != kind:
            st = self.add_source(name, kind)
        rec = self.recorder
        raw = RawRecord(t=t_rx, source=name, kind=kind, data=bytes(data)) if rec else None
        vlog = st.verdicts if type(st.verdicts) is VerdictLog else None
        player = st.verdicts if type(st.verdicts) is VerdictPlayer else None
        if raw is not None and vlog is None:
            rec.write(raw)  # before parsing: nothing a parser does can lose it
        if player is not None:
            player.load(verdicts)
        st.chunks += 1
        st.bytes += len(data)
        st.t_last = t_rx
        try:
            samples = st.parser.feed(data, t_rx)
        except Exception:  # noqa: BLE001 - a parser bug must not stop the service
            st.parser_errors += 1
            st.parser.stats.reject("parser_error")
            log.exception("parser for %s failed on a %d-byte chunk", name, len(data))
            samples = []
        if vlog is not None:  # signing verified: the chunk and its verdicts in one write
            v = vlog.take(data)
            if raw is not None and v is None:
                rec.write(raw)
            elif raw is not None:
                rec.write(raw, RawRecord(t=t_rx, source=name, kind=VERDICTS_KIND,
                                         data=encode_verdicts(v)))
        elif player is not None:
            player.done(st.parser.stats)
        return self._queue(name, st, samples, t_rx) if samples else 0

    def _queue(self, name: str, st: SourceState, samples: list[Sample], t_rx: float) -> int:
        queued = 0
        pending = self.pending
        for s in samples:
            if s.t > t_rx + 1.0:
                self.engine.push(s, now=t_rx)  # counted as "future" by the engine
                continue
            if len(pending) >= self.queue_size:
                self.dropped[name] += 1
                continue
            pending.append(s)
            queued += 1
        st.samples += queued
        if queued and self.on_queued is not None:
            self.on_queued()
        return queued

    def tick(self, t: float) -> list[EstimateRecord]:
        """Record a tick at ``t`` (s), push the queued samples with ``sample.t <= t`` and
        step the engine; return its estimates."""
        if self.recorder is not None:
            self.recorder.write(RawRecord(t=t, source=TICK_SOURCE, kind="tick", data=b""))
        for name, st in self.sources.items():
            poll = getattr(st.parser, "poll", None)
            if poll is not None:  # e.g. an NMEA epoch held past its hold time
                try:
                    self._queue(name, st, poll(t), t)
                except Exception:  # noqa: BLE001
                    st.parser_errors += 1
                    st.parser.stats.reject("parser_error")
        pending = self.pending
        push = self.engine.push
        if pending:
            keep: deque[Sample] = deque()
            for s in pending:
                if s.t <= t:
                    push(s, now=t)
                else:
                    keep.append(s)
            self.pending = keep
        self.ticks += 1
        return self.engine.tick(t)

    def parse_rejections(self) -> dict[str, int]:
        """Parser rejections by ``parse:<source>:<reason>``."""
        out: dict[str, int] = {}
        for name, st in self.sources.items():
            for reason, n in st.parser.stats.rejected.items():
                out[f"parse:{name}:{reason}"] = n
        return out


# --------------------------------------------------------------------------- replay


@dataclass
class ReplayResult:
    """What :func:`replay_recording` saw."""

    ticks: int = 0
    records: int = 0
    meta: list[dict[str, Any]] = field(default_factory=list)
    stats: ReadStats = field(default_factory=ReadStats)
    """Frame-level damage of the recording files (``truncated``, ``crc``, ...)."""
    rejected: dict[str, int] = field(default_factory=dict)
    """Parser rejections by ``parse:<input>:<reason>`` (engine ones are in engine.rejected)."""
    dropped: dict[str, int] = field(default_factory=dict)
    """Queue drops by input, as live."""


def recording_files(path: str | Path) -> list[Path]:
    """A recording file, or every recording in a directory in the order written."""
    p = Path(path)
    if p.is_dir():
        return sorted(p.glob(f"*{SUFFIX}"))
    return [p]


def recording_runs(directory: str | Path) -> dict[str, list[Path]]:
    """The recordings in ``directory`` grouped by run (one service start each), parts in
    order. Replay one run's parts together for an exact replay."""
    runs: dict[str, list[Path]] = {}
    for p in recording_files(directory):
        meta = recording_meta(p)
        run = str(meta.get("run") or p.stem)
        runs.setdefault(run, []).append(p)
    for parts in runs.values():
        parts.sort(key=lambda p: (int(recording_meta(p).get("part", 0) or 0), p.name))
    return runs


def recording_meta(path: str | Path) -> dict[str, Any]:
    """The first ``meta`` record of a recording file ({} when there is none)."""
    for rec in read_records(path):
        if rec.kind == "meta":
            try:
                return json.loads(rec.data)
            except ValueError:
                return {}
        return {}
    return {}


def recording_config(path: str | Path) -> Config | None:
    """The configuration the service ran with, from the recording's meta record."""
    from onboard.core.config import from_dict

    files = recording_files(path)
    if not files:
        return None
    cfg = recording_meta(files[0]).get("config")
    return from_dict(cfg, str(path)) if isinstance(cfg, dict) else None


def replay_recording(paths: str | Path | Iterable[str | Path], engine: Engine,
                     on_tick: Callable[[float, Sequence[EstimateRecord]], None],
                     *, queue_size: int | None = None,
                     restore_state: bool = True) -> ReplayResult:
    """Replay the service's recording(s) through ``engine`` exactly as live.

    ``paths`` is a file, a directory of parts, or a list of files in order (a directory
    holding several runs replays them one after the other, as one; pick one run with
    :func:`recording_runs` for an exact replay). The adaptive
    state the live service restored at start (meta ``state``) is restored into ``engine``
    first when ``restore_state``. ``on_tick(t, records)`` is called at every recorded tick.
    """
    if isinstance(paths, (str, Path)):
        files = recording_files(paths)
    else:
        files = [Path(p) for p in paths]
    qs = queue_size if queue_size is not None else engine.cfg.service.queue_size
    intake = Intake(engine, queue_size=qs, replay=True)
    result = ReplayResult()
    first = True
    for f in files:
        for rec, verdicts in with_verdicts(read_records(f, result.stats), result.stats):
            result.records += 1
            kind = rec.kind
            if kind == "tick":
                on_tick(rec.t, intake.tick(rec.t))
                result.ticks += 1
            elif kind == "meta":
                try:
                    meta = json.loads(rec.data)
                except ValueError:
                    continue
                result.meta.append(meta)
                if first and restore_state and isinstance(meta.get("state"), dict):
                    engine.set_state(meta["state"])
                if isinstance(meta.get("queue_size"), int) and queue_size is None:
                    intake.queue_size = meta["queue_size"]
            else:
                try:
                    intake.chunk(rec.source, kind, rec.data, rec.t, verdicts)
                except UnknownProtocol:  # a newer kind this reader does not know
                    result.stats.reject(f"unknown_kind:{kind}")
            first = False if kind != "meta" else first
    result.rejected = intake.parse_rejections()
    result.dropped = dict(intake.dropped)
    return result


def config_to_dict(cfg: Config) -> dict[str, Any]:
    """A configuration as plain JSON-ready data (for the meta record)."""
    data = msgspec.to_builtins(cfg)
    return data if isinstance(data, dict) else {}
