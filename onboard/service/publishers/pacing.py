"""Pacing of a publisher's periodic messages on the tick loop.

A publisher fed at every tick sends a periodic message at the first tick at or after its
due time. The next due time is kept on the grid of the first one (:func:`next_due`):
computed from the tick that sent, a tick a few milliseconds early would wait a whole tick,
and a 5 Hz output fed by 10 Hz ticks would average about 4 Hz.
"""

from __future__ import annotations

__all__ = ["next_due"]


def next_due(due: float, now: float, period: float) -> float:
    """When a message sent at ``now`` (s), due at ``due``, is due next: one ``period`` (s)
    after ``due``, on its grid, so that ticks that come a little before or after the due
    time (a tick loop's jitter) do not lengthen the period; one ``period`` after ``now``
    when that is not in the future (the first send, or after a gap of a period or more,
    which is not made up with a burst)."""
    nxt = due + period
    return nxt if nxt > now else now + period
