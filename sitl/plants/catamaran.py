"""Otter-class small catamaran (twin pontoons, twin fixed thrusters, skid steering).

3-DOF (surge, sway, yaw) Fossen (2021) model ``M nu_r' + C(nu_r) nu_r + D(nu_r) nu_r = tau``
about the origin midships on the centreline, with the centre of gravity ``x_g`` ahead of
it, so the mass matrix couples sway and yaw (Fossen eqs. 6.58-6.62, 3-DOF):

    M = [[m11, 0, 0], [0, m22, m23], [0, m23, m33]],  m23 = m x_g
    m11 u'           =  X + m22 v r + m23 r^2 - X_u u
    m22 v' + m23 r'  = -m11 u r - Y_v v + Y_cf
    m23 v' + m33 r'  =  N - (m22 - m11) u v - m23 u r - N_r (1 + 10 |r|) r + N_cf

* **Sway damping does not grow with speed**: ``Y_v`` is a constant (otter.m sets it from a
  sway time constant of 1 s, ``Y_v = m22 / T_sway``), so in a steady turn the hull drifts
  out of the turn by ``v = -(m11 / Y_v) u r``, about ``-0.52 u r`` (m/s): the sway scales
  with speed times yaw rate, and lags it by ``T_sway``. A GNSS latency ``tau`` shows in a
  steady turn as ``-tau u r``, the same signature.
* Cross-flow drag ``Y_cf``, ``N_cf`` by strip theory over the pontoons' length
  (Fossen eq. 6.111, otter.m's ``crossFlowDrag``): ``-1/2 rho T C_d |v + x r| (v + x r)``
  integrated over ``x``, so quadratic sway and yaw damping and their coupling.
* The Munk moment ``(m22 - m11) u v`` is kept, as otter.m keeps it.
* Propulsion: two fixed propellers at ``y = -/+ y_pont``. Each shaft speed ``n`` (rad/s)
  follows its command with a first-order lag, ``n' = (n_c - n) / tau_n`` with
  ``n_c = c n_max`` ahead and ``c |n_min|`` astern (``c`` in [-1, 1]), and pushes
  ``T = k_pos n|n|`` ahead or ``k_neg n|n|`` astern (Otter's bollard-pull data). Then
  ``X = T_L + T_R``, ``N = y_pont (T_L - T_R)`` (more left thrust turns to starboard).

Sources: Fossen's MSS toolbox, ``VESSELS/models/otter.m`` (revision 2024-06-05), the
Maritime Robotics Otter USV. Taken from it: L = 2.0 m, hull mass 55 kg with the default
25 kg payload at the origin (m = 80 kg), hull CG 0.2 m ahead of the origin (so
``x_g = 55 * 0.2 / 80 = 0.1375`` m), yaw radius of gyration ``0.25 L``, added masses
``Y_vdot = -1.5 m_hull``, ``N_rdot = -1.7 I_z``, surge added mass ~ 5.3 kg (otter.m's
``addedMassSurge``: Söding's formula at 55 kg), ``X_u = 24.4 g / U_max`` with
``U_max`` = 6 knots, ``Y_v = m22 / T_sway`` with ``T_sway = 1`` s, ``N_r = m33 / T_yaw``
with ``T_yaw = 1`` s and otter.m's ``(1 + 10 |r|)`` nonlinear yaw damping, pontoon beam
0.25 m and half spacing ``y_pont = 0.395`` m, block coefficient 0.4 (draft from the
displacement), ``k_pos = 0.02216 / 2``, ``k_neg = 0.01289 / 2`` and the shaft speed
limits from the bollard pulls 24.4 kg ahead and 13.6 kg astern. **Our choice**: the
shaft-speed time constant ``tau_n`` (0.4 s; otter.m takes the shaft speed as an input),
the cross-flow drag coefficient ``C_d`` = 1.0 (Hoerner's 2-D curve near ``B / 2T`` ~ 0.6;
otter.m interpolates it) integrated over one pontoon's draft as otter.m does, six strips,
and no heave, roll or pitch (the 3-DOF manoeuvring model).

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

__all__ = ["Catamaran", "CatamaranParams"]

G = 9.81
"""Acceleration of gravity (m/s^2), as in otter.m."""
RHO = 1025.0
"""Sea water density (kg/m^3), as in otter.m."""


@dataclass(frozen=True)
class CatamaranParams(ManoeuvringMasses):
    """Otter USV parameters (SI), from otter.m except where the module docstring says."""

    m: float = 80.0
    """Mass (kg): 55 kg hull plus otter.m's default 25 kg payload."""
    x_g: float = 0.1375
    """Centre of gravity ahead of the origin (m): 55 kg at 0.2 m and 25 kg at 0."""
    length: float = 2.0
    """Pontoon length (m)."""
    x_udot: float = -5.3
    """Surge added mass (kg), otter.m's addedMassSurge at 55 kg."""
    y_vdot: float = -82.5
    """Sway added mass (kg), -1.5 times the hull mass."""
    i_z: float = 15.3
    """Yaw inertia about the origin (kg m^2): 55 (0.25 L)^2 + 80 x_g^2."""
    n_rdot: float = -25.1
    """Yaw added inertia (kg m^2), -1.7 times the hull's 14.8 kg m^2."""
    x_u: float = 24.4 * G / (6 * 0.5144)
    """Linear surge damping (N s/m): full bollard pull at 6 knots."""
    t_sway: float = 1.0
    """Sway time constant (s) setting ``Y_v = m22 / t_sway``."""
    t_yaw: float = 1.0
    """Yaw time constant (s) setting ``N_r = m33 / t_yaw``."""
    draft: float = 80.0 / RHO / (2 * 0.4 * 0.25 * 2.0)
    """Draft (m) from the displacement: volume / (2 Cb B_pont L), ~0.195 m."""
    c_d: float = 1.0
    """2-D cross-flow drag coefficient of a pontoon section (-)."""
    y_pont: float = 0.395
    """Half the distance between the propellers (m)."""
    k_pos: float = 0.02216 / 2
    """Ahead thrust coefficient of one propeller (N s^2/rad^2)."""
    k_neg: float = 0.01289 / 2
    """Astern thrust coefficient of one propeller (N s^2/rad^2)."""
    tau_n: float = 0.4
    """Shaft-speed time constant (s), our choice."""
    strips: int = 6
    """Strips of the cross-flow drag integral."""

    @property
    def m23(self) -> float:
        """Sway-yaw inertia coupling m x_g (kg m)."""
        return self.m * self.x_g

    @property
    def y_v(self) -> float:
        """Linear sway damping (N s/m), speed independent."""
        return self.m22 / self.t_sway

    @property
    def n_r(self) -> float:
        """Linear yaw damping (N m s/rad)."""
        return self.m33 / self.t_yaw

    @property
    def n_max(self) -> float:
        """Shaft speed at full ahead command (rad/s): half the 24.4 kg bollard pull each."""
        return math.sqrt(0.5 * 24.4 * G / self.k_pos)

    @property
    def n_min(self) -> float:
        """Shaft speed at full astern command (rad/s, negative): half of 13.6 kg each."""
        return -math.sqrt(0.5 * 13.6 * G / self.k_neg)

    def thrust(self, n: float) -> float:
        """Thrust (N) of one propeller at shaft speed ``n`` (rad/s)."""
        return (self.k_pos if n >= 0.0 else self.k_neg) * n * abs(n)

    def shaft_command(self, c: float) -> float:
        """Commanded shaft speed (rad/s) for a normalized command ``c`` (clipped to [-1, 1])."""
        c = min(1.0, max(-1.0, c))
        return c * self.n_max if c >= 0.0 else -c * self.n_min

    def steady_speed(self, c: float) -> float:
        """Straight-line speed (m/s) with both propellers at command ``c`` >= 0."""
        return 2.0 * self.thrust(self.shaft_command(c)) / self.x_u


