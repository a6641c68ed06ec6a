"""NMEA 0183: GNSS fixes and headings from GGA, RMC, VTG, HDT, HDG and HDM; and encoders.

Parsing
-------
:class:`NmeaParser` is the one parser, used both live (``feed(data, t_rx)`` on serial/UDP
bytes) and on text captures (``feed_line(line, t_rx)``, see :mod:`drivers.textlog`).

* Any talker id is accepted (``GP``, ``GN``, ``GL``, ``GA``, ``GB``, ``HE``, ``II``, ...):
  only the three-letter sentence type matters.
* The checksum ``*hh`` is verified; a mismatch is rejected as ``"checksum"``. A sentence
  *without* a checksum is rejected as ``"no_checksum"`` by default: every receiver we know
  sends one, and on a raw serial line a sentence without one is almost always truncated
  (a cut-off GGA can still parse, with a wrong altitude). ``require_checksum=False`` accepts
  them (for old instruments); they are then counted in ``stats.by_type["no_checksum"]``.
* Empty fields become ``None``. ``nan``/``inf`` or non-numeric fields reject the sentence
  as ``"malformed"``, out-of-range values (latitude > 90 deg, minutes >= 60) as
  ``"out_of_range"``.
* Valid sentences of other types (GSA, GSV, proprietary ``$P...``) are not errors: they
  are counted in ``stats.by_type`` (by type and under ``"ignored"``), not rejected.
* Sentences that carry no usable data are rejected with a reason: ``"no_fix"`` (GGA
  quality 0, RMC status ``V``, empty position), ``"empty"`` (HDT/HDG/HDM without a
  heading, VTG without speed and course).

Epochs: one GnssFix per receiver epoch
--------------------------------------
A receiver sends several sentences per epoch (here GGA and RMC share the UTC time; VTG
has no time). They are merged into one :class:`~onboard.core.messages.GnssFix`:

* GGA gives position, MSL altitude, fix quality, satellites and HDOP; RMC gives the
  speed and course over ground (SOG/COG); VTG gives SOG/COG too (RMC wins when both).
* An epoch is opened by the first timed sentence (GGA or RMC) with a new UTC time and
  closed -- the fix emitted -- as soon as every timed sentence type this stream has sent
  so far is present (GGA+RMC on a receiver that sends both; this rule starts after the
  first epoch, once the stream's sentence set is known), or when a timed sentence of
  another UTC time arrives, or when ``hold_s`` of receive time has passed, or on
  :meth:`NmeaParser.flush`. An RMC-only (or GGA-only) epoch thus yields a fix too.
* A VTG received while an epoch is open belongs to it; a VTG received between epochs is
  kept for the next epoch (receivers send VTG first, as the Shenzhen USV's VTG, HDT, GGA,
  RMC order shows).

Headings (HDT true; HDM magnetic; HDG magnetic = sensor + deviation, with the variation
as ``declination_rad``, east positive) are :class:`~onboard.core.messages.Heading` samples.

Time
----
``time_base="synced"`` (live, and recordings of the live service): a fix is stamped with its
sentence UTC mapped to the receive clock through the least-delayed epoch seen
(:class:`drivers.sender_clock.SenderClock`, as an autopilot's boot time is), so fixes that
arrive bunched after a stall of the receiving computer keep the spacing the receiver gave
them; a heading is stamped with its own receive time.

``time_base="rx"`` (captures with receive times): a fix is stamped with the receive time
of the first sentence of its epoch, a heading with its own receive time.

``time_base="utc"`` (captures without receive times): samples are stamped with the
sentence UTC as POSIX seconds. The date comes from RMC (the last one seen; a capture
reader may pass ``date`` found by a pre-scan); without any date, ``t`` is seconds since
midnight UTC of the first day. A time of day more than 12 h earlier than the previous one
is a midnight rollover (day + 1) even before the next RMC brings the new date. Headings
have no time: they take the time of the epoch they belong to (the same rule as VTG), so
they are emitted with that epoch. Samples older than the last emitted one, by up to
``drivers.base.TIME_JUMP_S``, are rejected as ``"time_backwards"``; further back they are
passed on for the engine's time line (a clock reset, or a bad stamp it counts as an
outlier); a repeated epoch is ``"duplicate"``.

Encoders
--------
:func:`encode_gga`, :func:`encode_rmc`, :func:`encode_vtg`, :func:`encode_hdt`,
:func:`encode_hdg` and :func:`encode_hdm` build complete sentences (``$...*hh\\r\\n`` as
bytes) from SI values, for tests and benchmarks (the simulator writes its own:
:mod:`sitl.nmea_out`).
"""

