"""NMEA 0183 sentences out of the simulator, written with pynmeagps (not the drivers).

The simulator's GNSS receiver and gyro compass speak NMEA 0183. The NMEA-specific
encodings come from pynmeagps (semuconsulting's NMEA parser and generator, the ``sim``
extra): latitude and longitude as ``ddmm.mmmmmmm`` / ``dddmm.mmmmmmm`` (``ddd2dmm`` in
its high-precision mode: 7 decimals of a minute, 0.2 mm), the time of day as
``hhmmss.ss`` (``time2str``), the date as ``ddmmyy`` (``date2str``) and the checksum,
the XOR of the characters between ``$`` and ``*`` as two hex digits
(``generate_checksum``). This module lists the fields in the standard's order and
chooses the values and the decimals of the numeric fields, which the standard leaves
variable (``x.x``). (pynmeagps's ``NMEAMessage`` assembles whole sentences too, at 0.3 ms
each: twelve times this module's cost, which a demo flown at ten times real time feels.)

=========  ========================================================================
sentence   fields (NMEA 0183 4.10)
=========  ========================================================================
GGA        UTC time, latitude, N/S, longitude, E/W, fix quality, satellites (2
           digits), HDOP (0.1), altitude above mean sea level (mm), ``M``, geoid
           separation (0 m), ``M``, no differential age or station
RMC        UTC time, status ``A``, latitude, N/S, longitude, E/W, speed over ground
           (knots, 0.001), course over ground (degrees true, 0.01; empty when
           unknown), date, no magnetic variation, mode (``A`` autonomous, ``D``
           differential, ``R`` RTK fixed, ``F`` RTK float), navigational status ``V``
           (not provided)
VTG        course over ground true (0.01 deg) ``T``, magnetic (empty) ``M``, speed
           (knots, 0.001) ``N``, speed (km/h, 0.001) ``K``, mode ``A``
HDT        true heading (0.01 deg), ``T``
=========  ========================================================================

An epoch without a fix (an outage, the antenna under water) is sent as a receiver sends
it, every epoch, with the position, speed and course empty (the survey boat's receiver
in ``../shared/data/survey_boat_arduino_rc``, Test1: ``$GPGGA,174822.160,,,,,0,00,,,M,
0.0,M,,0000``, ``$GPRMC,174822.160,V,,,,,,,180209,,,N``):

=========  ========================================================================
sentence   fields of an epoch without a fix
=========  ========================================================================
GGA        UTC time, empty position, fix quality 0, satellites ``00``, empty HDOP
           and altitude, ``M``, geoid separation (0 m), ``M``, no differential data
RMC        UTC time, status ``V``, empty position, speed and course, date, no
           magnetic variation, mode ``N`` (not valid), navigational status ``V``
VTG        empty course and speed with their unit letters, mode ``N``
=========  ========================================================================

A heading epoch without a heading is an HDT with the heading empty, ``$HEHDT,,T``, as the
Shenzhen USV's dual-antenna receiver (``../shared/data/usv_rtk_gnss_heading_nmea_shenzhen``)
sends ``$GPHDT,,T*1B``.

The high-precision position makes GGA and RMC about 90 characters long, beyond the
standard's 82, as an RTK receiver's are. Times are POSIX seconds (UTC); they are rounded
to the hundredth of a second once, and the time of day and the RMC date are both taken
from that one rounded instant.
"""

from __future__ import annotations

import datetime as _dt
import math

try:
    from pynmeagps import date2str, ddd2dmm, generate_checksum, time2str
except ImportError as exc:  # pragma: no cover - the sim extra is missing
    raise ImportError("the simulator needs pynmeagps: pip install 'onboard[sim]'") from exc

KNOT_MPS = 1852.0 / 3600.0
"""One knot (m/s): the international nautical mile (1852 m) per hour."""
KMH_MPS = 1.0 / 3.6
"""One km/h in m/s."""
MINUTE_DECIMALS = 7
"""Decimals of a minute of arc in pynmeagps' high-precision latitude and longitude."""
CENTISECOND_S = 0.01
"""Resolution of the UTC time fields (s)."""
RMC_MODE = {1: "A", 2: "D", 4: "R", 5: "F", 6: "E"}
"""GGA fix quality -> RMC mode indicator (NMEA 2.3 and later); anything else: ``A``."""
_EPOCH = _dt.datetime(1970, 1, 1, tzinfo=_dt.timezone.utc)


def utc(t_utc: float) -> _dt.datetime:
    """POSIX seconds as a UTC date and time, rounded to the hundredth of a second."""
    return _EPOCH + _dt.timedelta(milliseconds=10 * round(t_utc / CENTISECOND_S))


