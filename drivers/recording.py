"""The service's own recording: every raw input with its receive time, crash-safe.

Layout: an 8-byte file magic ``ONBREC01`` followed by frames::

    0xA5 0x5A | u32 length | u32 crc32(payload) | payload (msgpack RawRecord)

all little-endian. Frames are only ever appended. A crash can leave at most a torn last
frame, which the reader detects (length or CRC) and counts as ``truncated``; a damaged
frame in the middle is counted as ``crc`` and the reader resynchronizes on the next frame
marker, so one bad sector never costs the rest of the file.

A :class:`RawRecord` holds the bytes exactly as received on one input (``kind`` names the
protocol: ``mavlink``, ``nmea``, ``dvl-json``, ``pd6``; ``sample`` is an already typed
sample encoded as msgpack, used by the simulator; ``tick`` marks a live engine tick, so a
replay reproduces the live estimates exactly; ``meta`` carries JSON metadata such as the
config used).
"""

from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path
from typing import BinaryIO, Iterator

import msgspec

from drivers.base import ReadStats, UnreadableLog

FILE_MAGIC = b"ONBREC01"
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


_enc = msgspec.msgpack.Encoder()
_dec = msgspec.msgpack.Decoder(RawRecord)


def encode_frame(rec: RawRecord) -> bytes:
    """The bytes of one frame holding ``rec``."""
    payload = _enc.encode(rec)
    return _HEAD.pack(FRAME_MARK, len(payload), zlib.crc32(payload)) + payload


class RecordingWriter:
    """Appends frames to a recording; the caller decides when to :meth:`flush`.

    ``fsync`` on flush makes the data durable against power loss, not only a crash of
    the process. Rotation and size caps are the recorder's job (onboard.recorder); this
    class writes one file.
    """

    def __init__(self, path: str | Path, *, fsync: bool = True) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        new = not self.path.exists() or self.path.stat().st_size == 0
        self._f: BinaryIO = open(self.path, "ab", buffering=1 << 16)
        self._fsync = fsync
        self.bytes_written = 0 if new else self.path.stat().st_size
        if new:
            self._f.write(FILE_MAGIC)
            self.bytes_written = len(FILE_MAGIC)

    def write(self, rec: RawRecord) -> None:
        frame = encode_frame(rec)
        self._f.write(frame)
        self.bytes_written += len(frame)

    def flush(self) -> None:
        self._f.flush()
        if self._fsync:
            os.fsync(self._f.fileno())

    def close(self) -> None:
        if not self._f.closed:
            self.flush()
            self._f.close()

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def is_recording(path: str | Path) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(len(FILE_MAGIC)) == FILE_MAGIC
    except OSError:
        return False


def read_records(path: str | Path, stats: ReadStats | None = None) -> Iterator[RawRecord]:
    """Every intact record of a recording, in file order; damage is skipped and counted."""
    stats = stats if stats is not None else ReadStats()
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise UnreadableLog(f"{path}: {err.strerror}") from None
    if not data.startswith(FILE_MAGIC):
        raise UnreadableLog(f"{path}: not an onboard recording (bad magic)")
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
        stats.records += 1
        stats.by_type[rec.kind] += 1
        pos = end
        yield rec


_sample_dec = None


def decode_sample(data: bytes):
    """Decode a ``kind == "sample"`` payload (a msgpack-encoded typed sample)."""
    global _sample_dec
    if _sample_dec is None:
        from onboard.messages import AnySample

        _sample_dec = msgspec.msgpack.Decoder(AnySample)
    return _sample_dec.decode(data)


class RecordingReader:
    """A recording as a log: re-parses every raw record with its protocol's parser.

    Each (source, kind) gets its own stream parser, fed the recorded bytes with the
    recorded receive time, exactly as the service fed it live. ``tick_times`` collects the
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
        from drivers.protocols import parser_for

        parsers: dict[tuple[str, str], object] = {}
        for rec in read_records(self.path, self.stats):
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
            else:
                key = (rec.source, rec.kind)
                parser = parsers.get(key)
                if parser is None:
                    try:
                        parser = parsers[key] = parser_for(rec.kind, rec.source)
                    except (KeyError, ValueError):
                        self.stats.reject(f"unknown_kind:{rec.kind}")
                        continue
                out = parser.feed(rec.data, rec.t)  # type: ignore[attr-defined]
            for s in out:
                self.stats.samples += 1
                yield s
        for p in parsers.values():
            for reason, n in p.stats.rejected.items():  # type: ignore[attr-defined]
                self.stats.rejected[reason] += n
