"""Water Linked DVL A50/A125 JSON protocol (TCP port 16171): velocity and dead reckoning.

One JSON object per line. Two generations of the protocol are read:

* ``"format": "json_v1"`` (firmware 2.0 and earlier): velocity reports only, with
  ``time`` = milliseconds since the previous report, ``vx, vy, vz`` (m/s, DVL frame),
  ``fom`` (m/s), ``altitude`` (m, -1 when unknown), ``transducers[4]``,
  ``velocity_valid``, ``status``;
* current firmware (``json_v2``/``json_v3.x``): ``"type": "velocity"`` adds
  ``covariance`` (3x3, m^2/s^2), ``time_of_validity`` and ``time_of_transmission``
  (microseconds, Unix epoch); ``"type": "position_local"`` is the DVL's dead reckoning
  ``ts`` (Unix s), ``x, y, z`` (m, NED from the reset point), ``std`` (m),
  ``roll, pitch, yaw`` (deg).

Water track (assumption, documented): Water Linked documents bottom-track velocity only
for the A50. A report whose ``type`` is ``"velocity_water"`` (or any ``velocity*`` type
containing ``"water"``), or which carries ``"track": "water"``, is read exactly like a
velocity report but with ``track="water"``.

Samples: a velocity report gives :class:`~onboard.core.messages.DvlVelocity` in the DVL
instrument frame (x forward along the LED, y right, z down; the mounting rotation is
configuration, applied by the engine). ``valid`` is ``velocity_valid``: on lock loss the
DVL sends zeros with ``velocity_valid: false``, which stays ``valid=False`` -- never a
valid zero velocity. ``altitude <= 0`` (the -1 "unknown") becomes ``None``.
``position_local`` gives :class:`~onboard.core.messages.DvlPosition` (angles in rad).

Time: live (``feed(data, t_rx)``), a report with its own time (``time_of_validity``, or
``ts``) is stamped with it, mapped to the receiver's clock through the least-delayed report
(:class:`~onboard.drivers.sender_clock.SenderClock` on ``time_of_transmission``, the
processing delay ``time_of_transmission - time_of_validity`` taken off when within
[0, 1] s): the DVL's clock need not be synchronized with ours, and a report that waited in
a socket buffer is stamped when it was measured, not when it was read. A json_v1 report
is stamped with its receive time. Captures without receive times (``nc host 16171 >
out.txt``) are read with :class:`DvlJsonLogReader`: ``t = time_of_validity`` (or ``ts``)
in Unix seconds when present; for json_v1, ``t`` is the running sum of ``time`` (s since
the first report).

Rejections: ``"json"`` (not JSON, or not an object), ``"malformed"`` (missing or wrongly
typed field, non-finite number), ``"duplicate"`` (a line identical to the previous one --
the tank captures repeat readings), ``"too_long"`` (a line over ``max_line`` bytes), ``"time_backwards"`` (reader: a report
older than the last one by up to ``drivers.base.TIME_JUMP_S``; further back it is passed on
for the engine's time line, a clock reset or an outlier).
Well-formed reports of other types (command responses) are counted in ``stats.by_type``
(by type and under ``"ignored"``), not rejected.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Iterator

import msgspec

from onboard.drivers.base import (LineAssembler, ReadStats, TimeOrder, UnreadableLog,
                                  counted_lines)
from onboard.drivers.sender_clock import SenderClock
from onboard.core.messages import DvlPosition, DvlVelocity, Sample

MAX_LINE = 16384
"""Longest accepted line (bytes); a velocity report with covariance is ~1.5 kB."""
BEAM_TILT_RAD = math.radians(22.5)
"""A50 transducer tilt from the z axis, used by the encoder to fill ``transducers``."""

_decoder = msgspec.json.Decoder()


class DvlJsonError(ValueError):
    """A report that cannot be used; ``reason`` is the ReadStats rejection key."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def _num(obj: dict, key: str, required: bool = True) -> float | None:
    v = obj.get(key)
    if v is None:
        if required:
            raise DvlJsonError("malformed")
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise DvlJsonError("malformed")
    return float(v)


def report_kind(obj: dict) -> str:
    """``"velocity"``, ``"velocity_water"``, ``"position_local"`` or the unknown type."""
    typ = obj.get("type")
    if typ is None:
        if obj.get("format") == "json_v1" or ("vx" in obj and "velocity_valid" in obj):
            typ = "velocity"
        else:
            return "unknown"
    if not isinstance(typ, str):
        return "unknown"
    if typ.startswith("velocity") and ("water" in typ or obj.get("track") == "water"):
        return "velocity_water"
    return typ


