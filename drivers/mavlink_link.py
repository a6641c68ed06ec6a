"""The autopilot on a MAVLink link: which component it is, its boot clock, what it sends.

A :class:`drivers.mavlink.MavlinkParser` given a :class:`AutopilotLink` shows it every
CRC-checked frame before decoding it. The link

* **finds the autopilot** by its HEARTBEAT: the first heartbeat whose type is not
  MAV_TYPE_GCS (6) and whose autopilot is not MAV_AUTOPILOT_INVALID (8) locks the link
  to that system and component (``target_system`` / ``target_component`` when
  configured). Before the lock, frames of component 1 (MAV_COMP_ID_AUTOPILOT1) of any
  system but 255 are decoded; after it, only the locked component's. Every other frame (a
  ground station at system 255, a camera or gimbal component, a companion computer's own
  component 191 echoed back by a router) is counted in :attr:`ignored` and its samples
  are dropped: they are look-alikes, not the vehicle's sensors. The exception are the
  messages a companion computer's driver sends *to* the autopilot
  (:data:`COMPANION_INPUT_IDS`: a DVL's VISION_POSITION_DELTA, which BlueOS's Water
  Linked DVL extension posts through mavlink2rest as system 255, component 0): the
  autopilot never sends them, so they are taken from whichever sender sends them,
  stamped on arrival and counted in :attr:`companion`.
* **maps the autopilot's boot clock to the receiver's clock**: ``time_boot_ms`` (or the
  microseconds since boot of SERVO_OUTPUT_RAW / RAW_IMU / HIGHRES_IMU) plus a filtered
  offset, which stamps the samples with the time they were measured instead of the time
  they arrived (:class:`.sender_clock.SenderClock`); TIMESYNC answers to the session's
  requests remove the remaining one-way delay;
* **detects reboots** (the boot clock going back by more than
  :data:`.sender_clock.REBOOT_BACK_S`) and boot clock jumps, counted in :attr:`reboots`
  and :attr:`clock_jumps` for the service's MAVLink session, which re-requests its
  streams after a reboot;
* **counts** the frames of each message id from the autopilot (:attr:`counts`, for the
  requested-versus-received rates) and keeps the COMMAND_ACKs and parameters it sent.

Everything here is a function of the bytes and their receive times only, so a replay of a
recording through the same parser reproduces the live stamps and filtering exactly.
"""

from __future__ import annotations

import struct
from collections import Counter, deque
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as _dialect

from onboard.drivers.sender_clock import SenderClock

MAV_TYPE_GCS = 6
MAV_AUTOPILOT_INVALID = 8
MAV_COMP_ID_AUTOPILOT1 = 1
GCS_SYSTEM_ID = 255
"""The system id ground stations use by convention (Mission Planner, QGC, MAVProxy)."""
HEARTBEAT_ID = 0
COMMAND_ACK_ID = 77
PARAM_VALUE_ID = 22
TIMESYNC_ID = 111
COMPANION_INPUT_IDS = frozenset({_dialect.MAVLINK_MSG_ID_VISION_POSITION_DELTA})
"""Messages a companion computer's sensor driver sends to the autopilot, taken from any
sender (the module docstring): the vehicle's own sensors, though not from the autopilot."""
def _boot_fields() -> dict[int, tuple[int, str, float]]:
    """message id -> (byte offset in the payload, struct code, seconds per unit) of the
    message's time-since-boot field, from pymavlink's wire layout."""
    out: dict[int, tuple[int, str, float]] = {}
    spec = {"ATTITUDE": "time_boot_ms", "SCALED_IMU": "time_boot_ms",
            "SCALED_IMU2": "time_boot_ms", "SCALED_IMU3": "time_boot_ms",
            "GLOBAL_POSITION_INT": "time_boot_ms", "SCALED_PRESSURE": "time_boot_ms",
            "SCALED_PRESSURE2": "time_boot_ms", "SCALED_PRESSURE3": "time_boot_ms",
            "SYSTEM_TIME": "time_boot_ms", "RC_CHANNELS": "time_boot_ms",
            "DISTANCE_SENSOR": "time_boot_ms", "SERVO_OUTPUT_RAW": "time_usec",
            "RAW_IMU": "time_usec", "HIGHRES_IMU": "time_usec"}
    for name, fname in spec.items():
        cls = getattr(_dialect, f"MAVLink_{name.lower()}_message")
        fmt = cls.unpacker.format.lstrip("<")
        codes = [c for c in _tokens(fmt)]
        off = 0
        for (count, code), fn in zip(codes, cls.ordered_fieldnames):
            if fn == fname:
                scale = 1e-3 if fname == "time_boot_ms" else 1e-6
                out[cls.id] = (off, code, scale)
                break
            off += struct.calcsize(f"<{count}{code}")
    return out


def _tokens(fmt: str) -> list[tuple[str, str]]:
    import re

    return re.findall(r"(\d*)([a-zA-Z?])", fmt)


BOOT_TIME_FIELDS = _boot_fields()
"""Message id -> (offset, struct code, scale) of its time since the autopilot booted."""
_WRAP_US = 2 ** 32 * 1e-6
"""SERVO_OUTPUT_RAW's 32-bit microseconds wrap every 71.6 minutes (s)."""


