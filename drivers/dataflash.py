"""ArduPilot DataFlash logs (``.bin``) -> typed samples.

A DataFlash log is a sequence of records ``[0xA3 0x95][type id][payload]``. The layout of
each type is declared in the log itself by ``FMT`` records (type 128, self-describing:
``Type B, Length B, Name n, Format N, Columns Z``), so the reader learns the formats as it
goes and decodes only the types it needs; the rest are skipped by their declared length.

Decoded (column units as documented by ArduPilot's LogStructure.h):

========  ==================================================================================
``IMU``   Imu: AccX..Z (m/s^2, specific force, FRD: level at rest reads AccZ ~ -9.8),
          GyrX..Z (rad/s). One source per instance (``I`` column, or IMU2/IMU3 names).
``ATT``   Attitude: Roll, Pitch, Yaw (deg -> rad). Yaw is the autopilot's (EKF) heading,
          true north. No separate Heading is emitted.
``GPS``   GnssFix, first receiver only (``I`` = 0, or the message named GPS): Status
          (GPS_FIX_TYPE, mapped like MAVLink, < 2 rejected ``"no_fix"``), Lat/Lng, Alt (m),
          NSats, HDop, Spd (m/s) -> sog, GCrs (deg) -> cog.
``BARO``  Pressure: Press (Pa), Temp (degC). One source per instance. ArduSub's BARO
          ``Alt`` is the negated depth relative to the ground calibration; the engine
          converts pressure to depth itself, so ``Alt`` is not used.
``RCOU``  ActuatorOutputs: C1..Cn (us).
``RCIN``  RcChannels: C1..Cn (us).
``PARM``  Parameter: Name, Value.
``RPM``   PropellerRpm: rpm1, rpm2 (negative = sensor unhealthy, dropped) or RPM (newer).
``MSG``,  VehicleInfo, once, from the firmware banner (``"ArduSub V4.1.0 ..."``): mav_type
``VER``   12 SUBMARINE for ArduSub; 10 GROUND_ROVER for ArduRover, 11 SURFACE_BOAT when
          ``FRAME_CLASS`` = 2 was logged before it; 1 FIXED_WING for ArduPlane;
          2 QUADROTOR for ArduCopter. autopilot 3 (ARDUPILOTMEGA), system id from
          ``SYSID_THISMAV`` when logged before, else 1.
========  ==================================================================================

``MAG`` is not decoded: a magnetometer heading needs tilt compensation, calibration and
declination, which the autopilot has already done into ``ATT.Yaw``.
``FMTU``/``UNIT``/``MULT`` are not needed: the scaled format characters (``c C e E L``) are
applied from the format, and the few columns read have fixed documented units.

Time base: ``Sample.t`` = ``TimeUS`` * 1e-6, seconds since the autopilot booted. The log
starts where its first stamps agree (:class:`onboard.core.stamps.Anchor`: the records
outside the largest group of the first five distinct stamps within :data:`TIME_JUMP_S`
of each other are ``"time_outlier"``), so a damaged first stamp costs one record. The
first GPS record whose ``GWk`` is set gives :attr:`DataflashReader.gps_time` (its
``TimeUS``, ``GWk``, ``GMS``), from which :mod:`drivers.logclock` finds the log's UTC.
ArduPilot writes from several threads, so records are slightly out of time order; the
reader re-orders them through a 2 s window. A record older than the last emitted sample
(beyond that window) is ``"time_backwards"``, and ``"time_outlier"`` when it is more than
:data:`TIME_JUMP_S` older (ArduPilot starts a new log file at each boot, so inside one file
that is a corrupted stamp). A record stamped more than :data:`TIME_JUMP_S` ahead is held
(:class:`_Ahead`) until the next records in the file confirm a jump, or show it to be a
``"time_outlier"``: one flipped byte of ``TimeUS`` costs one record.

Rejections: ``"garbage"`` bytes that are not a record start (resync on the next
``A3 95`` whose type is known and which is followed by another record start or the end
of the file); ``"unknown_format"`` a record type without FMT; ``"truncated"`` an
incomplete record at the end; ``"bad_fmt"`` an FMT record that cannot be understood (the
reader goes on from the next record start inside it: damaged bytes that only look like an
FMT do not swallow the records after them);
``"time_backwards"``, ``"time_outlier"`` (above);
handler rejections ``"no_fix"``, ``"nan"``, ``"invalid"``.
"""

