"""drivers.tlog: reading telemetry logs, surviving corruption, writing them.

Synthetic logs are written with pymavlink's encoders into tmp_path; the real log is
``ardusub_small_logs/small.tlog`` (QGC, ArduSub, 263 s, 35,916 frames, 4 bad-CRC BlueOS
frames), cross-checked against pymavlink's own decoding.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from onboard.drivers.base import TIME_JUMP_S, UnreadableLog
from onboard.drivers.tlog import TlogReader, TlogWriter, pymavlink_parse_seconds, scan_header
from onboard.core.messages import ActuatorOutputs, Attitude, GnssFix, Imu, Parameter, VehicleInfo

T0 = 1_700_000_000.0


def write_synthetic(path: Path, n: int = 100, *, mavlink1: bool = False) -> list[bytes]:
    """A tlog of ``n`` ATTITUDE frames at 10 Hz interleaved with unneeded SYS_STATUS, plus a
    HEARTBEAT and a PARAM_VALUE up front. Returns the frames written, in order."""
    m = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = [m.heartbeat_encode(12, 3, 81, 19, 4, 3).pack(m, force_mavlink1=mavlink1),
              m.param_value_encode(b"SERVO1_FUNCTION", 33.0, 9, 2, 1).pack(m, force_mavlink1=mavlink1)]
    for i in range(n):
        frames.append(m.attitude_encode(i * 100, 0.001 * i, 0.5, 1.0, 0.1, 0.2, 0.3)
                      .pack(m, force_mavlink1=mavlink1))
        frames.append(m.sys_status_encode(1, 1, 1, 500, 12000, 100, 80, 0, 0, 0, 0, 0, 0)
                      .pack(m, force_mavlink1=mavlink1))
    with TlogWriter(path) as w:
        for k, f in enumerate(frames):
            w.write(T0 + 0.05 * k, f)
    return frames


def rolls(samples) -> list[int]:
    """The ATTITUDE frame indices (roll = 0.001 * i) among ``samples``."""
    return [round(s.roll_rad * 1000) for s in samples if isinstance(s, Attitude)]


# --------------------------------------------------------------------------- synthetic

@pytest.mark.parametrize("mavlink1", [False, True])
def test_roundtrip(tmp_path, mavlink1):
    p = tmp_path / "a.tlog"
    write_synthetic(p, 50, mavlink1=mavlink1)
    r = TlogReader(p)
    out = list(r)
    assert rolls(out) == list(range(50))
    assert [type(s) for s in out[:3]] == [VehicleInfo, Parameter, Attitude]
    assert out[0].t == pytest.approx(T0) and out[2].t == pytest.approx(T0 + 0.1)
    assert r.stats.records == 102 and r.stats.samples == 52 and not r.stats.rejected
    assert r.stats.by_type["SYS_STATUS"] == 50 and r.stats.by_type["ATTITUDE"] == 50


def test_types_filter_and_scan_header(tmp_path):
    p = tmp_path / "a.tlog"
    write_synthetic(p, 20)
    assert {type(s) for s in TlogReader(p, types=[Attitude])} == {Attitude}
    infos, params = scan_header(p)
    assert [(v.mav_type, v.autopilot) for v in infos] == [(12, 3)]
    assert [(x.name, x.value) for x in params] == [("SERVO1_FUNCTION", 33.0)]


def test_truncated_tail_is_counted(tmp_path):
    p = tmp_path / "a.tlog"
    write_synthetic(p, 30)
    data = p.read_bytes()
    p.write_bytes(data[:-20])  # cut inside the last frame
    r = TlogReader(p)
    assert rolls(r) == list(range(30))  # the last record was an unneeded SYS_STATUS
    assert r.stats.rejected == {"truncated": 1}


def test_flipped_byte_costs_one_frame(tmp_path):
    p = tmp_path / "a.tlog"
    frames = write_synthetic(p, 30)
    data = bytearray(p.read_bytes())
    # record 2 + 2*10 is ATTITUDE i=10; flip a payload byte
    off = sum(8 + len(f) for f in frames[:22]) + 8 + 14
    data[off] ^= 0x01
    p.write_bytes(bytes(data))
    r = TlogReader(p)
    assert rolls(r) == [i for i in range(30) if i != 10]
    assert r.stats.rejected == {"crc": 1}


def test_corrupt_length_byte_resyncs(tmp_path):
    p = tmp_path / "a.tlog"
    frames = write_synthetic(p, 30)
    data = bytearray(p.read_bytes())
    off = sum(8 + len(f) for f in frames[:22]) + 8 + 1  # length byte of ATTITUDE i=10
    data[off] = 200
    p.write_bytes(bytes(data))
    r = TlogReader(p)
    assert rolls(r) == [i for i in range(30) if i != 10]
    assert sum(r.stats.rejected.values()) == 1


def test_inserted_garbage_loses_nothing(tmp_path):
    p = tmp_path / "a.tlog"
    frames = write_synthetic(p, 30)
    data = p.read_bytes()
    off = sum(8 + len(f) for f in frames[:22])
    noise = b"\x00\xfd\xfe garbage \xfd" + os.urandom(50).replace(b"\xfd", b"x").replace(b"\xfe", b"y")
    p.write_bytes(noise + data[:off] + noise + data[off:])
    r = TlogReader(p)
    assert rolls(r) == list(range(30))
    assert r.stats.rejected == {"garbage": 2}


def test_time_going_backwards_is_rejected(tmp_path):
    p = tmp_path / "a.tlog"
    m = mav.MAVLink(None, 1, 1)
    with TlogWriter(p) as w:
        for t, roll in [(T0, 0.001), (T0 + 1, 0.002), (T0 + 0.5, 0.003), (T0 + 2, 0.004)]:
            w.write(t, m.attitude_encode(0, roll, 0, 0, 0, 0, 0).pack(m))
    r = TlogReader(p)
    out = list(r)
    assert rolls(out) == [1, 2, 4]
    assert r.stats.rejected == {"time_backwards": 1}


@pytest.mark.parametrize("content", [b"", os.urandom(5000), b"this is a text file\n" * 200,
                                     b"\x00" * 1000])
def test_not_a_tlog_is_unreadable(tmp_path, content):
    p = tmp_path / "x.tlog"
    p.write_bytes(content)
    with pytest.raises(UnreadableLog):
        TlogReader(p)


def test_missing_file_is_unreadable(tmp_path):
    with pytest.raises(UnreadableLog):
        TlogReader(tmp_path / "nope.tlog")


def test_fuzzed_logs_never_raise(tmp_path):
    import random

    p = tmp_path / "a.tlog"
    write_synthetic(p, 40)
    clean = p.read_bytes()
    rng = random.Random(5)
    for k in range(30):
        data = bytearray(clean)
        for _ in range(rng.randrange(1, 20)):
            data[rng.randrange(len(data))] = rng.randrange(256)
        q = tmp_path / f"f{k}.tlog"
        q.write_bytes(bytes(data))
        try:
            r = TlogReader(q)
        except UnreadableLog:
            continue
        out = list(r)
        # in time order, but for a damaged stamp far back: passed on for the engine's
        # time line (a single one is its time_outlier; test_timeline.py)
        assert all(a.t <= b.t or a.t - b.t > TIME_JUMP_S for a, b in zip(out, out[1:]))
        assert len(rolls(out)) >= 40 - 2 * sum(r.stats.rejected.values())


def test_pymavlink_parse_seconds(tmp_path):
    p = tmp_path / "a.tlog"
    write_synthetic(p, 20)
    assert pymavlink_parse_seconds(p) > 0


# --------------------------------------------------------------------------- real log

@pytest.fixture(scope="module")
def small_tlog(shared_data) -> Path:
    p = shared_data / "ardusub_small_logs" / "small.tlog"
    if not p.exists():
        pytest.skip(f"{p} not present")
    return p


@pytest.fixture(scope="module")
def small_samples(small_tlog):
    r = TlogReader(small_tlog)
    return list(r), r.stats


@pytest.mark.data
def test_real_tlog_counts_and_rejections(small_samples):
    out, stats = small_samples
    assert stats.records == 35916  # SOURCE.md: 35,916 messages incl. 4 BAD_DATA
    assert sum(stats.by_type.values()) == 35916 - 4  # by_type counts only good frames
    assert stats.rejected["crc"] == 4  # the four BlueOS camera frames with bad CRC
    kinds = Counter(type(s).__name__ for s in out)
    assert kinds["Attitude"] == 5245
    assert kinds["ActuatorOutputs"] == 528
    # a fix ArduSub sent again (the same time_usec) is one fix: 2 here
    assert stats.rejected["repeated_fix"] == 2
    assert kinds["GnssFix"] == 528 - stats.rejected["no_fix"] - stats.rejected["repeated_fix"]
    assert kinds["Imu"] == 528 - stats.rejected["unknown_scaling"]  # RAW_IMU; SCALED_IMU2 empty
    assert stats.rejected["empty"] == 528  # ArduSub's SCALED_IMU2 is all zeros
    assert stats.by_type["VFR_HUD"] == 3060 and stats.by_type["HEARTBEAT"] == 1056


@pytest.mark.data
def test_real_tlog_time_order_and_plausible_values(small_samples):
    out, _ = small_samples
    assert all(a.t <= b.t for a, b in zip(out, out[1:]))
    assert out[-1].t - out[0].t == pytest.approx(263.4, abs=1.0)
    fixes = [s for s in out if isinstance(s, GnssFix)]
    assert all(abs(f.lat_deg - 48.386) < 0.001 and abs(f.lon_deg + 124.63) < 0.001 for f in fixes)
    imu = [s for s in out if isinstance(s, Imu)]
    mean_az = sum(s.accel_z for s in imu) / len(imu)
    assert -10.5 < mean_az < -9.0  # at rest, z down: specific force ~ -g
    pwm = [x for s in out if isinstance(s, ActuatorOutputs) for x in s.pwm_us[:8]]
    assert 1100 <= min(pwm) and max(pwm) <= 1900
    vehicles = {(s.system_id, s.component_id, s.mav_type, s.autopilot) for s in out
                if isinstance(s, VehicleInfo)}
    assert (1, 1, 12, 3) in vehicles  # ArduSub submarine
    assert all(v[2] != 6 for v in vehicles)  # the QGC heartbeat is skipped


@pytest.mark.data
def test_real_tlog_matches_pymavlink(small_tlog, small_samples):
    out, _ = small_samples
    ours = [s for s in out if isinstance(s, Attitude)]
    conn = mavutil.mavlink_connection(str(small_tlog))
    ref = []
    while (msg := conn.recv_match(type=["ATTITUDE"])) is not None:
        ref.append((msg._timestamp, msg.roll, msg.pitch, msg.yaw, msg.yawspeed))
    conn.close()
    assert len(ref) == len(ours)
    for s, (t, r, p, y, yr) in zip(ours, ref):
        assert (s.t, s.roll_rad, s.pitch_rad, s.yaw_rad, s.yaw_rate_rps) == pytest.approx(
            (t, r, p, y, yr), rel=1e-6, abs=1e-9)


@pytest.mark.data
def test_real_tlog_scan_header(small_tlog):
    infos, params = scan_header(small_tlog)
    assert any(v.mav_type == 12 and v.autopilot == 3 for v in infos)
    by_name = {p.name: p.value for p in params}
    assert by_name["SERVO1_FUNCTION"] == 33.0  # Motor1
    assert by_name["FRAME_CONFIG"] == 2.0  # vectored 6DOF
    assert not any(math.isnan(p.value) for p in params)
