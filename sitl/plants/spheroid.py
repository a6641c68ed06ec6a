"""The 2 m prolate-spheroid AUV of Fan et al.'s current-estimation paper, 6-DOF.

Scenario source: ../papers/nonlinear-observer-current-nonuniform-flow.txt (algorithms.md
section 4.2): a prolate spheroid hull, length 2 m, fineness ratio 10 (a = 1 m, b = 0.1 m),
four fins, neutrally buoyant, nominal speed 0.77 m/s.

Model (Fossen 2021, eq. 10.146, in the flow-relative velocity nu_r):

    (M_RB + M_A) nu_r' + C(nu_r) nu_r + D(nu_r) nu_r + g(eta) = tau_fins + tau_prop

* Mass and inertia [DERIVED, algorithms.md 4.3, rho = 1025 kg/m^3]: m = m_f =
  rho 4/3 pi a b^2 = 42.94 kg, I_xx = 2/5 m b^2 = 0.172, I_yy = I_zz = m (a^2 + b^2)/5 =
  8.67 kg m^2 about the CG. Lamb's added mass: X_udot = -k1 m = -0.889 kg,
  Y_vdot = Z_wdot = -k2 m = -41.23 kg, M_qdot = N_rdot = -k' I_yy = -7.66 kg m^2.
* C(nu_r): rigid-body plus added-mass Coriolis, which carries the Munk moments
  ``-(A22 - A11) u v`` (yaw) and ``(A33 - A11) u w`` (pitch) that make the bare hull
  unstable; the fins restore stability.
* Damping [DEFAULT, flagged as assumptions in algorithms.md 4.3]: axial drag
  ``X_uu = -1/2 rho C_d pi b^2`` with C_d = 0.2 (-3.22 kg/m); cross-flow drag
  ``Y_vv = Z_ww = -1/2 rho (2b)(2a) C_dc`` with C_dc = 1 (-205 kg/m) and its rotational
  counterpart ``N_rr = M_qq = -1/2 rho C_dc 2b * a^4/2`` (-51.3 kg m^2); roll damping
  K_p = -0.5 N m s (our choice).
* Fins [our choice]: two pairs at x_f = -0.9 m; each pair gives a lift
  ``L = -c_f u (v_f + u delta)`` normal to it, ``v_f`` the local cross-flow at the fin:

      Y_fin = -c_f u (v + x_f r + u delta_r),   N_fin = x_f Y_fin
      Z_fin = -c_f u (w - x_f q + u delta_s),   M_fin = -x_f Z_fin

  with c_f = 60 N s^2/(m^2 rad) (= 1/2 rho S C_L_alpha, e.g. S = 0.039 m^2 per pair and
  C_L_alpha = 3/rad). Fin yaw stiffness 0.9 c_f = 54 u v exceeds the Munk 40.3 u v, so the
  vehicle is directionally stable; the sway/yaw modes at 0.77 m/s have time constants of
  ~2 s and ~0.4 s. Positive ``rudder_rad`` turns the bow to starboard, positive
  ``stern_plane_rad`` pitches the nose down (the project conventions); limits +-0.35 rad.
* Restoring: W = B = m g (neutral), CB at the origin, CG 0.01 m below it (our choice, to
  give the vehicle a roll righting moment; a uniform spheroid would have none).
* Propeller [our choice]: thrust ``k_T n|n|`` with k_T chosen so that the nominal shaft
  speed (:data:`NOMINAL_RPM` = 1000 rpm) gives the paper's 0.77 m/s:
  ``k_T = -X_uu 0.77^2 / 1000^2``. ``command.propeller_rpm`` (rpm) or
  ``command.throttle * max_rpm`` (max_rpm = 1500) with a 0.3 s first-order shaft lag. No
  propeller torque.

The nonuniform-flow gradient terms of Thomasson & Woolsey are neglected (~1e-3 of the
damping for the paper's field, algorithms.md 4.1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from onboard.sitl.integrate import GRAVITY
from onboard.sitl.plants.base import Command, PlantBase, PropulsionWrench
from onboard.sitl.plants.fossen import (
    SparseMatrix,
    coriolis_times_nu,
    restoring_forces,
    rigid_body_mass,
    submerged_fraction,
)

__all__ = ["SpheroidParams", "SpheroidAUV", "NOMINAL_RPM", "NOMINAL_SPEED"]

NOMINAL_RPM = 1000.0
"""Propeller setting that gives the nominal speed (rpm)."""
NOMINAL_SPEED = 0.77
"""The paper's nominal speed (m/s)."""