class Catamaran(PlantBase):
    """Otter-class catamaran; inputs ``command.left`` and ``command.right`` in [-1, 1].
    Extra states: the two shaft speeds (rad/s)."""

    name = "catamaran"
    n_extra = 2

    def __init__(self, params: CatamaranParams | None = None, dt: float = 0.01) -> None:
        super().__init__(dt)
        self.params = params or CatamaranParams()
        p = self.params
        dx = p.length / p.strips
        self._xs = tuple(-0.5 * p.length + (i + 0.5) * dx for i in range(p.strips))
        self._k_cf = 0.5 * RHO * p.draft * p.c_d * dx
        det = p.m22 * p.m33 - p.m23**2
        self._inv = (p.m33 / det, -p.m23 / det, p.m22 / det)

    @property
    def shaft_speeds(self) -> tuple[float, float]:
        """(left, right) shaft speeds (rad/s)."""
        return float(self.x[12]), float(self.x[13])

    def cross_flow(self, v: float, r: float) -> tuple[float, float]:
        """Cross-flow drag (N, N m) on the pontoons at sway ``v`` (m/s), yaw rate ``r``."""
        y = n = 0.0
        for x in self._xs:
            w = v + x * r
            f = -self._k_cf * abs(w) * w
            y += f
            n += x * f
        return y, n

    def _rhs(self, t: float, x: list[float], command: Command) -> list[float]:
        p = self.params
        psi, u, v, r, nl, nr = x[5], x[6], x[7], x[11], x[12], x[13]
        tl, tr = p.thrust(nl), p.thrust(nr)
        m11, m22, m23 = p.m11, p.m22, p.m23
        y_cf, n_cf = self.cross_flow(v, r)
        udot = (tl + tr + m22 * v * r + m23 * r * r - p.x_u * u) / m11
        fy = -m11 * u * r - p.y_v * v + y_cf
        fn = (p.y_pont * (tl - tr) - (m22 - m11) * u * v - m23 * u * r
              - p.n_r * (1.0 + 10.0 * abs(r)) * r + n_cf)
        i22, i23, i33 = self._inv
        vdot = i22 * fy + i23 * fn
        rdot = i23 * fy + i33 * fn
        cpsi, spsi = math.cos(psi), math.sin(psi)
        vc = self._vc
        return [
            cpsi * u - spsi * v + vc[0], spsi * u + cpsi * v + vc[1], 0.0,
            0.0, 0.0, r,
            udot, vdot, 0.0, 0.0, 0.0, rdot,
            (p.shaft_command(command.left or 0.0) - nl) / p.tau_n,
            (p.shaft_command(command.right or 0.0) - nr) / p.tau_n,
        ]

    def propulsion(self, command: Command) -> PropulsionWrench:
        p = self.params
        return twin_thruster_wrench(p.thrust(float(self.x[12])), p.thrust(float(self.x[13])),
                                    p.y_pont, p)
