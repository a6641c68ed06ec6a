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

from onboard.messages import Sample


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

    def reject(self, reason: str) -> None:
        self.rejected[reason] += 1

    def as_dict(self) -> dict:
        return {
            "records": self.records,
            "samples": self.samples,
            "rejected": dict(sorted(self.rejected.items())),
            "by_type": dict(sorted(self.by_type.items())),
        }


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
