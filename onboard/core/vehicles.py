"""The vehicle classes and what each one is: the single table every module reads.

A configuration names its vehicle class (``[vehicle] class``, :data:`VehicleClass`); what
follows from the class (whether it dives, whether it moves sideways by design, which
pipelines' models fit it, what its autopilot's HEARTBEAT says, how many thrusters its
autopilot drives) is a :class:`VehicleTraits` in :data:`TRAITS`, read through
:func:`traits`. No other module lists class names to decide such things.

A buoyancy-driven glider is no class of its own: it is configured as a ``torpedo-auv``
with the current pipeline's glider model (``[pipelines.current.glider]``,
``config/slocum-glider-kolumbo.toml``), so it has the traits of a torpedo AUV.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

VehicleClass = Literal[
    "rudder-boat", "twin-thruster-boat", "bluerov2", "torpedo-auv", "spheroid", "unknown"
]
"""The vehicle classes a configuration may name (``[vehicle] class``)."""

MAV_TYPE_GROUND_ROVER = 10
"""HEARTBEAT ``MAV_TYPE`` of an ArduRover ground rover (a boat may report it)."""
MAV_TYPE_SURFACE_BOAT = 11
"""HEARTBEAT ``MAV_TYPE`` of an ArduRover boat."""
MAV_TYPE_SUBMARINE = 12
"""HEARTBEAT ``MAV_TYPE`` of an ArduSub vehicle."""

BOAT_MAV_TYPES = frozenset({MAV_TYPE_GROUND_ROVER, MAV_TYPE_SURFACE_BOAT})
"""The HEARTBEAT ``MAV_TYPE`` values of a surface vehicle's autopilot."""
DIVING_MAV_TYPES = frozenset({MAV_TYPE_SUBMARINE})
"""The HEARTBEAT ``MAV_TYPE`` values of a diving vehicle's autopilot."""


@dataclass(frozen=True)
class VehicleTraits:
    """What a vehicle class is, as the modules that depend on it ask.

    Attributes:
        underwater: the vehicle dives: its current and through-water velocity have a
            vertical component, its autopilot is asked for depth and INS velocity, and
            its HEARTBEAT says ``MAV_TYPE_SUBMARINE``.
        holonomic: the vehicle moves sideways by design (an ROV's vectored thrusters, the
            spheroid's flow-relative sway): its heading says nothing of its course over
            ground, so the heading/course integrity check does not apply.
        surge_heading_model: the surge/heading model of pipelines ``aie`` and ``kf``
            fits it (it goes where it points, driven along its heading).
        heartbeat_mav_types: the HEARTBEAT ``MAV_TYPE`` values its autopilot sends
            (empty: not known, nothing to compare with).
        thrusters: the motors its autopilot drives by ``SERVOn_FUNCTION`` Motor1..n
            (0: it steers with a rudder or two throttles instead).
        model_kind: the current pipeline's regression-model kind
            (:data:`onboard.estimators.vehicle_models.RegressionModel.KINDS`).
    """

    underwater: bool
    holonomic: bool
    surge_heading_model: bool
    heartbeat_mav_types: frozenset[int]
    thrusters: int
    model_kind: str


_BOAT = VehicleTraits(underwater=False, holonomic=False, surge_heading_model=True,
                      heartbeat_mav_types=BOAT_MAV_TYPES, thrusters=0,
                      model_kind="surface-rudder")

TRAITS: dict[str, VehicleTraits] = {
    "rudder-boat": _BOAT,
    "twin-thruster-boat": VehicleTraits(
        underwater=False, holonomic=False, surge_heading_model=True,
        heartbeat_mav_types=BOAT_MAV_TYPES, thrusters=0, model_kind="surface-twin"),
    "bluerov2": VehicleTraits(
        underwater=True, holonomic=True, surge_heading_model=False,
        heartbeat_mav_types=DIVING_MAV_TYPES, thrusters=6, model_kind="rov"),
    "torpedo-auv": VehicleTraits(
        underwater=True, holonomic=False, surge_heading_model=True,
        heartbeat_mav_types=DIVING_MAV_TYPES, thrusters=0, model_kind="torpedo"),
    "spheroid": VehicleTraits(
        underwater=True, holonomic=True, surge_heading_model=False,
        heartbeat_mav_types=DIVING_MAV_TYPES, thrusters=0, model_kind="torpedo"),
    "unknown": VehicleTraits(
        underwater=False, holonomic=False, surge_heading_model=True,
        heartbeat_mav_types=frozenset(), thrusters=0, model_kind="surface-rudder"),
}
"""Every :data:`VehicleClass` and its traits."""

CLASSES: tuple[str, ...] = get_args(VehicleClass)
"""The vehicle class names, in the order of :data:`VehicleClass`."""

MARINE_MAV_TYPES = frozenset().union(*(v.heartbeat_mav_types for v in TRAITS.values()))
"""Every HEARTBEAT ``MAV_TYPE`` some vehicle class's autopilot sends."""


def traits(vehicle_class: str) -> VehicleTraits:
    """The traits of ``vehicle_class`` (one of :data:`VehicleClass`; KeyError otherwise)."""
    return TRAITS[vehicle_class]

