"""MAVLink 2 message signing: verification of incoming frames.

Reference: the MAVLink signing specification, https://mavlink.io/en/guide/message_signing.html
(and pymavlink's ``MAVLink.check_signature``, which it refines: the stream timestamp is
updated only after the signature is found valid, so a forged frame cannot poison it).

A signed frame (incompatibility flag ``0x01``) carries 13 bytes after its CRC::

    link_id (1 B) | timestamp (6 B, little-endian, 10 us units since 2015-01-01 UTC) | signature (6 B)

    signature = first 48 bits of SHA-256(secret_key + header + payload + CRC + link_id + timestamp)

where ``header`` starts at the start byte ``0xFD``. Timestamps must increase on every
*stream*, the tuple (link id, system id, component id). :class:`SignatureVerifier` keeps the
last accepted timestamp of each stream and rejects, with a reason the parser counts:

===============  =============================================================================
``unsigned``     a MAVLink 1 frame or a MAVLink 2 frame without the signed flag
``signature``    the 48-bit signature does not match (wrong key, or bytes altered)
``sig_replay``   the timestamp is not newer than the last accepted one of its stream (a replay)
``sig_stale``    the first frame of a stream is more than one minute (6,000,000 units) behind
                 the local timestamp (the spec's rule for new streams)
``sig_future``   the timestamp is more than ``max_future_s`` ahead of the local timestamp
                 (only when ``max_future_s > 0``; the spec sets no bound)
===============  =============================================================================

The *local timestamp* is the largest of the wall clock, every accepted incoming timestamp
and :attr:`SignatureVerifier.high` (which the owner raises to the persisted and sent
timestamps), as the spec asks for systems without a reliable clock.

Exact replay. The verdicts depend on the key, the wall clock and the streams table, none
of which a replay has. So the service records them instead: :class:`VerdictLog` wraps the
live verifier of one input and notes which frames of each chunk it rejected and why; the
recorder writes that as a ``verdicts`` record right after the chunk
(:class:`drivers.verdicts.Verdicts`); on replay :class:`VerdictPlayer` stands in for the
verifier and rejects exactly those frames under the same reasons, without the key.
"""

from __future__ import annotations

import hashlib
import hmac
import time
import zlib
from typing import TYPE_CHECKING, Callable, Protocol

from onboard.drivers.mavlink_frame import IFLAG_SIGNED, SIGNATURE_LEN
from onboard.drivers.verdicts import Verdicts

if TYPE_CHECKING:
    from onboard.drivers.base import ReadStats

SIGNING_EPOCH = 1420070400
"""MAVLink signing timestamps count 10 us units from 2015-01-01T00:00:00Z (POSIX s)."""
TIMESTAMP_UNITS_PER_S = 100_000
"""Signing timestamp units (10 us) per second."""
NEW_STREAM_MAX_AGE = 6_000_000
"""A new stream's first timestamp may lag the local timestamp by at most one minute."""
_SIGNATURE_AT = 7
"""Offset of the 6-byte signature in the signature block, after the link id and the
6-byte timestamp."""

REASONS = frozenset(("unsigned", "signature", "sig_replay", "sig_stale", "sig_future"))
"""Every reason :meth:`SignatureVerifier.check` gives."""

StreamKey = tuple[int, int, int]
"""(link id, system id, component id)."""


class FrameVerifier(Protocol):
    """What a MAVLink parser asks of its verifier: :class:`SignatureVerifier` live, the
    :class:`VerdictLog` around it that notes its rejections, :class:`VerdictPlayer` in a
    replay."""

    def check(self, buf: bytes | bytearray, start: int, crc_end: int, sysid: int,
              compid: int, inc_flags: int) -> str | None:
        """None if the frame is accepted, else the rejection reason."""


def signing_timestamp(unix_s: float) -> int:
    """The signing timestamp (10 us units since 2015-01-01 UTC) of a POSIX time (s)."""
    return int((unix_s - SIGNING_EPOCH) * TIMESTAMP_UNITS_PER_S)


class SignatureVerifier:
    """Checks the signature and timestamp of every frame (see the module docstring).

    Parameters:
        key: the 32-byte shared secret.
        streams: last accepted timestamp per (link id, system id, component id), e.g.
            restored from disk; kept and updated in place.
        high: a floor for the local timestamp (persisted or sent timestamps).
        max_future_s: reject timestamps more than this far ahead of the local timestamp
            (s); 0 disables the check.
        wall: the wall clock (POSIX s).
        on_accept: called after every accepted frame (the owner persists the streams).
    """

    __slots__ = ("_h0", "streams", "high", "max_future", "wall", "on_accept", "accepted")

    def __init__(self, key: bytes, *, streams: dict[StreamKey, int] | None = None,
                 high: int = 0, max_future_s: float = 0.0,
                 wall: Callable[[], float] = time.time,
                 on_accept: Callable[[], None] | None = None) -> None:
        if len(key) != 32:
            raise ValueError(f"a MAVLink signing key has 32 bytes, not {len(key)}")
        self._h0 = hashlib.sha256(key)
        self.streams: dict[StreamKey, int] = {} if streams is None else streams
        self.high = high
        self.max_future = int(max_future_s * TIMESTAMP_UNITS_PER_S)
        self.wall = wall
        self.on_accept = on_accept
        self.accepted = 0

    def local_timestamp(self) -> int:
        """max(wall clock, every accepted or persisted timestamp), in signing units."""
        return max(signing_timestamp(self.wall()), self.high)

    def check(self, buf: bytes | bytearray, start: int, crc_end: int, sysid: int,
              compid: int, inc_flags: int) -> str | None:
        """None if the CRC-valid frame ``buf[start:crc_end + SIGNATURE_LEN]`` is correctly
        signed and fresh (its stream timestamp is then advanced); else the rejection reason.

        ``crc_end`` is the index just past the frame's CRC; ``inc_flags`` its
        incompatibility flags (0 for MAVLink 1).
        """
        if not inc_flags & IFLAG_SIGNED:
            return "unsigned"
        h = self._h0.copy()
        sig = crc_end + _SIGNATURE_AT
        h.update(buf[start:sig])
        if not hmac.compare_digest(h.digest()[:6], bytes(buf[sig:crc_end + SIGNATURE_LEN])):
            return "signature"
        link = buf[crc_end]
        ts = int.from_bytes(buf[crc_end + 1:sig], "little")
        key = (link, sysid, compid)
        last = self.streams.get(key)
        if last is not None:
            if ts <= last:
                return "sig_replay"
        elif ts + NEW_STREAM_MAX_AGE < self.local_timestamp():
            return "sig_stale"
        if self.max_future and ts > self.local_timestamp() + self.max_future:
            return "sig_future"
        self.streams[key] = ts
        if ts > self.high:
            self.high = ts
        self.accepted += 1
        if self.on_accept is not None:
            self.on_accept()
        return None


