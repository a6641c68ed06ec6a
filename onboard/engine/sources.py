"""One source per quantity: the source selector between the intake and the pipelines.

A vehicle often has several sources of one quantity: the autopilot's GPS_RAW_INT and an
NMEA receiver, the AHRS yaw in ATTITUDE and VFR_HUD's whole-degree heading, two IMUs.
Fusing them as if they were one sensor is wrong (two receivers 3 m apart make the
position jump or average; a 1-degree heading beside a 0.01-degree one adds a sawtooth).
The selector lets exactly one source through per quantity:

* each quantity has a priority list of patterns (``[sources]`` in the configuration,
  :class:`onboard.core.config.SourcePriorities`); a source's rank is the index of the
  first pattern its name matches, unmatched sources rank after all listed ones (for the
  heading an ``Attitude`` source before a ``Heading`` source: an AHRS yaw before a bare
  compass; for the velocity a navigation solution's ``VelocityOverGround`` before a
  receiver's speed and course), then in the order they first appear, and a pattern
  starting with ``!``
  excludes the sources it matches from the quantity;
* the first usable sample of a quantity makes its source active, and within ``stale_s``
  of it a better-ranked source that appears takes over at once (the start-up choice);
  samples of sources not active are held back (counted in
  :attr:`SourceSelector.standby`);
* failover: a sample of another source arriving while the active source has delivered
  nothing usable for ``stale_s`` seconds makes the best-ranked fresh source active;
* failback: a better-ranked source that has delivered without a gap longer than
  ``stale_s`` for ``failback_s`` seconds becomes active again;
* every change is an event (``position: mavlink:1/GPS_RAW_INT -> gps2 (... silent 2.1 s)``).

``Attitude`` samples are selected as ``attitude`` (roll, pitch, rates) and compete for
``heading`` with the ``Heading`` samples: one that is the active attitude source but not
the active heading source passes with ``yaw_selected = False`` (its yaw is not to be used
as the heading); one that is the active heading source but not the attitude source
passes as a ``Heading`` sample. Likewise a ``GnssFix`` with speed and course over ground
is selected as ``position`` and competes for ``velocity`` with the
``VelocityOverGround`` samples: the position source's fix loses its ``sog_mps`` and
``cog_rad`` when another source is the velocity, and a fix whose source is the velocity
but not the position passes as a ``VelocityOverGround``.

The selector is a pure function of the samples and their times, in the order they are
pushed: live operation and the replay of its recording make the same choices.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from fnmatch import fnmatchcase

import msgspec

from onboard.core.config import SourcePriorities
from onboard.core.geo import wrap_2pi
from onboard.core.messages import (
    Altitude,
    Attitude,
    Depth,
    DvlVelocity,
    GnssFix,
    Heading,
    Imu,
    Sample,
    VelocityOverGround,
)

QUANTITY_OF: dict[type, str] = {
    GnssFix: "position",
    VelocityOverGround: "velocity",
    Heading: "heading",
    Attitude: "attitude",
    Imu: "imu",
    Depth: "depth",
    DvlVelocity: "dvl",
    Altitude: "altitude",
}
"""The quantity each selected sample class gives (``Pressure`` is selected as the
``Depth`` it becomes); other classes (actuators, parameters, ...) pass unselected."""

_PREFERRED = (Attitude, VelocityOverGround)
"""Sample classes ranked first among the unlisted sources of a quantity."""

QUANTITIES: tuple[str, ...] = ("position", "velocity", "heading", "attitude", "imu",
                               "depth", "dvl", "altitude")
"""The selected quantities, in the order of :class:`SourcePriorities`."""


def pattern_matches(pattern: str, source: str) -> bool:
    """True if ``source`` matches the glob ``pattern``; ``mavlink:NAME`` without a ``/``
    also matches ``NAME`` sent by any system (``mavlink:*/NAME``)."""
    if fnmatchcase(source, pattern):
        return True
    if pattern.startswith("mavlink:") and "/" not in pattern:
        return fnmatchcase(source, "mavlink:*/" + pattern[8:])
    return False


def usable(sample: Sample) -> bool:
    """Whether ``sample`` shows its source working (refreshes it): a GNSS fix with a fix,
    a DVL report the instrument marked valid; any other accepted sample (inlined in
    :meth:`SourceSelector._select` for the active source)."""
    cls = type(sample)
    if cls is GnssFix:
        return sample.fix_quality > 0  # type: ignore[attr-defined]
    if cls is DvlVelocity:
        return sample.valid  # type: ignore[attr-defined]
    return True


@dataclass
class _Quantity:
    """Selection state of one quantity."""

    name: str
    patterns: list[str]
    active: str | None = None
    last: dict[str, float] = field(default_factory=dict)
    """Source -> time (s) of its newest usable sample."""
    since: dict[str, float] = field(default_factory=dict)
    """Source -> start (s) of its current run of samples without a ``stale_s`` gap."""
    rank: dict[str, float] = field(default_factory=dict)
    """Source -> its rank (lower is better; ``inf`` excluded), cached."""
    order: int = 0
    t_start: float = math.inf
    """Time (s) of the quantity's first choice (its start-up window is ``stale_s``)."""

    def rank_of(self, source: str, preferred: bool = False) -> float:
        """The rank of ``source`` (see the module docstring), cached; ``preferred``: the
        source sends ``Attitude`` or ``VelocityOverGround`` (ranked first among the
        unlisted sources of the heading or the velocity)."""
        r = self.rank.get(source)
        if r is None:
            r = math.inf if any(p.startswith("!") and pattern_matches(p[1:], source)
                                for p in self.patterns) else None
            if r is None:
                listed = [p for p in self.patterns if not p.startswith("!")]
                r = next((float(i) for i, p in enumerate(listed) if pattern_matches(p, source)),
                         None)
                if r is None:
                    r = len(listed) + (0.0 if preferred else 0.5) + 1e-6 * self.order
                    self.order += 1
            self.rank[source] = r
        return r


