"""Valid inputs from the project's own encoders, then mutated (:mod:`.mutation`).

Each ``<name>_input(rng)`` builds one fuzz input from a :class:`random.Random`, so an
input is reproduced from the generator's seed alone. NMEA and MAVLink checksums are
recomputed after a field mutation, so the field decoders are reached, not only the
checksum test.
"""

from __future__ import annotations

import random
from typing import Any

import msgspec

from onboard.drivers import dvl_json, nmea, pd6
from onboard.drivers.mavlink import select
from onboard.drivers.mavlink_frame import CRC_EXTRA, x25crc
from onboard.apps.bench import synthesize_tlog
from tests.fuzz.mutation import mutate, mutate_fields
from tests.fuzz.scratch import SCRATCH
from tests.helpers.dataflash_log import synthetic_log


def nmea_corpus(rng: random.Random, n: int = 12) -> list[bytes]:
    """Valid sentences: a receiver's epochs (GGA, RMC, VTG) and headings (HDT/HDM/HDG)."""
    out = []
    t = 1.7e9 + rng.uniform(0, 86400 * 30)
    for _ in range(n):
        t += rng.choice((0.2, 1.0, 0.0, -1.0, 43200.0))
        lat, lon = rng.uniform(-89.9, 89.9), rng.uniform(-179.9, 179.9)
        sog, cog = rng.uniform(0, 10), rng.uniform(-7, 7)
        k = rng.randrange(7)
        if k == 0:
            out.append(nmea.encode_gga(t, lat, lon, rng.uniform(-50, 50), rng.randint(0, 5)))
        elif k == 1:
            out.append(nmea.encode_rmc(t, lat, lon, sog, cog, valid=rng.random() < 0.9))
        elif k == 2:
            out.append(nmea.encode_vtg(sog, cog if rng.random() < 0.8 else None))
        elif k == 3:
            out.append(nmea.encode_hdt(rng.uniform(-7, 7)))
        elif k == 4:
            out.append(nmea.encode_hdm(rng.uniform(-7, 7)))
        elif k == 5:
            out.append(nmea.encode_hdg(rng.uniform(-7, 7), rng.uniform(-0.1, 0.1),
                                       rng.uniform(-0.3, 0.3)))
        else:
            out.append(b"$GPGSV,3,1,11,03,03,111,00,04,15,270,00,06,01,010,00,13,06,292,00*74\r\n")
    return out


def fix_nmea_checksum(line: str) -> str:
    """``line`` with its ``*hh`` checksum recomputed (unchanged if it has none)."""
    if line.startswith("$") and "*" in line:
        body = line[1:line.rindex("*")]
        return f"${body}*{nmea.checksum(body):02X}"
    return line


def nmea_input(rng: random.Random) -> bytes:
    """A stream of valid, field-mutated (checksum recomputed) and byte-mutated sentences."""
    parts = []
    for s in nmea_corpus(rng, rng.randint(1, 12)):
        r = rng.random()
        if r < 0.45:
            parts.append(s)
        elif r < 0.85:
            line = s.decode().strip()
            m = mutate_fields(line, rng)
            if rng.random() < 0.8:
                m = fix_nmea_checksum(m)
            ending = rng.choice((b"\r\n", b"\n", b"\r", b""))
            parts.append(m.encode("utf-8", "surrogatepass") + ending)
        else:
            parts.append(mutate(s, rng, rng.randint(1, 4)))
    return b"".join(parts)


DECODED_IDS = sorted(select(None))
"""Message ids the MAVLink decoder turns into samples (the handlers we fuzz)."""


def mav_frame(msgid: int, payload: bytes, *, v2: bool = True, seq: int = 0, sysid: int = 1,
              compid: int = 1) -> bytes:
    """A MAVLink 1 or 2 frame with a correct CRC (any payload bytes)."""
    payload = payload[:255]
    if v2:
        hdr = bytes([0xFD, len(payload), 0, 0, seq & 255, sysid, compid,
                     msgid & 255, (msgid >> 8) & 255, (msgid >> 16) & 255])
    else:
        hdr = bytes([0xFE, len(payload), seq & 255, sysid, compid, msgid & 255])
    crc = x25crc(hdr[1:] + payload, CRC_EXTRA.get(msgid, 0))
    return hdr + payload + bytes([crc & 255, crc >> 8])


