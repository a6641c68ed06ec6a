"""Dead reckoning of a surface vehicle's position through a GNSS gap, with its covariance.

Used by :mod:`onboard.estimators.reconstruction` when no fix has arrived for longer than
``max_gap_s``: the position is propagated with the surge filter's speed (model of
algorithms.md §1.1, ZOH §1.2, input held at the filter's estimate) along the heading
filter's heading (the compass keeps running), the paper's §3.3 reconstruction without
the GNSS increments::

    ds = c1 v + c2 u,   v+ = alpha v + c1 u,   N += ds cos(psi_mid),  E += ds sin(psi_mid)

Uncertainty, per axis (m^2), first order in the errors:

* a speed *bias* ``b`` (m/s), constant over the gap, std ``sigma_b``: the error
  ``b * T`` with ``T = sum(dt (cos psi_mid, sin psi_mid))`` (s), so a vehicle that turns
  back cancels part of it, as a real bias does;
* a heading *bias* ``h`` (rad), std ``sigma_psi``: the error ``h * rot90(D)`` with
  ``D = sum(ds (cos, sin))`` the dead-reckoned displacement (m);
* white parts per step: the filter's forecast variance of the increment
  ``c1^2 P_vv + c2^2 V_u`` along the step and ``ds^2 var_psi_white`` across it.

No fix is used here; when the fixes return the pipeline restarts its increment chain.
"""

from __future__ import annotations

import math

from onboard.estimators.axis_model import Discrete


class DeadReckoner:
    """Position and speed propagated without fixes, and their variances.

    Attributes:
        t: time of the state (s).
        n, e: position north/east (m).
        v: speed (m/s); ``p_vv`` its variance ((m/s)^2).
        var_n0, var_e0: position variance at the start of the gap (m^2).
        sigma_b: std of the speed bias over the gap (m/s).
        sigma_psi: std of the heading bias over the gap (rad).
    """

    __slots__ = ("t", "n", "e", "v", "p_vv", "var_n0", "var_e0", "sigma_b", "sigma_psi",
                 "_tn", "_te", "_dn", "_de", "_wn", "_we")

    def __init__(self, t: float, n: float, e: float, v: float, p_vv: float,
                 var_n: float, var_e: float, sigma_b: float, sigma_psi: float) -> None:
        self.t, self.n, self.e, self.v, self.p_vv = t, n, e, v, p_vv
        self.var_n0, self.var_e0 = var_n, var_e
        self.sigma_b, self.sigma_psi = sigma_b, sigma_psi
        self._tn = self._te = 0.0     # sum dt (cos, sin) (s)
        self._dn = self._de = 0.0     # sum ds (cos, sin) (m)
        self._wn = self._we = 0.0     # white variance (m^2)

    def advance(self, k: Discrete, u: float, psi_mid: float, V_u: float) -> None:
        """Propagate over ``k.dt`` with input ``u`` (m/s^2, error variance ``V_u``)
        along the mid-step heading ``psi_mid`` (rad)."""
        ds = k.c1 * self.v + k.c2 * u
        c, s = math.cos(psi_mid), math.sin(psi_mid)
        self.n += ds * c
        self.e += ds * s
        var_a = k.c1 * k.c1 * self.p_vv + k.c2 * k.c2 * V_u
        self._wn += c * c * var_a
        self._we += s * s * var_a
        self._tn += k.dt * c
        self._te += k.dt * s
        self._dn += ds * c
        self._de += ds * s
        self.v = k.alpha * self.v + k.c1 * u
        self.p_vv = k.alpha * k.alpha * self.p_vv + k.c1 * k.c1 * V_u
        self.t += k.dt

    def variances(self) -> tuple[float, float]:
        """``(var_n, var_e)`` (m^2) of the dead-reckoned position at :attr:`t`."""
        b2, h2 = self.sigma_b ** 2, self.sigma_psi ** 2
        vn = self.var_n0 + self._wn + b2 * self._tn ** 2 + h2 * self._de ** 2
        ve = self.var_e0 + self._we + b2 * self._te ** 2 + h2 * self._dn ** 2
        return vn, ve
