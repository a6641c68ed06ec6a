"""Course and speed over ground from the track of fixes that carry none.

A receiver that reports no course over ground (the DDBoat's ``GPS [...]`` lines, an NMEA
GGA without RMC/VTG) still gives a course: the direction of the chord between two of its
fixes. Two fixes of one-sigma ``s0`` and ``s1`` (m) a distance ``d`` apart give the chord's
direction with a one-sigma of ``hypot(s0, s1) / d`` (rad, for ``d`` much larger than the
noise), so the chord is taken only from the newest fix back to the latest earlier fix far
enough for :data:`COURSE_MAX_STD_RAD`, and no further back than
:data:`COURSE_BASELINE_MAX_S` (a longer chord cuts a turn). The heading it is compared with
is the circular mean of the headings over the chord's span: on an arc flown at a steady
rate and speed the chord's direction is the heading at its middle, which is that mean.

The vehicle moves when the chord's length over its duration, the mean speed over ground,
exceeds the heading check's speed floor (``onboard.monitor.integrity``). The course is
the heading's only on a straight track (the headings over the chord within
:data:`COURSE_STRAIGHT_RAD`), in one run (no gap in the fixes longer than
:data:`COURSE_GAP_S`) and going ahead (no command astern in the last :data:`ASTERN_S`).
"""

from __future__ import annotations

import math
from collections import deque

COURSE_MAX_STD_RAD = math.radians(10.0)
"""Largest one-sigma (rad) of a course derived from two fixes: the chord must be at least
``hypot(s0, s1) / COURSE_MAX_STD_RAD`` long (16 m for two fixes of 2 m), so that the fixes'
noise does not dominate it (the heading check's bound is 25 deg)."""
COURSE_BASELINE_MAX_S = 30.0
"""Longest time (s) between the two fixes of a derived course."""
COURSE_GAP_S = 3.0
"""A gap between fixes longer than this (s) starts the track anew: a new run, or fixes
lost, across which the chord is no course."""
ASTERN_S = 60.0
"""For this long (s) after a command astern the vehicle may be moving backwards (the
BlueBoat coasts astern for about 20 s after its reverse steps at 2.3 m/s), its heading
opposite its track: no course is derived."""
COURSE_STRAIGHT_RAD = math.radians(10.0)
"""Largest circular standard deviation (rad) of the headings over the chord: the track is
straight. A vehicle that spins or zig-zags between the chord's fixes (a system
identification run's turns, coasting) has no one course to compare its heading with."""


class TrackCourse:
    """Course over ground from consecutive fixes (module docstring).

    Attributes:
        active: whether a fix without a course has come: the headings are kept from then
            on (a log whose fixes carry their course keeps none).
    """

    def __init__(self) -> None:
        self.active = False
        self._fixes: deque[tuple[float, float, float, float]] = deque()  # t, n, e, var m^2
        self._headings: deque[tuple[float, float]] = deque()  # t, heading rad
        self._astern_t = -math.inf

    def astern(self, t: float) -> None:
        """A command astern at ``t`` (s): the thrusters push backwards."""
        self._astern_t = t

    def heading(self, t: float, heading_rad: float) -> None:
        """A heading (rad, true) at ``t`` (s), kept while :attr:`active`."""
        if self.active:
            self._headings.append((t, heading_rad))

    def fix(self, t: float, north: float, east: float, var_m2: float
            ) -> tuple[float, float, float] | None:
        """A fix without a course at ``t`` (s), north/east (m) in a local frame, of
        variance ``var_m2`` (m^2) per axis. Returns the speed over ground (m/s), the
        course (rad) and the mean heading (rad) over the chord from the latest earlier
        fix far enough away, or None when there is none or no heading over its span."""
        self.active = True
        fixes, headings = self._fixes, self._headings
        if fixes and t - fixes[-1][0] > COURSE_GAP_S:
            fixes.clear()
        while fixes and fixes[0][0] < t - COURSE_BASELINE_MAX_S:
            fixes.popleft()
        while headings and headings[0][0] < t - COURSE_BASELINE_MAX_S:
            headings.popleft()
        chord = None
        for t0, n0, e0, v0 in reversed(fixes):
            d = math.hypot(north - n0, east - e0)
            if d * COURSE_MAX_STD_RAD >= math.sqrt(v0 + var_m2) and t > t0:
                chord = (t0, d / (t - t0), math.atan2(east - e0, north - n0))
                break
        fixes.append((t, north, east, var_m2))
        if chord is None or t - self._astern_t < ASTERN_S:
            return None
        t0, sog, cog = chord
        span = [h for th, h in headings if t0 <= th <= t]
        if not span:
            return None
        s, c = sum(map(math.sin, span)), sum(map(math.cos, span))
        r = min(math.hypot(s, c) / len(span), 1.0)
        if r <= 0.0 or -2.0 * math.log(r) > COURSE_STRAIGHT_RAD ** 2:
            return None
        return sog, cog, math.atan2(s, c)
