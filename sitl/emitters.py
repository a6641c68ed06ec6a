"""Emitters: typed samples out as the bytes real instruments and autopilots send.

Two layers, kept apart so each can be tested alone:

* **encoders** turn the samples of one instant into protocol frames:
  :class:`MavlinkEncoder` (MAVLink 2, pymavlink's ``ardupilotmega`` dialect, CRCs by
  pymavlink), :class:`NmeaEncoder` (GGA, RMC, VTG, HDT built by pynmeagps,
  :mod:`sitl.nmea_out`), :class:`DvlJsonEncoder` (Water Linked A50 JSON lines,
  :mod:`sitl.dvl_json_out`) and :class:`Pd6Encoder` (Teledyne RDI PD6 ensembles,
  :mod:`sitl.pd6_out`). None of them uses the drivers that read these protocols back
  (``tests/test_layering.py``): the simulator's writers follow the protocols'
  documents, so a misreading in a driver shows as a failed round trip instead of being
  shared by both ends;
* **sinks** move frames: :class:`TlogSink` (a ``.tlog``: 8-byte big-endian microseconds
  since the Unix epoch, then the frame), :class:`UdpSink`, :class:`TcpServerSink` (a
  listening socket; every connected client gets every frame), :class:`PtySink` (a serial
  pseudo-terminal; the slave path is what a reader opens) and :class:`FileSink`.

Every encoder is deterministic: the same samples give the same bytes (MAVLink sequence
numbers start at 0; time fields derive from the sample times and ``epoch_s``).

MAVLink mapping (what :mod:`drivers.mavlink` reads back):

=====================  ====================================================================
sample                 MAVLink message
=====================  ====================================================================
VehicleInfo            HEARTBEAT (MAV_TYPE of the vehicle, MAV_AUTOPILOT_ARDUPILOTMEGA)
Parameter              PARAM_VALUE (SERVOn_FUNCTION, as an ArduPilot INT16 parameter)
GnssFix                GPS_RAW_INT (fix_type 3)
GnssNoFix              GPS_RAW_INT (fix_type 1, NO_FIX: the last fix's place and time_usec)
VelocityOverGround     GLOBAL_POSITION_INT (vx, vy, vz; lat/lon dead-reckoned from them;
                       hdg the sample's own heading, else the last attitude's yaw; alt
                       from the last depth)
Imu                    SCALED_IMU (mg, mrad/s; xmag..zmag from the last heading)
Attitude               ATTITUDE
Heading                VFR_HUD (groundspeed from the last fix/INS, throttle from the last
                       outputs), at most ``vfr_hud_hz``
Depth                  SCALED_PRESSURE2 (the external pressure sensor of ArduSub)
ActuatorOutputs        SERVO_OUTPUT_RAW
PropellerRpm           RPM (rpm1, rpm2 = -1 when absent)
DvlVelocity (bottom)   VISION_POSITION_DELTA (position delta over the time since the
                       previous report, confidence 0 on lock loss) and DISTANCE_SENSOR
                       (downward, the DVL altitude)
=====================  ====================================================================

DvlPosition and water-track DvlVelocity have no MAVLink message here; they go out on the
DVL JSON and PD6 links.
"""

from __future__ import annotations

import array
import fcntl
import math
import os
import select
import socket
import termios
import time
import tty
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, Sequence

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from onboard.core.messages import (
    ActuatorOutputs,
    Attitude,
    Depth,
    DvlPosition,
    DvlVelocity,
    GnssFix,
    Heading,
    Imu,
    Parameter,
    PropellerRpm,
    Sample,
    VehicleInfo,
    VelocityOverGround,
)
from onboard.sitl import dvl_json_out, nmea_out, pd6_out
from onboard.sitl.frames import GeoOrigin, body_to_ned_fast, ned_to_body_fast
from onboard.sitl.sensors import GnssNoFix, HeadingInvalid

DEFAULT_EPOCH_S = 1_767_225_600.0
"""Unix time of simulation t = 0 in logs: 2026-01-01T00:00:00Z (fixed, for determinism)."""

