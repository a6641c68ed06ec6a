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

from collections import Counter
from dataclasses import dataclass, field
from typing import Iterator, Protocol

from onboard.core.messages import Sample

TIME_JUMP_S = 10.0
"""Stamps this far apart (s), either way, are for the time line to judge
(``onboard.engine.timeline.TIME_JUMP_S``, the same figure: a test checks it). The CSV and
DataFlash readers apply the time line's rule to their rows themselves (a single bad stamp
is their ``"time_outlier"``). The tlog, NMEA and DVL readers drop a sample a little older
than the newest they emitted (``"time_backwards"``) but pass one this much older on to
the engine's time line, so that a clock reset (a reboot) becomes a new segment and a
single bad stamp a counted ``time_outlier``, instead of every later sample being dropped
until the clock catches up."""


class UnreadableLog(Exception):
    """The file cannot be read at all, or is not in a format this reader understands."""


@dataclass
class ReadStats:
    """Counters a reader or parser keeps: what it saw, what it produced, what it rejected."""

    records: int = 0
    """Records (frames, lines, rows) seen."""
    samples: int = 0
    """Typed samples produced."""
    rejected: Counter[str] = field(default_factory=Counter)
    """Rejected records by reason."""
    by_type: Counter[str] = field(default_factory=Counter)
    """Records by message type (MAVLink name, NMEA sentence, ...), for summaries."""
    skipped: Counter[str] = field(default_factory=Counter)
    """Records left out by design, not for a fault, by reason (an MCAP's channels that
    are not the MAVLink read: :mod:`drivers.mcap_log`)."""

    def reject(self, reason: str) -> None:
        """Count one rejection for ``reason``."""
        self.rejected[reason] += 1

    def as_dict(self) -> dict:
        """The counts as a JSON-serializable dict (``records``, ``samples``, ``rejected`` and
        ``by_type``, keys sorted; ``skipped`` too when any)."""
        out = {
            "records": self.records,
            "samples": self.samples,
            "rejected": dict(sorted(self.rejected.items())),
            "by_type": dict(sorted(self.by_type.items())),
        }
        if self.skipped:
            out["skipped"] = dict(sorted(self.skipped.items()))
        return out


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