from __future__ import annotations

import calendar
import math
import time as _time
from dataclasses import dataclass, field
from typing import Literal

from onboard.drivers.base import TIME_JUMP_S, LineAssembler, ReadStats, ddmm_degrees
from onboard.drivers.sender_clock import SenderClock
from onboard.core.geo import wrap_2pi
from onboard.core.messages import GnssFix, Heading, Sample

KNOT_MPS = 1852.0 / 3600.0
"""One knot in m/s."""
SUPPORTED = ("GGA", "RMC", "VTG", "HDT", "HDG", "HDM")
"""Sentence types that produce samples."""

MAX_LINE = 256
"""Longest accepted line (bytes). NMEA allows 82 characters; high-precision RTK receivers
send ~100. Longer runs without a line end are garbage and are dropped as ``"too_long"``."""


class NmeaError(ValueError):
    """A sentence that cannot be used; ``reason`` is the ReadStats rejection key."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


# ---------------------------------------------------------------------------- low level


def checksum(body: str | bytes) -> int:
    """XOR of the characters between ``$`` and ``*`` (exclusive)."""
    if isinstance(body, str):
        body = body.encode("ascii", "replace")
    c = 0
    for b in body:
        c ^= b
    return c


def split_sentence(line: str, require_checksum: bool = True) -> tuple[str, str, list[str], bool]:
    """Validate one sentence and split it: ``(talker, type, fields, had_checksum)``.

    ``line`` starts with ``$`` or ``!``; trailing CR/LF and spaces are ignored. ``fields``
    excludes the address field. Raises :class:`NmeaError` (``"malformed"``,
    ``"checksum"``, ``"no_checksum"``).
    """
    s = line.strip()
    if len(s) < 6 or s[0] not in "$!":
        raise NmeaError("malformed", "not a sentence")
    star = s.rfind("*")
    had = star >= 0
    if had:
        body, given = s[1:star], s[star + 1 :]
        if len(given) != 2:
            raise NmeaError("checksum", "checksum must be two hex digits")
        try:
            want = int(given, 16)
        except ValueError:
            raise NmeaError("checksum", "checksum is not hex") from None
        if checksum(body) != want:
            raise NmeaError("checksum")
    else:
        if require_checksum:
            raise NmeaError("no_checksum")
        body = s[1:]
    if not body.isascii() or not body.isprintable():
        raise NmeaError("malformed", "non-printable characters")
    parts = body.split(",")
    addr = parts[0]
    if len(addr) < 3 or not addr.isalnum():
        raise NmeaError("malformed", "bad address field")
    if addr[0] == "P":  # proprietary: $PSRFT, $PUBX...
        return "P", addr[1:], parts[1:], had
    return addr[:-3], addr[-3:], parts[1:], had


def _num(s: str) -> float | None:
    """A numeric field: ``None`` when empty; NmeaError for non-numeric or non-finite."""
    s = s.strip()
    if not s:
        return None
    try:
        v = float(s)
    except ValueError:
        raise NmeaError("malformed", f"not a number: {s!r}") from None
    if not math.isfinite(v):
        raise NmeaError("malformed", f"not finite: {s!r}")
    return v


def _int(s: str) -> int | None:
    v = _num(s)
    return None if v is None else int(v)


def _field(fields: list[str], i: int) -> str:
    return fields[i] if i < len(fields) else ""


def _latlon(value: str, hemi: str, is_lat: bool) -> float | None:
    """``ddmm.mmmm``/``dddmm.mmmm`` + hemisphere to signed decimal degrees (None if empty)."""
    v = _num(value)
    if v is None or not hemi:
        return None
    if v < 0:
        raise NmeaError("out_of_range", "negative coordinate")
    d = ddmm_degrees(v)
    if d is None:
        raise NmeaError("out_of_range", "minutes >= 60")
    if d > (90.0 if is_lat else 180.0):
        raise NmeaError("out_of_range", "coordinate beyond the pole/antimeridian")
    if hemi in ("S", "W"):
        d = -d
    elif hemi not in ("N", "E"):
        raise NmeaError("malformed", f"hemisphere {hemi!r}")
    return d


def _tod(s: str) -> float | None:
    """``hhmmss.ss`` to seconds since midnight (None if empty)."""
    s = s.strip()
    if not s:
        return None
    if len(s) < 6 or not s[:6].isdigit():
        raise NmeaError("malformed", f"time {s!r}")
    hh, mm = int(s[0:2]), int(s[2:4])
    ss = _num(s[4:])
    if ss is None or hh > 23 or mm > 59 or ss >= 61.0:
        raise NmeaError("out_of_range", f"time {s!r}")
    return hh * 3600.0 + mm * 60.0 + ss


def _date(s: str) -> float | None:
    """RMC ``ddmmyy`` to the POSIX time of that day's midnight UTC (None if empty)."""
    s = s.strip()
    if not s:
        return None
    if len(s) != 6 or not s.isdigit():
        raise NmeaError("malformed", f"date {s!r}")
    dd, mo, yy = int(s[0:2]), int(s[2:4]), int(s[4:6])
    year = 2000 + yy if yy < 80 else 1900 + yy
    if not (1 <= mo <= 12 and 1 <= dd <= 31):
        raise NmeaError("out_of_range", f"date {s!r}")
    try:
        return float(calendar.timegm((year, mo, dd, 0, 0, 0)))
    except (ValueError, OverflowError):
        raise NmeaError("out_of_range", f"date {s!r}") from None


