"""The controllers' shared definitions: the BlueROV2's 4-DOF model parameters and
allocation, the circle reference, the controller interface and what it returns.

Every controller (:mod:`.pid`, :mod:`.nmpc`, :mod:`.ampc`) builds on these; the package
(:mod:`sitl.controllers`) re-exports them beside its factory
:func:`sitl.controllers.make_controller`.

Frames: NED earth, FRD body, ZYX Euler angles, SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from onboard.core.messages import EstimateRecord


@dataclass(frozen=True)
class Bluerov2Params:
    """BlueROV2 4-DOF model parameters (paper Table I; algorithms.md §5.4), FRD/NED, SI.

    Added masses and damping are positive numbers (the paper lists the damping negated).
    ``allocation`` is the 4 x 6 map from thruster forces (N) to ``[X, Y, Z, N]``;
    ``thrust_max_n`` / ``thrust_min_n`` the per-thruster force limits; the thrust curve is
    ``f = f_max c|c|`` (T200, ``thrust_exponent`` 2). These equal the simulated plant's
    (:mod:`sitl.plants.bluerov2`, rows X, Y, Z, N of its ``ALLOCATION``; a test checks it).
    """

    mass: float = 11.26
    inertia_z: float = 0.58
    added_mass: tuple[float, float, float, float] = (1.7182, 0.0, 5.468, 0.4006)
    """X_udot, Y_vdot, Z_wdot, N_rdot (kg, kg, kg, kg m^2)."""
    damping_linear: tuple[float, float, float, float] = (11.7391, 20.0, 31.8678, 5.0)
    damping_quadratic: tuple[float, float, float, float] = (18.18, 21.66, 36.99, 1.55)
    weight: float = 112.8
    buoyancy: float = 114.8
    allocation: tuple[tuple[float, ...], ...] = (
        (0.7071, 0.7071, -0.7071, -0.7071, 0.0, 0.0),
        (-0.7071, 0.7071, -0.7071, 0.7071, 0.0, 0.0),
        (0.0, 0.0, 0.0, 0.0, -1.0, -1.0),
        (-0.167, 0.167, 0.175, -0.175, 0.0, 0.0),
    )
    thrust_max_n: float = 40.0
    thrust_min_n: float = -30.0
    thrust_exponent: float = 2.0
    """Thrust = max * sign(c) |c|^exponent of a normalized command c in [-1, 1]."""

    @property
    def B(self) -> np.ndarray:
        """The 4 x 6 allocation matrix."""
        return np.asarray(self.allocation, dtype=float)

    @property
    def B_pinv(self) -> np.ndarray:
        """6 x 4 minimum-norm allocation: thruster forces of a wrench."""
        return np.linalg.pinv(self.B)

    def thrusters_from_wrench(self, wrench: np.ndarray) -> tuple[float, ...]:
        """Normalized thruster commands in [-1, 1] producing ``wrench`` (clipped)."""
        return self.commands_from_forces(self.B_pinv @ np.asarray(wrench, dtype=float))

    def commands_from_forces(self, forces: np.ndarray) -> tuple[float, ...]:
        """Normalized commands in [-1, 1] of per-thruster forces (N), through the inverse
        thrust curve, clipped."""
        out = []
        for f in np.asarray(forces, dtype=float):
            full = self.thrust_max_n if f >= 0 else -self.thrust_min_n
            c = min(abs(float(f)) / full, 1.0) ** (1.0 / self.thrust_exponent)
            out.append(math.copysign(c, f) if f != 0 else 0.0)
        return tuple(out)

    def wrench_from_thrusters(self, commands: tuple[float, ...]) -> np.ndarray:
        """The wrench ``[X, Y, Z, N]`` of normalized thruster commands."""
        f = []
        for c in commands:
            mag = min(abs(c), 1.0) ** self.thrust_exponent
            f.append(mag * (self.thrust_max_n if c >= 0 else self.thrust_min_n))
        return self.B @ np.asarray(f)


@dataclass(frozen=True)
class ReferencePoint:
    """The reference at one instant: NED position (m), yaw (rad), body velocity
    ``(u, v, w)`` (m/s) and yaw rate ``r`` (rad/s)."""

    position: np.ndarray
    yaw: float
    velocity_body: np.ndarray
    yaw_rate: float
    velocity_ned: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True)
class CircleReference:
    """The paper's circle (algorithms.md §5.3), turned into NED.

    Their code is z-up with x, y = ``-r cos(v t / r)``, ``-r sin(v t / r)``, z = -20 m and
    psi = ``v t / r - pi/2`` measured from x. With x = east, y = north, z = up:
    ``north = -r sin(w t)``, ``east = -r cos(w t)``, ``down = depth``, heading
    ``pi - w t`` (clockwise from north), ``w = v / r``: the vehicle faces along the path,
    which it flies anticlockwise seen from above. The reference is a function of time, so
    any controller samples it at its own prediction times (no 4x fast preview).
    """

    radius: float = 2.0
    speed: float = 0.5
    """m/s along the arc. The paper's 1.5 m/s needs up to 117 N of thrust against the 99 N
    the simulated thrusters give (docs/eseso-mpc.md); 0.5 m/s is feasible all round."""
    depth: float = 20.0
    center_north: float = 0.0
    center_east: float = 0.0

    @property
    def omega(self) -> float:
        """Angular rate along the circle, ``speed / radius`` (rad/s)."""
        return self.speed / self.radius

    def __call__(self, t: float) -> ReferencePoint:
        w, r = self.omega, self.radius
        n = self.center_north - r * math.sin(w * t)
        e = self.center_east - r * math.cos(w * t)
        vn = -r * w * math.cos(w * t)
        ve = r * w * math.sin(w * t)
        yaw = math.pi - w * t
        return ReferencePoint(
            position=np.array([n, e, self.depth]),
            yaw=yaw,
            velocity_body=np.array([self.speed, 0.0, 0.0]),
            yaw_rate=-w,
            velocity_ned=np.array([vn, ve, 0.0]),
        )


@dataclass(frozen=True)
class ControlOutput:
    """What a controller returns: the wrench ``[X, Y, Z, N]`` (body FRD; N, N m), the
    normalized thruster commands, and the solver time (s) when there is a solver."""

    wrench: np.ndarray
    thrusters: tuple[float, ...]
    solve_time_s: float | None = None
    status: str = "ok"


class Controller(Protocol):
    """One control law. ``update`` is called at the control rate (20 Hz)."""

    name: str

    def update(self, t: float, estimate: EstimateRecord,
               reference: CircleReference) -> ControlOutput:
        """The command for time ``t`` (s) from the published estimate and the reference."""
        ...


def state_from_record(rec: EstimateRecord) -> np.ndarray:
    """The 4-DOF controller state ``[N, E, D, psi, u, v, w, r]`` from an ``eseso``
    estimate record (values ``north, east, down, yaw, u, v, w, rate_r``)."""
    v = rec.values
    return np.array([v["north"], v["east"], v["down"], v["yaw"], v["u"], v["v"], v["w"],
                     v.get("rate_r", 0.0)])
