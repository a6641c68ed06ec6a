"""``quadratic_drag``: hull resistance grows with the square of speed, ``-d U|U|`` in the
surge equation (d in 1/m). At planing or displacement speeds of a small boat it dominates
the linear term."""

from __future__ import annotations

from onboard.offline.closure.effects.base import Effect


class QuadraticDrag(Effect):
    """The surge term ``-d U|U|`` (``d`` in 1/m)."""

    name = "quadratic_drag"
    params = ("d",)
    needs_commands = True
    dynamic = True

    def columns(self, ds, ctx):
        u = ds.along_s
        return {"along": (-u * abs(u))[:, None]}

    def surge_terms(self, theta, ds):
        return None, None, float(theta[0])

    def physical(self, theta):
        return bool(theta[0] > 0.0)


EFFECT = QuadraticDrag()
