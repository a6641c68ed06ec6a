"""The UTC of a log's clock: where each log format's time stamps come from, and how they
map to UTC where the log knows it.

Every reader stamps its samples on the log's own clock (``Sample.t``, s; summary.json
``time_span``). That clock is UTC (POSIX seconds) for some formats, a time since boot or
since the start for others, and some logs that are stamped in time since boot carry GPS
time elsewhere. :func:`log_clock` says which, as a :class:`LogClock`:

* tlog: each record's receive time, the logging computer's clock; UTC as is.
* MCAP (BlueOS): the recorder's wall clock; UTC as is.
* DataFlash ``.bin``: ``TimeUS``, time since boot; UTC from the first GPS record with a
  GPS time (``GWk`` > 0, :attr:`DataflashReader.gps_time`).
* service recording: the service's monotonic clock; UTC from each file's meta record
  (``wall_time`` and ``clock`` when the file was opened).
* CSV: the time column times ``time_scale``, each later run of a directory shifted onto one
  time line; UTC as the column reads, run by run.
* NMEA capture: the lines' wall-clock prefixes, UTC from the valid RMC sentences' date and
  time (the median of their difference: the prefixes may be local time), as is without
  any; else the sentences' UTC with the first RMC date, UTC as is.
* mixed Arduino capture: the GPS's UTC with its clock jumps removed; UTC as the GPS read
  after its last jump (``MixedCaptureReader.utc_offset_s``).
* DVL JSON: ``time_of_validity`` or ``ts`` (Unix time), else the sum of json_v1 ``time``
  since the first report; UTC as is.
* Slocum glider binary log: ``m_present_time``, POSIX seconds; UTC as is.
* PD6: the TS lines' time (taken as UTC); UTC as is.
* DDBoat log: the lines' wall-clock stamps (the boat's clock), UTC from its GPS lines' time
  of day on the lines' date (the median of their difference: the boat's clock may be off
  or in local time), as is without any GPS time.

"as is" holds only where the stamps are a date: a clock that reads before
:data:`UTC_MIN_S` (2000-01-01) is a time since boot or since the start (no boot or run lasts
30 years; a computer whose clock was never set counts from 1970), and one from
:data:`UTC_MAX_S` on is not a clock at all. Then the log has no UTC, and
:attr:`LogClock.source` says why. GPS time is turned into UTC with the leap seconds of
:data:`LEAP_SECONDS` (IERS Bulletin C; 18 s since 2017-01-01).
"""

from __future__ import annotations

import bisect
import calendar
import json
import math
import os
import statistics
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from onboard.core.stamps import UTC_MAX_S, UTC_MIN_S

GPS_EPOCH_S = float(calendar.timegm((1980, 1, 6, 0, 0, 0)))
"""The start of GPS week 0 (POSIX s, 1980-01-06T00:00:00Z)."""
SECONDS_PER_WEEK = 604800.0
SECONDS_PER_HOUR = 3600.0
SECONDS_PER_DAY = 86400.0
MS_PER_S = 1000.0
LEAP_SECONDS: tuple[tuple[float, int], ...] = tuple(
    (float(calendar.timegm((y, m, 1, 0, 0, 0))), n) for n, (y, m) in enumerate((
        (1981, 7), (1982, 7), (1983, 7), (1985, 7), (1988, 1), (1990, 1), (1991, 1),
        (1992, 7), (1993, 7), (1994, 7), (1996, 1), (1997, 7), (1999, 1), (2006, 1),
        (2009, 1), (2012, 7), (2015, 7), (2017, 1)), start=1))
"""(UTC from which it holds, POSIX s; GPS time minus UTC, s): every leap second since the
GPS epoch, from IERS Bulletin C."""


@dataclass(frozen=True)
class LogClock:
    """How a log's clock maps to UTC.

    Attributes:
        source: the log's clock and where its UTC comes from, in words (or why it has none).
        offsets: ``(t_from, offset_s)`` pairs, ``t_from`` increasing: UTC (POSIX s) is
            ``t + offset_s`` of the last pair with ``t_from <= t`` (the first pair's before
            its ``t_from``); empty when the log has no UTC.
    """

    source: str
    offsets: tuple[tuple[float, float], ...] = ()

    @property
    def utc(self) -> bool:
        """True when the log's times can be given in UTC."""
        return bool(self.offsets)

    def to_utc(self, t: float) -> float | None:
        """The UTC (POSIX s) of log time ``t`` (s); None when the log has no UTC."""
        if not self.offsets:
            return None
        k = bisect.bisect_right([p[0] for p in self.offsets], t) - 1
        return t + self.offsets[max(k, 0)][1]

    def summary(self, t_start: float) -> dict:
        """``utc`` (bool), ``source`` and ``start`` (the UTC of ``t_start`` in ISO 8601,
        null without UTC): summary.json's ``utc``."""
        start = self.to_utc(t_start)
        return {"utc": self.utc, "source": self.source,
                "start": iso8601(start) if start is not None else None}