MAV_TYPE_SURFACE_BOAT = 11
MAV_TYPE_SUBMARINE = 12
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_STATE_ACTIVE = 4
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_MODE_FLAG_MANUAL_INPUT_ENABLED = 64
MAV_MODE_FLAG_STABILIZE_ENABLED = 16
MAV_MODE_FLAG_GUIDED_ENABLED = 8
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
ROVER_MANUAL_INPUT_MODES = frozenset({0, 1, 3})
"""Rover's modes (custom_mode) that take the pilot's sticks: MANUAL, ACRO, STEERING."""
ROVER_AUTOPILOT_MODES = frozenset({5, 6, 7, 8, 9, 10, 11, 12, 15})
"""Rover's modes that steer themselves: LOITER, FOLLOW, SIMPLE, DOCK, CIRCLE, AUTO, RTL,
SMART_RTL, GUIDED."""
SUB_GUIDED_MODES = frozenset({3, 4, 7, 16})
"""ArduSub's modes flagged guided: AUTO, GUIDED, CIRCLE, POSHOLD."""
MAV_PARAM_TYPE_INT16 = 4
GPS_FIX_TYPE_NO_FIX = 1
UINT16_UNKNOWN = 65535
MAV_SENSOR_ROTATION_PITCH_270 = 25
MAV_DISTANCE_SENSOR_ULTRASOUND = 1
GRAVITY_MSS = 9.80665
"""ArduPilot's mg scaling constant (m/s^2 per 1000 mg)."""
EARTH_FIELD_GAUSS = (0.2, 0.0, 0.4)
"""A mid-latitude magnetic field in NED (gauss), for SCALED_IMU's magnetometer fields."""
DVL_DRIVER_SYSTEM, DVL_DRIVER_COMPONENT = 255, 0
"""The MAVLink sender of the DVL's VISION_POSITION_DELTA: BlueOS's Water Linked DVL
extension posts it through mavlink2rest with this header (bluerobotics/
BlueOS-Water-Linked-DVL, ``mavlink2resthelper.py``), ``time_usec`` 0; the autopilot only
receives it."""
DVL_POSITION_STD_M = 0.1
"""Standard deviation of a dead-reckoned DVL position that gives none (m)."""
PD6_TEMPERATURE_C = 10.0
"""Water temperature in PD6's TS line until a Depth sample brings one (C)."""


def _i16(x: float) -> int:
    return max(-32768, min(32767, int(round(x))))


def _u16(x: float) -> int:
    return max(0, min(65535, int(round(x))))


def heartbeat_base_mode(mav_type: int, custom_mode: int, armed: bool = True) -> int:
    """HEARTBEAT ``base_mode`` as ArduPilot's firmware sets it for a vehicle of
    ``mav_type`` in mode ``custom_mode`` (``GCS_MAVLINK_Sub::base_mode``,
    ``GCS_MAVLINK_Rover::base_mode``): ArduSub armed in MANUAL or STABILIZE sends 209 (in
    MANUAL in the ArduSub tlog of ../shared/data), a Rover armed in AUTO 137."""
    mode = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if mav_type == MAV_TYPE_SUBMARINE:
        mode |= MAV_MODE_FLAG_STABILIZE_ENABLED | MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if custom_mode in SUB_GUIDED_MODES:
            mode |= MAV_MODE_FLAG_GUIDED_ENABLED
    else:
        if custom_mode in ROVER_MANUAL_INPUT_MODES:
            mode |= MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if custom_mode in ROVER_AUTOPILOT_MODES:
            mode |= MAV_MODE_FLAG_GUIDED_ENABLED
    return mode | (MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)


