"""The Kalman update every filter of the package makes, and the Kalman filter of one surge
or heading axis, shared by AIE and the KF baseline.

**The update** (:func:`update`, filterpy's ``update(x, P, z, R, H)``; Bar-Shalom, Li &
Kirubarajan 2001, section 5.2): for a measurement ``z = H x + v``, ``v ~ N(0, R)``::

    y = z - H x,   S = H P H^T + R,   K = P H^T S^-1,   NIS = y^T S^-1 y
    x+ = x + K y,  P+ = (I - K H) P (I - K H)^T + K R K^T          (Joseph form)

The Joseph form keeps ``P+`` right (and symmetric positive semi-definite) for any gain,
not only the optimal one, so a filter may zero rows of ``K`` (states it must not correct:
a Schmidt-Kalman or consider update, Schmidt 1966; Simon 2006, section 7.5) and still carry the
right covariance. The joint current filter (:mod:`.current_kf`, with the restored-current
twin) and the ESESO (:mod:`.eseso_filter`, an error-state filter: ``x = 0``, ``z`` the
innovation) update through it, and so does :class:`ReferenceIncrementKF`, the matrix
form of the scalar filters below. The high-gain and flow observers are not Kalman
filters: their gains are designed (LMI, pole placement), and a measurement enters their
continuous-time dynamics, not an update (:mod:`.current_hgo`, :mod:`.flow_observer`).

**The axis filter.** algorithms.md §2.2 on the §1.2 model. The seed paper's augmented
state is ``X = [s_k, v_k, s_{k-1}]`` with output ``y = s_k - s_{k-1}``. Its direction
``[1, 0, 1]``
(adding a constant to both path lengths) is unobservable from increments, so the
covariance of the 3-state filter grows without bound along it. In the coordinates
``(d_k, v_k, s_{k-1})`` with ``d_k = s_k - s_{k-1}`` the block ``(d, v)`` evolves on its
own::

    d_{k+1} = c1 v_k + c2 u_k          (c1, c2: ZOH coefficients, §1.2)
    v_{k+1} = alpha v_k + c1 u_k
    y_k     = d_k + noise

and the measurement sees only that block, so the Kalman filter of ``(d, v)`` gives
exactly the same innovations, gains and ``(d, v)`` estimates as the 3-state filter of the
paper (tests/test_kf.py checks this against the 3-state numpy filter) without the
unbounded direction. This module runs that filter with plain floats, its covariance packed
as ``P = [dd, dv, de, vv, ve, ee]``: at 3-4 states a numpy call costs more than the whole
arithmetic. :class:`ReferenceIncrementKF` is the same filter with matrices in numpy, which
the tests compare the scalar filters with.

Sign convention of §2.2: innovation ``z = C x_fc - y``; ``x_da = x_fc - L z``.
"""

from __future__ import annotations

import functools
import math
from typing import Callable, NamedTuple

from mypy_extensions import mypyc_attr
import numpy as np
from numpy.typing import NDArray

from onboard.core.so3 import frozen_eye
from onboard.estimators.axis_model import Discrete

Array = NDArray[np.float64]


def inv_small(S: Array) -> np.ndarray | None:
    """Inverse of a 2x2 or 3x3 matrix (an innovation covariance) by the adjugate, or None
    if it is singular; other sizes by numpy (None if singular). ``np.linalg.inv`` costs
    several µs of call overhead at these sizes."""
    m = len(S)
    if m == 2:
        (a, b), (c, d) = S.tolist()
        det = a * d - b * c
        if det == 0.0:
            return None
        return np.array([[d / det, -b / det], [-c / det, a / det]])
    if m == 3:
        (a, b, c), (d, e, f), (g, h, i) = S.tolist()
        A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
        det = a * A + b * B + c * C
        if det == 0.0:
            return None
        return np.array([[A / det, (c * h - b * i) / det, (b * f - c * e) / det],
                         [B / det, (a * i - c * g) / det, (c * d - a * f) / det],
                         [C / det, (b * g - a * h) / det, (a * e - b * d) / det]])
    try:
        return np.linalg.inv(S)
    except np.linalg.LinAlgError:
        return None


@functools.lru_cache(maxsize=16)
def identity(n: int) -> Array:
    """The ``n`` x ``n`` identity, made once per size (read-only): :func:`update`'s, and a
    measurement noise ``r I`` without ``np.eye``'s call each time."""
    return frozen_eye(n)


