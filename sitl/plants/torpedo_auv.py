"""Torpedo AUV (REMUS 100 / Gavia class): 6-DOF Prestero model with propeller, rudder and
stern planes.

Source: T. Prestero, "Verification of a six-degree of freedom simulation model for the
REMUS autonomous underwater vehicle", MSc thesis, MIT/WHOI, 2001: equations of motion
(his ch. 3, body origin at the centre of buoyancy) and the coefficient table (his
Table 4.2 / appendix), re-typed here; Fossen (2021) section 8 gives the same structure.
algorithms.md section 3.3 states the Gavia regression model in this form. All symbols
are Prestero's; the fin coefficients absorb the fin lift ``~ u^2 delta``:

    (m - X_udot) u' + m z_g q' = X_HS + X_uu u|u| + (X_wq - m) w q + X_qq q^2
                                + (X_vr + m) v r + X_rr r^2 - m z_g p r + X_prop
    (m - Y_vdot) v' - m z_g p' - Y_rdot r' = Y_HS + Y_vv v|v| + Y_rr r|r| + Y_uv u v
                                + (Y_ur - m) u r + (Y_wp + m) w p + Y_pq p q
                                - m z_g q r + Y_uudr u^2 delta_r
    (m - Z_wdot) w' - Z_qdot q' = Z_HS + Z_ww w|w| + Z_qq q|q| + Z_uw u w + (Z_uq + m) u q
                                + (Z_vp - m) v p + Z_rp r p + m z_g (p^2 + q^2)
                                + Z_uuds u^2 delta_s
    (I_xx - K_pdot) p' - m z_g v' = K_HS + K_pp p|p| - (I_zz - I_yy) q r
                                + m z_g (u r - w p) + K_prop
    (I_yy - M_qdot) q' + m z_g u' - M_wdot w' = M_HS + M_ww w|w| + M_qq q|q| + M_uw u w
                                + M_uq u q + M_vp v p + (M_rp - (I_xx - I_zz)) r p
                                - m z_g (w q - v r) + M_uuds u^2 delta_s
    (I_zz - N_rdot) r' - N_vdot v' = N_HS + N_vv v|v| + N_rr r|r| + N_uv u v + N_ur u r
                                + N_wp w p + (N_pq - (I_yy - I_xx)) p q + N_uudr u^2 delta_r

with x_g = y_g = 0, CB at the origin and hydrostatics ``X_HS = -(W - B) sin(theta)``,
``Y_HS = (W - B) cos(theta) sin(phi)``, ``Z_HS = (W - B) cos(theta) cos(phi)``,
``K_HS = -z_g W cos(theta) sin(phi)``, ``M_HS = -z_g W sin(theta)``, ``N_HS = 0``.
(The ``m z_g`` cross terms are the rigid-body terms of Prestero's eqs. 3.23 with
x_g = y_g = 0.)

Propeller (a documented simplification of Prestero's fixed X_prop): thrust and torque
quadratic in shaft speed ``n`` (rpm), ``X_prop = k_T n|n|``, ``K_prop = k_Q n|n|``, with
``k_T``, ``k_Q`` set so that Prestero's values (X_prop = 3.86 N, K_prop = -0.543 N m) are
reached at 1500 rpm, the REMUS cruise setting; then the steady speed is
``u = n sqrt(k_T / -X_uu)`` = 1.54 m/s at 1500 rpm. The shaft follows
``command.propeller_rpm`` (or ``command.throttle * max_rpm``) with a first-order lag.

Sign conventions: ``command.rudder_rad`` positive turns the bow to starboard, which is
Prestero's *negative* delta_r (his N_uudr < 0); ``command.stern_plane_rad`` positive
pitches the nose down, Prestero's positive delta_s (M_uuds < 0). Fins are limited to
+-0.35 rad (20 deg).

Changes from the printed table, so that the axisymmetric hull stays symmetric: the
printed Y_vv (-1.31e3) and M_qq (-1.88e2) are replaced by Z_ww (-131 kg/m) and N_rr
(-94 kg m^2/rad^2): a cross-flow drag coefficient of ~1 on a 1.33 m x 0.19 m hull gives
~130 kg/m, not 1310.

Open-loop stability: linearized at 1.54 m/s the yaw mode is +0.99 1/s and the pitch modes
+0.44 +- 0.16j 1/s, i.e. Prestero's REMUS is unstable without its autopilot (Munk moment
|N_uv| = 24 kg against a fin yaw damping N_ur of only -2 kg m); open loop it settles into
a slow turn limited by the quadratic damping. Scenarios must close heading and depth
loops (the tests use a PD rudder/stern-plane autopilot). REMUS is 7 N positively buoyant (W = 299 N, B = 306 N); without a
depth controller it rises and floats (:func:`sitl.plants.fossen.submerged_fraction`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from onboard.sitl.integrate import GRAVITY
from onboard.sitl.plants.base import Command, PlantBase, PropulsionWrench
from onboard.sitl.plants.fossen import SparseMatrix, submerged_fraction

__all__ = ["TorpedoParams", "TorpedoAUV", "REMUS100"]


@dataclass(frozen=True)
class TorpedoParams:
    """Prestero (2001) REMUS 100 coefficients (SI; Prestero's units: kg, m, rad)."""

    weight: float = 299.0
    buoyancy: float = 306.0
    z_g: float = 0.0196
    i_xx: float = 0.177
    i_yy: float = 3.45
    i_zz: float = 3.45
    length: float = 1.33
    diameter: float = 0.191
    x_uu: float = -1.62
    x_udot: float = -0.93
    x_wq: float = -35.5
    x_qq: float = -1.93
    x_vr: float = 35.5
    x_rr: float = -1.93
    y_vv: float = -131.0
    y_rr: float = 0.632
    y_uv: float = -28.6
    y_vdot: float = -35.5
    y_rdot: float = 1.93
    y_ur: float = 5.22
    y_wp: float = 35.5
    y_pq: float = 1.93
    y_uudr: float = 9.64
    z_ww: float = -131.0
    z_qq: float = -0.632
    z_uw: float = -28.6
    z_wdot: float = -35.5
    z_qdot: float = -1.93
    z_uq: float = -5.22
    z_vp: float = -35.5
    z_rp: float = 1.93
    z_uuds: float = -9.64
    k_pp: float = -0.130
    k_pdot: float = -0.0704
    m_ww: float = 3.18
    m_qq: float = -94.0
    m_uw: float = 24.0
    m_wdot: float = -1.93
    m_qdot: float = -4.88
    m_uq: float = -2.0
    m_vp: float = -1.93
    m_rp: float = 4.86
    m_uuds: float = -6.15
    n_vv: float = -3.18
    n_rr: float = -94.0
    n_uv: float = -24.0
    n_vdot: float = 1.93
    n_rdot: float = -4.88
    n_ur: float = -2.0
    n_wp: float = -1.93
    n_pq: float = -4.86
    n_uudr: float = -6.15
    x_prop_ref: float = 3.86
    """Prestero's propeller thrust (N) at ``rpm_ref``."""
    k_prop_ref: float = -0.543
    """Prestero's propeller torque (N m) at ``rpm_ref``."""
    rpm_ref: float = 1500.0
    """Shaft speed at which the Prestero propeller values hold (rpm)."""
    max_rpm: float = 2500.0
    """Shaft speed at ``throttle = 1`` (rpm)."""
    tau_rpm: float = 0.3
    """Shaft-speed time constant (s)."""
    fin_max: float = math.radians(20.0)
    """Rudder and stern-plane limit (rad)."""

    @property
    def m(self) -> float:
        """Mass W / g (kg)."""
        return self.weight / GRAVITY

    @property
    def k_t(self) -> float:
        """Thrust coefficient (N/rpm^2)."""
        return self.x_prop_ref / self.rpm_ref**2

    @property
    def k_q(self) -> float:
        """Torque coefficient (N m/rpm^2)."""
        return self.k_prop_ref / self.rpm_ref**2

    def steady_speed(self, rpm: float) -> float:
        """Straight, level steady speed (m/s): ``k_T n^2 = -X_uu u^2``."""
        return abs(rpm) * math.sqrt(self.k_t / -self.x_uu)

    def mass_matrix(self) -> np.ndarray:
        """The 6x6 left-hand-side matrix of Prestero's equations (rigid body + added)."""
        m, zg = self.m, self.z_g
        return np.array([
            [m - self.x_udot, 0.0, 0.0, 0.0, m * zg, 0.0],
            [0.0, m - self.y_vdot, 0.0, -m * zg, 0.0, -self.y_rdot],
            [0.0, 0.0, m - self.z_wdot, 0.0, -self.z_qdot, 0.0],
            [0.0, -m * zg, 0.0, self.i_xx - self.k_pdot, 0.0, 0.0],
            [m * zg, 0.0, -self.m_wdot, 0.0, self.i_yy - self.m_qdot, 0.0],
            [0.0, -self.n_vdot, 0.0, 0.0, 0.0, self.i_zz - self.n_rdot],
        ])


REMUS100 = TorpedoParams()
"""Prestero's REMUS 100."""


class TorpedoAUV(PlantBase):
    """REMUS 100 / Gavia-class torpedo AUV. Inputs: ``command.propeller_rpm`` (rpm; else
    ``command.throttle * max_rpm``), ``command.rudder_rad``, ``command.stern_plane_rad``.
    Extra state: shaft speed (rpm)."""

    name = "torpedo_auv"
    n_extra = 1

    def __init__(self, params: TorpedoParams | None = None, dt: float = 0.01) -> None:
        super().__init__(dt)
        self.params = params or REMUS100
        self._mass = self.params.mass_matrix()
        self._minv = SparseMatrix(np.linalg.inv(self._mass), tol=1e-14)
        self._rpm_cmd = 0.0
        self._dr = 0.0
        self._ds = 0.0
        self.reset()

    def reset(
        self, *, north: float = 0.0, east: float = 0.0, down: float = 0.0, yaw: float = 0.0,
        u: float = 0.0,
    ) -> None:
        """As :meth:`PlantBase.reset`; the shaft starts at the speed that holds ``u``."""
        super().reset(north=north, east=east, down=down, yaw=yaw, u=u)
        p = self.params
        self.x[12] = math.copysign(abs(u) * math.sqrt(-p.x_uu / p.k_t), u)

    def _prepare(self, command: Command) -> None:
        p = self.params
        if command.propeller_rpm is not None:
            rpm = float(command.propeller_rpm)
        else:
            rpm = p.max_rpm * min(1.0, max(-1.0, command.throttle or 0.0))
        self._rpm_cmd = rpm
        lim = p.fin_max
        # Prestero's delta_r is opposite to our rudder_rad (see the module docstring).
        self._dr = -min(lim, max(-lim, command.rudder_rad or 0.0))
        self._ds = min(lim, max(-lim, command.stern_plane_rad or 0.0))

    def _rhs(self, t: float, x: list[float], command: Command) -> list[float]:
        c = self.params
        kin = self._kinematics(x)
        phi, theta = float(x[3]), float(x[4])
        u, v, w, p, q, r, n = x[6:13]
        m, zg = c.m, c.z_g
        b = c.buoyancy * submerged_fraction(float(x[2]), c.diameter)
        wb = c.weight - b
        sth, cth = math.sin(theta), math.cos(theta)
        sphi, cphi = math.sin(phi), math.cos(phi)
        uu = u * u
        nn = n * abs(n)
        dr, ds = self._dr, self._ds
        fx = (-wb * sth + c.x_uu * u * abs(u) + (c.x_wq - m) * w * q + c.x_qq * q * q
              + (c.x_vr + m) * v * r + c.x_rr * r * r - m * zg * p * r + c.k_t * nn)
        fy = (wb * cth * sphi + c.y_vv * v * abs(v) + c.y_rr * r * abs(r) + c.y_uv * u * v
              + (c.y_ur - m) * u * r + (c.y_wp + m) * w * p + c.y_pq * p * q - m * zg * q * r
              + c.y_uudr * uu * dr)
        fz = (wb * cth * cphi + c.z_ww * w * abs(w) + c.z_qq * q * abs(q) + c.z_uw * u * w
              + (c.z_uq + m) * u * q + (c.z_vp - m) * v * p + c.z_rp * r * p
              + m * zg * (p * p + q * q) + c.z_uuds * uu * ds)
        mk = (-zg * c.weight * cth * sphi + c.k_pp * p * abs(p) - (c.i_zz - c.i_yy) * q * r
              + m * zg * (u * r - w * p) + c.k_q * nn)
        mm = (-zg * c.weight * sth + c.m_ww * w * abs(w) + c.m_qq * q * abs(q) + c.m_uw * u * w
              + c.m_uq * u * q + c.m_vp * v * p + (c.m_rp - (c.i_xx - c.i_zz)) * r * p
              - m * zg * (w * q - v * r) + c.m_uuds * uu * ds)
        mn = (c.n_vv * v * abs(v) + c.n_rr * r * abs(r) + c.n_uv * u * v + c.n_ur * u * r
              + c.n_wp * w * p + (c.n_pq - (c.i_yy - c.i_xx)) * p * q + c.n_uudr * uu * dr)
        nudot = self._minv.matvec([fx, fy, fz, mk, mm, mn])
        return kin + nudot + [(self._rpm_cmd - n) / c.tau_rpm]

    @property
    def rpm(self) -> float:
        """Current shaft speed (rpm)."""
        return float(self.x[12])

    def propulsion(self, command: Command) -> PropulsionWrench:
        c = self.params
        self._prepare(command)
        n = float(self.x[12])
        nn = n * abs(n)
        uu = float(self.x[6]) ** 2
        x_f = c.k_t * nn
        y_f = c.y_uudr * uu * self._dr
        z_f = c.z_uuds * uu * self._ds
        n_f = c.n_uudr * uu * self._dr
        return PropulsionWrench(
            force=(x_f, y_f, z_f),
            moment=(c.k_q * nn, c.m_uuds * uu * self._ds, n_f),
            surge_input=x_f / self._mass[0, 0],
            yaw_input=n_f / self._mass[5, 5],
        )