class MavlinkEncoder:
    """Samples -> MAVLink 2 frames from one vehicle (system ``system_id``, component 1).

    ``origin`` is the (lat, lon) in degrees of the local frame, used to dead-reckon the
    GLOBAL_POSITION_INT position from the INS velocity (starting at ``start_ne``, m).
    ``dvl_period_s`` is the time delta of the first VISION_POSITION_DELTA.
    """

    def __init__(self, *, mav_type: int, system_id: int = 1, component_id: int = 1,
                 custom_mode: int = 0, origin: tuple[float, float] = (0.0, 0.0),
                 start_ne: tuple[float, float] = (0.0, 0.0), dvl_period_s: float = 0.2,
                 dvl_max_altitude_m: float = 50.0, vfr_hud_hz: float = 2.0,
                 epoch_s: float = DEFAULT_EPOCH_S) -> None:
        self.mav = mavlink2.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.dvl_driver = mavlink2.MAVLink(None, srcSystem=DVL_DRIVER_SYSTEM,
                                           srcComponent=DVL_DRIVER_COMPONENT)
        """The companion's DVL driver, the sender of VISION_POSITION_DELTA."""
        self.mav_type = mav_type
        self.custom_mode = custom_mode
        self._geo = GeoOrigin(*origin)
        self.origin = origin
        self.ins_ne = list(start_ne)
        self.epoch_s = epoch_s
        self.dvl_period_s = dvl_period_s
        self.dvl_max_cm = _u16(dvl_max_altitude_m * 100.0)
        self.vfr_period = 1.0 / vfr_hud_hz if vfr_hud_hz > 0 else math.inf
        self._t_vfr = -math.inf
        self._t_ins: float | None = None
        self._t_dvl: float | None = None
        self._att: Attitude | None = None
        self._depth = 0.0
        self._climb = 0.0
        self._speed = 0.0
        self._throttle = 0
        self._heading = 0.0
        self._params: list[Parameter] = []
        self.frames = 0
        self.boot_t0 = 0.0
        """Simulation time (s) at which the autopilot booted: ``time_boot_ms`` counts from
        it (:class:`sitl.autopilot.SimAutopilot` moves it on a reboot)."""
        self.raw_imu = False
        """Send Imu samples as RAW_IMU (ArduPilot's RAW_SENSORS stream) instead of SCALED_IMU."""
        self._last_fix = (0, 0, 0, 0)
        """The newest GPS_RAW_INT fix's ``time_usec``, lat, lon (1e-7 deg) and alt (mm):
        what AP_GPS keeps through a loss of the fix (zeros before the first)."""

    def _pack(self, msg, sender=None) -> bytes:
        """``msg`` packed by ``sender`` (a MAVLink instance; default the autopilot's)."""
        mav = self.mav if sender is None else sender
        buf = msg.pack(mav)
        mav.seq = (mav.seq + 1) % 256
        self.frames += 1
        return buf

    def gps_no_fix(self) -> bytes:
        """GPS_RAW_INT of an epoch without a fix, as AP_GPS sends it at its stream rate
        through a loss: fix_type NO_FIX, the last fix's place, and its ``time_usec``
        (``last_fix_time_ms``, held: 768,005,000 in every frame of the ArduSub tlog's loss
        at 79-82 s); accuracy, speed and course unknown, no satellites."""
        time_usec, lat, lon, alt_mm = self._last_fix
        return self._pack(self.mav.gps_raw_int_encode(
            time_usec, GPS_FIX_TYPE_NO_FIX, lat, lon, alt_mm, UINT16_UNKNOWN, UINT16_UNKNOWN,
            0, UINT16_UNKNOWN, 0))

    def set_parameters(self, params: Sequence[Parameter]) -> None:
        """The parameter set, so PARAM_VALUE carries the right count and indices."""
        self._params = list(params)

    def encode(self, samples: Sequence[Sample]) -> list[bytes]:
        """The frames for ``samples`` (one instant, in order)."""
        out: list[bytes] = []
        m = self.mav
        for s in samples:
            t = s.t
            ms = int(round((t - self.boot_t0) * 1000.0)) & 0xFFFFFFFF
            if isinstance(s, Imu) and self.raw_imu:
                out.append(self._pack(m.raw_imu_encode(
                    int(round((t - self.boot_t0) * 1e6)),
                    _i16(s.accel_x / GRAVITY_MSS * 1000.0), _i16(s.accel_y / GRAVITY_MSS * 1000.0),
                    _i16(s.accel_z / GRAVITY_MSS * 1000.0), _i16(s.gyro_x * 1000.0),
                    _i16(s.gyro_y * 1000.0), _i16(s.gyro_z * 1000.0), *self._mag_mgauss(), 0, 2000)))
            elif isinstance(s, Imu):
                out.append(self._pack(m.scaled_imu_encode(
                    ms, _i16(s.accel_x / GRAVITY_MSS * 1000.0),
                    _i16(s.accel_y / GRAVITY_MSS * 1000.0),
                    _i16(s.accel_z / GRAVITY_MSS * 1000.0),
                    _i16(s.gyro_x * 1000.0), _i16(s.gyro_y * 1000.0), _i16(s.gyro_z * 1000.0),
                    *self._mag_mgauss(), 2000)))
            elif isinstance(s, Attitude):
                self._att = s
                out.append(self._pack(m.attitude_encode(
                    ms, s.roll_rad, s.pitch_rad, s.yaw_rad, s.roll_rate_rps or 0.0,
                    s.pitch_rate_rps or 0.0, s.yaw_rate_rps or 0.0)))
            elif isinstance(s, GnssFix):
                self._speed = s.sog_mps or 0.0
                cog = 65535 if s.cog_rad is None else _u16(
                    math.degrees(s.cog_rad) % 360.0 * 100.0) % 36000
                alt_mm = int(round((s.alt_m or 0.0) * 1000.0))
                # time_usec: the fix's boot time, as AP_GPS sends it (last_fix_time_ms;
                # 689,065,000 at the ArduSub tlog's first), not Unix time
                self._last_fix = (max(0, int(round((t - self.boot_t0) * 1e6))),
                                  int(round(s.lat_deg * 1e7)), int(round(s.lon_deg * 1e7)),
                                  alt_mm)
                time_usec, lat, lon, _ = self._last_fix
                out.append(self._pack(m.gps_raw_int_encode(
                    time_usec, 3 if s.fix_quality == 1 else 4, lat, lon, alt_mm,
                    _u16((s.hdop or 0.0) * 100.0) if s.hdop is not None else 65535, 65535,
                    _u16((s.sog_mps or 0.0) * 100.0), cog, s.num_sats or 255, alt_mm,
                    int(round((s.h_acc_m or 0.0) * 1000.0)),
                    int(round((s.v_acc_m or 0.0) * 1000.0)), 0, 0, 0)))
            elif isinstance(s, GnssNoFix):
                out.append(self.gps_no_fix())
            elif isinstance(s, VelocityOverGround):
                out.append(self._global_position(s, ms))
            elif isinstance(s, Heading):
                self._heading = s.heading_rad
                if t >= self._t_vfr + self.vfr_period - 1e-9:
                    self._t_vfr = t
                    out.append(self._pack(m.vfr_hud_encode(
                        self._speed, self._speed, int(round(math.degrees(s.heading_rad))) % 360,
                        self._throttle, -self._depth, self._climb)))
            elif isinstance(s, Depth):
                self._depth = s.depth_m
                p = s.pressure_pa
                if p is None:
                    p = 101325.0 + 1025.0 * GRAVITY_MSS * s.depth_m
                out.append(self._pack(m.scaled_pressure2_encode(
                    ms, p / 100.0, (p - 101325.0) / 100.0,
                    _i16((s.temperature_c if s.temperature_c is not None else 15.0) * 100.0))))
            elif isinstance(s, ActuatorOutputs):
                pwm = [_u16(x) for x in s.pwm_us[:16]] + [0] * max(0, 16 - len(s.pwm_us))
                self._throttle = self._throttle_percent(pwm)
                out.append(self._pack(m.servo_output_raw_encode(
                    int(round((t - self.boot_t0) * 1e6)) & 0xFFFFFFFF, 0, *pwm)))
            elif isinstance(s, PropellerRpm):
                r = list(s.rpm) + [-1.0]
                out.append(self._pack(m.rpm_encode(float(r[0]), float(r[1]))))
            elif isinstance(s, DvlVelocity):
                if s.track == "bottom":
                    out.extend(self._dvl(s, ms))
            elif isinstance(s, VehicleInfo):
                out.append(self._pack(m.heartbeat_encode(
                    self.mav_type, MAV_AUTOPILOT_ARDUPILOTMEGA,
                    heartbeat_base_mode(self.mav_type, self.custom_mode),
                    self.custom_mode, MAV_STATE_ACTIVE, 3)))
            elif isinstance(s, Parameter):
                names = [p.name for p in self._params]
                idx = names.index(s.name) if s.name in names else 65535
                out.append(self._pack(m.param_value_encode(
                    s.name.encode("ascii")[:16], float(s.value), MAV_PARAM_TYPE_INT16,
                    max(len(self._params), 1), idx)))
            # DvlPosition: no MAVLink message (DVL JSON / PD6 only)
        return out

    def _throttle_percent(self, pwm: list[int]) -> int:
        """VFR_HUD throttle (%): the largest deflection of any output from 1500 us."""
        dev = [abs(p - 1500) for p in pwm if p]
        return min(100, int(round(max(dev, default=0) / 4.0)))

    def _mag_mgauss(self) -> tuple[int, int, int]:
        """Body-frame magnetometer (mgauss) consistent with the last heading and attitude."""
        psi = self._heading
        phi = self._att.roll_rad if self._att else 0.0
        th = self._att.pitch_rad if self._att else 0.0
        x, y, z = ned_to_body_fast(phi, th, psi, EARTH_FIELD_GAUSS)
        return _i16(x * 1000.0), _i16(y * 1000.0), _i16(z * 1000.0)

    def _global_position(self, s: VelocityOverGround, ms: int) -> bytes:
        t = s.t
        if self._t_ins is not None:
            dt = t - self._t_ins
            self.ins_ne[0] += s.v_north_mps * dt
            self.ins_ne[1] += s.v_east_mps * dt
        self._t_ins = t
        self._speed = math.hypot(s.v_north_mps, s.v_east_mps)
        self._climb = -(s.v_down_mps or 0.0)
        lat, lon = self._geo.to_latlon(self.ins_ne[0], self.ins_ne[1])
        yaw = s.heading_rad
        if yaw is None:
            yaw = self._att.yaw_rad if self._att is not None else self._heading
        hdg = _u16(math.degrees(yaw) % 360.0 * 100.0) % 36000
        alt_mm = int(round(-self._depth * 1000.0))
        return self._pack(self.mav.global_position_int_encode(
            ms, int(round(lat * 1e7)), int(round(lon * 1e7)), alt_mm, alt_mm,
            _i16(s.v_north_mps * 100.0), _i16(s.v_east_mps * 100.0),
            _i16((s.v_down_mps or 0.0) * 100.0), hdg))

    def _dvl(self, s: DvlVelocity, ms: int) -> list[bytes]:
        t = s.t
        dt = self.dvl_period_s if self._t_dvl is None else t - self._t_dvl
        self._t_dvl = t
        dt_us = max(1, int(round(dt * 1e6)))
        dts = dt_us * 1e-6
        a = self._att
        ang = [0.0, 0.0, 0.0]
        if a is not None:
            ang = [(a.roll_rate_rps or 0.0) * dts, (a.pitch_rate_rps or 0.0) * dts,
                   (a.yaw_rate_rps or 0.0) * dts]
        if s.valid:
            pos = [s.vx * dts, s.vy * dts, s.vz * dts]
            conf = 100.0 if s.fom_mps is None else max(1.0, min(100.0, 100.0 - 1000.0 * s.fom_mps))
        else:
            pos, conf = [0.0, 0.0, 0.0], 0.0
        out = [self._pack(self.dvl_driver.vision_position_delta_encode(
            0, dt_us, ang, pos, conf), self.dvl_driver)]
        if s.valid and s.altitude_m is not None:
            out.append(self._pack(self.mav.distance_sensor_encode(
                ms, 5, self.dvl_max_cm, _u16(s.altitude_m * 100.0),
                MAV_DISTANCE_SENSOR_ULTRASOUND, 1, MAV_SENSOR_ROTATION_PITCH_270, 255,
                0.0, 0.0, (0.0, 0.0, 0.0, 0.0), 100)))
        return out


