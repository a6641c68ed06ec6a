"""Trajectory reconstruction from the estimated increments, and its uncertainty.

algorithms.md §2.11 (the seed paper's §3.3 evaluation). The heading is rebuilt from the
heading filter's increments (:class:`HeadingTrack`), the position from the surge filter's
path increments laid along the mid-step heading (:class:`PositionTrack`)::

    psi <- psi + d_psi                      (then: the measured point minus its noise)
    N   <- N + d_s cos(psi_mid),   E <- E + d_s sin(psi_mid)

The common mode of the increments is unobservable, so the position is pulled toward the
GNSS point by a small fixed gain (the anchor), and the heading comes out as the measured
point minus the filter's estimate of that point's noise (with the MA(1) noise model) or
is pulled toward it by ``heading_anchor``.

Position variance per axis (m^2), first order, cross-covariances between steps and
between north and east neglected, kept at the last surge step:

* the step's increment adds ``P_dd`` (the surge filter's increment variance after its
  update) along the mid-step heading and ``d_s^2 var(psi)`` across it;
* model error (sideslip in turns, a wrong thrust map: errors correlated over many steps)
  is not in those covariances, so the predicted variance is raised to what the anchor
  residuals show when larger: ``mean(r^2) - R`` (``r`` the point minus the reconstructed
  position, per axis, a running mean over about 20 steps, ``R`` the point's noise);
* the anchor's fixed-gain blend with the point: ``var <- (1 - k)^2 var + k^2 R``.

The published sigma adds the prediction to the tick and the whole one-fix variance
``sigma_p^2`` (:func:`position_std`): the fix error is mostly slowly varying (receiver
drift), which the anchor passes unaveraged.
"""

from __future__ import annotations

import math

from mypy_extensions import mypyc_attr

from onboard.core.geo import wrap_pi
from onboard.estimators.kalman import IncrementKF

ANCHOR_RESIDUAL_GAIN = 0.05
"""Weight of the newest anchor residual in its running mean square (about 20 steps)."""


@mypyc_attr(allow_interpreted_subclasses=True)
class HeadingTrack:
    """The reconstructed heading (§2.11).

    Attributes:
        psi: heading (rad, unwrapped) at :attr:`t`; None before the first point.
        t: time (s) of the last heading step; None before the first point.
        var: its variance (rad^2).
    """

    def __init__(self, var0: float) -> None:
        self.psi: float | None = None
        self.t: float | None = None
        self.var = var0

    def restart(self, t: float, psi: float, R: float) -> None:
        """(Re)start at the measured point ``psi`` (rad) of noise variance ``R``."""
        self.psi = psi
        self.t = t
        self.var = R

    def step(self, t: float, psi_meas: float, R: float, kf: IncrementKF, anchor: float,
             psi_prev: float) -> None:
        """Integrate the filter's increment to the point at ``t`` (s). With the MA(1)
        noise model the result is the measured point ``psi_meas`` minus its estimated
        noise ``n_hat = y - d + e`` (the ``e`` state makes the absolute heading
        observable), of variance ``P_dd - 2 P_de + P_ee``; with white increments it is
        pulled toward the point by ``anchor``. ``psi_prev``: the previous point, used
        if no heading has been reconstructed."""
        pred = (self.psi if self.psi is not None else psi_prev) + kf.d
        n_hat = kf.point_noise()
        if n_hat is not None:
            self.psi = pred + wrap_pi(psi_meas - n_hat - pred)
            P = kf.P
            self.var = P[0] - 2.0 * P[2] + P[5]
        else:
            self.psi = pred + anchor * wrap_pi(psi_meas - pred)
            self.var = (1.0 - anchor) ** 2 * (self.var + kf.P[0]) + anchor * anchor * R
        self.t = t


@mypyc_attr(allow_interpreted_subclasses=True)
class PositionTrack:
    """The reconstructed position (§2.11), north/east (m) in the local frame.

    Attributes:
        n, e: position at :attr:`t` (m); have: True once a point has set it.
        t: time (s) of the last surge step; None before the first point.
        var_n, var_e: its variance per axis (m^2), before the one-fix variance.
    """

    def __init__(self) -> None:
        self.n = self.e = 0.0
        self.t: float | None = None
        self.have = False
        self.var_n = self.var_e = 0.0
        self._r2n = self._r2e = 0.0   # running mean square anchor residual less R (m^2)

    def restart(self, t: float, n: float, e: float, R: float) -> None:
        """Start at the point ``(n, e)`` of noise variance ``R`` (m^2)."""
        self.n, self.e = n, e
        self.var_n = self.var_e = R
        self.have = True
        self.t = t

    def follow(self, t: float, dn: float, de: float, var: float) -> None:
        """Across a gap: follow the measured displacement ``(dn, de)`` (m) of variance
        ``var`` (both points' noise)."""
        self.n += dn
        self.e += de
        self.var_n += var
        self.var_e += var
        self.t = t

    def step(self, t: float, d: float, mid: float, var_d: float, var_mid: float,
             point: tuple[float, float], R: float, anchor: float) -> None:
        """One surge step to ``t`` (s): the increment ``d`` (m, variance ``var_d``) along
        the mid-step heading ``mid`` (rad, variance ``var_mid``), then the anchor gain
        ``anchor`` toward ``point`` (m) of noise variance ``R`` (m^2)."""
        c, s = math.cos(mid), math.sin(mid)
        self.n += d * c
        self.e += d * s
        rn, re = point[0] - self.n, point[1] - self.e
        g = ANCHOR_RESIDUAL_GAIN
        self._r2n += g * (rn * rn - R - self._r2n)
        self._r2e += g * (re * re - R - self._r2e)
        self.n += anchor * rn
        self.e += anchor * re
        var_x = d * d * var_mid
        vn = self.var_n + c * c * var_d + s * s * var_x
        ve = self.var_e + s * s * var_d + c * c * var_x
        keep = (1.0 - anchor) ** 2
        blend = anchor * anchor * R
        self.var_n = keep * (vn if vn > self._r2n else self._r2n) + blend
        self.var_e = keep * (ve if ve > self._r2e else self._r2e) + blend
        self.t = t


def position_std(var_n: float, var_e: float, c: float, s: float, var_along: float,
                 var_across: float, var_point: float) -> tuple[float, float]:
    """One sigma (m) north and east of a position predicted along the heading ``(c, s)``
    = ``(cos, sin)`` from a reconstructed one of variances ``var_n``, ``var_e``: the
    prediction's variance ``var_along`` along the heading and ``var_across`` across it,
    plus ``var_point`` on each axis (the fix's own variance and what a held position
    has not followed)."""
    cc, ss = c * c, s * s
    return (math.sqrt(var_n + cc * var_along + ss * var_across + var_point),
            math.sqrt(var_e + ss * var_along + cc * var_across + var_point))
