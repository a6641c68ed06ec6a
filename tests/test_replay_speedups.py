"""The replay's fast paths give the reference results: the generated value checkers of
:mod:`onboard.validate` against the generic one, and the early stop of
:func:`drivers.tlog.scan_header`."""

from __future__ import annotations

import math
import random
from pathlib import Path

import msgspec
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from drivers.tlog import TlogWriter, scan_header
from onboard import validate
from onboard.core.messages import (
    ActuatorOutputs,
    Attitude,
    GnssFix,
    Heading,
    Imu,
    Parameter,
    VehicleInfo,
)

T0 = 1.7e9

_SAMPLES = [
    Imu(t=T0, source="s", accel_x=0.1, accel_y=-0.2, accel_z=-9.8, gyro_x=0.01,
        gyro_y=0.0, gyro_z=0.3),
    GnssFix(t=T0, source="s", lat_deg=41.6, lon_deg=-71.3, fix_quality=1, alt_m=3.0,
            sog_mps=1.5, cog_rad=0.2),
    Heading(t=T0, source="s", heading_rad=1.0),
    Attitude(t=T0, source="s", roll_rad=0.0, pitch_rad=0.1, yaw_rad=2.0),
    ActuatorOutputs(t=T0, source="s", pwm_us=(1500.0, 1600.0, 1400.0)),
    Parameter(t=T0, source="s", name="SERVO1_FUNCTION", value=26.0),
    VehicleInfo(t=T0, source="s", system_id=1, component_id=1, mav_type=11, autopilot=3),
]
_BAD = [math.nan, math.inf, -math.inf, 1e308, -1e308, 1.7976931348623157e308, 1e6, -1e6,
        0.0, -1.0, 5000.0, None]


def _reason(fn, s) -> str | None:
    try:
        return fn(s)
    except TypeError:
        return "TypeError"


def test_generated_checkers_give_the_reference_reasons() -> None:
    """Random corruptions of every field (NaN, infinities, overflowing sums, out of range,
    None, a zero or negative time): the same verdict and reason as the generic check."""
    rng = random.Random(0)
    for s in _SAMPLES:
        assert validate.check_values(s) is None
        names = [n for n in s.__struct_fields__ if n != "source"]
        for _ in range(400):
            kw = {rng.choice(names): rng.choice(_BAD) for _ in range(rng.randint(1, 3))}
            bad = msgspec.structs.replace(s, **kw)
            assert _reason(validate.check_values, bad) == _reason(validate._reason, bad), bad
    assert validate.check_values(msgspec.structs.replace(_SAMPLES[0], accel_x=math.nan)) == "nan"
    assert validate.check_values(msgspec.structs.replace(_SAMPLES[0], accel_x=400.0)) == "range"
    assert validate.check_values(msgspec.structs.replace(_SAMPLES[1], fix_quality=0)) == "no_fix"
    assert validate.check_values(msgspec.structs.replace(_SAMPLES[2], t=0.0)) == "zero_time"


def _write(path: Path, params: list[tuple[bytes, float, int, int]], *, late: bool) -> None:
    """HEARTBEAT, PARAM_VALUEs (name, value, count, index), 200 ATTITUDE frames, and with
    ``late`` one more SERVO1_FUNCTION value at the end."""
    m = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = [m.heartbeat_encode(11, 3, 81, 19, 4, 3).pack(m)]
    frames += [m.param_value_encode(n, v, 2, c, i).pack(m) for n, v, c, i in params]
    frames += [m.attitude_encode(k, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0).pack(m) for k in range(200)]
    if late:
        frames.append(m.param_value_encode(b"SERVO1_FUNCTION", 33.0, 2, 2, 0).pack(m))
    with TlogWriter(path) as w:
        for k, f in enumerate(frames):
            w.write(T0 + 0.05 * k, f)


@pytest.mark.parametrize("complete", [True, False])
def test_scan_header_stops_once_the_parameter_set_is_complete(tmp_path: Path,
                                                              complete: bool) -> None:
    """With every index of ``param_count`` seen and a vehicle HEARTBEAT, the scan stops:
    a later change is not read. With an index missing it reads on to the last value."""
    p = tmp_path / "a.tlog"
    params = [(b"SERVO1_FUNCTION", 26.0, 2, 0), (b"SERVO3_FUNCTION", 70.0, 2, 1)]
    _write(p, params if complete else params[:1], late=True)
    infos, found = scan_header(p)
    assert [(v.mav_type, v.autopilot) for v in infos] == [(11, 3)]
    by_name = {x.name: x.value for x in found}
    assert by_name["SERVO1_FUNCTION"] == (26.0 if complete else 33.0)
