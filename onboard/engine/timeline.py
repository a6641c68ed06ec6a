"""The time line of a run: single bad stamps are outliers, real clock jumps start segments.

A log's stamps are trusted only when they agree with each other. Every sample passes
:meth:`Timeline.admit` before the engine's other time checks:

* a sample within :data:`TIME_JUMP_S` of the newest released time (either side) continues
  the current segment and is released at once (the engine's ``backwards`` and ``late``
  checks still apply to it);
* a sample further away is *held*, with the samples that agree with it (within
  :data:`TIME_JUMP_S` of the newest held one), until one side is confirmed by
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
stamp more than :data:`TIME_JUMP_S` from the receive time of its tick, either way, is an
outlier at once (a source's clock that stepped: an autopilot that rebooted before its
time was mapped again, a GNSS receiver's UTC before its first fix), counted and warned of
like a log's.
"""

from __future__ import annotations

from dataclasses import dataclass

from onboard.core.messages import Sample

TIME_JUMP_S = 10.0
"""A stamp this far (s) from the newest released one, either way, is held until the
samples after it say whether it is an outlier or a jump (the engine's default ``gap_s``)."""
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


class Timeline:
    """Sorts stamps into segments and outliers (see the module docstring).

    Attributes:
        segments: the segments so far, in the order they started.
        outliers: samples found to be outliers since the consumer last cleared the list.
        jump: the jump confirmed by the last :meth:`admit`, None if it confirmed none.
    """

    def __init__(self) -> None:
        """An empty time line."""
        self.segments: list[Segment] = []
        self.outliers: list[Sample] = []
        self.jump: Jump | None = None
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
        is held; the held ones with it when it confirms a jump). Sets :attr:`jump`."""
        self.jump = None
        t = sample.t
        if not self.segments:
            self.segments.append(Segment(t, t))
            return [sample]
        seg = self.segments[-1]
        if self._held and abs(t - self._held_newest) <= TIME_JUMP_S:
            return self._hold(sample)
        if abs(t - seg.end) <= TIME_JUMP_S:
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
        when it is an outlier (more than :data:`TIME_JUMP_S` from ``now``; listed in
        :attr:`outliers`). One segment, on the receive clock."""
        t = sample.t
        if abs(t - now) > TIME_JUMP_S:
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

    def flush(self) -> None:
        """The run ended: samples still held are outliers."""
        self._drop_held()

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
