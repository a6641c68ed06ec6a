"""PID position and heading controller of the BlueROV2: the paper's baseline (fig. 4-5).

A textbook PID per axis in the earth frame, on the same ESESO state estimate the MPCs use,
with the weight-minus-buoyancy compensated and no model feed-forward (the paper's PID
knows neither the path's acceleration nor the drag; that is what separates it from the
MPCs)::

    F_ned = Kp e + Ki int(e) + Kd (v_ref - v),   e = p_ref - p     (N)
    [X, Y, Z] = R(psi)^T F_ned - [0, 0, W - B]
    N = Kp_psi e_psi + Ki_psi int(e_psi) + Kd_psi (r_ref - r)       (N m)

with anti-windup by clamping the integrals and conditional integration while the
wrench saturates the thrusters. Gains [DEFAULT] were tuned on ``bluerov2-circle``
without the push for a well-damped response (~1.5 s rise) that does not saturate the
thrusters on the nominal circle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from onboard.core.messages import EstimateRecord
from onboard.sitl.controllers.base import (
    Bluerov2Params,
    CircleReference,
    ControlOutput,
    state_from_record,
)


@dataclass(frozen=True)
class PidGains:
    """Gains per earth axis (N/m, N/(m s), N s/m) and for yaw (N m/rad, ...)."""

    kp: tuple[float, float, float] = (60.0, 60.0, 60.0)
    ki: tuple[float, float, float] = (10.0, 10.0, 10.0)
    kd: tuple[float, float, float] = (40.0, 40.0, 40.0)
    kp_yaw: float = 8.0
    ki_yaw: float = 0.5
    kd_yaw: float = 3.0
    integral_limit_n: float = 60.0
    """Clamp of each integral term (N or N m)."""


class PidController:
    """The PID (``pid``)."""

    name = "pid"

    def __init__(self, params: Bluerov2Params | None = None, gains: PidGains | None = None,
                 rate_hz: float = 20.0) -> None:
        self.p = params or Bluerov2Params()
        self.g = gains or PidGains()
        self.dt = 1.0 / rate_hz
        self._int = np.zeros(3)
        self._int_yaw = 0.0

    def update(self, t: float, estimate: EstimateRecord,
               reference: CircleReference) -> ControlOutput:
        """The PID wrench (module docstring) for time ``t`` (s) from the published
        estimate and the reference, and the thruster commands that produce it."""
        x = state_from_record(estimate)
        rp = reference(t)
        g = self.g
        psi = float(x[3])
        c, s = math.cos(psi), math.sin(psi)
        v_ned = np.array([c * x[4] - s * x[5], s * x[4] + c * x[5], x[6]])
        e = rp.position - x[0:3]
        e_psi = math.remainder(rp.yaw - psi, 2 * math.pi)
        F = (np.asarray(g.kp) * e + np.asarray(g.ki) * self._int
             + np.asarray(g.kd) * (rp.velocity_ned - v_ned))
        Nz = g.kp_yaw * e_psi + g.ki_yaw * self._int_yaw + g.kd_yaw * (rp.yaw_rate - x[7])
        fb = np.array([c * F[0] + s * F[1], -s * F[0] + c * F[1], F[2]])
        fb[2] -= self.p.weight - self.p.buoyancy
        wrench = np.array([fb[0], fb[1], fb[2], Nz])
        forces = self.p.B_pinv @ wrench
        saturated = bool(np.any(forces > self.p.thrust_max_n)
                         or np.any(forces < self.p.thrust_min_n))
        if not saturated:
            lim = g.integral_limit_n
            ki = np.maximum(np.asarray(g.ki), 1e-9)
            self._int = np.clip(self._int + e * self.dt, -lim / ki, lim / ki)
            lim_yaw = lim / max(g.ki_yaw, 1e-9)
            self._int_yaw = float(np.clip(self._int_yaw + e_psi * self.dt, -lim_yaw, lim_yaw))
        return ControlOutput(wrench=wrench, thrusters=self.p.thrusters_from_wrench(wrench))
