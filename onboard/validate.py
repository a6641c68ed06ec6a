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
    """A checker specialised to one sample type: finiteness of every number by one sum
    (NaN and infinities propagate through addition), then the type's physical bounds."""
    floats, tuples = _float_fields(cls)
    get_floats = attrgetter(*floats) if len(floats) > 1 else (
        (lambda s, _g=attrgetter(floats[0]): (_g(s),)) if floats else (lambda s: ()))
    get_tuples = [attrgetter(n) for n in tuples]
    bounds = [(attrgetter(n), lo, hi) for n, lo, hi in _BOUNDS.get(cls, ())]
    isfinite = math.isfinite

    def check(sample: Sample) -> str | None:
        total = 0.0
        for v in get_floats(sample):
            if v is not None:
                total += v
        for g in get_tuples:
            tup = g(sample)
            if tup:
                total += sum(tup)
        if not isfinite(total):
            return "nan"
        for g, lo, hi in bounds:
            v = g(sample)
            if v is not None and not lo <= v <= hi:
                return "range"
        return None

    return check


_CHECKERS: dict[type, Callable[[Sample], str | None]] = {}


def _reason(sample: Sample) -> str | None:
    """The reference check: the reason ``sample`` is unusable, or None. The straight-line
    checkers of :func:`check_values` fall back to it to name a rejection."""
    t = sample.t
    if not math.isfinite(t):
        return "nan"
    cls = type(sample)
    if cls in _ALWAYS_OK:
        return None
    if t <= 0.0:
        return "zero_time"
    checker = _CHECKERS.get(cls)
    if checker is None:
        checker = _CHECKERS[cls] = _make_checker(cls)
    reason = checker(sample)
    if reason is not None:
        return reason
    return _extra_reason(sample)


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


def _make_fast_checker(cls: type) -> Callable[[Sample], str | None]:
    """One straight-line function per sample class that accepts exactly what
    :func:`_reason` accepts: ``0 < t < inf``, the same left-to-right sum of the numeric
    fields (so an overflow to infinity is caught as there), the bounds as chained
    comparisons (false for NaN). Anything else goes to :func:`_reason`, so the
    rejection reasons ("nan", "range", ...) are the reference ones. Per accepted sample
    (CPU, 2026-11-22): IMU 0.26 us against 1.16 us for the generic check, GNSS fix 0.52
    against 1.13 us, heading 0.23 against 0.63 us.
    """
    import typing

    env: dict[str, object] = {"_reason": _reason, "_extra": _extra_reason,
                              "_isfinite": math.isfinite, "_inf": math.inf}
    if cls in _ALWAYS_OK:
        body = ["    if -_inf < s.t < _inf:", "        return None", "    return _reason(s)"]
    else:
        floats, tuples = _float_fields(cls)
        hints = typing.get_type_hints(cls)
        optional = {n for n in floats if type(None) in typing.get_args(hints[n])}
        bounds = _BOUNDS.get(cls, ())
        bounded = {name for name, _, _ in bounds}
        body = ["    if not 0.0 < s.t < _inf:", "        return _reason(s)"]
        # With every other number required and bounded (by far less than the largest
        # float), t finite and the bounds met imply a finite sum: no sum needed.
        if tuples or any(n != "t" and (n not in bounded or n in optional) for n in floats):
            # the reference adds field by field from 0.0: same order, same result
            terms = [f"(0.0 if s.{n} is None else s.{n})" if n in optional else f"s.{n}"
                     for n in floats]
            terms += [f"(sum(s.{n}) if s.{n} else 0)" for n in tuples]
            body += [f"    if not _isfinite({' + '.join(['0.0', *terms])}):",
                     "        return _reason(s)"]
        checks = [f"(s.{n} is None or {lo!r} <= s.{n} <= {hi!r})" if n in optional
                  else f"{lo!r} <= s.{n} <= {hi!r}" for n, lo, hi in bounds]
        if checks:
            body += [f"    if not ({' and '.join(checks)}):", "        return _reason(s)"]
        body.append("    return _extra(s)" if cls in _EXTRA else "    return None")
    # a value of an unexpected type (None in a required field ...) raises here: the
    # reference then decides, as it always did
    src = ("def check(s):\n    try:\n" + "\n".join("    " + b for b in body)
           + "\n    except TypeError:\n        return _reason(s)\n")
    exec(compile(src, f"<check_values {cls.__name__}>", "exec"), env)
    return env["check"]  # type: ignore[return-value]


_FAST: dict[type, Callable[[Sample], str | None]] = {}


def checker_for(cls: type) -> Callable[[Sample], str | None]:
    """The :func:`check_values` of one sample class (callers that cache it per class
    save the lookup)."""
    fast = _FAST.get(cls)
    if fast is None:
        fast = _FAST[cls] = _make_fast_checker(cls)
    return fast


def check_values(sample: Sample) -> str | None:
    """The reason ``sample`` is unusable on its own, or None if it is fine."""
    fast = _FAST.get(type(sample))
    if fast is None:
        fast = checker_for(type(sample))
    return fast(sample)


_TAGS: dict[type, str] = {}


def sample_type(sample: Sample) -> str:
    """The tag of a sample (``gnss``, ``imu``, ...), used in counters."""
    cls = type(sample)
    tag = _TAGS.get(cls)
    if tag is None:
        tag = _TAGS[cls] = cls.__struct_config__.tag  # type: ignore[attr-defined]
    return tag
