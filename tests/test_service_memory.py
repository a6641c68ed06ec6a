"""What the service keeps for as long as it runs stays bounded, whatever its inputs send:
the parsers' counts by record type (names read from the bytes) and the recorder's lists of
file names (docs/service.md, "Memory over a long run")."""

from __future__ import annotations

import json
import struct

import pytest

from onboard.drivers.base import BY_TYPE_KEYS, OTHER_TYPES
from onboard.drivers.nmea import checksum
from onboard.drivers.protocols import parser_for
from onboard.drivers.recording import RawRecord
from onboard.service import recorder as recorder_mod
from onboard.service.recorder import Recorder

N = 3 * BY_TYPE_KEYS
"""Distinct type names sent: more than the counts keep."""


def _nmea(i: int) -> bytes:
    body = f"PX{i:05d},1"
    return f"${body}*{checksum(body):02X}\r\n".encode()


def _mavlink_unknown_id(i: int) -> bytes:
    """A MAVLink 2 frame of an id outside every dialect (no CRC to check it against)."""
    msgid = 0x800000 + i
    payload = bytes(4)
    head = struct.pack("<BBBBBBB", 0xFD, len(payload), 0, 0, i & 0xFF, 1, 1)
    return head + msgid.to_bytes(3, "little") + payload + b"\x00\x00"


@pytest.mark.parametrize("kind, line", [
    ("nmea", _nmea),
    ("gpsd", lambda i: json.dumps({"class": f"C{i}"}).encode() + b"\n"),
    ("dvl-json", lambda i: json.dumps({"type": f"t{i}"}).encode() + b"\n"),
    ("mavlink", _mavlink_unknown_id),
])
def test_counts_by_type_keep_a_bounded_number_of_names(kind, line):
    parser = parser_for(kind, kind)
    for i in range(N):
        parser.feed(line(i), float(i))
    parser.feed(line(N), float(N))  # a MAVLink frame of unknown id counts once the next starts
    by_type = parser.stats.by_type
    assert len(by_type) <= BY_TYPE_KEYS + 1
    assert by_type[OTHER_TYPES] > 0
    # every record is still counted, the names beyond the bound together
    named = sum(n for k, n in by_type.items() if k not in ("ignored", "unknown"))
    assert named >= N


def test_counts_by_type_below_the_bound_are_by_name():
    parser = parser_for("nmea", "gps")
    for i in range(10):
        parser.feed(_nmea(i) * 2, float(i))
    assert OTHER_TYPES not in parser.stats.by_type
    assert parser.stats.by_type["PX00003"] == 2


def test_recorder_lists_the_newest_file_names(tmp_path, monkeypatch):
    monkeypatch.setattr(recorder_mod, "FILES_LISTED", 8)
    rec = Recorder(tmp_path, rotate_mb=0.004, max_total_mb=0.010, fsync=False)
    for i in range(40):
        rec.write(RawRecord(t=float(i), source="imu", kind="mavlink", data=bytes(200)))
        rec.rotate()
    rec.close()
    assert rec.part == 40
    assert len(rec.files) == 8 and rec.path == rec.files[-1] and rec.path.exists()
    assert rec.files[0].name.endswith("-0033.onbrec")
    assert 0 < len(rec.deleted) <= 8


def _resolution_reference(samples):
    """The resolution check's window as tuples in a deque (what the arrays replace), for
    the verdicts and RMS figures it gives."""
    from collections import deque

    from onboard.monitor.current_resolution import (RESOLVE_MIN_SPAN, RESOLVE_MIN_STD_MPS,
                                                    RESOLVE_SNR, RESOLVE_WINDOW_S)

    win: deque = deque()
    sx = s_s = 0.0
    out = []
    unresolved, rms, sigma = False, 0.0, 0.0
    for t, v, sd in samples:
        x2, s2 = v * v, sd * sd
        win.append((t, x2, s2))
        sx += x2
        s_s += s2
        while win[0][0] < t - RESOLVE_WINDOW_S:
            _, ox, os = win.popleft()
            sx -= ox
            s_s -= os
        if t - win[0][0] >= RESOLVE_MIN_SPAN * RESOLVE_WINDOW_S:
            n = len(win)
            rms, sigma = (max(sx, 0.0) / n) ** 0.5, (max(s_s, 0.0) / n) ** 0.5
            unresolved = sigma > RESOLVE_MIN_STD_MPS and rms < RESOLVE_SNR * sigma
        out.append((unresolved, rms, sigma))
    return out


def _ticks(n: int, rate_hz: float = 20.0, seed: int = 3):
    import numpy as np

    rng = np.random.default_rng(seed)
    v = rng.normal(0.0, 0.2, n).cumsum() * 0.01
    sd = 0.1 + 0.1 * rng.random(n)
    return [(1000.0 + k / rate_hz, float(v[k]), float(sd[k])) for k in range(n)]


def test_current_resolution_window_gives_the_same_verdicts_in_arrays():
    from onboard.monitor.current_resolution import AxisResolution

    samples = _ticks(40_000)
    ax = AxisResolution()
    got = []
    for t, v, sd in samples:
        got.append((ax.add(t, v, sd), ax.rms, ax.sigma))
    assert got == _resolution_reference(samples)  # to the bit


def test_current_resolution_window_holds_24_bytes_a_tick():
    """A full window at 20 ticks a second (12 000 entries) holds about 24 B an entry, not
    the ~140 B of a tuple of three floats in a deque."""
    import tracemalloc

    from onboard.monitor.current_resolution import AxisResolution, RESOLVE_WINDOW_S

    samples = _ticks(30_000)
    ax = AxisResolution()
    tracemalloc.start()
    try:
        for t, v, sd in samples:
            ax.add(t, v, sd)
        held, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    entries = RESOLVE_WINDOW_S * 20.0
    assert held / entries < 40.0, held / entries
