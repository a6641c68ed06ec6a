"""The service's own recordings as fuzz inputs: format version 1 (every record kind) and
version 2 (signed MAVLink chunks with their ``verdicts`` records, then damaged)."""

from __future__ import annotations

import hashlib
import math
import random
import zlib

from onboard.drivers.mavlink import MavlinkParser
from onboard.drivers.mavlink_frame import CRC_EXTRA, x25crc
from onboard.drivers.mavlink_signing import (
    NEW_STREAM_MAX_AGE,
    SignatureVerifier,
    VerdictLog,
    signing_timestamp,
)
from onboard.drivers.protocols import encode_sample
from onboard.drivers.recording import (
    _HEAD,
    FILE_MAGIC,
    FRAME_MARK,
    VERDICTS_KIND,
    RawRecord,
    RecordingWriter,
    Verdicts,
    encode_frame,
    encode_verdicts,
    file_magic,
)
from onboard.core.messages import Imu
from tests.fuzz.corpora import (
    DECODED_IDS,
    dvl_input,
    mav_frame,
    mavlink_input,
    mavlink_payload,
    nmea_input,
    pd6_input,
)
from tests.fuzz.mutation import mutate
from tests.fuzz.scratch import SCRATCH


def recording_input(rng: random.Random) -> tuple[bytes, int]:
    """(file bytes, number of intact frames) of a recording with all record kinds; some
    frames damaged (bytes mutated after framing: CRC fails) and some with a mutated payload
    but a recomputed CRC (reaches the msgpack decoder)."""
    frames, intact = [FILE_MAGIC], 0
    for i in range(rng.randint(1, 10)):
        kind = rng.choice(("mavlink", "nmea", "dvl-json", "pd6", "sample", "tick", "meta"))
        if rng.random() < 0.02:
            kind = "bogus"  # rare: a kind no parser knows, a counted rejection
        if kind == "mavlink":
            data = mavlink_input(rng)[0]
        elif kind == "nmea":
            data = nmea_input(rng)
        elif kind == "dvl-json":
            data = dvl_input(rng)
        elif kind == "pd6":
            data = pd6_input(rng)
        elif kind == "sample":
            data = encode_sample(Imu(t=float(i), source="sim", accel_x=0.0, accel_y=0.0,
                                     accel_z=-9.8, gyro_x=0.0, gyro_y=0.0, gyro_z=0.0))
            if rng.random() < 0.3:
                data = mutate(data, rng, 1)
        else:
            data = rng.randbytes(rng.randint(0, 20))
        frame = encode_frame(RawRecord(t=float(i) * rng.choice((1.0, -1.0, 1e9)),
                                       source=rng.choice(("gps", "ap", "")), kind=kind, data=data))
        r = rng.random()
        if r < 0.15:
            frames.append(mutate(frame, rng, rng.randint(1, 3)))
        elif r < 0.25:
            payload = mutate(frame[_HEAD.size:], rng, rng.randint(1, 2))
            frames.append(_HEAD.pack(FRAME_MARK, len(payload), zlib.crc32(payload)) + payload)
        else:
            frames.append(frame)
            intact += 1
    return b"".join(frames), intact


SIGN_KEY = bytes(range(32))
"""The signing key of the corpus's autopilot."""

SIGN_WALL = 1420070400 + 3.0e8
"""A fixed wall clock (POSIX s) for the live verifier of the corpus: deterministic verdicts."""

SIGNING_REASONS = ("unsigned", "signature", "sig_replay", "sig_stale", "sig_future")
"""The rejection reasons a signature verifier gives."""

HOSTILE_REASONS = ("", "evil", "UNSIGNED", "parse:ap:x", "x" * 300)
"""Reasons no verifier gives; a verdicts record naming one is damaged."""


def signed_frame(msgid: int, payload: bytes, ts: int, *, key: bytes = SIGN_KEY, link: int = 0,
                 seq: int = 0, sysid: int = 1, compid: int = 1) -> bytes:
    """A signed MAVLink 2 frame (drivers.mavlink_signing module docstring)."""
    payload = payload[:255]
    hdr = bytes([0xFD, len(payload), 0x01, 0, seq & 255, sysid, compid,
                 msgid & 255, (msgid >> 8) & 255, (msgid >> 16) & 255])
    crc = x25crc(hdr[1:] + payload, CRC_EXTRA.get(msgid, 0))
    body = hdr + payload + bytes([crc & 255, crc >> 8, link]) + ts.to_bytes(6, "little")
    return body + hashlib.sha256(key + body).digest()[:6]


