"""The service's recordings: every raw input, recorded as the engine consumed it, and their
exact replay.

* :class:`Recorder` writes the service's recording (format: :mod:`drivers.recording`):
  every raw chunk of every input with its receive time, a ``tick`` record at each engine
  tick and a ``meta`` record (JSON: config, sources, restored adaptive state) at the start
  of each file. Files rotate at ``rotate_mb``; the oldest are deleted beyond
  ``max_total_mb``; data reaches the disk (``fsync``, in a worker thread so the estimator
  loop never waits on the disk) at most ``flush_interval_s`` after it was recorded. The
  :class:`onboard.service.intake.Intake` writes the records: in the live service a chunk
  when it is parsed, at the latest at the next tick (``1/rate_hz`` after it was received).
  A crash loses at most these two intervals and leaves at most one torn frame, which the
  reader skips.
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
import math
import os
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import msgspec

from onboard.drivers.base import ReadStats
from onboard.drivers.protocols import UnknownProtocol
from onboard.drivers.recording import (
    VERDICTS_KIND,
    VERDICTS_VERSION,
    RawRecord,
    RecordingWriter,
    encode_frame,
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
FILES_LISTED = 256
"""Newest file names (count) :attr:`Recorder.files` and :attr:`Recorder.deleted` keep: a
service that records for weeks rotates a part every hour or so, and the older names are in
the log (deleted ones) or on the disk; 256 parts of the default 64 MB are eight times the
default size cap."""


def free_bytes(directory: Path) -> int:
    """Bytes available to an unprivileged writer on the file system of ``directory``."""
    st = os.statvfs(directory)
    return st.f_bavail * st.f_frsize


class Recorder:
    """Crash-safe, rotating, size-capped writer of raw records.

    The event loop only encodes records into memory (:meth:`write`); one worker thread
    opens, appends, fsyncs, rotates and deletes files, so the estimator loop never waits on
    the disk. What the disk refuses never reaches the caller: a write, fsync or open error
    (disk full, EIO) is counted (``write_errors``), the records of that batch are counted
    lost (``lost_records``) and the file is reopened for the next batch. Below
    ``min_free_mb`` free the oldest recordings are deleted; if that is not enough,
    recording pauses (records counted in ``dropped_records``) until the space is back.
    Records waiting for a slow disk are bounded by ``max_pending_mb``; beyond it they are
    dropped and counted too. Each of these is reported once per episode through
    ``on_event`` (called from :meth:`poll`, on the caller's thread).

    Parameters:
        directory: where recordings go (created).
        flush_interval_s: longest time (s, on ``clock``) a record waits before it is
            handed to the worker, written and fsync'ed.
        rotate_mb: start a new file when the current one reaches this size (MB = 1e6 B).
        max_total_mb: delete the oldest recordings in ``directory`` beyond this total.
        meta: JSON-ready metadata written as the first record of every file.
        clock: receive-time clock (s), used for the flush interval.
        fsync: make flushed data durable (off only in tests of throughput).
        version: format version of the files (:mod:`drivers.recording`): 2 when MAVLink
            signatures are verified (``verdicts`` records), else 1, which older readers
            read too. :meth:`write` moves to a version-2 file by itself (a new part) if
            given ``verdicts`` with a lower version.
        min_free_mb: free space (MB) the recorder leaves on the file system (0: no check).
        max_pending_mb: records (MB) allowed to wait for the disk.
        on_event: called with a one-line text for every error or disk-space episode.
        open_writer: ``(path, version) -> RecordingWriter``-like (tests inject failures).
        free_space: ``directory -> bytes free`` (default :func:`free_bytes`).
    """

    DISK_CHECK_S = 1.0
    """Shortest wall time (s) between two free-space checks of the worker."""

    def __init__(self, directory: str | Path, *, flush_interval_s: float = 0.5,
                 rotate_mb: float = 64.0, max_total_mb: float = 2048.0,
                 meta: dict[str, Any] | None = None,
                 clock: Callable[[], float] = time.monotonic, fsync: bool = True,
                 version: int = 1, min_free_mb: float = 0.0, max_pending_mb: float = 32.0,
                 on_event: Callable[[str], None] | None = None,
                 open_writer: Callable[[Path, int], RecordingWriter] | None = None,
                 free_space: Callable[[Path], int] = free_bytes) -> None:
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.flush_interval_s = max(0.0, flush_interval_s)
        self.rotate_bytes = max(4096, int(rotate_mb * 1e6))
        self.max_total_bytes = max(self.rotate_bytes, int(max_total_mb * 1e6))
        self.min_free_bytes = max(0, int(min_free_mb * 1e6))
        self.max_pending_bytes = max(1 << 16, int(max_pending_mb * 1e6))
        self.meta = dict(meta or {})
        self.clock = clock
        self.fsync = fsync
        self.version = version
        self.on_event = on_event
        self._open_writer = open_writer or (
            lambda path, v: RecordingWriter(path, fsync=self.fsync, version=v))
        self._free_space = free_space
        self.run_id = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime()) + "-" + os.urandom(2).hex()
        """Names this service start: UTC start time and a random suffix."""
        self.part = 0
        self.records = 0
        """Records accepted by :meth:`write` (handed to the worker)."""
        self.files: list[Path] = []
        """The parts written by this recorder, oldest first (the newest
        :data:`FILES_LISTED`)."""
        self.deleted: list[Path] = []
        """The recordings the size cap or the disk space deleted, oldest first (the newest
        :data:`FILES_LISTED`)."""
        self.write_errors = 0
        """Disk errors (write, fsync, open, close), counted by the worker."""
        self.lost_records = 0
        """Records of batches the disk refused (worker)."""
        self.dropped_records = 0
        """Records not recorded because recording was paused (disk full) or too many
        waited for the disk."""
        self.paused = False
        """Recording paused for lack of free space (set by the worker)."""
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="recorder")
        self._pending_sync: concurrent.futures.Future[None] | None = None
        self._buf: list[bytes] = []
        self._buf_records = 0
        self._file_bytes = 0
        self._submitted = 0
        self._done = 0
        self._events: deque[str] = deque()
        self._overflowing = False
        self._t_disk = -math.inf
        self._dirty = False
        self._last_flush = clock()
        self._writer: RecordingWriter | None = None
        """The open file; touched by the worker thread only."""
        self._want: tuple[Path, int] | None = None
        """The file the worker should be writing (path, version); worker only."""
        self._open()

    @property
    def path(self) -> Path | None:
        """The file being written."""
        return self.files[-1] if self.files else None

    @property
    def dropped(self) -> int:
        """Every record that did not reach the disk: lost, paused or overflowed."""
        return self.lost_records + self.dropped_records

    def _open(self) -> None:
        path = self.directory / f"onboard-{self.run_id}-{self.part:04d}{SUFFIX}"
        n = 0
        while path.exists() or path in self.files:  # two starts within one second
            n += 1
            path = self.directory / f"onboard-{self.run_id}-{self.part:04d}.{n}{SUFFIX}"
        self.files.append(path)
        if len(self.files) > FILES_LISTED:
            del self.files[:-FILES_LISTED]
        self._file_bytes = 0
        self._submit(self._switch_job, path, self.version)
        meta = dict(self.meta, format=META_FORMAT, part=self.part, run=self.run_id,
                    wall_time=time.time(), clock=self.clock())
        if self.part > 0:
            meta.pop("state", None)  # the adaptive state at start belongs to part 0
        self._append(encode_frame(RawRecord(t=self.clock(), source="recorder", kind="meta",
                                            data=json.dumps(meta, default=str).encode())), 0)
        self._dirty = True

    def _submit(self, fn: Callable[..., None], *args: Any) -> concurrent.futures.Future[None]:
        fut = self._pool.submit(fn, *args)
        self._pending_sync = fut
        return fut

    def _append(self, frames: bytes, n_records: int) -> None:
        self._buf.append(frames)
        self._buf_records += n_records
        self._file_bytes += len(frames)

    def write(self, rec: RawRecord, *more: RawRecord) -> None:
        """Append one record (and ``more``, in the same write: never split by a flush or
        a rotation); flush when the interval is due; rotate when the file is full.

        Never raises for the disk's sake and never waits for it (see the class docstring);
        after :meth:`close` it does nothing.
        """
        if self._pool is None:
            return
        if self.version < VERDICTS_VERSION and (
                rec.kind == VERDICTS_KIND or any(r.kind == VERDICTS_KIND for r in more)):
            self.version = VERDICTS_VERSION
            self.rotate()
        n = 1 + len(more)
        pending = self._submitted - self._done
        if self.paused or pending > self.max_pending_bytes:
            self.dropped_records += n
            if not self.paused and not self._overflowing:
                self._overflowing = True
                self._note(f"recorder: disk too slow, {pending / 1e6:.0f} MB waiting: "
                           "records dropped (counted)")
            return
        self._overflowing = False
        frames = encode_frame(rec)
        if more:
            frames += b"".join(encode_frame(r) for r in more)
        self._append(frames, n)
        self.records += n
        self._dirty = True
        if self._file_bytes >= self.rotate_bytes:
            self.rotate()
        else:
            self.poll(self.clock())

    def poll(self, now: float) -> None:
        """Flush if the flush interval has passed since the last flush, and report what
        the worker saw (call it often, from the thread that writes)."""
        if self._dirty and now - self._last_flush >= self.flush_interval_s:
            self.flush(now)
        while self._events:
            text = self._events.popleft()
            if self.on_event is not None:
                self.on_event(text)

    def flush(self, now: float | None = None, wait: bool = False) -> None:
        """Hand the records written so far to the worker, which writes and fsyncs them
        (``wait`` blocks until they are on disk)."""
        self._last_flush = self.clock() if now is None else now
        self._dirty = False
        if self._pool is None:
            return
        if self._buf:
            data = b"".join(self._buf)
            self._submitted += len(data)
            fut = self._submit(self._append_job, data, self._buf_records)
            self._buf, self._buf_records = [], 0
        else:
            fut = self._pending_sync
        if wait and fut is not None:
            fut.result()

    def rotate(self) -> None:
        """Close the current file and start the next part (both in the worker)."""
        self.flush()
        self.part += 1
        self._open()

    def close(self) -> None:
        """Flush, fsync and close, waiting for the worker; idempotent."""
        if self._pool is None:
            return
        self.flush()
        self._submit(self._switch_job, None, self.version)
        self._pool.shutdown(wait=True)
        self._pool = None  # type: ignore[assignment]
        self.poll(self.clock())

    # ------------------------------------------------------------------ worker thread

    def _note(self, text: str) -> None:
        """Queue an event for :meth:`poll` (any thread); log it when no ``on_event``
        takes it (the service's logs its events itself)."""
        if self.on_event is None:
            log.warning("%s", text)
        self._events.append(text)

    def _switch_job(self, path: Path | None, version: int) -> None:
        """Close the current file; open ``path`` (None: none)."""
        self._close_writer()
        self._want = (path, version) if path is not None else None
        if path is not None:
            self._ensure_writer()
            self._enforce_cap()

    def _close_writer(self) -> None:
        w, self._writer = self._writer, None
        if w is None:
            return
        try:
            w.close()
        except (OSError, ValueError) as err:
            self.write_errors += 1
            self._note(f"recorder: error closing {w.path.name}: {_why(err)}")

    def _ensure_writer(self) -> RecordingWriter | None:
        if self._writer is None and self._want is not None:
            path, version = self._want
            try:
                self._writer = self._open_writer(path, version)
            except OSError as err:
                self.write_errors += 1
                if self.write_errors == 1 or self.write_errors % 100 == 0:
                    self._note(f"recorder: error opening {path.name}: {_why(err)} "
                               f"({self.write_errors} errors)")
        return self._writer

    def _append_job(self, data: bytes, n_records: int) -> None:
        try:
            w = self._ensure_writer()
            if w is None:
                self.lost_records += n_records
                return
            try:
                w.write_encoded(data)
                w.flush()
            except (OSError, ValueError) as err:
                self.write_errors += 1
                self.lost_records += n_records
                if self.write_errors == 1 or self.write_errors % 100 == 0:
                    self._note(f"recorder: write error on {w.path.name}: {_why(err)}; "
                               f"{self.lost_records} records lost ({self.write_errors} errors)")
                self._writer = None  # reopened for the next batch
                try:
                    w.close()
                except (OSError, ValueError):
                    pass
        finally:
            self._done += len(data)
            self._check_disk()

    def _check_disk(self) -> None:
        if self.min_free_bytes <= 0:
            return
        t = time.monotonic()
        if t - self._t_disk < self.DISK_CHECK_S:
            return
        self._t_disk = t
        try:
            free = self._free_space(self.directory)
        except OSError:
            return
        if free < self.min_free_bytes and not self.paused:
            freed = self._enforce_cap(need=self.min_free_bytes - free)
            if free + freed >= self.min_free_bytes:
                self._note(f"recorder: low disk space ({free / 1e6:.0f} MB free, minimum "
                           f"{self.min_free_bytes / 1e6:.0f} MB): deleted the oldest "
                           f"recordings ({freed / 1e6:.1f} MB)")
            else:
                self.paused = True
                self._note(f"recorder: disk full ({(free + freed) / 1e6:.0f} MB free, minimum "
                           f"{self.min_free_bytes / 1e6:.0f} MB): recording paused, records "
                           "dropped (counted)")
        elif self.paused and free >= 1.25 * self.min_free_bytes:
            self.paused = False
            self._note(f"recorder: recording again ({free / 1e6:.0f} MB free); "
                       f"{self.dropped_records} records were not recorded")

    def _enforce_cap(self, need: int = 0) -> int:
        """Delete the oldest recordings beyond ``max_total_mb``, and ``need`` bytes more;
        return the bytes deleted."""
        try:
            files = sorted(self.directory.glob(f"*{SUFFIX}"),
                           key=lambda p: (p.stat().st_mtime, p.name))
            sizes = {p: p.stat().st_size for p in files}
        except OSError:
            return 0
        total = sum(sizes.values())
        current = self._want[0] if self._want is not None else None
        freed = 0
        for p in files:
            if total <= self.max_total_bytes and freed >= need:
                break
            if p == current:
                continue
            try:
                p.unlink()
            except OSError:
                continue
            total -= sizes[p]
            freed += sizes[p]
            self.deleted.append(p)
            if len(self.deleted) > FILES_LISTED:
                del self.deleted[:-FILES_LISTED]
            log.info("recorder: deleted %s (%s)", p.name,
                     "low disk space" if need else f"size cap {self.max_total_bytes / 1e6:.0f} MB")
        return freed


def _why(err: BaseException) -> str:
    return getattr(err, "strerror", None) or str(err) or type(err).__name__


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
    """The configuration the service ran with, from the recording's meta record; keys
    renamed since the recording was made are read under their new names
    (:func:`onboard.core.config_renames.migrate`)."""
    from onboard.core.config import from_dict
    from onboard.core.config_renames import migrate

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
    return from_dict(migrate(cfg), str(path))


def _utc_as_live(engine: Engine, meta: dict) -> None:
    """The records' ``utc`` as the live service stamped them: service time plus the meta's
    ``utc_offset_s`` (recordings made before it was recorded keep the engine's own)."""
    off = meta.get("utc_offset_s")
    if isinstance(off, (int, float)) and not isinstance(off, bool):
        engine.whereabouts.utc_of = lambda t, off=float(off): t + off


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
                _utc_as_live(engine, meta)
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
