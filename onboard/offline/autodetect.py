"""Detect the vehicle class and input mapping from a log (architecture.md §4.1).

Evidence, strongest first:

1. ``SERVOn_FUNCTION`` parameters (PARAM_VALUE in a tlog, PARM in a DataFlash log):
   73/74 (ThrottleLeft/Right) mean skid steering -> ``twin-thruster-boat`` with those
   channels; 26 (GroundSteering) with 70 (Throttle) -> ``rudder-boat``; 33-38
   (Motor1-6) -> ``bluerov2`` thrusters on those channels; a submarine with 21 (Rudder)
   and 19 (Elevator) -> ``torpedo-auv`` (propeller speed from ``RPM.rpm1``).
2. The autopilot's HEARTBEAT ``MAV_TYPE``: 12 (SUBMARINE) -> ``bluerov2`` (ArduSub),
   10/11 (GROUND_ROVER/SURFACE_BOAT) -> a boat.
3. ArduPilot defaults otherwise: Rover with SERVO1 = steering and SERVO3 = throttle.

The mapping's pulse-width scaling comes from the bundled class config; the
``SERVOn_MIN/MAX/TRIM`` parameters refine it where the log has them. What a class is
(whether it dives, its HEARTBEAT, its thrusters) is read from
:mod:`onboard.core.vehicles`.
"""

from __future__ import annotations

from typing import Iterable

import msgspec

from onboard.core import config as configmod
from onboard.core.config import ChannelMap, Config, Inputs
from onboard.core.messages import Parameter, Sample, VehicleInfo
from onboard.core.vehicles import (
    BOAT_MAV_TYPES,
    MARINE_MAV_TYPES,
    MAV_TYPE_SUBMARINE,
    traits,
)

_GCS_TYPES = {6, 18, 26}  # GCS, ONBOARD_CONTROLLER, GIMBAL... not the vehicle

SERVO_ELEVATOR = 19
SERVO_RUDDER = 21
SERVO_GROUND_STEERING = 26
SERVO_THROTTLE = 70
SERVO_THROTTLE_LEFT = 73
SERVO_THROTTLE_RIGHT = 74
SERVO_MOTOR1 = 33
ROV_MOTORS = traits("bluerov2").thrusters
"""Motor functions (``SERVO_MOTOR1`` on) that make a log a ``bluerov2``'s."""


def _servo_functions(params: dict[str, float]) -> dict[int, int]:
    """channel -> function number from SERVOn_FUNCTION parameters."""
    out = {}
    for name, value in params.items():
        if name.startswith("SERVO") and name.endswith("_FUNCTION"):
            try:
                out[int(name[5:-9])] = int(value)
            except ValueError:
                continue
    return out


def _refine(m: ChannelMap, channel: int, params: dict[str, float]) -> ChannelMap:
    """Set the channel and, where the log has them, trim and range from SERVOn_*."""
    trim = params.get(f"SERVO{channel}_TRIM")
    lo = params.get(f"SERVO{channel}_MIN")
    hi = params.get(f"SERVO{channel}_MAX")
    kw: dict = {"channel": channel}
    if trim and lo and hi and lo < trim < hi:
        kw["neutral_us"] = float(trim)
        kw["half_range_us"] = float(min(trim - lo, hi - trim))
    if params.get(f"SERVO{channel}_REVERSED"):
        kw["reverse"] = True
    return msgspec.structs.replace(m, **kw)


def _evidence(samples: Iterable[Sample]) -> tuple[dict[str, float], int | None]:
    """The parameters by name and the vehicle's most frequent HEARTBEAT ``MAV_TYPE``
    (ground stations' left out; None without one) among ``samples``."""
    params: dict[str, float] = {}
    mav_types: list[int] = []
    for s in samples:
        if isinstance(s, Parameter):
            params[s.name] = s.value
        elif isinstance(s, VehicleInfo) and s.mav_type not in _GCS_TYPES:
            mav_types.append(s.mav_type)
    return params, (max(set(mav_types), key=mav_types.count) if mav_types else None)


