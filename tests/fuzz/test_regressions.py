"""Regression tests: minimal reproducers of what fuzzing found, each pinning the
behaviour its name states. docs/fuzzing.md lists the findings with their history; a fixed
finding is a plain test here, an open one an ``xfail`` until its fix lands."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import msgspec

from onboard.drivers import dvl_json
from onboard.drivers.base import ReadStats
from onboard.drivers.dataflash import DataflashReader
from onboard.drivers.mavlink import MavlinkParser
from onboard.drivers.mavlink_signing import SignatureVerifier, VerdictLog, VerdictPlayer, signing_timestamp
from onboard.drivers.protocols import SampleParser, encode_sample
from onboard.drivers.recording import (
    _HEAD,
    FILE_MAGIC,
    FRAME_MARK,
    RawRecord,
    RecordingReader,
    RecordingWriter,
    Verdicts,
    encode_frame,
    encode_verdicts,
    read_records,
)
from onboard.core.config import Config
from onboard.core.messages import Imu
from onboard.engine import Engine
from onboard.service.recorder import replay_recording
from tests.fuzz.corpora import mav_frame
from tests.fuzz.recording_corpora import SIGN_KEY, SIGN_WALL, signed_frame
from tests.fuzz.targets import run_mavlink


def _unknown_id_header(plen: int = 32) -> bytes:
    """What line noise can look like: a v2 start byte, then bytes that read as a length
    and a message id outside the dialect (0x332211)."""
    return bytes([0xFD, plen, 0, 0, 0, 1, 1, 0x11, 0x22, 0x33])


def test_mavlink_noise_is_judged_the_same_whatever_the_chunking():
    """Line noise reading as a 51-byte unknown-id frame with a PARAM_VALUE starting inside
    it, cut where the noise is complete but the inner frame is not: the parser waits for
    the inner frame's bytes before judging the noise, so the PARAM_VALUE is decoded as in
    the uncut stream (chunking invariance)."""
    data = bytes.fromhex(
        "fd110000000101160000b6df175f45e89dc4b3ec513f6176f90b094cacfd33000001fff374567bc1"
        "6c0fa41d382c04b931aea4e758975a21cb190345f97e82d884fa5aa517763279cba2cad8c1ae1c1a"
        "f268fd190000020101160000fec5d78d8300aeb42181948379c5d154a798068a2956d745a202cafd"
        "25000003ff01240000029ac9fd96f2d6b69c1b3d0729dc82a80ee9b4a7a6be4384ad431dc35e655c"
        "692fca61d4eab3ab")
    run_mavlink(data, [92, 103])


def test_mavlink_noise_with_a_start_byte_does_not_swallow_the_next_frame():
    """Noise that reads as the header of an unknown-id frame does not swallow the frames
    after it: both ATTITUDE frames are decoded and the noise is counted as rejected."""
    good = mav_frame(30, bytes(28))  # ATTITUDE, all zeros: a valid sample
    p = MavlinkParser()
    out = p.feed(_unknown_id_header() + good + good, 1.0)
    assert len(out) == 2 and p.stats.rejected


def test_mavlink_noise_spanning_intact_frames_does_not_swallow_them():
    """An unknown-id "frame" inside which a CRC-valid known frame starts is noise, even
    when its length ends exactly on a start byte: the three frames it spans are decoded."""
    frames = [mav_frame(30, bytes(28), seq=i) for i in range(3)]      # ATTITUDE, 40 bytes
    # line noise that reads as a v1 header of unknown id 189 whose length ends exactly at
    # the third frame's start byte
    noise = bytes([0xFE, len(frames[0]) + len(frames[1]) - 2, 0, 1, 1, 189])
    p = MavlinkParser()
    assert len(p.feed(noise + b"".join(frames), 1.0)) == 3


def test_dvl_json_invalid_utf8_in_a_string_is_a_counted_rejection():
    """Invalid UTF-8 inside a JSON string is a ``json`` rejection, not an exception."""
    p = dvl_json.DvlJsonParser()
    assert p.feed(b'{"type":"\xc6"}\n', 0.0) == []
    assert p.stats.rejected["json"] == 1


def _recording(tmp_path: Path, *frames: bytes) -> Path:
    """A version-1 recording file of ``frames``."""
    p = tmp_path / "r.onbrec"
    p.write_bytes(FILE_MAGIC + b"".join(frames))
    return p


def test_recording_unknown_kind_is_a_counted_rejection(tmp_path):
    """A record of a kind no parser knows is rejected and counted by RecordingReader."""
    p = _recording(tmp_path, encode_frame(RawRecord(t=1.0, source="x", kind="bogus", data=b"")))
    r = RecordingReader(p)
    assert list(r) == [] and r.stats.rejected


def test_recording_invalid_utf8_string_is_a_counted_rejection(tmp_path):
    """A CRC-valid frame with invalid UTF-8 in a string field is a ``decode`` rejection."""
    payload = (b"\x94" + msgspec.msgpack.encode(1.0) + b"\xa2\xc6\x00"
               + msgspec.msgpack.encode("nmea") + msgspec.msgpack.encode(b"x"))
    p = _recording(tmp_path, _HEAD.pack(FRAME_MARK, len(payload), zlib.crc32(payload)) + payload)
    stats = ReadStats()
    assert list(read_records(p, stats)) == [] and stats.rejected["decode"] == 1


def test_recording_damaged_length_does_not_cost_the_rest_of_the_file(tmp_path):
    """A length field damaged to point past the end of the file is not taken for a torn
    tail: the reader resynchronises and the two intact frames after it are read."""
    a = encode_frame(RawRecord(t=1.0, source="s", kind="nmea", data=b"x" * 10))
    b = encode_frame(RawRecord(t=2.0, source="s", kind="nmea", data=b"y" * 10))
    bad = bytearray(a)
    bad[4] = 0x01  # one bit in the length field: +65,536 bytes, past the end of the file
    p = _recording(tmp_path, bytes(bad), b, b)
    stats = ReadStats()
    assert len(list(read_records(p, stats))) == 2


def test_dataflash_fmt_typing_a_number_as_text_is_a_counted_rejection(tmp_path):
    """A FMT that gives a column the reader needs as a number a text format code (PARM
    Value as ``N``, char[16]) makes the message unusable: its records are rejected and
    counted, never decoded as numbers."""
    def fmt(typ: int, name: str, f: str, cols: str, size: int) -> bytes:
        return b"\xa3\x95\x80" + struct.pack("<BB4s16s64s", typ, 3 + size, name.encode(),
                                               f.encode(), cols.encode())

    data = (fmt(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns", 86)
            + fmt(64, "PARM", "QNN", "TimeUS,Name,Value", 40)           # Value as char[16]
            + b"\xa3\x95\x40" + struct.pack("<Q16s16s", 1000, b"FRAME_CLASS", b"2"))
    p = tmp_path / "parm.bin"
    p.write_bytes(data)
    r = DataflashReader(p)
    assert list(r) == [] and r.stats.rejected


def test_sample_records_with_non_finite_values_are_rejected():
    """SampleParser rejects a ``sample`` record decoding to NaN or infinite values."""
    p = SampleParser()
    bad = Imu(t=float("nan"), source="sim", accel_x=float("inf"), accel_y=0.0, accel_z=-9.8,
              gyro_x=0.0, gyro_y=0.0, gyro_z=0.0)
    assert p.feed(encode_sample(bad), 1.0) == [] and p.stats.rejected


def test_recording_reader_rejects_a_sample_record_with_non_finite_values(tmp_path):
    """RecordingReader, which decodes ``sample`` records itself (not through SampleParser),
    rejects a sample at ``t = -inf`` (a mutated payload with a recomputed frame CRC) as
    ``nan``, like SampleParser."""
    bad = Imu(t=float("-inf"), source="sim", accel_x=0.0, accel_y=0.0, accel_z=-9.8,
              gyro_x=0.0, gyro_y=0.0, gyro_z=0.0)
    p = _recording(tmp_path, encode_frame(RawRecord(1.0, "", "sample", encode_sample(bad))))
    r = RecordingReader(p)
    assert list(r) == [] and r.stats.rejected == {"nan": 1}


def test_a_record_with_a_non_finite_receive_time_is_a_counted_rejection(tmp_path):
    """A CRC-valid record whose receive time decodes to NaN or infinity (a mutated
    payload) is damage, rejected as ``time``: no clock gives such a time, so neither its
    samples (stamped with it) nor a tick at it reach the engine."""
    att = encode_frame(RawRecord(float("nan"), "ap", "mavlink", mav_frame(30, bytes(28))))
    tick = encode_frame(RawRecord(float("inf"), "engine", "tick", b""))
    ok = encode_frame(RawRecord(2.0, "ap", "mavlink", mav_frame(30, bytes(28))))
    p = _recording(tmp_path, att, tick, ok)
    stats = ReadStats()
    assert [r.t for r in read_records(p, stats)] == [2.0]
    assert stats.rejected == {"time": 2} and stats.records == 1
    r = RecordingReader(p)
    assert [s.t for s in r] == [2.0] and r.tick_times == []


def _signed_chunk_and_verdicts():
    """A chunk of one accepted and one unsigned ATTITUDE frame and its live verdicts."""
    good = signed_frame(30, bytes(28), signing_timestamp(SIGN_WALL))
    bad = mav_frame(30, bytes(28))
    vlog = VerdictLog(SignatureVerifier(SIGN_KEY, wall=lambda: SIGN_WALL))
    chunk = good + bad
    assert len(MavlinkParser(verifier=vlog).feed(chunk, 1.0)) == 1
    v = vlog.take(chunk)
    assert v is not None and v.checks == 2 and [r[:2] for r in v.rejected] == [(1, "unsigned")]
    return chunk, v


def _replay_player(chunk: bytes, v) -> ReadStats:
    player = VerdictPlayer()
    p = MavlinkParser(verifier=player)
    player.load(v)
    p.feed(chunk, 1.0)
    player.done(p.stats)
    return p.stats


def test_verdicts_bound_to_a_record_that_is_not_a_mavlink_chunk_are_an_orphan(tmp_path):
    """A verdicts record bound (time, source, CRC) to a record that is not a MAVLink chunk
    (here a tick) is an orphan: counted ``verdicts_orphan`` by the reader and the replay,
    never silently dropped."""
    tick = RawRecord(1.0, "engine", "tick", b"")
    p = tmp_path / "r.onbrec"
    with RecordingWriter(p, fsync=False, version=2) as w:
        verdicts = encode_verdicts(Verdicts(zlib.crc32(b""), 1, [(0, "unsigned", 0)]))
        w.write(tick, RawRecord(1.0, "engine", "verdicts", verdicts))
    r = RecordingReader(p)
    assert list(r) == [] and r.stats.rejected == {"verdicts_orphan": 1}
    res = replay_recording(p, Engine(Config(), []), lambda t, x: None)
    assert res.ticks == 1 and res.stats.rejected == {"verdicts_orphan": 1}


def test_verdicts_naming_a_reason_no_verifier_gives_reject_as_a_mismatch():
    """A recorded rejection naming a reason no verifier gives (empty, made up, overlong)
    rejects the frame as ``verdict_mismatch``: a damaged or forged verdicts record never
    puts its own names into the counters, and never makes a frame accepted."""
    chunk, v = _signed_chunk_and_verdicts()
    (i, _, crc), = v.rejected
    for reason in ("", "evil", "x" * 300):
        stats = _replay_player(chunk, Verdicts(v.chunk_crc, v.checks, [(i, reason, crc)]))
        assert stats.rejected == {"verdict_mismatch": 1}  # still rejected, never accepted
    assert _replay_player(chunk, v).rejected == {"unsigned": 1}


def test_verdicts_with_an_index_out_of_range_or_listed_twice_are_a_mismatch():
    """A recorded rejection whose index is outside the chunk's recorded number of frames
    (negative, >= checks, 2^63 - 1), or the same frame listed twice, counts the chunk
    ``verdict_mismatch``; the valid rejection beside it still counts."""
    chunk, v = _signed_chunk_and_verdicts()
    (i, reason, crc), = v.rejected
    for extra in ((2, "unsigned", 0), (-1, "signature", 0), (2**63 - 1, "unsigned", crc),
                  (i, reason, crc)):
        stats = _replay_player(chunk, Verdicts(v.chunk_crc, v.checks, [(i, reason, crc), extra]))
        assert stats.rejected == {"unsigned": 1, "verdict_mismatch": 1}, extra
