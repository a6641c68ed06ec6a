"""Teledyne RDI PD6 DVL output (also emitted by Nortek, Wayfinder and others in PD6 mode).

One ensemble is a group of ASCII lines, each starting with ``:`` and a two-letter id::

    :SA,+PP.PP,+RR.RR,HHH.HH                 attitude: pitch, roll, heading (deg)
    :TS,YYMMDDHHmmsshh,SS.S,+TT.T,DDDD.D,CCCC.C,BBB
                                             time, salinity (ppt), temperature (C),
                                             depth of transducer (m), speed of sound (m/s), BIT
    :WI / :BI,+XXXXX,+YYYYY,+ZZZZZ,+EEEEE,S  water / bottom velocity, instrument frame (mm/s),
                                             error velocity E, status A (good) / V (bad)
    :WS / :BS,+TTTTT,+LLLLL,+NNNNN,S         water / bottom velocity, ship frame (mm/s):
                                             transverse (starboard), longitudinal (forward),
                                             normal (up)
    :WE / :BE,+EEEEE,+NNNNN,+UUUUU,S         water / bottom velocity, earth frame (mm/s)
    :WD / :BD,+E.EE,+N.NN,+U.UU,DDDD.DD,TTT.TT
                                             distance made good east/north/up (m), range to
                                             the bottom / water-mass layer (m), time since the
                                             last good velocity (s)

-32768 marks a missing velocity. PD6 has no checksum, so every field is checked against
its format (sign and digits, status letter, field count); a line that does not match is
``"malformed"``.

Samples:

* ``BS`` (default) or ``BI`` (``velocity_frame="instrument"``) -> DvlVelocity,
  track ``"bottom"``; ``WS``/``WI`` -> DvlVelocity, track ``"water"``. Ship frame to FRD:
  ``vx = L, vy = T, vz = -N``. Instrument frame (RDI: Z toward the transducer face, i.e. up
  for a down-looking unit) to FRD-like axes: ``vx = X, vy = -Y, vz = -Z``; the mounting
  rotation is configuration. BI's error velocity becomes ``fom_mps`` (an indicator, not
  a calibrated one-sigma). Status ``V`` or a -32768 component gives ``valid=False`` with
  zero velocity -- never a valid sample.
* ``BE`` -> VelocityOverGround (north, east, down = -U), only when valid.
* ``TS`` -> Depth (transducer depth, temperature) and the ensemble time.
* ``SA`` -> Attitude (roll, pitch, heading as yaw; rad).
* ``BD`` -> Altitude (range to the bottom) when > 0.
* ``WE`` and ``WD`` carry nothing the estimators use: counted in ``stats.by_type`` (by id
  and under ``"ignored"``), not rejected. Unknown ids are rejected as ``"unsupported"``.

Time: ``time_base="rx"`` stamps samples with the receive time (live);
``time_base="instrument"`` with the last ``TS`` time (POSIX s; captures), and lines before
the first ``TS`` are rejected as ``"untimed"``; an SA line (sent before TS in an
ensemble) is held and stamped with the TS that follows. In the instrument time base a
sample up to ``drivers.base.TIME_JUMP_S`` older than the newest is ``"time_backwards"``,
one further back is passed on for the engine's time line to judge
(:class:`drivers.base.TimeOrder`).
"""

from __future__ import annotations

import calendar
import math
import re
import time as _t
from pathlib import Path
from typing import Iterator, Literal

import msgspec

from onboard.drivers.base import LineAssembler, ReadStats, TimeOrder, UnreadableLog, counted_lines
from onboard.core.geo import wrap_2pi
from onboard.core.messages import (
    Altitude,
    Attitude,
    Depth,
    DvlVelocity,
    Sample,
    VelocityOverGround,
)

MAX_LINE = 160
"""Longest accepted line (bytes)."""
MISSING = -32768
"""PD6 marker of a missing velocity component."""

_VEL = re.compile(r"^[+-]?\d{1,6}$")
_DEC = re.compile(r"^[+-]?\d+(\.\d*)?$")
_TS = re.compile(r"^\d{14}$")


