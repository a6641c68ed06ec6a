"""Sample checks applied by the engine before anything reaches a pipeline.

Every rejection has a short reason, counted per ``<type>:<reason>``: ``nan`` (a NaN or
infinite value), ``range`` (physically impossible: latitude beyond 90 deg, a speed of
100 m/s, an acceleration of 50 g ...), ``zero_time`` (a zero or negative stamp),
``backwards`` (older than the previous sample of the same type and source), ``future``
(ahead of the receive clock, live only), ``late`` (older than the newest sample by more
than the configured age), ``invalid`` (the sensor's own validity flag, e.g. DVL lock loss,
counted but never fused).
"""

from __future__ import annotations

import math
from typing import Iterable

from onboard.messages import (
    ActuatorOutputs,
    Altitude,
    Attitude,
    Depth,
    DvlVelocity,
    GnssFix,
    Heading,
    Imu,
    Parameter,
    Pressure,
    PropellerRpm,
    RcChannels,
    Sample,
    VehicleInfo,
    VelocityOverGround,
)

# (field, lower, upper) bounds that no sensor on a small vehicle can legitimately exceed.
_BOUNDS: dict[type, tuple[tuple[str, float, float], ...]] = {
    GnssFix: (("lat_deg", -90.0, 90.0), ("lon_deg", -180.0, 180.0), ("alt_m", -1e4, 1e5),
              ("sog_mps", 0.0, 50.0)),
    VelocityOverGround: (("v_north_mps", -30.0, 30.0), ("v_east_mps", -30.0, 30.0),
                         ("v_down_mps", -30.0, 30.0)),
    Imu: (("accel_x", -300.0, 300.0), ("accel_y", -300.0, 300.0), ("accel_z", -300.0, 300.0),
          ("gyro_x", -40.0, 40.0), ("gyro_y", -40.0, 40.0), ("gyro_z", -40.0, 40.0)),
    Heading: (("heading_rad", -7.0, 7.0),),
    Attitude: (("roll_rad", -7.0, 7.0), ("pitch_rad", -7.0, 7.0), ("yaw_rad", -7.0, 7.0)),
    DvlVelocity: (("vx", -20.0, 20.0), ("vy", -20.0, 20.0), ("vz", -20.0, 20.0)),
    Depth: (("depth_m", -50.0, 11000.0),),
    Pressure: (("pressure_pa", 5e3, 1.2e8),),
    Altitude: (("altitude_m", 0.0, 1e4),),
}
_ALWAYS_OK = (Parameter, VehicleInfo)


def _numbers(sample: Sample) -> Iterable[float]:
    for name in sample.__struct_fields__:
        v = getattr(sample, name)
        if isinstance(v, float):
            yield v
        elif isinstance(v, tuple):
            for x in v:
                if isinstance(x, float):
                    yield x


def check_values(sample: Sample) -> str | None:
    """The reason ``sample`` is unusable on its own, or None if it is fine."""
    if not math.isfinite(sample.t):
        return "nan"
    if isinstance(sample, _ALWAYS_OK):
        return None
    if sample.t <= 0.0:
        return "zero_time"
    for v in _numbers(sample):
        if not math.isfinite(v):
            return "nan"
    for name, lo, hi in _BOUNDS.get(type(sample), ()):
        v = getattr(sample, name)
        if v is not None and not lo <= v <= hi:
            return "range"
    if isinstance(sample, (ActuatorOutputs, RcChannels)):
        if any(p < 0.0 or p > 3000.0 for p in sample.pwm_us):
            return "range"
    elif isinstance(sample, PropellerRpm):
        if any(abs(r) > 1e5 for r in sample.rpm):
            return "range"
    elif isinstance(sample, DvlVelocity) and not sample.valid:
        return "invalid"
    elif isinstance(sample, GnssFix) and sample.fix_quality <= 0:
        return "no_fix"
    return None


def sample_type(sample: Sample) -> str:
    """The tag of a sample (``gnss``, ``imu``, ...), used in counters."""
    return type(sample).__struct_config__.tag  # type: ignore[return-value]