from __future__ import annotations

import heapq
import math
import os
import re
import struct
from collections import Counter
from pathlib import Path
from typing import Callable, Iterable, Iterator

from onboard.drivers.base import RELEASE_BYTES, TIME_JUMP_S, MappedLog, ReadStats, UnreadableLog
from onboard.drivers.mavlink import GPS_FIX_TO_QUALITY, wanted_types
from onboard.core.geo import wrap_2pi
from onboard.core.stamps import Anchor
from onboard.core.messages import (
    ActuatorOutputs,
    Attitude,
    GnssFix,
    Imu,
    Parameter,
    Pressure,
    PropellerRpm,
    RcChannels,
    Sample,
    VehicleInfo,
)

HEAD = b"\xa3\x95"
"""The two bytes every DataFlash record starts with."""
FMT_ID = 128
_FMT = struct.Struct("<BB4s16s64s")

FORMAT_CHARS: dict[str, tuple[str, float | None]] = {
    "a": ("64s", None),  # int16_t[32], kept as raw bytes (not used here)
    "b": ("b", None), "B": ("B", None), "h": ("h", None), "H": ("H", None),
    "i": ("i", None), "I": ("I", None), "f": ("f", None), "d": ("d", None),
    "n": ("4s", None), "N": ("16s", None), "Z": ("64s", None),
    "c": ("h", 0.01), "C": ("H", 0.01), "e": ("i", 0.01), "E": ("I", 0.01),
    "L": ("i", 1e-7), "M": ("B", None), "q": ("q", None), "Q": ("Q", None),
}
"""DataFlash format character -> (struct code, multiplier applied on decoding)."""

REORDER_WINDOW_S = 2.0
"""Samples are held this long (log time) to put slightly out-of-order records in order."""

CONFIRM_STAMPS = 2
"""Distinct stamps, one after another in the file and agreeing with each other, that
confirm a jump ahead (a real gap: ArduSub's small.BIN ends with two parameter records
109 s after the rest)."""


class _Ahead:
    """Records stamped far ahead of the reader's clock, held until the records after them
    in the file say what they are: a jump (:data:`CONFIRM_STAMPS` agreeing stamps in a
    row) or outliers (a record near the clock comes first: a corrupted stamp, counted
    ``"time_outlier"``). Without it, one flipped byte of ``TimeUS`` would empty the
    re-ordering window at once and every later record would be ``"time_backwards"``."""

    def __init__(self, stats: ReadStats) -> None:
        self.stats = stats
        self.held: list[tuple[float, Sample]] = []

    def hold(self, t: float, sample: Sample) -> list[tuple[float, Sample]]:
        """Hold ``sample`` stamped ``t`` (s); return the held records once they are a jump."""
        held = self.held
        if held and abs(t - held[-1][0]) > TIME_JUMP_S:
            self.drop()  # unrelated to the records held so far
        held.append((t, sample))
        if len({h[0] for h in held}) < CONFIRM_STAMPS:
            return []
        self.held = []
        return held

    def drop(self) -> None:
        """The held records are outliers."""
        for _ in self.held:
            self.stats.reject("time_outlier")
        self.held = []


