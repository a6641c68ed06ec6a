"""BlueBoat/Otter-class twin-thruster surface vessel (skid steering).

3-DOF (surge, sway, yaw) Fossen (2021) model ``M nu_r' + C(nu_r) nu_r + D(nu_r) nu_r = tau``
with ``M = diag(m11, m22, m33)`` (rigid body + added mass, CG at the origin) and the
rigid-body plus added-mass Coriolis/centripetal matrix (Fossen eqs. 6.43, 6.44):

    m11 u' =  X + m22 v r - (d_u + d_uu |u|) u
    m22 v' =  Y - m11 u r - (d_v + d_vv |v|) v
    m33 r' =  N - (m22 - m11) u v - (d_r + d_rr |r|) r          (Munk moment included)

Propulsion: two fixed thrusters at ``y = -b`` (left) and ``y = +b`` (right), parallel to
the x axis. Each shaft speed ``n`` (rev/s) follows its command with a first-order motor lag

    n' = (n_max c - n) / tau_m,        c in [-1, 1] (command.left / command.right)

and produces thrust quadratic in shaft speed, ``T = k_f n|n|`` ahead and ``T = k_r n|n|``
astern (Blue Robotics T200: ~40 N ahead, ~30 N astern at full command). Then

    X = T_L + T_R,   Y = 0,   N = b (T_L - T_R)       (more left thrust turns to starboard)

Parameters: a BlueBoat-like hull, L ~ 1.2 m, 15 kg, two T200s 0.57 m apart. Damping is
**our choice**, set for a top speed of 3.0 m/s with both thrusters at full (BlueBoat's
advertised maximum is ~3 m/s) and a yaw rate of ~1 rad/s when spinning on the spot at
~22 N per thruster. The extra states are the two shaft speeds.

Truth: ``force_x = X``, ``moment_z = N``, ``surge_input = X / m11``, ``yaw_input = N / m33``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from onboard.sitl.plants.base import (
    Command,
    ManoeuvringMasses,
    PlantBase,
    PropulsionWrench,
    twin_thruster_wrench,
)

__all__ = ["TwinThrusterParams", "TwinThrusterBoat"]


@dataclass(frozen=True)
class TwinThrusterParams(ManoeuvringMasses):
    """BlueBoat-like parameters (SI); damping values are our documented choice."""

    m: float = 15.0
    """Mass (kg)."""
    x_udot: float = -1.5
    """Surge added mass (kg)."""
    y_vdot: float = -10.0
    """Sway added mass (kg) (two pontoons)."""
    i_z: float = 2.0
    """Yaw inertia (kg m^2), ~ m (L^2 + B^2) / 12 with mass concentrated near the centre."""
    n_rdot: float = -1.0
    """Yaw added inertia (kg m^2)."""
    b: float = 0.285
    """Half the distance between the thrusters (m)."""
    n_max: float = 3500.0 / 60.0
    """Shaft speed at full command (rev/s)."""
    t_fwd: float = 40.0
    """Thrust at full ahead command (N), T200."""
    t_rev: float = 30.0
    """Thrust at full astern command (N), T200."""
    tau_m: float = 0.3
    """Shaft-speed time constant (s): motor spin-up plus the ESC's ramp."""
    d_u: float = 5.0
    """Linear surge damping (N s/m)."""
    d_uu: float = 7.2
    """Quadratic surge damping (N s^2/m^2)."""
    d_v: float = 40.0
    """Linear sway damping (N s/m)."""
    d_vv: float = 80.0
    """Quadratic sway damping (N s^2/m^2)."""
    d_r: float = 4.0
    """Linear yaw damping (N m s/rad)."""
    d_rr: float = 8.0
    """Quadratic yaw damping (N m s^2/rad^2)."""

    @property
    def k_f(self) -> float:
        """Ahead thrust coefficient (N s^2/rev^2)."""
        return self.t_fwd / self.n_max**2

    @property
    def k_r(self) -> float:
        """Astern thrust coefficient (N s^2/rev^2)."""
        return self.t_rev / self.n_max**2

    def thrust(self, n: float) -> float:
        """Thrust (N) of one thruster at shaft speed ``n`` (rev/s)."""
        return (self.k_f if n >= 0.0 else self.k_r) * n * abs(n)

    def steady_speed(self, total_thrust: float) -> float:
        """Straight-line speed (m/s): root of d_uu u^2 + d_u u = X (X >= 0, N)."""
        return (-self.d_u + math.sqrt(self.d_u**2 + 4.0 * self.d_uu * total_thrust)) / (
            2.0 * self.d_uu
        )

    def steady_yaw_rate(self, moment: float) -> float:
        """Spin rate on the spot (rad/s): root of d_rr r^2 + d_r r = N (N >= 0, N m)."""
        return (-self.d_r + math.sqrt(self.d_r**2 + 4.0 * self.d_rr * moment)) / (
            2.0 * self.d_rr
        )


class TwinThrusterBoat(PlantBase):
    """BlueBoat-class skid-steered boat; inputs ``command.left`` and ``command.right``."""

    name = "twin_thruster"
    n_extra = 2

    def __init__(self, params: TwinThrusterParams | None = None, dt: float = 0.01) -> None:
        super().__init__(dt)
        self.params = params or TwinThrusterParams()

    @property
    def shaft_speeds(self) -> tuple[float, float]:
        """(left, right) shaft speeds (rev/s)."""
        return float(self.x[12]), float(self.x[13])

    def _rhs(self, t: float, x: list[float], command: Command) -> list[float]:
        p = self.params
        cl = min(1.0, max(-1.0, command.left or 0.0))
        cr = min(1.0, max(-1.0, command.right or 0.0))
        psi, u, v, r, nl, nr = x[5], x[6], x[7], x[11], x[12], x[13]
        tl, tr = p.thrust(nl), p.thrust(nr)
        m11, m22, m33 = p.m11, p.m22, p.m33
        cpsi, spsi = math.cos(psi), math.sin(psi)
        vc = self._vc
        udot = (tl + tr + m22 * v * r - (p.d_u + p.d_uu * abs(u)) * u) / m11
        vdot = (-m11 * u * r - (p.d_v + p.d_vv * abs(v)) * v) / m22
        rdot = (p.b * (tl - tr) - (m22 - m11) * u * v - (p.d_r + p.d_rr * abs(r)) * r) / m33
        return [
            cpsi * u - spsi * v + vc[0], spsi * u + cpsi * v + vc[1], 0.0,
            0.0, 0.0, r,
            udot, vdot, 0.0, 0.0, 0.0, rdot,
            (p.n_max * cl - nl) / p.tau_m, (p.n_max * cr - nr) / p.tau_m,
        ]

    def propulsion(self, command: Command) -> PropulsionWrench:
        p = self.params
        return twin_thruster_wrench(p.thrust(float(self.x[12])), p.thrust(float(self.x[13])),
                                    p.b, p)