class NmeaEncoder:
    """GnssFix -> GGA, RMC, VTG (talker GP); GnssNoFix (a receiver epoch without a fix)
    -> GGA of quality 0, RMC ``V``, VTG ``N``; Heading -> HDT (talker HE); HeadingInvalid
    -> an empty HDT; sentences by :mod:`sitl.nmea_out` (pynmeagps). Time of day and date
    from ``epoch_s + t``."""

    def __init__(self, epoch_s: float = DEFAULT_EPOCH_S) -> None:
        self.epoch_s = epoch_s

    def encode(self, samples: Sequence[Sample]) -> list[bytes]:
        """The frames for ``samples`` (one instant, in order); samples this encoder has no
        sentence or report for give none."""
        out: list[bytes] = []
        for s in samples:
            if isinstance(s, GnssFix):
                tu = self.epoch_s + s.t
                sog = s.sog_mps or 0.0
                out.append(nmea_out.gga(tu, s.lat_deg, s.lon_deg, s.alt_m or 0.0,
                                        s.fix_quality, s.num_sats or 0, s.hdop or 1.0))
                out.append(nmea_out.rmc(tu, s.lat_deg, s.lon_deg, sog, s.cog_rad,
                                        s.fix_quality))
                out.append(nmea_out.vtg(sog, s.cog_rad))
            elif isinstance(s, GnssNoFix):
                tu = self.epoch_s + s.t
                out += [nmea_out.gga_no_fix(tu), nmea_out.rmc_no_fix(tu), nmea_out.vtg_no_fix()]
            elif isinstance(s, Heading):
                out.append(nmea_out.hdt(s.heading_rad))
            elif isinstance(s, HeadingInvalid):
                out.append(nmea_out.hdt(None))
        return out