def _angle(deg: float | None) -> float | None:
    """Degrees to radians wrapped to [0, 2*pi)."""
    if deg is None:
        return None
    return wrap_2pi(math.radians(deg))


def _ew(value: float | None, hemi: str) -> float | None:
    """A magnitude with an E/W letter to a signed value, east positive."""
    if value is None:
        return None
    return -value if hemi.strip() == "W" else value


# ---------------------------------------------------------------------------- sentences


@dataclass
class Gga:
    """GGA content. ``tod_s`` seconds since midnight UTC, ``alt_m`` above mean sea level."""

    tod_s: float | None
    lat_deg: float | None
    lon_deg: float | None
    quality: int
    num_sats: int | None
    hdop: float | None
    alt_m: float | None
    geoid_sep_m: float | None


@dataclass
class Rmc:
    """RMC content: ``valid`` is status ``A``; ``day_s`` POSIX time of the date's midnight."""

    tod_s: float | None
    valid: bool
    lat_deg: float | None
    lon_deg: float | None
    sog_mps: float | None
    cog_rad: float | None
    day_s: float | None
    variation_rad: float | None
    mode: str


@dataclass
class Vtg:
    """VTG content: SOG (m/s) and true COG (rad)."""

    sog_mps: float | None
    cog_rad: float | None


