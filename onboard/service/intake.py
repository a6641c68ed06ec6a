"""The intake: the one gate from raw bytes to the engine.

:class:`Intake` ``chunk()`` records a chunk (:class:`onboard.service.recorder.Recorder`),
parses it (:func:`drivers.protocols.parser_for`) and queues its samples in a bounded queue
(drops counted per source); ``tick(T)`` records the tick, puts the queued samples
stamped ``t <= T`` on the engine's time line (later ones wait for the next tick, so a
pipeline never sees a sample from its future; one stamped more than
``onboard.engine.timeline.TIME_JUMP_S`` before ``T`` is a counted and warned ``time_outlier``, as
in a replay of a log), pushes them and steps the engine. The live service splits ``chunk()`` in two:
``receive()`` keeps the chunk, ``parse()`` (called by ``tick()`` and by the service while
it waits for a sample) records and parses the chunks kept, in order. Parsing a handful
of chunks together costs about half the CPU time of parsing each as it arrives (the
parsers' code and data stay in the processor's caches), and gives the same samples: a
parser's output is a function of the bytes and their receive times only. Parsers with a ``poll(t)`` (NMEA: an epoch held
past its hold time) are polled at every tick, so that too is replayed exactly. When
MAVLink signing is verified (``verifier``), each MAVLink chunk is recorded after it was
parsed, in one write with a ``verdicts`` record listing the frames the verifier rejected
in it (only when it rejected any), in a format-version-2 file (:mod:`drivers.recording`).

The live service (:mod:`onboard.service.daemon`) and the replay of its recordings
(:func:`onboard.service.recorder.replay_recording`) both feed an :class:`Intake`, which is
what makes the replay exact.
"""

from __future__ import annotations

import logging
import math
from collections import Counter, deque
from itertools import islice
from dataclasses import dataclass, field
from typing import Callable, Protocol

from onboard.drivers.base import StreamParser
from onboard.drivers.mavlink_link import AutopilotLink
from onboard.drivers.mavlink_signing import SignatureVerifier, VerdictLog, VerdictPlayer
from onboard.drivers.protocols import parser_for
from onboard.drivers.recording import VERDICTS_KIND, RawRecord, encode_verdicts
from onboard.drivers.verdicts import Verdicts
from onboard.core.messages import EstimateRecord, Sample
from onboard.engine import Engine

log = logging.getLogger(__name__)

TICK_SOURCE = "engine"
"""The source name of the ``tick`` records the intake writes."""


class RecordWriter(Protocol):
    """Where the intake records what it consumed: the service's
    :class:`onboard.service.recorder.Recorder`, or any writer with the same ``write``."""

    def write(self, rec: RawRecord, *more: RawRecord) -> None:
        """Record ``rec`` (and ``more``, in the same write: a chunk and its verdicts are
        never split)."""
        ...


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
    link: AutopilotLink | None = None
    """MAVLink inputs: the autopilot on the link (its identity, boot clock, what it sent),
    shared with the service's MAVLink session."""