class DvlJsonEncoder:
    """DvlVelocity -> Water Linked velocity-and-transducer reports (``velocity``, or
    ``velocity_water`` in water tracking; an invalid one with an altitude was flagged while
    locked and keeps its velocity, as the A50's); DvlPosition -> ``position_local`` dead
    reckoning reports: one JSON object per line, by :mod:`sitl.dvl_json_out`."""

    def __init__(self, epoch_s: float = DEFAULT_EPOCH_S, period_s: float = 0.2) -> None:
        self.epoch_s = epoch_s
        self.period_s = period_s
        self._t_last: dict[str, float] = {}

    def encode(self, samples: Sequence[Sample]) -> list[bytes]:
        """The report lines for ``samples`` (one instant, in order); other sample types give
        none."""
        out: list[bytes] = []
        for s in samples:
            if isinstance(s, DvlVelocity):
                last = self._t_last.get(s.track)
                self._t_last[s.track] = s.t
                out.append(dvl_json_out.velocity_report(
                    s.vx, s.vy, s.vz, valid=s.valid, fom_mps=s.fom_mps or 0.0,
                    altitude_m=s.altitude_m, covariance=s.covariance, track=s.track,
                    locked=s.valid or s.altitude_m is not None,
                    dt_s=self.period_s if last is None else s.t - last,
                    t_validity_s=self.epoch_s + s.t))
            elif isinstance(s, DvlPosition):
                out.append(dvl_json_out.dead_reckoning_report(
                    s.north_m, s.east_m, s.down_m, t_s=self.epoch_s + s.t,
                    std_m=s.std_m if s.std_m is not None else DVL_POSITION_STD_M,
                    roll_rad=s.roll_rad or 0.0, pitch_rad=s.pitch_rad or 0.0,
                    yaw_rad=s.yaw_rad or 0.0))
        return out


