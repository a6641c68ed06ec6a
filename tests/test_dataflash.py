"""drivers.dataflash: ArduPilot DataFlash logs, synthetic and real.

Synthetic logs are built record by record (tests/helpers/dataflash_log.py); the real
log is ``ardusub_small_logs/small.BIN`` (ArduSub 4.1.0, 7,510 records, 23.6 s), cross-checked
against pymavlink's DFReader.
"""

from __future__ import annotations

import math
import random
from collections import Counter
from pathlib import Path

import pytest

from onboard.drivers.base import UnreadableLog
from onboard.drivers.dataflash import DataflashReader
from onboard.core.messages import (
    ActuatorOutputs,
    Attitude,
    GnssFix,
    Imu,
    Parameter,
    Pressure,
    PropellerRpm,
    RcChannels,
    VehicleInfo,
)
from tests.helpers.dataflash_log import HEAD, record, synthetic_log


def read(path: Path) -> tuple[list, DataflashReader]:
    r = DataflashReader(path)
    return list(r), r


def test_synthetic_log_decodes_every_type(tmp_path):
    p = tmp_path / "a.bin"
    p.write_bytes(synthetic_log())
    out, r = read(p)
    kinds = Counter(type(s) for s in out)
    assert kinds[GnssFix] == 20  # only the first receiver
    assert kinds[Attitude] == 20 and kinds[PropellerRpm] == 20 and kinds[ActuatorOutputs] == 20
    assert kinds[Imu] == 2 and kinds[Parameter] == 2 and kinds[VehicleInfo] == 1
    assert not r.stats.rejected
    assert all(a.t <= b.t for a, b in zip(out, out[1:]))  # the late IMU was re-ordered
    v = next(s for s in out if isinstance(s, VehicleInfo))
    assert (v.mav_type, v.autopilot, v.system_id) == (11, 3, 7)  # FRAME_CLASS 2: a boat
    g = next(s for s in out if isinstance(s, GnssFix))
    assert (g.lat_deg, g.lon_deg, g.alt_m) == pytest.approx((47.5, -122.3, 12.34))
    assert g.hdop == pytest.approx(0.9) and g.sog_mps == 1.5
    assert g.cog_rad == pytest.approx(math.pi / 2) and g.t == pytest.approx(0.1)
    a = next(s for s in out if isinstance(s, Attitude))
    assert (a.roll_rad, a.pitch_rad, a.yaw_rad) == pytest.approx(
        (math.radians(1.5), math.radians(-2.0), math.radians(90.0)))
    assert next(s for s in out if isinstance(s, PropellerRpm)).rpm == (1200.0,)
    assert next(s for s in out if isinstance(s, ActuatorOutputs)).pwm_us == (1500, 1600, 1400, 0)
    imu = [s for s in out if isinstance(s, Imu)]
    assert [s.accel_z for s in imu] == pytest.approx([-9.7, -9.8])
    assert imu[0].source == "dataflash/IMU[1]"  # IMU2 is the second instance


def test_types_filter(tmp_path):
    p = tmp_path / "a.bin"
    p.write_bytes(synthetic_log())
    assert {type(s) for s in DataflashReader(p, types=[Imu, "attitude"])} == {Imu, Attitude}


def test_truncated_tail_is_counted(tmp_path):
    p = tmp_path / "a.bin"
    data = synthetic_log()
    p.write_bytes(data[:-10])
    out, r = read(p)
    assert Counter(type(s) for s in out)[Imu] == 1
    assert r.stats.rejected == {"truncated": 1}


@pytest.mark.parametrize("seed", [0, 1, 584, 1275])
def test_inserted_garbage_costs_at_most_the_record_before(tmp_path, seed):
    """Seeds 584 and 1275 put an FMT type after the inserted ``A3 95``: 89 bytes that
    frame like a record and swallowed the ATT after them until a format that cannot be
    understood made the reader go on from inside it."""
    p = tmp_path / "a.bin"
    data = synthetic_log()
    cut = data.index(record("ATT", 500_010, 0, 150, 0, -200, 0, 9000, 0, 0, 3))
    rng = random.Random(seed)
    junk = bytes(rng.randrange(256) for _ in range(40)).replace(b"\xa3", b"x")
    p.write_bytes(data[:cut] + b"\xa3garbage\xa3\x95" + junk + data[cut:])
    out, r = read(p)
    kinds = Counter(type(s) for s in out)
    assert kinds[Attitude] == 20
    assert kinds[GnssFix] + kinds[ActuatorOutputs] + kinds[PropellerRpm] >= 59
    assert set(r.stats.rejected) <= {"garbage", "unknown_format", "bad_fmt"}


