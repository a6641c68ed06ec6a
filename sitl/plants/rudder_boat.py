"""Jaiabot-class rudder boat: a 1 m, 3 kg surface vessel with one propeller and a rudder.

3-DOF (surge u, sway v, yaw r) manoeuvring model in the flow-relative velocity, Fossen
(2021) eq. 6.26 structure with diagonal mass matrix ``M = diag(m11, m22, m33)``,
``m11 = m - X_udot``, ``m22 = m - Y_vdot``, ``m33 = I_z - N_rdot``:

    m11 u' =  T(s) + m22 v r - (d_u + d_uu |u|) u - X_dd u^2 delta^2
    m22 v' = -m11 u r - (Y_v0 + Y_vu |u|) v - Y_vv v|v| + Y_d u|u| delta
    m33 r' =  N_d u|u| delta - (N_r0 + N_ru |u|) r - N_rr r|r|
    s'     = (th - s) / tau_shaft

* Shaft: ``s`` is the propeller shaft speed as a fraction of full speed; it follows the
  throttle ``th`` (clipped to [-1, 1]) with the motor's first-order lag ``tau_shaft``
  (0.3 s; ``tau_shaft = 0`` makes the shaft follow the throttle at once). The extra state
  ``x[12]`` is ``s``.
* Thrust map (a fixed-pitch propeller, quadratic in shaft speed): ``T = T_max s|s|``
  ahead, ``T = k_rev T_max s|s|`` astern.
* Rudder at ``x_r`` aft: side force ``Y_d u|u| delta`` (Y_d < 0: the stern is pushed to
  port) and yaw moment ``N_d = x_r Y_d > 0`` (positive rudder turns the bow to starboard);
  both scale with u^2, so the boat cannot turn at rest (surge-yaw coupling). Rudder drag
  ``X_dd u^2 delta^2`` and the centripetal term ``m22 v r`` (v < 0 in a starboard turn)
  make turning slow the boat down.
* Yaw and sway damping grow with speed (hull lift ~ u), so the steady turning diameter
  ``D = 2 U / r ~ 2 N_ru / (N_d delta)`` is nearly speed independent, as on real hulls.
* The Munk moment ``(m22 - m11) u v`` is assumed cancelled by the keel and rudder lift in
  sway and is not modelled: the hull is directionally stable.

Parameters are **our choice** (the seed paper's identified values are not recoverable,
algorithms.md section 1.4): a 1 m, 3 kg hull, top speed 2.5 m/s at full throttle (the
Jaiabot table's 5 m/s at 100 % is a feed-forward map, not physics), surge time constant
m11 / (d_u + 2 d_uu u) ~ 0.7 s at 1 m/s (algorithms.md suggests a ~ 1 1/s), turning
diameter ~ 4 m (4 boat lengths) at 0.3 rad of rudder.

Truth: ``force_x = T`` (at the lagged shaft speed), ``force_y`` = rudder side force, ``moment_z`` = rudder moment,
``surge_input = T / m11`` (m/s^2), ``yaw_input = N_rudder / m33`` (rad/s^2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from onboard.sitl.plants.base import Command, ManoeuvringMasses, PlantBase, PropulsionWrench

__all__ = ["RudderBoatParams", "RudderBoat"]


@dataclass(frozen=True)
class RudderBoatParams(ManoeuvringMasses):
    """Physical parameters (SI). All are our documented choice for a 1 m, 3 kg hull."""

    m: float = 3.0
    """Mass (kg)."""
    x_udot: float = -0.15
    """Surge added mass (kg), ~5 % of m for a slender hull."""
    y_vdot: float = -1.5
    """Sway added mass (kg), ~50 % of m."""
    i_z: float = 0.2
    """Yaw moment of inertia (kg m^2), ~ m L^2 / 15."""
    n_rdot: float = -0.05
    """Yaw added inertia (kg m^2)."""
    t_max: float = 12.5
    """Static thrust at full throttle (N)."""
    k_rev: float = 0.5
    """Astern thrust as a fraction of ahead thrust."""
    d_u: float = 2.0
    """Linear surge damping (N s/m)."""
    d_uu: float = 1.2
    """Quadratic surge damping (N s^2/m^2)."""
    y_v0: float = 2.0
    """Linear sway damping at rest (N s/m)."""
    y_vu: float = 6.0
    """Speed-dependent sway damping (N s^2/m^2), hull/keel lift."""
    y_vv: float = 10.0
    """Quadratic sway (cross-flow) damping (N s^2/m^2)."""
    y_d: float = -0.93
    """Rudder side-force coefficient (N s^2/(m^2 rad)), Y = y_d u|u| delta."""
    x_r: float = -0.45
    """Rudder position aft of the origin (m)."""
    x_dd: float = 1.0
    """Rudder drag coefficient (N s^2/(m^2 rad^2))."""
    n_r0: float = 0.05
    """Linear yaw damping at rest (N m s/rad)."""
    n_ru: float = 0.25
    """Speed-dependent yaw damping (N m s^2/(m rad))."""
    n_rr: float = 0.1
    """Quadratic yaw damping (N m s^2/rad^2)."""
    rudder_max: float = 0.6
    """Rudder deflection limit (rad)."""
    tau_shaft: float = 0.3
    """Shaft-speed time constant (s): motor and propeller spin-up; 0 for none."""

    @property
    def n_d(self) -> float:
        """Rudder yaw-moment coefficient x_r * y_d (N s^2/rad), > 0."""
        return self.x_r * self.y_d

    def thrust(self, throttle: float) -> float:
        """Propeller thrust (N) at a shaft speed of ``throttle`` (fraction of full speed,
        clipped to [-1, 1]); in steady state the shaft speed equals the throttle."""
        th = min(1.0, max(-1.0, throttle))
        k = self.t_max if th >= 0.0 else self.k_rev * self.t_max
        return k * th * abs(th)

    def steady_speed(self, throttle: float) -> float:
        """Closed-form straight-line speed (m/s): root of d_uu u^2 + d_u u = T, throttle >= 0."""
        t = self.thrust(throttle)
        return (-self.d_u + math.sqrt(self.d_u**2 + 4.0 * self.d_uu * t)) / (2.0 * self.d_uu)


class RudderBoat(PlantBase):
    """Jaiabot-class rudder boat (see the module docstring for the equations).

    Inputs: ``command.throttle`` in [-1, 1], ``command.rudder_rad`` (rad, positive turns
    the bow to starboard). Heave, roll and pitch stay zero (waves add their first-order
    motion in the truth only).
    """

    name = "rudder_boat"
    n_extra = 1

    def __init__(self, params: RudderBoatParams | None = None, dt: float = 0.01) -> None:
        super().__init__(dt)
        self.params = params or RudderBoatParams()

    def reset(
        self, *, north: float = 0.0, east: float = 0.0, down: float = 0.0, yaw: float = 0.0,
        u: float = 0.0,
    ) -> None:
        """Pose (m, rad) and surge speed through water ``u`` (m/s); the shaft turns at the
        speed that holds ``u`` in a straight line."""
        super().reset(north=north, east=east, down=down, yaw=yaw, u=u)
        p = self.params
        if u > 0.0:
            drag = (p.d_u + p.d_uu * u) * u
            self.x[12] = math.sqrt(min(1.0, drag / p.t_max))

    @property
    def shaft_speed(self) -> float:
        """Propeller shaft speed as a fraction of full speed (signed)."""
        return float(self.x[12])

    def _inputs(self, command: Command, s: float | None = None) -> tuple[float, float]:
        """(thrust N, clipped rudder rad) at shaft speed ``s`` (default: the state's)."""
        p = self.params
        if p.tau_shaft <= 0.0:
            s = command.throttle or 0.0
        elif s is None:
            s = float(self.x[12])
        d = command.rudder_rad or 0.0
        return p.thrust(s), min(p.rudder_max, max(-p.rudder_max, d))

    def _rhs(self, t: float, x: list[float], command: Command) -> list[float]:
        p = self.params
        thrust, d = self._inputs(command, x[12])
        th = min(1.0, max(-1.0, command.throttle or 0.0))
        sdot = (th - x[12]) / p.tau_shaft if p.tau_shaft > 0.0 else 0.0
        psi, u, v, r = x[5], x[6], x[7], x[11]
        au = abs(u)
        cpsi, spsi = math.cos(psi), math.sin(psi)
        vc = self._vc
        m11, m22, m33 = p.m11, p.m22, p.m33
        udot = (thrust + m22 * v * r - (p.d_u + p.d_uu * au) * u - p.x_dd * u * u * d * d) / m11
        vdot = (-m11 * u * r - (p.y_v0 + p.y_vu * au) * v - p.y_vv * v * abs(v)
                + p.y_d * u * au * d) / m22
        rdot = (p.n_d * u * au * d - (p.n_r0 + p.n_ru * au) * r - p.n_rr * r * abs(r)) / m33
        return [
            cpsi * u - spsi * v + vc[0], spsi * u + cpsi * v + vc[1], 0.0,
            0.0, 0.0, r,
            udot, vdot, 0.0, 0.0, 0.0, rdot, sdot,
        ]

    def propulsion(self, command: Command) -> PropulsionWrench:
        p = self.params
        thrust, d = self._inputs(command)
        u = float(self.x[6])
        fy = p.y_d * u * abs(u) * d
        nz = p.x_r * fy
        return PropulsionWrench(
            force=(thrust, fy, 0.0),
            moment=(0.0, 0.0, nz),
            surge_input=thrust / p.m11,
            yaw_input=nz / p.m33,
        )
