"""The simulated autopilot's MAVLink side on a live link, as ArduPilot behaves.

What ArduPilot does (libraries/GCS_MAVLink/GCS_Common.cpp, GCS_MAVLink docs) and this
module reproduces:

* **Nothing but HEARTBEAT until asked.** The ``SRn_*`` stream rates of a USB or TELEM port
  default to 0 on a fresh board here (ArduPilot's defaults are 0-4 Hz depending on the
  port and vehicle; a companion computer cannot count on any of them), so a receiver that
  never asks gets 1 Hz heartbeats only.
* **COMMAND_LONG MAV_CMD_SET_MESSAGE_INTERVAL (511)**: ``param1`` message id, ``param2``
  interval in us; -1 stops the message, 0 restores its default (its group's ``SRn_*``
  rate), below 1000 us means 1 ms. Answered with COMMAND_ACK ACCEPTED, or FAILED for a
  message this autopilot does not stream.
* **REQUEST_DATA_STREAM** (legacy): sets every message of an ArduPilot stream group to
  ``req_message_rate`` Hz (``start_stop`` 0 stops them); no ACK. Groups
  (:data:`STREAM_GROUP_MESSAGES`): RAW_SENSORS (1) RAW_IMU, SCALED_IMU2/3,
  SCALED_PRESSURE/2/3; EXTENDED_STATUS (2) GPS_RAW_INT, GPS2_RAW; RC_CHANNELS (3)
  SERVO_OUTPUT_RAW, RC_CHANNELS; POSITION (6) GLOBAL_POSITION_INT; EXTRA1 (10)
  ATTITUDE, RPM; EXTRA2 (11) VFR_HUD; EXTRA3 (12) DISTANCE_SENSOR, SYSTEM_TIME. ArduPilot's
  first IMU goes out as RAW_IMU in RAW_SENSORS (same mg / mrad/s scaling as SCALED_IMU);
  SCALED_IMU is sent only when asked for by id.
* **TIMESYNC** with ``tc1`` 0 answered with ``tc1`` = the boot time in ns and the request's
  ``ts1``.
* **PARAM_REQUEST_READ / PARAM_REQUEST_LIST** answered with PARAM_VALUE (``SERVOn_FUNCTION``
  of the vehicle's outputs, ``FRAME_CLASS``, the ``SR0_*`` stream rates); an unknown name
  gets no answer.
* A message goes out on the first sensor sample at or after its next due time, due times
  spaced by its interval, from the samples the simulated sensors produce (a 50 Hz IMU asked
  at 20 Hz averages 20 Hz; asked faster than the sensor, at the sensor's rate).
* **GPS_RAW_INT at the rate asked, fix or not**: asked faster than the receiver gives
  fixes, the newest fix is sent again, its ``time_usec`` unchanged (2 of the ArduSub
  tlog's 528 fixes); with no fix for :data:`GNSS_LOST_S` (an outage, a dive), fix_type
  NO_FIX at the last fix's place and ``time_usec``, as ArduPilot keeps its receiver's last
  location and fix time (:meth:`sitl.emitters.MavlinkEncoder.gps_no_fix`).
* **Reboot** (:meth:`SimAutopilot.reboot`): silent for ``REBOOT_S``, then heartbeats
  again with ``time_boot_ms`` counting from the reboot and every stream off until asked
  again.
* **Other components on the link** (``others=True``): a ground station (system 255,
  component 190: HEARTBEAT MAV_TYPE_GCS) and a camera (the vehicle's system, component 100:
  HEARTBEAT MAV_TYPE_CAMERA, MAV_AUTOPILOT_INVALID) both send ATTITUDE, SCALED_IMU and
  GPS_RAW_INT look-alikes with wrong values, which a receiver must ignore.

Recorded logs (``--tlog``) do not go through this: a telemetry log is what a ground station
that asked for the streams records, so the simulator writes every message there.
``stream_unasked=True`` makes a live link stream everything unasked, as before.
"""

from __future__ import annotations

import math
from typing import Sequence

from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from pymavlink.generator.mavcrc import x25crc

from onboard.core.messages import GnssFix, Imu, Parameter, Sample, VehicleInfo
from onboard.sitl.emitters import DVL_DRIVER_COMPONENT, DVL_DRIVER_SYSTEM, MavlinkEncoder, Sink