def signed_stream(rng: random.Random) -> bytes:
    """MAVLink bytes as a signing autopilot sends them, with what a verifier rejects:
    unsigned, forged (other key), replayed, stale, far-future frames; some garbage."""
    now = signing_timestamp(SIGN_WALL)
    ts = now - rng.randint(0, 1000)
    parts = []
    for i in range(rng.randint(1, 8)):
        mid = rng.choice(DECODED_IDS)
        payload = mavlink_payload(rng, mid)
        r = rng.random()
        ts += rng.randint(1, 500)
        if r < 0.55:
            parts.append(signed_frame(mid, payload, ts, seq=i, link=rng.choice((0, 0, 1))))
        elif r < 0.65:
            parts.append(mav_frame(mid, payload, v2=rng.random() < 0.7, seq=i))
        elif r < 0.72:
            parts.append(signed_frame(mid, payload, ts, key=bytes(32), seq=i))
        elif r < 0.8:
            parts.append(signed_frame(mid, payload, ts - rng.randint(500, 10_000), seq=i))
        elif r < 0.86:
            parts.append(signed_frame(mid, payload, now - NEW_STREAM_MAX_AGE - 1000, seq=i,
                                      link=rng.randint(2, 200)))
        elif r < 0.9:
            parts.append(signed_frame(mid, payload, now + 10**9, seq=i, link=rng.randint(2, 200)))
        elif r < 0.95:
            parts.append(mutate(signed_frame(mid, payload, ts, seq=i), rng, 1))
        else:
            parts.append(rng.randbytes(rng.randint(1, 30)))
    return b"".join(parts)


def hostile_verdicts(v, chunk: bytes, rng: random.Random):
    """``v`` (a chunk's live verdicts, or None) damaged in one way a bad disk, a bug or
    an attacker could: wrong count, indices out of range or repeated, wrong chunk or frame
    CRC, a reason no verifier gives; or a made-up record for a chunk without verdicts."""
    if v is None:
        v = Verdicts(zlib.crc32(chunk), rng.randint(0, 4), [])
    rej = [tuple(e) for e in v.rejected]
    r = rng.randrange(8)
    checks, crc = v.checks, v.chunk_crc
    if r == 0:
        checks = rng.choice((checks + rng.randint(1, 3), max(0, checks - rng.randint(1, 3)),
                             -1, 2**63 - 1))
    elif r == 1:
        rej.append((rng.choice((checks, checks + 5, -1, 2**63 - 1, -2**63)),
                    rng.choice(SIGNING_REASONS), rng.randrange(2**16)))
    elif r == 2:
        crc = rng.randrange(2**32)
    elif r == 3 and rej:
        k = rng.randrange(len(rej))
        rej[k] = (rej[k][0], rng.choice(HOSTILE_REASONS), rej[k][2])
    elif r == 3:
        rej.append((0, rng.choice(HOSTILE_REASONS), rng.randrange(2**16)))
    elif r == 4 and rej:
        k = rng.randrange(len(rej))
        rej[k] = (rej[k][0], rej[k][1], rej[k][2] ^ (1 << rng.randrange(16)))
    elif r == 5 and rej:
        rej.append(rej[rng.randrange(len(rej))])  # the same frame twice
    elif r == 6:
        rej = [(i, rng.choice(SIGNING_REASONS + HOSTILE_REASONS[:2]), rng.randrange(2**16))
               for i in range(rng.randint(0, 4))]
    else:
        rej.reverse()
    return Verdicts(crc, checks, rej)


