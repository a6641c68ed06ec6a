"""``thrust_nonlinearity``: propeller thrust grows with the square of the command.

A fixed-pitch propeller gives thrust proportional to ``n |n|``; with the command roughly
proportional to shaft speed the surge equation gains ``b2 c|c|`` (for a skid-steered boat
the mean of ``l|l|`` and ``r|r|``). ``quadratic_fraction`` is ``b2 / (b + b2)``: 0 for a
linear map, 1 for a purely quadratic one."""

from __future__ import annotations

from onboard.closure.effects.base import Effect


class ThrustNonlinearity(Effect):
    name = "thrust_nonlinearity"
    params = ("b2",)
    needs_commands = True

    def columns(self, ds, ctx):
        return {"along": ds.thrust_quadratic[:, None]}

    def dynamics(self, theta, u, i, ds):
        return theta[0] * ds.thrust_quadratic[i]


EFFECT = ThrustNonlinearity()
