"""Teledyne RDI PD6 lines out of the simulator, written from Teledyne's documents.

PD6 (Teledyne RD Instruments, "DVL Output Data Format (PD6)" in the WorkHorse and
Pathfinder guides; Water Linked's DVLs send it too, "PD formats") is an ASCII ensemble
of lines, each ``:`` and a two-letter id, then comma-separated fixed-width fields
(right-aligned, padded with spaces), then CR LF::

    :SA,±PP.PP,±RR.RR,HHH.HH                  attitude: pitch, roll, heading (deg)
    :TS,YYMMDDHHmmsshh,SS.S,+TT.T,DDDD.D,CCCC.C,BBB
                                              time (UTC), salinity (ppt), temperature
                                              (C), depth of the transducer (m), speed
                                              of sound (m/s), built-in-test result
    :WI / :BI,±XXXXX,±YYYYY,±ZZZZZ,±EEEEE,S   water-mass / bottom-track velocity in
                                              instrument axes (mm/s): X (+ = movement
                                              from beam 1 to beam 2), Y (+ = from beam
                                              4 to beam 3), Z (+ = away from the
                                              bottom), error velocity; status A good,
                                              V bad
    :WS / :BS,±TTTTT,±LLLLL,±NNNNN,S          ship axes (mm/s): transverse (+ = port
                                              to starboard), longitudinal (+ = aft to
                                              forward), normal (+ = away from the
                                              bottom)
    :BE,±EEEEE,±NNNNN,±UUUUU,S                earth axes (mm/s): east, north, up
    :BD,±EEEEEEEE.EE,±NNNNNNNN.NN,±UUUUUUUU.UU,DDDD.DD,TTT.TT
                                              distance made good east, north, up (m),
                                              range to the bottom (m), time since the
                                              last good velocity (s)

A missing velocity component is sent as -32768 (with status V). The velocities here are
the vehicle's movement over the bottom (or through the water), as PD6 states them, not
the bottom's movement past the instrument (PD0).

The simulated DVL looks down, mounted with beam 2 forward: the instrument's X axis
(beam 1 to beam 2) points forward, Z (away from the bottom) up, and so Y (right-handed,
beam 4 to beam 3) to port. A velocity ``(vx, vy, vz)`` in the DVL's forward-right-down
axes is therefore sent as ``X = vx, Y = -vy, Z = -vz``, and in ship axes as
``T = vy, L = vx, N = -vz``.
"""

from __future__ import annotations

import datetime as _dt
import math

MISSING_MMPS = -32768
"""The PD6 value of a missing velocity component."""
MAX_MMPS = 32767
"""Largest velocity component a field holds (mm/s)."""
SALINITY_PPT = 35.0
"""Salinity the simulated DVL is set to (sea water, ppt)."""
SOUND_SPEED_MPS = 1500.0
"""Speed of sound the simulated DVL is set to (m/s)."""
BIT_OK = 0
"""Built-in-test result code of a healthy instrument."""
MM_PER_M = 1000.0
CENTISECOND_S = 0.01
"""Resolution of the TS time (s)."""
_EPOCH = _dt.datetime(1970, 1, 1, tzinfo=_dt.timezone.utc)


def _line(ident: str, *fields: str) -> bytes:
    return (":" + ",".join((ident, *fields)) + "\r\n").encode("ascii")


def _mmps(v_mps: float | None) -> str:
    """A velocity component (m/s; None: missing) as a ``±XXXXX`` field (mm/s)."""
    if v_mps is None:
        return f"{MISSING_MMPS:+6d}"
    mm = max(-MAX_MMPS, min(MAX_MMPS, int(round(v_mps * MM_PER_M))))
    return f"{mm:+6d}"


def _status(valid: bool) -> str:
    return "A" if valid else "V"


def sa(roll_rad: float, pitch_rad: float, heading_rad: float) -> bytes:
    """The SA line: pitch, roll and heading (rad; sent in degrees, heading in [0, 360))."""
    heading = round(math.degrees(heading_rad) % 360.0, 2) % 360.0
    return _line("SA", f"{math.degrees(pitch_rad):+6.2f}", f"{math.degrees(roll_rad):+6.2f}",
                 f"{heading:6.2f}")


def ts(t_utc: float, depth_m: float, temperature_c: float, salinity_ppt: float = SALINITY_PPT,
       sound_speed_mps: float = SOUND_SPEED_MPS) -> bytes:
    """The TS line: time (POSIX s, sent to the hundredth), salinity, temperature, depth of
    the transducer, speed of sound, and a healthy built-in test."""
    stamp = _EPOCH + _dt.timedelta(milliseconds=10 * round(t_utc / CENTISECOND_S))
    when = stamp.strftime("%y%m%d%H%M%S") + f"{stamp.microsecond // 10_000:02d}"
    return _line("TS", when, f"{salinity_ppt:4.1f}", f"{temperature_c:+5.1f}",
                 f"{depth_m:6.1f}", f"{sound_speed_mps:6.1f}", f"{BIT_OK:3d}")


def instrument_velocity(vx: float, vy: float, vz: float, error_mps: float, valid: bool,
                        water: bool = False) -> bytes:
    """The BI (``water``: WI) line of a velocity in the DVL's forward-right-down axes
    (m/s) and its error velocity (m/s); every component missing when not ``valid``."""
    xyz = (vx, -vy, -vz, error_mps) if valid else (None, None, None, None)
    return _line("WI" if water else "BI", *(_mmps(v) for v in xyz), _status(valid))


def ship_velocity(vx: float, vy: float, vz: float, valid: bool, water: bool = False) -> bytes:
    """The BS (``water``: WS) line of a velocity in the DVL's forward-right-down axes
    (m/s); every component missing when not ``valid``."""
    tln = (vy, vx, -vz) if valid else (None, None, None)
    return _line("WS" if water else "BS", *(_mmps(v) for v in tln), _status(valid))


def earth_velocity(v_north_mps: float, v_east_mps: float, v_down_mps: float,
                   valid: bool) -> bytes:
    """The BE line of a velocity over the bottom in NED (m/s)."""
    enu = (v_east_mps, v_north_mps, -v_down_mps) if valid else (None, None, None)
    return _line("BE", *(_mmps(v) for v in enu), _status(valid))


def bottom_distance(east_m: float, north_m: float, up_m: float, range_m: float,
                    since_good_s: float) -> bytes:
    """The BD line: distance made good (m), range to the bottom (m; 0 when there is
    none), time since the last good velocity (s)."""
    return _line("BD", f"{east_m:+12.2f}", f"{north_m:+12.2f}", f"{up_m:+12.2f}",
                 f"{range_m:7.2f}", f"{since_good_s:6.2f}")