class KalmanUpdate(NamedTuple):
    """The outcome of :func:`update`, with filterpy's names."""

    x: Array
    """The updated state ``x + K y`` (the prior ``x`` if ``S`` is singular)."""
    P: Array
    """Its covariance, Joseph form (the prior ``P`` if ``S`` is singular)."""
    y: Array
    """The innovation ``z - H x`` (the measurement's units)."""
    S: Array
    """Its covariance ``H P H^T + R`` (symmetrized with ``symmetric=True``)."""
    K: Array | None
    """The gain used (rows outside ``keep`` zero); None if ``S`` is singular."""
    nis: float
    """The normalized innovation squared ``y^T S^-1 y`` (NaN if ``S`` is singular)."""


def update(x: Array, P: Array, z: Array, R: Array, H: Array, *,
           keep: slice | None = None, symmetric: bool = False,
           inverse: Callable[[Array], Array | None] = inv_small) -> KalmanUpdate:
    """One Kalman update (the module docstring's equations), a pure function.

    Args:
        x, P: the prior state and its covariance (not changed).
        z: the measurement (``m``); for an error-state filter ``x = 0`` and ``z`` the
            innovation ``z_meas - h(x_nominal)``.
        R: its noise covariance (``m`` x ``m``).
        H: the measurement matrix (the Jacobian of ``h``; ``m`` x ``len(x)``).
        keep: the states the update may correct (the other rows of ``K`` are zeroed: a
            Schmidt-Kalman update, the Joseph form keeping ``P`` right for that gain);
            None = all.
        symmetric: replace ``S`` by its symmetric part ``(S + S^T) / 2`` (rounding leaves
            ``H (P H^T)`` asymmetric in its last digits).
        inverse: ``S^-1``, or None when ``S`` is singular (:func:`inv_small`;
            ``np.linalg.inv`` raises ``np.linalg.LinAlgError`` instead).

    The products are evaluated as ``H (P H^T)``, ``(P H^T) S^-1``, ``((I - K H) P) (I -
    K H)^T + (K R) K^T``: the filters' estimates depend on that order in their last
    digits, so it is fixed here.
    """
    y = z - H @ x
    PHt = P @ H.T
    S = H @ PHt + R
    if symmetric:
        S = 0.5 * (S + S.T)
    Sinv = inverse(S)
    if Sinv is None:
        return KalmanUpdate(x, P, y, S, None, math.nan)
    nis = float(y @ Sinv @ y)
    K = PHt @ Sinv
    if keep is not None:
        kept = K[keep].copy()
        K = np.zeros_like(K)
        K[keep] = kept
    IKH = identity(len(x)) - K @ H
    return KalmanUpdate(x + K @ y, IKH @ P @ IKH.T + K @ R @ K.T, y, S, K, nis)

VARIANCE_FLOOR = 1e-300
"""The smallest variance of the rate (and of the input bias) an update leaves, in the
state's squared unit. An update that determines the rate all but exactly (an exact
increment on a rank-one forecast covariance, or a rate measured with ``R_v = 0``)
subtracts two nearly equal numbers, and rounding can leave zero or a tiny negative
variance; the floor keeps ``std_v = sqrt(P_vv)`` defined and the next rate innovation
variance ``P_vv + R_v`` positive. Any variance the filter carries in use is far above it."""


