"""MAVLink v1/v2 frames -> typed samples: a fast, selective decoder.

Only the messages the estimators need are decoded (table :data:`HANDLERS`); every other
frame is framed by its length byte, CRC-checked when its id is in the dialect (about
0.6 us, :func:`drivers.mavlink_frame.x25crc`) and skipped. The frame layout is
:mod:`drivers.mavlink_frame`'s. Field layouts and ``CRC_EXTRA`` bytes come from pymavlink's
``ardupilotmega`` dialect at import time, so they always match the installed pymavlink.
Payloads are decoded with one precompiled :class:`struct.Struct` per message id; v2
zero-truncated payloads are padded with zeros to the full length.

Mapping (units and frames in ``docs/formats-mavlink.md``)
---------------------------------------------------------
GPS_RAW_INT, GPS2_RAW -> GnssFix; GLOBAL_POSITION_INT -> VelocityOverGround (with its
``hdg`` as ``heading_rad``) + Heading;
ATTITUDE -> Attitude; SCALED_IMU/2/3, RAW_IMU (ArduPilot only), HIGHRES_IMU -> Imu;
VFR_HUD -> Heading; SERVO_OUTPUT_RAW -> ActuatorOutputs; RC_CHANNELS -> RcChannels;
RPM -> PropellerRpm; VISION_SPEED_ESTIMATE -> VelocityOverGround;
VISION_POSITION_DELTA -> DvlVelocity; DISTANCE_SENSOR (downward) -> Altitude;
SCALED_PRESSURE/2/3 -> Pressure; HEARTBEAT -> VehicleInfo; PARAM_VALUE -> Parameter.

``Sample.source`` is ``"mavlink:<sysid>/<MSGNAME>"`` for the autopilot component
(component id 1) and ``"mavlink:<sysid>.<compid>/<MSGNAME>"`` for any other component, so
two IMUs (SCALED_IMU vs SCALED_IMU2) or two barometers never mix.
"""

from __future__ import annotations

import math
import re
import struct
from collections import Counter
from typing import TYPE_CHECKING, Callable, Iterable

import msgspec
from pymavlink.dialects.v20 import ardupilotmega as _dialect

from onboard.drivers.base import ReadStats
from onboard.drivers.mavlink_frame import (
    CRC_EXTRA,
    CRC_LEN,
    HEADER_LEN_V2,
    IFLAG_SIGNED,
    MAGIC_V1,
    MAGIC_V2,
    START_BYTES,
    crc_matches,
    header_at,
)
from onboard.core.geo import wrap_2pi
from onboard.core.messages import (
    ActuatorOutputs,
    Altitude,
    Attitude,
    DvlVelocity,
    GnssFix,
    Heading,
    Imu,
    Parameter,
    Pressure,
    PropellerRpm,
    RcChannels,
    Sample,
    VehicleInfo,
    VelocityOverGround,
)

if TYPE_CHECKING:
    from onboard.drivers.mavlink_link import AutopilotLink
    from onboard.drivers.mavlink_signing import FrameVerifier

GRAVITY_MSS = 9.80665
"""Standard gravity (m/s^2); ArduPilot scales mg with this constant (``GRAVITY_MSS``)."""
UINT16_MAX = 0xFFFF
_BIG = 1e30
"""Finite-value guard: ``abs(x) < _BIG`` is False for NaN and +-inf."""
MAV_TYPE_GCS = 6
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_INVALID = 8
MAV_AUTOPILOT_PX4 = 12
MAV_SENSOR_ROTATION_PITCH_270 = 25
"""DISTANCE_SENSOR orientation of a downward-looking range finder."""

GPS_FIX_TO_QUALITY: dict[int, int] = {2: 1, 3: 1, 4: 2, 5: 5, 6: 4, 7: 1, 8: 2}
"""MAVLink ``GPS_FIX_TYPE`` -> NMEA GGA fix quality (see :class:`GnssFix`).

2D and 3D fix -> 1, DGPS -> 2, RTK float -> 5, RTK fixed -> 4, STATIC -> 1, PPP -> 2.
NO_GPS (0) and NO_FIX (1) have no position: the frame is skipped and counted as the
rejection ``"no_fix"``."""