class Pd6Encoder:
    """DvlVelocity -> one PD6 ensemble per instant (:mod:`sitl.pd6_out`): SA and TS from
    the last Attitude and Depth, then WI, WS for a water-track report and BI, BS, BE, BD
    for a bottom-track report. BE is the velocity rotated into NED by the last attitude;
    BD's distance made good sums BE over the time between good bottom-track reports."""

    def __init__(self, epoch_s: float = DEFAULT_EPOCH_S) -> None:
        self.epoch_s = epoch_s
        self._att: Attitude | None = None
        self._depth = 0.0
        self._temperature_c = PD6_TEMPERATURE_C
        self._made_good = [0.0, 0.0, 0.0]
        """Distance made good east, north, up (m)."""
        self._t_good: float | None = None

    def encode(self, samples: Sequence[Sample]) -> list[bytes]:
        """The ensemble for ``samples`` (one instant), none without a DvlVelocity among
        them; Attitude and Depth are kept for the ensembles."""
        water = bottom = None
        for s in samples:
            if isinstance(s, Attitude):
                self._att = s
            elif isinstance(s, Depth):
                self._depth = s.depth_m
                if s.temperature_c is not None:
                    self._temperature_c = s.temperature_c
            elif isinstance(s, DvlVelocity):
                if s.track == "water":
                    water = s
                else:
                    bottom = s
        if water is None and bottom is None:
            return []
        t = bottom.t if bottom is not None else water.t  # type: ignore[union-attr]
        a = self._att
        roll, pitch, yaw = (a.roll_rad, a.pitch_rad, a.yaw_rad) if a else (0.0, 0.0, 0.0)
        lines = [pd6_out.sa(roll, pitch, yaw),
                 pd6_out.ts(self.epoch_s + t, max(0.0, self._depth), self._temperature_c)]
        if water is not None:
            w = water
            lines += [pd6_out.instrument_velocity(w.vx, w.vy, w.vz, w.fom_mps or 0.0, w.valid,
                                                  water=True),
                      pd6_out.ship_velocity(w.vx, w.vy, w.vz, w.valid, water=True)]
        if bottom is not None:
            lines += self._bottom(bottom, roll, pitch, yaw)
        return [b"".join(lines)]

    def _bottom(self, b: DvlVelocity, roll: float, pitch: float, yaw: float) -> list[bytes]:
        """BI, BS, BE and BD of a bottom-track report."""
        v_ned = body_to_ned_fast(roll, pitch, yaw, (b.vx, b.vy, b.vz))
        if b.valid:
            if self._t_good is not None:
                dt = b.t - self._t_good
                for i, v in enumerate((v_ned[1], v_ned[0], -v_ned[2])):
                    self._made_good[i] += v * dt
            self._t_good = b.t
        since_good = 0.0 if self._t_good is None else b.t - self._t_good
        rng = b.altitude_m if b.valid and b.altitude_m is not None else 0.0
        return [pd6_out.instrument_velocity(b.vx, b.vy, b.vz, b.fom_mps or 0.0, b.valid),
                pd6_out.ship_velocity(b.vx, b.vy, b.vz, b.valid),
                pd6_out.earth_velocity(*v_ned, b.valid),
                pd6_out.bottom_distance(*self._made_good, rng, since_good)]