def iso8601(t_utc: float) -> str:
    """``YYYY-MM-DDTHH:MM:SS.mmmZ`` of a POSIX time (s), to the millisecond."""
    sec, ms = divmod(round(t_utc * MS_PER_S), round(MS_PER_S))
    return datetime.fromtimestamp(sec, timezone.utc).strftime("%Y-%m-%dT%H:%M:%S") + \
        f".{ms:03d}Z"


def is_date(t: float) -> bool:
    """True when ``t`` (s) reads as a POSIX date (from :data:`UTC_MIN_S` to before
    :data:`UTC_MAX_S`), not a time since boot or start."""
    return UTC_MIN_S <= t < UTC_MAX_S


def gps_to_utc(week: int, tow_ms: float) -> float:
    """The UTC (POSIX s) of GPS week ``week`` and time of week ``tow_ms`` (ms)."""
    t_gps = GPS_EPOCH_S + week * SECONDS_PER_WEEK + tow_ms / MS_PER_S
    for since, leap in reversed(LEAP_SECONDS):
        if t_gps - leap >= since:
            return t_gps - leap
    return t_gps


NO_DATE = "reads before 2000 (a time since boot or since the start), not a date"
"""Why stamps that are no date give no UTC, in words."""
POSIX_CLOCKS: dict[str, tuple[str, str | None]] = {
    "TlogReader": ("the tlog's record stamps (the logging computer's clock)", None),
    "McapReader": ("the MCAP's log times (the recorder's wall clock)", None),
    "DvlJsonLogReader": ("the DVL reports' time_of_validity (Unix time, the DVL's clock)",
                         "the DVL reports carry no time (json_v1: the sum of their "
                         "intervals since the first report)"),
    "Pd6LogReader": ("the PD6 TS lines' time (taken as UTC)", None),
    "SlocumReader": ("the glider's m_present_time (POSIX s)", None),
}
"""Reader class -> (its clock in words, why it has no UTC when its stamps are no date, or
None for the words of :data:`NO_DATE`), for the readers whose stamps are UTC when they are
a date (:func:`is_date`)."""


def log_clock(fmt: str, reader: object, path: str | os.PathLike, t_first: float) -> LogClock:
    """The :class:`LogClock` of the log at ``path``: ``fmt`` is its format
    (:func:`drivers.logs.sniff`), ``reader`` its reader (for a CSV or mixed capture, after
    the first sample: its runs and clock jumps are known then), ``t_first`` its first
    sample's time (s). A DataFlash log is read again up to its first GPS time."""
    if fmt == "dataflash":
        return _dataflash_clock(path)
    if fmt == "recording":
        return _recording_clock(path)
    runs = getattr(reader, "runs", None)
    if fmt in ("csv", "csv-dir") and runs:
        return _csv_clock(runs)
    name = type(reader).__name__
    if name == "MixedCaptureReader":
        return _mixed_clock(reader, t_first)
    if name == "NmeaCaptureReader" and getattr(reader, "receive_times", False):
        return _prefixed_nmea_clock(path, t_first)
    if name == "DdboatLogReader":
        return _ddboat_clock(path, t_first)
    if name == "NmeaCaptureReader":
        return _posix("the NMEA sentences' UTC time and the capture's first RMC date",
                      t_first, no_date="the NMEA sentences give a time of day, and the "
                      "capture has no RMC date")
    words, no_date = POSIX_CLOCKS.get(name, (f"the {fmt} log's time stamps", None))
    return _posix(words, t_first, no_date=no_date)


def _posix(words: str, t_first: float, offset_s: float = 0.0,
           no_date: str | None = None) -> LogClock:
    """UTC from ``words`` (plus ``offset_s``) where the first stamp is a date; else none,
    for ``no_date`` (default: the stamps read before 2000)."""
    if is_date(t_first + offset_s):
        return LogClock(f"UTC from {words}", ((t_first, offset_s),))
    return LogClock("no UTC: " + (no_date or f"{words} {NO_DATE}"))


def _prefixed_nmea_clock(path: str | os.PathLike, t_first: float) -> LogClock:
    """The wall-clock line prefixes put on UTC by the capture's valid RMC sentences: the
    median of (RMC date and time less the line's prefix); the prefixes as UTC without
    any."""
    from onboard.drivers.nmea import NmeaError, parse_rmc, split_sentence
    from onboard.drivers.textlog import prefix_time

    offsets = []
    for line in Path(path).read_bytes().splitlines():
        stamp, i = prefix_time(line) or (None, 0)
        j = line.find(b"$", i)
        if stamp is None or j < 0 or line[j + 3:j + 7] != b"RMC,":
            continue
        try:
            rmc = parse_rmc(split_sentence(line[j:].decode("ascii", "replace"))[2])
        except NmeaError:
            continue
        if rmc.valid and rmc.day_s is not None and rmc.tod_s is not None:
            offsets.append(rmc.day_s + rmc.tod_s - stamp)
    if not offsets:
        return _posix("the capture's wall-clock line prefixes (taken as UTC: no valid RMC "
                      "sentence gives the date)", t_first)
    offset = statistics.median(offsets)
    return _posix("the RMC sentences' date and time (the capture's wall-clock line "
                  f"prefixes are {-offset / SECONDS_PER_HOUR:+.2f} h from UTC: their "
                  "time zone, or their computer's clock error)", t_first, offset)


