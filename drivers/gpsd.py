"""gpsd's JSON protocol (gpsd_json(5)): TPV, ATT and SKY reports to typed samples.

A client connects to gpsd (TCP, port 2947 by default), sends
``?WATCH={"enable":true,"json":true}`` (:data:`WATCH`; the gpsd transport in
:mod:`drivers.transports` does it on every connection) and receives one JSON object per
line, each with a ``"class"``:

=======  ====================================================================
class    what is read
=======  ====================================================================
TPV      ``mode`` (0 unknown, 1 no fix, 2 2-D, 3 3-D), ``status`` (2 DGPS, 3 RTK
         fixed, 4 RTK float), ``time`` (ISO 8601 UTC), ``lat``/``lon`` (deg),
         ``altHAE`` (or the older ``alt``, m), ``speed`` (m/s), ``track`` (deg true),
         ``climb`` (m/s), the error estimates ``epx``/``epy``/``eph``/``epv`` (m),
         ``eps`` (m/s), ``ept`` (s) -> :class:`GnssFix`
ATT      ``heading`` (deg true), ``pitch``, ``roll`` (deg) -> :class:`Heading`, plus
         :class:`Attitude` when pitch and roll are given
SKY      ``hdop``, ``uSat`` or the satellites with ``"used": true`` -> kept and put
         into the following fixes (``hdop``, ``num_sats``)
others   (VERSION, DEVICES, WATCH, DEVICE, GST, PPS, TOFF, ...) counted by class, ignored
=======  ====================================================================

gpsd gives its error estimates at 95 % confidence (gpsd_json(5)). The fix's one-sigma
accuracies are ``h_acc_m = max(epx, epy) / 1.96`` (per axis), else ``eph / 2.45`` (a
2-D radius: 2.45 sigma holds 95 % of a circular normal), and ``v_acc_m = epv / 1.96``;
``speed_acc_mps = eps / 1.96``; the pipelines take them as the fix's noise
(``[sensors.gnss]`` where a fix has none). ``t_acc_s`` (``ept / 1.96``) and the others are
reported in :attr:`GpsdParser.last_errors` for health.

Rejected and counted: a line that is not JSON (``json``), a TPV with ``mode`` below 2
(``no_fix``: gpsd reports no position), a TPV without ``lat``/``lon`` or with a number out
of range (``malformed``), a TPV repeating the previous one's ``time`` (``duplicate``:
gpsd may report one epoch twice), an ``ERROR`` object (``gpsd_error``).

Samples are stamped with the receive time, as every live input (docs/service.md).
"""

from __future__ import annotations

import math
from typing import Any

import msgspec

from onboard.drivers.base import LineAssembler, ReadStats
from onboard.core.geo import wrap_2pi, wrap_pi
from onboard.core.messages import Attitude, GnssFix, Heading, Sample

WATCH = b'?WATCH={"enable":true,"json":true}\n'
"""The request that makes gpsd stream JSON reports (gpsd_json(5), WATCH)."""
DEFAULT_PORT = 2947
"""gpsd's TCP port (IANA)."""

SIGMA_95_1D = 1.96
"""A one-dimensional 95 % bound over its sigma."""
SIGMA_95_2D = 2.4477
"""A circular 95 % radius over the per-axis sigma: sqrt(-2 ln 0.05)."""
_STATUS_QUALITY = {2: 2, 3: 4, 4: 5}
"""TPV ``status`` -> GGA fix quality (DGPS, RTK fixed, RTK float); others GPS (1)."""
MAX_LINE = 8192
"""Longest line kept (bytes); gpsd's SKY with many satellites is a few kB."""

_decoder = msgspec.json.Decoder()


def _num(obj: dict[str, Any], key: str) -> float | None:
    """``obj[key]`` as a finite float, else None (absent, null, text, bool, NaN)."""
    v = obj.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    v = float(v)
    return v if math.isfinite(v) else None