def _lamb(a: float, b: float) -> tuple[float, float, float]:
    """Lamb's k-factors (k1, k2, k') of a prolate spheroid with semi-axes a > b."""
    e = math.sqrt(1.0 - (b / a) ** 2)
    ln = math.log((1.0 + e) / (1.0 - e))
    alpha0 = 2.0 * (1.0 - e * e) / e**3 * (0.5 * ln - e)
    beta0 = 1.0 / e**2 - (1.0 - e * e) / (2.0 * e**3) * ln
    k1 = alpha0 / (2.0 - alpha0)
    k2 = beta0 / (2.0 - beta0)
    kp = e**4 * (beta0 - alpha0) / (
        (2.0 - e * e) * (2.0 * e * e - (2.0 - e * e) * (beta0 - alpha0))
    )
    return k1, k2, kp


@dataclass(frozen=True)
class SpheroidParams:
    """Geometry and coefficients; derived quantities are computed from a, b and rho."""

    a: float = 1.0
    """Semi-major axis (m)."""
    b: float = 0.1
    """Semi-minor axis (m)."""
    rho: float = 1025.0
    """Water density (kg/m^3)."""
    z_g: float = 0.01
    """CG below the CB (m), our choice."""
    c_d: float = 0.2
    """Axial drag coefficient on the frontal area pi b^2."""
    c_dc: float = 1.0
    """Cross-flow drag coefficient on the projected area 2b x 2a."""
    k_p: float = -0.5
    """Linear roll damping (N m s/rad)."""
    x_fin: float = -0.9
    """Fin position (m)."""
    c_fin: float = 60.0
    """Lift coefficient of one fin pair, 1/2 rho S C_L_alpha (N s^2/(m^2 rad))."""
    fin_max: float = 0.35
    """Fin deflection limit (rad)."""
    max_rpm: float = 1500.0
    """Shaft speed at throttle = 1 (rpm)."""
    tau_rpm: float = 0.3
    """Shaft-speed time constant (s)."""
    m: float = field(init=False)
    inertia: tuple[float, float, float] = field(init=False)
    added_mass: tuple[float, ...] = field(init=False)
    x_uu: float = field(init=False)
    y_vv: float = field(init=False)
    n_rr: float = field(init=False)
    k_t: float = field(init=False)

    def __post_init__(self) -> None:
        s = object.__setattr__
        a, b = self.a, self.b
        m = self.rho * 4.0 / 3.0 * math.pi * a * b * b
        iyy = m * (a * a + b * b) / 5.0
        k1, k2, kp = _lamb(a, b)
        s(self, "m", m)
        s(self, "inertia", (0.4 * m * b * b, iyy, iyy))
        s(self, "added_mass", (k1 * m, k2 * m, k2 * m, 0.0, kp * iyy, kp * iyy))
        s(self, "x_uu", -0.5 * self.rho * self.c_d * math.pi * b * b)
        s(self, "y_vv", -0.5 * self.rho * (2 * b) * (2 * a) * self.c_dc)
        s(self, "n_rr", -0.5 * self.rho * self.c_dc * 2 * b * a**4 / 2.0)
        s(self, "k_t", -self.x_uu * NOMINAL_SPEED**2 / NOMINAL_RPM**2)

    def steady_speed(self, rpm: float) -> float:
        """Straight-line speed (m/s): ``k_T n^2 = -X_uu u^2``."""
        return abs(rpm) * math.sqrt(self.k_t / -self.x_uu)

    def mass_matrix(self) -> np.ndarray:
        """M_RB + M_A (6x6)."""
        mrb = rigid_body_mass(self.m, (0.0, 0.0, self.z_g), np.diag(self.inertia))
        return mrb + np.diag(self.added_mass)