class _Order:
    """The samples of the records in time order: the start where the first stamps agree
    (:class:`onboard.core.stamps.Anchor`, the others ``"time_outlier"``), then the
    re-ordering window of :data:`REORDER_WINDOW_S`, records far ahead held
    (:class:`_Ahead`), records behind the last emitted sample dropped (see the module
    docstring).

    Attributes:
        clock: the stamp (s) of a record that carries none: the latest stamp taken into
            the window, before that the last stamp seen, 0 before any.
    """

    def __init__(self, stats: ReadStats) -> None:
        self.stats = stats
        self.clock = 0.0
        self._anchor: Anchor[Sample] = Anchor(TIME_JUMP_S)
        self._ahead = _Ahead(stats)
        self._heap: list[tuple[float, int, Sample]] = []
        self._seq = 0
        self._emitted_t = -math.inf
        self._latest_t = -math.inf

    def push(self, t: float, sample: Sample) -> list[Sample]:
        """Take ``sample`` stamped ``t`` (s); return the samples ready, in time order."""
        if self._anchor.decided:
            return self._order(t, sample)
        self.clock = t
        return self._start(*self._anchor.push(t, sample))

    def flush(self) -> list[Sample]:
        """The log ended: the samples still waiting, in time order (held far-ahead ones
        are outliers)."""
        out = [] if self._anchor.decided else self._start(*self._anchor.decide())
        self._ahead.drop()
        while self._heap:
            self._emitted_t, _, s = heapq.heappop(self._heap)
            out.append(s)
        return out

    def _start(self, kept: list[tuple[float, Sample]],
               outliers: list[tuple[float, Sample]]) -> list[Sample]:
        for _ in outliers:
            self.stats.reject("time_outlier")
        return [out for t, s in kept for out in self._order(t, s)]

    def _order(self, t: float, sample: Sample) -> list[Sample]:
        if t < self._emitted_t:
            self.stats.reject("time_outlier" if t < self._emitted_t - TIME_JUMP_S
                              else "time_backwards")
            return []
        latest = self._latest_t
        if latest != -math.inf and t > latest + TIME_JUMP_S:
            batch = self._ahead.hold(t, sample)
        else:
            self._ahead.drop()
            batch = [(t, sample)]
        heap = self._heap
        for bt, bs in batch:
            latest = max(latest, bt)
            heapq.heappush(heap, (bt, self._seq, bs))
            self._seq += 1
        self._latest_t = self.clock = latest
        out = []
        while heap and heap[0][0] <= latest - REORDER_WINDOW_S:
            self._emitted_t, _, s = heapq.heappop(heap)
            out.append(s)
        return out


_VEHICLES = {"ArduSub": 12, "ArduRover": 10, "ArduPlane": 1, "ArduCopter": 2}
_BANNER = re.compile(r"\b(ArduSub|ArduRover|ArduPlane|ArduCopter)\b")

_Handler = Callable[[tuple, float, "_State"], "Sample | None"]


class _State:
    """Reader state the handlers share."""

    def __init__(self, stats: ReadStats) -> None:
        self.stats = stats
        self.params: dict[str, float] = {}
        self.vehicle_sent = False
        self.gps_time: tuple[float, int, int] | None = None
        """(TimeUS in s, GWk, GMS) of the first GPS record with a GPS time (GWk > 0)."""


class _Format:
    __slots__ = ("type", "name", "length", "struct", "columns", "scales", "handler", "timed")

    def __init__(self, typ: int, name: str, length: int, fmt: str, columns: list[str]) -> None:
        codes = []
        scales: list[float | None] = []
        for ch in fmt:
            code, scale = FORMAT_CHARS[ch]  # KeyError -> bad_fmt
            codes.append(code)
            scales.append(scale)
        self.struct = struct.Struct("<" + "".join(codes))
        if self.struct.size != length - 3 or len(columns) != len(fmt):
            raise ValueError(f"FMT {name}: size {self.struct.size + 3} != length {length}")
        self.type, self.name, self.length = typ, name, length
        self.columns = {c: i for i, c in enumerate(columns)}
        self.scales = scales
        self.timed = bool(columns) and columns[0] == "TimeUS"
        """The first column is TimeUS (us since boot)."""
        self.handler: _Handler | None = None


