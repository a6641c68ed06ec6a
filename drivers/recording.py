"""The service's own recording: every raw input with its receive time, crash-safe.

Layout: an 8-byte file magic ``ONBREC0<version>`` followed by frames::

    0xA5 0x5A | u32 length | u32 crc32(payload) | payload (msgpack RawRecord)

all little-endian. Frames are only ever appended. A crash can leave at most a torn last
frame, which the reader detects (length or CRC) and counts as ``truncated``; a damaged
frame in the middle is counted as ``crc`` and the reader resynchronizes on the next frame
marker, so one bad sector never costs the rest of the file. A record whose receive time
is not finite (no clock gives one) is damaged too, counted as ``time``.

A :class:`RawRecord` holds the bytes exactly as received on one input (``kind`` names the
protocol: ``mavlink``, ``nmea``, ``dvl-json``, ``pd6``; ``sample`` is an already typed
sample encoded as msgpack, used by the simulator; ``tick`` marks a live engine tick, so a
replay reproduces the live estimates exactly; ``meta`` carries JSON metadata such as the
config used; ``verdicts`` (version 2) lists the frames of the chunk just before it that the
input's signature verifier rejected live, see :class:`drivers.verdicts.Verdicts`).

Versions and compatibility. The file magic carries the format version:

* ``ONBREC01``: the record kinds above except ``verdicts``.
* ``ONBREC02``: version 1 plus ``verdicts`` records. Written only by a service that verifies
  MAVLink signatures (``require_signing``); every other recording stays version 1, readable
  by older readers.

A reader refuses a version it does not know (``UnreadableLog``: bad magic) rather than
misread it. Within a version it knows, a reader skips and counts (``unknown_kind:<kind>``)
a record kind it does not know. The rule for writers: a new record kind that a reader may
skip without changing what the other records mean keeps the version; one that a reader
must understand to reproduce the live results (as ``verdicts``: skipping it would accept
frames that live rejected) bumps it, and is written only where it is needed.
"""

from __future__ import annotations

import math
import os
import struct
import zlib
from pathlib import Path
from typing import BinaryIO, Iterable, Iterator

import msgspec

from onboard.drivers.base import ReadStats, UnreadableLog
from onboard.drivers.verdicts import Verdicts

FILE_MAGIC = b"ONBREC01"
"""The magic of version 1 (see the module docstring for the versions)."""
VERSIONS = {b"ONBREC01": 1, b"ONBREC02": 2}
"""File magic -> format version, for every version this reader knows."""
VERDICTS_VERSION = 2
"""The first version with ``verdicts`` records."""
VERDICTS_KIND = "verdicts"
FRAME_MARK = b"\xa5\x5a"
_HEAD = struct.Struct("<2sII")
MAX_FRAME = 1 << 20
"""Largest payload accepted (1 MiB); a longer length field means corruption."""


class RawRecord(msgspec.Struct, array_like=True):
    """One raw input: receive time ``t`` (s, service clock), input name, protocol, bytes."""

    t: float
    source: str
    kind: str
    data: bytes


def file_magic(version: int) -> bytes:
    """The magic of format ``version``."""
    for magic, v in VERSIONS.items():
        if v == version:
            return magic
    raise ValueError(f"unknown recording format version {version}")


def file_version(head: bytes) -> int | None:
    """The format version of a file starting with ``head`` (None: not a recording this
    reader knows)."""
    return VERSIONS.get(bytes(head[:len(FILE_MAGIC)]))


_enc = msgspec.msgpack.Encoder()
_dec = msgspec.msgpack.Decoder(RawRecord)
_vdec = msgspec.msgpack.Decoder(Verdicts)


def encode_verdicts(v: Verdicts) -> bytes:
    """The payload of a ``verdicts`` record (:func:`decode_verdicts` reads it back)."""
    return _enc.encode(v)


def decode_verdicts(data: bytes) -> Verdicts:
    """Raises msgspec.DecodeError on bad data."""
    return _vdec.decode(data)


def encode_frame(rec: RawRecord) -> bytes:
    """The bytes of one frame holding ``rec``."""
    payload = _enc.encode(rec)
    return _HEAD.pack(FRAME_MARK, len(payload), zlib.crc32(payload)) + payload


