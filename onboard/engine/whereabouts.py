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
  independent of any model); else, on a vehicle that dives (``dead_reckon``), the last
  fix dead reckoned with the navigation solution's velocity over ground (a DVL-aided INS,
  ``VelocityOverGround``) since: an AUV under water after its surface fix; else the
  position of the first pipeline whose record of this tick has ``north`` and ``east`` (a
  filtered position, e.g. a boat's through a GNSS outage), turned into latitude and
  longitude with that pipeline's local frame; null when there is none of them.
* ``position_std_m`` is that position's one-sigma per horizontal axis (m): the fix's
  reported ``h_acc_m``; dead reckoned, the fix's (:data:`FIX_STD_M` when the receiver
  gave none) grown with the distance travelled and the time since
  (:meth:`DeadReckoning.std_m`); a pipeline's, its own ``std_north``/``std_east``, the
  larger; null when unknown.
"""

from __future__ import annotations

import math
from typing import Callable, Iterable, Mapping, NamedTuple

from onboard.core.geo import LocalFrame
from onboard.core.messages import GnssFix, VelocityOverGround

FIX_MAX_AGE_S = 2.0
"""A GNSS fix at most this old (s) at the tick is the vehicle's position; an older one
gives way to a dead-reckoned or a pipeline's position."""
FIX_STD_M = 2.5
"""One-sigma (m per axis) of a fix whose receiver reports no ``h_acc_m``: a consumer
receiver's horizontal accuracy."""
DR_DISTANCE_FRACTION = 0.01
"""Dead reckoning's one-sigma growth per metre travelled (per axis): 1 % of the distance
since the fix, the drift of DVL dead reckoning with a magnetic-compass heading (0.2-2 %
of the distance in the AUV literature; an INS-grade heading does better)."""
DR_VELOCITY_BIAS_MPS = 0.005
"""Dead reckoning's one-sigma growth per second (m/s per axis): a velocity bias the
distance term misses while the vehicle barely moves (a DVL-aided INS's bias)."""
DR_MAX_GAP_S = 5.0
"""A velocity over ground this long (s) after the previous one breaks the dead
reckoning (the navigation solution was lost): no dead-reckoned position until the next
fix."""

UtcClock = Callable[[float], "float | None"]
"""Engine time (s) -> UTC (POSIX s), or None when unknown."""

Frame = tuple[LocalFrame, tuple[float, float]]
"""A pipeline's local frame and the published (north, east) of its origin (m)."""


class Place(NamedTuple):
    """Where the vehicle is at a tick: latitude, longitude (deg) and the one-sigma per
    horizontal axis (m); each None when unknown."""

    lat_deg: float | None
    lon_deg: float | None
    std_m: float | None


NOWHERE = Place(None, None, None)


class DeadReckoning:
    """A GNSS fix carried forward with the velocity over ground (north, east; m/s) of
    the navigation solution: ``north``, ``east`` (m) travelled since the fix, each
    velocity held from its sample to the next (at most :data:`DR_MAX_GAP_S`).

    Its one-sigma per axis (m) grows from the fix's ``std0_m`` with the distance
    travelled ``d`` and the time since the fix ``dt``::

        std = sqrt(std0^2 + (DR_DISTANCE_FRACTION d)^2 + (DR_VELOCITY_BIAS_MPS dt)^2)
    """

    def __init__(self, fix: GnssFix) -> None:
        self.fix, self.frame = fix, LocalFrame(fix.lat_deg, fix.lon_deg)
        self.std0_m = fix.h_acc_m if fix.h_acc_m is not None and fix.h_acc_m > 0 else FIX_STD_M
        self.north = self.east = self.distance = 0.0
        self.t = fix.t                 # the time (s) the sums reach
        self.velocity: tuple[float, float] | None = None
        self.broken = False

    def advance(self, v: VelocityOverGround) -> None:
        """Carry the sums to ``v.t`` with the velocity held since the last sample, then
        hold ``v``'s; a gap over :data:`DR_MAX_GAP_S` breaks the reckoning."""
        dt = v.t - self.t
        if dt <= 0.0:
            return
        if self.velocity is not None and dt <= DR_MAX_GAP_S:
            vn, ve = self.velocity
            self.north += vn * dt
            self.east += ve * dt
            self.distance += math.hypot(vn, ve) * dt
        elif self.velocity is not None:
            self.broken = True
        self.t = v.t
        if math.isfinite(v.v_north_mps) and math.isfinite(v.v_east_mps):
            self.velocity = (v.v_north_mps, v.v_east_mps)

    def std_m(self, t: float) -> float:
        """The one-sigma per axis (m) of the reckoned position at ``t`` (s)."""
        return math.sqrt(self.std0_m ** 2 + (DR_DISTANCE_FRACTION * self.distance) ** 2
                         + (DR_VELOCITY_BIAS_MPS * (t - self.fix.t)) ** 2)

    def place(self, t: float) -> Place:
        """The reckoned position at tick ``t`` (s); :data:`NOWHERE` when broken or when
        the newest velocity is older than :data:`DR_MAX_GAP_S`."""
        if self.broken or self.velocity is None or t - self.t > DR_MAX_GAP_S:
            return NOWHERE
        lat, lon = self.frame.to_latlon(self.north, self.east)
        return Place(lat, lon, self.std_m(t))


