"""Magnetic headings made true: the declination from the World Magnetic Model.

A compass measures the heading from magnetic north; every pipeline works from true north.
The difference, the declination ``D`` (east positive), is ``true = magnetic + D``: 12
degrees at Kodiak Island, Alaska, where an uncorrected compass on a boat at 1.5 m/s puts
``1.5 sin(12 deg)`` = 0.31 m/s of false cross-track current into the current pipeline.
This module applies it once, in the engine's input path (``Engine.push``), so that no
pipeline sees a magnetic heading.

Which declination (``[corrections] declination_deg``):

* a number (degrees, east positive): that value for every magnetic heading (``config``);
* ``"auto"`` (the default), per heading:

  - the heading's own declination when the sensor gives one (NMEA HDG's variation,
    ``Heading.declination_rad``; ``sensor``);
  - else the World Magnetic Model (:func:`wmm_declination`, the package ``pygeomag``)
    at the first GNSS fix's position, on the date of that fix when its time stamp is a
    UTC time (a log's clock: NMEA UTC, a tlog's receive time), else on today's date, at
    midnight UTC (the live service's monotonic clock, a DataFlash boot time) (``wmm``);
  - before the first fix: the heading is rejected (``no_declination``), for at most
    :data:`WAIT_FOR_FIX_S` after the first magnetic heading; after that it is used as it
    is (``none``) and the engine warns (``no_declination``): a vehicle without GNSS needs
    ``declination_deg``.

A heading marked true (NMEA HDT, a dual-antenna GNSS heading, an autopilot's yaw, which
ArduPilot's EKF already corrects) passes unchanged. Which sources are magnetic: NMEA HDM
and HDG, the text capture's compass yaw, a CSV ``heading`` with ``heading_reference =
"magnetic"`` (drivers/).

The value in use is reported as :class:`~onboard.core.messages.DeclinationReport`
(:attr:`DeclinationCorrector.report`): in the health record and in ``summary.json``.
"""

from __future__ import annotations

import calendar
import math
import time
from typing import Callable, Literal

import msgspec

from onboard.core.geo import wrap_2pi
from onboard.core.messages import DeclinationReport, GnssFix, Heading
from onboard.core.stamps import UTC_MAX_S, UTC_MIN_S

WAIT_FOR_FIX_S = 30.0
"""Longest a magnetic heading waits (s after the first one) for a fix that gives the
model its position; meanwhile magnetic headings are rejected (``no_declination``)."""
DAY_S = 86400.0
MODEL_YEARS = (2010, 2029)
"""The years the package's models cover (WMM-2010 to WMM-2025); a date outside is
extrapolated from the nearest."""
BLACKOUT_NT = 2000.0
"""Below this horizontal field (nT) the WMM's declination is unreliable (its blackout
zone near the magnetic poles): the corrector warns."""

Outcome = Literal["corrected", "true", "wait", "uncorrected"]
"""What :meth:`DeclinationCorrector.heading` did: made a magnetic heading true, passed a
true one, asks the caller to reject it (waiting for a fix), or passed it magnetic."""


def decimal_year(t_utc: float) -> float:
    """The decimal year (e.g. 2026.5) of a POSIX time ``t_utc`` (s)."""
    year = time.gmtime(t_utc).tm_year
    start = calendar.timegm((year, 1, 1, 0, 0, 0))
    end = calendar.timegm((year + 1, 1, 1, 0, 0, 0))
    return year + (t_utc - start) / (end - start)


def wmm_declination(lat_deg: float, lon_deg: float, year: float,
                    alt_km: float = 0.0) -> tuple[float, str, float]:
    """The World Magnetic Model's declination (deg, east positive) at geodetic
    ``lat_deg``, ``lon_deg`` (deg), ``alt_km`` above the ellipsoid, on the decimal
    ``year``; returns ``(declination_deg, model, horizontal_field_nT)``.

    The model whose five-year life span holds ``year`` (WMM-2010 to WMM-2025); outside
    them the nearest one, extrapolated (the model name then says so). Checked against
    the published WMM-2025 test values (tests/test_declination.py)."""
    from pygeomag import GeoMag  # pure Python, a core dependency

    gm = GeoMag(base_year=min(max(int(year), MODEL_YEARS[0]), MODEL_YEARS[1]))
    lo, hi = gm.life_span
    inside = lo <= year <= hi
    r = gm.calculate(lat_deg, lon_deg, alt_km, year, allow_date_outside_lifespan=not inside)
    return float(r.d), gm.model + ("" if inside else " (extrapolated)"), float(r.h)