@dataclass
class Intake:
    """Raw chunks in, samples to the engine at ticks (see the module docstring).

    ``queue_size`` bounds the samples waiting for the next tick; beyond it new samples are
    dropped and counted in ``dropped[source]``.
    """

    engine: Engine
    queue_size: int = 4096
    recorder: RecordWriter | None = None
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

    backlog: deque[tuple[str, SourceState, bytes, float]] = field(default_factory=deque)
    """Chunks received (:meth:`receive`) and not parsed yet: (input, state, bytes, t_rx)."""
    max_backlog: int = 256
    """A :meth:`receive` that finds this many chunks waiting parses them at once (a
    bound on the memory they hold while the ticks are late)."""
    fresh_rx: float | None = None
    """After :meth:`parse` with ``after``: the receive time (s) of the first chunk that
    queued a sample stamped after it, or None (the service predicts the next tick's
    wake-up from it)."""

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
            link = self._link(name) if kind == "mavlink" else None
            st = self.sources[name] = SourceState(
                kind, parser_for(kind, name, verifier=v, link=link), verdicts=v, link=link)
        return st

    def _link(self, name: str) -> AutopilotLink:
        """The autopilot link of MAVLink input ``name``, set up from its ``[[service.sources]]``
        entry (the configuration a recording carries, so a replay filters and stamps the
        frames as the live service did)."""
        for i, src in enumerate(self.engine.cfg.service.sources):
            if (src.name or f"{src.kind}{i}") == name and src.kind == "mavlink":
                return AutopilotLink(target_system=src.target_system,
                                     target_component=src.target_component,
                                     stamp_boot_time=src.autopilot_time,
                                     filter_components=src.filter_components)
        return AutopilotLink()

    def chunk(self, name: str, kind: str, data: bytes, t_rx: float,
              verdicts: Verdicts | None = None) -> int:
        """Record, parse and queue one raw chunk received at ``t_rx`` (s) on input
        ``name``; return the number of samples queued. Never raises on bad bytes.

        ``verdicts``: in a replay, the chunk's recorded signature verdicts."""
        if self.backlog:
            self.parse()  # in the order received
        st = self._received(name, kind, data, t_rx)
        return self._parse(name, st, data, t_rx, verdicts)

    def receive(self, name: str, kind: str, data: bytes, t_rx: float) -> None:
        """Keep one raw chunk received at ``t_rx`` (s) on input ``name`` for :meth:`parse`,
        which records and parses it (the next :meth:`tick` at the latest). Never raises on
        bad bytes."""
        st = self._received(name, kind, data, t_rx)
        backlog = self.backlog
        backlog.append((name, st, data, t_rx))
        if len(backlog) >= self.max_backlog:
            self.parse()

    def parse(self, after: float = -math.inf) -> int:
        """Record, parse and queue the chunks kept by :meth:`receive`, in the order
        received; return the number of samples queued that are stamped after ``after``
        (s; all by default). With ``after`` given, :attr:`fresh_rx` is then the receive
        time of the first chunk that queued such a sample (None if none did)."""
        backlog = self.backlog
        parse = self._parse
        pending = self.pending
        rec = self.recorder
        # every chunk recorded before parsing, in one write, unless an input records after
        # its parse (signatures verified: each chunk with its verdicts)
        recorded = rec is not None and self.verifier is None
        if rec is not None and recorded and backlog:
            rec.write(*[RawRecord(t=t_rx, source=name, kind=st.kind, data=bytes(data))
                        for name, st, data, t_rx in backlog])
        queued = fresh = 0
        counting = after > -math.inf
        self.fresh_rx = None
        while backlog:
            name, st, data, t_rx = backlog.popleft()
            n0 = len(pending)
            q = parse(name, st, data, t_rx, None, recorded=recorded)
            if q and counting:
                f = sum(s.t > after for s in islice(pending, n0, None))
                if f and not fresh:
                    self.fresh_rx = t_rx
                fresh += f
            queued += q
        return fresh if counting else queued

    def _received(self, name: str, kind: str, data: bytes, t_rx: float) -> SourceState:
        """Count a chunk; return its input's state."""
        st = self.sources.get(name)
        if st is None or st.kind != kind:
            st = self.add_source(name, kind)
        st.chunks += 1
        st.bytes += len(data)
        st.t_last = t_rx
        return st

    def _parse(self, name: str, st: SourceState, data: bytes, t_rx: float,
               verdicts: Verdicts | None, recorded: bool = False) -> int:
        """Record (unless ``recorded`` already, or its input verifies signatures: it is
        then recorded with its verdicts once parsed) and parse one chunk of input ``name``
        (counted by :meth:`_received`); queue its samples; return the number queued."""
        vlog = st.verdicts if type(st.verdicts) is VerdictLog else None
        player = st.verdicts if type(st.verdicts) is VerdictPlayer else None
        rec = self.recorder
        if rec is not None and vlog is None and not recorded:
            # before parsing: nothing a parser does can lose it
            rec.write(RawRecord(t=t_rx, source=name, kind=st.kind, data=bytes(data)))
        if player is not None:
            player.load(verdicts)
        try:
            samples = st.parser.feed(data, t_rx)
        except Exception:  # noqa: BLE001 - a parser bug must not stop the service
            st.parser_errors += 1
            st.parser.stats.reject("parser_error")
            log.exception("parser for %s failed on a %d-byte chunk", name, len(data))
            samples = []
        if vlog is not None:  # signing verified: the chunk and its verdicts in one write
            v = vlog.take(data)
            if rec is not None:
                raw = RawRecord(t=t_rx, source=name, kind=st.kind, data=bytes(data))
                if v is None:
                    rec.write(raw)
                else:
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
        """Parse the chunks received, record a tick at ``t`` (s), push the queued samples
        with ``sample.t <= t`` and step the engine; return its estimates."""
        if self.backlog:
            self.parse()
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
        admit = self.engine.admit
        if pending:
            keep: deque[Sample] = deque()
            for s in pending:
                if s.t <= t:
                    for r in admit(s, t):  # the receive clock's time line
                        push(r, now=t)
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
