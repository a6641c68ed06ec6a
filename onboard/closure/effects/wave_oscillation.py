"""``wave_oscillation``: first-order wave motion, the orbital velocity of a regular sea.

A long-crested sea of period ``T`` travelling toward ``direction`` moves the water, and a
small boat with it, back and forth along ``direction`` at the phase
``w t - k (N cos(direction) + E sin(direction))`` (``w = 2 pi / T``, deep-water
wavenumber ``k = w^2 / g``): a moving boat meets the crests at the *encounter* frequency,
which changes with its heading and speed. The oscillation is modelled in the earth frame,
``w_n = A_n sin(phase) + B_n cos(phase)`` and ``w_e`` alike (four linear parameters once
period and direction are fixed), and projected on the measured heading for the lateral and
along-track channels. Period and direction come from a search of the residual
(:func:`onboard.closure.select.find_wave`). Without positions, ``k`` is taken as 0.
Reported: ``period`` (s), ``direction`` (rad) and the velocity amplitude (m/s).
"""

from __future__ import annotations

import math

import numpy as np

from onboard.closure.effects.base import Context, Effect

GRAVITY = 9.81


def wave_phase(ds, period_s: float, direction_rad: float) -> np.ndarray:
    """Phase (rad) of a deep-water wave of ``period_s`` toward ``direction_rad`` as seen
    by the vehicle at its measured positions."""
    w = 2.0 * math.pi / period_s
    k = w * w / GRAVITY
    north = np.nan_to_num(ds.north)
    east = np.nan_to_num(ds.east)
    return w * ds.t - k * (north * math.cos(direction_rad) + east * math.sin(direction_rad))


class WaveOscillation(Effect):
    """The orbital velocity of a regular sea at the encounter phase (module docstring);
    the period and direction come from the residual's spectrum."""

    name = "wave_oscillation"
    params = ("n_sin", "n_cos", "e_sin", "e_cos")

    def applies(self, ds, ctx: Context):
        """Only when the residual's spectrum showed a wave period (``ctx.wave_period_s``)."""
        return ctx.wave_period_s is not None

    def _basis(self, ds, ctx):
        ph = wave_phase(ds, ctx.wave_period_s, ctx.extra.get("wave_direction", 0.0))
        return np.sin(ph), np.cos(ph)

    def columns(self, ds, ctx):
        s, c = self._basis(ds, ctx)
        cp, sp = np.cos(ds.psi), np.sin(ds.psi)
        cols = {"lateral": np.column_stack([-sp * s, -sp * c, cp * s, cp * c])}
        if ds.has_commands:
            # along = U + out, out = cos(psi) w_n + sin(psi) w_e; in the derivative-form
            # channel the effect adds out' + a out (phase rate taken as 2 pi / T).
            w = 2.0 * math.pi / ctx.wave_period_s
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
        s, c = self._basis(ds, ctx)
        wn = theta[0] * s + theta[1] * c
        we = theta[2] * s + theta[3] * c
        return np.cos(ds.psi) * wn + np.sin(ds.psi) * we

    def describe(self, theta, std):
        amp = math.sqrt(0.5 * float(np.sum(np.asarray(theta) ** 2)))
        return ({"period": float("nan"), "direction": float("nan"),
                 "velocity_amplitude_mps": math.sqrt(2.0) * amp},
                {"velocity_amplitude_mps": float(np.sqrt(np.mean(np.asarray(std) ** 2)))})


EFFECT = WaveOscillation()
