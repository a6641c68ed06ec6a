"""``gps_latency``: GNSS position and velocity arrive ``seconds`` late.

The measured velocity over ground is the true one ``tau`` seconds ago: ``v(t - tau) ~
v(t) - tau v'(t)``. Projected on the (prompt) heading, a turn gives ``-tau U r`` across
the heading, which alone looks like sideslip; but the lag also shows along the heading
during speed changes: the measured speed answers a command ``tau`` late, so in the
derivative-form surge channel ``U' = -a U + b c(t - tau) ~ ... - tau b c'``, which sideslip
does not.
"""

from __future__ import annotations

import numpy as np

from onboard.closure.dataset import _smooth
from onboard.closure.effects.base import Effect, speed


class GpsLatency(Effect):
    name = "gps_latency"
    params = ("seconds",)

    def columns(self, ds, ctx):
        cols = {"lateral": (-speed(ds) * ds.r)[:, None]}
        if ds.has_commands:
            win = max(5, int(round(1.0 / ds.dt)) | 1)
            cmd_dot = _smooth(np.nan_to_num(ds.cmd_surge), win, 1, ds.dt)
            cols["along"] = (-ctx.b * cmd_dot)[:, None]
        return cols

    def output_delay_s(self, theta):
        return float(theta[0])

    def physical(self, theta):
        return bool(theta[0] > 0.0)


EFFECT = GpsLatency()