class DeclinationCorrector:
    """Magnetic headings to true (module docstring); one per engine.

    Attributes:
        setting: ``declination_deg`` as configured: degrees, or ``"auto"``.
        report: the declination in use and where it came from.
        waiting: magnetic headings rejected while waiting for a fix.
        uncorrected: magnetic headings passed as they are (no declination known).
    """

    def __init__(self, setting: float | str = "auto",
                 today: Callable[[], float] = time.time) -> None:
        """``setting``: ``[corrections] declination_deg``; ``today``: the wall clock
        (POSIX s) whose date is used when the fixes' time stamps are not UTC."""
        self.setting = setting
        self._today = today
        self._first_magnetic_t: float | None = None
        self.waiting = 0
        self.uncorrected = 0
        self._wmm_rad: float | None = None
        self._wmm_date = ""
        """The date (YYYY-MM-DD) the WMM's declination was computed for."""
        if isinstance(setting, (int, float)):
            self.report = DeclinationReport(deg=float(setting), source="config")
            self._config_rad: float | None = math.radians(setting)
        else:
            self.report = DeclinationReport()
            self._config_rad = None

    @property
    def needs_fix(self) -> bool:
        """Whether the next GNSS fix should be shown to :meth:`observe_fix`."""
        return self._config_rad is None and self._wmm_rad is None

    def observe_fix(self, fix: GnssFix) -> tuple[str, str] | None:
        """The first fix (in ``auto``): the WMM's declination at its position and date.
        Returns the ``declination_unreliable`` warning (its line and details) when that
        value is unreliable: near a magnetic pole, or extrapolated to a date outside the
        models' years (a receiver's unset clock gives such dates); else None."""
        if not self.needs_fix:
            return None
        utc = UTC_MIN_S <= fix.t < UTC_MAX_S
        # today's date at midnight UTC: two replays of a log without UTC on one day agree
        # to the bit, not only to the model's accuracy
        t_date = fix.t if utc else DAY_S * math.floor(self._today() / DAY_S)
        year = decimal_year(t_date)
        deg, model, h_nt = wmm_declination(fix.lat_deg, fix.lon_deg, year)
        self._wmm_rad = math.radians(deg)
        self.report = DeclinationReport(deg=deg, source="wmm", model=model,
                                        lat_deg=fix.lat_deg, lon_deg=fix.lon_deg,
                                        year=round(year, 3),
                                        date_from="log" if utc else "today")
        date = self._wmm_date = time.strftime("%Y-%m-%d", time.gmtime(t_date))
        if h_nt < BLACKOUT_NT:
            return (f"the World Magnetic Model's declination ({deg:+.1f} deg) is unreliable "
                    f"this close to the magnetic pole (horizontal field {h_nt:.0f} nT); "
                    "set [corrections] declination_deg from a local chart",
                    "so are compass headings there")
        if model.endswith("(extrapolated)"):
            return (f"the World Magnetic Model's declination ({deg:+.1f} deg) is extrapolated "
                    f"to {date}, outside the years its models cover ({MODEL_YEARS[0]}-"
                    f"{MODEL_YEARS[1]}); if the log was not made then, set [corrections] "
                    "declination_deg",
                    ("the date of the log's first fix; a GNSS receiver may report a default "
                     "date until its clock is set" if utc else "today's date: the log has "
                     "no UTC time stamps") + " (summary.json declination)")
        return None

    @property
    def warning(self) -> tuple[str, str]:
        """The ``no_declination`` warning, its line and details, once a magnetic heading
        was used as true (empty before): what was done to which headings, and the key
        that changes it."""
        if not self.uncorrected:
            return "", ""
        done = (f"{self.waiting} magnetic heading(s) rejected while waiting "
                f"{WAIT_FOR_FIX_S:.0f} s for a GNSS fix, then {self.uncorrected} used as "
                "true (over this warning's span)")
        r = self.report
        if r.deg is None:
            return ("magnetic headings used as true: no GNSS fix for the World Magnetic "
                    "Model and no [corrections] declination_deg; set declination_deg for "
                    "where the log was made", done)
        where = (f" at {r.lat_deg:.4f}, {r.lon_deg:.4f} on {self._wmm_date} ({r.model}; "
                 + ("the log's date)" if r.date_from == "log" else "today's date)")
                 if r.source == "wmm" else "")
        return (f"magnetic headings used as true until the first GNSS fix, then corrected "
                f"by {r.deg:+.1f} deg ({r.source}); set [corrections] declination_deg to "
                "correct them all", f"{done}; the declination after it{where}: "
                "summary.json declination")

    def heading(self, s: Heading) -> tuple[Heading, Outcome]:
        """``s`` relative to true north (``reference = "true"``, ``declination_rad`` None:
        the value applied is in :attr:`report`), and what was done (:data:`Outcome`)."""
        if s.reference != "magnetic":
            return s, "true"
        dec, source = self._declination(s)
        if dec is None:
            if self._first_magnetic_t is None:
                self._first_magnetic_t = s.t
            if s.t - self._first_magnetic_t < WAIT_FOR_FIX_S:
                self.waiting += 1
                return s, "wait"
            self.uncorrected += 1
            if self.report.source != "none":
                self.report = DeclinationReport()
            return s, "uncorrected"
        if source == "sensor" and self.report.deg != math.degrees(dec):
            self.report = DeclinationReport(deg=math.degrees(dec), source="sensor")
        return msgspec.structs.replace(s, heading_rad=wrap_2pi(s.heading_rad + dec),
                                       reference="true", declination_rad=None), "corrected"

    def _declination(self, s: Heading) -> tuple[float | None, str]:
        """The declination (rad) for magnetic heading ``s`` and its source."""
        if self._config_rad is not None:
            return self._config_rad, "config"
        if s.declination_rad is not None and math.isfinite(s.declination_rad):
            return s.declination_rad, "sensor"
        return self._wmm_rad, "wmm"
