"""``gyro_bias``: a constant offset of the gyro's yaw rate (rad/s).

The measured heading turns at the true rate ``r`` and the gyro reads ``r + bias``, so the
measured heading drifts against the integrated gyro by ``-bias (t - t0)``. Needs a gyro."""

from __future__ import annotations

from onboard.offline.closure.dataset import segment_starts
from onboard.offline.closure.effects.base import Effect


class GyroBias(Effect):
    """The gyro yaw-rate bias, a drift of the heading against the integrated gyro."""

    name = "gyro_bias"
    params = ("bias",)
    needs_gyro = True

    def columns(self, ds, ctx):
        s0 = segment_starts(ds)
        return {"heading": -(ds.t - ds.t[s0])[:, None]}


EFFECT = GyroBias()
