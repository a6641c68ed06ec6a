"""Vehicle plants: the true dynamics the simulator integrates.

One module per vehicle; every plant implements :class:`sitl.plants.base.Plant`.
Use :func:`make_plant` to build one by name.
"""

from __future__ import annotations

from onboard.sitl.plants.base import Command, Plant, PlantBase, PropulsionWrench
from onboard.sitl.plants.bluerov2 import BlueROV2
from onboard.sitl.plants.catamaran import Catamaran
from onboard.sitl.plants.rudder_boat import RudderBoat
from onboard.sitl.plants.spheroid import SpheroidAUV
from onboard.sitl.plants.torpedo_auv import TorpedoAUV
from onboard.sitl.plants.twin_thruster import TwinThrusterBoat

PLANTS: dict[str, type[PlantBase]] = {
    RudderBoat.name: RudderBoat,
    TwinThrusterBoat.name: TwinThrusterBoat,
    Catamaran.name: Catamaran,
    BlueROV2.name: BlueROV2,
    TorpedoAUV.name: TorpedoAUV,
    SpheroidAUV.name: SpheroidAUV,
}
"""Plant classes by name: rudder_boat, twin_thruster, catamaran, bluerov2, torpedo_auv,
spheroid."""


def make_plant(name: str, dt: float = 0.01) -> PlantBase:
    """A plant with default parameters by its name (see :data:`PLANTS`)."""
    try:
        cls = PLANTS[name]
    except KeyError:
        raise ValueError(f"unknown plant {name!r}; known: {', '.join(PLANTS)}") from None
    return cls(dt=dt)


__all__ = [
    "Command",
    "Plant",
    "PlantBase",
    "PropulsionWrench",
    "PLANTS",
    "make_plant",
    "BlueROV2",
    "Catamaran",
    "RudderBoat",
    "SpheroidAUV",
    "TorpedoAUV",
    "TwinThrusterBoat",
]
