"""A sender's clock mapped to the receiver's: stamps for the time a sample was measured.

An autopilot stamps its MAVLink messages with its time since boot, a Water Linked DVL its
reports with its own Unix time (``time_of_validity``). Neither clock is ours, and a frame
arrives a transport delay after it was stamped; :class:`SenderClock` maps the sender's
time to ours through the least-delayed frame seen, so that a sample is stamped with the
time it was measured, not the time it arrived after a varying delay.

Everything here is a function of the stamps and their receive times only, so a replay of a
recording reproduces the live stamps exactly.
"""

from __future__ import annotations

MAX_SYNC_RTT_S = 0.5
"""A TIMESYNC round trip longer than this (s) is not used."""

REBOOT_BACK_S = 1.0
"""The sender's clock going back by more than this (s) is a reboot (or a clock step)."""
JUMP_S = 1.0
"""A receive-minus-sender offset this far (s) below the filtered one is a clock jump; this far
above it for longer than ``JUMP_PERSIST_S`` too (a link delay never lasts that long)."""
JUMP_PERSIST_S = 3.0
SYNC_KEEP_S = 30.0
"""How long (s) the best TIMESYNC exchange is kept before a worse one replaces it."""
DRIFT_PPM = 200.0
"""How fast (parts per million) the filtered offset may grow: crystal drift of the two
clocks (ArduPilot boards: < 50 ppm; a DVL on NTP: less) with margin; a smaller transport
delay lowers it at once."""


class SenderClock:
    """A sender's clock (s: an autopilot's boot time, a DVL's Unix time) -> receiver time
    (s) with a filtered offset.

    Each frame with a sender time ``b`` received at ``t_rx`` gives ``t_rx - b``: the offset
    plus the transport delay, which is never negative. The filter keeps the smallest seen
    (the least-delayed frame), allowed to grow at ``DRIFT_PPM`` so that it follows the
    two crystals' drift; a mapped time ``b + offset`` is therefore never later than the
    frame's arrival and is earlier by the delay beyond the smallest one. A reboot (sender
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
        """Take a sender time and its receive time; return the mapped time (s)."""
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
