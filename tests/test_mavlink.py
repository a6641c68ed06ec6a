"""drivers.mavlink: the selective MAVLink decoder and the live stream parser.

Frames are produced by pymavlink's own encoders, so every layout and CRC_EXTRA is checked
against an independent implementation.
"""

from __future__ import annotations

import math
import os
import random

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from onboard.drivers.mavlink import GRAVITY_MSS, HANDLERS, MavlinkParser
from onboard.drivers.mavlink_frame import x25crc
from onboard.core.messages import (
    ActuatorOutputs,
    Altitude,
    Attitude,
    DvlVelocity,
    GnssFix,
    Heading,
    Imu,
    Parameter,
    Pressure,
    PropellerRpm,
    RcChannels,
    VehicleInfo,
    VelocityOverGround,
)


def link(sysid: int = 1, compid: int = 1) -> mav.MAVLink:
    return mav.MAVLink(None, srcSystem=sysid, srcComponent=compid)


def parse(*frames: bytes, t: float = 10.0, **kw) -> tuple[list, MavlinkParser]:
    p = MavlinkParser(**kw)
    out = p.feed(b"".join(frames), t)
    return out, p


def ardupilot_heartbeat(m: mav.MAVLink) -> bytes:
    return m.heartbeat_encode(12, 3, 81, 19, 4, 3).pack(m)


def test_crc_matches_pymavlink_x25():
    rng = random.Random(1)
    for n in (0, 1, 7, 40, 255):
        data = bytes(rng.randrange(256) for _ in range(n))
        ref = mavutil.x25crc(data)
        ref.accumulate(bytes([77]))
        assert x25crc(data, 77) == ref.crc


def test_handlers_cover_the_brief():
    names = {s.name for s in HANDLERS.values()}
    assert {"GPS_RAW_INT", "GLOBAL_POSITION_INT", "ATTITUDE", "SCALED_IMU", "SCALED_IMU2",
            "SCALED_IMU3", "RAW_IMU", "HIGHRES_IMU", "VFR_HUD", "SERVO_OUTPUT_RAW",
            "RC_CHANNELS", "RPM", "VISION_SPEED_ESTIMATE", "VISION_POSITION_DELTA",
            "DISTANCE_SENSOR", "SCALED_PRESSURE", "SCALED_PRESSURE2", "SCALED_PRESSURE3",
            "HEARTBEAT", "PARAM_VALUE"} <= names


def test_gps_raw_int_units_and_unknowns():
    m = link()
    f = m.gps_raw_int_encode(0, 6, 483861418, -1246305732, 12345, 160, 65535, 250, 9000, 21,
                             0, 1500, 0).pack(m)
    (s,), _ = parse(f)
    assert isinstance(s, GnssFix)
    assert s.lat_deg == pytest.approx(48.3861418) and s.lon_deg == pytest.approx(-124.6305732)
    assert s.alt_m == pytest.approx(12.345)
    assert s.fix_quality == 4  # RTK fixed
    assert s.hdop == pytest.approx(1.6) and s.num_sats == 21
    assert s.sog_mps == pytest.approx(2.5) and s.cog_rad == pytest.approx(math.pi / 2)
    assert s.h_acc_m == pytest.approx(1.5) and s.v_acc_m is None  # 0 = not given
    assert s.speed_acc_mps is None
    f = m.gps_raw_int_encode(0, 3, 1, 2, 0, 160, 65535, 250, 9000, 12, 0, 1500, 0, 300).pack(m)
    (s,), _ = parse(f)
    assert s.speed_acc_mps == pytest.approx(0.3)  # vel_acc mm/s
    assert s.source == "mavlink:1/GPS_RAW_INT" and s.t == 10.0
    # unknown velocity/course/sats and no-fix frames
    f = m.gps_raw_int_encode(0, 3, 1, 2, 0, 65535, 65535, 65535, 65535, 255).pack(m)
    (s,), _ = parse(f)
    assert (s.hdop, s.sog_mps, s.cog_rad, s.num_sats) == (None, None, None, None)
    out, p = parse(m.gps_raw_int_encode(0, 1, 0, 0, 0, 0, 0, 0, 0, 0).pack(m))
    assert out == [] and p.stats.rejected["no_fix"] == 1


