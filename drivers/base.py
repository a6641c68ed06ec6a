"""What every driver shares: rejection counting and the reader/parser shapes.

Two shapes of driver:

* a **stream parser** turns bytes as they arrive (serial, UDP, TCP, or a log's raw
  records) into typed samples: ``parser.feed(data, t_rx) -> list[Sample]``;
* a **log reader** iterates a file and yields typed samples in time order.

Neither raises on bad input: a corrupt record is skipped and counted in
:class:`ReadStats` under a short reason (``"crc"``, ``"checksum"``, ``"json"``,
``"nan"``, ``"truncated"``, ...). Only an unreadable file (missing, not this format at all)
raises :class:`UnreadableLog`.
"""

from __future__ import annotations

import math
import mmap
import os
from collections import Counter
from dataclasses import dataclass, field
from typing import Iterable, Iterator, Protocol, Union

from onboard.core.messages import Sample

TIME_JUMP_S = 10.0
"""Stamps this far apart (s), either way, are for the time line to judge
(``onboard.engine.timeline.TIME_JUMP_S``, the same figure: a test checks it). The CSV and
DataFlash readers apply the time line's rule to their rows themselves (a single bad stamp,
or a first stamp outside the group of first stamps that agree, is their
``"time_outlier"``). The tlog, NMEA, DVL, PD6 and DDBoat readers drop a sample a little
older than the newest they emitted (``"time_backwards"``) but pass one this much older on
to the engine's time line (:class:`TimeOrder`), so that a clock reset (a reboot) becomes
a new segment and a single bad stamp a counted ``time_outlier``, instead of every later
sample being dropped until the clock catches up."""


TIME_REASONS = ("time_backwards", "time_outlier", "timestamp")
"""The rejections of a reader's time rules: records dropped for their stamp alone."""
UNREAD_REASONS = frozenset({
    "crc", "checksum", "no_checksum", "garbage", "truncated", "too_long", "incompat",
    "json", "bad_json", "malformed", "unrecognized", "unknown_format", "bad_fmt",
    "decode", "length", "bad_time", "format"})
"""The rejections of a record that could not be read whole (framing, checksum, syntax), as
opposed to one read whole that said nothing usable (``"no_fix"``, ``"nan"``,
``"duplicate"`` ...): the line readers count the bytes of the first kind as not used."""
USED_SHARE_MIN = 0.5
"""A log of which the reader used less than this share is reported in one loud line
(:func:`shortfall`, the ``log_mostly_unread`` warning): the share of the file's bytes in
records read whole, times the share of those records its time rules kept. Half: where
"mostly" begins, and far from both sides measured. The real logs of ``../shared/data``
use 98.3 % (``nmea_log.txt``, its logger's own lines) to 100 %; a tlog with a tenth of
its bytes randomised 4-7 %; a README with four NMEA sentences in its prose 12.6 %. A
smaller loss is in the counts (``read.rejected``, ``read.used_bytes``), not warned of."""


def ddmm_degrees(ddmm: float) -> float | None:
    """Decimal degrees of a position written as degrees and decimal minutes,
    ``DDDMM.MMMM`` (NMEA 0183, a Slocum's ``m_gps_lat``), its sign kept; None where it
    is not a number or its minutes are 60 or more."""
    if not math.isfinite(ddmm):
        return None
    a = abs(ddmm)
    deg = math.floor(a / 100.0)
    minutes = a - 100.0 * deg
    if minutes >= 60.0:
        return None
    return math.copysign(deg + minutes / 60.0, ddmm)


class UnreadableLog(Exception):
    """The file cannot be read at all, or is not in a format this reader understands."""


LogBytes = Union[bytes, mmap.mmap]
"""A log's bytes: in memory, or the file mapped (:class:`MappedLog`)."""

RELEASE_BYTES = 8 << 20
"""A mapped log (:class:`MappedLog`) hands the pages behind its reader back to the page
cache every this many bytes read: the reader's resident memory stays near this, whatever
the log's length."""