def clear_of_next_degree(deg: float) -> float:
    """``deg``, or the whole degree just beyond it when its minutes would round up to
    60 at :data:`MINUTE_DECIMALS` (pynmeagps does not carry the minute into the degrees:
    42.99999999999 would be written ``4260.0000000``, which is no angle). The two differ
    by less than the field's resolution."""
    minutes = (abs(deg) * 60.0) % 60.0
    if 60.0 - minutes < 10.0 ** -MINUTE_DECIMALS:
        return math.copysign(float(round(abs(deg))), deg)
    return deg


def degrees_0_360(rad: float, decimals: int) -> str:
    """An angle (rad) as degrees in [0, 360) with ``decimals`` decimals."""
    deg = round(math.degrees(rad) % 360.0, decimals) % 360.0
    return f"{deg:.{decimals}f}"


def sentence(talker: str, kind: str, fields: list[str]) -> bytes:
    """``$``, the address (talker and sentence type), the fields, ``*``, the checksum,
    CR LF."""
    checksum = generate_checksum(talker, kind, fields)
    return f"${talker}{kind},{','.join(fields)}*{checksum}\r\n".encode("ascii")


def position(lat_deg: float, lon_deg: float) -> list[str]:
    """Latitude, N/S, longitude, E/W (decimal degrees in)."""
    lat, lon = clear_of_next_degree(lat_deg), clear_of_next_degree(lon_deg)
    return [ddd2dmm(lat, "LA", True), "N" if lat >= 0.0 else "S",
            ddd2dmm(lon, "LN", True), "E" if lon >= 0.0 else "W"]


def gga(t_utc: float, lat_deg: float, lon_deg: float, alt_m: float, fix_quality: int,
        num_sats: int, hdop: float, talker: str = "GP") -> bytes:
    """A GGA sentence (fix data): position in decimal degrees, ``alt_m`` above mean sea
    level (m)."""
    return sentence(talker, "GGA", [
        time2str(utc(t_utc).time()), *position(lat_deg, lon_deg), str(fix_quality),
        f"{num_sats:02d}", f"{hdop:.1f}", f"{alt_m:.3f}", "M", "0.000", "M", "", ""])


def rmc(t_utc: float, lat_deg: float, lon_deg: float, sog_mps: float, cog_rad: float | None,
        fix_quality: int = 1, talker: str = "GP") -> bytes:
    """An RMC sentence (recommended minimum data) of a valid fix: speed over ground
    (m/s, sent in knots), course over ground (rad, sent in degrees true; None: empty)."""
    stamp = utc(t_utc)
    return sentence(talker, "RMC", [
        time2str(stamp.time()), "A", *position(lat_deg, lon_deg), f"{sog_mps / KNOT_MPS:.3f}",
        "" if cog_rad is None else degrees_0_360(cog_rad, 2), date2str(stamp.date(), "DT"),
        "", "", RMC_MODE.get(fix_quality, "A"), "V"])


def vtg(sog_mps: float, cog_rad: float | None, talker: str = "GP") -> bytes:
    """A VTG sentence (course and speed over ground): m/s sent as knots and km/h, course
    (rad) as degrees true (None: empty)."""
    return sentence(talker, "VTG", [
        "" if cog_rad is None else degrees_0_360(cog_rad, 2), "T", "", "M",
        f"{sog_mps / KNOT_MPS:.3f}", "N", f"{sog_mps / KMH_MPS:.3f}", "K", "A"])


def gga_no_fix(t_utc: float, talker: str = "GP") -> bytes:
    """A GGA sentence of an epoch without a fix: the time, fix quality 0, no position."""
    return sentence(talker, "GGA", [
        time2str(utc(t_utc).time()), "", "", "", "", "0", "00", "", "", "M", "0.000", "M",
        "", ""])


def rmc_no_fix(t_utc: float, talker: str = "GP") -> bytes:
    """An RMC sentence of an epoch without a fix: the time and date, status ``V``, mode
    ``N``, the position, speed and course empty."""
    stamp = utc(t_utc)
    return sentence(talker, "RMC", [
        time2str(stamp.time()), "V", "", "", "", "", "", "", date2str(stamp.date(), "DT"),
        "", "", "N", "V"])


def vtg_no_fix(talker: str = "GP") -> bytes:
    """A VTG sentence of an epoch without a fix: course and speed empty, mode ``N``."""
    return sentence(talker, "VTG", ["", "T", "", "M", "", "N", "", "K", "N"])


def hdt(heading_rad: float | None, talker: str = "HE") -> bytes:
    """An HDT sentence: true heading (rad, sent in degrees; None: empty, no valid
    heading)."""
    return sentence(talker, "HDT", [
        "" if heading_rad is None else degrees_0_360(heading_rad, 2), "T"])
