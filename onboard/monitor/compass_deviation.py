"""Compass deviation learned against course over ground on straight legs.

A magnetic compass near iron and motors errs by an amount that depends on the heading
(its *deviation*; Bowditch, The American Practical Navigator, ch. 6): a constant, a
semicircular term (one cycle per turn, hard iron) and a quadrantal term (two cycles,
soft iron),

    d(psi) = A + B1 sin psi + C1 cos psi + B2 sin 2 psi + C2 cos 2 psi.

On a straight leg the velocity over ground ``v_g`` (speed ``sog``, course ``chi``) less
the current ``(c_n, c_e)`` is the through-water velocity, which points along the
true heading ``psi - d(psi)``: their cross product vanishes. To first order in the
deviation, with ``y = sog sin(psi - chi)`` the ground velocity across the compass
heading and ``u = sog cos(psi - chi)`` along it (m/s),

    y = d(psi) u + c_n sin psi - c_e cos psi + e,

linear in the seven unknowns ``(A, B1, C1, B2, C2, c_n, c_e)`` (the neglected term is
``d`` times the current along the heading: a deviation read a few tens of percent off
in a strong current at low speed, never a current read as a deviation). The deviation's
columns scale with the speed through the water and the current's do not, so the two
separate once the vehicle has held several headings at different speeds (a current's
crab at low speed is large, 20 deg for 0.29 m/s at 0.65 m/s on the simulator's
``effect-current``, and this form holds it exactly); the constant ``A`` also carries any
steady sideslip and a heading bias, so only the harmonic terms are called deviation.

The current is the water the vehicle crosses, and that changes along its track (a
channel's shear, an eddy, a front): it is a random walk of :data:`CURRENT_WALK` from leg
to leg, the deviation a constant. A fit that holds one current for every leg takes the
difference between the water of a lawnmower's northbound and southbound lines for a
deviation (fleet-survey's rudder boats, no deviation simulated: 25-32 deg RMS at a Wald
statistic of 22-79), because the few headings of a lawnmower give the four harmonic
terms as many degrees of freedom as it has kinds of line. With the walk, only headings
changed within a short time (a turn, in nearly the same water) inform the deviation.

:class:`CompassDeviation` is the Kalman filter of the seven unknowns (with no walk, the
least-squares fit of every leg under a Gaussian prior) and reports the harmonic terms
with their covariance, scaled by the innovations' mean NIS where they scatter more than
the legs' assumed noise. Pure Python: seven unknowns, one leg every few seconds.
"""

from __future__ import annotations

import math

UNTIMED_LEG_S = 5.0
"""The time between legs (s) the current walks over when the caller gives no times: the
integrity monitor's leg length."""
N_PARAMS = 7
"""Unknowns: the constant, four harmonic terms, the current's north and east (m/s)."""
HARMONICS = slice(1, 5)
"""The deviation's harmonic terms among the unknowns."""
MIN_LEGS = 12
"""Legs needed before the fit is reported (7 unknowns and the residual's scale)."""
MIN_HEADING_SPREAD = 0.5
"""Least circular spread ``1 - R`` of the legs' headings (R the mean resultant length,
0: one heading, 1: uniform round the circle) for the harmonics to be identifiable."""
MIN_SECTORS = 6
"""Least number of 30-degree heading sectors the legs must cover."""
LEG_NOISE_MPS = 0.02
"""One-sigma (m/s) of a leg's ground velocity across the heading from the sensors' noise
alone (a consumer receiver's Doppler velocity, 0.1 m/s per fix, over 5 s of fixes at
5 Hz); the innovations' mean NIS scales it up when the legs scatter more."""
PRIOR_STD = (0.5, 0.3, 0.3, 0.05, 0.05, 0.5, 0.5)
"""Prior one-sigma of the unknowns (rad; m/s for the current): any constant or
semicircular deviation, a quadrantal one of a few degrees (a small craft's soft iron),
a current up to half a metre per second. The prior keeps a fit over few headings
determined; the data overrule it wherever they speak."""
CURRENT_WALK = 0.003
"""Random walk of the current between legs (m/s per sqrt(s)): 0.05 m/s over five
minutes, the change of a coastal current over a few hundred metres of track (the fleet
field's prior spread of 0.1 m/s over 300 m, docs/algorithms.md §8.3, is 0.08 m/s over a
250-m line). Measured (docs/integrity.md): 0 gives the lawnmowers' false deviations,
0.003 silences them and finds the simulator's deviations on the same legs as without a
walk; at 0.005 ``effect-two``'s is no longer found."""


def _row(psi: float, chi: float, sog: float) -> tuple[tuple[float, ...], float]:
    """One leg's regressors and observation ``y`` (m/s): heading ``psi`` and course
    ``chi`` (rad), speed over ground ``sog`` (m/s)."""
    u = sog * math.cos(psi - chi)
    sp, cp = math.sin(psi), math.cos(psi)
    x = (u, u * sp, u * cp, u * math.sin(2.0 * psi), u * math.cos(2.0 * psi), sp, -cp)
    return x, sog * math.sin(psi - chi)


def solve_spd(a: list[list[float]], b: list[float]) -> tuple[list[float], list[list[float]]]:
    """The solution of ``a x = b`` and the inverse of ``a`` (symmetric positive
    definite, small) by Gauss-Jordan elimination with partial pivoting."""
    n = len(b)
    m = [list(a[i]) + [b[i]] + [1.0 if j == i else 0.0 for j in range(n)]
         for i in range(n)]
    for col in range(n):
        piv = max(range(col, n), key=lambda r: abs(m[r][col]))
        m[col], m[piv] = m[piv], m[col]
        p = m[col][col]
        m[col] = [v / p for v in m[col]]
        for r in range(n):
            if r != col and m[r][col] != 0.0:
                f = m[r][col]
                m[r] = [v - f * w for v, w in zip(m[r], m[col])]
    return [m[i][n] for i in range(n)], [m[i][n + 1:] for i in range(n)]


