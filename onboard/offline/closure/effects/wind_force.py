"""``wind_force``: a push fixed in the earth frame, so the thrust the hull needs depends on
its heading (wind on the superstructure, a towed body's drag toward the tide).

A force per mass ``(north, east)`` (m/s^2, the direction it pushes toward) adds
``north cos(psi) + east sin(psi)`` to the surge equation ``U' = -a U + b c + c0``: the
boat runs faster downwind and slower upwind *through the water*. That is what separates it
from a ``water_current``, which carries the boat over ground by the same amount in every
channel (across the heading as much as along it) and leaves the speed through the water
alone. A wind's leeway across the heading is small on a keeled hull; where it shows, it
looks like a drift over ground (``water_current``) and is reported as such. Reported:
``north``, ``east`` (m/s^2) and the steady speed change they make up- and downwind,
``speed_change_mps = hypot(north, east) / a``.
"""

from __future__ import annotations

import math

import numpy as np

from onboard.offline.closure.effects.base import Context, Effect


class WindForce(Effect):
    """An earth-fixed force per mass in the surge equation (module docstring)."""

    name = "wind_force"
    params = ("north", "east")
    needs_commands = True
    dynamic = True

    def columns(self, ds, ctx: Context):
        return {"along": np.column_stack([np.cos(ds.psi), np.sin(ds.psi)])}

    def surge_terms(self, theta, ds):
        return theta[0] * np.cos(ds.psi) + theta[1] * np.sin(ds.psi), None, 0.0

    def describe(self, theta, std, pole: float | None = None):
        params, sd = super().describe(theta, std)
        if pole:
            params["speed_change_mps"] = math.hypot(float(theta[0]), float(theta[1])) / pole
        return params, sd


EFFECT = WindForce()
