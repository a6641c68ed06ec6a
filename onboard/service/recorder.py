"""The service's recordings: every raw input, recorded as the engine consumed it, and their
exact replay.

* :class:`Recorder` writes the service's recording (format: :mod:`drivers.recording`):
  every raw chunk of every input with its receive time, a ``tick`` record at each engine
  tick and a ``meta`` record (JSON: config, sources, restored adaptive state) at the start
  of each file. Files rotate at ``rotate_mb``; the oldest are deleted beyond
  ``max_total_mb``; data reaches the disk (``fsync``, in a worker thread so the estimator
  loop never waits on the disk) at most ``flush_interval_s`` after it was received. A
  crash loses at most that interval and leaves at most one torn frame, which the reader
  skips. The :class:`onboard.service.intake.Intake` writes the records.
* :func:`replay_recording` feeds a recording through a fresh
  :class:`~onboard.service.intake.Intake` in file order, which reproduces the live
  estimates exactly: same bytes, same parsers, same ticks, same order of pushes, and the
  same frames rejected on signing grounds (the recorded verdicts,
  :class:`drivers.mavlink_signing.VerdictPlayer`; the replay needs no key). (Replaying
  with :func:`onboard.engine.run` and the tick times alone is exact only when no sample
  arrives after a tick that its time stamp precedes: an NMEA fix stamped at its first
  sentence but completed by a later one, or a chunk stamped just before a tick and
  processed just after it, would land one tick earlier.)
"""

from __future__ import annotations

import concurrent.futures
import json
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import msgspec

from drivers.base import ReadStats
from drivers.protocols import UnknownProtocol
from drivers.recording import (
    VERDICTS_KIND,
    VERDICTS_VERSION,
    RawRecord,
    RecordingWriter,
    read_records,
    with_verdicts,
)
from onboard.core.config import Config
from onboard.core.messages import EstimateRecord
from onboard.engine import Engine
from onboard.service.intake import Intake

log = logging.getLogger(__name__)

SUFFIX = ".onbrec"
"""File name suffix of recordings."""
META_FORMAT = 1
"""Version of the JSON in ``meta`` records."""


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
    if not isinstance(cfg, dict):
        return None
    for src in (cfg.get("service") or {}).get("sources") or []:
        if isinstance(src, dict) and src.get("kind") == "mavlink" and "autopilot_time" not in src:
            # made before the autopilot link existed: every frame was decoded and stamped
            # with its receive time; replay it so
            src.update(autopilot_time=False, filter_components=False)
    return from_dict(cfg, str(path))


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
