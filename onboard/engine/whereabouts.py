"""Where and when a tick is: the UTC and the vehicle's position every record carries.

Every :class:`~onboard.core.messages.EstimateRecord` (schema 2) says when its tick was in
UTC and where the vehicle was, so that a shore service can put the estimates of many
vehicles on one map and one time line (``onboard fleet``, docs/fleet.md):

* ``utc`` (POSIX s) is the engine's tick time ``t`` on the UTC clock given by
  :attr:`Whereabouts.utc_of`: in a replay the log's own clock mapped to UTC
  (:func:`onboard.drivers.logclock.log_clock`: a tlog's receive times, a DataFlash log's
  GPS week and time of week, an NMEA capture's RMC date and time; a service recording's
  meta ``utc_offset_s``, so that its replay stamps as live did), live the vehicle
  computer's system clock at the service's start plus its monotonic time since
  (``onboard.service.daemon.ServiceClock.utc``; on a vehicle the system clock is usually
  disciplined by GNSS through chrony or gpsd); null when neither is known (a log stamped
  in time since boot with no GPS time).
* ``lat_deg``/``lon_deg`` are the vehicle's best position at the tick: the newest GNSS fix
  handed to the pipelines when it is at most :data:`FIX_MAX_AGE_S` old (a measurement,
  independent of any model), else the position of the first pipeline whose record of this
  tick has ``north`` and ``east`` (a dead-reckoned or filtered position, e.g. an AUV under
  water), turned into latitude and longitude with that pipeline's local frame; null when
  there is neither.
"""

from __future__ import annotations

import math
from typing import Callable, Iterable, Mapping

from onboard.core.geo import LocalFrame
from onboard.core.messages import GnssFix

FIX_MAX_AGE_S = 2.0
"""A GNSS fix at most this old (s) at the tick is the vehicle's position; an older one
gives way to a pipeline's position."""

UtcClock = Callable[[float], "float | None"]
"""Engine time (s) -> UTC (POSIX s), or None when unknown."""

Frame = tuple[LocalFrame, tuple[float, float]]
"""A pipeline's local frame and the published (north, east) of its origin (m)."""


class Whereabouts:
    """The UTC and position of the engine's ticks (see the module docstring).

    Attributes:
        utc_of: the engine clock's UTC mapping (None: no UTC known).
        fix: the newest GNSS fix with a position handed to the pipelines.
    """

    def __init__(self, utc_of: UtcClock | None = None) -> None:
        self.utc_of = utc_of
        self.fix: GnssFix | None = None

    def observe(self, fix: GnssFix) -> None:
        """A GNSS fix handed to the pipelines; one without a position is ignored."""
        if fix.fix_quality > 0:
            self.fix = fix

    def utc(self, t: float) -> float | None:
        """The UTC (POSIX s) of engine time ``t`` (s), None when unknown."""
        if self.utc_of is None:
            return None
        utc = self.utc_of(t)
        return utc if utc is not None and math.isfinite(utc) else None

    def position(self, t: float,
                 estimates: Iterable[tuple[Mapping[str, float], Frame | None]]
                 ) -> tuple[float | None, float | None]:
        """``(lat_deg, lon_deg)`` of the vehicle at tick ``t`` (s): the fresh fix, else the
        first of ``estimates`` (a pipeline's values and its frame) with a position; (None,
        None) without either."""
        fix = self.fix
        if fix is not None and t - fix.t <= FIX_MAX_AGE_S:
            return fix.lat_deg, fix.lon_deg
        for values, frame in estimates:
            n, e = values.get("north"), values.get("east")
            if n is not None and e is not None and frame is not None:
                origin, (n0, e0) = frame
                return origin.to_latlon(n - n0, e - e0)
        return None, None