@dataclass
class AutopilotLink:
    """The autopilot seen on one MAVLink input (see the module docstring).

    ``target_system`` / ``target_component``: 0 = the first autopilot heard.
    ``stamp_boot_time``: stamp samples with the mapped boot time (else their receive time).
    ``filter_components``: drop the frames of other systems and components.
    """

    target_system: int = 0
    target_component: int = 0
    stamp_boot_time: bool = True
    filter_components: bool = True
    """False: every component's frames are decoded (the autopilot is still found and
    counted)."""
    system_id: int | None = None
    """The autopilot's system id, once found."""
    component_id: int | None = None
    mav_type: int | None = None
    autopilot: int | None = None
    t_heartbeat: float | None = None
    """Receive time of its last HEARTBEAT (s)."""
    heartbeats: int = 0
    counts: Counter[int] = field(default_factory=Counter)
    """Frames from the autopilot per message id."""
    ignored: Counter[str] = field(default_factory=Counter)
    """Frames of other systems and components, by ``"<sysid>.<compid>"``."""
    companion: Counter[str] = field(default_factory=Counter)
    """Frames of :data:`COMPANION_INPUT_IDS` taken from other senders, by
    ``"<sysid>.<compid>"``."""
    acks: deque[tuple[int, int]] = field(default_factory=lambda: deque(maxlen=64))
    """(command, result) of the autopilot's COMMAND_ACKs, oldest first (the session
    consumes them)."""
    params: dict[str, float] = field(default_factory=dict)
    """The parameters it sent (PARAM_VALUE), by name."""
    clock: SenderClock = field(default_factory=SenderClock)
    t_last: float | None = None
    """Receive time of the last frame from the autopilot (s)."""
    _last_stamp: dict[int, float] = field(default_factory=dict)

    @property
    def found(self) -> bool:
        """True once the autopilot's HEARTBEAT was heard."""
        return self.system_id is not None

    @property
    def reboots(self) -> int:
        """Reboots seen (the boot clock went back)."""
        return self.clock.reboots

    def accept(self, sysid: int, compid: int, msgid: int, buf, start: int, plen: int,
               t_rx: float) -> float | None:
        """Whether to decode a frame: its sample time (s) if it is the autopilot's, else
        None (counted in :attr:`ignored`). ``buf[start:start+plen]`` is its payload."""
        if msgid == HEARTBEAT_ID and not self.found:
            self._maybe_lock(sysid, compid, buf, start, plen)
        if self.found:
            mine = sysid == self.system_id and compid == self.component_id
        elif self.target_system:
            mine = sysid == self.target_system and compid == (self.target_component or MAV_COMP_ID_AUTOPILOT1)
        else:
            mine = sysid != GCS_SYSTEM_ID and compid == MAV_COMP_ID_AUTOPILOT1
        if not mine:
            if not self.filter_components:
                return t_rx
            if msgid in COMPANION_INPUT_IDS:
                self.companion[f"{sysid}.{compid}"] += 1
                return t_rx
            self.ignored[f"{sysid}.{compid}"] += 1
            return None
        self.counts[msgid] += 1
        self.t_last = t_rx
        if msgid == HEARTBEAT_ID:
            self.t_heartbeat = t_rx
            self.heartbeats += 1
        elif msgid == TIMESYNC_ID and plen >= 8:
            raw = bytes(buf[start:start + plen]) + bytes(max(0, 16 - plen))
            tc1, ts1 = struct.unpack_from("<qq", raw)
            if tc1 > 0:
                self.clock.timesync(tc1 * 1e-9, ts1 * 1e-9, t_rx)
        elif msgid == COMMAND_ACK_ID and plen >= 3:
            cmd = buf[start] | (buf[start + 1] << 8)
            self.acks.append((cmd, buf[start + 2]))
        f = BOOT_TIME_FIELDS.get(msgid)
        if f is None:
            return t_rx
        off, code, scale = f
        size = 8 if code == "Q" else 4
        if plen < off + size:
            return t_rx  # zero-truncated: no boot time in this frame
        raw = (int.from_bytes(bytes(buf[start + off:start + off + size]), "little"))
        boot = raw * scale
        if code == "I" and scale == 1e-6:
            boot = self._unwrap_us(boot)
        t = self.clock.update(boot, t_rx)
        if not self.stamp_boot_time:
            return t_rx
        last = self._last_stamp.get(msgid)
        if last is not None and t < last:
            t = last  # the offset fell by more than a sample period: keep the stream in order
        t = min(t, t_rx)
        self._last_stamp[msgid] = t
        return t

    def _unwrap_us(self, boot: float) -> float:
        """A 32-bit microsecond boot time made whole with the millisecond clock."""
        ref = self.clock.last_boot
        if ref is None or ref < _WRAP_US:
            return boot
        k = round((ref - boot) / _WRAP_US)
        return boot + k * _WRAP_US

    def _maybe_lock(self, sysid: int, compid: int, buf, start: int, plen: int) -> None:
        # HEARTBEAT wire order: custom_mode (u32), type, autopilot, base_mode, ...
        if plen < 6:
            return
        typ, ap = buf[start + 4], buf[start + 5]
        if typ == MAV_TYPE_GCS or ap == MAV_AUTOPILOT_INVALID:
            return
        if self.target_system and sysid != self.target_system:
            return
        if self.target_component and compid != self.target_component:
            return
        if not self.target_component and compid != MAV_COMP_ID_AUTOPILOT1:
            return
        self.system_id, self.component_id = sysid, compid
        self.mav_type, self.autopilot = typ, ap

    def note_param(self, name: str, value: float) -> None:
        """Record a parameter the autopilot sent."""
        self.params[name] = value

    def reset_streams(self) -> None:
        """Forget the stamps of the streams (after a reboot the boot clock restarts)."""
        self._last_stamp.clear()