def recording_v2_input(rng: random.Random) -> tuple[bytes, int]:
    """(file bytes, number of intact frames) of a version-2 recording as a service that
    verifies MAVLink signatures writes it: MAVLink chunks parsed live by a verifying parser
    (:class:`drivers.mavlink_signing.VerdictLog`) and written with their ``verdicts`` by
    :class:`drivers.recording.RecordingWriter` (one write), with NMEA, DVL, sample, tick and
    meta records between; then verdicts damaged (:func:`hostile_verdicts`), truncated,
    orphaned, duplicated, put before their chunk or given another time or source, frames
    damaged, and sometimes the file's bytes mutated."""
    logs = {src: VerdictLog(SignatureVerifier(SIGN_KEY, wall=lambda: SIGN_WALL,
                                              max_future_s=600.0)) for src in ("ap", "ap2")}
    parsers = {src: MavlinkParser(verifier=logs[src]) for src in logs}
    p = SCRATCH / "v2-writer.onbrec"
    p.unlink(missing_ok=True)
    groups: list[list[RawRecord]] = []
    with RecordingWriter(p, fsync=False, version=2) as w:
        w.write(RawRecord(0.0, "engine", "meta", b'{"format": 1}'))
        stream = {src: signed_stream(rng) for src in logs}
        for i in range(rng.randint(1, 10)):
            t = 1.0 + i * 0.1
            kind = rng.choice(("mavlink", "mavlink", "mavlink", "nmea", "dvl-json", "sample",
                               "tick"))
            if kind == "mavlink":
                src = rng.choice(("ap", "ap", "ap2"))
                s = stream[src] or signed_stream(rng)
                cut = rng.randint(1, len(s))
                chunk, stream[src] = s[:cut], s[cut:]
                parsers[src].feed(chunk, t)
                v = logs[src].take(chunk)  # as Intake.chunk does live
                recs = [RawRecord(t, src, "mavlink", chunk)]
                if v is not None:
                    recs.append(RawRecord(t, src, VERDICTS_KIND, encode_verdicts(v)))
                if rng.random() < 0.35:
                    v2 = hostile_verdicts(v, chunk, rng)
                    rv = RawRecord(t, src, VERDICTS_KIND, encode_verdicts(v2))
                    recs[1:] = [rv]
                groups.append(recs)
                w.write(*recs)
                continue
            if kind == "nmea":
                rec = RawRecord(t, "gps", kind, nmea_input(rng))
            elif kind == "dvl-json":
                rec = RawRecord(t, "dvl", kind, dvl_input(rng))
            elif kind == "sample":
                rec = RawRecord(t, "sim", kind, encode_sample(
                    Imu(t=t, source="sim", accel_x=0.0, accel_y=0.0, accel_z=-9.8,
                        gyro_x=0.0, gyro_y=0.0, gyro_z=0.0)))
            else:
                rec = RawRecord(t + 0.05, "engine", "tick", b"")
            groups.append([rec])
            w.write(rec)
    data = p.read_bytes()
    if rng.random() < 0.6:
        return data, len(groups) + 1  # as written (the writer's own bytes), meta included
    # damage record by record
    recs = [r for g in groups for r in g]
    vs = [k for k, r in enumerate(recs) if r.kind == VERDICTS_KIND]
    out = [RawRecord(0.0, "engine", "meta", b'{"format": 1}')]
    for k, r in enumerate(recs):
        if r.kind == VERDICTS_KIND:
            m = rng.random()
            if m < 0.15:
                r = RawRecord(r.t, r.source, r.kind, r.data[:rng.randrange(len(r.data))])
            elif m < 0.25:
                r = RawRecord(r.t, r.source, r.kind, mutate(r.data, rng, 1))
            elif m < 0.35:
                out.append(r)  # duplicated
            elif m < 0.45 and out:
                out.insert(len(out) - 1, r)  # before its chunk
                continue
            elif m < 0.5:
                continue  # lost
            elif m < 0.6:
                r = RawRecord(rng.choice((r.t + 1.0, -r.t, float("nan"))), r.source, r.kind, r.data)
            elif m < 0.65:
                other = rng.choice(("gps", "engine", "ap2" if r.source == "ap" else "ap"))
                r = RawRecord(r.t, other, r.kind, r.data)
        elif vs and rng.random() < 0.1:
            # an orphan: some chunk's verdicts after a record that is not that chunk
            out.append(r)
            r = recs[rng.choice(vs)]
        elif r.kind != "mavlink" and rng.random() < 0.1:
            # verdicts bound (time, source, CRC) to a record that is not a MAVLink chunk
            out.append(r)
            r = RawRecord(r.t, r.source, VERDICTS_KIND, encode_verdicts(Verdicts(
                zlib.crc32(r.data), rng.randint(0, 2), [(0, "unsigned", 0)])))
        out.append(r)
    if rng.random() < 0.1:
        rng.shuffle(out)
    frames, intact = [file_magic(rng.choice((2, 2, 2, 1)))], 0
    for r in out:
        frame = encode_frame(r)
        m = rng.random()
        if m < 0.07:
            frames.append(mutate(frame, rng, rng.randint(1, 3)))
        elif m < 0.12:
            payload = mutate(frame[_HEAD.size:], rng, rng.randint(1, 2))
            frames.append(_HEAD.pack(FRAME_MARK, len(payload), zlib.crc32(payload)) + payload)
        else:
            frames.append(frame)
            intact += math.isfinite(r.t)  # a non-finite receive time is damage, rejected
    data = b"".join(frames)
    if rng.random() < 0.15:
        return mutate(data, rng, rng.randint(1, 4)), None
    return data, intact
