"""The innovations of every pipeline, summarized per channel for health and summaries.

Each pipeline hands the engine the :class:`~onboard.core.messages.Innovation` records of
its measurement updates (:meth:`onboard.pipelines.base.Pipeline.innovations`); an
:class:`InnovationMonitor` keeps, per pipeline and channel, the counts, the mean NIS since
the start and over the recent updates, and the newest innovation with its test ratio;
a channel fed by several sources (two GNSS receivers) is also summarized per source.
:meth:`InnovationMonitor.snapshot` gives them as :class:`ChannelHealth` records (the
health record's ``innovations``, summary.json's ``innovations``).
"""

from __future__ import annotations

import math
from typing import Iterable

from onboard.core.messages import ChannelHealth, Innovation

RECENT_STEPS = 20
"""Updates over which ``nis_recent`` averages (a running mean of weight 1/20)."""


class RecentMean:
    """The running mean of the recent values: weight ``1/n`` for the first
    :data:`RECENT_STEPS`, then ``1/RECENT_STEPS`` (about the last 20).

    Attributes:
        n: values seen; value: the mean (0 before any).
    """

    __slots__ = ("n", "value")

    def __init__(self) -> None:
        self.n = 0
        self.value = 0.0

    def add(self, x: float) -> float:
        """One value; returns the mean."""
        self.n += 1
        self.value += max(1.0 / RECENT_STEPS, 1.0 / self.n) * (x - self.value)
        return self.value


def _finite(x: float) -> float | None:
    """``x``, or None when it is not finite (JSON has no NaN)."""
    return x if math.isfinite(x) else None


class ChannelStats:
    """The running summary of one channel's innovations, and per source when
    ``per_source``.

    Attributes:
        sources: source -> the summary of its innovations alone, from the second source
            on (until then the channel's own summary is its one source's); None when not
            ``per_source``.
    """

    __slots__ = ("n", "rejected", "reasons", "dof", "_nis_sum", "_recent",
                 "last", "_ratio_max", "sources")

    def __init__(self, dof: int, per_source: bool = True) -> None:
        self.sources: dict[str, ChannelStats] | None = {} if per_source else None
        self.n = 0
        self.rejected = 0
        self.reasons: dict[str, int] = {}
        self.dof = dof
        self._nis_sum = 0.0
        self._recent = RecentMean()
        self.last: Innovation | None = None
        self._ratio_max = 0.0

    def add(self, rec: Innovation) -> None:
        """One measurement update."""
        sources = self.sources
        if sources is not None and (sources or (self.last is not None
                                                and rec.source != self.last.source)):
            self._add_by_source(sources, rec)
        self.n += 1
        self.dof = rec.dof
        self.last = rec
        ratio = rec.nis / rec.gate   # rec.test_ratio, without the property's call
        if ratio > self._ratio_max:
            self._ratio_max = ratio
        if not rec.accepted:
            self.rejected += 1
            self.reasons[rec.reason] = self.reasons.get(rec.reason, 0) + 1
            return
        if not math.isfinite(rec.nis):
            return
        self._nis_sum += rec.nis
        self._recent.add(rec.nis)

    def _add_by_source(self, sources: dict[str, ChannelStats], rec: Innovation) -> None:
        """``rec`` into its source's summary; at the second source, the summary so far
        becomes the first source's."""
        if not sources and self.last is not None:
            sources[self.last.source] = self._clone()
        sub = sources.get(rec.source)
        if sub is None:
            sub = sources[rec.source] = ChannelStats(rec.dof, per_source=False)
        sub.add(rec)

    def _clone(self) -> ChannelStats:
        """A copy of this summary without its per-source summaries."""
        c = ChannelStats(self.dof, per_source=False)
        c.n, c.rejected, c.reasons = self.n, self.rejected, dict(self.reasons)
        c._nis_sum, c.last, c._ratio_max = self._nis_sum, self.last, self._ratio_max
        c._recent.n, c._recent.value = self._recent.n, self._recent.value
        return c

    def snapshot(self, reset_max: bool = True) -> ChannelHealth:
        """The summary now; the largest test ratio starts afresh unless ``reset_max`` is
        False."""
        last = self.last
        ratio_max = self._ratio_max
        if reset_max:
            self._ratio_max = 0.0
        return ChannelHealth(
            n=self.n, rejected=self.rejected, reasons=dict(self.reasons), dof=self.dof,
            nis_mean=_finite(self._nis_sum / self._recent.n) if self._recent.n else None,
            nis_recent=_finite(self._recent.value) if self._recent.n else None,
            nis=_finite(last.nis) if last is not None else None,
            test_ratio=_finite(last.test_ratio) if last is not None else None,
            test_ratio_max=_finite(ratio_max) if last is not None else None,
            z=[_finite(x) for x in last.z] if last is not None else [],
            S=[_finite(x) for x in last.S] if last is not None else [],
            t=last.t if last is not None else None,
            source=last.source if last is not None else "",
            by_source=self._by_source(reset_max))

    def _by_source(self, reset_max: bool) -> dict[str, ChannelHealth]:
        """Each source's summary, when there has been more than one (else empty)."""
        if not self.sources:
            return {}
        return {src: sub.snapshot(reset_max) for src, sub in self.sources.items()}


class InnovationMonitor:
    """Per pipeline and channel, the :class:`ChannelStats` of its innovations."""

    def __init__(self) -> None:
        self.channels: dict[str, dict[str, ChannelStats]] = {}
        self._kept: dict[str, list[Innovation]] = {}

    def keep(self, pipeline: str) -> list[Innovation]:
        """From now on, also keep every record of ``pipeline`` as it arrives, in the list
        returned (reports and tests that need each update, not the summary)."""
        return self._kept.setdefault(pipeline, [])

    def add(self, pipeline: str, records: Iterable[Innovation]) -> None:
        """The records of one pipeline's updates, in order."""
        kept = self._kept.get(pipeline)
        if kept is not None:
            records = list(records)
            kept.extend(records)
        per = self.channels.get(pipeline)
        for rec in records:
            if per is None:
                per = self.channels[pipeline] = {}
            stats = per.get(rec.channel)
            if stats is None:
                stats = per[rec.channel] = ChannelStats(rec.dof)
            stats.add(rec)

    def snapshot(self, reset_max: bool = True) -> dict[str, dict[str, ChannelHealth]]:
        """``pipeline -> channel -> ChannelHealth``, channels in first-seen order."""
        return {p: {c: s.snapshot(reset_max) for c, s in per.items()}
                for p, per in self.channels.items()}