def test_global_position_int_gives_velocity_and_heading():
    m = link()
    (v, h), _ = parse(m.global_position_int_encode(0, 0, 0, 0, 0, 150, -20, 5, 27000).pack(m))
    assert isinstance(v, VelocityOverGround) and isinstance(h, Heading)
    assert (v.v_north_mps, v.v_east_mps, v.v_down_mps) == pytest.approx((1.5, -0.2, 0.05))
    assert h.heading_rad == pytest.approx(1.5 * math.pi) and h.reference == "true"
    out, _ = parse(m.global_position_int_encode(0, 0, 0, 0, 0, 1, 2, 3, 65535).pack(m))
    assert [type(s) for s in out] == [VelocityOverGround]


def test_attitude():
    m = link()
    (a,), _ = parse(m.attitude_encode(5, 0.1, -0.2, 3.0, 0.01, 0.02, -0.03).pack(m))
    assert isinstance(a, Attitude)
    assert (a.roll_rad, a.pitch_rad, a.yaw_rad) == pytest.approx((0.1, -0.2, 3.0))
    assert a.yaw_rate_rps == pytest.approx(-0.03)
    out, p = parse(m.attitude_encode(5, float("nan"), 0, 0, 0, 0, 0).pack(m))
    assert out == [] and p.stats.rejected["nan"] == 1


def test_scaled_imu_is_specific_force_frd():
    # ArduPilot: a level vehicle at rest reads zacc ~ -1000 mg (specific force, z down).
    m = link()
    (s,), _ = parse(m.scaled_imu2_encode(0, 10, -20, -1000, 5, -6, 7, 0, 0, 0).pack(m))
    assert isinstance(s, Imu) and s.source == "mavlink:1/SCALED_IMU2"
    assert s.accel_z == pytest.approx(-GRAVITY_MSS)
    assert s.accel_x == pytest.approx(0.01 * GRAVITY_MSS)
    assert (s.gyro_x, s.gyro_y, s.gyro_z) == pytest.approx((0.005, -0.006, 0.007))
    # an IMU instance the autopilot does not have is all zeros: skipped, counted
    out, p = parse(m.scaled_imu3_encode(0, 0, 0, 0, 0, 0, 0, 1, 2, 3).pack(m))
    assert out == [] and p.stats.rejected["empty"] == 1


def test_raw_imu_only_for_ardupilot():
    m = link()
    raw = m.raw_imu_encode(0, 0, 0, -1000, 0, 0, 100, 0, 0, 0).pack(m)
    out, p = parse(raw)
    assert out == [] and p.stats.rejected["unknown_scaling"] == 1
    out, _ = parse(ardupilot_heartbeat(m), raw)
    imu = [s for s in out if isinstance(s, Imu)]
    assert imu[0].accel_z == pytest.approx(-GRAVITY_MSS) and imu[0].gyro_z == pytest.approx(0.1)


def test_highres_imu_si_units():
    m = link()
    f = m.highres_imu_encode(0, 0.1, 0.2, -9.8, 0.01, 0.02, 0.03, 0, 0, 0, 0, 0, 0, 0, 0x3F).pack(m)
    (s,), _ = parse(f)
    assert (s.accel_x, s.accel_z, s.gyro_z) == pytest.approx((0.1, -9.8, 0.03))
    for bad in (float("nan"), float("inf")):
        f = m.highres_imu_encode(0, bad, 0, -9.8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x3F).pack(m)
        out, p = parse(f)
        assert out == [] and p.stats.rejected["nan"] == 1


def test_vfr_hud_heading():
    m = link()
    (h,), _ = parse(m.vfr_hud_encode(0, 1.0, 225, 0, 0, 0).pack(m))
    assert isinstance(h, Heading) and h.heading_rad == pytest.approx(math.radians(225))
    assert h.source == "mavlink:1/VFR_HUD"


def test_servo_output_raw_v2_has_16_channels_v1_has_8():
    m = link()
    msg = m.servo_output_raw_encode(0, 0, *range(1100, 1900, 100), *range(1000, 1800, 100))
    (s,), _ = parse(msg.pack(m))
    assert isinstance(s, ActuatorOutputs) and len(s.pwm_us) == 16
    assert s.pwm_us[0] == 1100 and s.pwm_us[8] == 1000 and s.pwm_us[15] == 1700
    (s1,), _ = parse(msg.pack(m, force_mavlink1=True))
    assert s1.pwm_us == s.pwm_us[:8]


def test_rc_channels_uses_chancount():
    m = link()
    chans = [1500 + i for i in range(18)]
    (s,), _ = parse(m.rc_channels_encode(0, 8, *chans, 255).pack(m))
    assert isinstance(s, RcChannels) and s.pwm_us == tuple(float(c) for c in chans[:8])
    # ArduSub sends chancount 0: trailing unused channels are trimmed
    chans = [1500] * 11 + [0] * 7
    (s,), _ = parse(m.rc_channels_encode(0, 0, *chans, 0).pack(m))
    assert len(s.pwm_us) == 11