class CompassDeviation:
    """The deviation and the current from straight legs (module docstring), a Kalman
    filter of ``(A, B1, C1, B2, C2, c_n, c_e)``.

    Attributes:
        legs: legs taken so far.
        theta: the unknowns (rad, rad, ..., m/s), None before :data:`MIN_LEGS` legs over
            :data:`MIN_HEADING_SPREAD` and :data:`MIN_SECTORS`.
        cov: their covariance, None with ``theta``.
        residual_std: the legs' noise across the heading that their innovations show,
            :data:`LEG_NOISE_MPS` times the root of their mean NIS (m/s; the first
            :data:`N_PARAMS` legs, which start the unknowns, left out), None with
            ``theta``.
    """

    def __init__(self) -> None:
        self._x = [0.0] * N_PARAMS
        self._P = [[PRIOR_STD[i] ** 2 if i == j else 0.0 for j in range(N_PARAMS)]
                   for i in range(N_PARAMS)]
        self._t: float | None = None
        self._nis_sum = 0.0
        self._hs = self._hc = 0.0  # sums of the legs' heading unit vectors
        self._sectors: set[int] = set()
        self.legs = 0
        self.theta: list[float] | None = None
        self.cov: list[list[float]] | None = None
        self.residual_std: float | None = None

    def leg(self, psi: float, chi: float, sog: float, t: float | None = None) -> None:
        """One straight leg's circular-mean heading ``psi`` and course ``chi`` (rad), mean
        speed over ground ``sog`` (m/s) and time ``t`` (s; the current walks over the
        time since the previous leg, :data:`UNTIMED_LEG_S` when not given)."""
        dt = UNTIMED_LEG_S if t is None or self._t is None else max(t - self._t, 0.0)
        self._t = t
        self._update(*_row(psi, chi, sog), CURRENT_WALK ** 2 * dt)
        self._hs += math.sin(psi)
        self._hc += math.cos(psi)
        self._sectors.add(int(math.degrees(psi) % 360.0 // 30.0))
        self.legs += 1
        self._publish()

    def _update(self, h: tuple[float, ...], y: float, q: float) -> None:
        """The current's walk ``q`` (m^2/s^2) on its two variances, then the update with
        the leg's row ``h`` and observation ``y`` (noise :data:`LEG_NOISE_MPS`)."""
        x, P = self._x, self._P
        P[5][5] += q
        P[6][6] += q
        ph = [sum(a * b for a, b in zip(row, h)) for row in P]
        s = sum(a * b for a, b in zip(h, ph)) + LEG_NOISE_MPS ** 2
        z = y - sum(a * b for a, b in zip(h, x))
        for i in range(N_PARAMS):
            x[i] += ph[i] * z / s
            row = P[i]
            for j in range(N_PARAMS):
                row[j] -= ph[i] * ph[j] / s
        if self.legs >= N_PARAMS:  # the first legs start the unknowns from their prior
            self._nis_sum += z * z / s

    def spread(self) -> float:
        """The circular spread ``1 - R`` of the legs' headings (0 before any)."""
        if not self.legs:
            return 0.0
        return 1.0 - math.hypot(self._hs, self._hc) / self.legs

    def _publish(self) -> None:
        """``theta`` and ``cov`` from the filter once enough legs round enough headings
        are in; the covariance scaled up by the innovations' mean NIS where it exceeds
        1 (legs that scatter more than :data:`LEG_NOISE_MPS`), both over the legs after
        the first :data:`N_PARAMS`."""
        n = self.legs
        if (n < MIN_LEGS or self.spread() < MIN_HEADING_SPREAD
                or len(self._sectors) < MIN_SECTORS):
            return
        nis = self._nis_sum / (n - N_PARAMS)  # the innovations' mean NIS (_update)
        self.theta = list(self._x)
        self.cov = [[max(1.0, nis) * v for v in row] for row in self._P]
        self.residual_std = LEG_NOISE_MPS * math.sqrt(nis)

    def deviation(self, psi: float) -> float:
        """The harmonic deviation (rad) at heading ``psi`` (rad); 0 before a fit."""
        th = self.theta
        if th is None:
            return 0.0
        return (th[1] * math.sin(psi) + th[2] * math.cos(psi)
                + th[3] * math.sin(2.0 * psi) + th[4] * math.cos(2.0 * psi))

    def rms(self) -> float:
        """The harmonic deviation's RMS over a full turn (rad): ``sqrt(sum of squared
        harmonic terms / 2)``; 0 before a fit."""
        th = self.theta
        if th is None:
            return 0.0
        return math.sqrt(sum(v * v for v in th[HARMONICS]) / 2.0)

    def significance(self) -> float:
        """The Wald statistic of the four harmonic terms, ``h' C^-1 h`` (chi-square with
        4 degrees of freedom when there is no deviation); 0 before a fit."""
        th, cov = self.theta, self.cov
        if th is None or cov is None:
            return 0.0
        idx = range(HARMONICS.start, HARMONICS.stop)
        c = [[cov[i][j] for j in idx] for i in idx]
        h = [th[i] for i in idx]
        try:
            x, _ = solve_spd(c, h)
        except ZeroDivisionError:
            return 0.0
        return sum(a * b for a, b in zip(h, x))