def parse_gga(f: list[str]) -> Gga:
    """Fields of a GGA sentence (after the address)."""
    if len(f) < 9:
        raise NmeaError("malformed", "GGA needs at least 9 fields")
    return Gga(
        tod_s=_tod(f[0]),
        lat_deg=_latlon(f[1], f[2].strip(), True),
        lon_deg=_latlon(f[3], f[4].strip(), False),
        quality=_int(f[5]) or 0,
        num_sats=_int(f[6]),
        hdop=_num(f[7]),
        alt_m=_num(f[8]),
        geoid_sep_m=_num(_field(f, 10)),
    )


# RMC mode indicator (NMEA 2.3+) to GGA fix quality.
_RMC_MODE_QUALITY = {"A": 1, "D": 2, "P": 3, "R": 4, "F": 5, "E": 6, "M": 7, "S": 8}


def parse_rmc(f: list[str]) -> Rmc:
    """Fields of an RMC sentence (after the address)."""
    if len(f) < 9:
        raise NmeaError("malformed", "RMC needs at least 9 fields")
    sog = _num(f[6])
    var = _num(_field(f, 9))
    return Rmc(
        tod_s=_tod(f[0]),
        valid=f[1].strip() == "A",
        lat_deg=_latlon(f[2], f[3].strip(), True),
        lon_deg=_latlon(f[4], f[5].strip(), False),
        sog_mps=None if sog is None else sog * KNOT_MPS,
        cog_rad=_angle(_num(f[7])),
        day_s=_date(f[8]),
        variation_rad=None if var is None else math.radians(_ew(var, _field(f, 10)) or 0.0),
        mode=_field(f, 11).strip()[:1],
    )


def parse_vtg(f: list[str]) -> Vtg:
    """Fields of a VTG sentence (NMEA 2.3 form ``cog,T,cogm,M,kn,N,kmh,K,mode``; the old
    form without the unit letters is accepted too)."""
    if len(f) >= 8 and f[1].strip() in ("T", ""):
        cog, kn, kmh = _num(f[0]), _num(f[4]), _num(f[6])
    elif len(f) >= 4:  # pre-2.3: cog_true, cog_mag, sog_kn, sog_kmh
        cog, kn, kmh = _num(f[0]), _num(f[2]), _num(f[3])
    else:
        raise NmeaError("malformed", "VTG too short")
    sog = kn * KNOT_MPS if kn is not None else (kmh / 3.6 if kmh is not None else None)
    if len(f) >= 9 and f[8].strip()[:1] == "N":
        raise NmeaError("no_fix", "VTG mode N")
    if sog is None and cog is None:
        raise NmeaError("empty")
    return Vtg(sog_mps=sog, cog_rad=_angle(cog))


def parse_heading(kind: str, f: list[str]) -> tuple[float, Literal["true", "magnetic"], float | None]:
    """HDT/HDM/HDG fields to ``(heading_rad, reference, declination_rad)``.

    HDG ``sensor,dev,E/W,var,E/W``: magnetic heading = sensor + deviation (east positive);
    the variation becomes the declination (true = magnetic + declination).
    """
    h = _num(_field(f, 0))
    if h is None:
        raise NmeaError("empty")
    if kind == "HDT":
        return wrap_2pi(math.radians(h)), "true", None
    if kind == "HDM":
        return wrap_2pi(math.radians(h)), "magnetic", None
    dev = _ew(_num(_field(f, 1)), _field(f, 2))
    var = _ew(_num(_field(f, 3)), _field(f, 4))
    mag = h + (dev or 0.0)
    return wrap_2pi(math.radians(mag)), "magnetic", None if var is None else math.radians(var)


# ---------------------------------------------------------------------------- the parser


@dataclass
class _Epoch:
    tod_s: float
    t_rx: float | None
    gga: Gga | None = None
    rmc: Rmc | None = None
    vtg: Vtg | None = None
    headings: list[tuple[float, str, float | None]] = field(default_factory=list)