def _valid_frame_inside(buf: bytes | bytearray, start: int, stop: int) -> bool | None:
    """True if a complete, CRC-valid frame of a known id starts in ``buf[start:stop]``:
    then the unknown-id "frame" spanning it is line noise, not a frame. None when that
    cannot be told yet: a start byte there whose header or frame has not fully arrived
    (the caller waits for more bytes, so the answer does not depend on how the stream
    was cut into chunks)."""
    n = len(buf)
    undecided = False
    for k in range(start, stop):
        b = buf[k]
        if b != MAGIC_V2 and b != MAGIC_V1:
            continue
        h = header_at(buf, k, n)
        if h is None:
            undecided = True
            continue
        hdr, plen, _, _, _, msgid, _ = h
        extra = CRC_EXTRA.get(msgid)
        if extra is None:
            continue
        if k + hdr + plen + CRC_LEN > n:
            undecided = True
            continue
        if crc_matches(buf, k, hdr, plen, extra):
            return True
    return None if undecided else False


# --------------------------------------------------------------------------- dialect tables

MSG_NAMES: dict[int, str] = {mid: cls.msgname for mid, cls in _dialect.mavlink_map.items()}
"""Message name per id."""

_TOKEN = re.compile(r"(\d*)([a-zA-Z?])")


def _layout(name: str) -> tuple[int, struct.Struct, dict[str, int]]:
    """(msgid, wire Struct, field name -> index of its first element in the unpacked tuple).

    The wire order is pymavlink's ``ordered_fieldnames``; a ``char[n]`` array unpacks to one
    bytes element, any other array ``T[n]`` to ``n`` elements.
    """
    cls = getattr(_dialect, f"MAVLink_{name.lower()}_message")
    st: struct.Struct = cls.unpacker
    tokens = _TOKEN.findall(st.format.lstrip("<"))
    if len(tokens) != len(cls.ordered_fieldnames):
        raise RuntimeError(f"unexpected pymavlink layout for {name}: {st.format}")
    idx: dict[str, int] = {}
    k = 0
    for (count, code), fname in zip(tokens, cls.ordered_fieldnames):
        idx[fname] = k
        k += 1 if (code == "s" or not count) else int(count)
    return cls.id, st, idx


# --------------------------------------------------------------------------- context

class DecodeContext:
    """State shared by the handlers of one parser or reader.

    ``stats`` receives rejections; ``autopilot`` maps a system id to the MAV_AUTOPILOT of
    its HEARTBEAT (RAW_IMU scaling and PX4 parameter encoding depend on it);
    ``include_gcs`` keeps ground-station heartbeats.
    """

    __slots__ = ("stats", "autopilot", "include_gcs", "_sources", "fix_times")

    def __init__(self, stats: ReadStats, include_gcs: bool = False) -> None:
        self.stats = stats
        self.autopilot: dict[int, int] = {}
        self.include_gcs = include_gcs
        self._sources: dict[int, str] = {}
        self.fix_times: dict[str, int] = {}
        """Per GNSS source, the ``time_usec`` of its newest fix (a resent fix has it)."""

    def source(self, sysid: int, compid: int, msgid: int) -> str:
        """The ``Sample.source`` string of a frame (cached)."""
        key = (sysid << 32) | (compid << 24) | msgid
        s = self._sources.get(key)
        if s is None:
            who = f"{sysid}" if compid == 1 else f"{sysid}.{compid}"
            s = self._sources[key] = f"mavlink:{who}/{MSG_NAMES.get(msgid, msgid)}"
        return s


Handler = Callable[[tuple, float, int, int, int, bool, DecodeContext], "Sample | list[Sample] | None"]
"""``handler(values, t, sysid, compid, msgid, v2, ctx)`` -> sample(s) or None."""