def _ddboat_clock(path: str | os.PathLike, t_first: float) -> LogClock:
    """The DDBoat's wall-clock line stamps put on UTC by its GPS lines: the median of (the
    GPS time of day, ``hhmmss`` UTC, on the line's date, less the line's stamp) over the
    lines with a fix and a GPS time not seen on the line before (a repeated time is an old
    fix); a difference of 12 h or more is the day before or after. The stamps as UTC
    without any GPS time."""
    from onboard.drivers.textlog import ddboat_gps_times

    offsets = [_within_half_a_day(stamp - stamp % SECONDS_PER_DAY + tod - stamp)
               for stamp, tod in ddboat_gps_times(path)]
    words = "the lines' wall-clock stamps (the boat's clock"
    if not offsets:
        return _posix(f"{words}, taken as UTC: no GPS line with a fix gives the time)",
                      t_first)
    offset = statistics.median(offsets)
    return _posix("the GPS lines' time of day (hhmmss) on the lines' date (the boat's "
                  f"wall-clock line stamps are {-offset / SECONDS_PER_HOUR:+.2f} h, "
                  f"{_hms(-offset)}, from UTC: its time zone, or its clock's error)",
                  t_first, offset)


def _within_half_a_day(seconds: float) -> float:
    """``seconds`` less the whole days that bring it into [-12 h, 12 h)."""
    half = SECONDS_PER_DAY / 2
    return (seconds + half) % SECONDS_PER_DAY - half


def _hms(seconds: float) -> str:
    """``+H:MM:SS`` of a signed number of seconds, rounded to the second."""
    sign = "-" if seconds < 0 else "+"
    m, s = divmod(round(abs(seconds)), 60)
    return f"{sign}{m // 60}:{m % 60:02d}:{s:02d}"


def _dataflash_clock(path: str | os.PathLike) -> LogClock:
    """TimeUS mapped to UTC by the first GPS record with a GPS time."""
    from onboard.core.messages import GnssFix
    from onboard.drivers.dataflash import DataflashReader

    reader = DataflashReader(path, types=[GnssFix])
    for _ in reader:
        if reader.gps_time is not None:
            break
    if reader.gps_time is None:
        return LogClock("no UTC: the DataFlash log's clock is TimeUS (time since boot), and "
                        "no GPS record has a GPS time (GWk)")
    t, week, tow_ms = reader.gps_time
    return LogClock("UTC from the first DataFlash GPS record with a GPS time (GWk, GMS; leap "
                    "seconds removed); the log's clock is TimeUS, time since boot",
                    ((t, gps_to_utc(week, tow_ms) - t),))


def _recording_clock(path: str | os.PathLike) -> LogClock:
    """The service's monotonic clock mapped to UTC by each file's meta record (the
    vehicle computer's wall clock when the file was opened)."""
    from onboard.drivers.recording import read_records

    p = Path(path)
    files = sorted(p.glob("*.onbrec")) if p.is_dir() else [p]
    offsets: list[tuple[float, float]] = []
    for f in files:
        meta = next((r for r in read_records(f) if r.kind == "meta"), None)
        try:
            doc = json.loads(meta.data) if meta is not None else {}
            clock, wall = float(doc["clock"]), float(doc["wall_time"])
        except (ValueError, KeyError, TypeError):
            continue
        if is_date(wall) and math.isfinite(clock) and (not offsets or clock > offsets[-1][0]):
            offsets.append((clock, wall - clock))
    if not offsets:
        return LogClock("no UTC: the recording's clock is the service's monotonic clock, and "
                        "no meta record has a wall time that is a date")
    return LogClock("UTC from the vehicle computer's wall clock when each file was opened "
                    "(its meta record); the recording's clock is the service's monotonic "
                    "clock", tuple(offsets))


def _csv_clock(runs) -> LogClock:
    """The CSV time column, each run at its own time (undoing the shift onto one line)."""
    runs = [r for r in runs if r.t_start == r.t_start]
    if not runs or not all(is_date(r.t_start - r.t_offset) for r in runs):
        return LogClock(f"no UTC: the CSV time column {NO_DATE}")
    return LogClock("UTC from the CSV time column (POSIX time), each run at its own time",
                    tuple((r.t_start, -r.t_offset) for r in runs))


def _mixed_clock(reader, t_first: float) -> LogClock:
    """The GPS's UTC after the capture's last clock jump."""
    offset = reader.utc_offset_s
    if offset is None:
        return LogClock("no UTC: no GPS time in the capture (its rows are timed at the "
                        "assumed row rate)")
    jumps = reader.stats.by_type.get("clock_jump", 0)
    words = "the GPS's time in the capture's NMEA" + (
        f", as it read after the last of its {jumps} clock jumps" if jumps else "")
    return _posix(words, t_first, offset)
