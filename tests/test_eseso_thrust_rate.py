"""The ESESO's thrust update runs at the actuator's rate: once per thruster command, at the
first IMU sample after it, never again for a held command (docs/algorithms.md §5.1)."""

from __future__ import annotations

import numpy as np
import pytest

from onboard.core.messages import ActuatorCommand, Attitude, Depth, DvlVelocity, Imu
from onboard.pipelines.eseso import Eseso, EsesoConfig

IMU_HZ = 50
SECONDS = 10


def _stream(command_every: int, seed: int = 0) -> list:
    """A hovering ROV: 50 Hz IMU, attitude, depth and DVL at 5 Hz, a thruster command every
    ``command_every`` IMU samples."""
    rng = np.random.default_rng(seed)
    out: list = []
    for k in range(IMU_HZ * SECONDS):
        t = k / IMU_HZ
        if k % 10 == 0:
            out += [Attitude(t=t, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0),
                    Depth(t=t, depth_m=20.0), DvlVelocity(t=t, vx=0.0, vy=0.0, vz=0.0)]
        if k % command_every == 0:
            out.append(ActuatorCommand(t=t, thrusters=(0.1, -0.1, 0.0, 0.0, 0.2, 0.2)))
        out.append(Imu(t=t, accel_x=rng.normal(0, 0.05), accel_y=rng.normal(0, 0.05),
                       accel_z=-9.81 + rng.normal(0, 0.05), gyro_x=0.0, gyro_y=0.0,
                       gyro_z=0.0))
    return out


def _thrust_updates(command_every: int) -> tuple[int, int]:
    """(thrust updates, commands) over the stream, ticked at 20 Hz."""
    p = Eseso(EsesoConfig())
    samples = _stream(command_every)
    for k in range(20 * SECONDS):
        t = (k + 1) / 20
        p.step(t, [s for s in samples if k / 20 < s.t <= t or (k == 0 and s.t == 0.0)])
    commands = sum(isinstance(s, ActuatorCommand) for s in samples)
    return p.health().counts.get("fused.thrust", 0), commands


@pytest.mark.parametrize("command_every", [5, 2, 1])
def test_one_thrust_update_per_command(command_every: int) -> None:
    """A 10, 25 or 50 Hz command stream gives one thrust update per command (the first
    command arrives before the filter starts, the second before two IMU samples exist)."""
    updates, commands = _thrust_updates(command_every)
    assert commands - 2 <= updates <= commands


def test_a_held_command_is_not_fused_again() -> None:
    """With a single command (at t = 0) the thrust is fused once, however many IMU samples
    follow while it is fresh (0.5 s: 24 samples)."""
    p = Eseso(EsesoConfig())
    p.step(1.0, [s for s in _stream(IMU_HZ * SECONDS) if s.t <= 1.0])
    assert p.health().counts.get("fused.thrust", 0) == 1
