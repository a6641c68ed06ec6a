"""BlueROV2 (standard, 6 thrusters) 6-DOF Fossen model with the ESESO paper's parameters.

    M nu_r' + C(nu_r) nu_r + D(nu_r) nu_r + g(eta) = tau_thr + tau_ext        (Fossen eq. 10.146)

* ``M = M_RB + M_A``: m = 11.26 kg, inertia diag(0.3, 0.63, 0.58) kg m^2 about the CG
  (shifted to the origin by the parallel-axis theorem), CG at r_g = (0, 0, z_G) below the
  centre of buoyancy (the origin), ``M_A = diag(1.7182, 0, 5.468, 0, 1.2481, 0.4006)``
  (kg, kg m^2/rad). Source: ESESO paper Table I (../papers/eseso-ampc-bluerov2.txt) and
  HKPolyU-UAV/bluerov2 bluerov2_dob.h (algorithms.md section 5.4).
* ``C(nu_r)``: rigid-body plus added-mass Coriolis/centripetal, :func:`coriolis_times_nu`.
* ``D(nu_r) nu_r = -(D_l + D_nl |nu_r|) nu_r`` element-wise with the Table I values
  ``D_l = [-11.7391, -20, -31.8678, -25, -44.9085, -5]`` and
  ``D_nl = [-18.18, -21.66, -36.99, -1.55, -1.55, -1.55]`` (negative numbers).
* ``g(eta)``: weight W = 112.8 N, buoyancy B = 114.8 N (Table I; 2 N net upward, so an
  idle vehicle rises at ~0.059 m/s), CB at the origin, CG at z_G = 0.2 m below it
  (Table I). The HKPolyU code uses z_G = 0.02 m; with it the righting moment W z_G =
  2.3 N m/rad is weaker than the Munk pitch moment of the added masses, and the paper's
  [40, 40, 10] N disturbance pitches the model by ~65 deg, which the vehicle does not do;
  Table I's 0.2 m gives 22.6 N m/rad. (With the inertias taken about the origin, 0.2 m
  would make M indefinite: hence "about the CG" above.) W / g = 11.5 kg differs from
  m = 11.26 kg; both are kept as published (m for inertia, W for weight). Buoyancy fades
  out as the hull breaks the surface (:func:`submerged_fraction`, height 0.25 m).
* ``tau_thr = K f(c)``: six T200 thrusters, normalized commands ``c_i in [-1, 1]``
  (``command.thrusters``), thrust ``f = 40 c|c|`` N ahead, ``30 c|c|`` N astern (T200 at
  ~14.8 V), no motor lag. Order and geometry (body FRD; the HKPolyU K_alloc, which is
  written in FLU axes, converted to FRD):

      t0 front-right, t1 front-left, t2 rear-right, t3 rear-left: horizontal, vectored at
         45 deg; positive t0/t1 push forward (t0 toward port, t1 toward starboard),
         positive t2/t3 push backward;
      t4 right vertical, t5 left vertical: positive pushes up (-z).

  :data:`ALLOCATION` rows (X, Y, Z, K, M, N); yaw arms 0.167 m (front) and 0.175 m (rear)
  and the vertical thrusters' roll arm 0.1105 m are the HKPolyU values. The horizontal
  thrusters act at the height of the origin (no roll/pitch moment from them): the code's
  +-0.0513 m roll arm would roll and pitch the vehicle under surge and sway thrust (18 deg
  at full surge), which the real vehicle does not do.
* ``tau_ext = [R^T F_ext; 0]``: ``command.external_force_world`` (N, NED) at the origin.

With all horizontal thrusters at full surge, X = 0.707 (40 + 40 + 30 + 30) = 99 N and the
steady speed is the root of ``11.7391 u + 18.18 u^2 = 99``, 2.03 m/s; Blue Robotics quote
~1.5 m/s for the real vehicle, whose drag at speed is larger than these low-speed
identified coefficients (a known limit of the model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from onboard.sitl.frames import ned_to_body_fast
from onboard.sitl.plants.base import Command, PlantBase, PropulsionWrench
from onboard.sitl.plants.fossen import (
    SparseMatrix,
    coriolis_times_nu,
    restoring_forces,
    rigid_body_mass,
    submerged_fraction,
)

__all__ = [
    "ALLOCATION",
    "BlueROV2Params",
    "BlueROV2",
    "thruster_forces",
    "thruster_commands",
]

_S = math.sqrt(0.5)

ALLOCATION = np.array([
    [_S, _S, -_S, -_S, 0.0, 0.0],
    [-_S, _S, -_S, _S, 0.0, 0.0],
    [0.0, 0.0, 0.0, 0.0, -1.0, -1.0],
    [0.0, 0.0, 0.0, 0.0, -0.1105, 0.1105],
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [-0.167, 0.167, 0.175, -0.175, 0.0, 0.0],
])
"""Thruster allocation K (6x6, body FRD): ``tau = K @ f`` with f the six thrusts (N)."""
_ALLOCATION_PINV = np.linalg.pinv(ALLOCATION)
"""pinv(K), computed once (:func:`thruster_commands` runs at every control tick)."""

T_FWD = 40.0
"""T200 thrust at full ahead command (N)."""
T_REV = 30.0
"""T200 thrust at full astern command (N)."""


def thruster_forces(commands: tuple[float, ...] | np.ndarray | None) -> np.ndarray:
    """Thrust (N) of each of the six thrusters for normalized commands in [-1, 1]
    (clipped): ``40 c|c|`` ahead, ``30 c|c|`` astern. ``None`` or missing entries are 0."""
    f = np.zeros(6)
    if commands is None:
        return f
    for i, c in enumerate(list(commands)[:6]):
        c = min(1.0, max(-1.0, float(c)))
        f[i] = (T_FWD if c >= 0.0 else T_REV) * c * abs(c)
    return f


def thruster_commands(wrench_body: np.ndarray) -> tuple[float, ...]:
    """Normalized commands that best produce a body wrench ``[X, Y, Z, K, M, N]`` (N, N m):
    least-squares thrusts ``pinv(K) tau``, inverted through the thrust curve, clipped to
    [-1, 1]. Pitch (M) is not actuated and is ignored."""
    f = _ALLOCATION_PINV @ np.asarray(wrench_body, dtype=float)
    out = []
    for fi in f:
        k = T_FWD if fi >= 0.0 else T_REV
        out.append(float(np.clip(math.copysign(math.sqrt(abs(fi) / k), fi), -1.0, 1.0)))
    return tuple(out)


@dataclass(frozen=True)
class BlueROV2Params:
    """ESESO paper Table I / HKPolyU bluerov2 parameters (SI)."""

    m: float = 11.26
    """Mass (kg)."""
    weight: float = 112.8
    """W (N), Table I."""
    buoyancy: float = 114.8
    """B (N), Table I."""
    z_g: float = 0.2
    """CG below the CB (m), Table I (the HKPolyU code uses 0.02; see the module doc)."""
    inertia: tuple[float, float, float] = (0.3, 0.63, 0.58)
    """Ix, Iy, Iz about the CG (kg m^2)."""
    added_mass: tuple[float, ...] = (1.7182, 0.0, 5.468, 0.0, 1.2481, 0.4006)
    """Diagonal of M_A (kg, kg m^2)."""
    d_lin: tuple[float, ...] = (-11.7391, -20.0, -31.8678, -25.0, -44.9085, -5.0)
    """Linear damping D_l (N s/m, N m s/rad), negative."""
    d_quad: tuple[float, ...] = (-18.18, -21.66, -36.99, -1.55, -1.55, -1.55)
    """Quadratic damping D_nl (N s^2/m^2, N m s^2/rad^2), negative."""
    height: float = 0.25
    """Vertical extent for the free-surface buoyancy fade (m)."""
    mass_matrix: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        mrb = rigid_body_mass(self.m, (0.0, 0.0, self.z_g), np.diag(self.inertia))
        object.__setattr__(self, "mass_matrix", mrb + np.diag(self.added_mass))

    def steady_speed(self, axis: int, force: float) -> float:
        """Closed-form steady velocity (m/s or rad/s) along ``axis`` (0..5) under a constant
        generalized force: root of ``D_l x + D_nl x|x| + F = 0``."""
        a, b = -self.d_quad[axis], -self.d_lin[axis]
        s = (-b + math.sqrt(b * b + 4.0 * a * abs(force))) / (2.0 * a)
        return math.copysign(s, force)


class BlueROV2(PlantBase):
    """BlueROV2 6-DOF plant; inputs ``command.thrusters`` (6 normalized) and
    ``command.external_force_world`` (N, NED)."""

    name = "bluerov2"
    n_extra = 0

    def __init__(self, params: BlueROV2Params | None = None, dt: float = 0.01) -> None:
        super().__init__(dt)
        self.params = params or BlueROV2Params()
        self._mass = self.params.mass_matrix
        self._mass_sp = SparseMatrix(self._mass)
        self._minv_sp = SparseMatrix(np.linalg.inv(self._mass), tol=1e-14)
        self._dl = [-d for d in self.params.d_lin]
        self._dnl = [-d for d in self.params.d_quad]
        self._tau_thr = [0.0] * 6
        self._ext: tuple[float, float, float] | None = None
        self.reset()

    def _prepare(self, command: Command) -> None:
        self._tau_thr = (ALLOCATION @ thruster_forces(command.thrusters)).tolist()
        ext = command.external_force_world
        self._ext = None if ext is None else (float(ext[0]), float(ext[1]), float(ext[2]))

    def _external_body(self, phi: float, theta: float, psi: float) -> tuple[float, float, float]:
        """R^T F_ext (N, body) for the held external force (zeros without one)."""
        if self._ext is None:
            return 0.0, 0.0, 0.0
        return ned_to_body_fast(phi, theta, psi, self._ext)

    def _rhs(self, t: float, x: list[float], command: Command) -> list[float]:
        p = self.params
        kin = self._kinematics(x)
        phi, theta, psi = float(x[3]), float(x[4]), float(x[5])
        nu = x[6:12]
        b = p.buoyancy * submerged_fraction(float(x[2]), p.height)
        g = restoring_forces(p.weight, b, (0.0, 0.0, p.z_g), (0.0, 0.0, 0.0), phi, theta)
        fx, fy, fz = self._external_body(phi, theta, psi)
        c = coriolis_times_nu(self._mass_sp, nu)
        dl, dnl = self._dl, self._dnl
        tau = self._tau_thr
        rhs = [
            tau[i] - c[i] - g[i] - (dl[i] + dnl[i] * abs(n)) * n
            for i, n in enumerate(nu)
        ]
        rhs[0] += fx
        rhs[1] += fy
        rhs[2] += fz
        return kin + self._minv_sp.matvec(rhs)

    def propulsion(self, command: Command) -> PropulsionWrench:
        tau = ALLOCATION @ thruster_forces(command.thrusters)
        m = self._mass
        return PropulsionWrench(
            force=(float(tau[0]), float(tau[1]), float(tau[2])),
            moment=(float(tau[3]), float(tau[4]), float(tau[5])),
            surge_input=float(tau[0] / m[0, 0]),
            yaw_input=float(tau[5] / m[5, 5]),
        )
