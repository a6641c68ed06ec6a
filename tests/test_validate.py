"""Sample checks (:mod:`onboard.engine.checks`): the reason a sample is refused, for every
sample type the drivers produce, against the rules written out here from the module's
docstring."""

from __future__ import annotations

import math
import random
import typing

import msgspec
import pytest

from onboard.engine import checks as validate
from onboard.core import messages as m

_T0 = 1.7e9


def _example_samples() -> list:
    """A valid sample of every type the drivers produce, every optional field set."""
    return [
        m.GnssFix(t=_T0, lat_deg=41.6, lon_deg=-71.3, alt_m=3.0, fix_quality=4, num_sats=12,
                  hdop=0.8, sog_mps=1.5, cog_rad=0.2, h_acc_m=0.02, v_acc_m=0.05,
                  speed_acc_mps=0.1),
        m.VelocityOverGround(t=_T0, v_north_mps=1.0, v_east_mps=-0.5, v_down_mps=0.01),
        m.Imu(t=_T0, accel_x=0.1, accel_y=-0.2, accel_z=-9.8, gyro_x=0.01, gyro_y=0.0,
              gyro_z=0.3),
        m.Heading(t=_T0, heading_rad=1.0, reference="magnetic", declination_rad=-0.25),
        m.Attitude(t=_T0, roll_rad=0.0, pitch_rad=0.1, yaw_rad=2.0, roll_rate_rps=0.0,
                   pitch_rate_rps=0.01, yaw_rate_rps=-0.2),
        m.DvlVelocity(t=_T0, vx=0.5, vy=0.0, vz=0.01, fom_mps=0.01,
                      covariance=(1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4),
                      altitude_m=3.0),
        m.DvlPosition(t=_T0, north_m=10.0, east_m=-4.0, down_m=20.0, roll_rad=0.0,
                      pitch_rad=0.0, yaw_rad=1.0, std_m=0.5),
        m.Depth(t=_T0, depth_m=20.0, pressure_pa=3.0e5, temperature_c=12.0),
        m.Pressure(t=_T0, pressure_pa=1.2e5, temperature_c=12.0),
        m.Altitude(t=_T0, altitude_m=3.0),
        m.ActuatorOutputs(t=_T0, pwm_us=(1500.0, 1600.0, 1400.0)),
        m.RcChannels(t=_T0, pwm_us=(1500.0, 1100.0)),
        m.PropellerRpm(t=_T0, rpm=(1200.0, -1100.0)),
        m.ActuatorColumn(t=_T0, column="rudder_deg", value=-15.0),
        m.ActuatorCommand(t=_T0, throttle=0.5, rudder_rad=0.1, left=0.4, right=0.6,
                          propeller_rpm=1200.0, stern_plane_rad=0.0,
                          thrusters=(0.1, -0.1, 0.0, 0.0, 0.2, 0.2)),
        m.Parameter(t=_T0, name="SERVO1_FUNCTION", value=26.0),
        m.VehicleInfo(t=_T0, system_id=1, component_id=1, mav_type=11, autopilot=3),
    ]


_EXAMPLES = {type(s): s for s in _example_samples()}


def _expected_reason(sample) -> str | None:
    """The rules in order: a non-finite time is "nan"; parameters and vehicle info carry
    nothing else to check; a time at or before 0 is "zero_time"; any non-finite number,
    or numbers whose left-to-right sum overflows, "nan"; a value out of its physical
    bounds "range"; pulse widths beyond 0-3000 us or propeller speeds beyond 1e5 rpm
    "range"; a DVL without lock "invalid"; a GNSS fix of quality 0 "no_fix"."""
    if not math.isfinite(sample.t):
        return "nan"
    if isinstance(sample, (m.Parameter, m.VehicleInfo)):
        return None
    if sample.t <= 0.0:
        return "zero_time"
    example = _EXAMPLES[type(sample)]
    total = 0.0
    for name in typing.get_type_hints(type(sample)):   # declaration order, base class first
        value, kind = getattr(sample, name), getattr(example, name)
        if isinstance(kind, float) and value is not None:
            total += value
        elif isinstance(kind, tuple) and value:
            total += sum(value)
    if not math.isfinite(total):
        return "nan"
    for name, lo, hi in validate._BOUNDS.get(type(sample), ()):
        value = getattr(sample, name)
        if value is not None and not lo <= value <= hi:
            return "range"
    if isinstance(sample, (m.ActuatorOutputs, m.RcChannels)):
        return "range" if any(not 0.0 <= p <= 3000.0 for p in sample.pwm_us) else None
    if isinstance(sample, m.PropellerRpm):
        return "range" if any(abs(r) > 1e5 for r in sample.rpm) else None
    if isinstance(sample, m.DvlVelocity) and not sample.valid:
        return "invalid"
    if isinstance(sample, m.GnssFix) and sample.fix_quality <= 0:
        return "no_fix"
    return None