class SourceSelector:
    """Admits the samples of the active source of each quantity (module docstring).

    Attributes:
        active: quantity -> the active source's name (a new dict object on every change,
            so it can be handed out as is).
        standby: held-back samples by ``(quantity, source)``.
        switches: number of source changes (failovers and failbacks).
        events: human-readable switch events, appended; the engine reports them.
    """

    def __init__(self, cfg: SourcePriorities, events: list[str] | None = None) -> None:
        self.stale_s = cfg.stale_s
        self.failback_s = cfg.failback_s
        self._q = {q: _Quantity(q, list(getattr(cfg, q))) for q in QUANTITIES}
        self.active: dict[str, str] = {}
        self.standby: Counter[tuple[str, str]] = Counter()
        self.switches = 0
        self.events: list[str] = [] if events is None else events

    def admit(self, sample: Sample) -> Sample | None:
        """The sample to queue for the pipelines: ``sample`` itself, a re-labelled
        ``Attitude``/``Heading`` (module docstring), or None when its source is not the
        active one of its quantity. Never raises."""
        cls = type(sample)
        q = QUANTITY_OF.get(cls)
        if q is None:
            return sample
        if cls is Attitude:
            return self._admit_attitude(sample)  # type: ignore[arg-type]
        if cls is GnssFix:
            return self._admit_fix(sample)  # type: ignore[arg-type]
        return sample if self._select(self._q[q], sample) else None

    def shift(self, dt_s: float) -> None:
        """The clock jumped by ``dt_s`` (s; :mod:`onboard.engine.timeline`): move every source's
        times with it, so that each keeps its age and the active sources stay active."""
        for q in self._q.values():
            q.last = {k: v + dt_s for k, v in q.last.items()}
            q.since = {k: v + dt_s for k, v in q.since.items()}
            q.t_start += dt_s

    def _admit_fix(self, s: GnssFix) -> Sample | None:
        pos = self._select(self._q["position"], s)
        if s.sog_mps is None or s.cog_rad is None:
            return s if pos else None
        vel = self._select(self._q["velocity"], s)
        if pos:
            return s if vel else msgspec.structs.replace(s, sog_mps=None, cog_rad=None)
        if vel:
            return VelocityOverGround(t=s.t, source=s.source,
                                      v_north_mps=s.sog_mps * math.cos(s.cog_rad),
                                      v_east_mps=s.sog_mps * math.sin(s.cog_rad))
        return None

    def _admit_attitude(self, s: Attitude) -> Sample | None:
        att = self._select(self._q["attitude"], s)
        hdg = self._select(self._q["heading"], s)
        if att:
            return s if hdg or not s.yaw_selected else msgspec.structs.replace(
                s, yaw_selected=False)
        if hdg:
            return Heading(t=s.t, source=s.source, heading_rad=wrap_2pi(s.yaw_rad))
        return None

    def _select(self, q: _Quantity, s: Sample) -> bool:
        """Update quantity ``q`` with sample ``s``; True if ``s``'s source is active."""
        src, t = s.source, s.t
        if src == q.active:  # the common case, in short (an active source is never excluded)
            cls = type(s)
            if (cls is not GnssFix or s.fix_quality > 0) and (  # type: ignore[attr-defined]
                    cls is not DvlVelocity or s.valid):  # type: ignore[attr-defined]
                last = q.last.get(src)
                if last is None or t - last > self.stale_s:
                    q.since[src] = t
                q.last[src] = t
            return True
        rank = q.rank_of(src, type(s) in _PREFERRED)
        if rank == math.inf:
            self.standby[(q.name, src)] += 1
            return False
        if usable(s):
            last = q.last.get(src)
            if last is None or t - last > self.stale_s:
                q.since[src] = t
            q.last[src] = t
        active = q.active
        if active == src:
            return True
        if active is None:
            if src in q.last:  # the first usable sample of the quantity
                self._switch(q, src, t, "first source")
                return True
            return False
        if src in q.last:
            t_act = q.last.get(active, -math.inf)
            if t - q.t_start <= self.stale_s and rank < q.rank_of(active):
                self._switch(q, src, t, f"better than {active}", startup=True)
                return True
            if t - t_act > self.stale_s:
                best = self._best_fresh(q, t)
                if best == src:
                    self._switch(q, src, t, f"{active} silent {t - t_act:.1f} s")
                    return True
            elif (rank < q.rank_of(active) and t - q.since[src] >= self.failback_s
                  and t - q.last[src] <= self.stale_s):
                self._switch(q, src, t, f"better source fresh for {t - q.since[src]:.1f} s")
                return True
        self.standby[(q.name, src)] += 1
        return False

    def _best_fresh(self, q: _Quantity, t: float) -> str | None:
        """The best-ranked source of ``q`` with a usable sample within ``stale_s`` of ``t``."""
        fresh = [(q.rank_of(s), s) for s, tl in q.last.items() if t - tl <= self.stale_s]
        return min(fresh)[1] if fresh else None

    def _switch(self, q: _Quantity, src: str, t: float, why: str,
                startup: bool = False) -> None:
        old = q.active
        q.active = src
        self.active = {**self.active, q.name: src}
        if old is None or startup:
            if old is None:
                q.t_start = t
            self.events.append(f"{q.name}: using {src} ({why})")
        else:
            self.switches += 1
            self.events.append(f"{q.name}: {old} -> {src} at t={t:.2f} ({why})")