def decode_report(obj: Any, t: float, source: str = "dvl") -> Sample:
    """One decoded JSON report to a sample stamped ``t``; raises DvlJsonError."""
    if not isinstance(obj, dict):
        raise DvlJsonError("json")
    kind = report_kind(obj)
    if kind in ("velocity", "velocity_water"):
        vx, vy, vz = _num(obj, "vx"), _num(obj, "vy"), _num(obj, "vz")
        valid = obj.get("velocity_valid")
        if not isinstance(valid, bool):
            raise DvlJsonError("malformed")
        fom = _num(obj, "fom", required=False)
        alt = _num(obj, "altitude", required=False)
        cov = obj.get("covariance")
        cov_t: tuple[float, ...] | None = None
        if cov is not None:
            try:
                flat = [float(x) for row in cov for x in row]
            except (TypeError, ValueError):
                raise DvlJsonError("malformed") from None
            if len(flat) != 9 or not all(math.isfinite(x) for x in flat):
                raise DvlJsonError("malformed")
            cov_t = tuple(flat)
        return DvlVelocity(
            t=t, source=source, vx=vx, vy=vy, vz=vz,  # type: ignore[arg-type]
            track="water" if kind == "velocity_water" else "bottom",
            valid=valid, fom_mps=fom, covariance=cov_t,
            altitude_m=alt if alt is not None and alt > 0.0 else None,
        )
    if kind == "position_local":
        def rad(key: str) -> float | None:
            v = _num(obj, key, required=False)
            return None if v is None else math.radians(v)

        return DvlPosition(
            t=t, source=source, north_m=_num(obj, "x"), east_m=_num(obj, "y"),  # type: ignore[arg-type]
            down_m=_num(obj, "z"), roll_rad=rad("roll"), pitch_rad=rad("pitch"),  # type: ignore[arg-type]
            yaw_rad=rad("yaw"), std_m=_num(obj, "std", required=False),
        )
    raise DvlJsonError("unsupported")


def report_time(obj: dict) -> float | None:
    """The report's own absolute time (Unix s): ``time_of_validity`` or ``ts``."""
    tov = obj.get("time_of_validity")
    if isinstance(tov, (int, float)) and not isinstance(tov, bool) and math.isfinite(tov) and tov > 0:
        return tov * 1e-6
    ts = obj.get("ts")
    if isinstance(ts, (int, float)) and not isinstance(ts, bool) and math.isfinite(ts) and ts > 0:
        return float(ts)
    return None


def processing_delay(obj: dict) -> float:
    """``time_of_transmission - time_of_validity`` in s, when present and in [0, 1]."""
    tov, tot = obj.get("time_of_validity"), obj.get("time_of_transmission")
    if isinstance(tov, (int, float)) and isinstance(tot, (int, float)):
        d = (tot - tov) * 1e-6
        if 0.0 <= d <= 1.0:
            return d
    return 0.0


class DvlJsonParser:
    """Incremental parser for the DVL's TCP byte stream (``feed(data, t_rx)``).

    Lines are assembled across chunks; blank lines are skipped; a line longer than
    ``max_line`` is dropped as ``"too_long"``.
    """

    def __init__(self, source: str = "dvl", max_line: int = MAX_LINE) -> None:
        self.source = source
        self.max_line = max_line
        self.stats = ReadStats()
        self._lines = LineAssembler(self.stats, max_line, split_cr=False, skip_blank=False)
        self._last_line: bytes | None = None
        self.clock = SenderClock()
        """The DVL's clock mapped to the receiver's (live stamps)."""

    def feed(self, data: bytes, t_rx: float) -> list[Sample]:
        """Consume bytes received at ``t_rx`` (s); return the complete samples."""
        out: list[Sample] = []
        for line in self._lines.push(data):
            s = self.feed_line(line, t_rx)
            if s is not None:
                out.append(s)
        return out

    def feed_line(self, line: bytes | str, t_rx: float) -> Sample | None:
        """Parse one line received at ``t_rx``; None when it is rejected or blank."""
        obj = self.decode_line(line)
        if obj is None:
            return None
        return self.to_sample(obj, self.stamp(obj, t_rx) if isinstance(obj, dict) else t_rx)

    def stamp(self, obj: dict, t_rx: float) -> float:
        """The receiver-clock time (s) at which report ``obj``, received at ``t_rx``, was
        valid: its own time mapped through :attr:`clock`, else ``t_rx``."""
        t_own = report_time(obj)
        if t_own is None:
            return t_rx
        delay = processing_delay(obj)
        return self.clock.update(t_own + delay, t_rx) - delay

    def decode_line(self, line: bytes | str) -> Any:
        """JSON-decode one line, counting the record; None when blank/rejected/duplicate."""
        if isinstance(line, str):
            line = line.encode("utf-8", "replace")
        line = line.strip()
        if not line:
            return None
        st = self.stats
        st.records += 1
        if line == self._last_line:
            st.reject("duplicate")
            return None
        self._last_line = line
        try:
            obj = _decoder.decode(line)
        except (msgspec.DecodeError, UnicodeDecodeError):
            st.reject("json")
            return None
        if not isinstance(obj, dict):
            st.reject("json")
            return None
        return obj

    def to_sample(self, obj: dict, t: float) -> Sample | None:
        """A decoded report to a sample stamped ``t``, counting type and rejections."""
        st = self.stats
        st.by_type[report_kind(obj)] += 1
        try:
            s = decode_report(obj, t, self.source)
        except DvlJsonError as err:
            if err.reason == "unsupported":
                st.by_type["ignored"] += 1
            else:
                st.reject(err.reason)
            return None
        st.samples += 1
        return s


