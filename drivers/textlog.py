"""Text captures: sniff the content and read it as NMEA, DVL JSON, PD6 or a mixed capture.

:func:`open_text_log` looks at the first 64 kB of a text file (and on, 64 kB at a time, up to
16 MB, until it recognises one of these) and returns a log reader:

``nmea``
    NMEA 0183 sentences, one per line (:class:`NmeaCaptureReader`). Lines may carry a
    wall-clock prefix ``YYYY-MM-DD HH:MM:SS[.,]fff ... $GP...`` (a loguru/logging capture,
    as ``ardusub_small_logs/nmea_log.txt``): that prefix is the receive time (parsed as
    UTC, the capture does not say its time zone) and samples are stamped with it.
    Without prefixes the sentences' own UTC times are used (see :mod:`drivers.nmea`),
    with the date of the first RMC in the file applied from the start.
``dvl-json``
    Water Linked DVL JSON lines (:class:`drivers.dvl_json.DvlJsonLogReader`).
``pd6``
    Teledyne PD6 lines (:class:`drivers.pd6.Pd6LogReader`).
``mixed``
    A raw serial capture of an Arduino logger that interleaves NMEA from a GPS with
    CSV rows ``ax,ay,az,mx,my,mz,rx,ry,rz,roll,pitch,yaw,throttle,rudder`` (the
    ``survey_boat_arduino_rc`` captures; :class:`MixedCaptureReader`).
``ddboat``
    The ENSTA DDBoat Python ``logging`` lines (:class:`DdboatLogReader`): GPS fixes, motor
    commands and the boat's own compass heading (``THETA``).

Anything else raises :class:`~drivers.base.UnreadableLog`.

Mixed captures: timing the CSV rows
-----------------------------------
The CSV rows carry no time. Every change of the GPS's UTC (GGA/RMC, fix or no fix) is an
*epoch mark* at its place in the file. The row rate is the median of rows per second
between marks at most ``max_gap_s`` apart (30 Hz if there are none). A mark whose time
goes backwards, or forwards by more than ``max(max_gap_s, 2 x (rows since the last mark
/ rate) + 1 s)``, is a *clock jump* (the GPS setting its clock: ``Test1`` starts in 2009
and jumps to 2018; ``Test3`` steps back 2 s at 17:56:08): the jump is removed -- the mark
is placed ``rows / rate`` after the previous one and every later time (rows and NMEA
samples) is shifted by the same amount -- and counted in ``stats.by_type["clock_jump"]``.
So ``t`` is one continuous time line that equals the GPS UTC up to the first jump (a GPS
that has not yet set its clock counts from a default date: ``Test1`` from 2009-02-14);
``utc_offset_s`` is the GPS UTC minus ``t`` after the last jump, the time the GPS settled
on. The rows
between two marks are spread evenly: row ``j`` of ``n`` gets ``t_k + j (t_k+1 - t_k) / n``;
rows before the first mark and after the last are placed at the row rate. The GPS sentences reach the logger
after their epoch (4800 baud), so rows are stamped up to ~0.3 s late relative to UTC; the
offset is nearly constant within a capture. The reader reads the capture line by line but
holds its samples until the end, and yields them sorted by time.

Row -> samples (source ``"arduino"``; the NMEA samples have source ``"nmea"``):

* :class:`~onboard.core.messages.Imu`: the sensor reads +9.8 m/s^2 on ``az`` when level, so
  its axes are taken as x forward, y left, z up and turned to FRD by negating y and z
  (accelerations m/s^2; gyro deg/s -> rad/s). The gyro sign was not verified against the
  yaw column (their correlation in ``Test2_clockwise`` is ~0).
* :class:`~onboard.core.messages.Heading`: ``yaw`` (deg, compass) as a magnetic heading.
* :class:`~onboard.core.messages.RcChannels`: ``(throttle, rudder)`` pulse widths (us),
  channel 1 = throttle, channel 2 = rudder.

Row rejections: ``"truncated"`` (fewer fields, or a row cut by a following sentence or
``START OF TEST``), ``"garbage"`` (binary noise), ``"malformed"`` (14 fields, not all
numeric), ``"out_of_range"`` (|a| > 160 m/s^2, |gyro| > 2000 deg/s, yaw outside
[0, 360], PWM outside [800, 2200] us). ``START OF TEST`` and the header row are counted
in ``stats.by_type``.
"""

