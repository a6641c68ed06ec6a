"""``thrust_nonlinearity``: thrust is not proportional to the command.

Two shapes every small-craft propulsor has: a fixed-pitch propeller's thrust grows like
``n |n|`` (the square of the command, ``b2 c|c|``), and it pushes less astern than ahead
(a thruster's reverse thrust is typically 60-80 % of its forward thrust: ``b_rev min(c,
0)``). For a skid-steered boat both are averaged over the two thrusters. Reported:
``quadratic_gain`` ``b2`` and ``reverse_gain`` ``b_rev`` (m/s^2 per unit command), with
``reverse_ratio = (b + b_rev) / b`` once the base gain ``b`` is known.
"""

from __future__ import annotations

import numpy as np

from onboard.offline.closure.effects.base import Effect


class ThrustNonlinearity(Effect):
    """The surge input terms ``b2 c|c| + b_rev min(c, 0)`` (module docstring)."""

    name = "thrust_nonlinearity"
    params = ("quadratic_gain", "reverse_gain")
    needs_commands = True
    dynamic = True

    def columns(self, ds, ctx):
        return {"along": np.column_stack([ds.thrust_quadratic, ds.thrust_reverse])}

    def describe(self, theta, std, base_gain: float | None = None):
        params, sd = super().describe(theta, std)
        if base_gain:
            # The power law c^n closest to (b c + b2 c^2) / (b + b2) over c in (0, 1].
            c = np.linspace(0.05, 1.0, 40)
            shape = (base_gain * c + theta[0] * c * c) / (base_gain + theta[0])
            ok = shape > 0
            if ok.sum() > 5:
                params["exponent"] = float(np.polyfit(np.log(c[ok]), np.log(shape[ok]), 1)[0])
            params["reverse_ratio"] = float((base_gain + theta[1]) / base_gain)
        return params, sd

    def surge_terms(self, theta, ds):
        return theta[0] * ds.thrust_quadratic + theta[1] * ds.thrust_reverse, None, 0.0


EFFECT = ThrustNonlinearity()