class RecordingWriter:
    """Appends frames to a recording; the caller decides when to :meth:`flush`.

    ``fsync`` on flush makes the data durable against power loss, not only a crash of
    the process. Rotation and size caps are the recorder's job (onboard.service.recorder); this
    class writes one file. ``version`` is the format version of a new file; appending to
    an existing file keeps its version, and raises ValueError when it is older than
    ``version`` (its readers would not know the newer records); so does writing a
    ``verdicts`` record into a version-1 file.
    """

    def __init__(self, path: str | Path, *, fsync: bool = True, version: int = 1) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        magic = file_magic(version)
        new = not self.path.exists() or self.path.stat().st_size == 0
        if not new:
            with open(self.path, "rb") as f:
                have = file_version(f.read(len(magic)))
            if have is not None and have < version:
                raise ValueError(f"{self.path}: cannot append format version {version} "
                                 f"records to a file of version {have}")
            version = have or version
        self.version = version
        self._f: BinaryIO = open(self.path, "ab", buffering=1 << 16)
        self._fsync = fsync
        self.bytes_written = 0 if new else self.path.stat().st_size
        if new:
            self._f.write(magic)
            self.bytes_written = len(magic)

    def write(self, rec: RawRecord, *more: RawRecord) -> None:
        """Append ``rec`` (and ``more``) in one write: records that belong together
        (a chunk and its verdicts) reach the OS together, never one without the other
        because a flush ran in between."""
        frame = encode_frame(rec)
        if more:
            frame += b"".join(encode_frame(r) for r in more)
        if self.version < VERDICTS_VERSION and (
                rec.kind == VERDICTS_KIND or any(r.kind == VERDICTS_KIND for r in more)):
            raise ValueError(f"{self.path}: verdicts records need format version "
                             f"{VERDICTS_VERSION}, the file has {self.version}")
        self._f.write(frame)
        self.bytes_written += len(frame)

    def write_encoded(self, frames: bytes) -> None:
        """Append frames already encoded by :func:`encode_frame` (the service's recorder
        encodes them on its event loop and writes them in a worker thread); the caller
        keeps ``verdicts`` records out of a version-1 file."""
        self._f.write(frames)
        self.bytes_written += len(frames)

    def flush(self) -> None:
        """Write the buffered frames to the file (and to the disk when ``fsync``)."""
        self._f.flush()
        if self._fsync:
            os.fsync(self._f.fileno())

    def close(self) -> None:
        """Flush and close the file; closing it again does nothing."""
        if not self._f.closed:
            self.flush()
            self._f.close()

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def is_recording(path: str | Path) -> bool:
    """Whether ``path`` starts with the file magic of a known recording version (False when it
    cannot be read)."""
    try:
        with open(path, "rb") as f:
            return file_version(f.read(len(FILE_MAGIC))) is not None
    except OSError:
        return False


def read_records(path: str | Path, stats: ReadStats | None = None) -> Iterator[RawRecord]:
    """Every intact record of a recording, in file order; damage is skipped and counted."""
    stats = stats if stats is not None else ReadStats()
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise UnreadableLog(f"{path}: {err.strerror}") from None
    if file_version(data) is None:
        raise UnreadableLog(f"{path}: not an onboard recording (bad magic)"
                            + (f": format {data[:8]!r} is newer than this reader"
                               if data.startswith(b"ONBREC") else ""))
    pos = len(FILE_MAGIC)
    n = len(data)
    while pos < n:
        if data[pos:pos + 2] != FRAME_MARK:
            nxt = data.find(FRAME_MARK, pos + 1)
            stats.reject("garbage")
            if nxt < 0:
                break
            pos = nxt
            continue
        if pos + _HEAD.size > n:
            stats.reject("truncated")
            break
        _, length, crc = _HEAD.unpack_from(data, pos)
        end = pos + _HEAD.size + length
        if length > MAX_FRAME:
            stats.reject("length")
            pos += 2
            continue
        if end > n:
            # A torn last frame, or a damaged length field: resynchronize on the next
            # frame marker if there is one, so damage never costs the frames after it.
            nxt = data.find(FRAME_MARK, pos + 2)
            if nxt < 0:
                stats.reject("truncated")
                break
            stats.reject("length")
            pos = nxt
            continue
        payload = data[pos + _HEAD.size:end]
        if zlib.crc32(payload) != crc:
            stats.reject("crc")
            pos += 2
            continue
        try:
            rec = _dec.decode(payload)
        except (msgspec.DecodeError, UnicodeDecodeError):
            stats.reject("decode")
            pos = end
            continue
        pos = end
        if not math.isfinite(rec.t):  # a service clock never gives it: damage
            stats.reject("time")
            continue
        stats.records += 1
        stats.by_type[rec.kind] += 1
        yield rec


