"""A synthetic ArduPilot DataFlash log built record by record (FMT records first, as
ArduPilot writes them): the DataFlash reader's tests and the fuzz corpus start from it."""

from __future__ import annotations

import struct

HEAD = b"\xa3\x95"
"""The two bytes that start every DataFlash record."""
FORMATS: dict[str, tuple[int, str, str]] = {
    "FMT": (128, "BBnNZ", "Type,Length,Name,Format,Columns"),
    "PARM": (64, "QNf", "TimeUS,Name,Value"),
    "MSG": (91, "QZ", "TimeUS,Message"),
    "GPS": (118, "QBBIHBcLLeffffB",
            "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U"),
    "IMU2": (131, "Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
    "ATT": (100, "QccccCCCCB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF"),
    "RPM": (174, "Qff", "TimeUS,rpm1,rpm2"),
    "RCOU": (94, "QHHHH", "TimeUS,C1,C2,C3,C4"),
}
"""Message name -> (type id, DataFlash format string, column names) of the log's FMTs."""
CODES = {"B": "B", "n": "4s", "N": "16s", "Z": "64s", "Q": "Q", "f": "f", "c": "h", "C": "H",
         "I": "I", "H": "H", "L": "i", "e": "i"}
"""DataFlash format character -> :mod:`struct` code (little-endian)."""


def _struct(name: str) -> struct.Struct:
    return struct.Struct("<" + "".join(CODES[c] for c in FORMATS[name][1]))


def fmt_record(name: str) -> bytes:
    """The FMT record that declares message ``name`` of :data:`FORMATS`."""
    typ, fmt, cols = FORMATS[name]
    length = 3 + _struct(name).size
    return HEAD + bytes([128]) + struct.pack("<BB4s16s64s", typ, length, name.encode(),
                                             fmt.encode(), cols.encode())


def record(name: str, *values: object) -> bytes:
    """A ``name`` record with ``values`` in its FMT's column order (raw integers, as
    logged: e.g. ATT angles in centidegrees, GPS position in 1e-7 deg)."""
    return HEAD + bytes([FORMATS[name][0]]) + _struct(name).pack(*values)


def synthetic_log() -> bytes:
    """A rover boat: FMTs, PARMs, the banner, then GPS, IMU2, ATT, RPM, RCOU for 2 s with
    one IMU record written 20 ms late (out of time order, as ArduPilot's threads do)."""
    out = [fmt_record(n) for n in FORMATS]
    out += [record("PARM", 1000, b"FRAME_CLASS", 2.0), record("PARM", 1100, b"SYSID_THISMAV", 7.0),
            record("MSG", 1200, b"ArduRover V4.2.0 (abcdef)")]
    for k in range(20):
        t = 100_000 * (k + 1)
        out.append(record("GPS", t, 0, 3, 0, 0, 12, 90, int(47.5e7), int(-122.3e7), 1234, 1.5, 90.0,
                          0.0, 0.0, 1))
        out.append(record("GPS", t, 1, 3, 0, 0, 12, 90, 0, 0, 0, 0.0, 0.0, 0.0, 0.0, 1))  # 2nd GPS
        out.append(record("ATT", t + 10, 0, 150, 0, -200, 0, 9000, 0, 0, 3))
        out.append(record("RPM", t + 20, 1200.0, -1.0))
        out.append(record("RCOU", t + 30, 1500, 1600, 1400, 0))
    out.append(record("IMU2", 1_500_000, 0.01, 0.02, 0.03, 0.1, 0.2, -9.8))
    out.append(record("IMU2", 1_480_000, 0.01, 0.02, 0.03, 0.1, 0.2, -9.7))  # late
    return b"".join(out)


def gps_timed_log(week: int, tow_ms: int, seconds: float = 2.4) -> bytes:
    """A boat moving north at 1 m/s: GPS records at 5 Hz from 10 s after boot for
    ``seconds``, the first two without a GPS time (``GWk`` 0), the others at GPS week
    ``week`` and time of week from ``tow_ms`` (ms), advancing with ``TimeUS``; an ATT record
    (heading north) with each."""
    out = [fmt_record(n) for n in FORMATS]
    for k in range(round(seconds * 5)):
        t_us = 10_000_000 + 200_000 * k
        wk, ms = (0, 0) if k < 2 else (week, tow_ms + 200 * k)
        lat = int(63.4e7 + 0.2 * k / 111_320.0 * 1e7)
        out.append(record("GPS", t_us, 0, 3, ms, wk, 12, 90, lat, int(10.3e7), 1000,
                          1.0, 0.0, 0.0, 0.0, 1))
        out.append(record("ATT", t_us + 10, 0, 0, 0, 0, 0, 0, 0, 0, 3))
    return b"".join(out)