class Pd6Error(ValueError):
    """A line that cannot be used; ``reason`` is the ReadStats rejection key."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def _vel(s: str) -> int:
    s = s.strip()
    if not _VEL.match(s):
        raise Pd6Error("malformed")
    return int(s)


def _dec(s: str) -> float:
    s = s.strip()
    if not _DEC.match(s):
        raise Pd6Error("malformed")
    return float(s)


def _status(s: str) -> bool:
    s = s.strip()
    if s not in ("A", "V"):
        raise Pd6Error("malformed")
    return s == "A"


def parse_ts_time(s: str) -> float:
    """``YYMMDDHHmmsshh`` to POSIX seconds (UTC assumed; PD6 does not say)."""
    s = s.strip()
    if not _TS.match(s):
        raise Pd6Error("malformed")
    yy, mo, dd, hh, mi, ss, cs = (int(s[i : i + 2]) for i in range(0, 14, 2))
    if not (1 <= mo <= 12 and 1 <= dd <= 31 and hh < 24 and mi < 60 and ss < 61):
        raise Pd6Error("out_of_range")
    return calendar.timegm((2000 + yy, mo, dd, hh, mi, ss)) + cs / 100.0


class Pd6Parser:
    """Incremental PD6 parser: ``feed(data, t_rx)`` for serial bytes, ``feed_line`` for text.

    ``velocity_frame`` chooses BS (``"ship"``, default) or BI (``"instrument"``) as the
    bottom-track DvlVelocity (and WS or WI for water track); the other frame is counted
    as ``"ignored"`` (in ``stats.by_type``) so a vehicle never fuses the same ping twice.
    """

    def __init__(
        self,
        source: str = "pd6",
        time_base: Literal["rx", "instrument"] = "rx",
        velocity_frame: Literal["ship", "instrument"] = "ship",
        max_line: int = MAX_LINE,
    ) -> None:
        self.source = source
        self.time_base = time_base
        self.velocity_frame = velocity_frame
        self.max_line = max_line
        self.stats = ReadStats()
        self.instrument_time: float | None = None
        """POSIX time of the last TS line."""
        self._lines = LineAssembler(self.stats, max_line, split_cr=True, skip_blank=True)
        self._order = TimeOrder(self.stats)
        self._pending_sa: Attitude | None = None

    def feed(self, data: bytes, t_rx: float) -> list[Sample]:
        """Consume bytes received at ``t_rx`` (s); return the complete samples."""
        out: list[Sample] = []
        for line in self._lines.push(data):
            out.extend(self.feed_line(line, t_rx))
        return out

    def feed_line(self, line: bytes | str, t_rx: float | None = None) -> list[Sample]:
        """Parse one line; garbage before the ``:`` is counted as ``"garbage"``."""
        if isinstance(line, bytes):
            line = line.decode("ascii", "replace")
        line = line.strip()
        if not line:
            return []
        st = self.stats
        st.records += 1
        i = line.find(":")
        if i < 0:
            st.reject("garbage")
            return []
        if i > 0:
            st.reject("garbage")
            st.records += 1
            line = line[i:]
        parts = line[1:].split(",")
        kind = parts[0].strip()
        if len(kind) != 2 or not kind.isalpha():
            st.reject("malformed")
            return []
        st.by_type[kind] += 1
        try:
            samples = self._parse(kind, [p.strip() for p in parts[1:]], t_rx)
        except Pd6Error as err:
            if err.reason == "ignored":
                st.by_type["ignored"] += 1
            else:
                st.reject(err.reason)
            return []
        out = [s for s in samples if self.time_base == "rx" or self._order.keep(s.t)]
        st.samples += len(out)
        return out

    def _time(self, t_rx: float | None) -> float:
        t = t_rx if self.time_base == "rx" else self.instrument_time
        if t is None:
            raise Pd6Error("untimed")
        return t

    def _parse(self, kind: str, f: list[str], t_rx: float | None) -> list[Sample]:
        src = self.source
        if kind == "TS":
            if len(f) < 5:
                raise Pd6Error("malformed")
            t_inst = parse_ts_time(f[0])
            temp, depth = _dec(f[2]), _dec(f[3])
            self.instrument_time = t_inst
            t = self._time(t_rx)
            out: list[Sample] = [Depth(t=t, source=src, depth_m=depth, temperature_c=temp)]
            if self._pending_sa is not None:  # SA precedes TS in an ensemble
                out.insert(0, msgspec.structs.replace(self._pending_sa, t=t))
                self._pending_sa = None
            return out
        if kind == "SA":
            if len(f) < 3:
                raise Pd6Error("malformed")
            pitch, roll, hdg = _dec(f[0]), _dec(f[1]), _dec(f[2])
            att = Attitude(t=t_rx or 0.0, source=src, roll_rad=math.radians(roll),
                           pitch_rad=math.radians(pitch),
                           yaw_rad=wrap_2pi(math.radians(hdg)))
            if self.time_base == "instrument":
                self._pending_sa = att  # stamped by the TS line that follows
                return []
            return [msgspec.structs.replace(att, t=self._time(t_rx))]
        if kind in ("BI", "WI"):
            if len(f) < 5:
                raise Pd6Error("malformed")
            x, y, z, e = (_vel(v) for v in f[:4])
            ok = _status(f[4])
            if self.velocity_frame != "instrument":
                raise Pd6Error("ignored")
            t = self._time(t_rx)
            valid = ok and MISSING not in (x, y, z)
            fom = abs(e) / 1000.0 if valid and e != MISSING else None
            return [self._dvl(t, kind, valid, x / 1000.0, -y / 1000.0, -z / 1000.0, fom)]
        if kind in ("BS", "WS"):
            if len(f) < 4:
                raise Pd6Error("malformed")
            tr, lo, no = (_vel(v) for v in f[:3])
            ok = _status(f[3])
            if self.velocity_frame != "ship":
                raise Pd6Error("ignored")
            t = self._time(t_rx)
            valid = ok and MISSING not in (tr, lo, no)
            return [self._dvl(t, kind, valid, lo / 1000.0, tr / 1000.0, -no / 1000.0, None)]
        if kind == "BE":
            if len(f) < 4:
                raise Pd6Error("malformed")
            ea, no, up = (_vel(v) for v in f[:3])
            ok = _status(f[3])
            t = self._time(t_rx)
            if not ok or MISSING in (ea, no, up):
                raise Pd6Error("invalid")
            return [VelocityOverGround(t=t, source=src, v_north_mps=no / 1000.0,
                                       v_east_mps=ea / 1000.0, v_down_mps=-up / 1000.0)]
        if kind == "BD":
            if len(f) < 5:
                raise Pd6Error("malformed")
            for v in f[:3]:
                _dec(v)
            rng = _dec(f[3])
            t = self._time(t_rx)
            if rng <= 0.0:
                raise Pd6Error("invalid")
            return [Altitude(t=t, source=src, altitude_m=rng)]
        if kind in ("WE", "WD", "RA"):
            raise Pd6Error("ignored")
        raise Pd6Error("unsupported")

    def _dvl(self, t: float, kind: str, valid: bool, vx: float, vy: float, vz: float,
             fom: float | None) -> DvlVelocity:
        if not valid:
            vx = vy = vz = 0.0
        return DvlVelocity(t=t, source=self.source, vx=vx, vy=vy, vz=vz,
                           track="bottom" if kind[0] == "B" else "water", valid=valid,
                           fom_mps=fom)


class Pd6LogReader:
    """A text capture of PD6 output, timed by its TS lines (``time_base="instrument"``)."""

    def __init__(self, path: str | Path, source: str = "pd6",
                 velocity_frame: Literal["ship", "instrument"] = "ship") -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise UnreadableLog(f"{self.path}: no such file")
        self._parser = Pd6Parser(source=source, time_base="instrument",
                                 velocity_frame=velocity_frame)
        self.stats = self._parser.stats

    def __iter__(self) -> Iterator[Sample]:
        with open(self.path, "rb") as fh:
            for line in counted_lines(self.stats, fh):
                if len(line) > self._parser.max_line:
                    self.stats.records += 1
                    self.stats.reject("too_long")
                    continue
                yield from self._parser.feed_line(line)


# ---------------------------------------------------------------------------- encoders


def _mm(v: float | None) -> str:
    if v is None or not math.isfinite(v):
        return f"{MISSING:+06d}"
    return f"{max(-32767, min(32767, int(round(v * 1000.0)))):+06d}"


def _line(body: str) -> bytes:
    return f":{body}\r\n".encode("ascii")


def encode_ts(t_utc: float, depth_m: float, temperature_c: float = 10.0,
              salinity_ppt: float = 35.0, sound_speed_mps: float = 1500.0) -> bytes:
    """A TS line: time (POSIX s, UTC), salinity, temperature, depth, speed of sound."""
    cs = int(round((t_utc % 1.0) * 100.0)) % 100
    stamp = _t.strftime("%y%m%d%H%M%S", _t.gmtime(math.floor(t_utc))) + f"{cs:02d}"
    return _line(f"TS,{stamp},{salinity_ppt:4.1f},{temperature_c:+05.1f},{depth_m:6.1f},"
                 f"{sound_speed_mps:6.1f},000")


def encode_sa(roll_rad: float, pitch_rad: float, heading_rad: float) -> bytes:
    """An SA line: pitch, roll, heading (rad, sent in degrees)."""
    return _line(f"SA,{math.degrees(pitch_rad):+06.2f},{math.degrees(roll_rad):+06.2f},"
                 f"{math.degrees(heading_rad) % 360.0:06.2f}")


def encode_bi(vx: float, vy: float, vz: float, error_mps: float = 0.0, valid: bool = True,
              water: bool = False) -> bytes:
    """A BI (or WI) line from an FRD-like instrument velocity (m/s); see the parser's
    frame mapping (sent as X = vx, Y = -vy, Z = -vz, mm/s)."""
    if not valid:
        vals = [None, None, None, None]
    else:
        vals = [vx, -vy, -vz, error_mps]
    return _line(f"{'WI' if water else 'BI'},{','.join(_mm(v) for v in vals)},"
                 f"{'A' if valid else 'V'}")


def encode_bs(forward_mps: float, right_mps: float, down_mps: float, valid: bool = True,
              water: bool = False) -> bytes:
    """A BS (or WS) line from a ship-frame FRD velocity (m/s)."""
    vals = [right_mps, forward_mps, -down_mps] if valid else [None, None, None]
    return _line(f"{'WS' if water else 'BS'},{','.join(_mm(v) for v in vals)},"
                 f"{'A' if valid else 'V'}")


def encode_be(v_north_mps: float, v_east_mps: float, v_down_mps: float,
              valid: bool = True) -> bytes:
    """A BE line from an earth-frame NED velocity (m/s)."""
    vals = [v_east_mps, v_north_mps, -v_down_mps] if valid else [None, None, None]
    return _line(f"BE,{','.join(_mm(v) for v in vals)},{'A' if valid else 'V'}")


def encode_bd(altitude_m: float, east_m: float = 0.0, north_m: float = 0.0, up_m: float = 0.0,
              since_good_s: float = 0.0) -> bytes:
    """A BD line: distance made good (m) and range to the bottom (m)."""
    return _line(f"BD,{east_m:+012.2f},{north_m:+012.2f},{up_m:+012.2f},{altitude_m:07.2f},"
                 f"{since_good_s:06.2f}")


def encode_ensemble(
    t_utc: float,
    forward_mps: float,
    right_mps: float,
    down_mps: float,
    *,
    valid: bool = True,
    depth_m: float = 0.0,
    altitude_m: float = 5.0,
    roll_rad: float = 0.0,
    pitch_rad: float = 0.0,
    heading_rad: float = 0.0,
    temperature_c: float = 10.0,
) -> bytes:
    """A whole ensemble (SA, TS, BI, BS, BE, BD) for a bottom-locked (or not) DVL.

    The earth-frame BE is the ship velocity rotated by heading only (level vehicle).
    """
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    vn, ve = c * forward_mps - s * right_mps, s * forward_mps + c * right_mps
    return b"".join([
        encode_sa(roll_rad, pitch_rad, heading_rad),
        encode_ts(t_utc, depth_m, temperature_c),
        encode_bi(forward_mps, right_mps, down_mps, valid=valid),
        encode_bs(forward_mps, right_mps, down_mps, valid=valid),
        encode_be(vn, ve, down_mps, valid=valid),
        encode_bd(altitude_m if valid else 0.0),
    ])
