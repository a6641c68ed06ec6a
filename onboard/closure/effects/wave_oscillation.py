"""``wave_oscillation``: first-order wave motion, an oscillation of the velocity over
ground at the wave encounter period (s), found as the strongest peak of the residual
spectrum.

The orbital velocity of a long-crested sea is along the (fixed) wave direction, so the
oscillation is modelled in the earth frame, ``w_n = A_n sin(w t) + B_n cos(w t)`` and
``w_e`` alike, and projected on the measured heading for the lateral and along-track
channels. Reported: the period and the amplitude of the horizontal oscillation (m/s).
"""

from __future__ import annotations

import math

import numpy as np

from onboard.closure.effects.base import Context, Effect


class WaveOscillation(Effect):
    name = "wave_oscillation"
    params = ("n_sin", "n_cos", "e_sin", "e_cos")

    def applies(self, ds, ctx: Context):
        return ctx.wave_period_s is not None

    def _basis(self, ds, ctx):
        w = 2.0 * math.pi / ctx.wave_period_s
        return w, np.sin(w * ds.t), np.cos(w * ds.t)

    def columns(self, ds, ctx):
        w, s, c = self._basis(ds, ctx)
        cp, sp = np.cos(ds.psi), np.sin(ds.psi)
        cols = {"lateral": np.column_stack([-sp * s, -sp * c, cp * s, cp * c])}
        if ds.has_commands:
            # along = U + out, out = cos(psi) w_n + sin(psi) w_e; in the derivative-form
            # channel the effect adds out' + a out.
            r = ds.r
            ds_, dc = w * c, -w * s
            cols["along"] = np.column_stack([
                cp * ds_ - r * sp * s + ctx.a * cp * s,
                cp * dc - r * sp * c + ctx.a * cp * c,
                sp * ds_ + r * cp * s + ctx.a * sp * s,
                sp * dc + r * cp * c + ctx.a * sp * c,
            ])
        return cols

    def along_output(self, theta, ds, ctx):
        _, s, c = self._basis(ds, ctx)
        wn = theta[0] * s + theta[1] * c
        we = theta[2] * s + theta[3] * c
        return np.cos(ds.psi) * wn + np.sin(ds.psi) * we

    def describe(self, theta, std):
        amp_n = math.hypot(theta[0], theta[1])
        amp_e = math.hypot(theta[2], theta[3])
        amp = math.hypot(amp_n, amp_e)
        return ({"period": float("nan"), "amplitude_mps": amp,
                 "direction": math.atan2(amp_e, amp_n)},
                {"amplitude_mps": float(np.sqrt(np.mean(np.asarray(std) ** 2)))})


EFFECT = WaveOscillation()
