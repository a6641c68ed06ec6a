"""``surge_yaw_coupling``: the boat slows down in turns, ``-k r^2 U`` in the surge
equation (k in s): the rudder's drag and the sway-yaw Coriolis term grow with the square of
the turn rate."""

from __future__ import annotations

from onboard.closure.effects.base import Effect


class SurgeYawCoupling(Effect):
    name = "surge_yaw_coupling"
    params = ("k",)
    needs_commands = True

    def columns(self, ds, ctx):
        return {"along": (-ds.r**2 * ds.along_s)[:, None]}

    def dynamics(self, theta, u, i, ds):
        return -theta[0] * ds.r[i] ** 2 * u


EFFECT = SurgeYawCoupling()