from __future__ import annotations

import calendar
import itertools
import math
import os
import re
import statistics
from pathlib import Path
from typing import Iterable, Iterator

import msgspec

from onboard.drivers.base import (LogReader, ReadStats, TimeOrder, UnreadableLog,
                                  counted_lines, ddmm_degrees)
from onboard.drivers.nmea import NmeaError, NmeaParser, parse_gga, parse_rmc, split_sentence
from onboard.core.geo import wrap_2pi
from onboard.core.messages import ActuatorCommand, GnssFix, Heading, Imu, RcChannels, Sample

SNIFF_BYTES = 65536
"""Bytes of a text capture :func:`open_text_log` judges at a time (a window)."""
SNIFF_MAX_BYTES = 16 << 20
"""Bytes into a text capture :func:`open_text_log` looks for its first record: a logger's
status lines before its first sentence are passed over up to this far (a few seconds of
sniffing at most); a file with none in them is refused, the message saying how far it
looked."""
_PREFIX = re.compile(rb"^(\d{4})-(\d{2})-(\d{2})[ T](\d{2}):(\d{2}):(\d{2})(?:[.,](\d{1,6}))?")
_NMEA = re.compile(rb"[$!][A-Z]{2}[A-Z0-9]{2,4},[^*\r\n]*\*[0-9A-Fa-f]{2}")
_PD6 = re.compile(rb"^:[A-Z]{2},")
_NUM = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)$")
ARDUINO_FIELDS = ("ax", "ay", "az", "mx", "my", "mz", "rx", "ry", "rz", "roll", "pitch",
                  "yaw", "throttle", "rudder")


def prefix_time(line: bytes) -> tuple[float, int] | None:
    """A leading ``YYYY-MM-DD HH:MM:SS[.,]fff`` as (POSIX s, taken as UTC; end index)."""
    m = _PREFIX.match(line)
    if not m:
        return None
    y, mo, d, h, mi, s = (int(x) for x in m.groups()[:6])
    frac = m.group(7)
    try:
        t = calendar.timegm((y, mo, d, h, mi, s))
    except (ValueError, OverflowError):
        return None
    if frac:
        t += int(frac) / 10 ** len(frac)
    return float(t), m.end()


_DVL_KEYS = re.compile(rb'"vx"|"position_local"')
"""What makes a JSON line a Water Linked DVL report (:mod:`drivers.dvl_json`): a velocity
(``vx``, every generation of the protocol) or a dead reckoning (``position_local``)."""


def sniff_text(head: bytes) -> str:
    """The kind of a text capture from its first bytes (see the module docstring), or ``""``."""
    lines = [ln.strip() for ln in head.splitlines()[:-1] or head.splitlines()]
    n_nmea = n_json = n_pd6 = n_csv = n_ddboat = 0
    for ln in lines:
        if not ln:
            continue
        if b"/cmd motors l,r are" in ln or b"/GPS [" in ln or b"/GPS timeout" in ln:
            n_ddboat += 1
        elif ln.startswith(b"{") and ln.endswith(b"}") and _DVL_KEYS.search(ln):
            n_json += 1   # one report per line: not a JSON document, nor other JSON lines
        elif _PD6.match(ln):
            n_pd6 += 1
        elif _NMEA.search(ln):
            n_nmea += 1
        elif ln.count(b",") == 13 and _arduino_values(ln) is not None:
            n_csv += 1
    if n_ddboat:
        return "ddboat"
    if n_csv and n_csv >= max(n_json, n_pd6):
        return "mixed"
    best = max((n_nmea, "nmea"), (n_json, "dvl-json"), (n_pd6, "pd6"))
    return best[1] if best[0] > 0 else ""