class DvlJsonLogReader:
    """A text capture of the DVL's JSON stream (one report per line), in time order.

    Timing without receive times: see the module docstring. ``path`` may hold json_v1
    and newer reports; blank lines are ignored.
    """

    def __init__(self, path: str | Path, source: str = "dvl") -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise UnreadableLog(f"{self.path}: no such file")
        self.source = source
        self._parser = DvlJsonParser(source=source)
        self.stats = self._parser.stats

    def __iter__(self) -> Iterator[Sample]:
        p = self._parser
        t_rel = 0.0
        first_rel = True
        order = TimeOrder(p.stats)
        with open(self.path, "rb") as fh:
            for line in counted_lines(p.stats, fh):
                if len(line) > p.max_line:
                    p.stats.records += 1
                    p.stats.reject("too_long")
                    continue
                obj = p.decode_line(line)
                if obj is None:
                    continue
                t = report_time(obj)
                if t is None:
                    dt = obj.get("time")
                    if not first_rel and isinstance(dt, (int, float)) and not isinstance(dt, bool) \
                            and math.isfinite(dt) and dt > 0:
                        t_rel += dt * 1e-3
                    first_rel = False
                    t = t_rel
                if order.behind(t):
                    p.stats.reject("time_backwards")
                    continue
                s = p.to_sample(obj, t)
                if s is not None:
                    order.newest = t
                    yield s


# ---------------------------------------------------------------------------- encoders


def _line(obj: dict) -> bytes:
    return msgspec.json.encode(obj) + b"\n"


def encode_velocity_report(
    vx: float,
    vy: float,
    vz: float,
    *,
    valid: bool = True,
    fom_mps: float = 0.002,
    altitude_m: float = 5.0,
    dt_ms: float = 66.7,
    t_validity_s: float | None = None,
    t_transmission_s: float | None = None,
    covariance: tuple[float, ...] | None = None,
    status: int = 0,
    track: str = "bottom",
    fmt: str = "json_v3.1",
) -> bytes:
    """One velocity report line as the DVL sends it (m/s, m, Unix s).

    ``fmt="json_v1"`` produces the old report (no type, covariance or absolute times).
    On lock loss pass ``valid=False``: velocities are sent as zeros and altitude as -1,
    as the real DVL does. ``track="water"`` sends ``"type": "velocity_water"`` (see the
    module docstring's assumption).
    """
    if not valid:
        vx = vy = vz = 0.0
        altitude_m = -1.0
    beams = []
    for i, az in enumerate((45.0, -45.0, -135.0, 135.0)):
        a = math.radians(az)
        bx = math.sin(BEAM_TILT_RAD) * math.cos(a)
        by = math.sin(BEAM_TILT_RAD) * math.sin(a)
        bz = math.cos(BEAM_TILT_RAD)
        beams.append({
            "id": i,
            "velocity": bx * vx + by * vy + bz * vz if valid else 0.0,
            "distance": altitude_m / bz if valid else -1.0,
            "rssi": -40.0 if valid else -90.0,
            "nsd": -90.0,
            "beam_valid": valid,
        })
    obj: dict[str, Any] = {"time": dt_ms, "vx": vx, "vy": vy, "vz": vz, "fom": fom_mps}
    if fmt != "json_v1":
        cov = covariance if covariance is not None else (fom_mps**2, 0, 0, 0, fom_mps**2, 0, 0, 0, fom_mps**2)
        obj["covariance"] = [list(cov[0:3]), list(cov[3:6]), list(cov[6:9])]
    obj.update({"altitude": altitude_m, "transducers": beams, "velocity_valid": valid,
                "status": status})
    if fmt != "json_v1":
        tov = t_validity_s if t_validity_s is not None else 0.0
        tot = t_transmission_s if t_transmission_s is not None else tov
        obj["time_of_validity"] = int(round(tov * 1e6))
        obj["time_of_transmission"] = int(round(tot * 1e6))
        obj["type"] = "velocity_water" if track == "water" else "velocity"
    obj["format"] = fmt
    return _line(obj)


def encode_position_local(
    north_m: float,
    east_m: float,
    down_m: float,
    *,
    t_s: float,
    std_m: float = 0.1,
    roll_rad: float = 0.0,
    pitch_rad: float = 0.0,
    yaw_rad: float = 0.0,
    status: int = 0,
    fmt: str = "json_v3.1",
) -> bytes:
    """One ``position_local`` (dead-reckoning) line: metres NED, angles rad (sent in
    degrees), ``t_s`` Unix seconds."""
    return _line({
        "ts": t_s, "x": north_m, "y": east_m, "z": down_m, "std": std_m,
        "roll": math.degrees(roll_rad), "pitch": math.degrees(pitch_rad),
        "yaw": math.degrees(yaw_rad), "type": "position_local", "status": status,
        "format": fmt,
    })
