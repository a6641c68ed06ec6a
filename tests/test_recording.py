"""The recording format is append-only and survives torn writes and damaged frames."""

from __future__ import annotations

import pytest

from onboard.drivers.base import ReadStats, UnreadableLog
from onboard.drivers.recording import RawRecord, RecordingWriter, encode_frame, read_records


def _write(path, n=100):
    with RecordingWriter(path, fsync=False) as w:
        for i in range(n):
            w.write(RawRecord(t=1000.0 + i * 0.1, source="gps", kind="nmea",
                              data=b"$GPGGA,%d*00\r\n" % i))


def test_round_trip(tmp_path):
    p = tmp_path / "r.onb"
    _write(p)
    recs = list(read_records(p))
    assert len(recs) == 100
    assert recs[5].data == b"$GPGGA,5*00\r\n" and recs[5].t == pytest.approx(1000.5)


def test_appending_after_a_restart_keeps_one_file(tmp_path):
    p = tmp_path / "r.onb"
    _write(p, 10)
    _write(p, 10)
    assert len(list(read_records(p))) == 20


def test_torn_tail_loses_only_the_last_frame(tmp_path):
    p = tmp_path / "r.onb"
    _write(p)
    data = p.read_bytes()
    p.write_bytes(data[:-7])
    stats = ReadStats()
    assert len(list(read_records(p, stats))) == 99
    assert stats.rejected["truncated"] == 1


def test_damaged_frame_in_the_middle_is_skipped_and_the_rest_read(tmp_path):
    p = tmp_path / "r.onb"
    _write(p)
    data = bytearray(p.read_bytes())
    frame = len(encode_frame(RawRecord(t=1000.0, source="gps", kind="nmea", data=b"$GPGGA,0*00\r\n")))
    data[8 + 50 * frame + 15] ^= 0xFF  # flip a payload byte of frame 50
    p.write_bytes(bytes(data))
    stats = ReadStats()
    recs = list(read_records(p, stats))
    assert len(recs) == 99
    assert stats.rejected["crc"] == 1


def test_not_a_recording(tmp_path):
    p = tmp_path / "x"
    p.write_bytes(b"hello")
    with pytest.raises(UnreadableLog):
        list(read_records(p))