def open_text_log(path: str | Path) -> LogReader:
    """A reader for the text capture at ``path``; UnreadableLog if it is none we know.

    The kind is that of the first window of :data:`SNIFF_BYTES` (the first, then each next
    one, whole lines carried over) in which :func:`sniff_text` recognises one, up to
    :data:`SNIFF_MAX_BYTES` into the file: a logger's status lines before its first
    sentence do not hide the capture, and one window is in memory at a time."""
    p = Path(path)
    looked = 0
    try:
        with open(p, "rb") as fh:
            window = fh.read(SNIFF_BYTES)
            if not window.strip() and len(window) < SNIFF_BYTES:
                raise UnreadableLog(f"{p}: empty file")
            kind = sniff_text(window)
            looked = len(window)
            while not kind and looked < SNIFF_MAX_BYTES:
                chunk = fh.read(SNIFF_BYTES)
                if not chunk:
                    break
                looked += len(chunk)
                carry = window[window.rfind(b"\n") + 1:] if b"\n" in window else b""
                window = (carry if len(carry) < SNIFF_BYTES else b"") + chunk
                kind = sniff_text(window)
    except OSError as err:
        raise UnreadableLog(f"{p}: {err.strerror or err}") from None
    if kind == "nmea":
        return NmeaCaptureReader(p)
    if kind == "dvl-json":
        from onboard.drivers.dvl_json import DvlJsonLogReader

        return DvlJsonLogReader(p)
    if kind == "pd6":
        from onboard.drivers.pd6 import Pd6LogReader

        return Pd6LogReader(p)
    if kind == "mixed":
        return MixedCaptureReader(p)
    if kind == "ddboat":
        return DdboatLogReader(p)
    where = (f"in the first {_kb(looked)} (it looks no further)" if looked >= SNIFF_MAX_BYTES
             else f"in the whole file ({_kb(looked)})")
    raise UnreadableLog(f"{p}: no NMEA, DVL JSON, PD6 or known logger lines {where}")


def _kb(n: int) -> str:
    """``n`` bytes in kB (MB from 10 MB on), for a message."""
    return f"{n / (1 << 20):,.0f} MB" if n >= 10 << 20 else f"{max(1, round(n / 1024)):,} kB"


LINE_CHUNK_BYTES = 1 << 20
"""A text capture is read this many bytes at a time (:func:`_read_lines`)."""


def _split_lines(data: bytes) -> list[bytes]:
    return data.replace(b"\r\n", b"\n").replace(b"\r", b"\n").split(b"\n")


def _read_lines(path: Path, chunk_bytes: int = LINE_CHUNK_BYTES) -> Iterator[bytes]:
    """The lines of the file at ``path``, as its whole text split at CR LF, LF or CR (a
    last line after the last line end, empty when the file ends with one), read
    ``chunk_bytes`` at a time: the line being read carries over into the next chunk, and
    so does a CR at a chunk's end (the first half of a CR LF)."""
    try:
        with open(path, "rb") as fh:
            carry = b""
            while chunk := fh.read(chunk_bytes):
                buf = carry + chunk
                held = b"\r" if buf.endswith(b"\r") else b""
                lines = _split_lines(buf[:len(buf) - len(held)])
                carry = lines.pop() + held
                yield from lines
    except OSError as err:
        raise UnreadableLog(f"{path}: {err.strerror or err}") from None
    yield from _split_lines(carry)


def first_rmc_date(lines: Iterable[bytes]) -> float | None:
    """POSIX midnight of the capture's first day: the first RMC date (valid checksum), a
    day earlier when that RMC comes after midnight and an earlier sentence before it."""
    first_tod: float | None = None
    for ln in lines:
        i = max(ln.find(b"RMC,"), ln.find(b"GGA,"))
        if i < 3:
            continue
        j = ln.rfind(b"$", 0, i)
        if j < 0:
            continue
        try:
            _, kind, f, _ = split_sentence(ln[j:].decode("ascii", "replace"))
            if kind == "GGA":
                tod = parse_gga(f).tod_s
            elif kind == "RMC":
                rmc = parse_rmc(f)
                tod = rmc.tod_s
                if rmc.day_s is not None:
                    if first_tod is not None and tod is not None and tod < first_tod - 43200.0:
                        return rmc.day_s - 86400.0
                    return rmc.day_s
            else:
                continue
            if first_tod is None and tod is not None:
                first_tod = tod
        except NmeaError:
            continue
    return None