def test_rpm_drops_invalid_sensor():
    m = link()
    (s,), _ = parse(m.rpm_encode(1200.0, 900.0).pack(m))
    assert isinstance(s, PropellerRpm) and s.rpm == (1200.0, 900.0)
    (s,), _ = parse(m.rpm_encode(1200.0, -1.0).pack(m))
    assert s.rpm == (1200.0,)
    out, p = parse(m.rpm_encode(-1.0, -1.0).pack(m))
    assert out == [] and p.stats.rejected["invalid"] == 1


def test_vision_speed_and_position_delta():
    m = link()
    (v,), _ = parse(m.vision_speed_estimate_encode(0, 0.5, -0.25, 0.1).pack(m))
    assert isinstance(v, VelocityOverGround) and v.source.endswith("VISION_SPEED_ESTIMATE")
    assert (v.v_north_mps, v.v_east_mps, v.v_down_mps) == pytest.approx((0.5, -0.25, 0.1))
    f = m.vision_position_delta_encode(0, 200_000, [0, 0, 0.01], [0.1, -0.02, 0.004], 80.0).pack(m)
    (d,), _ = parse(f)
    assert isinstance(d, DvlVelocity) and d.track == "bottom" and d.valid
    assert (d.vx, d.vy, d.vz) == pytest.approx((0.5, -0.1, 0.02))
    f = m.vision_position_delta_encode(0, 200_000, [0, 0, 0], [0, 0, 0], 0.0).pack(m)
    (d,), _ = parse(f)
    assert not d.valid


def test_distance_sensor_downward_only():
    m = link()
    (a,), _ = parse(m.distance_sensor_encode(0, 20, 5000, 345, 0, 0, 25, 0).pack(m))
    assert isinstance(a, Altitude) and a.altitude_m == pytest.approx(3.45)
    out, p = parse(m.distance_sensor_encode(0, 20, 5000, 345, 0, 0, 0, 0).pack(m))  # forward
    assert out == [] and not p.stats.rejected
    out, p = parse(m.distance_sensor_encode(0, 20, 5000, 6000, 0, 0, 25, 0).pack(m))
    assert out == [] and p.stats.rejected["out_of_range"] == 1


def test_scaled_pressure_hpa_to_pa():
    m = link()
    (p,), _ = parse(m.scaled_pressure2_encode(0, 1015.8, 0.0, 1245).pack(m))
    assert isinstance(p, Pressure) and p.pressure_pa == pytest.approx(101580.0, abs=0.01)
    assert p.temperature_c == pytest.approx(12.45)
    assert p.source == "mavlink:1/SCALED_PRESSURE2"


def test_heartbeat_skips_gcs_unless_asked():
    gcs = link(255, 190)
    frame = gcs.heartbeat_encode(6, 8, 192, 0, 4, 3).pack(gcs)
    assert parse(frame)[0] == []
    (v,), _ = parse(frame, include_gcs=True)
    assert v.mav_type == 6
    m = link()
    (v,), _ = parse(ardupilot_heartbeat(m))
    assert isinstance(v, VehicleInfo)
    assert (v.system_id, v.component_id, v.mav_type, v.autopilot) == (1, 1, 12, 3)


def test_param_value_name_is_nul_stripped():
    m = link()
    (p,), _ = parse(m.param_value_encode(b"SERVO1_FUNCTION", 33.0, 9, 800, 900).pack(m))
    assert isinstance(p, Parameter) and p.name == "SERVO1_FUNCTION" and p.value == 33.0


def test_other_component_source_names_component():
    m = link(1, 194)
    (a,), _ = parse(m.attitude_encode(0, 0, 0, 0, 0, 0, 0).pack(m))
    assert a.source == "mavlink:1.194/ATTITUDE"


def test_v2_zero_truncated_payload_is_padded():
    m = link()
    frame = m.scaled_imu_encode(0, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0).pack(m)
    assert frame[1] < 24  # pymavlink truncated the trailing zeros
    (s,), _ = parse(frame)
    assert s.accel_z == pytest.approx(-GRAVITY_MSS) and s.gyro_z == 0.0