class GpsdParser:
    """Stream parser of gpsd's JSON reports (module docstring); never raises.

    Attributes:
        stats: records, samples, rejections by reason, records by class.
        hdop, num_sats: the newest SKY's values, put into the following fixes.
        last_errors: the newest TPV's one-sigma errors (``h``, ``v`` m, ``speed`` m/s,
            ``time`` s) where gpsd gave them.
    """

    def __init__(self, source: str = "gpsd") -> None:
        self.source = source
        self.stats = ReadStats()
        self._lines = LineAssembler(self.stats, MAX_LINE)
        self.hdop: float | None = None
        self.num_sats: int | None = None
        self.last_errors: dict[str, float] = {}
        self._last_time: str | None = None

    def feed(self, data: bytes, t_rx: float) -> list[Sample]:
        """The samples of the complete lines in ``data`` received at ``t_rx`` (s)."""
        out: list[Sample] = []
        for line in self._lines.push(data):
            out.extend(self.line(line, t_rx))
        return out

    def line(self, line: bytes, t: float) -> list[Sample]:
        """The samples of one JSON line, stamped ``t`` (s)."""
        st = self.stats
        st.records += 1
        try:
            obj = _decoder.decode(line)
        except (msgspec.DecodeError, UnicodeDecodeError):
            st.reject("json")
            return []
        if not isinstance(obj, dict) or not isinstance(obj.get("class"), str):
            st.reject("json")
            return []
        cls = obj["class"]
        st.by_type[cls] += 1
        if cls == "TPV":
            out = self._tpv(obj, t)
        elif cls == "ATT":
            out = self._att(obj, t)
        elif cls == "SKY":
            self._sky(obj)
            out = []
        elif cls == "ERROR":
            st.reject("gpsd_error")
            out = []
        else:
            out = []
        st.samples += len(out)
        return out

    def _tpv(self, o: dict[str, Any], t: float) -> list[Sample]:
        st = self.stats
        mode = o.get("mode")
        if not isinstance(mode, int) or mode < 2:
            st.reject("no_fix")
            return []
        lat, lon = _num(o, "lat"), _num(o, "lon")
        if lat is None or lon is None or not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            st.reject("malformed")
            return []
        stamp = o.get("time")
        if isinstance(stamp, str) and stamp == self._last_time:
            st.reject("duplicate")
            return []
        self._last_time = stamp if isinstance(stamp, str) else None
        alt = _num(o, "altHAE")
        if alt is None:
            alt = _num(o, "alt")
        epx, epy, eph, epv = _num(o, "epx"), _num(o, "epy"), _num(o, "eph"), _num(o, "epv")
        h_acc = None
        if epx is not None and epy is not None:
            h_acc = max(epx, epy) / SIGMA_95_1D
        elif eph is not None:
            h_acc = eph / SIGMA_95_2D
        v_acc = epv / SIGMA_95_1D if epv is not None and mode >= 3 else None
        errors = {"h": h_acc, "v": v_acc}
        for key, name in (("eps", "speed"), ("ept", "time")):
            e = _num(o, key)
            errors[name] = e / SIGMA_95_1D if e is not None else None
        self.last_errors = {k: v for k, v in errors.items() if v is not None}
        s_acc = errors["speed"]
        speed, track = _num(o, "speed"), _num(o, "track")
        status = o.get("status")
        quality = _STATUS_QUALITY.get(status, 1) if isinstance(status, int) else 1
        return [GnssFix(
            t=t, source=self.source, lat_deg=lat, lon_deg=lon,
            alt_m=alt if mode >= 3 else None, fix_quality=quality,
            num_sats=self.num_sats, hdop=self.hdop,
            sog_mps=speed, cog_rad=wrap_2pi(math.radians(track)) if track is not None else None,
            h_acc_m=h_acc if h_acc is not None and h_acc > 0.0 else None,
            v_acc_m=v_acc if v_acc is not None and v_acc > 0.0 else None,
            speed_acc_mps=s_acc if s_acc is not None and s_acc > 0.0 else None,
        )]

    def _att(self, o: dict[str, Any], t: float) -> list[Sample]:
        heading = _num(o, "heading")
        if heading is None:
            self.stats.reject("no_heading")
            return []
        psi = wrap_2pi(math.radians(heading))
        out: list[Sample] = [Heading(t=t, source=self.source, heading_rad=psi)]
        pitch, roll = _num(o, "pitch"), _num(o, "roll")
        if pitch is not None and roll is not None:
            out.append(Attitude(t=t, source=self.source, roll_rad=wrap_pi(math.radians(roll)),
                                pitch_rad=wrap_pi(math.radians(pitch)), yaw_rad=wrap_pi(psi)))
        return out

    def _sky(self, o: dict[str, Any]) -> None:
        hdop = _num(o, "hdop")
        if hdop is not None and hdop > 0.0:
            self.hdop = hdop
        used = o.get("uSat")
        if isinstance(used, int) and not isinstance(used, bool):
            self.num_sats = used
            return
        sats = o.get("satellites")
        if isinstance(sats, list):
            self.num_sats = sum(1 for s in sats if isinstance(s, dict) and s.get("used") is True)