def mavlink_payload(rng: random.Random, msgid: int) -> bytes:
    """A payload for message ``msgid``: random bytes of its size, shorter or longer, or
    with NaN and infinite floats written in."""
    size = select(None)[msgid].size
    r = rng.random()
    if r < 0.5:
        return rng.randbytes(size)
    if r < 0.8:  # v2 zero-truncation, or junk shorter/longer
        return rng.randbytes(rng.randint(0, size))
    b = bytearray(rng.randbytes(size))  # NaN / inf floats sprinkled in
    for _ in range(3):
        i = rng.randrange(0, max(1, size - 3))
        b[i:i + 4] = rng.choice((b"\x00\x00\xc0\x7f", b"\x00\x00\x80\x7f", b"\x00\x00\x80\xff"))
    return bytes(b[:size])


def mavlink_input(rng: random.Random, garbage_magic: bool = True,
                  damaged: bool = True) -> tuple[bytes, int]:
    """(stream, number of intact frames of dialect ids in it). ``garbage_magic=False`` keeps
    the start bytes 0xFD/0xFE out of the garbage; ``damaged=False`` adds no damaged frames."""
    parts, intact = [], 0
    for i in range(rng.randint(1, 10)):
        r = rng.random()
        mid = rng.choice(DECODED_IDS)
        v2 = mid > 255 or rng.random() < 0.7
        frame = mav_frame(mid, mavlink_payload(rng, mid), v2=v2, seq=i, sysid=rng.choice((1, 255)))
        if r < 0.6:
            parts.append(frame)
            intact += 1
        elif r < 0.8 and damaged:
            parts.append(mutate(frame, rng, 1))
        else:
            g = rng.randbytes(rng.randint(1, 40))
            if not garbage_magic:
                g = g.replace(b"\xfd", b"\x00").replace(b"\xfe", b"\x00")
            parts.append(g)
    return b"".join(parts), intact


JSON_HOSTILE: tuple[Any, ...] = (None, "x", "", [], {}, [1, 2], True, False, 0, -1, 1e308, -1e308,
                                  10**30, "nan", [[1, 2, 3]] * 3, [[float("nan")] * 3] * 3,
                                  [1.0] * 9)
"""JSON values of the wrong type or range for a DVL report's keys."""


def dvl_corpus(rng: random.Random) -> list[dict]:
    """Valid Water Linked reports, decoded: velocity (json_v3 bottom or water track, json_v1),
    position_local, and a command response."""
    out = []
    for _ in range(rng.randint(1, 8)):
        k = rng.randrange(4)
        t = 1.7e9 + rng.uniform(0, 1e4)
        if k == 0:
            line = dvl_json.encode_velocity_report(
                rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 0.1), valid=rng.random() < 0.8,
                t_validity_s=t, t_transmission_s=t + rng.uniform(-0.5, 2.0),
                covariance=tuple(rng.uniform(0, 1e-4) for _ in range(9)),
                track=rng.choice(("bottom", "water")))
        elif k == 1:
            line = dvl_json.encode_velocity_report(rng.gauss(0, 1), 0.0, 0.0, fmt="json_v1")
        elif k == 2:
            line = dvl_json.encode_position_local(rng.uniform(-99, 99), rng.uniform(-99, 99),
                                                  rng.uniform(0, 50), t_s=t)
        else:
            line = (b'{"response_to":"get_config","success":true,"error_message":"",'
                    b'"result":null,"format":"json_v3.1","type":"response"}\n')
        out.append(msgspec.json.decode(line))
    return out


def dvl_input(rng: random.Random) -> bytes:
    """DVL JSON lines: valid, with keys dropped or set to :data:`JSON_HOSTILE` values, or
    byte-mutated; some repeated."""
    lines = []
    for obj in dvl_corpus(rng):
        r = rng.random()
        if r < 0.3:
            lines.append(msgspec.json.encode(obj))
        elif r < 0.8:
            for _ in range(rng.randint(1, 3)):
                key = rng.choice(list(obj) + ["type", "format", "covariance", "time"])
                if rng.random() < 0.25:
                    obj.pop(key, None)
                else:
                    obj[key] = rng.choice(JSON_HOSTILE)
            try:
                lines.append(msgspec.json.encode(obj))
            except (msgspec.EncodeError, ValueError, OverflowError):
                lines.append(repr(obj).encode())
            if rng.random() < 0.2:  # NaN/Infinity as some emitters write it
                lines[-1] = lines[-1].replace(b"null", b"NaN", 1)
        else:
            lines.append(mutate(msgspec.json.encode(obj), rng, rng.randint(1, 4)))
        if rng.random() < 0.1:
            lines.append(lines[-1])  # the tank captures' repeated readings
    return b"\n".join(lines) + b"\n"