def test_signed_frames_are_accepted():
    m = link()
    m.signing.secret_key = bytes(range(32))
    m.signing.link_id = 0
    m.signing.timestamp = 1
    m.signing.sign_outgoing = True
    frame = m.attitude_encode(0, 0.1, 0.2, 0.3, 0, 0, 0).pack(m)
    assert frame[2] & 1  # signed
    (a, b), p = parse(frame + m.attitude_encode(0, 0.4, 0, 0, 0, 0, 0).pack(m))
    assert (a.roll_rad, b.roll_rad) == pytest.approx((0.1, 0.4)) and not p.stats.rejected


def test_unknown_incompat_flags_are_rejected():
    m = link()
    frame = bytearray(m.attitude_encode(0, 0.1, 0.2, 0.3, 0, 0, 0).pack(m))
    frame[2] = 0x02
    out, p = parse(bytes(frame))
    assert out == [] and p.stats.rejected["incompat"] == 1


def test_bad_crc_and_garbage_are_counted_and_survived():
    m = link()
    good = [m.attitude_encode(i, 0.01 * i, 0.5, 0.5, 0.1, 0.1, 0.1).pack(m) for i in range(12)]
    bad = bytearray(good[2])
    bad[15] ^= 0x40
    # a false start byte claiming a 253-byte frame holds decoding back until 261 bytes
    # have arrived (then its CRC fails and the search resumes right after it)
    stream = b"hello\xfe\xfd" + good[0] + good[1] + bytes(bad) + b"\x00" * 7 + b"".join(good[3:])
    out, p = parse(stream)
    assert [round(a.roll_rad, 2) for a in out] == [0.01 * i for i in range(12) if i != 2]
    # the corrupt frame, plus false start bytes in the noise, fail their CRC
    assert p.stats.rejected["crc"] >= 1
    assert p.stats.rejected["garbage"] >= 1


def _mixed_stream(n: int = 200) -> bytes:
    m = link()
    rng = random.Random(7)
    parts = [ardupilot_heartbeat(m)]
    for i in range(n):
        k = rng.randrange(5)
        if k == 0:
            parts.append(m.attitude_encode(i, rng.random(), 0, 0, 0, 0, 0).pack(m))
        elif k == 1:
            parts.append(m.raw_imu_encode(i, 1, 2, -1000, 3, 4, 5, 0, 0, 0).pack(m))
        elif k == 2:
            parts.append(m.sys_status_encode(0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0).pack(m))
        elif k == 3:
            parts.append(os.urandom(rng.randrange(1, 30)))  # line noise
        else:
            f = bytearray(m.gps_raw_int_encode(i, 3, 1, 2, 3, 4, 5, 6, 7, 8).pack(m))
            f[rng.randrange(1, len(f))] ^= 0x10  # corrupted frame
            parts.append(bytes(f))
    return b"".join(parts)


def test_chunked_stream_equals_one_chunk():
    stream = _mixed_stream()
    whole = MavlinkParser()
    ref = whole.feed(stream, 1.0)
    assert len(ref) > 50
    rng = random.Random(3)
    for _ in range(5):
        p = MavlinkParser()
        out, i = [], 0
        while i < len(stream):
            k = rng.randrange(1, 60)
            out += p.feed(stream[i:i + k], 1.0)
            i += k
        assert out == ref
        assert p.stats.as_dict() == whole.stats.as_dict()


def test_types_filter():
    m = link()
    frames = [ardupilot_heartbeat(m), m.attitude_encode(0, 0, 0, 0, 0, 0, 0).pack(m),
              m.scaled_imu_encode(0, 1, 1, -1000, 0, 0, 0, 0, 0, 0).pack(m)]
    out, _ = parse(*frames, types=["imu"])
    assert [type(s) for s in out] == [Imu]
    out, _ = parse(*frames, types=[Attitude, VehicleInfo])
    assert [type(s) for s in out] == [VehicleInfo, Attitude]


def test_a_fix_sent_again_with_its_time_is_one_fix():
    """ArduPilot sends its newest fix at the rate asked; a slower receiver's fix goes out
    again with the same time_usec, which is one measurement, not two. A time_usec of 0
    (unknown) is never a repeat."""
    m = link()

    def fix(time_usec: int, lat: int = 480000000) -> bytes:
        return m.gps_raw_int_encode(time_usec, 3, lat, -40000000, 10000, 120, 65535, 150,
                                    9000, 9).pack(m)

    out, p = parse(fix(1_000_000) + fix(1_000_000) + fix(1_200_000) + fix(0) + fix(0))
    assert [type(s).__name__ for s in out] == ["GnssFix"] * 4
    assert p.stats.rejected == {"repeated_fix": 1}
