"""``water_current``: a uniform current (north, east in m/s) carries the vehicle.

Velocity over ground = through-water velocity along the heading + current ``c``. Across
the heading the current shows as ``-sin(psi) c_n + cos(psi) c_e``; along it as
``cos(psi) c_n + sin(psi) c_e``, so the along-track speed over ground rises and falls with
heading (downstream faster). In the derivative-form surge equation, with
``U = along - c.h(psi)``, the current adds ``a c.h(psi) + r c.h_perp(psi)``; to a glider's
along-track speed (its glide speed through the water, no surge equation) it adds
``c.h(psi)`` itself.
Heading must vary (turns) for both components to be observable.
"""

from __future__ import annotations

import numpy as np

from onboard.offline.closure.effects.base import Context, Effect


class WaterCurrent(Effect):
    """A uniform current ``(north, east)`` (m/s) in the lateral and along-track channels."""

    name = "water_current"
    params = ("north", "east")

    def columns(self, ds, ctx: Context):
        c, s = np.cos(ds.psi), np.sin(ds.psi)
        cols = {"lateral": np.column_stack([-s, c])}
        if ds.has_commands:
            cols["along"] = np.column_stack([ctx.a * c - ds.r * s, ctx.a * s + ds.r * c])
        elif ds.u_model is not None:
            cols["along"] = np.column_stack([c, s])
        return cols

    def along_output(self, theta, ds, ctx):
        return theta[0] * np.cos(ds.psi) + theta[1] * np.sin(ds.psi)


EFFECT = WaterCurrent()