@mypyc_attr(allow_interpreted_subclasses=True)
class IncrementKF:
    """Kalman filter of ``x = (d, v, e)`` for one axis (§2.2), scalar-specialised.

    The increment measured from two noisy points, ``y_k = d_k + n_k - n_{k-1}``, has
    MA(1) noise (§1.3: lag-1 correlation -1/2). With ``correlated=True`` (default) the
    previous point's noise ``e = n_{k-1}`` is a state, ``y_k = d_k - e_k + n_k`` with
    ``C = [1, 0, -1]`` and ``Var(n_k) = R``; after the update ``n_k = y_k - d_k + e_k``
    becomes the next ``e``. This is exact, and equivalent to filtering the cumulative path
    with white noise: the velocity error roughly halves against treating the increments as
    white (the simpler filter, ``correlated=False``, with ``R`` the increment variance).

    A receiver's drift (an error that wanders slowly, the same in consecutive points but
    for its change ``delta`` over the step) adds ``delta`` to the increment: ``y_k = d_k -
    e_k + w_k + delta_k``, ``Var(delta_k) = q`` (:meth:`innovation`'s ``q_drift``), of
    which only the white ``w_k`` is the next step's ``e``. ``S`` takes ``q``; the forecast
    carries the white part of the point's estimated noise ``n = w + delta``: ``w`` and
    ``delta`` enter the data only as their sum, so ``E[w | n] = rho n`` with ``rho = R /
    (R + q)`` and ``Var(w | n) = rho q``: ``e+ = rho n``, its covariances ``rho`` times
    ``n``'s, its variance ``rho^2 Var(n) + rho q``. With ``q = 0`` the drift's changes
    would stay in ``e`` and the innovations would carry the drift accumulated since the
    filter's start (docs/integrity.md, "The receiver's drift in the innovations").

    Attributes (filterpy-style, read them to debug):
        d, v, e: the estimate after :meth:`update` (increment over the last step in m or
            rad; rate in m/s or rad/s; noise of the previous point, m or rad).
        P: covariance, packed ``(dd, dv, de, vv, ve, ee)``, symmetric by construction.
        z: last innovation ``C x_fc - y``; S: its predicted variance; nis: ``z^2 / S``.
        z_v, S_v: the same of the last rate measurement (:meth:`update_rate`).
        Ld, Lv: the gains of ``d`` and ``v`` in the last update.
        R: variance of one point's noise (correlated) or of the increment (white).
        q_drift: variance of the drift's change over the last increment (0: none).
    """

    __slots__ = ("d", "v", "e", "P", "z", "S", "nis", "z_v", "S_v", "Ld", "Lv", "R", "q_v",
                 "q_drift", "correlated", "initialized", "_y", "_skipped")

    def __init__(self, R: float, q_v: float = 0.0, correlated: bool = True) -> None:
        """``R``: measurement variance (see the class doc); ``q_v``: extra rate random
        walk per step (m^2/s^2 or rad^2/s^2)."""
        self.R = R
        self.q_v = q_v
        self.correlated = correlated
        self.d = self.v = self.e = 0.0
        self.P = [0.0] * 6
        self.z = 0.0
        self.S = R
        self.nis = 0.0
        self.z_v = self.S_v = 0.0
        self.Ld = self.Lv = 0.0
        self.q_drift = 0.0
        self.initialized = False
        self._y = 0.0
        self._skipped = False

    @property
    def pvv(self) -> float:
        """Variance of the rate estimate."""
        return self.P[3]

    @pvv.setter
    def pvv(self, value: float) -> None:
        self.P[3] = value

    def init(self, y: float, dt: float, R_prev: float, var_v: float) -> None:
        """Start from a first increment ``y`` over ``dt``: ``v = y/dt`` (variance
        ``var_v``) and the previous point's noise of variance ``R_prev``, then update."""
        self.d, self.v, self.e = y, y / dt, 0.0
        big = 100.0 * (R_prev + self.R) + var_v * dt * dt
        pe = R_prev if self.correlated else 0.0
        self.P = [big, 0.0, 0.0, var_v, 0.0, pe]
        self.initialized = True
        self.innovation(y)
        self.update()

    def forecast(self, k: Discrete, u: float, V_u: float) -> None:
        """Forecast over one step with input ``u`` (m/s^2 or rad/s^2) of error variance
        ``V_u`` (§2.2: ``x_fc = A x_da + B u``, ``P_f = A P A^T + V_u B B^T + Q_w``).

        First the last point's noise ``n = y - d + e`` replaces ``e`` (a linear map of
        the error; its white part where the increment carried a drift, the class doc),
        then ``d+ = c1 v + c2 u``, ``v+ = alpha v + c1 u``, ``e+ = n``.
        """
        c1, c2, al = k.c1, k.c2, k.alpha
        dd, dv, de, vv, ve, ee = self.P
        v = self.v
        if self.correlated and self._skipped:   # last point unused: its noise is prior
            self.e, vn, nn = 0.0, 0.0, self.R
        elif self.correlated:
            self.e = self._y - self.d + self.e
            # error of n = -err(d) + err(e): covariances with v and n
            vn = ve - dv
            nn = dd - 2.0 * de + ee
            q = self.q_drift
            if q > 0.0:   # n = w + delta: its white part w carries
                rho = self.R / (self.R + q)
                self.e *= rho
                vn *= rho
                nn = rho * rho * nn + rho * q
        else:
            self.e = 0.0
            vn = nn = 0.0
        self._skipped = False
        self.d = c1 * v + c2 * u
        self.v = al * v + c1 * u
        self.P = [c1 * c1 * vv + V_u * c2 * c2,
                  c1 * al * vv + V_u * c2 * c1,
                  c1 * vn,
                  al * al * vv + V_u * c1 * c1 + self.q_v,
                  al * vn,
                  nn]

    def innovation(self, y: float, q_drift: float = 0.0) -> float:
        """Set and return ``z = (d - e)_fc - y``, ``S`` and ``nis`` before the update;
        ``q_drift``: the variance of the drift's change over this increment (class doc)."""
        dd, dv, de, vv, ve, ee = self.P
        z = self.d - self.e - y
        S = dd - 2.0 * de + ee + self.R
        if q_drift > 0.0:
            S += q_drift
        self.q_drift = q_drift
        self._y = y
        self.z = z
        self.S = S
        self.nis = z * z / S
        return z

    def point_noise(self) -> float | None:
        """Estimated noise ``n_k = y_k - d_k + e_k`` of the newest point (m or rad) after
        an update in the correlated filter, else None. ``point - n_k`` is then the
        filtered point itself (e.g. the absolute heading)."""
        if not (self.correlated and self.initialized) or self._skipped:
            return None
        return self._y - self.d + self.e

    def skip(self) -> None:
        """Do not assimilate the last measurement (an outlier): keep the forecast."""
        self._skipped = True

    def update(self) -> None:
        """Data assimilation with the innovation of :meth:`innovation` (§2.2),
        ``C = [1, 0, -1]``; Joseph-equivalent for the optimal gain, symmetric storage."""
        dd, dv, de, vv, ve, ee = self.P
        S = self.S
        # P C^T
        cd = dd - de
        cv = dv - ve
        ce = de - ee
        Ld, Lv, Le = cd / S, cv / S, ce / S
        z = self.z
        self.d -= Ld * z
        self.v -= Lv * z
        self.e -= Le * z
        vv_n = vv - Lv * cv
        self.P = [dd - Ld * cd, dv - Ld * cv, de - Ld * ce,
                  vv_n if vv_n > VARIANCE_FLOOR else VARIANCE_FLOOR, ve - Lv * ce, ee - Le * ce]
        self.Ld, self.Lv = Ld, Lv

    def update_rate(self, y_v: float, R_v: float, gate: float = math.inf) -> float:
        """Assimilate a direct measurement of the rate, ``y_v = v + n_v``,
        ``Var(n_v) = R_v`` (GNSS Doppler speed over ground, m/s), after :meth:`update`
        at the same step: a second scalar row ``C_v = [0, 1, 0]`` applied sequentially
        (exact for independent noises). Returns the NIS ``z_v^2 / S_v``; above ``gate``
        the measurement is not used (an outlier) and the state is unchanged.
        """
        dd, dv, de, vv, ve, ee = self.P
        S = self.S_v = vv + R_v
        z = self.z_v = self.v - y_v
        nis = z * z / S
        if not nis <= gate:
            return nis
        Ld, Lv, Le = dv / S, vv / S, ve / S
        self.d -= Ld * z
        self.v -= Lv * z
        self.e -= Le * z
        vv_n = vv - Lv * vv
        self.P = [dd - Ld * dv, dv - Ld * vv, de - Ld * ve,
                  vv_n if vv_n > VARIANCE_FLOOR else VARIANCE_FLOOR, ve - Lv * ve, ee - Le * ve]
        return nis

    def predict_ahead(self, k: Discrete, u: float) -> tuple[float, float]:
        """``(increment, rate)`` ``k.dt`` seconds after the last update with input ``u``
        held (estimates between measurement steps). The state is unchanged."""
        return k.c1 * self.v + k.c2 * u, k.alpha * self.v + k.c1 * u

    def markov(self, k: Discrete, n_f: int) -> list[float]:
        """``H_i = C A_bar^{i-1} B``, ``i = 1..n_f``, ``A_bar = A (I - L C)`` (§2.4),
        on the ``(d, v)`` block with the gains of the last update. ``H_1 = c2``."""
        c1, c2, al = k.c1, k.c2, k.alpha
        out = [c2]
        wd, wv = c2, c1
        Lv = self.Lv
        for _ in range(n_f - 1):
            wd, wv = -c1 * Lv * wd + c1 * wv, -al * Lv * wd + al * wv
            out.append(wd)
        return out

    @property
    def std_v(self) -> float:
        """One-sigma uncertainty of the rate ``v`` (m/s or rad/s), ``sqrt(P_vv)``."""
        return math.sqrt(self.P[3])


