"""The accelerometer's measure of the path acceleration, integrated for short forecasts.

Between two GNSS fixes the track of :mod:`onboard.estimators.reconstruction` predicts
the path speed. A first-order model (algorithms.md §1.1) cannot follow what it
does not contain (waves moving the boat at the wave period, a wrong thrust map); the
IMU measures the acceleration itself. This module turns the body specific force into
the derivative of the signed path speed and integrates it, so a forecast over ``tau``
seconds is ``v(t0) + dV - b tau`` (standard GNSS/INS aiding in one dimension, with the
accelerometer bias ``b`` a slow state estimated against the filtered speed).

Per IMU sample (body FRD, specific force ``f`` in m/s^2, rates in rad/s):

* gravity removed with the attitude (roll ``phi``, pitch ``theta``): ``f = a - R^T g``
  gives ``a_x = f_x - g sin(theta)``, ``a_y = f_y + g sin(phi) cos(theta)``. The roll and
  pitch are the newest AHRS values propagated to the IMU sample with its own gyro
  (Euler-angle rates), since a wave pitches the hull at its period: at 10 Hz attitude a
  held pitch misses up to 0.1 s of it, ``g`` times that (0.24 m/s^2 in ``effect-waves``);
* projected on the direction of travel: the signed path speed ``s = +-|v|`` has
  ``ds/dt = a_x cos(beta) + a_y sin(beta)``, ``beta`` the crab angle (course over ground
  minus heading, folded into (-pi/2, pi/2] when going astern);
* integrated with the acceleration held from one sample to the next: cumulative speed
  ``V`` and path ``S`` at each sample, queried between any two times.

A sample without a recent attitude (older than ``max_attitude_age_s``) or after a silence
longer than ``max_gap_s`` starts the integral afresh: queries across the break return
None and the caller falls back to its model.

:class:`ForecastBlend` weighs this forecast against the model's by their misses of the
same measurements (the GNSS Doppler speed at each filter step).
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_right

from mypy_extensions import mypyc_attr

GRAVITY = 9.80665
"""Standard gravity (m/s^2)."""


@mypyc_attr(allow_interpreted_subclasses=True)
class PathAccelerometer:
    """Integrated path acceleration from IMU and attitude samples (see the module doc).

    Attributes:
        bias: estimated accelerometer bias along the path (m/s^2), subtracted from the
            measured acceleration; updated by :meth:`update_bias`.
        bias_var: running mean square of the per-step bias observations around
            ``bias`` ((m/s^2)^2): the measured acceleration's error over a step, used as
            the forecast's noise.
        n_samples: IMU samples integrated; ``n_breaks``: integrals restarted.
    """

    __slots__ = ("gravity", "keep_s", "max_gap_s", "max_attitude_age_s", "bias",
                 "bias_var", "bias_gain", "n_samples", "n_breaks", "_t", "_V", "_S", "_a",
                 "_roll", "_pitch", "_t_att", "_cb", "_sb", "_t_last", "_bias_n")

    def __init__(self, keep_s: float = 6.0, max_gap_s: float = 0.5,
                 max_attitude_age_s: float = 0.5, bias_gain: float = 0.005,
                 gravity: float = GRAVITY) -> None:
        """Args:
            keep_s: history kept for queries (s); longer spans return None.
            max_gap_s: a longer silence between IMU samples breaks the integral (s).
            max_attitude_age_s: an attitude older than this is not used (s).
            bias_gain: weight of the newest bias observation (one per filter step).
            gravity: local gravity (m/s^2).
        """
        self.gravity = gravity
        self.keep_s = keep_s
        self.max_gap_s = max_gap_s
        self.max_attitude_age_s = max_attitude_age_s
        self.bias_gain = bias_gain
        self.bias = 0.0
        self.bias_var = 0.0
        self._bias_n = 0
        self.n_samples = 0
        self.n_breaks = 0
        # flat arrays of doubles: a copy of the pipeline (the forks of
        # onboard.engine.latency.FixedLagQueue) copies them as memory blocks
        self._t = array("d")
        self._V = array("d")
        self._S = array("d")
        self._a = array("d")
        self._roll = self._pitch = 0.0
        self._t_att = -math.inf
        self._cb, self._sb = 1.0, 0.0  # cos, sin of the crab angle
        self._t_last = -math.inf

    def attitude(self, t: float, roll: float, pitch: float) -> None:
        """An AHRS attitude at ``t`` (s): roll and pitch (rad)."""
        self._roll, self._pitch, self._t_att = roll, pitch, t

    def crab(self, beta: float) -> None:
        """The crab angle (rad): course over ground minus heading, any value; folded
        into (-pi/2, pi/2] (astern: the path speed is negative)."""
        b = math.remainder(beta, math.pi)
        b = b if math.isfinite(b) else 0.0
        self._cb, self._sb = math.cos(b), math.sin(b)

    def add(self, t: float, fx: float, fy: float, p: float, q: float, r: float) -> bool:
        """One IMU sample at ``t`` (s): specific force ``fx``, ``fy`` (m/s^2) and body
        rates ``p``, ``q``, ``r`` (rad/s), FRD. Returns False (integral broken) when no
        attitude is recent enough or the sample is not finite (their sum is not: NaN and
        infinities propagate through it, and only values beyond 1e307, far outside the
        engine's bounds, could overflow it)."""
        t_att = self._t_att
        if not (t - t_att <= self.max_attitude_age_s and math.isfinite(fx + fy + p + q + r)):
            self._break()
            return False
        # attitude propagated from its time to t with the gyro (ZYX Euler rates)
        dt_a = t - t_att
        phi, th = self._roll, self._pitch
        if dt_a > 0.0:
            sp, cp = math.sin(phi), math.cos(phi)
            ct = math.cos(th)
            tt = math.sin(th) / ct if abs(ct) > 1e-3 else 0.0
            phi += (p + (q * sp + r * cp) * tt) * dt_a
            th += (q * cp - r * sp) * dt_a
            self._roll, self._pitch, self._t_att = phi, th, t
        g = self.gravity
        ax = fx - g * math.sin(th)
        ay = fy + g * math.sin(phi) * math.cos(th)
        a = ax * self._cb + ay * self._sb
        ts, V, S, acc = self._t, self._V, self._S, self._a
        t_last = self._t_last
        if not ts or t - t_last > self.max_gap_s:
            if ts:
                self._break()
            ts.append(t)
            V.append(0.0)
            S.append(0.0)
            acc.append(a)
        elif t > t_last:
            dt = t - t_last
            a0, V0 = acc[-1], V[-1]
            ts.append(t)
            V.append(V0 + a0 * dt)
            S.append(S[-1] + V0 * dt + 0.5 * a0 * dt * dt)
            acc.append(a)
            if t - ts[0] > self.keep_s + 2.0:
                cut = bisect_right(ts, t - self.keep_s)
                del ts[:cut], V[:cut], S[:cut], acc[:cut]
        else:   # same time stamp: the newer reading
            acc[-1] = a
        self._t_last = t
        self.n_samples += 1
        return True

    def _break(self) -> None:
        if self._t:
            self.n_breaks += 1
        del self._t[:], self._V[:], self._S[:], self._a[:]

    def _at(self, t: float) -> tuple[float, float] | None:
        """Cumulative ``(V, S)`` at ``t`` (acceleration held after each sample, up to
        ``max_gap_s`` past the newest); None outside the integral."""
        ts = self._t
        if not ts or t < ts[0] or t > ts[-1] + self.max_gap_s:
            return None
        i = bisect_right(ts, t) - 1
        h = t - ts[i]
        a, V = self._a[i], self._V[i]
        return V + a * h, self._S[i] + V * h + 0.5 * a * h * h

    def delta(self, t0: float, t1: float) -> tuple[float, float] | None:
        """``(dv, ds)`` from ``t0`` to ``t1`` (s), bias removed: the speed change (m/s)
        and the path beyond ``v(t0) (t1 - t0)`` (m), i.e. ``v(t1) = v(t0) + dv`` and
        ``s(t1) - s(t0) = v(t0) (t1 - t0) + ds``. None if the integral does not cover
        both times."""
        p0, p1 = self._at(t0), self._at(t1)
        if p0 is None or p1 is None:
            return None
        tau = t1 - t0
        dv = p1[0] - p0[0] - self.bias * tau
        ds = p1[1] - p0[1] - p0[0] * tau - 0.5 * self.bias * tau * tau
        return dv, ds

    def update_bias(self, t0: float, t1: float, dv_filtered: float) -> None:
        """One bias observation: the filtered speed changed by ``dv_filtered`` (m/s) from
        ``t0`` to ``t1`` (s) while the accelerometer integrated ``dv``; their difference
        over the time is the bias left (m/s^2). Running mean with ``bias_gain`` (faster
        for the first ``1 / bias_gain`` steps); its mean square spread in ``bias_var``."""
        tau = t1 - t0
        d = self.delta(t0, t1)
        if d is None or tau <= 1e-3:
            return
        e = (d[0] - dv_filtered) / tau
        if not math.isfinite(e):
            return
        self._bias_n += 1
        g = max(self.bias_gain, 1.0 / self._bias_n)
        self.bias += g * e
        self.bias_var += g * (e * e - self.bias_var)


@mypyc_attr(allow_interpreted_subclasses=True)
class ForecastBlend:
    """The weight of two forecasts of one quantity that minimises the mean square error
    of their combination ``w f_imu + (1 - w) f_model``, learned from their misses of the
    same measurements.

    With misses ``e_m``, ``e_i`` (forecast minus measurement; the measurement's noise and
    the common starting error are in both) the optimal weight of the second is
    ``w = (E[e_m^2] - E[e_m e_i]) / (E[e_m^2] + E[e_i^2] - 2 E[e_m e_i])``: the common
    parts cancel, so only the forecasts' own errors and their correlation count. The
    moments are running means (weight ``gain``, faster over the first ``1 / gain``
    misses); before ``min_n`` misses the weight is ``w0``.

    Attributes:
        w: the current weight of the second forecast, in [0, 1].
        n: misses seen.
    """

    __slots__ = ("gain", "min_n", "w0", "w", "n", "_mm", "_ii", "_mi")

    def __init__(self, gain: float = 0.01, min_n: int = 20, w0: float = 1.0) -> None:
        """Args:
            gain: weight of the newest miss in the running moments.
            min_n: misses before the weight is learned.
            w0: the weight until then.
        """
        self.gain = gain
        self.min_n = min_n
        self.w0 = w0
        self.w = w0
        self.n = 0
        self._mm = self._ii = self._mi = 0.0

    def add(self, e_model: float, e_imu: float) -> None:
        """One pair of misses (same unit, e.g. m/s) of the same measurement."""
        if not (math.isfinite(e_model) and math.isfinite(e_imu)):
            return
        self.n += 1
        g = max(self.gain, 1.0 / self.n)
        self._mm += g * (e_model * e_model - self._mm)
        self._ii += g * (e_imu * e_imu - self._ii)
        self._mi += g * (e_model * e_imu - self._mi)
        if self.n < self.min_n:
            return
        den = self._mm + self._ii - 2.0 * self._mi
        if den <= 1e-12:
            self.w = self.w0
            return
        w = (self._mm - self._mi) / den
        self.w = 0.0 if w < 0.0 else 1.0 if w > 1.0 else w