def test_unknown_record_type_is_counted(tmp_path):
    p = tmp_path / "a.bin"
    data = synthetic_log()
    cut = data.index(record("ATT", 500_010, 0, 150, 0, -200, 0, 9000, 0, 0, 3))
    p.write_bytes(data[:cut] + HEAD + bytes([250]) + b"\x00" * 10 + data[cut:])
    out, r = read(p)
    assert Counter(type(s) for s in out)[Attitude] == 20
    assert r.stats.rejected["unknown_format"] >= 1


@pytest.mark.parametrize("content", [b"", random.Random(3).randbytes(3000), b"not a log\n" * 100])
def test_not_dataflash_is_unreadable(tmp_path, content):
    p = tmp_path / "x.bin"
    p.write_bytes(content)
    with pytest.raises(UnreadableLog):
        DataflashReader(p)


def test_fuzzed_logs_never_raise(tmp_path):
    import random

    clean = synthetic_log()
    rng = random.Random(11)
    for k in range(30):
        data = bytearray(clean)
        for _ in range(rng.randrange(1, 30)):
            data[rng.randrange(len(data))] = rng.randrange(256)
        q = tmp_path / f"f{k}.bin"
        q.write_bytes(bytes(data))
        try:
            out = list(DataflashReader(q))
        except UnreadableLog:
            continue
        assert all(a.t <= b.t for a, b in zip(out, out[1:]))


# --------------------------------------------------------------------------- real log

@pytest.fixture(scope="module")
def small_bin(shared_data) -> Path:
    p = shared_data / "ardusub_small_logs" / "small.BIN"
    if not p.exists():
        pytest.skip(f"{p} not present")
    return p


@pytest.mark.data
def test_real_bin_counts(small_bin):
    out, r = read(small_bin)
    kinds = Counter(type(s).__name__ for s in out)
    # SOURCE.md: IMU 594, BARO 474 (two instances), ATT/RCOU/RCIN 237, PARM 876
    assert kinds == {"Imu": 594, "Pressure": 474, "Attitude": 237, "ActuatorOutputs": 237,
                     "RcChannels": 237, "Parameter": 876, "VehicleInfo": 1}
    assert r.stats.records == 7510 and not r.stats.rejected
    assert r.stats.by_type["MAG"] == 474  # counted, not decoded
    assert all(a.t <= b.t for a, b in zip(out, out[1:]))
    imu_t = [s.t for s in out if isinstance(s, Imu)]
    assert imu_t[-1] - imu_t[0] == pytest.approx(23.6, abs=0.5)  # a late PARM comes at 401 s


@pytest.mark.data
def test_real_bin_values_plausible(small_bin):
    out, _ = read(small_bin)
    v = next(s for s in out if isinstance(s, VehicleInfo))
    assert (v.mav_type, v.autopilot) == (12, 3)  # "ArduSub V4.1.0"
    rcou = [s.pwm_us for s in out if isinstance(s, ActuatorOutputs)]
    assert all(1492 <= x <= 1508 for pwm in rcou for x in pwm[:6])  # disarmed, neutral
    assert all(len(s.pwm_us) == 14 for s in out if isinstance(s, RcChannels))
    imu = [s for s in out if isinstance(s, Imu)]
    assert -10.3 < sum(s.accel_z for s in imu) / len(imu) < -9.3
    press = [s.pressure_pa for s in out if isinstance(s, Pressure)]
    assert all(90_000 < x < 110_000 for x in press)


@pytest.mark.data
def test_real_bin_matches_pymavlink(small_bin):
    from pymavlink import DFReader

    ref = []
    d = DFReader.DFReader_binary(str(small_bin))
    while (m := d.recv_match(type=["ATT"])) is not None:
        ref.append((m.TimeUS / 1e6, math.radians(m.Roll), math.radians(m.Pitch),
                    math.radians(m.Yaw)))
    ours = [s for s in read(small_bin)[0] if isinstance(s, Attitude)]
    assert len(ours) == len(ref) == 237
    for s, (t, r, p, y) in zip(ours, ref):
        assert (s.t, s.roll_rad, s.pitch_rad, s.yaw_rad) == pytest.approx((t, r, p, y), abs=1e-9)
