"""The time line of a run: single bad stamps are outliers, real clock jumps start segments.

A log's stamps are trusted only when they agree with each other. Every sample passes
:meth:`Timeline.admit` before the engine's other time checks; ``jump_s`` below is the time
line's jump span (:data:`TIME_JUMP_S` unless ``[engine] time_jump_s`` says otherwise):

* the log starts where its first stamps agree, not on its first one
  (:class:`onboard.core.stamps.Anchor`): the first samples are held until
  :data:`~onboard.core.stamps.ANCHOR_STAMPS` distinct stamps (or the end, :meth:`flush`),
  the largest group of them that chain within ``jump_s`` is released as the
  first segment and the others are outliers;
* after that, a sample within ``jump_s`` of the newest released time (either side) continues
  the current segment and is released at once (the engine's ``backwards`` and ``late``
  checks still apply to it);
* a sample further away is *held*, with the samples that agree with it (within
  ``jump_s`` of the newest held one), until one side is confirmed by
  :data:`CONFIRM_STAMPS` distinct stamps:

  - the held side first: a real **jump** (a reboot, a clock step, a gap in the log). A
    new :class:`Segment` starts at the first held sample, the held samples are released
    in their order, and :attr:`Timeline.jump` says so (:class:`Jump`);
  - the current side first: the held samples are **outliers** (a corrupted or mistyped
    stamp), dropped and listed in :attr:`Timeline.outliers` for the engine to count
    (``<type>:time_outlier``); the samples after them are kept.

  A sample that agrees with neither side makes the held ones outliers and is held itself
  (a run of unrelated bad stamps is all rejected). Samples still held at the end of the
  run (:meth:`Timeline.flush`) are outliers: fewer than :data:`CONFIRM_STAMPS` stamps
  never make a segment.

The rule needs no look-ahead; it delays a jump's first samples by :data:`CONFIRM_STAMPS`
stamps (a fraction of a second at the usual rates) and never walks across the time between
two stamps, however far apart.

Live (:meth:`Timeline.admit_at`), the receive clock is the time line: it is monotonic and
every sample is stamped on it or mapped onto it, so nothing on it can confirm a jump. A
stamp more than ``jump_s`` from the receive time of its tick, either way, is an
outlier at once (a source's clock that stepped: an autopilot that rebooted before its
time was mapped again, a GNSS receiver's UTC before its first fix), counted and warned of
like a log's.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Sequence

from onboard.core.messages import Sample
from onboard.core.stamps import UTC_MAX_S, UTC_MIN_S, Anchor

TIME_JUMP_S = 10.0
"""A stamp this far (s) from the newest released one, either way, is held until the
samples after it say whether it is an outlier or a jump (the engine's default ``gap_s``;
the default of ``[engine] time_jump_s``, a :class:`Timeline`'s ``jump_s``)."""
CONFIRM_STAMPS = 2
"""Distinct stamps that confirm a side: the held samples' side (a jump) or the current
segment's (the held samples are outliers). Two: a corrupted stamp is one stamp (all the
samples of one CSV row or one record share it), and a real jump may be short (ArduSub's
small.BIN ends with two parameter records 109 s after the rest)."""


@dataclass
class Segment:
    """A stretch of the log on one continuous clock: first and newest stamp (s)."""

    start: float
    end: float

    @property
    def duration_s(self) -> float:
        """``end - start`` (s)."""
        return self.end - self.start


@dataclass(frozen=True)
class Jump:
    """A confirmed clock jump: the newest stamp before it and the first after (s)."""

    t_before: float
    t_after: float

    @property
    def step_s(self) -> float:
        """``t_after - t_before`` (s): negative when the clock went back (a reboot)."""
        return self.t_after - self.t_before

    def words(self) -> str:
        """What jumped, for a warning: ``the log's clock went back 10.4 s, from
        2023-05-04 17:15:49.4 UTC to 2023-05-04 17:15:39.0 UTC (a reboot or a clock
        reset)``, or ``no sample for 109.0 s, from t = 291.9 s to t = 400.9 s (a gap in the
        log or a clock step)``."""
        step = self.step_s
        span = f"from {stamp_words(self.t_before)} to {stamp_words(self.t_after)}"
        if step < 0:
            return (f"the log's clock went back {duration_words(-step)}, {span} "
                    "(a reboot or a clock reset)")
        return f"no sample for {duration_words(step)}, {span} (a gap in the log or a clock step)"


def log_time(segments: Sequence[tuple[float, float]], t: float) -> float:
    """Seconds into the log of the stamp ``t`` (s): the durations of the segments
    (``(start, end)`` stamps, in order) before the one ``t`` belongs to, plus ``t`` less
    its start; never negative. ``t`` belongs to the newest segment that spans it, else
    the newest that started before it, as a tick belongs to its run (the ``run`` column
    of estimates.csv)."""
    if not segments:
        return 0.0
    k = next((i for i in range(len(segments) - 1, -1, -1)
              if segments[i][0] <= t <= segments[i][1]), None)
    if k is None:
        k = next((i for i in range(len(segments) - 1, -1, -1) if segments[i][0] <= t), 0)
    return sum(b - a for a, b in segments[:k]) + max(t - segments[k][0], 0.0)


def outlier_words(n: int, t: float, ref: float | None) -> str:
    """``n`` samples dropped as outliers, the last stamped ``t`` while the log's clock was
    at ``ref`` (s), for a warning."""
    where = ""
    if ref is not None:
        side = "after" if t > ref else "before"
        where = (f" (the last stamped {stamp_words(t)}, {duration_words(abs(t - ref))} "
                 f"{side} the log's clock at {stamp_words(ref)})")
    return f"samples stamped far from their neighbours were dropped, {n:,} so far{where}"


EPOCH_STAMPS_S = (UTC_MIN_S, UTC_MAX_S)
"""Stamps in this range (s) are read as POSIX time (2000-01-01 to 2100-01-01 UTC) when a
warning names them; others are seconds on the log's own clock (since a boot, say)."""
_UNITS_S = ((365.25 * 86400.0, "years"), (86400.0, "days"), (3600.0, "h"), (60.0, "min"))


def stamp_words(t: float) -> str:
    """A stamp (s) as a user reads it: ``2023-05-04 17:16:35.1 UTC`` for POSIX time
    (:data:`EPOCH_STAMPS_S`), else ``t = 1,444.3 s`` on the log's clock."""
    if EPOCH_STAMPS_S[0] <= t <= EPOCH_STAMPS_S[1]:
        whole = math.floor(t)
        day = time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(whole))
        return f"{day}.{int(10 * (t - whole))} UTC"
    return f"t = {t:,.1f} s" if math.isfinite(t) else f"t = {t}"