REBOOT_S = 2.0
"""How long (s) the autopilot is silent while it reboots."""
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_GET_MESSAGE_INTERVAL = 510
MAV_RESULT_ACCEPTED = 0
MAV_RESULT_UNSUPPORTED = 3
MAV_RESULT_FAILED = 4
MAV_TYPE_GCS = 6
MAV_TYPE_CAMERA = 30
MAV_AUTOPILOT_INVALID = 8
MAV_PARAM_TYPE_INT8 = 2
MAV_PARAM_TYPE_INT16 = 4

STREAM_GROUP_MESSAGES: dict[int, tuple[str, ...]] = {
    1: ("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3", "SCALED_PRESSURE", "SCALED_PRESSURE2",
        "SCALED_PRESSURE3"),
    2: ("GPS_RAW_INT", "GPS2_RAW"),
    3: ("SERVO_OUTPUT_RAW", "RC_CHANNELS"),
    6: ("GLOBAL_POSITION_INT",),
    10: ("ATTITUDE", "RPM"),
    11: ("VFR_HUD",),
    12: ("DISTANCE_SENSOR", "SYSTEM_TIME"),
}
"""MAV_DATA_STREAM group -> the messages of it this simulator produces (ArduPilot's
``STREAM_*_msgs`` tables)."""
SR_PARAMS = {1: "SR0_RAW_SENS", 2: "SR0_EXT_STAT", 3: "SR0_RC_CHAN", 6: "SR0_POSITION",
             10: "SR0_EXTRA1", 11: "SR0_EXTRA2", 12: "SR0_EXTRA3"}
"""The stream-rate parameter of each group on port 0."""
_ID = {cls.msgname: mid for mid, cls in mavlink2.mavlink_map.items()}
STREAMABLE = {_ID[n] for ms in STREAM_GROUP_MESSAGES.values() for n in ms} | {
    _ID["SCALED_IMU"]}
"""Message ids this autopilot sends when asked (SCALED_IMU by id only). The DVL's
VISION_POSITION_DELTA is not one: the companion's DVL driver sends it, unasked, at the
DVL's rate (:data:`sitl.emitters.DVL_DRIVER_SYSTEM`)."""
MAVLINK2_HEADER_LEN = 10
"""Bytes of a MAVLink 2 frame before its payload (start byte to message id)."""
HEARTBEAT_ID = _ID["HEARTBEAT"]
SCALED_IMU_ID = _ID["SCALED_IMU"]
RAW_IMU_ID = _ID["RAW_IMU"]
SYSTEM_TIME_ID = _ID["SYSTEM_TIME"]
PARAM_VALUE_ID = _ID["PARAM_VALUE"]
GPS_RAW_INT_ID = _ID["GPS_RAW_INT"]
GNSS_LOST_S = 1.0
"""Without a new fix for this long (s) the receiver reports no fix: a receiver at 1-10 Hz
has then missed at least one epoch."""
RESEND_AFTER = 1.5
"""A GPS_RAW_INT due this many of its intervals after the newest fix is that fix sent
again: later than a fix on time (the receiver at the rate asked, its epochs jittered by
up to half an interval) would come."""
TOLERANCE_S = 1e-3
"""Slack when comparing a message's age with its interval (s): sample times are exact
multiples of the sensor periods up to float rounding."""


def _msgid(frame: bytes) -> int:
    """The message id of a MAVLink 2 frame."""
    return frame[7] | (frame[8] << 8) | (frame[9] << 16)


def _from_dvl_driver(frame: bytes) -> bool:
    """Whether a MAVLink 2 frame is the companion's DVL driver's, not the autopilot's."""
    return frame[5] == DVL_DRIVER_SYSTEM and frame[6] == DVL_DRIVER_COMPONENT