@mypyc_attr(allow_interpreted_subclasses=True)
class BiasIncrementKF(IncrementKF):
    """:class:`IncrementKF` with a random-walk input bias ``b`` as a fourth state.

    The classical remedy for a known input that is systematically wrong (the KF
    baseline's nominal thrust map on a boat it does not fit): the forecast input is
    ``u + b``, ``b`` constant but for a random walk of ``q_b`` (m/s^2)^2 per second, and
    the measurements (increment and rate rows) estimate it with the rest of the state::

        d+ = c1 v + c2 (u + b),   v+ = alpha v + c1 (u + b),   e+ = n,   b+ = b + w_b

    ``P`` keeps the packed ``(d, v, e)`` block of the base class; the covariances with
    ``b`` are ``Pb = [P_db, P_vb, P_eb]`` and ``pbb``. Bar the bias this is the base
    filter (tests/test_kf.py checks it reduces to it with ``q_b = 0`` and ``pbb = 0``).

    Attributes (beyond the base class's):
        b: the input bias (m/s^2 or rad/s^2); Pb, pbb: its covariances.
        q_b: its random-walk variance per second ((m/s^2)^2 / s).
    """

    __slots__ = ("b", "Pb", "pbb", "q_b", "pbb0")

    def __init__(self, R: float, q_v: float = 0.0, correlated: bool = True,
                 q_b: float = 0.01, pbb0: float = 1.0) -> None:
        """``R``, ``q_v``, ``correlated``: as :class:`IncrementKF`; ``q_b``: the bias's
        random walk ((m/s^2)^2 per second); ``pbb0``: its variance at the start."""
        super().__init__(R, q_v, correlated)
        self.q_b = q_b
        self.pbb0 = pbb0
        self.b = 0.0
        self.Pb = [0.0, 0.0, 0.0]
        self.pbb = pbb0

    def init(self, y: float, dt: float, R_prev: float, var_v: float) -> None:
        """As :meth:`IncrementKF.init`; the bias restarts at 0 with variance ``pbb0``
        only on the first start (a restart after a gap keeps what was learned)."""
        self.Pb = [0.0, 0.0, 0.0]
        super().init(y, dt, R_prev, var_v)

    def forecast(self, k: Discrete, u: float, V_u: float) -> None:
        """Forecast over one step with input ``u + b`` (see the class doc)."""
        c1, c2, al = k.c1, k.c2, k.alpha
        dd, dv, de, vv, ve, ee = self.P
        db, vb, eb = self.Pb
        bb = self.pbb
        v = self.v
        if self.correlated and self._skipped:
            self.e, vn, nn, bn = 0.0, 0.0, self.R, 0.0
        elif self.correlated:
            self.e = self._y - self.d + self.e
            vn = ve - dv
            nn = dd - 2.0 * de + ee
            bn = eb - db
            q = self.q_drift
            if q > 0.0:   # the white part carries (IncrementKF's doc)
                rho = self.R / (self.R + q)
                self.e *= rho
                vn *= rho
                bn *= rho
                nn = rho * rho * nn + rho * q
        else:
            self.e = 0.0
            vn = nn = bn = 0.0
        self._skipped = False
        ub = u + self.b
        self.d = c1 * v + c2 * ub
        self.v = al * v + c1 * ub
        self.P = [c1 * c1 * vv + 2.0 * c1 * c2 * vb + c2 * c2 * (bb + V_u),
                  c1 * al * vv + (c1 * c1 + c2 * al) * vb + c2 * c1 * (bb + V_u),
                  c1 * vn + c2 * bn,
                  al * al * vv + 2.0 * al * c1 * vb + c1 * c1 * (bb + V_u) + self.q_v,
                  al * vn + c1 * bn,
                  nn]
        self.Pb = [c1 * vb + c2 * bb, al * vb + c1 * bb, bn]
        self.pbb = bb + self.q_b * k.dt

    def _apply(self, pc: tuple[float, float, float, float], S: float, z: float) -> None:
        """``x -= K z``, ``P -= K (P C')^T`` with ``K = P C' / S`` (``pc = P C'``)."""
        cd, cv, ce, cb = pc
        Ld, Lv, Le, Lb = cd / S, cv / S, ce / S, cb / S
        self.d -= Ld * z
        self.v -= Lv * z
        self.e -= Le * z
        self.b -= Lb * z
        dd, dv, de, vv, ve, ee = self.P
        db, vb, eb = self.Pb
        vv_n = vv - Lv * cv
        self.P = [dd - Ld * cd, dv - Ld * cv, de - Ld * ce,
                  vv_n if vv_n > VARIANCE_FLOOR else VARIANCE_FLOOR, ve - Lv * ce, ee - Le * ce]
        self.Pb = [db - Ld * cb, vb - Lv * cb, eb - Le * cb]
        bb_n = self.pbb - Lb * cb
        self.pbb = bb_n if bb_n > VARIANCE_FLOOR else VARIANCE_FLOOR
        self.Ld, self.Lv = Ld, Lv

    def update(self) -> None:
        """Data assimilation of the increment row ``C = [1, 0, -1, 0]`` (§2.2)."""
        dd, dv, de, vv, ve, ee = self.P
        db, vb, eb = self.Pb
        self._apply((dd - de, dv - ve, de - ee, db - eb), self.S, self.z)

    def update_rate(self, y_v: float, R_v: float, gate: float = math.inf) -> float:
        """The measured rate, row ``C_v = [0, 1, 0, 0]`` (as the base class)."""
        dd, dv, de, vv, ve, ee = self.P
        S = self.S_v = vv + R_v
        z = self.z_v = self.v - y_v
        nis = z * z / S
        if not nis <= gate:
            return nis
        self._apply((dv, vv, ve, self.Pb[1]), S, z)
        return nis