class NmeaParser:
    """Incremental NMEA 0183 parser: bytes or lines in, GnssFix and Heading samples out.

    Parameters
    ----------
    source:
        ``Sample.source`` of the samples produced.
    time_base:
        ``"synced"`` stamps fixes with their sentence UTC mapped to the receive clock,
        ``"rx"`` with the receive time, ``"utc"`` with the sentence UTC (see the module
        docstring).
    require_checksum:
        Reject sentences without ``*hh`` (default) or accept them.
    hold_s:
        Longest an open epoch waits (receive time, s) for its other sentences.
    date:
        POSIX time of the UTC midnight to use until an RMC date arrives (``utc`` base).
    max_line:
        Longest line accepted by :meth:`feed` (bytes).
    monotonic:
        In ``utc`` time base, reject samples older than the last one (``"time_backwards"``).
        A capture reader that repairs GPS clock jumps itself turns this off.
    """

    def __init__(
        self,
        source: str = "nmea",
        time_base: Literal["synced", "rx", "utc"] = "synced",
        require_checksum: bool = True,
        hold_s: float = 0.25,
        date: float | None = None,
        max_line: int = MAX_LINE,
        monotonic: bool = True,
    ) -> None:
        self.source = source
        self.monotonic = monotonic
        self.time_base = time_base
        self.require_checksum = require_checksum
        self.hold_s = hold_s
        self.max_line = max_line
        self.stats = ReadStats()
        self.utc_time: float | None = None
        """UTC (POSIX s, or s since the first midnight without a date) of the latest timed
        sentence, valid fix or not; readers use it to time other lines of a capture."""
        self._day0: float | None = date
        self._last_tod: float | None = None
        self._timed_types: set[str] = set()
        self._learned = False  # True once one epoch has been closed by the next one
        self._epoch: _Epoch | None = None
        self._pending_vtg: Vtg | None = None
        self._pending_headings: list[tuple[float, str, float | None]] = []
        self._last_t: float | None = None
        self._last_fix_key: float | None = None
        self._lines = LineAssembler(self.stats, max_line, split_cr=True, skip_blank=True)
        self._clock = SenderClock()

    # -- byte stream

    def feed(self, data: bytes, t_rx: float) -> list[Sample]:
        """Consume serial/UDP bytes received at ``t_rx`` (s); return complete samples.

        Lines end at LF or CR; bytes before a ``$`` are garbage (``"garbage"``); a line
        longer than ``max_line`` is dropped (``"too_long"``); a partial line waits for the
        next call.
        """
        out = self._expire(t_rx)
        for line in self._lines.push(data):
            out.extend(self.feed_line(line, t_rx))
        return out

    def feed_line(self, line: bytes | str, t_rx: float | None = None) -> list[Sample]:
        """Parse one line (which may hold garbage and several merged sentences).

        Each ``$``/``!`` starts a candidate sentence; a non-empty prefix before the first
        one is counted as ``"garbage"``. ``t_rx`` may be None in ``utc`` time base.
        """
        if isinstance(line, bytes):
            line = line.decode("ascii", "replace")
        line = line.strip()
        out: list[Sample] = []
        if t_rx is not None:
            out.extend(self._expire(t_rx))
        starts = [i for i, c in enumerate(line) if c in "$!"]
        if not starts:
            if line:
                self.stats.records += 1
                self.stats.reject("garbage")
            return out
        if starts[0] > 0 and line[: starts[0]].strip():
            self.stats.records += 1
            self.stats.reject("garbage")
        for a, b in zip(starts, starts[1:] + [len(line)]):
            out.extend(self.feed_sentence(line[a:b], t_rx))
        return out

    def feed_sentence(self, sentence: str, t_rx: float | None = None) -> list[Sample]:
        """Parse one sentence starting with ``$``; return the samples it completes."""
        st = self.stats
        st.records += 1
        try:
            talker, kind, f, had = split_sentence(sentence, self.require_checksum)
        except NmeaError as err:
            st.reject(err.reason)
            return []
        if not had:
            st.by_type["no_checksum"] += 1
        st.by_type[kind if talker != "P" else "P" + kind] += 1
        if talker == "P" or kind not in SUPPORTED:
            st.by_type["ignored"] += 1
            return []
        try:
            if kind == "GGA":
                return self._timed(parse_gga(f), None, t_rx)
            if kind == "RMC":
                return self._timed(None, parse_rmc(f), t_rx)
            if kind == "VTG":
                vtg = parse_vtg(f)
                if self._epoch is not None:
                    self._epoch.vtg = vtg
                else:
                    self._pending_vtg = vtg
                return []
            h = parse_heading(kind, f)
        except NmeaError as err:
            st.reject(err.reason)
            return []
        if self.time_base != "utc":
            if t_rx is None:
                st.reject("untimed")
                return []
            return self._emit([Heading(t=t_rx, source=self.source, heading_rad=h[0],
                                       reference=h[1], declination_rad=h[2])])  # type: ignore[arg-type]
        if self._epoch is not None:
            self._epoch.headings.append(h)
        else:
            self._pending_headings.append(h)
        return []

    def flush(self) -> list[Sample]:
        """Close the open epoch (end of stream); return its samples."""
        return self._close()

    def poll(self, t_now: float) -> list[Sample]:
        """Close the open epoch if it has waited more than ``hold_s`` (receive time, s).

        A live transport may call this on its own timer so that the last fix before a
        pause in the stream is not held until the next bytes arrive."""
        return self._expire(t_now)

    # -- epochs

    def _expire(self, t_rx: float) -> list[Sample]:
        e = self._epoch
        if e is not None and e.t_rx is not None and t_rx - e.t_rx > self.hold_s:
            self._learned = True
            return self._close()
        return []

    def _timed(self, gga: Gga | None, rmc: Rmc | None, t_rx: float | None) -> list[Sample]:
        kind = "GGA" if gga is not None else "RMC"
        tod = gga.tod_s if gga is not None else rmc.tod_s  # type: ignore[union-attr]
        out: list[Sample] = []
        if tod is None:
            # An untimed GGA/RMC (seen while a receiver has no time yet): no epoch to join.
            no_fix = (gga is not None and gga.quality <= 0) or (rmc is not None and not rmc.valid)
            self.stats.reject("no_fix" if no_fix else "no_time")
            return out
        self._advance_clock(tod, rmc.day_s if rmc is not None else None)
        e = self._epoch
        if e is not None and abs(e.tod_s - tod) > 1e-6:
            out.extend(self._close())
            self._learned = True
            e = None
        if e is None:
            e = self._epoch = _Epoch(tod_s=tod, t_rx=t_rx, vtg=self._pending_vtg,
                                     headings=self._pending_headings)
            self._pending_vtg = None
            self._pending_headings = []
        self._timed_types.add(kind)
        if gga is not None:
            e.gga = gga
        else:
            e.rmc = rmc
        have = {k for k, v in (("GGA", e.gga), ("RMC", e.rmc)) if v is not None}
        if self._learned and have >= self._timed_types:
            out.extend(self._close())
        return out

    def _advance_clock(self, tod: float, day: float | None = None) -> None:
        if day is not None:
            self._day0 = day  # an RMC date is authoritative
        elif self._day0 is None:
            self._day0 = 0.0
        elif self._last_tod is not None and tod < self._last_tod - 43200.0:
            self._day0 += 86400.0  # midnight rollover before the RMC date catches up
        self._last_tod = tod
        self.utc_time = self._day0 + tod

    def _close(self) -> list[Sample]:
        e = self._epoch
        self._epoch = None
        if e is None:
            return []
        t = self._epoch_time(e)
        if t is None:
            self.stats.reject("untimed")
            return []
        out: list[Sample] = []
        fix = self._fix(e, t)
        if fix is not None:
            out.append(fix)
        for h in e.headings:
            out.append(Heading(t=t, source=self.source, heading_rad=h[0],
                               reference=h[1], declination_rad=h[2]))  # type: ignore[arg-type]
        return self._emit(out)

    def _epoch_time(self, e: _Epoch) -> float | None:
        """The stamp of epoch ``e`` in this parser's time base (None: untimed)."""
        if self.time_base == "rx":
            return e.t_rx
        utc = (self._day0 or 0.0) + e.tod_s
        if self._last_tod is not None and e.tod_s > self._last_tod + 43200.0:
            utc -= 86400.0  # epoch from just before a rollover that was already applied
        if self.time_base == "utc":
            return utc
        return None if e.t_rx is None else self._clock.update(utc, e.t_rx)

    def _fix(self, e: _Epoch, t: float) -> GnssFix | None:
        g, r, v = e.gga, e.rmc, e.vtg
        lat = lon = None
        quality = 0
        if g is not None:
            lat, lon, quality = g.lat_deg, g.lon_deg, g.quality
        elif r is not None and r.valid:
            lat, lon = r.lat_deg, r.lon_deg
            quality = _RMC_MODE_QUALITY.get(r.mode, 1) if r.mode != "N" else 0
        if quality <= 0 or lat is None or lon is None:
            self.stats.reject("no_fix")
            return None
        sog = cog = None
        if r is not None and r.valid and (r.sog_mps is not None or r.cog_rad is not None):
            sog, cog = r.sog_mps, r.cog_rad
        elif v is not None:
            sog, cog = v.sog_mps, v.cog_rad
        key = (self._day0 or 0.0) + e.tod_s
        if self._last_fix_key is not None and key == self._last_fix_key:
            self.stats.reject("duplicate")
            return None
        self._last_fix_key = key
        return GnssFix(
            t=t, source=self.source, lat_deg=lat, lon_deg=lon,
            alt_m=g.alt_m if g is not None else None, fix_quality=quality,
            num_sats=g.num_sats if g is not None else None,
            hdop=g.hdop if g is not None else None, sog_mps=sog, cog_rad=cog,
        )

    def _emit(self, samples: list[Sample]) -> list[Sample]:
        out = []
        for s in samples:
            if (self.monotonic and self.time_base == "utc" and self._last_t is not None
                    and self._last_t - TIME_JUMP_S <= s.t < self._last_t):
                self.stats.reject("time_backwards")
                continue
            self._last_t = s.t
            out.append(s)
        self.stats.samples += len(out)
        return out