_BIG = 1e30
"""Finite-value guard: ``abs(x) < _BIG`` is False for NaN and +-inf."""


def _finite(x: float | None) -> float | None:
    """``x``, or None when it is missing, NaN or infinite."""
    return x if x is not None and abs(x) < _BIG else None


def _text(b: bytes) -> str:
    return b.split(b"\0", 1)[0].decode("ascii", "replace")


def _getter(f: _Format, col: str) -> Callable[[tuple], float] | None:
    """Function returning the scaled value of column ``col``, or None when absent."""
    i = f.columns.get(col)
    if i is None:
        return None
    k = f.scales[i]
    if k is None:
        return lambda v: v[i]
    return lambda v: v[i] * k


def _instance(f: _Format, base: str) -> Callable[[tuple], int]:
    """Instance number of a record: the ``I`` column, else the digit of ``IMU2``-style names."""
    i = f.columns.get("I")
    if i is not None:
        return lambda v: v[i]
    tail = f.name[len(base):]
    n = int(tail) - 1 if tail.isdigit() else 0
    return lambda v: n


# ------------------------------------------------------------------ handler factories

def _imu(f: _Format, base: str) -> _Handler | None:
    ix = [f.columns.get(c) for c in ("AccX", "AccY", "AccZ", "GyrX", "GyrY", "GyrZ")]
    if None in ix:
        return None
    inst = _instance(f, base)
    a0, a1, a2, g0, g1, g2 = ix
    sources: dict[int, str] = {}

    def h(v, t, st):
        ax, ay, az, gx, gy, gz = v[a0], v[a1], v[a2], v[g0], v[g1], v[g2]
        if not (abs(ax) < _BIG and abs(ay) < _BIG and abs(az) < _BIG and abs(gx) < _BIG
                and abs(gy) < _BIG and abs(gz) < _BIG):  # NaN or inf
            st.stats.reject("nan")
            return None
        n = inst(v)
        src = sources.get(n) or sources.setdefault(n, f"dataflash/IMU[{n}]")
        return Imu(t=t, source=src, accel_x=ax, accel_y=ay, accel_z=az, gyro_x=gx, gyro_y=gy, gyro_z=gz)
    return h


def _att(f: _Format, base: str) -> _Handler | None:
    r, p, y = _getter(f, "Roll"), _getter(f, "Pitch"), _getter(f, "Yaw")
    if r is None or p is None or y is None:
        return None
    d2r = math.pi / 180.0

    def h(v, t, st):
        roll, pitch, yaw = r(v), p(v), y(v)
        if not (abs(roll) < _BIG and abs(pitch) < _BIG and abs(yaw) < _BIG):
            st.stats.reject("nan")
            return None
        return Attitude(t=t, source="dataflash/ATT", roll_rad=roll * d2r, pitch_rad=pitch * d2r,
                        yaw_rad=wrap_2pi(yaw * d2r))
    return h


def _gps(f: _Format, base: str) -> _Handler | None:
    if f.name != "GPS":  # GPS2 (old logs): second receiver
        return None
    g = {c: _getter(f, c) for c in ("Status", "Lat", "Lng", "Alt", "NSats", "HDop", "Spd", "GCrs",
                                    "GWk", "GMS")}
    if g["Status"] is None or g["Lat"] is None or g["Lng"] is None:
        return None
    timed = g["GWk"] is not None and g["GMS"] is not None
    inst = _instance(f, base)
    d2r = math.pi / 180.0

    def val(c, v):
        fn = g[c]
        return None if fn is None else fn(v)

    def h(v, t, st):
        if inst(v) != 0:
            return None
        if timed and st.gps_time is None and g["GWk"](v) > 0:
            st.gps_time = (t, int(g["GWk"](v)), int(g["GMS"](v)))
        status = g["Status"](v)
        q = GPS_FIX_TO_QUALITY.get(status)
        if q is None:
            st.stats.reject("no_fix")
            return None
        alt, spd, crs, hdop, ns = (_finite(val(c, v)) for c in ("Alt", "Spd", "GCrs", "HDop", "NSats"))
        return GnssFix(t=t, source="dataflash/GPS[0]", lat_deg=g["Lat"](v), lon_deg=g["Lng"](v),
                       alt_m=alt if status >= 3 else None, fix_quality=q, num_sats=ns,
                       hdop=hdop, sog_mps=spd,
                       cog_rad=wrap_2pi(crs * d2r) if crs is not None else None)
    return h


