"""``surge_yaw_coupling``: the boat slows down in turns, ``-k r^2 U`` in the surge
equation (k in s): the rudder's drag and the sway-yaw Coriolis term grow with the square of
the turn rate."""

from __future__ import annotations

from onboard.offline.closure.effects.base import Effect


class SurgeYawCoupling(Effect):
    """The surge term ``-k r^2 U``: slowing down in turns (``k`` in s)."""

    name = "surge_yaw_coupling"
    params = ("k",)
    needs_commands = True
    dynamic = True

    def columns(self, ds, ctx):
        return {"along": (-ds.r**2 * ds.along_s)[:, None]}

    def surge_terms(self, theta, ds):
        return None, theta[0] * ds.r**2, 0.0

    def physical(self, theta):
        return bool(theta[0] > 0.0)


EFFECT = SurgeYawCoupling()