def _frame_crc(buf: bytes | bytearray, crc_end: int) -> int:
    """The CRC-16 field of the frame whose CRC ends at ``crc_end``."""
    return buf[crc_end - 2] | (buf[crc_end - 1] << 8)


class VerdictLog:
    """Wraps the live verifier of one input and notes its rejections, chunk by chunk.

    Used as the parser's verifier (same ``check``); :meth:`take` after each chunk returns
    its :class:`~drivers.verdicts.Verdicts` (None when every frame was accepted) and starts
    the next chunk.
    """

    __slots__ = ("checks", "rejected", "verifier")

    def __init__(self, verifier: SignatureVerifier) -> None:
        self.verifier = verifier
        self.checks = 0
        self.rejected: list[tuple[int, str, int]] = []

    def check(self, buf: bytes | bytearray, start: int, crc_end: int, sysid: int,
              compid: int, inc_flags: int) -> str | None:
        """The live verifier's verdict (:meth:`SignatureVerifier.check`), noting a rejection
        with the frame's index in the chunk and its CRC-16."""
        reason = self.verifier.check(buf, start, crc_end, sysid, compid, inc_flags)
        if reason is not None:
            self.rejected.append((self.checks, reason, _frame_crc(buf, crc_end)))
        self.checks += 1
        return reason

    def take(self, chunk: bytes) -> Verdicts | None:
        """The verdicts of the chunk ``chunk`` just parsed (None: nothing rejected)."""
        out = None
        if self.rejected:
            out = Verdicts(zlib.crc32(chunk), self.checks, self.rejected)
            self.rejected = []
        self.checks = 0
        return out


class VerdictPlayer:
    """The verifier of a replay: rejects the frames the live verifier rejected.

    :meth:`load` before each chunk with the chunk's recorded verdicts (None: every frame
    was accepted live). A frame whose CRC-16 is not the recorded one, or a chunk whose
    number of frames differs from the recorded one, means the replay no longer follows the
    recording (a damaged recording): the frame is rejected as ``verdict_mismatch`` rather
    than accepted, and :meth:`done` counts a chunk mismatch the same way. Verdicts that no
    live verifier writes are damaged too: a reason not in :data:`REASONS` rejects its frame
    as ``verdict_mismatch``; an index listed twice or outside the recorded number of frames
    is a chunk mismatch.
    """

    __slots__ = ("checks", "expected", "rejected", "bad")

    def __init__(self) -> None:
        self.checks = 0
        self.expected: int | None = None
        self.rejected: dict[int, tuple[str, int]] | None = None
        self.bad = False

    def load(self, verdicts: Verdicts | None) -> None:
        """Take the recorded verdicts of the chunk about to be parsed (None: every frame was
        accepted live)."""
        self.checks = 0
        if verdicts is None:
            self.expected = self.rejected = None
            self.bad = False
        else:
            self.expected = n = verdicts.checks
            self.rejected = {int(i): (reason if reason in REASONS else "verdict_mismatch",
                                      int(crc)) for i, reason, crc in verdicts.rejected}
            self.bad = (len(self.rejected) != len(verdicts.rejected)
                        or any(not 0 <= i < n for i in self.rejected))

    def check(self, buf: bytes | bytearray, start: int, crc_end: int, sysid: int,
              compid: int, inc_flags: int) -> str | None:
        """The recorded verdict of the next frame of the chunk: None (accepted), its recorded
        reason, or ``verdict_mismatch`` when the frame's CRC-16 is not the recorded one."""
        k = self.checks
        self.checks = k + 1
        if self.rejected is None:
            return None
        r = self.rejected.get(k)
        if r is None:
            return None
        return r[0] if r[1] == _frame_crc(buf, crc_end) else "verdict_mismatch"

    def done(self, stats: ReadStats) -> None:
        """After the chunk: count ``verdict_mismatch`` in ``stats`` if it held a different
        number of frames than live, or its verdicts were inconsistent (see the class)."""
        if self.expected is not None and (self.checks != self.expected or self.bad):
            stats.reject("verdict_mismatch")
        self.expected = self.rejected = None
        self.bad = False
        self.checks = 0
