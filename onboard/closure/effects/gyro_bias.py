"""``gyro_bias``: a constant offset of the gyro's yaw rate (rad/s).

The measured heading turns at the true rate ``r`` and the gyro reads ``r + bias``, so the
heading-rate channel (heading derivative minus gyro) is ``-bias``. Needs a gyro."""

from __future__ import annotations

import numpy as np

from onboard.closure.effects.base import Effect


class GyroBias(Effect):
    name = "gyro_bias"
    params = ("bias",)
    needs_gyro = True

    def columns(self, ds, ctx):
        return {"heading_rate": -np.ones((len(ds), 1))}


EFFECT = GyroBias()
