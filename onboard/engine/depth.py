"""Pressure to depth, and the surface/submerged mode of the vehicle.

A pressure sensor's reading becomes a depth by hydrostatics,
``d = (p - p_surface) / (rho g)``, with the water density ``rho`` and the surface
pressure ``p_surface`` of ``[sensors.depth]`` (:class:`onboard.core.config.DepthNoise`).
The newest depth decides the mode: deeper than ``surface_depth_m`` the vehicle is
submerged: no satellite signal reaches the antenna, and the engine rejects a GNSS fix
then as ``gnss:submerged``.
"""

from __future__ import annotations

from onboard.core.config import DepthNoise
from onboard.core.messages import Depth, Pressure

GRAVITY = 9.80665
"""Standard gravity, m/s^2."""
SURFACE = "surface"
SUBMERGED = "submerged"


class DepthMode:
    """The depth of pressure samples and the surface/submerged mode from the newest depth.

    Attributes:
        mode: :data:`SURFACE` or :data:`SUBMERGED` (:data:`SURFACE` until a depth comes).
        depth_m: the newest depth (m, positive down), None before the first.
    """

    def __init__(self, cfg: DepthNoise) -> None:
        """Hydrostatics and the surface threshold of ``cfg``."""
        self.rho_g = cfg.water_density_kgm3 * GRAVITY
        """Water density times gravity (Pa/m)."""
        self.p_surface = cfg.surface_pressure_pa
        self.surface_depth_m = cfg.surface_depth_m
        self.mode = SURFACE
        self.depth_m: float | None = None

    @property
    def submerged(self) -> bool:
        """True while the newest depth is below the surface threshold."""
        return self.mode == SUBMERGED

    def depth(self, sample: Pressure) -> Depth:
        """``sample`` as a depth sample: ``d = (p - p_surface) / (rho g)`` (m)."""
        return Depth(t=sample.t, source=sample.source,
                     depth_m=(sample.pressure_pa - self.p_surface) / self.rho_g,
                     pressure_pa=sample.pressure_pa, temperature_c=sample.temperature_c)

    def observe(self, sample: Depth) -> None:
        """Take ``sample`` as the newest depth and set the mode from it."""
        self.depth_m = sample.depth_m
        self.mode = SUBMERGED if sample.depth_m > self.surface_depth_m else SURFACE
