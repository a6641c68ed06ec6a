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
  are dropped: they are look-alikes, not the vehicle's sensors.
* **maps the autopilot's boot clock to the receiver's clock**: ``time_boot_ms`` (or the
  microseconds since boot of SERVO_OUTPUT_RAW / RAW_IMU / HIGHRES_IMU) plus a filtered
  offset, which stamps the samples with the time they were measured instead of the time
  they arrived (:class:`BootClock`); TIMESYNC answers to the session's requests remove
  the remaining one-way delay;
* **detects reboots** (the boot clock going back by more than ``REBOOT_BACK_S``) and boot
  clock jumps, counted in :attr:`reboots` and :attr:`clock_jumps` for the service's
  MAVLink session, which re-requests its streams after a reboot;
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

MAV_TYPE_GCS = 6
MAV_AUTOPILOT_INVALID = 8
MAV_COMP_ID_AUTOPILOT1 = 1
GCS_SYSTEM_ID = 255
"""The system id ground stations use by convention (Mission Planner, QGC, MAVProxy)."""
HEARTBEAT_ID = 0
COMMAND_ACK_ID = 77
PARAM_VALUE_ID = 22
TIMESYNC_ID = 111
MAX_SYNC_RTT_S = 0.5
"""A TIMESYNC round trip longer than this (s) is not used."""

REBOOT_BACK_S = 1.0
"""The boot clock going back by more than this (s) is a reboot."""
JUMP_S = 1.0
"""A receive-minus-boot offset this far (s) below the filtered one is a clock jump; this far
above it for longer than ``JUMP_PERSIST_S`` too (a link delay never lasts that long)."""
JUMP_PERSIST_S = 3.0
SYNC_KEEP_S = 30.0
"""How long (s) the best TIMESYNC exchange is kept before a worse one replaces it."""
DRIFT_PPM = 200.0
"""How fast (parts per million) the filtered offset may grow: crystal drift of the two
clocks (ArduPilot boards: < 50 ppm) with margin; a smaller transport delay lowers it at
once."""


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


class BootClock:
    """Autopilot boot time (s) -> receiver time (s) with a filtered offset.

    Each frame with a boot time ``b`` received at ``t_rx`` gives ``t_rx - b``: the offset
    plus the transport delay, which is never negative. The filter keeps the smallest seen
    (the least-delayed frame), allowed to grow at ``DRIFT_PPM`` so that it follows the
    two crystals' drift; a mapped time ``b + offset`` is therefore never later than the
    frame's arrival and is earlier by the delay beyond the smallest one. A reboot (boot
    time back by more than ``REBOOT_BACK_S``) or a jump (see ``JUMP_S``) re-anchors it.
    """

    def __init__(self) -> None:
        self.offset: float | None = None
        self.sync: tuple[float, float, float] | None = None
        """(offset, round trip, receive time) of the best recent TIMESYNC exchange (s)."""
        self.t_update: float = 0.0
        self.last_boot: float | None = None
        self.reboots = 0
        self.jumps = 0
        self._t_above: float | None = None

    def update(self, boot_s: float, t_rx: float) -> float:
        """Take a boot time and its receive time; return the mapped time (s)."""
        raw = t_rx - boot_s
        off = self.offset
        last = self.last_boot
        if last is not None and boot_s < last - REBOOT_BACK_S:
            self.reboots += 1
            off = None
            self.sync = None
        self.last_boot = boot_s if last is None or off is None else max(last, boot_s)
        if off is None:
            off = raw
            self._t_above = None
        else:
            grown = off + DRIFT_PPM * 1e-6 * max(0.0, t_rx - self.t_update)
            if raw < off - JUMP_S:
                self.jumps += 1
                off = raw
            elif raw > grown + JUMP_S:
                if self._t_above is None:
                    self._t_above = t_rx
                elif t_rx - self._t_above > JUMP_PERSIST_S:
                    self.jumps += 1
                    off = raw
                    self._t_above = None
            else:
                self._t_above = None
                off = min(raw, grown)
        self.offset = off
        self.t_update = t_rx
        sync = self.sync
        if sync is not None and off is not None and sync[0] <= off + 1e-3:
            return boot_s + sync[0]
        return boot_s + off

    def timesync(self, tc1_s: float, ts1_s: float, t_rx: float) -> None:
        """A TIMESYNC answer: the autopilot's boot time ``tc1_s`` when it answered our
        request sent at ``ts1_s`` (our clock), received at ``t_rx``. With a symmetric
        link, the offset is ``ts1 + rtt/2 - tc1``: the least-delay estimate without the
        one-way delay. The exchange with the shortest round trip of the last ``SYNC_KEEP_S``
        is used; a reboot forgets it."""
        rtt = t_rx - ts1_s
        if not 0.0 <= rtt <= MAX_SYNC_RTT_S:
            return
        if self.last_boot is not None and tc1_s < self.last_boot - REBOOT_BACK_S:
            return  # an answer from before a reboot
        est = ts1_s + 0.5 * rtt - tc1_s
        old = self.sync
        if old is None or rtt <= old[1] or t_rx - old[2] > SYNC_KEEP_S:
            self.sync = (est, rtt, t_rx)


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
    acks: deque[tuple[int, int]] = field(default_factory=lambda: deque(maxlen=64))
    """(command, result) of the autopilot's COMMAND_ACKs, oldest first (the session
    consumes them)."""
    params: dict[str, float] = field(default_factory=dict)
    """The parameters it sent (PARAM_VALUE), by name."""
    clock: BootClock = field(default_factory=BootClock)
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