class Spec:
    """What the decoder needs to know about one message id."""

    __slots__ = ("msgid", "name", "struct", "size", "crc_extra", "handler", "produces")

    def __init__(self, name: str, handler: Handler,
                 produces: tuple[type[msgspec.Struct], ...]) -> None:
        self.msgid, self.struct, _ = _layout(name)
        self.name = name
        self.size = self.struct.size
        self.crc_extra = CRC_EXTRA[self.msgid]
        self.handler = handler
        self.produces = produces


HANDLERS: dict[int, Spec] = {}
"""Decoded message ids -> :class:`Spec`."""


def _register(name: str, produces: tuple[type[msgspec.Struct], ...]):
    def deco(make: Callable[[dict[str, int], int], Handler]) -> Callable:
        msgid, _, idx = _layout(name)
        HANDLERS[msgid] = Spec(name, make(idx, msgid), produces)
        return make
    return deco


# --------------------------------------------------------------------------- handlers

def _gps(idx: dict[str, int], msgid: int) -> Handler:
    """GPS_RAW_INT / GPS2_RAW -> GnssFix. ArduPilot sends its newest fix at the rate it
    is asked for, so a receiver slower than that rate has each fix sent again with the same
    ``time_usec`` (40 of the 528 of the ArduSub tlog of ../shared/data): a repeat is one
    fix, not two independent measurements, and is dropped, counted ``repeated_fix``. A
    ``time_usec`` of 0 (unknown) is never taken as a repeat."""
    i_time = idx["time_usec"]
    i_lat, i_lon, i_alt = idx["lat"], idx["lon"], idx["alt"]
    i_eph, i_vel, i_cog = idx["eph"], idx["vel"], idx["cog"]
    i_fix, i_sat, i_hacc, i_vacc = idx["fix_type"], idx["satellites_visible"], idx["h_acc"], idx["v_acc"]
    i_sacc = idx["vel_acc"]
    fixmap = GPS_FIX_TO_QUALITY
    rad = math.pi / 18000.0

    def h(v, t, sysid, compid, mid, v2, ctx):
        q = fixmap.get(v[i_fix])
        if q is None:
            ctx.stats.reject("no_fix")
            return None
        src = ctx.source(sysid, compid, mid)
        stamp = v[i_time]
        if stamp:
            if ctx.fix_times.get(src) == stamp:
                ctx.stats.reject("repeated_fix")
                return None
            ctx.fix_times[src] = stamp
        eph, vel, cog, sat, hacc, vacc = v[i_eph], v[i_vel], v[i_cog], v[i_sat], v[i_hacc], v[i_vacc]
        return GnssFix(
            t=t, source=src,
            lat_deg=v[i_lat] * 1e-7, lon_deg=v[i_lon] * 1e-7,
            alt_m=v[i_alt] * 1e-3 if v[i_fix] >= 3 else None,
            fix_quality=q,
            num_sats=sat if sat != 255 else None,
            hdop=eph * 0.01 if eph != UINT16_MAX else None,
            sog_mps=vel * 0.01 if vel != UINT16_MAX else None,
            cog_rad=wrap_2pi(cog * rad) if cog != UINT16_MAX else None,
            h_acc_m=hacc * 1e-3 if hacc else None,
            v_acc_m=vacc * 1e-3 if vacc else None,
            speed_acc_mps=v[i_sacc] * 1e-3 if v[i_sacc] else None,
        )
    return h


_register("GPS_RAW_INT", (GnssFix,))(_gps)
_register("GPS2_RAW", (GnssFix,))(_gps)


@_register("GLOBAL_POSITION_INT", (VelocityOverGround, Heading))
def _global_position_int(idx, msgid):
    i_vx, i_vy, i_vz, i_hdg = idx["vx"], idx["vy"], idx["vz"], idx["hdg"]
    rad = math.pi / 18000.0

    def h(v, t, sysid, compid, mid, v2, ctx):
        src = ctx.source(sysid, compid, mid)
        hdg = v[i_hdg]
        if hdg == UINT16_MAX:
            return VelocityOverGround(t=t, source=src, v_north_mps=v[i_vx] * 0.01,
                                      v_east_mps=v[i_vy] * 0.01, v_down_mps=v[i_vz] * 0.01)
        psi = wrap_2pi(hdg * rad)
        vel = VelocityOverGround(t=t, source=src, v_north_mps=v[i_vx] * 0.01,
                                 v_east_mps=v[i_vy] * 0.01, v_down_mps=v[i_vz] * 0.01,
                                 heading_rad=psi)
        return [vel, Heading(t=t, source=src, heading_rad=psi)]
    return h