class Whereabouts:
    """The UTC and position of the engine's ticks (see the module docstring).

    Attributes:
        utc_of: the engine clock's UTC mapping (None: no UTC known).
        fix: the newest GNSS fix with a position handed to the pipelines.
        dead_reckon: whether the last fix is carried forward with the velocity over
            ground (a vehicle that dives).
        reckoning: the dead reckoning from the last fix (None: none yet, or off).
    """

    def __init__(self, utc_of: UtcClock | None = None, dead_reckon: bool = False) -> None:
        self.utc_of = utc_of
        self.fix: GnssFix | None = None
        self.dead_reckon = dead_reckon
        self.reckoning: DeadReckoning | None = None

    def observe(self, fix: GnssFix) -> None:
        """A GNSS fix handed to the pipelines; one without a position is ignored."""
        if fix.fix_quality > 0:
            self.fix = fix
            if self.dead_reckon:
                self.reckoning = DeadReckoning(fix)

    def observe_velocity(self, v: VelocityOverGround) -> None:
        """A velocity over ground handed to the pipelines: the dead reckoning's."""
        if self.reckoning is not None:
            self.reckoning.advance(v)

    def utc(self, t: float) -> float | None:
        """The UTC (POSIX s) of engine time ``t`` (s), None when unknown."""
        if self.utc_of is None:
            return None
        utc = self.utc_of(t)
        return utc if utc is not None and math.isfinite(utc) else None

    def place(self, t: float,
              estimates: Iterable[tuple[Mapping[str, float], Frame | None]]) -> Place:
        """Where the vehicle is at tick ``t`` (s): the fresh fix, else the dead reckoning,
        else the first of ``estimates`` (a pipeline's values and its frame) with a
        position; :data:`NOWHERE` without any (see the module docstring)."""
        fix = self.fix
        if fix is not None and t - fix.t <= FIX_MAX_AGE_S:
            return Place(fix.lat_deg, fix.lon_deg, fix.h_acc_m)
        if self.reckoning is not None:
            reckoned = self.reckoning.place(t)
            if reckoned.lat_deg is not None:
                return reckoned
        for values, frame in estimates:
            n, e = values.get("north"), values.get("east")
            if n is not None and e is not None and frame is not None:
                origin, (n0, e0) = frame
                lat, lon = origin.to_latlon(n - n0, e - e0)
                stds = [values[k] for k in ("std_north", "std_east") if k in values]
                return Place(lat, lon, max(stds) if stds else None)
        return NOWHERE

    def position(self, t: float,
                 estimates: Iterable[tuple[Mapping[str, float], Frame | None]]
                 ) -> tuple[float | None, float | None]:
        """``(lat_deg, lon_deg)`` of :meth:`place`."""
        p = self.place(t, estimates)
        return p.lat_deg, p.lon_deg
