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

AMPLITUDE_MAX_RAD = math.pi / 2.0
"""The largest amplitude (rad) a compass's deviation can have. The hull's hard iron, a
field ``b`` times the earth's horizontal one, turns the needle by ``atan2(b sin(theta),
1 + b cos(theta))``, at most ``arcsin(b)`` while ``b < 1``; at ``b >= 1`` the needle
follows the hull and the error takes every value, no deviation curve at all. A larger
fitted amplitude (the survey boat's 104 deg on its 117 s ``Test6_slow`` run, whose
heading is 100-150 deg off the course) is a heading that is not a compass's, which
``heading_bias`` measures and the replay's ``heading_course_mismatch`` flags: evidence of
that, not of a deviation."""


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

    def physical(self, theta):
        return bool(math.hypot(float(theta[0]), float(theta[1])) <= AMPLITUDE_MAX_RAD)

    def describe(self, theta, std):
        a, b = float(theta[0]), float(theta[1])
        amp = math.hypot(a, b)
        sa, sb = float(std[0]), float(std[1])
        amp_std = math.hypot(a * sa, b * sb) / amp if amp > 0 else math.hypot(sa, sb)
        phase_std = math.hypot(b * sa, a * sb) / amp**2 if amp > 0 else math.pi
        return ({"amplitude": amp, "phase": math.atan2(b, a)},
                {"amplitude": amp_std, "phase": phase_std})


EFFECT = CompassDeviation()