# --------------------------------------------------------------------------- sinks


class Sink(Protocol):
    """Where frames go. ``t`` is the simulation time of the frame (s)."""

    def write(self, t: float, frame: bytes) -> None:
        """Send or store one frame of simulation time ``t`` (s); never blocks for long."""
        ...

    def close(self) -> None:
        """Release the file or socket."""
        ...


class TlogSink:
    """A MAVLink telemetry log (:class:`drivers.tlog.TlogWriter`): per frame, the receive
    time ``epoch_s + t`` as big-endian microseconds since the Unix epoch, then the frame."""

    def __init__(self, path: str | Path, epoch_s: float = DEFAULT_EPOCH_S) -> None:
        from onboard.drivers.tlog import TlogWriter

        self.path = Path(path)
        self.epoch_s = epoch_s
        self._w = TlogWriter(self.path)

    def write(self, t: float, frame: bytes) -> None:
        """Append the record ``[epoch_s + t as big-endian us][frame]``."""
        self._w.write(self.epoch_s + t, frame)

    def close(self) -> None:
        """Close the log."""
        self._w.close()


class FileSink:
    """Raw bytes to a file (an NMEA, DVL JSON or PD6 capture)."""

    def __init__(self, path: str | Path) -> None:
        self._f = open(path, "wb", buffering=1 << 16)

    def write(self, t: float, frame: bytes) -> None:
        """Append ``frame`` (``t`` is not stored)."""
        self._f.write(frame)

    def close(self) -> None:
        """Close the file."""
        self._f.close()


class UdpSink:
    """One datagram per frame to ``host:port`` (what ``mavutil`` calls ``udpin`` on the
    receiving side listens for)."""

    def __init__(self, host: str, port: int) -> None:
        self.addr = (host, port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.dropped = 0

    def read(self) -> bytes:
        """What the receiver sent back to this socket's port (never blocks)."""
        out = bytearray()
        while True:
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError, OSError):
                return bytes(out)
            out += data

    def write(self, t: float, frame: bytes) -> None:
        """Send ``frame`` as one datagram (a failed send is dropped and counted)."""
        try:
            self.sock.sendto(frame, self.addr)
        except OSError:  # nobody listening (ICMP refused) or buffer full: a lost datagram
            self.dropped += 1

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()