_BAD_NUMBERS = [math.nan, math.inf, -math.inf, 1e308, -1e308, 1.7976931348623157e308, 1e6,
                -1e6, 5000.0, -1.0, 0.0, -0.0, 5e-324]
_BAD_TUPLES = [(), (math.nan,), (1500.0, math.inf), (-1.0,), (3001.0,), (2e5,),
               (1e308, 1e308), (1500.0,) * 20, None]


def _verdict(check, sample) -> str | None:
    """The reason, or "TypeError" for a value of the wrong type (None in a required
    field), which the decoders never produce and the check does not hide."""
    try:
        return check(sample)
    except TypeError:
        return "TypeError"


def test_every_sample_type_has_an_example_that_passes() -> None:
    assert set(_EXAMPLES) == set(typing.get_args(m.AnySample))
    for s in _EXAMPLES.values():
        assert validate.check_values(s) is None, s


def test_random_corruptions_get_the_documented_reason() -> None:
    """NaN, infinities, sums overflowing to infinity, out-of-range values, zero or negative
    times, bad tuples, flags: 600 corruptions of up to 3 fields per sample type."""
    rng = random.Random(7)
    for s in _EXAMPLES.values():
        fields = [n for n in s.__struct_fields__ if n != "source"]
        for _ in range(600):
            kw = {}
            for name in rng.sample(fields, rng.randint(1, min(3, len(fields)))):
                value = getattr(s, name)
                if isinstance(value, tuple):
                    kw[name] = rng.choice(_BAD_TUPLES)
                elif isinstance(value, bool):
                    kw[name] = rng.choice((True, False))
                elif isinstance(value, int):
                    kw[name] = rng.choice((0, -1, 1, 255))
                elif isinstance(value, float):
                    kw[name] = rng.choice(_BAD_NUMBERS)
            bad = msgspec.structs.replace(s, **kw)
            want = _verdict(_expected_reason, bad)
            assert _verdict(validate.check_values, bad) == want, bad
            assert _verdict(validate.checker_for(type(bad)), bad) == want, bad


@pytest.mark.parametrize(("cls", "change", "reason"), [
    (m.Imu, {"accel_x": math.nan}, "nan"),
    (m.Imu, {"accel_x": 400.0}, "range"),
    (m.Imu, {"t": 0.0}, "zero_time"),
    (m.Imu, {"t": math.inf}, "nan"),
    (m.GnssFix, {"fix_quality": 0}, "no_fix"),
    (m.GnssFix, {"lat_deg": 91.0}, "range"),
    (m.GnssFix, {"hdop": 1e308, "alt_m": 1e308}, "nan"),   # finite values, infinite sum
    (m.DvlVelocity, {"valid": False}, "invalid"),
    (m.ActuatorOutputs, {"pwm_us": (1500.0, 3001.0)}, "range"),
    (m.PropellerRpm, {"rpm": (2e5,)}, "range"),
    (m.Parameter, {"t": -1.0}, None),
    (m.Parameter, {"t": math.nan}, "nan"),
])
def test_named_rejections(cls: type, change: dict, reason: str | None) -> None:
    assert validate.check_values(msgspec.structs.replace(_EXAMPLES[cls], **change)) == reason


def test_a_missing_optional_value_is_not_a_rejection() -> None:
    fix = msgspec.structs.replace(_EXAMPLES[m.GnssFix], alt_m=None, sog_mps=None, hdop=None)
    assert validate.check_values(fix) is None
