"""Where a log's time line starts: the consensus of its first stamps, not its first one.

In a log the stamps are the only clock, and the first stamp is no more trustworthy than
any other: a damaged first record (a flipped byte of its time) or a mistyped first row
would otherwise anchor the time line far from every later stamp, and whatever judges the
later stamps against it (a reader's time order, the engine's time line) would drop them
all, or start the log with a segment of one sample and a clock jump.

:class:`Anchor` holds the first items of a log until it has seen :data:`ANCHOR_STAMPS`
distinct stamps (or the log ends), then keeps the largest *group* of them: stamps that
chain within a tolerance of each other (sorted, no step between neighbours larger than
the tolerance; the readers' and the time line's ``TIME_JUMP_S``). The items whose stamps
are outside that group are outliers. A tie goes to the group whose first item comes
first in the log, so a log of two disagreeing stamps keeps its first, as before any
anchoring. The CSV and DataFlash readers (``drivers.csvlog``, ``drivers.dataflash``) and
the engine's time line (``onboard.engine.timeline``) start with it.
"""

from __future__ import annotations

from typing import Generic, TypeVar

T = TypeVar("T")

UTC_MIN_S = 946_684_800.0
"""Earliest stamp taken as a date (POSIX s, 2000-01-01T00:00:00Z): earlier ones are
seconds on a log's own clock (since a boot, a simulator's start) or a clock never set."""
UTC_MAX_S = 4_102_444_800.0
"""Stamps from this one on are no date (POSIX s, 2100-01-01T00:00:00Z)."""
ANCHOR_STAMPS = 5
"""Distinct stamps the start of a time line is chosen from: up to two bad ones among the
first five, far ahead or far back, agreeing with each other or not, are outliers. A log
whose clock truly jumps within its first five stamps loses the stamps before the jump
(counted as outliers) instead of starting with a short segment."""


class Anchor(Generic[T]):
    """Holds ``(stamp, item)`` pairs until the start of the time line is chosen (see the
    module docstring); afterwards it passes every pair straight through.

    Attributes:
        decided: the start has been chosen (:meth:`push` passes pairs through).
    """

    def __init__(self, tolerance_s: float, stamps: int = ANCHOR_STAMPS) -> None:
        """``tolerance_s``: the largest step (s) between neighbouring stamps of a group;
        ``stamps``: how many distinct stamps to wait for."""
        self.tolerance_s = tolerance_s
        self.stamps = stamps
        self.decided = False
        self._items: list[tuple[float, T]] = []
        self._distinct: set[float] = set()

    def push(self, t: float, item: T) -> tuple[list[tuple[float, T]], list[tuple[float, T]]]:
        """Take ``item`` stamped ``t`` (s); return ``(kept, outliers)``, each a list of
        ``(t, item)`` in the order they were pushed: both empty while the start is still
        open, everything held so far once the ``stamps``-th distinct stamp decides it,
        and ``([(t, item)], [])`` after that."""
        if self.decided:
            return [(t, item)], []
        self._items.append((t, item))
        self._distinct.add(t)
        if len(self._distinct) < self.stamps:
            return [], []
        return self.decide()

    def decide(self) -> tuple[list[tuple[float, T]], list[tuple[float, T]]]:
        """Choose the start from what is held now (the log ended before ``stamps``
        distinct stamps); ``(kept, outliers)`` as :meth:`push` returns them."""
        items, self._items = self._items, []
        self._distinct = set()
        self.decided = True
        if not items:
            return [], []
        lo, hi = largest_group([t for t, _ in items], self.tolerance_s)
        kept = [p for p in items if lo <= p[0] <= hi]
        outliers = [p for p in items if not lo <= p[0] <= hi]
        return kept, outliers


def largest_group(stamps: list[float], tolerance_s: float) -> tuple[float, float]:
    """``(first, last)`` stamp (s) of the largest group of ``stamps`` (in log order) that
    chain within ``tolerance_s``, counted in distinct stamps; a tie goes to the group
    that appears first in ``stamps``."""
    groups: list[list[float]] = []   # [lo, hi, distinct stamps]
    for t in sorted(set(stamps)):
        if groups and t - groups[-1][1] <= tolerance_s:
            groups[-1][1] = t
            groups[-1][2] += 1
        else:
            groups.append([t, t, 1])

    def first_seen(g: list[float]) -> int:
        return next(i for i, t in enumerate(stamps) if g[0] <= t <= g[1])

    best = max(groups, key=lambda g: (g[2], -first_seen(g)))
    return best[0], best[1]