HEAD_LINES = 500
"""Lines of an NMEA capture whose prefixes decide whether it carries receive times: its
first ones, or its first with a sentence when those have none."""


class NmeaCaptureReader:
    """An NMEA text capture, with or without wall-clock receive-time prefixes."""

    def __init__(self, path: str | Path, source: str = "nmea") -> None:
        self.path = Path(path)
        self.source = source
        head = list(itertools.islice(_read_lines(self.path), HEAD_LINES))
        if not any(b"$" in ln for ln in head):   # status lines first: judge the sentences
            head = list(itertools.islice((ln for ln in _read_lines(self.path) if b"$" in ln),
                                         HEAD_LINES))
        stamped = sum(1 for ln in head if _PREFIX.match(ln) and b"$" in ln)
        nmea = sum(1 for ln in head if b"$" in ln)
        self.receive_times = nmea > 0 and stamped >= nmea / 2
        """True when the lines carry wall-clock receive times (used as ``t``)."""
        self._parser = NmeaParser(
            source=source, time_base="rx" if self.receive_times else "utc",
            date=None if self.receive_times else first_rmc_date(_read_lines(self.path)),
            hold_s=1e9 if self.receive_times else 0.25,
        )
        self.stats = self._parser.stats

    def __iter__(self) -> Iterator[Sample]:
        p, st = self._parser, self.stats
        order = TimeOrder(st)

        def ordered(samples: list[Sample]) -> Iterator[Sample]:
            for s in samples:
                if not order.keep(s.t):
                    st.samples -= 1
                    continue
                yield s

        for ln in counted_lines(st, _read_lines(self.path), ends=1):
            ln = ln.strip()
            if not ln:
                continue
            if self.receive_times:
                pt = prefix_time(ln)
                i = ln.find(b"$")
                if pt is None or i < 0:
                    st.records += 1
                    st.reject("unrecognized")
                    continue
                yield from ordered(p.feed_line(ln[i:], pt[0]))
            else:
                yield from ordered(p.feed_line(ln))
        yield from ordered(p.flush())


def _arduino_values(line: bytes) -> list[float] | None:
    parts = line.decode("ascii", "replace").split(",")
    if len(parts) != len(ARDUINO_FIELDS):
        return None
    out = []
    for s in parts:
        s = s.strip()
        if not _NUM.match(s):
            return None
        out.append(float(s))
    return out


