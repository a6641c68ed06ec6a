"""``sideslip``: a steady crab angle from a side force, ``v = k U|U|`` across the heading.

A side force that grows with the square of speed (a keel or hull asymmetry, a trailing
line, windage on a superstructure: ``F = c u|u|``) pushed against the hull's linear sway
damping gives a sway velocity ``v ~ (c / Y_v) U|U|``: the crab angle grows with speed.
That is what separates it from a ``heading_bias``, whose crab angle is the same at every
speed, and from the hull's own sway in turns (``v = x_p r``), which is in the base model.
Reported: ``k`` (s/m), and the crab angle at 1 m/s, ``k`` rad.
"""

from __future__ import annotations

import numpy as np

from onboard.offline.closure.effects.base import Effect, speed


class Sideslip(Effect):
    """The crab ``v = k U|U|`` from a side force growing with speed (``k`` in s/m)."""

    name = "sideslip"
    params = ("k",)

    def columns(self, ds, ctx):
        u = speed(ds)
        return {"lateral": (u * np.abs(u))[:, None]}


EFFECT = Sideslip()
