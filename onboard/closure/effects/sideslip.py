"""``sideslip``: the hull slides sideways in turns, ``v = k r`` (k in m, the distance from
the centre of gravity to the pivot point). Shows across the heading only, in proportion
to the yaw rate, with no lag along the heading."""

from __future__ import annotations

from onboard.closure.effects.base import Effect


class Sideslip(Effect):
    name = "sideslip"
    params = ("k_m",)

    def columns(self, ds, ctx):
        return {"lateral": ds.r[:, None]}


EFFECT = Sideslip()