class SimAutopilot:
    """ArduPilot's stream negotiation on top of a :class:`MavlinkEncoder` (module docstring).

    ``emit(t, samples)`` replaces :meth:`sitl.emitters.Channel.emit` for a live link:
    it first reads what the receiver sent on the ``sinks`` (those with a ``read()``), then
    writes the frames due. ``frame_class`` is the ``FRAME_CLASS`` parameter (ArduRover: 2
    boat; ArduSub's frame is ``FRAME_CONFIG``, reported under the same name here).
    """

    def __init__(self, encoder: MavlinkEncoder, sinks: Sequence[Sink], *,
                 params: Sequence[Parameter] = (), frame_class: int = 2,
                 stream_unasked: bool = False, others: bool = False,
                 reboot_at: Sequence[float] = (), epoch_s: float | None = None,
                 message_interval: bool = True) -> None:
        self.enc = encoder
        self.message_interval = message_interval
        """False: firmware without SET_MESSAGE_INTERVAL (answered MAV_RESULT_UNSUPPORTED;
        only REQUEST_DATA_STREAM works)."""
        self.sinks = list(sinks)
        self.stream_unasked = stream_unasked
        self.others = others
        self.reboot_at = sorted(reboot_at)
        self.epoch_s = encoder.epoch_s if epoch_s is None else epoch_s
        self.params: dict[str, tuple[float, int]] = {
            p.name: (float(p.value), MAV_PARAM_TYPE_INT16) for p in params}
        self.params["FRAME_CLASS"] = (float(frame_class), MAV_PARAM_TYPE_INT8)
        self.params["SYSID_THISMAV"] = (float(encoder.mav.srcSystem), MAV_PARAM_TYPE_INT16)
        for name in SR_PARAMS.values():
            self.params[name] = (0.0, MAV_PARAM_TYPE_INT16)
        self.intervals: dict[int, float] = {}
        """Message id -> interval (s) asked for."""
        self._seq = 0
        """The sequence number of the autopilot's next frame sent (:meth:`_write`)."""
        self._last: dict[int, float] = {}
        """Message id -> when it is next due (s)."""
        self._fix: tuple[float, GnssFix, bytes] | None = None
        """(t, sample, frame) of the newest fix, sent or not."""
        self._gps_sent = -math.inf
        """When the newest GPS_RAW_INT went out (s)."""
        self._down_until = -math.inf
        self._rx = mavlink2.MAVLink(None)
        self._rx.robust_parsing = True
        self.frames = 0
        self.received: list[str] = []
        """Names of the messages the receiver sent (for tests)."""
        self.reboots = 0
        self._others = [mavlink2.MAVLink(None, srcSystem=255, srcComponent=190),
                        mavlink2.MAVLink(None, srcSystem=encoder.mav.srcSystem, srcComponent=100)]
        self._t_others = -math.inf
        self._t_hb_other = -math.inf

    # ------------------------------------------------------------------ receiving

    def poll(self, t: float) -> None:
        """Read and handle what the receiver sent (requests are ignored while rebooting)."""
        for sink in self.sinks:
            read = getattr(sink, "read", None)
            data = read() if read is not None else b""
            if not data:
                continue
            for msg in self._rx.parse_buffer(data) or []:
                if msg.get_type() == "BAD_DATA":
                    continue
                self.received.append(msg.get_type())
                if t >= self._down_until:
                    self._handle(t, msg)

    def _handle(self, t: float, msg) -> None:
        me_sys, me_comp = self.enc.mav.srcSystem, self.enc.mav.srcComponent
        typ = msg.get_type()
        target = (getattr(msg, "target_system", me_sys), getattr(msg, "target_component", me_comp))
        if target[0] not in (0, me_sys) or target[1] not in (0, me_comp):
            return
        if typ == "COMMAND_LONG" and msg.command == MAV_CMD_SET_MESSAGE_INTERVAL:
            self._ack(t, msg, self._set_interval(int(msg.param1), int(msg.param2))
                      if self.message_interval else MAV_RESULT_UNSUPPORTED)
        elif typ == "COMMAND_LONG" and msg.command == MAV_CMD_GET_MESSAGE_INTERVAL:
            mid = int(msg.param1)
            iv = self.intervals.get(mid)
            self._write(t, self._pack(self.enc.mav.message_interval_encode(
                mid, int(round(iv * 1e6)) if iv is not None else -1)))
            self._ack(t, msg, MAV_RESULT_ACCEPTED)
        elif typ == "COMMAND_LONG":   # what this autopilot does not model: said so
            self._ack(t, msg, MAV_RESULT_UNSUPPORTED)
        elif typ == "REQUEST_DATA_STREAM":
            groups = list(STREAM_GROUP_MESSAGES) if msg.req_stream_id == 0 else [msg.req_stream_id]
            for g in groups:
                for name in STREAM_GROUP_MESSAGES.get(g, ()):
                    mid = _ID[name]
                    if msg.start_stop and msg.req_message_rate > 0:
                        self.intervals[mid] = 1.0 / msg.req_message_rate
                    else:
                        self.intervals.pop(mid, None)
        elif typ == "PARAM_REQUEST_READ":
            name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
            names = list(self.params)
            if msg.param_index >= 0:
                name = names[msg.param_index] if msg.param_index < len(names) else ""
            if name in self.params:
                self._param(t, name)
        elif typ == "PARAM_REQUEST_LIST":
            for name in self.params:
                self._param(t, name)
        elif typ == "TIMESYNC" and msg.tc1 == 0:  # answered with our boot time in ns
            self._write(t, self._pack(self.enc.mav.timesync_encode(
                int(round((t - self.enc.boot_t0) * 1e9)), msg.ts1)))

    def _ack(self, t: float, msg, result: int) -> None:
        """COMMAND_ACK of ``msg``'s command with ``result``, to its sender."""
        self._write(t, self._pack(self.enc.mav.command_ack_encode(
            msg.command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())))

    def _set_interval(self, msgid: int, interval_us: int) -> int:
        if msgid not in STREAMABLE:
            return MAV_RESULT_FAILED
        if interval_us in (-1, 0):  # -1 stops; 0 is the group's SR0_* default, 0 Hz here
            self.intervals.pop(msgid, None)
        else:
            self.intervals[msgid] = max(interval_us, 1000) * 1e-6
        return MAV_RESULT_ACCEPTED

    def _param(self, t: float, name: str) -> None:
        value, ptype = self.params[name]
        names = list(self.params)
        self._write(t, self._pack(self.enc.mav.param_value_encode(
            name.encode("ascii")[:16], value, ptype, len(names), names.index(name))))

    # ------------------------------------------------------------------ sending

    def reboot(self, t: float) -> None:
        """Reboot at ``t``: silent for ``REBOOT_S``, boot clock from ``t``, streams off."""
        self.reboots += 1
        self._down_until = t + REBOOT_S
        self.intervals.clear()
        self._last.clear()
        self._fix = None
        self.enc.boot_t0 = t

    def emit(self, t: float, samples: Sequence[Sample]) -> int:
        """Handle requests, then send the frames of ``samples`` that are due at ``t``."""
        while self.reboot_at and t >= self.reboot_at[0]:
            self.reboot(self.reboot_at.pop(0))
        self.poll(t)
        if t < self._down_until:
            return 0
        n = 0
        for s in samples:
            if isinstance(s, Parameter):  # ArduPilot sends parameters only when asked
                if self.stream_unasked:
                    n += self._frames(t, self.enc.encode([s]))
                continue
            if isinstance(s, VehicleInfo):
                n += self._frames(t, self.enc.encode([s]))
                continue
            if isinstance(s, Imu):
                self.enc.raw_imu = RAW_IMU_ID in self.intervals and SCALED_IMU_ID not in self.intervals
            for f in self.enc.encode([s]):
                mid = _msgid(f)
                if isinstance(s, GnssFix) and mid == GPS_RAW_INT_ID:
                    self._fix = (t, s, f)
                if _from_dvl_driver(f) or self._due(t, mid):
                    self._write(t, f)
                    n += 1
                    if mid == GPS_RAW_INT_ID:
                        self._gps_sent = t
        n += self._gps_between_fixes(t)
        if self._due(t, SYSTEM_TIME_ID):
            self._write(t, self._pack(self.enc.mav.system_time_encode(
                int(round((self.epoch_s + t) * 1e6)),
                int(round((t - self.enc.boot_t0) * 1000.0)) & 0xFFFFFFFF)))
            n += 1
        if self.others:
            n += self._emit_others(t)
        return n

    def _gps_between_fixes(self, t: float) -> int:
        """GPS_RAW_INT when due without a new fix (module docstring): the newest fix sent
        again, or NO_FIX :data:`GNSS_LOST_S` after it; the number of frames sent."""
        iv = self.intervals.get(GPS_RAW_INT_ID)
        if iv is None or self._fix is None or self.stream_unasked:
            return 0
        t_fix, _, frame = self._fix
        if t - t_fix < RESEND_AFTER * iv or t - self._gps_sent < iv - TOLERANCE_S:
            return 0
        if t - t_fix >= GNSS_LOST_S:
            frame = self.enc.gps_no_fix()
        self._write(t, frame)
        self._gps_sent = t
        return 1

    def _due(self, t: float, msgid: int) -> bool:
        if self.stream_unasked and msgid != SYSTEM_TIME_ID:
            return True
        iv = self.intervals.get(msgid)
        if iv is None:
            return False
        due = self._last.get(msgid)
        if due is not None and t < due - TOLERANCE_S:
            return False
        # keep the phase, so the average rate is the asked one when the interval is not a
        # multiple of the sensor period; start afresh after a gap longer than an interval
        self._last[msgid] = due + iv if due is not None and t - due < iv else t + iv
        return True

    def _frames(self, t: float, frames: list[bytes]) -> int:
        for f in frames:
            self._write(t, f)
        return len(frames)

    def _pack(self, msg) -> bytes:
        buf = msg.pack(self.enc.mav)
        self.enc.mav.seq = (self.enc.mav.seq + 1) % 256
        return buf

    def _write(self, t: float, frame: bytes) -> None:
        mav = self.enc.mav
        if frame[5] == mav.srcSystem and frame[6] == mav.srcComponent:
            frame = self._sequenced(frame)
        self.frames += 1
        for s in self.sinks:
            s.write(t, frame)

    def _sequenced(self, frame: bytes) -> bytes:
        """The autopilot's (unsigned MAVLink 2) ``frame`` with the sequence number of the
        frames it has sent, its checksum made again: the encoder numbers every frame it
        packs, those not due too, and a receiver would count the numbers skipped as lost
        (ArduSub's own tlog of ../shared/data has no gap in 32,584 frames)."""
        out = bytearray(frame)
        out[4] = self._seq
        self._seq = (self._seq + 1) % 256
        end = MAVLINK2_HEADER_LEN + out[1]
        crc = x25crc(out[1:end])
        crc.accumulate(bytes([mavlink2.mavlink_map[_msgid(frame)].crc_extra]))
        out[end:end + 2] = crc.crc.to_bytes(2, "little")
        return bytes(out)

    def _emit_others(self, t: float) -> int:
        """The ground station's and the camera's frames: HEARTBEAT at 1 Hz, look-alike
        ATTITUDE (yaw 2 rad, rolling), SCALED_IMU (1 g sideways) and GPS_RAW_INT (1 km off)
        at 10 Hz."""
        if t - self._t_others < 0.1 - TOLERANCE_S:
            return 0
        self._t_others = t
        n = 0
        ms = int(round((t - self.enc.boot_t0) * 1000.0)) & 0xFFFFFFFF
        hb = t - self._t_hb_other >= 1.0 - TOLERANCE_S
        if hb:
            self._t_hb_other = t
        for k, mav in enumerate(self._others):
            msgs = []
            if hb:
                msgs.append(mav.heartbeat_encode(MAV_TYPE_GCS if k == 0 else MAV_TYPE_CAMERA,
                                                 MAV_AUTOPILOT_INVALID, 0, 0, 4, 3))
            msgs.append(mav.attitude_encode(ms + 5000 * k, 0.5, -0.4, 2.0, 1.0, 1.0, 1.0))
            msgs.append(mav.scaled_imu_encode(ms, 0, 1000, 0, 500, 500, 500, 0, 0, 0, 2000))
            msgs.append(mav.gps_raw_int_encode(int(round((self.epoch_s + t) * 1e6)), 3,
                                               int(round((self.enc.origin[0] + 0.01) * 1e7)),
                                               int(round((self.enc.origin[1] + 0.01) * 1e7)),
                                               0, 100, 65535, 300, 9000, 10, 0, 500, 500, 0, 0, 0))
            for m in msgs:
                buf = m.pack(mav)
                mav.seq = (mav.seq + 1) % 256
                self._write(t, buf)
                n += 1
        return n

    def close(self) -> None:
        """Close the sinks."""
        for s in self.sinks:
            s.close()
