"""``compass_deviation``: heading error ``amplitude * sin(heading + phase)`` (rad).

Hard- and soft-iron magnetism of the hull gives a heading error that is periodic in the
heading. Writing ``delta = a sin(psi) + b cos(psi)`` (``amplitude = hypot(a, b)``,
``phase = atan2(b, a)``): the vehicle moves along the true heading, so across the
measured heading the velocity is ``-U delta``; and against the integrated gyro the measured heading drifts by
``delta(psi) - delta(psi0)``. It leaves the along-track speed alone, which is what
separates it from a current (whose naive fit would report a false current of several
cm/s).
"""

from __future__ import annotations

import math

import numpy as np

from onboard.offline.closure.dataset import segment_starts
from onboard.offline.closure.effects.base import Context, Effect, speed


class CompassDeviation(Effect):
    """The compass deviation ``a sin(psi) + b cos(psi)`` (module docstring); reported as
    ``amplitude`` and ``phase``."""

    name = "compass_deviation"
    params = ("a", "b")

    def columns(self, ds, ctx: Context):
        c, s = np.cos(ds.psi), np.sin(ds.psi)
        u = speed(ds)
        cols = {"lateral": np.column_stack([-u * s, -u * c])}
        if ds.has_gyro:
            s0 = segment_starts(ds)
            cols["heading"] = np.column_stack([s - s[s0], c - c[s0]])
        return cols

    def describe(self, theta, std):
        a, b = float(theta[0]), float(theta[1])
        amp = math.hypot(a, b)
        sa, sb = float(std[0]), float(std[1])
        amp_std = math.hypot(a * sa, b * sb) / amp if amp > 0 else math.hypot(sa, sb)
        phase_std = math.hypot(b * sa, a * sb) / amp**2 if amp > 0 else math.pi
        return ({"amplitude": amp, "phase": math.atan2(b, a)},
                {"amplitude": amp_std, "phase": phase_std})


EFFECT = CompassDeviation()