class MixedCaptureReader:
    """The survey-boat Arduino capture: NMEA interleaved with CSV IMU/RC rows.

    ``imu_rate_hz`` is the row rate assumed when the GPS gives no usable time;
    ``max_gap_s`` the longest interval between epoch marks that rows are spread over.
    """

    def __init__(self, path: str | Path, imu_rate_hz: float = 30.0, max_gap_s: float = 3.0,
                 source: str = "arduino") -> None:
        self.path = Path(path)
        self.source = source
        self.imu_rate_hz = imu_rate_hz
        self.max_gap_s = max_gap_s
        self.stats = ReadStats()
        self.row_rate_hz: float | None = None
        """Median row rate between good epoch marks (after iteration)."""
        self.utc_offset_s: float | None = None
        """UTC (POSIX s) minus ``t`` after the last clock jump: the GPS's time at its last
        epoch mark less that mark's place on the time line (0 without jumps; None without
        any GPS time). Known once the first sample is out."""

    def __iter__(self) -> Iterator[Sample]:
        st = self.stats
        nmea = NmeaParser(source="nmea", time_base="utc",
                          date=first_rmc_date(_read_lines(self.path)),
                          monotonic=False)
        nmea.stats = st  # one set of counters for the whole capture
        fixes: list[tuple[Sample, int]] = []  # (sample, index of the latest mark)
        rows: list[list[float]] = []
        marks: list[tuple[int, float]] = []  # (index of the next row, GPS UTC)
        last_utc: float | None = None
        for raw in counted_lines(st, _read_lines(self.path), ends=1):
            ln = raw.strip()
            if not ln:
                continue
            i = ln.find(b"$")
            if i >= 0:
                if i > 0:
                    st.records += 1
                    st.reject("truncated" if _looks_csv(ln[:i]) else "garbage")
                k = len(marks) - 1
                fixes.extend((s, k) for s in nmea.feed_line(ln[i:]))
                if nmea.utc_time is not None and nmea.utc_time != last_utc:
                    last_utc = nmea.utc_time
                    marks.append((len(rows), last_utc))
                continue
            st.records += 1
            vals = _arduino_values(ln) if ln.count(b",") == 13 else None
            if vals is not None:
                reason = _check_row(vals)
                if reason:
                    st.reject(reason)
                else:
                    rows.append(vals)
                    st.by_type["arduino"] += 1
                continue
            text = ln.decode("ascii", "replace")
            if text == "START OF TEST":
                st.by_type["start_of_test"] += 1
            elif text.replace(" ", "").startswith("ax,ay,az"):
                st.by_type["header"] += 1
            elif not ln.isascii() or not text.isprintable():
                st.reject("garbage")
            elif ln.count(b",") != 13 or "START OF TEST" in text:
                st.reject("truncated")
            else:
                st.reject("malformed")
        fixes.extend((s, len(marks) - 1) for s in nmea.flush())
        adj = self._timeline(marks)
        samples: list[Sample] = []
        for s, k in fixes:
            # the sample belongs to mark k (or k + 1 when it closed with the line of k + 1)
            cands = [j for j in (k, k + 1) if 0 <= j < len(marks)]
            if not cands:
                samples.append(s)
                continue
            j = min(cands, key=lambda j: abs(marks[j][1] - s.t))
            samples.append(msgspec.structs.replace(s, t=s.t + adj[j] - marks[j][1]))
        times = self._row_times(len(rows), [(p, a) for (p, _), a in zip(marks, adj)])
        for t, v in zip(times, rows):
            samples.extend(self._row_samples(t, v))
        samples.sort(key=lambda s: s.t)
        st.samples = len(samples)
        yield from samples

    def _timeline(self, marks: list[tuple[int, float]]) -> list[float]:
        """Mark times with GPS clock jumps removed (see the module docstring)."""
        rates = [(p1 - p0) / (t1 - t0) for (p0, t0), (p1, t1) in zip(marks, marks[1:])
                 if p1 > p0 and 0.0 < t1 - t0 <= self.max_gap_s]
        rate = statistics.median(rates) if rates else self.imu_rate_hz
        self.row_rate_hz = rate
        adj: list[float] = []
        for k, (p, t) in enumerate(marks):
            if k == 0:
                adj.append(t)
                continue
            p0, t0 = marks[k - 1]
            d = t - t0
            expected = (p - p0) / rate
            if 0.0 < d <= max(self.max_gap_s, 2.0 * expected + 1.0):
                adj.append(adj[-1] + d)
            else:
                self.stats.by_type["clock_jump"] += 1
                adj.append(adj[-1] + max(expected, 1e-3))
        if marks:
            self.utc_offset_s = marks[-1][1] - adj[-1]
        return adj

    def _row_times(self, n: int, marks: list[tuple[int, float]]) -> list[float]:
        """Row times from (row index, time) marks whose times increase."""
        rate = self.row_rate_hz or self.imu_rate_hz
        if not marks:
            return [j / rate for j in range(n)]
        times = [0.0] * n
        p0, t0 = marks[0]
        for j in range(min(p0, n)):
            times[j] = t0 - (p0 - j) / rate
        for k, (pk, tk) in enumerate(marks):
            pn, tn = marks[k + 1] if k + 1 < len(marks) else (n, None)
            span = pn - pk
            if span <= 0:
                continue
            dt = (tn - tk) / span if tn is not None else 1.0 / rate
            for j in range(pk, min(pn, n)):
                times[j] = tk + (j - pk) * dt
        return times

    def _row_samples(self, t: float, v: list[float]) -> list[Sample]:
        ax, ay, az, _mx, _my, _mz, rx, ry, rz, _roll, _pitch, yaw, thr, rud = v
        src = self.source
        d2r = math.pi / 180.0
        return [
            Imu(t=t, source=src, accel_x=ax, accel_y=-ay, accel_z=-az,
                gyro_x=rx * d2r, gyro_y=-ry * d2r, gyro_z=-rz * d2r),
            Heading(t=t, source=src, heading_rad=wrap_2pi(yaw * d2r),
                    reference="magnetic"),
            RcChannels(t=t, source=src, pwm_us=(thr, rud)),
        ]


