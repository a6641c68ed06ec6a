"""The plant interface shared by every simulated vehicle, and a base class implementing it.

A *plant* is the true vehicle dynamics. The SITL loop calls, at its own rate,

    plant.step(dt, command, env, t)     # advance from t to t + dt
    plant.truth(t + dt, env)            # the hidden truth (sitl.truth.TruthRecord)
    plant.specific_force_body()         # what an ideal IMU measures now
    plant.angular_rate_body()

and the plant integrates internally with RK4 sub-steps of at most ``plant.dt`` (s).

State layout of :class:`PlantBase` (every plant): ``x = [N, E, D, phi, theta, psi,
u_r, v_r, w_r, p, q, r, extra...]``: NED position (m), ZYX Euler angles (rad), the body
FRD velocity **through the water** (m/s) and the body rates (rad/s), then plant-specific
states (motor speeds). Currents are irrotational, so the angular velocity through water
equals the angular velocity over ground. Kinematics (Fossen 2021, eqs. 2.40, 10.125):

    p'     = R(Theta) nu_r[0:3] + V_c(t, p)
    Theta' = T(Theta) omega

Over-ground body velocity ``nu[0:3] = nu_r[0:3] + R^T V_c``. The kinetics are written
in ``nu_r`` (Fossen Property 10.1: exact for a constant irrotational current). For a
neutrally buoyant body in a uniformly accelerating flow the Froude-Krylov force exactly
cancels the inertial term, so integrating ``nu_r`` is also right for slowly varying tidal
flow; the gradient terms of a nonuniform flow (~1e-3 of the damping in Fan et al.'s
field) are neglected. The current is held constant over each RK4 sub-step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from onboard.core.messages import ActuatorCommand
from onboard.sitl.frames import euler_to_matrix, kinematics, wrap_pi
from onboard.sitl.environment import Environment
from onboard.sitl.integrate import GRAVITY, rk4_step_list
from onboard.sitl.truth import TruthRecord

__all__ = ["Command", "ManoeuvringMasses", "Plant", "PlantBase", "PropulsionWrench"]


class ManoeuvringMasses:
    """Effective masses of a 3-DOF (surge, sway, yaw) manoeuvring model, for parameter
    dataclasses with ``m``, ``x_udot``, ``y_vdot`` (kg), ``i_z``, ``n_rdot`` (kg m^2)."""

    m: float
    x_udot: float
    y_vdot: float
    i_z: float
    n_rdot: float

    @property
    def m11(self) -> float:
        """Effective surge mass m - X_udot (kg)."""
        return self.m - self.x_udot

    @property
    def m22(self) -> float:
        """Effective sway mass m - Y_vdot (kg)."""
        return self.m - self.y_vdot

    @property
    def m33(self) -> float:
        """Effective yaw inertia I_z - N_rdot (kg m^2)."""
        return self.i_z - self.n_rdot


@dataclass(frozen=True)
class Command:
    """The *true* actuator values applied to a plant (same fields as
    :class:`onboard.core.messages.ActuatorCommand`; ``None`` is read as 0 / not fitted).

    * ``throttle``: single propulsor, [-1, 1];
    * ``rudder_rad``: rudder deflection (rad), positive turns the bow to starboard;
    * ``left``, ``right``: skid-steer thrusters, [-1, 1];
    * ``propeller_rpm``: shaft speed (rev/min) of a torpedo AUV's propeller;
    * ``stern_plane_rad``: stern plane deflection (rad), positive pitches the nose down;
    * ``thrusters``: per-thruster commands in [-1, 1] (BlueROV2 order, see
      :mod:`sitl.plants.bluerov2`);
    * ``external_force_world``: an external force (N, NED) on the vehicle, e.g. the
      BlueROV2 disturbance test's [40, 40, 10] N.
    """

    throttle: float | None = None
    rudder_rad: float | None = None
    left: float | None = None
    right: float | None = None
    propeller_rpm: float | None = None
    stern_plane_rad: float | None = None
    thrusters: tuple[float, ...] | None = None
    external_force_world: np.ndarray | None = None

    @classmethod
    def from_actuator(
        cls, cmd: ActuatorCommand, external_force_world: np.ndarray | None = None
    ) -> Command:
        """The plant command equal to a normalized :class:`ActuatorCommand`."""
        return cls(
            throttle=cmd.throttle,
            rudder_rad=cmd.rudder_rad,
            left=cmd.left,
            right=cmd.right,
            propeller_rpm=cmd.propeller_rpm,
            stern_plane_rad=cmd.stern_plane_rad,
            thrusters=cmd.thrusters,
            external_force_world=external_force_world,
        )

    def to_actuator(self, t: float, source: str = "sitl") -> ActuatorCommand:
        """This command as an :class:`ActuatorCommand` sample at time ``t`` (s)."""
        return ActuatorCommand(
            t=t,
            source=source,
            throttle=self.throttle,
            rudder_rad=self.rudder_rad,
            left=self.left,
            right=self.right,
            propeller_rpm=self.propeller_rpm,
            stern_plane_rad=self.stern_plane_rad,
            thrusters=self.thrusters,
        )


@runtime_checkable
class Plant(Protocol):
    """What the SITL needs from a vehicle model."""

    name: str
    dt: float
    """Internal integration step (s), <= 0.01."""

    def reset(
        self, *, north: float = 0.0, east: float = 0.0, down: float = 0.0, yaw: float = 0.0,
        u: float = 0.0,
    ) -> None:
        """Put the vehicle at rest (or at surge speed ``u`` through water, m/s) at a pose."""
        ...

    def step(self, dt: float, command: Command, env: Environment, t: float) -> None:
        """Advance from time ``t`` to ``t + dt`` (s) with RK4 sub-steps <= ``self.dt``."""
        ...

    def truth(self, t: float, env: Environment) -> TruthRecord:
        """The true state at time ``t`` (must be the time reached by the last step)."""
        ...

    def specific_force_body(self) -> np.ndarray:
        """(3,) specific force (m/s^2, body FRD): acceleration minus gravity."""
        ...

    def angular_rate_body(self) -> np.ndarray:
        """(3,) angular rate (rad/s, body FRD)."""
        ...


@dataclass(frozen=True)
class PropulsionWrench:
    """The true propulsion/control wrench in body axes and the AIE-normalized inputs.

    ``force`` (N) and ``moment`` (N m) are body FRD; ``surge_input`` = X / m_11 (m/s^2)
    and ``yaw_input`` = N / m_66 (rad/s^2) with the plant's effective (rigid + added)
    surge mass and yaw inertia, or None where the plant does not define them.
    """

    force: tuple[float, float, float]
    moment: tuple[float, float, float]
    surge_input: float | None = None
    yaw_input: float | None = None


def twin_thruster_wrench(t_left: float, t_right: float, half_spacing: float,
                         masses: ManoeuvringMasses) -> PropulsionWrench:
    """The wrench of two parallel thrusters ``half_spacing`` (m) either side of the
    centre line pushing ``t_left`` and ``t_right`` (N): surge force ``X = T_l + T_r`` and
    yaw moment ``N = half_spacing (T_l - T_r)`` (FRD: port ahead turns to starboard),
    with their AIE-normalized inputs ``X / m11`` and ``N / m33``."""
    x_f, n_z = t_left + t_right, half_spacing * (t_left - t_right)
    return PropulsionWrench(force=(x_f, 0.0, 0.0), moment=(0.0, 0.0, n_z),
                            surge_input=x_f / masses.m11, yaw_input=n_z / masses.m33)


class PlantBase:
    """Common machinery: state, RK4 sub-stepping, truth, ideal IMU.

    Subclasses set ``name``, ``n_extra`` and implement :meth:`_rhs` (the state
    derivative) and :meth:`propulsion` (the wrench reported in the truth).
    """

    name: str = "plant"
    n_extra: int = 0
    """Number of plant-specific states after the 12 rigid-body ones."""

    def __init__(self, dt: float = 0.01) -> None:
        if not 0.0 < dt <= 0.01:
            raise ValueError(f"internal step dt must be in (0, 0.01] s, got {dt}")
        self.dt = dt
        self.x = np.zeros(12 + self.n_extra)
        self._t = 0.0
        self._env: Environment | None = None
        self._command = Command()
        self._vc = (0.0, 0.0, 0.0)
        self._xdot: np.ndarray | None = None

    # ----------------------------------------------------------------- interface
    def reset(
        self, *, north: float = 0.0, east: float = 0.0, down: float = 0.0, yaw: float = 0.0,
        u: float = 0.0,
    ) -> None:
        """Pose (m, rad) and surge speed through water ``u`` (m/s); everything else zero."""
        self.x = np.zeros(12 + self.n_extra)
        self.x[0:3] = (north, east, down)
        self.x[5] = yaw
        self.x[6] = u
        self._t = 0.0
        self._env = None
        self._command = Command()
        self._vc = (0.0, 0.0, 0.0)
        self._xdot = None
        self._prepare(self._command)

    def step(self, dt: float, command: Command, env: Environment, t: float) -> None:
        """Advance by ``dt`` (s) from ``t`` with equal RK4 sub-steps of at most ``self.dt``."""
        self._command = command
        self._env = env
        self._prepare(command)
        if dt > 0.0:
            n = max(1, math.ceil(dt / self.dt - 1e-9))
            h = dt / n
            x = self.x.tolist()
            f = self._f
            for i in range(n):
                ti = t + i * h
                self._vc = tuple(env.current_ned(ti, np.array(x[0:3])).tolist())
                x = rk4_step_list(f, ti, x, h)
            self.x = np.array(x)
        self._t = t + dt
        self._vc = tuple(float(c) for c in env.current_ned(self._t, self.x[0:3]))
        self._xdot = None

    def truth(self, t: float, env: Environment) -> TruthRecord:
        """The true state at ``t`` with first-order wave motion superposed."""
        x = self.x
        phi, theta, psi = float(x[3]), float(x[4]), float(x[5])
        vc = env.current_ned(t, x[0:3])
        rot = euler_to_matrix(phi, theta, psi)
        v_r = x[6:9]
        v_ned = rot @ v_r + vc
        wm = env.wave_motion(t, x[0:3], v_ned, psi)
        pos = x[0:3] + wm.displacement
        roll, pitch = phi + wm.roll, theta + wm.pitch
        rot_t = euler_to_matrix(roll, pitch, psi) if env.waves is not None else rot
        v_body = rot_t.T @ (v_ned + wm.velocity)
        w_body = self.angular_rate_body()
        wr = self.propulsion(self._command)
        ext = self._command.external_force_world
        dist = None if ext is None else rot.T @ np.asarray(ext, dtype=float)
        ll = env.latlon(float(pos[0]), float(pos[1]))
        return TruthRecord(
            t=float(t),
            north=float(pos[0]),
            east=float(pos[1]),
            down=float(pos[2]),
            roll=float(roll),
            pitch=float(pitch),
            yaw=wrap_pi(psi),
            u=float(v_body[0]),
            v=float(v_body[1]),
            w=float(v_body[2]),
            p=float(w_body[0]),
            q=float(w_body[1]),
            r=float(w_body[2]),
            u_r=float(v_r[0]),
            v_r=float(v_r[1]),
            w_r=float(v_r[2]),
            current_north=float(vc[0]),
            current_east=float(vc[1]),
            current_down=float(vc[2]),
            surge_input=None if wr.surge_input is None else float(wr.surge_input),
            yaw_input=None if wr.yaw_input is None else float(wr.yaw_input),
            force_x=float(wr.force[0]),
            force_y=float(wr.force[1]),
            force_z=float(wr.force[2]),
            moment_z=float(wr.moment[2]),
            disturbance_x=None if dist is None else float(dist[0]),
            disturbance_y=None if dist is None else float(dist[1]),
            disturbance_z=None if dist is None else float(dist[2]),
            lat_deg=None if ll is None else ll[0],
            lon_deg=None if ll is None else ll[1],
        )

    def specific_force_body(self) -> np.ndarray:
        """Ideal accelerometer (m/s^2, body FRD): ``R^T (a_ned - g_ned)`` with

            a_ned = R (nu_r' + omega x nu_r) + dV_c/dt + a_wave

        evaluated at the state and command of the last step. At rest and level it is
        ``[0, 0, -9.81]``.
        """
        x = self.x
        phi, theta, psi = float(x[3]), float(x[4]), float(x[5])
        rot = euler_to_matrix(phi, theta, psi)
        xdot = self._derivative_now()
        v_r = x[6:9]
        # omega x nu_r written out (np.cross costs ~10x more on 3-vectors; same operations
        # and rounding as numpy's: a1 b2 - a2 b1, a2 b0 - a0 b2, a0 b1 - a1 b0)
        p, q, r = float(x[9]), float(x[10]), float(x[11])
        u, v, w = float(x[6]), float(x[7]), float(x[8])
        a_ned = rot @ (xdot[6:9] + np.array((q * w - r * v, r * u - p * w, p * v - q * u)))
        env = self._env
        if env is not None:
            v_ned = rot @ v_r + np.asarray(self._vc)
            a_ned = a_ned + env.current_rate_ned(self._t, x[0:3], v_ned)
            if env.waves is not None:
                wm = env.wave_motion(self._t, x[0:3], v_ned, psi)
                a_ned = a_ned + wm.acceleration
                rot = euler_to_matrix(phi + wm.roll, theta + wm.pitch, psi)
        g = GRAVITY if env is None else env.gravity
        return rot.T @ (a_ned - np.array([0.0, 0.0, g]))

    def angular_rate_body(self) -> np.ndarray:
        """Ideal gyro (rad/s, body FRD): ``[p, q, r]`` plus the wave-following roll/pitch rates."""
        w = np.array(self.x[9:12], dtype=float)
        env = self._env
        if env is not None and env.waves is not None:
            x = self.x
            rot = euler_to_matrix(float(x[3]), float(x[4]), float(x[5]))
            v_ned = rot @ x[6:9] + np.asarray(self._vc)
            wm = env.wave_motion(self._t, x[0:3], v_ned, float(x[5]))
            w[0] += wm.p
            w[1] += wm.q
        return w

    # ------------------------------------------------------------- state helpers
    @property
    def position_ned(self) -> np.ndarray:
        """Low-frequency NED position (m)."""
        return self.x[0:3].copy()

    @property
    def euler(self) -> np.ndarray:
        """Low-frequency (roll, pitch, yaw) (rad); yaw is not wrapped."""
        return self.x[3:6].copy()

    @property
    def nu_r(self) -> np.ndarray:
        """Body velocity through water and body rates ``[u_r, v_r, w_r, p, q, r]``."""
        return self.x[6:12].copy()

    def velocity_ned(self) -> np.ndarray:
        """Low-frequency over-ground velocity (m/s, NED)."""
        x = self.x
        rot = euler_to_matrix(float(x[3]), float(x[4]), float(x[5]))
        return rot @ x[6:9] + np.asarray(self._vc)

    # --------------------------------------------------------- for subclasses
    def _f(self, t: float, x: list[float]) -> list[float]:
        return self._rhs(t, x, self._command)

    def _derivative_now(self) -> np.ndarray:
        if self._xdot is None:
            self._xdot = np.array(self._rhs(self._t, self.x.tolist(), self._command))
        return self._xdot

    def _kinematics(self, x: list[float]) -> list[float]:
        """``[N', E', D', phi', theta', psi']`` for the state ``x`` and the held current:
        ``R(Theta) nu_r[0:3] + V_c`` and ``T(Theta) omega``
        (:func:`onboard.sitl.frames.kinematics`)."""
        dn, de, dd, dphi, dtheta, dpsi = kinematics(x[3], x[4], x[5], x[6:12])
        vc = self._vc
        return [dn + vc[0], de + vc[1], dd + vc[2], dphi, dtheta, dpsi]

    def _prepare(self, command: Command) -> None:
        """Precompute what depends only on the command (called once per :meth:`step`)."""

    def _rhs(self, t: float, x: list[float], command: Command) -> list[float]:
        """State derivative ``x'`` (same layout as ``x``), on plain lists of floats."""
        raise NotImplementedError

    def propulsion(self, command: Command) -> PropulsionWrench:
        """The true propulsion wrench at the current state for ``command``."""
        raise NotImplementedError

