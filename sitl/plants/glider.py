"""A Slocum glider's flight in its vertical plane: the dynamic model of Merckelbach,
Berger and Smeed (2019), "A dynamic flight model for Slocum gliders and implications for
turbulence microstructure measurements", J. Atmos. Oceanic Technol. 36, 281-296, with
their coefficients.

The glider is a point mass ``m_g`` (kg) moving through the water with velocity ``(u, w)``
(m/s: ``u`` horizontal along its heading, ``w`` vertical, up positive) under

* buoyancy ``F_B = g rho (V_g (1 - epsilon p) + V_bp)`` up, ``p`` the pressure (Pa,
  ``rho g z``), ``V_bp`` the pump's volume (m^3) and ``epsilon`` the hull's
  compressibility, and gravity ``m_g g`` down;
* lift ``L = q (a_w + a_h) alpha`` normal to the path and drag ``D = q (C_D0 + C_D1
  alpha^2)`` against it, ``q = rho S U^2 / 2``, ``U = |(u, w)|``, ``alpha = pitch -
  gamma`` the angle of attack and ``gamma = atan2(w, u)`` the flight-path angle; the wing's
  lift slope from its aspect ratio ``A`` and sweep ``Omega`` (Whicker and Fehlner 1958, as
  Merckelbach et al. eq. 7) ``a_w = 2 pi A / (2 + sqrt(A^2 (1 + tan^2 Omega) + 4))`` and
  the induced drag ``C_D1 = a_w^2 / (pi e A) + C_D1,hull``;
* the inertia of the glider and of the water it carries: ``(m_g + m_a) (u', w')``, with
  ``m_a`` the added mass of a cylinder moving sideways for ``w`` (``rho pi r^2 l``) and a
  tenth of the glider's mass along ``u``.

Its pitch follows the pitch battery's set point as a first-order lag (a Slocum's pitch
controller settles in ~10 s); the pump moves at a fixed rate. Nothing here is taken from
the estimators: their glider model (onboard/estimators/vehicle_models.py) is Graver's
steady glide with Graver's coefficients.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from onboard.sitl.integrate import GRAVITY, rk4_step_list

MERCKELBACH_CD0 = 0.15
"""Parasite drag coefficient ``C_D0`` (-), Merckelbach et al. (2019)."""
MERCKELBACH_AH = 3.8
"""Hull lift slope ``a_h`` (1/rad)."""
MERCKELBACH_CD1_HULL = 9.7
"""Hull induced-drag coefficient (1/rad^2)."""
WING_AREA_M2 = 0.1
"""Reference area ``S`` (m^2)."""
WING_ASPECT_RATIO = 7.0
"""``A`` (-)."""
WING_SWEEP_RAD = math.radians(43.0)
"""``Omega`` (rad)."""
OSWALD_EFFICIENCY = 0.8
"""``e`` (-)."""
HULL_COMPRESSIBILITY_PER_PA = 5.0e-10
"""``epsilon`` (1/Pa)."""
GLIDER_MASS_KG = 65.0
"""``m_g`` (kg), Merckelbach et al.'s reference glider."""
HULL_RADIUS_M = 0.11
"""A Slocum's hull radius (m): 22 cm diameter."""
HULL_LENGTH_M = 1.5
"""Its hull length (m)."""
PITCH_TIME_CONSTANT_S = 8.0
"""Time constant (s) of the pitch about the battery's set point."""
PUMP_RATE_CC_S = 8.0
"""The buoyancy pump's rate (cm^3/s)."""


def wing_lift_slope(aspect_ratio: float = WING_ASPECT_RATIO,
                    sweep: float = WING_SWEEP_RAD) -> float:
    """``a_w`` (1/rad) of a swept wing (module docstring)."""
    return 2.0 * math.pi * aspect_ratio / (
        2.0 + math.sqrt(aspect_ratio ** 2 * (1.0 + math.tan(sweep) ** 2) + 4.0))


@dataclass
class SlocumGlider:
    """The glider's state through water and its coefficients (module docstring).

    ``trim_cc``: the pump volume (cm^3) at which the glider is neutral at the surface
    (a ballast error); ``cd0`` its parasite drag (fouling raises it), ``hull_lift`` its
    ``a_h`` and ``compressibility`` its hull's ``epsilon`` (another hull's)."""

    density: float = 1025.0
    cd0: float = MERCKELBACH_CD0
    hull_lift: float = MERCKELBACH_AH
    compressibility: float = HULL_COMPRESSIBILITY_PER_PA
    trim_cc: float = 0.0
    u: float = 0.0
    w: float = 0.0
    pitch: float = 0.0
    pump_cc: float = 0.0
    depth: float = 0.0

    def __post_init__(self) -> None:
        aw = wing_lift_slope()
        self.lift_slope = aw + self.hull_lift
        self.cd1 = aw * aw / (math.pi * OSWALD_EFFICIENCY * WING_ASPECT_RATIO) \
            + MERCKELBACH_CD1_HULL
        # neutral at the surface with the pump at trim_cc
        self.volume_m3 = GLIDER_MASS_KG / self.density - self.trim_cc * 1e-6
        self.mass_u = 1.1 * GLIDER_MASS_KG
        self.mass_w = GLIDER_MASS_KG + self.density * math.pi * HULL_RADIUS_M ** 2 \
            * HULL_LENGTH_M

    def forces(self, u: float, w: float, depth: float) -> tuple[float, float]:
        """Horizontal and vertical (up) force (N) at velocity ``(u, w)`` and ``depth``."""
        rho = self.density
        pressure = rho * GRAVITY * max(depth, 0.0)
        buoy = GRAVITY * rho * (self.volume_m3 * (1.0 - self.compressibility * pressure)
                                + self.pump_cc * 1e-6)
        net_up = buoy - GLIDER_MASS_KG * GRAVITY
        speed = math.hypot(u, w)
        if speed < 1e-9:
            return 0.0, net_up
        gamma = math.atan2(w, u)
        alpha = self.pitch - gamma
        q = 0.5 * rho * WING_AREA_M2 * speed * speed
        lift = q * self.lift_slope * alpha
        drag = q * (self.cd0 + self.cd1 * alpha * alpha)
        cg, sg = u / speed, w / speed
        return (-drag * cg - lift * sg, -drag * sg + lift * cg + net_up)

    def step(self, dt: float, pitch_set: float, pump_set_cc: float,
             vertical_water: float = 0.0) -> None:
        """Advance ``dt`` (s): pitch toward ``pitch_set`` (rad), pump toward
        ``pump_set_cc`` at its rate, the velocity through water by the forces, the depth
        by the vertical velocity and the water's own (``vertical_water``, m/s up). At the
        surface the glider floats: no depth above 0, no speed while buoyant there."""
        a = dt / PITCH_TIME_CONSTANT_S
        self.pitch += (pitch_set - self.pitch) * a / (1.0 + a)
        move = pump_set_cc - self.pump_cc
        self.pump_cc += math.copysign(min(abs(move), PUMP_RATE_CC_S * dt), move)

        def f(_t: float, x: list[float]) -> list[float]:
            fx, fz = self.forces(x[0], x[1], x[2])
            return [fx / self.mass_u, fz / self.mass_w, -(x[1] + vertical_water)]

        u, w, depth = rk4_step_list(f, 0.0, [self.u, self.w, self.depth], dt)
        if depth <= 0.0:
            depth = 0.0
            if w > 0.0:   # buoyant at the surface: it floats
                u = w = 0.0
        self.u, self.w, self.depth = u, w, depth