def with_verdicts(records: Iterable[RawRecord],
                  stats: ReadStats) -> Iterator[tuple[RawRecord, Verdicts | None]]:
    """Every record but the ``verdicts`` ones, each with the verdicts recorded for it
    (None: every frame of it was accepted live, or signing was not verified).

    A chunk and its verdicts are written in one write, so the verdicts follow their chunk
    directly; one that does not (its chunk lost to damage, or not its chunk's CRC, or
    the record before it not a MAVLink chunk) is counted ``verdicts_orphan`` and ignored.
    """
    held: RawRecord | None = None
    for rec in records:
        if rec.kind == VERDICTS_KIND:
            v = None
            if (held is not None and held.kind == "mavlink" and held.source == rec.source
                    and held.t == rec.t):
                try:
                    v = decode_verdicts(rec.data)
                except (msgspec.DecodeError, UnicodeDecodeError):
                    v = None
                if v is not None and v.chunk_crc != zlib.crc32(held.data):
                    v = None
            if v is None:
                stats.reject("verdicts_orphan")
            else:
                yield held, v  # type: ignore[misc]
                held = None
            continue
        if held is not None:
            yield held, None
        held = rec
    if held is not None:
        yield held, None


_sample_dec = None


def decode_sample(data: bytes):
    """Decode a ``kind == "sample"`` payload (a msgpack-encoded typed sample)."""
    global _sample_dec
    if _sample_dec is None:
        from onboard.core.messages import AnySample

        _sample_dec = msgspec.msgpack.Decoder(AnySample)
    return _sample_dec.decode(data)


def _link_for(meta: list[bytes], source: str):
    """The autopilot link the service gave MAVLink input ``source``, from the newest
    ``meta`` record's configuration (as :class:`onboard.service.intake.Intake` builds it):
    its ``[[service.sources]]`` options; a recording made before the link existed (no
    ``autopilot_time`` key) decodes every component with receive-time stamps."""
    import json

    from onboard.drivers.mavlink_link import AutopilotLink

    try:
        cfg = json.loads(meta[-1]).get("config") if meta else None
    except (ValueError, AttributeError):
        cfg = None
    sources = ((cfg or {}).get("service") or {}).get("sources") or [] if isinstance(cfg, dict) else []
    for i, src in enumerate(sources):
        if not isinstance(src, dict) or src.get("kind") != "mavlink":
            continue
        if (src.get("name") or f"mavlink{i}") != source:
            continue
        if "autopilot_time" not in src:
            return AutopilotLink(stamp_boot_time=False, filter_components=False)
        return AutopilotLink(target_system=int(src.get("target_system", 0)),
                             target_component=int(src.get("target_component", 0)),
                             stamp_boot_time=bool(src.get("autopilot_time", True)),
                             filter_components=bool(src.get("filter_components", True)))
    return AutopilotLink()


class RecordingReader:
    """A recording as a log: re-parses every raw record with its protocol's parser.

    Each (source, kind) gets its own stream parser, fed the recorded bytes with the
    recorded receive time, exactly as the service fed it live; MAVLink frames that the
    live service rejected on signing grounds (``verdicts`` records) are rejected again,
    under the same reason. ``tick_times`` collects the
    live engine's tick times (``tick`` records) while iterating, for exact reproduction.
    """

    def __init__(self, path: str | Path) -> None:
        if not is_recording(path):
            raise UnreadableLog(f"{path}: not an onboard recording")
        self.path = Path(path)
        self.stats = ReadStats()
        self.tick_times: list[float] = []
        self.meta: list[bytes] = []

    def __iter__(self):
        from onboard.drivers.mavlink_signing import VerdictPlayer
        from onboard.drivers.protocols import _finite, parser_for

        parsers: dict[tuple[str, str], object] = {}
        players: dict[tuple[str, str], VerdictPlayer] = {}
        for rec, verdicts in with_verdicts(read_records(self.path, self.stats), self.stats):
            if rec.kind == "tick":
                self.tick_times.append(rec.t)
                continue
            if rec.kind == "meta":
                self.meta.append(rec.data)
                continue
            if rec.kind == "sample":
                try:
                    out = [decode_sample(rec.data)]
                except (msgspec.DecodeError, UnicodeDecodeError):
                    self.stats.reject("sample_decode")
                    continue
                if not _finite(out[0]):  # as SampleParser: NaN or infinity is damage
                    self.stats.reject("nan")
                    continue
            else:
                key = (rec.source, rec.kind)
                parser = parsers.get(key)
                if parser is None:
                    player = VerdictPlayer()
                    link = _link_for(self.meta, rec.source) if rec.kind == "mavlink" else None
                    try:
                        parser = parsers[key] = parser_for(rec.kind, rec.source, verifier=player,
                                                           link=link)
                    except (KeyError, ValueError):
                        self.stats.reject(f"unknown_kind:{rec.kind}")
                        continue
                    players[key] = player
                player = players[key]
                player.load(verdicts)
                out = parser.feed(rec.data, rec.t)  # type: ignore[attr-defined]
                player.done(parser.stats)  # type: ignore[attr-defined]
            for s in out:
                self.stats.samples += 1
                yield s
        for p in parsers.values():
            for reason, n in p.stats.rejected.items():  # type: ignore[attr-defined]
                self.stats.rejected[reason] += n