@_register("ATTITUDE", (Attitude,))
def _attitude(idx, msgid):
    i = idx["roll"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        r, p, y, rr, pr, yr = v[i:i + 6]
        if not (abs(r) < _BIG and abs(p) < _BIG and abs(y) < _BIG):  # NaN or inf
            ctx.stats.reject("nan")
            return None
        return Attitude(t=t, source=ctx.source(sysid, compid, mid), roll_rad=r, pitch_rad=p,
                        yaw_rad=y, roll_rate_rps=rr if abs(rr) < _BIG else None,
                        pitch_rate_rps=pr if abs(pr) < _BIG else None,
                        yaw_rate_rps=yr if abs(yr) < _BIG else None)
    return h


def _scaled_imu(idx: dict[str, int], msgid: int) -> Handler:
    """SCALED_IMU*: mg and mrad/s, body FRD. ArduPilot fills xacc..zgyro with the
    calibrated specific force (a level vehicle at rest reads zacc ~ -1000 mg) and sends
    all zeros for an IMU instance it does not have; an all-zero accelerometer is skipped
    (rejection ``"empty"``)."""
    i = idx["xacc"]
    k_a = GRAVITY_MSS * 1e-3

    def h(v, t, sysid, compid, mid, v2, ctx):
        ax, ay, az, gx, gy, gz = v[i:i + 6]
        if ax == 0 and ay == 0 and az == 0:
            ctx.stats.reject("empty")
            return None
        return Imu(t=t, source=ctx.source(sysid, compid, mid), accel_x=ax * k_a,
                   accel_y=ay * k_a, accel_z=az * k_a, gyro_x=gx * 1e-3, gyro_y=gy * 1e-3,
                   gyro_z=gz * 1e-3)
    return h


_register("SCALED_IMU", (Imu,))(_scaled_imu)
_register("SCALED_IMU2", (Imu,))(_scaled_imu)
_register("SCALED_IMU3", (Imu,))(_scaled_imu)


@_register("RAW_IMU", (Imu,))
def _raw_imu(idx, msgid):
    """RAW_IMU is "raw sensor units" in the spec, but ArduPilot fills it with the same
    scaling as SCALED_IMU (mg, mrad/s; GCS_MAVLINK::send_raw_imu). It is decoded only for a
    system whose HEARTBEAT says MAV_AUTOPILOT_ARDUPILOTMEGA; otherwise skipped (rejection
    ``"unknown_scaling"``)."""
    inner = _scaled_imu(idx, msgid)

    def h(v, t, sysid, compid, mid, v2, ctx):
        if ctx.autopilot.get(sysid) != MAV_AUTOPILOT_ARDUPILOTMEGA:
            ctx.stats.reject("unknown_scaling")
            return None
        return inner(v, t, sysid, compid, mid, v2, ctx)
    return h


@_register("HIGHRES_IMU", (Imu,))
def _highres_imu(idx, msgid):
    i = idx["xacc"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        ax, ay, az, gx, gy, gz = v[i:i + 6]
        if not (abs(ax) < _BIG and abs(ay) < _BIG and abs(az) < _BIG and abs(gx) < _BIG
                and abs(gy) < _BIG and abs(gz) < _BIG):
            ctx.stats.reject("nan")
            return None
        return Imu(t=t, source=ctx.source(sysid, compid, mid), accel_x=ax, accel_y=ay,
                   accel_z=az, gyro_x=gx, gyro_y=gy, gyro_z=gz)
    return h


@_register("VFR_HUD", (Heading,))
def _vfr_hud(idx, msgid):
    """VFR_HUD.heading: integer degrees, the autopilot's yaw (ArduPilot: ahrs yaw, true
    north since the EKF applies the declination). 1-degree resolution: prefer ATTITUDE."""
    i = idx["heading"]
    rad = math.pi / 180.0

    def h(v, t, sysid, compid, mid, v2, ctx):
        return Heading(t=t, source=ctx.source(sysid, compid, mid),
                       heading_rad=wrap_2pi(v[i] * rad), reference="true")
    return h


@_register("SERVO_OUTPUT_RAW", (ActuatorOutputs,))
def _servo_output_raw(idx, msgid):
    """servo1..8_raw, and servo9..16_raw when the frame is MAVLink 2 (extension fields; a
    v1 frame cannot carry them). Values as sent: 0 means "output not configured"."""
    i1, i9, i_port = idx["servo1_raw"], idx["servo9_raw"], idx["port"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        pwm = v[i1:i1 + 8] + v[i9:i9 + 8] if v2 else v[i1:i1 + 8]
        src = ctx.source(sysid, compid, mid)
        if v[i_port]:
            src = f"{src}:port{v[i_port]}"
        return ActuatorOutputs(t=t, source=src, pwm_us=tuple(float(x) for x in pwm))
    return h


@_register("RC_CHANNELS", (RcChannels,))
def _rc_channels(idx, msgid):
    """The first ``chancount`` channels; when chancount is 0 (ArduSub sends 0), the 18
    channels with trailing unused ones (0 or UINT16_MAX) removed."""
    i1, i_n = idx["chan1_raw"], idx["chancount"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        n = v[i_n]
        ch = v[i1:i1 + 18]
        if 0 < n <= 18:
            ch = ch[:n]
        else:
            n = 18
            while n and ch[n - 1] in (0, UINT16_MAX):
                n -= 1
            ch = ch[:n]
        return RcChannels(t=t, source=ctx.source(sysid, compid, mid), pwm_us=tuple(float(x) for x in ch))
    return h


@_register("RPM", (PropellerRpm,))
def _rpm(idx, msgid):
    """ArduPilot RPM (id 226): rpm1, rpm2; a negative value (ArduPilot's -1) means the
    sensor is absent/unhealthy. rpm2 is dropped when invalid; the sample is skipped
    (rejection ``"invalid"``) when rpm1 is."""
    i1, i2 = idx["rpm1"], idx["rpm2"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        r1, r2 = v[i1], v[i2]
        if not 0 <= r1 < _BIG:
            ctx.stats.reject("invalid")
            return None
        rpm = (r1, r2) if 0 <= r2 < _BIG else (r1,)
        return PropellerRpm(t=t, source=ctx.source(sysid, compid, mid), rpm=rpm)
    return h


@_register("VISION_SPEED_ESTIMATE", (VelocityOverGround,))
def _vision_speed(idx, msgid):
    """x, y, z (m/s) in the local NED frame -> VelocityOverGround (source names the message:
    this is the external-vision / DVL velocity input of ArduPilot)."""
    i = idx["x"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        x, y, z = v[i:i + 3]
        if not (abs(x) < _BIG and abs(y) < _BIG):
            ctx.stats.reject("nan")
            return None
        return VelocityOverGround(t=t, source=ctx.source(sysid, compid, mid), v_north_mps=x,
                                  v_east_mps=y, v_down_mps=z if abs(z) < _BIG else None)
    return h


@_register("VISION_POSITION_DELTA", (DvlVelocity,))
def _vision_position_delta(idx, msgid):
    """The DVL message of ArduSub (BlueOS DVL extension): ``position_delta`` (m, FRD of the
    current frame) over ``time_delta_usec`` -> DvlVelocity(vx, vy, vz) = delta / dt,
    bottom track, ``valid`` = confidence > 0. ``angle_delta`` is not carried."""
    i_dt, i_pd, i_c = idx["time_delta_usec"], idx["position_delta"], idx["confidence"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        dt = v[i_dt] * 1e-6
        dx, dy, dz = v[i_pd:i_pd + 3]
        if dt <= 0:
            ctx.stats.reject("dt")
            return None
        if not (abs(dx) < _BIG and abs(dy) < _BIG and abs(dz) < _BIG):
            ctx.stats.reject("nan")
            return None
        c = v[i_c]
        return DvlVelocity(t=t, source=ctx.source(sysid, compid, mid), vx=dx / dt, vy=dy / dt,
                           vz=dz / dt, track="bottom", valid=bool(c > 0))
    return h


@_register("DISTANCE_SENSOR", (Altitude,))
def _distance_sensor(idx, msgid):
    """Downward range finders only (orientation 25, PITCH_270); current_distance (cm) ->
    m. Outside [min_distance, max_distance] -> rejection ``"out_of_range"``;
    signal_quality 1 (invalid) -> ``"invalid"``. Other orientations are skipped silently."""
    i_min, i_max, i_cur = idx["min_distance"], idx["max_distance"], idx["current_distance"]
    i_or, i_q = idx["orientation"], idx["signal_quality"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        if v[i_or] != MAV_SENSOR_ROTATION_PITCH_270:
            return None
        cur = v[i_cur]
        if not v[i_min] <= cur <= v[i_max]:
            ctx.stats.reject("out_of_range")
            return None
        if v[i_q] == 1:
            ctx.stats.reject("invalid")
            return None
        return Altitude(t=t, source=ctx.source(sysid, compid, mid), altitude_m=cur * 0.01)
    return h


def _scaled_pressure(idx: dict[str, int], msgid: int) -> Handler:
    i_p, i_t = idx["press_abs"], idx["temperature"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        p = v[i_p]
        if not 0 < p < _BIG:  # also NaN, inf
            ctx.stats.reject("invalid")
            return None
        return Pressure(t=t, source=ctx.source(sysid, compid, mid), pressure_pa=p * 100.0,
                        temperature_c=v[i_t] * 0.01)
    return h


_register("SCALED_PRESSURE", (Pressure,))(_scaled_pressure)
_register("SCALED_PRESSURE2", (Pressure,))(_scaled_pressure)
_register("SCALED_PRESSURE3", (Pressure,))(_scaled_pressure)


@_register("HEARTBEAT", (VehicleInfo,))
def _heartbeat(idx, msgid):
    """HEARTBEAT -> VehicleInfo; ground stations (type 6) are skipped unless
    ``include_gcs``. Also records the system's autopilot in the context."""
    i_type, i_ap = idx["type"], idx["autopilot"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        typ, ap = v[i_type], v[i_ap]
        if ap != MAV_AUTOPILOT_INVALID:
            ctx.autopilot[sysid] = ap
        if typ == MAV_TYPE_GCS and not ctx.include_gcs:
            return None
        return VehicleInfo(t=t, source=ctx.source(sysid, compid, mid), system_id=sysid,
                           component_id=compid, mav_type=typ, autopilot=ap)
    return h


_PX4_INT = {1: "<B", 2: "<b", 3: "<H", 4: "<h", 5: "<I", 6: "<i"}


@_register("PARAM_VALUE", (Parameter,))
def _param_value(idx, msgid):
    """PARAM_VALUE -> Parameter(name, value). ArduPilot sends integers cast to float (used
    as is); PX4 (autopilot 12) sends them bytewise in the float, which is undone here."""
    i_v, i_id, i_ty = idx["param_value"], idx["param_id"], idx["param_type"]

    def h(v, t, sysid, compid, mid, v2, ctx):
        name = v[i_id].split(b"\0", 1)[0].decode("ascii", "replace")
        val = v[i_v]
        if ctx.autopilot.get(sysid) == MAV_AUTOPILOT_PX4 and v[i_ty] in _PX4_INT:
            raw = struct.pack("<f", val)
            fmt = _PX4_INT[v[i_ty]]
            val = float(struct.unpack_from(fmt, raw)[0])
        if not name or not abs(val) < _BIG:
            ctx.stats.reject("invalid")
            return None
        return Parameter(t=t, source=ctx.source(sysid, compid, mid), name=name, value=float(val))
    return h


HEARTBEAT_ID = 0
PARAM_VALUE_ID = _layout("PARAM_VALUE")[0]


def select(types: Iterable[type | str] | None) -> dict[int, Spec]:
    """The handler table restricted to message ids producing any of ``types``.

    ``types`` are Sample subclasses or their tags (``"imu"``, ``"gnss"``...); None = all.
    HEARTBEAT is always kept (its handler records the autopilot type the RAW_IMU and
    PARAM_VALUE handlers need); its samples are filtered out by the caller when
    VehicleInfo is not wanted (see :func:`wants`).
    """
    if types is None:
        return dict(HANDLERS)
    wanted = _normalize(types)
    out = {mid: s for mid, s in HANDLERS.items() if any(p in wanted for p in s.produces)}
    out[HEARTBEAT_ID] = HANDLERS[HEARTBEAT_ID]
    return out


def _normalize(types: Iterable[type | str]) -> set[type]:
    by_tag = {c.__struct_config__.tag: c for s in HANDLERS.values() for c in s.produces}
    out: set[type] = set()
    for x in types:
        if isinstance(x, str):
            if x not in by_tag:
                raise ValueError(f"unknown sample type {x!r}; known: {sorted(map(str, by_tag))}")
            out.add(by_tag[x])
        else:
            out.add(x)
    return out


def wanted_types(types: Iterable[type | str] | None) -> tuple[type, ...] | None:
    """``types`` as a tuple of classes for isinstance filtering (None = everything)."""
    return None if types is None else tuple(_normalize(types))


# --------------------------------------------------------------------------- frame decoding

def decode_payload(spec: Spec, buf, start: int, plen: int, t: float, sysid: int, compid: int,
                   v2: bool, ctx: DecodeContext) -> Sample | list[Sample] | None:
    """Unpack the payload ``buf[start:start+plen]`` of a CRC-checked frame with ``spec``.

    A shorter payload (v2 zero truncation, or a v1 frame without extension fields) is
    padded with zeros; a longer one (newer dialect) is cut to the known fields.
    """
    size = spec.size
    if plen >= size:
        values = spec.struct.unpack_from(buf, start)
    else:
        values = spec.struct.unpack(bytes(buf[start:start + plen]) + bytes(size - plen))
    return spec.handler(values, t, sysid, compid, spec.msgid, v2, ctx)


class MavlinkParser:
    """Incremental MAVLink 1/2 parser for a live byte stream (serial, UDP, TCP).

    ``feed(data, t_rx)`` returns the samples of the frames completed by ``data``, all
    stamped ``t_rx``. Every frame whose id is in the dialect is CRC-checked (a failed frame
    is counted ``"crc"`` and the search resumes one byte after its start byte); bytes
    between frames count as one ``"garbage"`` rejection per run; a frame with unknown
    incompatibility flags is ``"incompat"``. Frames of ids outside the dialect cannot be
    checked and are skipped by their length (counted in ``by_type`` as ``UNKNOWN_<id>``).
    Without a ``verifier``, signed MAVLink 2 frames are accepted and their 13-byte
    signature is skipped, not verified. With one (signing required, see
    :mod:`drivers.mavlink_signing`), every frame must be signed with the key and fresh:
    otherwise it is counted under the verifier's reason (``"unsigned"``, ``"signature"``,
    ``"sig_replay"``, ``"sig_stale"``, ``"sig_future"``) and produces nothing.
    The result does not depend on how the stream is cut into chunks.

    ``types`` restricts the samples produced (Sample classes or tags); ``include_gcs``
    keeps ground-station heartbeats. With a ``link`` (:class:`drivers.mavlink_link.AutopilotLink`)
    only the autopilot's frames are decoded, stamped with its boot time mapped to the
    receive clock (other systems' and components' frames are counted in ``link.ignored``).
    """

    def __init__(self, *, types: Iterable[type | str] | None = None, include_gcs: bool = False,
                 verifier: "FrameVerifier | None" = None,
                 link: "AutopilotLink | None" = None) -> None:
        self.verifier = verifier
        self.link = link
        self.stats = ReadStats()
        self._ctx = DecodeContext(self.stats, include_gcs)
        self._specs = select(types)
        self._want = wanted_types(types)
        self._buf = bytearray()
        self._in_garbage = False
        self._counts: Counter[int] = Counter()

    def feed(self, data: bytes, t_rx: float) -> list[Sample]:
        """Consume ``data`` received at ``t_rx`` (s); return the samples completed."""
        buf = self._buf
        buf += data
        out: list[Sample] = []
        n = len(buf)
        i = 0
        specs, ctx, stats = self._specs, self._ctx, self.stats
        find = START_BYTES.search
        verify = self.verifier.check if self.verifier is not None else None
        link = self.link
        while i < n:
            m = find(buf, i)
            if m is None:
                if not self._in_garbage:
                    stats.reject("garbage")
                    self._in_garbage = True
                i = n
                break
            j = m.start()
            if j > i and not self._in_garbage:
                stats.reject("garbage")
                self._in_garbage = True
            i = j
            h = header_at(buf, j, n)
            if h is None:
                break
            hdr, plen, inc, sysid, compid, msgid, end = h
            if end > n:
                break
            v2 = hdr == HEADER_LEN_V2
            if inc & ~IFLAG_SIGNED:
                stats.reject("incompat")
                self._in_garbage = True
                i = j + 1
                continue
            extra = CRC_EXTRA.get(msgid)
            if extra is None:
                # No CRC to check an id outside the dialect: take it as a frame only if
                # another frame starts right after it (wait for that byte), so a stray
                # start byte in line noise cannot swallow the intact frames behind it.
                if end >= n:
                    break
                inside = (_valid_frame_inside(buf, j + 1, end) if buf[end] in (MAGIC_V1, MAGIC_V2)
                          else True)
                if inside is None:
                    break  # a frame inside it is still arriving: decide with its bytes
                if inside:
                    stats.reject("garbage")
                    self._in_garbage = True
                    i = j + 1
                    continue
                self._counts[-1 - msgid] += 1  # negative key: unknown id
                stats.records += 1
                self._in_garbage = False
                i = end
                if verify is not None:
                    reason = verify(buf, j, j + hdr + plen + 2, sysid, compid, inc)
                    if reason is not None:
                        stats.reject(reason)
                continue
            ce = j + hdr + plen
            if not crc_matches(buf, j, hdr, plen, extra):
                stats.reject("crc")
                self._in_garbage = True
                i = j + 1
                continue
            self._in_garbage = False
            stats.records += 1
            self._counts[msgid] += 1
            i = end
            if verify is not None:
                reason = verify(buf, j, ce + 2, sysid, compid, inc)
                if reason is not None:
                    stats.reject(reason)
                    continue
            t = t_rx
            if link is not None:
                ts = link.accept(sysid, compid, msgid, buf, j + hdr, plen, t_rx)
                if ts is None:
                    continue
                t = ts
            spec = specs.get(msgid)
            if spec is None:
                continue
            res = decode_payload(spec, buf, j + hdr, plen, t, sysid, compid, v2, ctx)
            if res is not None:
                if link is not None and msgid == PARAM_VALUE_ID and type(res) is Parameter:
                    link.note_param(res.name, res.value)
                _emit(res, out, self._want)
        del buf[:i]
        stats.samples += len(out)
        self._flush_counts()
        return out

    def _flush_counts(self) -> None:
        for k, c in self._counts.items():
            self.stats.by_type[type_name(k)] += c
        self._counts.clear()


def type_name(key: int) -> str:
    """by_type key of a message id (negative keys: ``UNKNOWN_<id>`` outside the dialect)."""
    if key < 0:
        return f"UNKNOWN_{-1 - key}"
    return MSG_NAMES.get(key, f"UNKNOWN_{key}")


def _emit(res, out: list, want: tuple[type, ...] | None) -> None:
    if type(res) is list:
        for s in res:
            if want is None or isinstance(s, want):
                out.append(s)
    elif want is None or isinstance(res, want):
        out.append(res)