def _baro(f: _Format, base: str) -> _Handler | None:
    p, tmp = _getter(f, "Press"), _getter(f, "Temp")
    if p is None:
        return None
    inst = _instance(f, "BAR" if f.name.startswith("BAR") and f.name != "BARO" else base)
    sources: dict[int, str] = {}

    def h(v, t, st):
        pa = p(v)
        if not 0 < pa < _BIG:
            st.stats.reject("invalid")
            return None
        n = inst(v)
        src = sources.get(n) or sources.setdefault(n, f"dataflash/BARO[{n}]")
        return Pressure(t=t, source=src, pressure_pa=float(pa),
                        temperature_c=_finite(tmp(v)) if tmp is not None else None)
    return h


def _channels(cls: type, f: _Format, base: str) -> _Handler | None:
    ix = []
    k = 1
    while f"C{k}" in f.columns:
        ix.append(f.columns[f"C{k}"])
        k += 1
    if not ix:
        return None
    src = f"dataflash/{f.name}"

    def h(v, t, st):
        return cls(t=t, source=src, pwm_us=tuple(float(v[i]) for i in ix))
    return h


def _parm(f: _Format, base: str) -> _Handler | None:
    n, val = f.columns.get("Name"), _getter(f, "Value")
    if n is None or val is None:
        return None

    def h(v, t, st):
        name, x = _text(v[n]), val(v)
        if not name or not abs(x) < _BIG:
            st.stats.reject("invalid")
            return None
        st.params[name] = x
        return Parameter(t=t, source="dataflash/PARM", name=name, value=float(x))
    return h


def _banner(f: _Format, base: str) -> _Handler | None:
    col = f.columns.get("Message" if f.name == "MSG" else "FWS")
    if col is None:
        return None

    def h(v, t, st):
        if st.vehicle_sent:
            return None
        m = _BANNER.search(_text(v[col]))
        if m is None:
            return None
        st.vehicle_sent = True
        mav_type = _VEHICLES[m.group(1)]
        if mav_type == 10 and st.params.get("FRAME_CLASS") == 2:
            mav_type = 11
        sysid = int(st.params.get("SYSID_THISMAV", 1))
        return VehicleInfo(t=t, source=f"dataflash/{f.name}", system_id=sysid, component_id=1,
                           mav_type=mav_type, autopilot=3)
    return h


def _rpm(f: _Format, base: str) -> _Handler | None:
    r1, r2, r = _getter(f, "rpm1"), _getter(f, "rpm2"), _getter(f, "RPM")
    if r1 is None and r is None:
        return None
    inst = _instance(f, base) if r is not None else (lambda v: 0)

    def h(v, t, st):
        if r1 is not None:
            a = r1(v)
            b = r2(v) if r2 is not None else -1.0
            if not 0 <= a < _BIG:
                st.stats.reject("invalid")
                return None
            rpm = (a, b) if 0 <= b < _BIG else (a,)
            src = "dataflash/RPM"
        else:
            a = r(v)
            if not 0 <= a < _BIG:
                st.stats.reject("invalid")
                return None
            rpm = (a,)
            src = f"dataflash/RPM[{inst(v)}]"
        return PropellerRpm(t=t, source=src, rpm=rpm)
    return h