class SpheroidAUV(PlantBase):
    """Fan et al.'s 2 m spheroid AUV. Inputs: ``command.propeller_rpm`` (or ``throttle``),
    ``command.rudder_rad``, ``command.stern_plane_rad``. Extra state: shaft speed (rpm)."""

    name = "spheroid"
    n_extra = 1

    def __init__(self, params: SpheroidParams | None = None, dt: float = 0.01) -> None:
        super().__init__(dt)
        self.params = params or SpheroidParams()
        self._mass = self.params.mass_matrix()
        self._mass_sp = SparseMatrix(self._mass)
        self._minv = SparseMatrix(np.linalg.inv(self._mass), tol=1e-14)
        self._weight = self.params.m * GRAVITY
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
            self._rpm_cmd = float(command.propeller_rpm)
        else:
            self._rpm_cmd = p.max_rpm * min(1.0, max(-1.0, command.throttle or 0.0))
        lim = p.fin_max
        self._dr = min(lim, max(-lim, command.rudder_rad or 0.0))
        self._ds = min(lim, max(-lim, command.stern_plane_rad or 0.0))

    def _fins(self, u: float, v: float, w: float, q: float, r: float) -> tuple[float, float]:
        """(Y_fin, Z_fin) in N."""
        p = self.params
        cu = p.c_fin * u
        y_f = -cu * (v + p.x_fin * r + u * self._dr)
        z_f = -cu * (w - p.x_fin * q + u * self._ds)
        return y_f, z_f

    def _rhs(self, t: float, x: list[float], command: Command) -> list[float]:
        c = self.params
        kin = self._kinematics(x)
        phi, theta = float(x[3]), float(x[4])
        nu = x[6:12]
        u, v, w, p, q, r = nu
        n = float(x[12])
        b = self._weight * submerged_fraction(float(x[2]), 2.0 * c.b)
        g = restoring_forces(self._weight, b, (0.0, 0.0, c.z_g), (0.0, 0.0, 0.0), phi, theta)
        cor = coriolis_times_nu(self._mass_sp, nu)
        y_f, z_f = self._fins(u, v, w, q, r)
        xf = c.x_fin
        tau = [
            c.k_t * n * abs(n) + c.x_uu * u * abs(u),
            y_f + c.y_vv * v * abs(v),
            z_f + c.y_vv * w * abs(w),
            c.k_p * p,
            -xf * z_f + c.n_rr * q * abs(q),
            xf * y_f + c.n_rr * r * abs(r),
        ]
        nudot = self._minv.matvec([tau[i] - cor[i] - g[i] for i in range(6)])
        return kin + nudot + [(self._rpm_cmd - n) / c.tau_rpm]

    @property
    def rpm(self) -> float:
        """Current shaft speed (rpm)."""
        return float(self.x[12])

    def propulsion(self, command: Command) -> PropulsionWrench:
        c = self.params
        self._prepare(command)
        n = float(self.x[12])
        u = float(self.x[6])
        # control part of the fin forces (the deflection terms only)
        y_d = -c.c_fin * u * u * self._dr
        z_d = -c.c_fin * u * u * self._ds
        x_f = c.k_t * n * abs(n)
        n_z = c.x_fin * y_d
        return PropulsionWrench(
            force=(x_f, y_d, z_d),
            moment=(0.0, -c.x_fin * z_d, n_z),
            surge_input=x_f / self._mass[0, 0],
            yaw_input=n_z / self._mass[5, 5],
        )