# ---------------------------------------------------------------------------- encoders


def _wrap(body: str) -> bytes:
    return f"${body}*{checksum(body):02X}\r\n".encode("ascii")


def _fmt_time(t_utc: float) -> str:
    tod = t_utc % 86400.0
    cs = int(round(tod * 100.0)) % 8640000
    hh, rem = divmod(cs, 360000)
    mm, rem = divmod(rem, 6000)
    return f"{hh:02d}{mm:02d}{rem // 100:02d}.{rem % 100:02d}"


def _fmt_lat(lat: float) -> tuple[str, str]:
    a = abs(lat)
    d = int(a)
    m = (a - d) * 60.0
    if round(m, 7) >= 60.0:
        d, m = d + 1, 0.0
    return f"{d:02d}{m:011.8f}", "N" if lat >= 0 else "S"


def _fmt_lon(lon: float) -> tuple[str, str]:
    a = abs(lon)
    d = int(a)
    m = (a - d) * 60.0
    if round(m, 7) >= 60.0:
        d, m = d + 1, 0.0
    return f"{d:03d}{m:011.8f}", "E" if lon >= 0 else "W"


def _opt(v: float | None, fmt: str) -> str:
    return "" if v is None else format(v, fmt)


def encode_gga(
    t_utc: float,
    lat_deg: float,
    lon_deg: float,
    alt_m: float = 0.0,
    fix_quality: int = 1,
    num_sats: int = 12,
    hdop: float = 0.8,
    geoid_sep_m: float = 0.0,
    talker: str = "GP",
) -> bytes:
    """A GGA sentence. ``t_utc`` POSIX seconds (only the time of day is sent), position in
    decimal degrees, ``alt_m`` above mean sea level (m)."""
    la, ns = _fmt_lat(lat_deg)
    lo, ew = _fmt_lon(lon_deg)
    return _wrap(
        f"{talker}GGA,{_fmt_time(t_utc)},{la},{ns},{lo},{ew},{fix_quality:d},{num_sats:02d},"
        f"{hdop:.1f},{alt_m:.3f},M,{geoid_sep_m:.3f},M,,"
    )