def _looks_csv(b: bytes) -> bool:
    s = b.decode("ascii", "replace").strip().rstrip(",")
    return bool(s) and all(_NUM.match(x.strip()) for x in s.split(",") if x.strip())


def _check_row(v: list[float]) -> str:
    ax, ay, az, _mx, _my, _mz, rx, ry, rz, _roll, _pitch, yaw, thr, rud = v
    if max(abs(ax), abs(ay), abs(az)) > 160.0 or max(abs(rx), abs(ry), abs(rz)) > 2000.0:
        return "out_of_range"
    if not 0.0 <= yaw <= 360.0 or not (800.0 <= thr <= 2200.0 and 800.0 <= rud <= 2200.0):
        return "out_of_range"
    return ""


_DD_GPS = re.compile(r"/GPS \[([\d.]+), '([NS])', ([\d.]+), '([EW])', ([\d.]+), '([AV])'\]")
_DD_CMD = re.compile(r"dirl: (\d), motl: (\d+), dirr: (\d), motr: (\d+)")
_DD_THETA = re.compile(r"/CONTROL: .*? THETA (\S+)")
DDBOAT_HEADING_SOURCE = "ddboat/THETA"
"""The source of the DDBoat's heading samples: the ``THETA`` of its ``CONTROL:`` record."""