def detect(samples: Iterable[Sample]) -> tuple[Config, str]:
    """The config implied by the HEARTBEAT and parameter samples of a log.

    Returns the config and a one-line explanation of the evidence used.
    """
    params, mav_type = _evidence(samples)
    functions = _servo_functions(params)
    by_function = {f: ch for ch, f in sorted(functions.items(), reverse=True)}

    if SERVO_THROTTLE_LEFT in by_function and SERVO_THROTTLE_RIGHT in by_function:
        base = configmod.load("twin-thruster-boat")
        left, right = by_function[SERVO_THROTTLE_LEFT], by_function[SERVO_THROTTLE_RIGHT]
        inputs = msgspec.structs.replace(
            base.inputs, left=_refine(base.inputs.left, left, params),
            right=_refine(base.inputs.right, right, params))
        why = f"SERVO{left}_FUNCTION=73, SERVO{right}_FUNCTION=74 (skid steering)"
    elif mav_type == MAV_TYPE_SUBMARINE and SERVO_RUDDER in by_function and (
        SERVO_ELEVATOR in by_function
    ):
        base = configmod.load("torpedo-auv")
        rudder, plane = by_function[SERVO_RUDDER], by_function[SERVO_ELEVATOR]
        inputs = msgspec.structs.replace(
            base.inputs, rudder=_refine(base.inputs.rudder, rudder, params),
            stern_plane=_refine(base.inputs.stern_plane, plane, params))
        why = (f"HEARTBEAT MAV_TYPE_SUBMARINE with SERVO{rudder}_FUNCTION=21 rudder and "
               f"SERVO{plane}_FUNCTION=19 elevator (torpedo AUV; propeller from RPM.rpm1)")
    elif any(SERVO_MOTOR1 <= f < SERVO_MOTOR1 + ROV_MOTORS for f in functions.values()) or (
        mav_type == MAV_TYPE_SUBMARINE
    ):
        base = configmod.load("bluerov2")
        motors = {f - SERVO_MOTOR1: ch for ch, f in functions.items()
                  if SERVO_MOTOR1 <= f < SERVO_MOTOR1 + ROV_MOTORS}
        thrusters = [
            _refine(m, motors.get(i, m.channel), params) for i, m in enumerate(base.inputs.thrusters)
        ]
        inputs = msgspec.structs.replace(base.inputs, thrusters=thrusters)
        why = (f"motor functions on SERVO{sorted(motors.values())}" if motors
               else "HEARTBEAT MAV_TYPE_SUBMARINE, ArduSub default motor channels 1-6")
    else:
        base = configmod.load("rudder-boat")
        steer = by_function.get(SERVO_GROUND_STEERING, by_function.get(SERVO_RUDDER, 1))
        throttle = by_function.get(SERVO_THROTTLE, 3)
        inputs = msgspec.structs.replace(
            base.inputs, rudder=_refine(base.inputs.rudder, steer, params),
            throttle=_refine(base.inputs.throttle, throttle, params))
        if functions:
            why = f"SERVO{steer}_FUNCTION=26 steering, SERVO{throttle}_FUNCTION=70 throttle"
        elif mav_type in BOAT_MAV_TYPES:
            why = f"HEARTBEAT MAV_TYPE {mav_type}; ArduRover defaults SERVO1 steering, SERVO3 throttle"
        else:
            why = "no vehicle evidence in the log; ArduRover defaults (SERVO1 steering, SERVO3 throttle)"
    return msgspec.structs.replace(base, inputs=inputs), why


def consistency(cfg: Config, samples: Iterable[Sample]) -> list[tuple[str, str]]:
    """What in a log's HEARTBEAT and SERVOn_FUNCTION samples disagrees with ``cfg``:
    ``(code, message)`` pairs, ``class_mismatch`` (the autopilot's MAV_TYPE is a marine
    vehicle's but not one the configured class's autopilot sends: a diving class against
    a boat or rover, or the other way round) and ``actuator_mapping_incomplete`` (motor
    functions for fewer than the class's thrusters: the missing ones keep the defaults'
    channels)."""
    samples = list(samples)
    params, mav_type = _evidence(samples)
    out: list[tuple[str, str]] = []
    cls = cfg.vehicle.vehicle_class
    expected = traits(cls).heartbeat_mav_types
    if mav_type in MARINE_MAV_TYPES and expected and mav_type not in expected:
        fit = detect(samples)[0].vehicle.vehicle_class
        out.append(("class_mismatch",
                    f"the configuration is for a {cls} but the autopilot's HEARTBEAT "
                    f"says MAV_TYPE {mav_type}, a {fit}'s: the models and inputs may not "
                    f"fit; --config {fit} fits the log, or no --config (detected from it)"))
    n = traits(cls).thrusters
    motors = {f for f in _servo_functions(params).values()
              if SERVO_MOTOR1 <= f < SERVO_MOTOR1 + n}
    if motors and len(motors) < n:
        lost = sorted(i + 1 for i in range(n) if SERVO_MOTOR1 + i not in motors)
        out.append(("actuator_mapping_incomplete",
                    f"SERVOn_FUNCTION names {len(motors)} of the {n} motors; "
                    f"motor(s) {lost} keep the default channels: set their channel in "
                    "[inputs] thrusters if that is wrong"))
    return out


def with_inputs(cfg: Config, inputs: Inputs) -> Config:
    """A copy of ``cfg`` with another input mapping."""
    return msgspec.structs.replace(cfg, inputs=inputs)