def duration_words(seconds: float) -> str:
    """A positive duration (s) in words: ``10.4 s``, ``837,399 s (9.7 days)``."""
    text = f"{seconds:,.1f} s" if seconds < 1000.0 else f"{seconds:,.0f} s"
    for unit_s, name in _UNITS_S:
        if seconds >= 2.0 * unit_s:
            return f"{text} ({seconds / unit_s:,.1f} {name})"
    return text


class Timeline:
    """Sorts stamps into segments and outliers (see the module docstring).

    Attributes:
        segments: the segments so far, in the order they started.
        outliers: samples found to be outliers since the consumer last cleared the list.
        jump: the jump confirmed by the last :meth:`admit`, None if it confirmed none.
    """

    def __init__(self, jump_s: float = TIME_JUMP_S) -> None:
        """An empty time line whose jumps are stamps more than ``jump_s`` (s) apart
        (:data:`TIME_JUMP_S`; ``[engine] time_jump_s``)."""
        self.jump_s = jump_s
        self.segments: list[Segment] = []
        self.outliers: list[Sample] = []
        self.jump: Jump | None = None
        self._anchor: Anchor[Sample] = Anchor(jump_s)
        self._held: list[Sample] = []
        self._held_stamps: set[float] = set()
        self._held_newest = 0.0
        self._current_stamps: set[float] = set()
        """Distinct stamps of the current segment since the first held sample."""

    @property
    def newest(self) -> float | None:
        """The newest released stamp of the current segment (s), None before the first."""
        return self.segments[-1].end if self.segments else None

    @property
    def duration_s(self) -> float:
        """The sum of the segments' durations (s): the gaps between them are not counted."""
        return sum(s.duration_s for s in self.segments)

    def admit(self, sample: Sample) -> list[Sample]:
        """Take one sample; return the samples released by it, in order (none while it
        is held; the held ones with it when it confirms a jump or the start). Sets
        :attr:`jump`."""
        self.jump = None
        t = sample.t
        if not self._anchor.decided:
            return self._start(*self._anchor.push(t, sample))
        seg = self.segments[-1]
        if self._held and abs(t - self._held_newest) <= self.jump_s:
            return self._hold(sample)
        if abs(t - seg.end) <= self.jump_s:
            if t > seg.end:
                seg.end = t
            elif t < seg.start:
                seg.start = t
            if self._held:
                self._current_stamps.add(t)
                if len(self._current_stamps) >= CONFIRM_STAMPS:
                    self._drop_held()
            return [sample]
        self._drop_held()
        return self._hold(sample)

    def admit_at(self, sample: Sample, now: float) -> list[Sample]:
        """Live: take one sample at the receive time ``now`` (s); return it, or nothing
        when it is an outlier (more than ``jump_s`` from ``now``; listed in
        :attr:`outliers`). One segment, on the receive clock."""
        t = sample.t
        if abs(t - now) > self.jump_s:
            self.outliers.append(sample)
            return []
        if not self.segments:
            self.segments.append(Segment(t, t))
        else:
            seg = self.segments[-1]
            if t > seg.end:
                seg.end = t
            elif t < seg.start:
                seg.start = t
        return [sample]

    def flush(self) -> list[Sample]:
        """The run ended: return the samples released by it (a log shorter than
        :data:`~onboard.core.stamps.ANCHOR_STAMPS` distinct stamps: its start is chosen
        now); samples still held are outliers."""
        self.jump = None
        if not self._anchor.decided:
            return self._start(*self._anchor.decide())
        self._drop_held()
        return []

    def _start(self, kept: list[tuple[float, Sample]],
               outliers: list[tuple[float, Sample]]) -> list[Sample]:
        """The first segment, once the anchor chose it: the stamps of ``kept`` agree
        with each other, so they are released in their order, and ``outliers`` listed."""
        self.outliers.extend(s for _, s in outliers)
        if not kept:
            return []
        stamps = [t for t, _ in kept]
        self.segments.append(Segment(min(stamps), max(stamps)))
        return [s for _, s in kept]

    def _hold(self, sample: Sample) -> list[Sample]:
        """Hold ``sample`` with the others of its side; release them all as a new segment
        once they have :data:`CONFIRM_STAMPS` distinct stamps."""
        held = self._held
        held.append(sample)
        self._held_stamps.add(sample.t)
        if len(held) == 1 or sample.t > self._held_newest:
            self._held_newest = sample.t
        if len(self._held_stamps) < CONFIRM_STAMPS:
            return []
        first = min(self._held_stamps)
        self.jump = Jump(self.segments[-1].end, first)
        self.segments.append(Segment(first, max(self._held_stamps)))
        self._held = []
        self._held_stamps = set()
        self._current_stamps = set()
        return held

    def _drop_held(self) -> None:
        """The held samples are outliers."""
        self.outliers.extend(self._held)
        self._held = []
        self._held_stamps = set()
        self._current_stamps = set()