_FACTORIES: dict[str, tuple[Callable[[_Format, str], _Handler | None], str, tuple[type, ...]]] = {
    "IMU": (_imu, "IMU", (Imu,)), "IMU2": (_imu, "IMU", (Imu,)), "IMU3": (_imu, "IMU", (Imu,)),
    "ATT": (_att, "ATT", (Attitude,)),
    "GPS": (_gps, "GPS", (GnssFix,)),
    "BARO": (_baro, "BARO", (Pressure,)), "BAR2": (_baro, "BAR", (Pressure,)),
    "BAR3": (_baro, "BAR", (Pressure,)),
    "RCOU": (lambda f, b: _channels(ActuatorOutputs, f, b), "RCOU", (ActuatorOutputs,)),
    "RCIN": (lambda f, b: _channels(RcChannels, f, b), "RCIN", (RcChannels,)),
    "PARM": (_parm, "PARM", (Parameter,)),
    "MSG": (_banner, "MSG", (VehicleInfo,)), "VER": (_banner, "VER", (VehicleInfo,)),
    "RPM": (_rpm, "RPM", (PropellerRpm,)),
}
"""DataFlash message name -> (handler factory, instance base name, sample types produced)."""


class DataflashReader:
    """Samples of an ArduPilot DataFlash log, in time order (see the module docstring).

    ``types`` restricts the samples produced (Sample classes or tags). PARM records are
    always decoded internally (the vehicle detection uses FRAME_CLASS and SYSID_THISMAV).
    Raises :class:`UnreadableLog` at construction when the file cannot be read, is empty,
    or does not start (within its first 64 KiB) with a DataFlash FMT record.
    """

    def __init__(self, path: str | os.PathLike, *, types: Iterable[type | str] | None = None) -> None:
        self.path = Path(path)
        self.stats = ReadStats()
        self._want = wanted_types(types) if types is not None else None
        self._state: _State | None = None
        try:
            with open(self.path, "rb") as f:
                head = f.read(1 << 16)
        except OSError as e:
            raise UnreadableLog(f"{self.path}: {e.strerror or e}") from e
        if not head:
            raise UnreadableLog(f"{self.path}: empty file")
        i = head.find(HEAD + bytes((FMT_ID,)))
        if i < 0 or not self._fmt_ok(head, i):
            raise UnreadableLog(f"{self.path}: not an ArduPilot DataFlash log (no FMT record)")
        self._first = i

    @staticmethod
    def _fmt_ok(data: bytes, i: int) -> bool:
        if i + 89 > len(data):
            return False
        typ, length, name, fmt, cols = _FMT.unpack_from(data, i + 3)
        name_s, fmt_s = _text(name), _text(fmt)
        return length >= 3 and name_s.isalnum() and all(c in FORMAT_CHARS for c in fmt_s)

    @property
    def gps_time(self) -> tuple[float, int, int] | None:
        """(log time in s, GPS week, GPS time of week in ms) of the first record of the first
        receiver that carries a GPS time (``GWk`` > 0), as far as the log has been read;
        None before that. :mod:`drivers.logclock` turns it into the log's UTC."""
        return self._state.gps_time if self._state is not None else None

    def _wanted_name(self, name: str) -> bool:
        if name == "PARM":
            return True
        entry = _FACTORIES.get(name)
        if entry is None:
            return False
        return self._want is None or any(issubclass(c, self._want) for c in entry[2])

    release_bytes = RELEASE_BYTES
    """Pages behind the reader are released every this many bytes (:class:`MappedLog`)."""

    def __iter__(self) -> Iterator[Sample]:
        mapped = MappedLog(self.path, self.release_bytes)
        stats = self.stats = ReadStats()
        counts: Counter[str] = Counter()
        try:
            yield from self._walk(mapped, stats, counts)
        finally:
            mapped.close()
            for k, c in counts.items():
                stats.by_type[k] += c

    def _walk(self, mapped: MappedLog, stats: ReadStats, counts: Counter[str]) -> Iterator[Sample]:
        data = mapped.data
        n = len(data)
        st = self._state = _State(stats)
        formats: dict[int, _Format] = {}
        lengths: dict[int, int] = {FMT_ID: 89}
        want = self._want
        order = _Order(stats)
        n_samples = 0
        records = 0
        used = 0  # bytes of the records read whole
        pos = self._first
        if pos > 0:
            stats.reject("garbage")
        while pos < n:
            if pos >= mapped.next_release:
                mapped.release(pos)
            reason = None
            if data[pos] == 0xA3 and pos + 3 <= n and data[pos + 1] == 0x95:
                typ = data[pos + 2]
                length = lengths.get(typ)
                if length is None:
                    reason = "unknown_format"
                elif pos + length > n:
                    reason = "truncated"
                else:
                    end = pos + length
                    if end + 2 <= n and (data[end] != 0xA3 or data[end + 1] != 0x95):
                        reason = "garbage"  # framing broken right after: distrust this record
            else:
                reason = "garbage" if pos + 3 <= n or data[pos] != 0xA3 else "truncated"
            if reason is not None:
                stats.reject(reason)
                nxt = self._resync(data, pos + 1, n, lengths)
                if nxt < 0:
                    break
                pos = nxt
                continue
            if typ == FMT_ID:
                if not self._add_format(data, pos, formats, lengths, stats):
                    # not a format: bytes that only looked like one; read on from the
                    # next record start inside them
                    nxt = self._resync(data, pos + 1, n, lengths)
                    if nxt < 0:
                        break
                    pos = nxt
                    continue
                records += 1
                used += length
                counts["FMT"] += 1
                pos = end
                continue
            records += 1
            used += length
            f = formats.get(typ)
            if f is None:  # length known only for FMT itself
                pos = end
                continue
            counts[f.name] += 1
            h = f.handler
            if h is not None:
                v = f.struct.unpack_from(data, pos + 3)
                t = v[0] / 1e6 if f.timed else order.clock
                try:
                    s = h(v, t, st)
                except (TypeError, ValueError, OverflowError):
                    # a FMT that types a column other than its message's layout (text
                    # where a number belongs): the record is unusable, not the log
                    stats.reject("format")
                    pos = end
                    continue
                if s is not None and (want is None or isinstance(s, want)):
                    for out in order.push(t, s):
                        n_samples += 1
                        yield out
            pos = end
        for out in order.flush():
            n_samples += 1
            yield out
        stats.records = records
        stats.samples = n_samples
        stats.size_bytes = n
        stats.used_bytes = used

    @staticmethod
    def _resync(data: bytes, start: int, n: int, lengths: dict[int, int]) -> int:
        """Next ``A3 95`` of a known type followed by another record start (or the end)."""
        p = data.find(HEAD, start)
        while p >= 0:
            if p + 3 <= n:
                length = lengths.get(data[p + 2])
                if length is not None:
                    end = p + length
                    if end == n or (end + 2 <= n and data[end] == 0xA3 and data[end + 1] == 0x95):
                        return p
            p = data.find(HEAD, p + 1)
        return -1

    def _add_format(self, data: bytes, pos: int, formats: dict[int, _Format],
                    lengths: dict[int, int], stats: ReadStats) -> bool:
        """Read the FMT record at ``pos`` into ``formats`` and ``lengths``; False (counted
        ``"bad_fmt"``) when it cannot be understood."""
        typ, length, name_b, fmt_b, cols_b = _FMT.unpack_from(data, pos + 3)
        if typ == FMT_ID:
            return True
        try:
            name, fmt, cols = _text(name_b), _text(fmt_b), _text(cols_b).split(",")
            f = _Format(typ, name, length, fmt, cols if fmt else [])
        except (KeyError, ValueError, struct.error):
            stats.reject("bad_fmt")
            return False
        if self._wanted_name(name):
            factory, base, _ = _FACTORIES[name]
            f.handler = factory(f, base)
        formats[typ] = f
        lengths[typ] = length
        return True