class DdboatLogReader:
    """ENSTA DDBoat ``logging`` lines: GPS fixes, left/right motor commands and the boat's
    compass heading.

    ``t`` is the line's wall-clock stamp (the boat's clock, taken as UTC). ``GPS [ddmm.mmmm,
    'N', dddmm.mmmm, 'W', hhmmss, 'A']`` gives a GnssFix (status ``V`` is ``"no_fix"``, a
    repeat of the previous GPS time ``"duplicate"``). ``cmd motors`` gives an
    ActuatorCommand with ``left``/``right`` = +-mot/255 (``dir`` 0 = ahead, as the
    controller's positive CMDL/CMDR show).

    ``CONTROL: ... THETA th`` gives a magnetic Heading (source
    :data:`DDBOAT_HEADING_SOURCE`): ``th`` is the boat's own compass heading, its raw
    magnetometer through the boat's calibration (ENSTA's ``DdboatFilter.cap``: 0 facing
    east, counterclockwise, rad), so the heading from north, clockwise, is ``pi/2 - th``.
    The sense is the data's: ``th`` turns against the gyro's z axis (which points down,
    as the accelerometer's -1 g on it shows) with 0.084 deg/s per count, the LSM9DS1's
    70 mdps per count at 2000 deg/s (correlation -0.62 over DDBOAT8_t_2022_9_2_0_0.log).
    A non-numeric ``THETA`` is rejected as ``"bad_heading"``.

    The raw ``IMU: MAG`` counts are not read as a second heading: they are the same
    sensor as ``THETA`` before the calibration, and the log does not carry the hard- and
    soft-iron calibration that turns them into a heading. The accelerometer and gyro
    counts are unscaled and not read either.
    """

    def __init__(self, path: str | Path, source: str = "ddboat", full_scale: float = 255.0) -> None:
        self.path = Path(path)
        self.source = source
        self.full_scale = full_scale
        self.stats = ReadStats()

    def __iter__(self) -> Iterator[Sample]:
        st, src = self.stats, self.source
        order = TimeOrder(st)
        last_gps: str | None = None
        for raw in counted_lines(st, _read_lines(self.path), ends=1):
            ln = raw.strip()
            if not ln:
                continue
            st.records += 1
            pt = prefix_time(ln)
            if pt is None:
                st.reject("unrecognized")
                continue
            t = pt[0]
            if not order.keep(t):
                continue
            text = ln.decode("utf-8", "replace")
            out: list[Sample] = []
            m = _DD_GPS.search(text)
            if m:
                st.by_type["gps"] += 1
                lat = _ddmm(m.group(1), m.group(2))
                lon = _ddmm(m.group(3), m.group(4))
                if m.group(6) != "A" or lat is None or lon is None:
                    st.reject("no_fix")
                elif m.group(5) == last_gps:
                    st.reject("duplicate")
                else:
                    last_gps = m.group(5)
                    out.append(GnssFix(t=t, source=src, lat_deg=lat, lon_deg=lon))
            elif "/GPS timeout" in text:
                st.by_type["gps_timeout"] += 1
            heading = self._heading(t, text)
            if heading is not None:
                out.append(heading)
            m = _DD_CMD.search(text)
            if m:
                st.by_type["cmd"] += 1
                dl, ml, dr, mr = (int(x) for x in m.groups())
                fs = self.full_scale
                left = min(ml / fs, 1.0) * (-1.0 if dl else 1.0)
                right = min(mr / fs, 1.0) * (-1.0 if dr else 1.0)
                out.append(ActuatorCommand(t=t, source=src, left=left + 0.0, right=right + 0.0))
            if not out and not m:
                st.by_type["other"] += 1
            st.samples += len(out)
            yield from out

    def _heading(self, t: float, text: str) -> Heading | None:
        """The Heading of a line's ``THETA`` (class docstring), or None without one."""
        m = _DD_THETA.search(text)
        if not m:
            return None
        self.stats.by_type["theta"] += 1
        try:
            theta = float(m.group(1))
        except ValueError:
            theta = math.nan
        if not math.isfinite(theta):
            self.stats.reject("bad_heading")
            return None
        return Heading(t=t, source=DDBOAT_HEADING_SOURCE,
                       heading_rad=wrap_2pi(0.5 * math.pi - theta), reference="magnetic")


def ddboat_gps_times(path: str | os.PathLike) -> Iterator[tuple[float, float]]:
    """(line stamp, GPS time of day) of each DDBoat GPS line with a fix and a GPS time not
    seen before (the fixes :class:`DdboatLogReader` reads): the stamp POSIX s on the
    boat's clock, the time of day s since midnight UTC (``hhmmss``)."""
    last: str | None = None
    for ln in _read_lines(Path(path)):
        if b"/GPS [" not in ln:
            continue
        pt = prefix_time(ln.strip())
        m = _DD_GPS.search(ln.decode("utf-8", "replace"))
        if pt is None or m is None or m.group(6) != "A" or m.group(5) == last:
            continue
        last = m.group(5)
        tod = _hhmmss(m.group(5))
        if tod is not None:
            yield pt[0], tod


def _hhmmss(value: str) -> float | None:
    """Seconds since midnight of ``hhmmss[.ss]``; None when it is no time of day."""
    try:
        v = float(value)
    except ValueError:
        return None
    h, rest = divmod(v, 10000.0)
    m, s = divmod(rest, 100.0)
    if not (math.isfinite(v) and 0.0 <= v and h < 24.0 and m < 60.0 and s < 61.0):
        return None
    return h * 3600.0 + m * 60.0 + s


def _ddmm(value: str, hemi: str) -> float | None:
    try:
        d = ddmm_degrees(float(value))
    except ValueError:
        return None
    if d is None:
        return None
    return -d if hemi in ("S", "W") else d
