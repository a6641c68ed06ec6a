"""Guidance and autopilots that fly the scenarios: the policy from what the vehicle knows to
the actuator command.

The hook every controller plugs into (:class:`Controller`): once per control period
(``rate_hz``) the runner calls ``controller(inp)`` with a :class:`ControlInput` and applies
the returned :class:`~sitl.plants.base.Command` until the next call. ``inp.samples`` are
the sensor samples emitted since the previous call (what an onboard autopilot sees),
``inp.truth`` the true state (a perfect navigation system, for controllers that are not
under test for their navigation), ``inp.reference`` the scenario's reference at ``t``.
A closed-loop controller under study (``onboard sitl --controller``) is one more
:class:`Controller`; see :func:`sitl.runner.simulate`'s ``controller`` argument.

Autopilots here:

* :class:`BoatAutopilot`: heading autopilot (PID on the compass heading and the gyro
  yaw rate, so compass errors steer the boat as they do at sea) plus an open-loop speed
  setpoint (feed-forward from speed to throttle, like the Jaiabot throttle table), over a
  repeating list of :class:`Leg` s; rudder or skid steering;
* :class:`AuvAutopilot`: depth (cascade depth -> pitch -> stern plane) and heading (rudder)
  autopilot at a constant propeller speed, following a heading schedule;
* :class:`RovCirclePid`: a PID with model feed-forward that flies the BlueROV2 around
  :class:`CircleReference` on the true state (the ESESO paper's Gazebo setup).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Protocol, Sequence

import numpy as np

from onboard.sitl.frames import wrap_pi
from onboard.core.messages import Heading, Imu, Sample
from onboard.sitl.plants.base import Command
from onboard.sitl.truth import TruthRecord


def _clip(x: float, lim: float) -> float:
    return -lim if x < -lim else lim if x > lim else x


@dataclass(frozen=True)
class ControlInput:
    """What a controller gets each control period (see the module docstring)."""

    t: float
    samples: Sequence[Sample]
    truth: TruthRecord
    reference: Any = None


class Controller(Protocol):
    """A control policy: ``rate_hz`` calls per second, each returning the command to hold."""

    rate_hz: float

    def __call__(self, inp: ControlInput) -> Command: ...


# --------------------------------------------------------------------------- surface boats


@dataclass(frozen=True)
class Leg:
    """One manoeuvre of a boat mission.

    ``heading_rad``: absolute heading to hold (rad, clockwise from north), or None to keep
    the reference the previous leg ended with; ``turn_rate_rps``: the reference then turns
    at this rate (rad/s, + starboard) for the whole leg (circles); ``speed_mps``: the speed
    setpoint through the water (m/s).
    """

    duration_s: float
    heading_rad: float | None = None
    turn_rate_rps: float = 0.0
    speed_mps: float = 1.0


class _Mission:
    """A repeating list of legs: the heading and speed reference at time t."""

    def __init__(self, legs: Sequence[Leg], initial_heading: float = 0.0) -> None:
        if not legs:
            raise ValueError("a mission needs at least one leg")
        self.legs = tuple(legs)
        self.period = sum(l.duration_s for l in legs)
        self.i = 0
        self.t0 = 0.0
        self.psi0 = initial_heading
        self._start_leg(0, 0.0, initial_heading)

    def _start_leg(self, i: int, t: float, psi_prev: float) -> None:
        self.i = i
        self.t0 = t
        leg = self.legs[i]
        self.psi0 = psi_prev if leg.heading_rad is None else leg.heading_rad

    def reference(self, t: float) -> tuple[float, float, float]:
        """(heading_ref rad, yaw-rate feed-forward rad/s, speed_ref m/s) at ``t``."""
        while t >= self.t0 + self.legs[self.i].duration_s - 1e-9:
            leg = self.legs[self.i]
            psi_end = self.psi0 + leg.turn_rate_rps * leg.duration_s
            self._start_leg((self.i + 1) % len(self.legs), self.t0 + leg.duration_s, psi_end)
        leg = self.legs[self.i]
        return (self.psi0 + leg.turn_rate_rps * (t - self.t0), leg.turn_rate_rps,
                leg.speed_mps)


class BoatAutopilot:
    """Heading autopilot plus open-loop speed setpoint for a rudder or skid-steered boat.

    Steering: ``s = kp e + ki int(e) - kd (r - r_ref)`` with ``e`` the wrapped heading error
    from the latest compass sample (truth before the first one) and ``r`` the latest gyro
    yaw rate; ``s`` is the rudder angle (rad, clipped to ``steer_limit``) for
    ``steering="rudder"`` or the left-minus-right thrust split for ``"skid"``.
    Speed: ``speed_to_command(speed_ref)`` gives the throttle (or the common thruster
    command) from the boat's nominal model, held open loop.
    """

    def __init__(self, legs: Sequence[Leg], speed_to_command: Callable[[float], float], *,
                 steering: str = "rudder", kp: float = 0.6, ki: float = 0.02,
                 kd: float = 0.15, steer_limit: float = 0.45, rate_hz: float = 10.0,
                 initial_heading: float = 0.0) -> None:
        if steering not in ("rudder", "skid"):
            raise ValueError(f"steering must be 'rudder' or 'skid', got {steering!r}")
        self.mission = _Mission(legs, initial_heading)
        self.speed_to_command = speed_to_command
        self.steering = steering
        self.kp, self.ki, self.kd = kp, ki, kd
        self.limit = steer_limit
        self.rate_hz = rate_hz
        self._int = 0.0
        self._psi: float | None = None
        self._r: float | None = None

    def __call__(self, inp: ControlInput) -> Command:
        for s in inp.samples:
            if isinstance(s, Heading):
                self._psi = s.heading_rad
            elif isinstance(s, Imu):
                self._r = s.gyro_z
        psi = inp.truth.yaw if self._psi is None else self._psi
        r = inp.truth.r if self._r is None else self._r
        psi_ref, r_ref, speed = self.mission.reference(inp.t)
        e = wrap_pi(psi_ref - psi)
        dt = 1.0 / self.rate_hz
        s = self.kp * e + self.ki * self._int - self.kd * (r - r_ref)
        if abs(s) < self.limit or s * e < 0:  # conditional integration (anti-windup)
            self._int = _clip(self._int + e * dt, 5.0)
        s = _clip(s, self.limit)
        base = self.speed_to_command(speed)
        if self.steering == "rudder":
            return Command(throttle=base, rudder_rad=s)
        left, right = base + s, base - s
        over = max(abs(left), abs(right))
        if over > 1.0:  # keep the turn, give up speed
            left -= math.copysign(over - 1.0, left)
            right -= math.copysign(over - 1.0, right)
        return Command(left=_clip(left, 1.0), right=_clip(right, 1.0))


# --------------------------------------------------------------------------- AUVs


@dataclass(frozen=True)
class HeadingSchedule:
    """Piecewise-constant heading reference (rad) switching every ``period_s`` through
    ``headings_rad``, shaped by a first-order filter of time constant ``tau_s`` (s)."""

    headings_rad: tuple[float, ...]
    period_s: float
    tau_s: float = 5.0


class AuvAutopilot:
    """Depth and heading autopilot of a torpedo-shaped AUV at constant propeller speed.

    Depth: ``theta_ref = clip(-kz (z_ref - z) - kiz int(z_ref - z) + kw w_down, theta_max)``
    (nose down to go deeper; the integral takes up the net buoyancy), stern plane
    ``ds = k_theta (theta - theta_ref) + kq q`` (positive pitches the nose down), clipped.
    Heading: rudder ``dr = kpsi e + ki int(e) - kr r``. All on the true state (an
    INS-grade AUV navigation solution). Propeller: ``rpm``, or with ``rpm_steps`` the
    steps' shaft speeds (rpm) in turn, each held for ``rpm_period_s`` (s).
    """

    def __init__(self, *, rpm: float, depth_m: float, schedule: HeadingSchedule,
                 rpm_steps: tuple[float, ...] = (), rpm_period_s: float = 60.0,
                 kz: float = 0.15, kiz: float = 0.01, kw: float = 0.3,
                 theta_max: float = 0.35,
                 k_theta: float = 1.5, kq: float = 0.8, kpsi: float = 1.0, ki: float = 0.02,
                 kr: float = 2.0, fin_limit: float = 0.26, rate_hz: float = 10.0) -> None:
        self.rpm = rpm
        self.rpm_steps = rpm_steps
        self.rpm_period_s = rpm_period_s
        self.depth = depth_m
        self.schedule = schedule
        self.kz, self.kiz, self.kw, self.theta_max = kz, kiz, kw, theta_max
        self._int_z = 0.0
        self.k_theta, self.kq = k_theta, kq
        self.kpsi, self.ki, self.kr = kpsi, ki, kr
        self.limit = fin_limit
        self.rate_hz = rate_hz
        self._int = 0.0
        self._psi_ref: float | None = None

    def heading_reference(self, t: float, dt: float) -> float:
        """The shaped heading reference (rad) at ``t``; call once per control period."""
        sch = self.schedule
        k = int(t // sch.period_s) % len(sch.headings_rad)
        target = sch.headings_rad[k]
        if self._psi_ref is None:
            self._psi_ref = target
        else:
            self._psi_ref += wrap_pi(target - self._psi_ref) * (1.0 - math.exp(-dt / sch.tau_s))
        return self._psi_ref

    def __call__(self, inp: ControlInput) -> Command:
        tr = inp.truth
        dt = 1.0 / self.rate_hz
        psi_ref = self.heading_reference(inp.t, dt)
        # vertical velocity over ground in NED, approximately
        w_down = -math.sin(tr.pitch) * tr.u + math.cos(tr.pitch) * tr.w
        ez = self.depth - tr.down
        theta_ref = -self.kz * ez - self.kiz * self._int_z + self.kw * w_down
        if abs(theta_ref) < self.theta_max:
            self._int_z = _clip(self._int_z + ez * dt, 20.0)
        theta_ref = _clip(theta_ref, self.theta_max)
        ds = _clip(self.k_theta * (tr.pitch - theta_ref) + self.kq * tr.q, self.limit)
        e = wrap_pi(psi_ref - tr.yaw)
        dr = self.kpsi * e + self.ki * self._int - self.kr * tr.r
        if abs(dr) < self.limit:
            self._int = _clip(self._int + e * dt, 2.0)
        rpm = self.rpm
        if self.rpm_steps:
            rpm = self.rpm_steps[int(inp.t // self.rpm_period_s) % len(self.rpm_steps)]
        return Command(propeller_rpm=rpm, rudder_rad=_clip(dr, self.limit),
                       stern_plane_rad=ds)


# --------------------------------------------------------------------------- BlueROV2


@dataclass(frozen=True)
class CircleReference:
    """The ESESO paper's circle (algorithms.md §5.3) in NED: ``north = -r sin(w t)``,
    ``east = -r cos(w t)``, ``down = depth``, heading ``pi - w t`` (facing along the path,
    anticlockwise seen from above), ``w = speed / radius`` (m, m/s, rad)."""

    radius: float = 2.0
    speed: float = 0.5
    """m/s along the arc. The paper's 1.5 m/s needs up to 117 N of thrust against the 99 N
    the simulated thrusters give (docs/eseso-mpc.md); 0.5 m/s is feasible all round."""
    depth: float = 20.0

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """(position NED m, velocity NED m/s, acceleration NED m/s^2, yaw rad, yaw rate rad/s)."""
        r = self.radius
        w = self.speed / r
        s, c = math.sin(w * t), math.cos(w * t)
        pos = np.array([-r * s, -r * c, self.depth])
        vel = np.array([-r * w * c, r * w * s, 0.0])
        acc = np.array([r * w * w * s, r * w * w * c, 0.0])
        return pos, vel, acc, math.pi - w * t, -w


class RovCirclePid:
    """PID with model feed-forward that flies a BlueROV2 along a reference on the true state.

    World-frame force ``F = M_eff (a_ref + kp e + kd e' + ki int(e)) + D(v_ref)`` (the
    integral, in the earth frame, takes up a constant push such as the scenario's
    [40, 40, 10] N), turned into body axes; yaw moment from a PD on the heading; the weight
    minus buoyancy compensated; thrusters from the plant's allocation
    (``allocate(wrench6) -> commands``).
    """

    def __init__(self, reference: CircleReference, allocate: Callable[[np.ndarray], tuple],
                 *, mass_eff: tuple[float, float, float] = (13.0, 11.3, 16.7),
                 inertia_eff: float = 0.98,
                 drag_lin: tuple[float, float, float] = (11.74, 20.0, 31.87),
                 drag_quad: tuple[float, float, float] = (18.18, 21.66, 36.99),
                 net_weight_n: float = -2.0, kp: float = 4.0, kd: float = 4.0, ki: float = 0.6,
                 kpsi: float = 6.0, kr: float = 4.0, rate_hz: float = 20.0) -> None:
        self.reference = reference
        self.allocate = allocate
        self.m = np.asarray(mass_eff)
        self.iz = inertia_eff
        self.dl = np.asarray(drag_lin)
        self.dq = np.asarray(drag_quad)
        self.net_weight = net_weight_n
        self.kp, self.kd, self.ki = kp, kd, ki
        self.kpsi, self.kr = kpsi, kr
        self.rate_hz = rate_hz
        self._int = np.zeros(3)

    def __call__(self, inp: ControlInput) -> Command:
        tr = inp.truth
        pos_r, vel_r, acc_r, psi_r, r_r = self.reference(inp.t)
        c, s = math.cos(tr.yaw), math.sin(tr.yaw)
        pos = np.array([tr.north, tr.east, tr.down])
        vel = np.array([c * tr.u - s * tr.v, s * tr.u + c * tr.v, tr.w])
        e = pos_r - pos
        self._int = np.clip(self._int + e / self.rate_hz, -20.0, 20.0)
        a = acc_r + self.kp * e + self.kd * (vel_r - vel) + self.ki * self._int
        # to body axes (yaw only; the ROV stays level)
        a_b = np.array([c * a[0] + s * a[1], -s * a[0] + c * a[1], a[2]])
        v_rb = np.array([c * vel_r[0] + s * vel_r[1], -s * vel_r[0] + c * vel_r[1], vel_r[2]])
        f_b = self.m * a_b + (self.dl + self.dq * np.abs(v_rb)) * v_rb
        f_b[2] -= self.net_weight  # W - B = -2 N: push down 2 N
        e_psi = wrap_pi(psi_r - tr.yaw)
        n_z = self.iz * (self.kpsi * e_psi + self.kr * (r_r - tr.r)) + (5.0 + 1.55 * abs(r_r)) * r_r
        wrench = np.array([f_b[0], f_b[1], f_b[2], 0.0, 0.0, n_z])
        return Command(thrusters=tuple(self.allocate(wrench)))