def encode_rmc(
    t_utc: float,
    lat_deg: float,
    lon_deg: float,
    sog_mps: float,
    cog_rad: float | None,
    valid: bool = True,
    variation_rad: float | None = None,
    mode: str = "A",
    talker: str = "GP",
) -> bytes:
    """An RMC sentence (NMEA 2.3, with mode). SOG in m/s (sent in knots), COG in rad
    (sent in degrees true), magnetic variation east positive."""
    la, ns = _fmt_lat(lat_deg)
    lo, ew = _fmt_lon(lon_deg)
    day = _time.strftime("%d%m%y", _time.gmtime(math.floor(t_utc / 86400.0) * 86400.0))
    var = ew_var = ""
    if variation_rad is not None:
        var = f"{abs(math.degrees(variation_rad)):.1f}"
        ew_var = "E" if variation_rad >= 0 else "W"
    cog = "" if cog_rad is None else f"{math.degrees(cog_rad) % 360.0:.2f}"
    return _wrap(
        f"{talker}RMC,{_fmt_time(t_utc)},{'A' if valid else 'V'},{la},{ns},{lo},{ew},"
        f"{sog_mps / KNOT_MPS:.3f},{cog},{day},{var},{ew_var},{mode if valid else 'N'}"
    )


def encode_vtg(sog_mps: float, cog_rad: float | None, cog_mag_rad: float | None = None,
               talker: str = "GP") -> bytes:
    """A VTG sentence: COG true (and magnetic) in rad, SOG in m/s (sent as knots and km/h)."""
    cog = "" if cog_rad is None else f"{math.degrees(cog_rad) % 360.0:.2f}"
    cogm = "" if cog_mag_rad is None else f"{math.degrees(cog_mag_rad) % 360.0:.2f}"
    return _wrap(
        f"{talker}VTG,{cog},T,{cogm},M,{sog_mps / KNOT_MPS:.3f},N,{sog_mps * 3.6:.3f},K,A"
    )


def encode_hdt(heading_rad: float, talker: str = "HE") -> bytes:
    """An HDT sentence: true heading (rad, sent in degrees)."""
    return _wrap(f"{talker}HDT,{math.degrees(heading_rad) % 360.0:.2f},T")


def encode_hdm(heading_rad: float, talker: str = "HC") -> bytes:
    """An HDM sentence: magnetic heading (rad, sent in degrees)."""
    return _wrap(f"{talker}HDM,{math.degrees(heading_rad) % 360.0:.2f},M")


def encode_hdg(
    sensor_heading_rad: float,
    deviation_rad: float | None = None,
    variation_rad: float | None = None,
    talker: str = "HC",
) -> bytes:
    """An HDG sentence: magnetic sensor heading, deviation and variation (rad, east
    positive). The parser yields magnetic heading = sensor + deviation."""

    def ew(v: float | None) -> tuple[str, str]:
        if v is None:
            return "", ""
        return f"{abs(math.degrees(v)):.1f}", "E" if v >= 0 else "W"

    d, de = ew(deviation_rad)
    v, ve = ew(variation_rad)
    return _wrap(f"{talker}HDG,{math.degrees(sensor_heading_rad) % 360.0:.2f},{d},{de},{v},{ve}")