@mypyc_attr(allow_interpreted_subclasses=True)
class ReferenceIncrementKF:
    """:class:`IncrementKF` (``bias=False``) and :class:`BiasIncrementKF` (``bias=True``)
    in numpy, the class docs' equations as matrices on ``x = [d, v, e(, b)]``, updated
    by :func:`update`; the scalar filters are this one unrolled (tests/test_kf.py
    compares them step by step).

    An increment with a drift (``q_drift > 0``) is taken the long way, without the
    scalar filters' split: the new point's white noise ``w`` is a further state (prior
    ``N(0, R)``) from the innovation through the updates, the increment row ``[1, 0, -1(,
    0), 1]`` of noise ``q_drift``, and the forecast makes ``w`` the next ``e``.

    Attributes: ``x``, ``P`` (full matrix), ``z``, ``S``, ``nis`` as the scalar filters';
    ``y`` the last increment and ``skipped`` whether it was used; ``aug`` the state and
    covariance with ``w`` between an innovation with a drift and the next forecast (None
    otherwise).
    """

    def __init__(self, R: float, q_v: float = 0.0, correlated: bool = True,
                 bias: bool = False, q_b: float = 0.0) -> None:
        """As :class:`BiasIncrementKF` (``q_b`` unused without ``bias``)."""
        self.n = 4 if bias else 3
        self.R, self.q_v, self.q_b, self.correlated = R, q_v, q_b, correlated
        self.x, self.P = np.zeros(self.n), np.zeros((self.n, self.n))
        self.y, self.skipped = 0.0, False
        self.z = self.S = self.nis = 0.0
        self.q_drift = 0.0
        self.aug: tuple[np.ndarray, np.ndarray] | None = None

    def forecast(self, k: Discrete, u: float, V_u: float) -> None:
        """``e <- n = y - d + e`` (map ``M``), or ``e <- w`` after an increment with a
        drift, then ``x+ = F x + G u``, ``P+ = F M P M^T F^T + V_u G G^T + Q``."""
        n, E = self.n, 2
        M = np.eye(n)
        x, P = self.x.copy(), self.P.copy()
        if self.correlated and not self.skipped and self.aug is not None:
            xa, Pa = self.aug                             # [x, w]: w becomes e
            x, P = xa[:n].copy(), Pa[:n, :n].copy()
            x[E] = xa[n]
            P[E, :], P[:, E] = Pa[n, :n], Pa[:n, n]
            P[E, E] = Pa[n, n]
        elif self.correlated and not self.skipped:
            M[E, 0] = -1.0                                # err(n) = err(e) - err(d)
            x[E] = self.y - x[0] + x[E]                   # n = y - d + e
            P = M @ P @ M.T
        else:                                             # the point's noise is prior
            x[E] = 0.0
            P[E, :] = P[:, E] = 0.0
            P[E, E] = self.R if self.correlated else 0.0
        self.aug = None
        F = np.zeros((n, n))
        F[0, 1], F[1, 1], F[E, E] = k.c1, k.alpha, 1.0    # d+ = c1 v, v+ = alpha v, e+ = n
        G = np.zeros(n)
        G[0], G[1] = k.c2, k.c1                           # + (c2, c1) (u + b)
        Q = np.zeros((n, n))
        Q[1, 1] = self.q_v
        if n == 4:
            F[0, 3], F[1, 3], F[3, 3] = k.c2, k.c1, 1.0   # b+ = b
            Q[3, 3] = self.q_b * k.dt
        self.x = F @ x + G * u
        self.P = F @ P @ F.T + V_u * np.outer(G, G) + Q
        self.skipped = False

    def _row(self) -> np.ndarray:
        """The increment row on ``x`` (``[1, 0, -1(, 0)]``), or on ``[x, w]`` with a
        drift (``w``'s coefficient 1)."""
        C = np.zeros(self.n + (self.aug is not None))
        C[0], C[2] = 1.0, -1.0
        if self.aug is not None:
            C[self.n] = 1.0
        return C

    def innovation(self, y: float, q_drift: float = 0.0) -> float:
        """``z = C x - y``, ``S = C P C^T + R + q_drift``; with a drift on the correlated
        filter, ``C`` and ``P`` of ``[x, w]`` and ``S = C P C^T + q_drift``."""
        self.y, self.q_drift = y, q_drift
        x, P, R = self.x, self.P, self.R + q_drift
        if self.correlated and q_drift > 0.0:
            x = np.append(self.x, 0.0)
            P = np.zeros((self.n + 1, self.n + 1))
            P[:self.n, :self.n], P[self.n, self.n] = self.P, self.R
            self.aug, R = (x, P), q_drift
        C = self._row()
        self.z = float(C @ x - y)
        self.S = float(C @ P @ C + R)
        self.nis = self.z * self.z / self.S
        return self.z

    def update(self) -> None:
        """The increment row (:meth:`_row`) through :func:`update` (``x + K (y - C x) =
        x - K z``)."""
        self._apply(self._row(), self.y,
                    self.q_drift if self.aug is not None else self.R + self.q_drift)

    def skip(self) -> None:
        """Keep the forecast; the last point's noise is then prior at the next step."""
        self.skipped = True

    def update_rate(self, y_v: float, R_v: float) -> float:
        """The rate row ``C_v = [0, 1, 0(, 0)(, 0)]``, ``Var = R_v``; returns the NIS."""
        C = np.zeros(self.n + (self.aug is not None))
        C[1] = 1.0
        return self._apply(C, y_v, R_v)

    def _apply(self, C: np.ndarray, y: float, R: float) -> float:
        """The scalar row ``y = C x + n``, ``Var(n) = R``, through :func:`update` (Joseph
        form) on ``x`` or ``[x, w]``, then the rate (and bias) variance floored; returns
        the NIS."""
        x, P = self.aug if self.aug is not None else (self.x, self.P)
        up = update(x, P, np.array([y]), np.array([[R]]), C[None, :])
        for i in (1, 3) if self.n == 4 else (1,):
            up.P[i, i] = max(up.P[i, i], VARIANCE_FLOOR)
        if self.aug is not None:
            self.aug = (up.x, up.P)
            self.x, self.P = up.x[:self.n], up.P[:self.n, :self.n]
        else:
            self.x, self.P = up.x, up.P
        return up.nis