def pd6_input(rng: random.Random) -> bytes:
    """Teledyne PD6 ensembles (SA, TS, BI, BS, BE, BD lines), lines field- or byte-mutated."""
    lines: list[bytes] = []
    for _ in range(rng.randint(1, 4)):
        ens = pd6.encode_ensemble(1.7e9 + rng.uniform(0, 1e5), rng.gauss(0, 1), rng.gauss(0, 1),
                                  rng.gauss(0, 0.1), valid=rng.random() < 0.8,
                                  depth_m=rng.uniform(0, 100), altitude_m=rng.uniform(-1, 50),
                                  heading_rad=rng.uniform(-7, 7))
        for line in ens.splitlines():
            r = rng.random()
            if r < 0.4:
                lines.append(line)
            elif r < 0.85:
                lines.append(mutate_fields(line.decode(), rng).encode("utf-8", "surrogatepass"))
            else:
                lines.append(mutate(line, rng, rng.randint(1, 3)))
    return b"\r\n".join(lines) + b"\r\n"


def tlog_bytes(seconds: float = 2.0) -> bytes:
    """A synthetic boat tlog of ``seconds`` s (the benchmark's), built once per process."""
    p = SCRATCH / f"base-{seconds}.tlog"
    if not p.exists():
        synthesize_tlog(p, seconds)
    return p.read_bytes()


def dataflash_bytes() -> bytes:
    """The DataFlash reader tests' synthetic log (tests/helpers/dataflash_log.py)."""
    return synthetic_log()


CSV_COLUMNS = ("original_timestamp", "lat", "lon", "alt", "yaw", "yaw_rate", "surge", "sway",
               "thr_left", "thr_right", "extra")
"""The survey-boat CSV columns the ``blueboat-ntnu-csv`` mapping reads, and one it ignores."""


def csv_input(rng: random.Random) -> bytes:
    """A survey-boat CSV: header shuffled or missing a column, rows with hostile cells, time
    going back or jumping, bytes mutated."""
    cols = list(CSV_COLUMNS)
    if rng.random() < 0.2:
        rng.shuffle(cols)
    if rng.random() < 0.1:
        del cols[rng.randrange(len(cols))]
    rows = [",".join(cols)]
    t = rng.uniform(0, 1e6)
    for _ in range(rng.randint(0, 30)):
        t += rng.choice((100.0, 100.0, 100.0, -50.0, 20000.0, 0.0))
        vals = {"original_timestamp": f"{t:.0f}", "lat": f"{63.4 + rng.gauss(0, 1e-3):.7f}",
                "lon": f"{10.4 + rng.gauss(0, 1e-3):.7f}", "alt": "0.1",
                "yaw": f"{rng.uniform(-10, 370):.2f}", "yaw_rate": f"{rng.gauss(0, 0.1):.4f}",
                "surge": f"{rng.gauss(1, 0.5):.3f}", "sway": f"{rng.gauss(0, 0.1):.3f}",
                "thr_left": str(rng.randint(1000, 2000)), "thr_right": str(rng.randint(1000, 2000)),
                "extra": "x"}
        line = ",".join(vals.get(c, "") for c in cols)
        if rng.random() < 0.4:
            line = mutate_fields(line, rng)
        rows.append(line)
    data = ("\n".join(rows) + "\n").encode("utf-8", "surrogatepass")
    if rng.random() < 0.3:
        data = mutate(data, rng, rng.randint(1, 4))
    return data


def text_capture_input(rng: random.Random) -> bytes:
    """A text capture the sniffer must classify: NMEA with or without a logging prefix, DVL
    JSON, or Arduino-style CSV rows mixed with NMEA; mutated."""
    kind = rng.randrange(3)
    if kind == 0:
        body = nmea_input(rng)
        if rng.random() < 0.5:  # logging prefix with receive time
            body = b"".join(b"2024-05-01 12:00:%02d.%03d | INFO | "
                            % (rng.randrange(60), rng.randrange(1000)) + ln
                            for ln in body.splitlines(keepends=True))
        return body
    if kind == 1:
        return dvl_input(rng)
    rows = []
    for _ in range(rng.randint(1, 30)):
        if rng.random() < 0.3:
            rows.append(nmea_corpus(rng, 1)[0].strip())
        else:
            v = ([rng.uniform(-20, 20) for _ in range(12)]
                 + [rng.randint(900, 2100) for _ in range(2)])
            line = ",".join(f"{x:.2f}" for x in v)
            if rng.random() < 0.3:
                line = mutate_fields(line, rng)
            rows.append(line.encode("utf-8", "surrogatepass"))
    return b"\n".join(rows) + b"\n"
