"""The effect vocabulary of ``onboard diagnose``, one module per effect.

Names are fixed by architecture.md §4.3. :data:`ALL` lists them in the order selection
considers them.
"""

from __future__ import annotations

from onboard.offline.closure.effects import (
    actuator_mapping,
    compass_deviation,
    gps_latency,
    gyro_bias,
    heading_bias,
    quadratic_drag,
    sideslip,
    surge_yaw_coupling,
    thrust_nonlinearity,
    water_current,
    wave_oscillation,
    wind_force,
)
from onboard.offline.closure.effects.base import Context, Effect

ALL: dict[str, Effect] = {m.EFFECT.name: m.EFFECT for m in (
    water_current, compass_deviation, heading_bias, gyro_bias, gps_latency,
    thrust_nonlinearity, quadratic_drag, surge_yaw_coupling, sideslip, wave_oscillation,
    actuator_mapping, wind_force)}

__all__ = ["ALL", "Context", "Effect"]
