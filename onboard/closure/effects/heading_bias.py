"""``heading_bias``: a constant heading error (rad), e.g. a misaligned compass or an
uncorrected magnetic declination. Across the measured heading the velocity over ground is
``-U bias`` at every heading; the heading rate is unaffected."""

from __future__ import annotations

import numpy as np

from onboard.closure.effects.base import Effect, speed


class HeadingBias(Effect):
    name = "heading_bias"
    params = ("bias",)

    def columns(self, ds, ctx):
        return {"lateral": -speed(ds)[:, None]}


EFFECT = HeadingBias()