class TcpServerSink:
    """A TCP server on ``host:port`` (port 0 picks a free one, see :attr:`port`); every
    connected client receives every frame written after it connected. A client that
    cannot keep up or goes away is dropped; the simulation never blocks on it."""

    def __init__(self, host: str, port: int) -> None:
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind((host, port))
        self.server.listen(4)
        self.server.setblocking(False)
        self.port = self.server.getsockname()[1]
        self.clients: list[socket.socket] = []
        self.dropped = 0

    def accept(self) -> None:
        """Accept any pending connections (called on each write)."""
        while True:
            try:
                c, _ = self.server.accept()
            except (BlockingIOError, InterruptedError):
                return
            c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            c.settimeout(1.0)
            self.clients.append(c)

    def wait_for_client(self, timeout_s: float) -> bool:
        """Block up to ``timeout_s`` for a first client; True when one is connected."""
        if not self.clients:
            r, _, _ = select.select([self.server], [], [], timeout_s)
            if r:
                self.accept()
        return bool(self.clients)

    def read(self) -> bytes:
        """What the connected clients sent (never blocks)."""
        self.accept()
        out = bytearray()
        for c in list(self.clients):
            try:
                out += c.recv(65536, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:
                continue
        return bytes(out)

    def write(self, t: float, frame: bytes) -> None:
        """Send ``frame`` to every connected client, accepting new ones first; a client whose
        send fails is dropped and counted."""
        self.accept()
        for c in list(self.clients):
            try:
                c.sendall(frame)
            except OSError:
                self.dropped += 1
                self.clients.remove(c)
                c.close()

    def close(self) -> None:
        """Close every client and the listening socket."""
        for c in self.clients:
            c.close()
        self.server.close()


class PtySink:
    """A serial pseudo-terminal: frames go to the master side; readers open
    :attr:`path` (the slave, e.g. ``/dev/pts/5``) as they would a USB serial port.

    The slave is in raw mode (no echo, no newline translation). Writes never block: while
    nobody reads, whole frames beyond ``max_pending`` bytes are dropped and counted, as
    bytes are lost on a serial line nobody listens to; a frame is never cut.
    """

    def __init__(self, max_pending: int = 1 << 20, drain_s: float = 2.0) -> None:
        self.drain_s = drain_s
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self._slave)
        self._pending: deque[bytes] = deque()
        self._pending_bytes = 0
        self.max_pending = max_pending
        self.dropped = 0

    def flush(self) -> None:
        """Write as much pending data as the terminal takes now."""
        q = self._pending
        while q:
            head = q[0]
            try:
                n = os.write(self.master, head)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # slave side gone
                self.dropped += len(q)
                q.clear()
                self._pending_bytes = 0
                return
            self._pending_bytes -= n
            if n < len(head):
                q[0] = head[n:]
                return
            q.popleft()

    def write(self, t: float, frame: bytes) -> None:
        """Queue ``frame`` for the terminal and write what it takes now; a frame that does not
        fit within ``max_pending`` is dropped whole and counted."""
        if self._pending_bytes + len(frame) > self.max_pending:
            self.flush()
            if self._pending_bytes + len(frame) > self.max_pending:
                self.dropped += 1
                return
        self._pending.append(frame)
        self._pending_bytes += len(frame)
        self.flush()

    def read(self) -> bytes:
        """What the reader wrote to the terminal (never blocks)."""
        out = bytearray()
        while True:
            try:
                data = os.read(self.master, 65536)
            except (BlockingIOError, InterruptedError, OSError):
                return bytes(out)
            if not data:
                return bytes(out)
            out += data

    def unread(self) -> int:
        """Bytes written but not yet read by the other side (in the terminal's queue)."""
        buf = array.array("i", [0])
        try:
            fcntl.ioctl(self._slave, termios.FIONREAD, buf)
        except OSError:
            return 0
        return buf[0]

    def close(self, drain_s: float | None = None) -> None:
        """Give a reader up to ``drain_s`` seconds (default: the constructor's) to take
        what is pending (ours and the terminal's queue), then close."""
        deadline = time.monotonic() + (self.drain_s if drain_s is None else drain_s)
        self.flush()
        quiet = 0  # the terminal moves data to the slave asynchronously: see it empty twice
        while quiet < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
            self.flush()
            quiet = quiet + 1 if not (self._pending or self.unread()) else 0
        os.close(self.master)
        os.close(self._slave)


def open_link(url: str) -> Sink:
    """A sink from ``udp:HOST:PORT``, ``tcp:HOST:PORT`` or ``pty``; ValueError otherwise."""
    if url == "pty":
        return PtySink()
    kind, _, rest = url.partition(":")
    host, _, port = rest.rpartition(":")
    if kind not in ("udp", "tcp") or not host or not port.isdigit():
        raise ValueError(f"link must be udp:HOST:PORT, tcp:HOST:PORT or pty, got {url!r}")
    return UdpSink(host, int(port)) if kind == "udp" else TcpServerSink(host, int(port))


@dataclass
class Channel:
    """An encoder feeding one or more sinks; :meth:`emit` pushes one instant's samples."""

    encoder: MavlinkEncoder | NmeaEncoder | DvlJsonEncoder | Pd6Encoder
    sinks: list[Sink]

    def emit(self, t: float, samples: Sequence[Sample]) -> int:
        """Encode one instant's ``samples`` and write every frame to every sink; returns the
        number of frames."""
        frames = self.encoder.encode(samples)
        for f in frames:
            for s in self.sinks:
                s.write(t, f)
        return len(frames)

    def close(self) -> None:
        """Close every sink."""
        for s in self.sinks:
            s.close()