class MappedLog:
    """A log file mapped read-only, as a bytes-like ``data`` (indexing, slicing,
    ``find``, ``struct.unpack_from``, ``re`` over it all read the file), released behind
    the reader as it goes.

    The binary readers (:mod:`drivers.tlog`, :mod:`drivers.dataflash`) walk a log by
    offset, look ahead to the next record and back to the last good one, and resynchronize
    anywhere after damage; mapped, they do all that over the whole file as over bytes in
    memory, with the same results, while only the pages they touch are resident.
    Touched file pages count in the process's resident memory until unmapped, so
    :meth:`release` (called with the reader's position, cheap when nothing is due) tells
    the kernel, every ``release_bytes``, that the pages before the position are not
    needed (``madvise(MADV_DONTNEED)``: they stay in the page cache, and a look back
    reads them again). Where ``madvise`` is missing (not Linux or BSD) the mapping is
    kept whole, resident as it is read. Raises :class:`UnreadableLog` when the file
    cannot be opened or mapped.
    """

    def __init__(self, path: str | os.PathLike, release_bytes: int = RELEASE_BYTES) -> None:
        self.path = path
        try:
            with open(path, "rb") as f:
                size = os.fstat(f.fileno()).st_size
                self.data: LogBytes = (
                    mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) if size else b"")
        except (OSError, ValueError) as e:
            raise UnreadableLog(f"{path}: {getattr(e, 'strerror', None) or e}") from e
        self._step = max(mmap.PAGESIZE, release_bytes // mmap.PAGESIZE * mmap.PAGESIZE)
        self._can_release = isinstance(self.data, mmap.mmap) and hasattr(mmap, "MADV_DONTNEED")
        self._released = 0
        self.next_release = self._step if self._can_release else 1 << 62
        """Position from which :meth:`release` has something to do."""

    @classmethod
    def of_bytes(cls, data: bytes, path: str | os.PathLike = "") -> "MappedLog":
        """Records already in memory (an MCAP's tlog records), read the same way; nothing
        to release."""
        log = cls.__new__(cls)
        log.path, log.data = path, data
        log._step, log._can_release, log._released = 0, False, 0
        log.next_release = 1 << 62
        return log

    def release(self, pos: int) -> None:
        """Hand back the whole pages before ``pos`` when ``pos`` has passed
        :attr:`next_release`."""
        if pos < self.next_release:
            return
        upto = pos // mmap.PAGESIZE * mmap.PAGESIZE
        self.data.madvise(mmap.MADV_DONTNEED, self._released,  # type: ignore[union-attr]
                          upto - self._released)
        self._released = upto
        self.next_release = upto + self._step

    def close(self) -> None:
        """Unmap the file (the samples read keep no reference to it)."""
        if isinstance(self.data, mmap.mmap):
            self.data.close()


BY_TYPE_KEYS = 1024
"""Record types (count) that :attr:`ReadStats.by_type` counts each under its own name;
further names are counted together under :data:`OTHER_TYPES`. The names come from the
bytes (an unknown MAVLink id, an NMEA sentence's address, a gpsd class, a DVL report's
type), so a noisy or hostile stream can bring a new one with every record, and a service
reads its inputs for days; a log or a link has a few dozen (a whole MAVLink dialect is
about 300)."""
OTHER_TYPES = "other_types"
"""The :attr:`ReadStats.by_type` key of the records of types beyond :data:`BY_TYPE_KEYS`."""


class TypeCounts(Counter):
    """A :class:`~collections.Counter` of at most :data:`BY_TYPE_KEYS` names (and
    :data:`OTHER_TYPES`): a count of a name it has no room for goes to :data:`OTHER_TYPES`."""

    def __setitem__(self, key: str, value: int) -> None:
        if len(self) >= BY_TYPE_KEYS and key not in self and key != OTHER_TYPES:
            # ``c[key] += n`` sets a new key to its count from zero
            key, value = OTHER_TYPES, self[OTHER_TYPES] + value
        super().__setitem__(key, value)


@dataclass
class ReadStats:
    """Counters a reader or parser keeps: what it saw, what it produced, what it rejected."""

    records: int = 0
    """Records (frames, lines, rows) seen."""
    samples: int = 0
    """Typed samples produced."""
    rejected: Counter[str] = field(default_factory=Counter)
    """Rejected records by reason."""
    by_type: Counter[str] = field(default_factory=TypeCounts)
    """Records by message type (MAVLink name, NMEA sentence, ...), for summaries; at most
    :data:`BY_TYPE_KEYS` names, the rest under :data:`OTHER_TYPES`."""
    skipped: Counter[str] = field(default_factory=Counter)
    """Records left out by design, not for a fault, by reason (an MCAP's channels that
    are not the MAVLink read: :mod:`drivers.mcap_log`)."""
    size_bytes: int = 0
    """Bytes of the file(s) read (a text log's characters); 0 when not known (a stream,
    an MCAP's compressed chunks)."""
    used_bytes: int = 0
    """Of :attr:`size_bytes`, those in records read whole (framing, checksum, syntax
    good), whatever they said: the rest is damage the reader skipped."""
    time_source: str = ""
    """Where the stamps come from, when a setting decides it (the CSV reader's
    ``[csv] time = "..." with time_scale = ...``), for a warning that they disagree."""
    unread: int = 0
    """Rejections for a reason of :data:`UNREAD_REASONS` so far (the line readers compare
    it before and after a line)."""

    def reject(self, reason: str) -> None:
        """Count one rejection for ``reason``."""
        self.rejected[reason] += 1
        if reason in UNREAD_REASONS:
            self.unread += 1

    def as_dict(self) -> dict:
        """The counts as a JSON-serializable dict (``records``, ``samples``, ``rejected`` and
        ``by_type``, keys sorted; ``skipped`` too when any; ``size_bytes`` and
        ``used_bytes`` when the size is known)."""
        out = {
            "records": self.records,
            "samples": self.samples,
            "rejected": dict(sorted(self.rejected.items())),
            "by_type": dict(sorted(self.by_type.items())),
        }
        if self.skipped:
            out["skipped"] = dict(sorted(self.skipped.items()))
        if self.size_bytes:
            out["size_bytes"] = self.size_bytes
            out["used_bytes"] = self.used_bytes
        return out


def counted_lines(stats: ReadStats, lines: Iterable[bytes], ends: int = 0) -> Iterator[bytes]:
    """Yield ``lines`` (with their line ends, or ``ends`` bytes short each), counting their
    bytes in ``stats.size_bytes`` and, unless the caller counted a rejection of
    :data:`UNREAD_REASONS` while it handled the line, in ``stats.used_bytes``."""
    for line in lines:
        unread = stats.unread
        yield line
        k = len(line) + ends
        stats.size_bytes += k
        if stats.unread == unread:
            stats.used_bytes += k


class TimeOrder:
    """The time rule of the readers that pass a clock reset on to the engine's time line
    (DVL JSON, PD6, the NMEA and DDBoat captures; the tlog reader and the NMEA parser
    apply it inline): a stamp up to :data:`TIME_JUMP_S`
    older than the newest one kept is dropped (``"time_backwards"``), one further back
    is kept and becomes the newest, so that the time line sees a reset (a new segment) or
    a single bad stamp (an outlier) instead of the reader dropping every later sample
    until its clock catches up; whatever the first stamp, nothing after it is lost."""

    def __init__(self, stats: ReadStats) -> None:
        self.stats = stats
        self.newest: float | None = None
        """The newest stamp kept (s)."""

    def behind(self, t: float) -> bool:
        """Whether a stamp ``t`` (s) is one to drop: up to :data:`TIME_JUMP_S` older than
        the newest kept."""
        newest = self.newest
        return newest is not None and newest - TIME_JUMP_S <= t < newest

    def keep(self, t: float) -> bool:
        """Whether a sample stamped ``t`` (s) is kept (then ``t`` is the newest); a dropped
        one is counted."""
        if self.behind(t):
            self.stats.reject("time_backwards")
            return False
        self.newest = t
        return True


def used_share(stats: ReadStats, time_outliers: int = 0) -> float:
    """The share of a log its reader used (0-1): of the file's bytes, those in records
    read whole (1 when the size is not known), times the share of the records the time
    rules kept: the reader's (:data:`TIME_REASONS` among its ``records``) or the engine's
    time line (``time_outliers`` among the reader's ``samples``), whichever dropped more."""
    whole = stats.used_bytes / stats.size_bytes if stats.size_bytes else 1.0
    by_reader = sum(stats.rejected[r] for r in TIME_REASONS) / max(stats.records, 1)
    by_engine = time_outliers / max(stats.samples, 1)
    return max(0.0, whole * (1.0 - max(by_reader, by_engine)))


def shortfall(stats: ReadStats, name: str, time_outliers: int = 0) -> str | None:
    """One line when the reader of log ``name`` used less than :data:`USED_SHARE_MIN` of
    it (:func:`used_share`), else None: how much, what to do (for the larger loss: a
    damaged file, or stamps that disagree, with the setting they come from,
    :attr:`ReadStats.time_source`), then why the rest was not used (the bytes in records read
    whole, the records and samples the time rules dropped, the largest rejections)."""
    share = used_share(stats, time_outliers)
    if share >= USED_SHARE_MIN:
        return None
    whole = stats.used_bytes / stats.size_bytes if stats.size_bytes else 1.0
    timed = sum(stats.rejected[r] for r in TIME_REASONS)
    why = []
    if whole < 1.0:
        why.append(f"{_size(stats.used_bytes)} of its {_size(stats.size_bytes)} were "
                   "records read whole")
    if timed:
        why.append(f"the time rules dropped {timed:,} of its {stats.records:,} records")
    if time_outliers:
        why.append(f"the time line dropped {time_outliers:,} of its {stats.samples:,} "
                   "samples as outliers")
    kept_by_time = share / whole if whole > 0.0 else 1.0
    if whole <= kept_by_time:
        fix = "the file is damaged, or mostly not log records: use an undamaged log"
    else:
        fix = ("its time stamps disagree with each other: check "
               + (stats.time_source or "the clock of the logger that wrote it"))
    top = sorted(stats.rejected.items(), key=lambda kv: -kv[1])[:_REASONS_SHOWN]
    counts = ", ".join(f"{k} {n:,}" for k, n in top)
    return (f"only {100 * share:.1f} % of {name} could be used: {fix}; " + "; ".join(why)
            + (f" (rejected: {counts})" if counts else ""))


_REASONS_SHOWN = 4
"""Rejection reasons :func:`shortfall` names, the largest first."""


def _size(n: int) -> str:
    """``n`` bytes in words: ``812 B``, ``19.6 kB``, ``1.51 MB``."""
    if n < 1000:
        return f"{n} B"
    if n < 1_000_000:
        return f"{n / 1e3:.3g} kB"
    return f"{n / 1e6:.3g} MB"


class LineAssembler:
    """Cuts a byte stream into lines for the text protocols (NMEA, PD6, DVL JSON).

    Lines end at LF (and at CR too with ``split_cr``); a partial line waits for the next
    chunk; a line longer than ``max_line`` bytes is dropped and counted once in ``stats``
    as ``"too_long"`` (with the rest of it, up to the next line end), so garbage without
    line ends cannot grow the buffer. Blank lines are skipped with ``skip_blank``.
    """

    def __init__(self, stats: "ReadStats", max_line: int, *, split_cr: bool = True,
                 skip_blank: bool = True) -> None:
        self.stats = stats
        self.max_line = max_line
        self.split_cr = split_cr
        self.skip_blank = skip_blank
        self._buf = bytearray()
        self._discarding = False

    def push(self, data: bytes) -> list[bytes]:
        """The complete lines in the stream so far, without their line ends."""
        out: list[bytes] = []
        buf = self._buf
        buf.extend(data)
        while True:
            nl = buf.find(b"\n")
            if self.split_cr:
                cr = buf.find(b"\r")
                nl = cr if nl < 0 else (nl if cr < 0 else min(nl, cr))
            if nl < 0:
                if len(buf) > self.max_line:
                    if not self._discarding:
                        self.stats.records += 1
                        self.stats.reject("too_long")
                    self._discarding = True
                    buf.clear()
                return out
            line = bytes(buf[:nl])
            del buf[: nl + 1]
            if self._discarding:
                self._discarding = False
                continue
            if self.skip_blank and not line.strip():
                continue
            if len(line) > self.max_line:
                self.stats.records += 1
                self.stats.reject("too_long")
                continue
            out.append(line)


class StreamParser(Protocol):
    """Incremental bytes-to-samples parser for one protocol."""

    stats: ReadStats

    def feed(self, data: bytes, t_rx: float) -> list[Sample]:
        """Consume ``data`` received at ``t_rx`` (s); return the complete samples in it.
        Partial records are kept for the next call."""
        ...


class LogReader(Protocol):
    """A recorded log: iterate for samples in time order; ``stats`` fills as you go."""

    stats: ReadStats

    def __iter__(self) -> Iterator[Sample]: ...
