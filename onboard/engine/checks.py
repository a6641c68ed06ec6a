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
from operator import attrgetter
from typing import Callable

from onboard.core.messages import (
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
_ALWAYS_OK = {Parameter, VehicleInfo}


def _float_fields(cls: type) -> tuple[list[str], list[str]]:
    """Names of the float-valued and tuple-valued fields of a sample type."""
    import typing

    floats, tuples = [], []
    for name, hint in typing.get_type_hints(cls).items():
        args = (hint,) if typing.get_origin(hint) is tuple else (typing.get_args(hint) or (hint,))
        if float in args:
            floats.append(name)
        elif any(typing.get_origin(a) is tuple for a in args):
            tuples.append(name)
    return floats, tuples


def _make_checker(cls: type) -> Callable[[Sample], str | None]:
    """The finiteness and bounds check of one sample type: every number finite, tested by
    one left-to-right sum (NaN and infinities propagate through addition, and a sum that
    overflows is rejected too), then the type's physical bounds (each bounded field is
    one of the float fields, read once for both)."""
    floats, tuples = _float_fields(cls)
    get_floats: Callable[[Sample], tuple[float | None, ...]]
    if len(floats) > 1:
        get_floats = attrgetter(*floats)
    elif floats:
        get_one = attrgetter(floats[0])
        get_floats = (lambda s: (get_one(s),))
    else:
        get_floats = (lambda s: ())
    get_tuples = [attrgetter(n) for n in tuples]
    bounds: list[tuple[int, float, float]] = [
        (floats.index(n), lo, hi) for n, lo, hi in _BOUNDS.get(cls, ())]
    isfinite = math.isfinite

    def check(sample: Sample) -> str | None:
        values = get_floats(sample)
        total = 0.0
        for v in values:
            if v is not None:
                total += v
        for g in get_tuples:
            tup = g(sample)
            if tup:
                total += sum(tup)
        if not isfinite(total):
            return "nan"
        for i, lo, hi in bounds:
            b = values[i]
            if b is not None and not lo <= b <= hi:
                return "range"
        return None

    return check


def _extra_reason(sample: Sample) -> str | None:
    """The checks beyond finiteness and bounds: pulse widths, propeller speeds, the
    sensor's own validity flag, the GNSS fix."""
    cls = type(sample)
    if cls is ActuatorOutputs or cls is RcChannels:
        for p in sample.pwm_us:  # type: ignore[attr-defined]
            if p < 0.0 or p > 3000.0:
                return "range"
    elif cls is PropellerRpm:
        if any(abs(r) > 1e5 for r in sample.rpm):  # type: ignore[attr-defined]
            return "range"
    elif cls is DvlVelocity and not sample.valid:  # type: ignore[attr-defined]
        return "invalid"
    elif cls is GnssFix and sample.fix_quality <= 0:  # type: ignore[attr-defined]
        return "no_fix"
    return None


_EXTRA = {ActuatorOutputs, RcChannels, PropellerRpm, DvlVelocity, GnssFix}
"""The classes :func:`_extra_reason` has checks for."""


def _time_only_check(sample: Sample) -> str | None:
    """The check of the classes that carry no measurement (parameters, vehicle info)."""
    return None if math.isfinite(sample.t) else "nan"


def _make_class_check(cls: type) -> Callable[[Sample], str | None]:
    """The whole check of one sample class, in order: the time stamp finite ("nan") and
    positive ("zero_time"), every number finite ("nan"), the bounds ("range"), then the
    class's own checks of :func:`_extra_reason`."""
    if cls in _ALWAYS_OK:
        return _time_only_check
    values = _make_checker(cls)
    extra = _extra_reason if cls in _EXTRA else None
    isfinite = math.isfinite

    def check(sample: Sample) -> str | None:
        t = sample.t
        if not isfinite(t):
            return "nan"
        if t <= 0.0:
            return "zero_time"
        reason = values(sample)
        if reason is None and extra is not None:
            return extra(sample)
        return reason

    return check


_CHECKS: dict[type, Callable[[Sample], str | None]] = {}


def checker_for(cls: type) -> Callable[[Sample], str | None]:
    """The :func:`check_values` of one sample class, its field lists resolved once
    (callers that keep it per class save the lookup)."""
    check = _CHECKS.get(cls)
    if check is None:
        check = _CHECKS[cls] = _make_class_check(cls)
    return check


def check_values(sample: Sample) -> str | None:
    """The reason ``sample`` is unusable on its own, or None if it is fine."""
    return checker_for(type(sample))(sample)


_TAGS: dict[type, str] = {}


def sample_type(sample: Sample) -> str:
    """The tag of a sample (``gnss``, ``imu``, ...), used in counters."""
    cls = type(sample)
    tag = _TAGS.get(cls)
    if tag is None:
        tag = _TAGS[cls] = str(cls.__struct_config__.tag)  # type: ignore[attr-defined]
    return tag
