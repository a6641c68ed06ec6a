"""The ESESO's compiled kernels: its propagation, its updates and the Python around them
(noise adaptation, gate, injection, thrust and attitude models, published values), in
numba.

The readable reference is :mod:`onboard.estimators.eseso_filter` (algorithms.md §5.1);
these functions compute the same equations on plain loops, compiled by numba, because at
23 states numpy's per-call overhead (~1 µs a call, ~50 calls a propagation and ~30 an
update) costs more than the arithmetic (docs/performance.md, "The ESESO's vehicle-day").
:class:`~onboard.estimators.eseso_filter.EsesoFilter` uses them when this module imports
(:func:`~onboard.estimators.eseso_filter.compiled_kernel`: numba installed, the ``fast``
extra, and ``ONBOARD_ESESO_KERNEL`` not ``0``); tests/test_eseso_kernel.py checks that
kernel and reference agree to rounding.

The nominal state is the filter's one array ``x``
(:data:`~onboard.estimators.eseso_filter.X_P` ...), which the kernels, as ``P``, write in
place: each propagation and each update is one call that returns no array or one.

* :func:`propagate`: :meth:`EsesoFilter.propagate` whole, the nominal state (paper eq.
  10b) and ``F P F^T + diag(q)`` (eq. 13) with ``F`` applied by the blocks of
  :class:`~onboard.estimators.eseso_filter.Transition`, as
  :func:`~onboard.estimators.eseso_filter.propagate_covariance` does.
* :func:`fuse`: :meth:`EsesoFilter.update` but its bookkeeping: the noise adaptation, the
  Kalman update as :func:`onboard.estimators.kalman.update` makes it for the ESESO
  (error state zero, ``S`` symmetrized and inverted, the gain's rows outside ``keep``
  zeroed; :func:`_gain`) with its Joseph form ``(I - K H) P (I - K H)^T + K R K^T``
  evaluated through its rank-``m`` factors (``(I - K H) X = X - K (H X)`` is ``m n^2``
  multiply-adds where the dense product is ``n^3``; :func:`_joseph_into`), the gate, the
  injection of the correction (eq. 16d; :func:`_inject_into`) and the reset ``G P G^T``
  (eq. 17b, Sola eq. 287, ``G`` the identity but for its attitude block
  ``I - [dtheta/2]x``, then symmetrized; :func:`_reset_into`).
* :func:`thrust_update`: :meth:`EsesoFilter.update_thrust` but its bookkeeping: the
  thrust model (:func:`h_tau`, also :meth:`EsesoFilter.h_tau`), the model-change
  variance, the noise, its adaptation, the Huber weight (:func:`mahalanobis`) and the
  update; :func:`learn_excess`, the published disturbance excess it learns.
* :func:`attitude_innovation`: the attitude update's innovation (:func:`log_so3`) and
  noise.
* :func:`estimates`: the ESESO pipeline's published values
  (:meth:`onboard.pipelines.eseso.Eseso.estimates`) in one array; :func:`finite`, its
  divergence test.

Each call costs ~1 µs of numba's dispatch and ~0.3 µs per array it returns, so a kernel
pays where it replaces a dozen numpy calls or more (docs/performance.md, "The Python
around the ESESO's kernels").

Compiled on first call, not at import (~11 s of CPU here, docs/performance.md), and
cached beside this module (``cache=True``), so a machine compiles once; a process then
pays numba's start, ~0.6 s, when the pipeline is made (``eseso_filter.warm_kernels``: each
kernel called once on a throwaway filter, not in a live service's first ticks). Loops
only: numba compiles array expressions, slice assignments and transposed views two to
four times slower, and BLAS's call costs more than these 3- and 23-row products.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# the error-state blocks of eseso_filter (P_, V_, TH, BA, BG, G_, XI, BI), as offsets
_P, _V, _TH, _BA, _BG, _G, _XI, _BI = 0, 3, 6, 9, 12, 15, 18, 21
_N = 23
# the nominal state's entries in the filter's one array (eseso_filter's X_P ... X_BI)
_XP, _XV, _XR, _XBA, _XBG, _XG, _XXI, _XBI = 0, 3, 6, 15, 18, 21, 24, 27
_NX = 29
_SMALL_ANGLE = 1e-6
"""Below this angle (rad) Exp and Jr take their series, as :mod:`onboard.core.so3`."""


@njit(cache=True)
def _mm(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A @ B`` on plain loops (BLAS's call costs more than these small products)."""
    n, m = A.shape[0], B.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for k in range(A.shape[1]):
            a = A[i, k]
            if a != 0.0:
                for j in range(m):
                    out[i, j] += a * B[k, j]
    return out


@njit(cache=True)
def _mmt(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A @ B.T`` on plain loops."""
    n, m = A.shape[0], B.shape[0]
    out = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for k in range(A.shape[1]):
                acc += A[i, k] * B[j, k]
            out[i, j] = acc
    return out


@njit(cache=True)
def _mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A @ x`` on plain loops."""
    out = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            out[i] += A[i, k] * x[k]
    return out


@njit(cache=True)
def _transpose(A: np.ndarray) -> np.ndarray:
    """``A.T``, contiguous."""
    out = np.empty((A.shape[1], A.shape[0]))
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[j, i] = A[i, j]
    return out


@njit(cache=True)
def _scaled(A: np.ndarray, a: float) -> np.ndarray:
    """``a A`` (a new array)."""
    out = np.empty_like(A)
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[i, j] = A[i, j] * a
    return out


@njit(cache=True)
def _sum(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A + B`` (a new array)."""
    out = np.empty_like(A)
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[i, j] = A[i, j] + B[i, j]
    return out


@njit(cache=True)
def _skew(t: np.ndarray) -> np.ndarray:
    """``[t]x`` of a 3-vector."""
    K = np.zeros((3, 3))
    K[0, 1], K[0, 2], K[1, 2] = -t[2], t[1], -t[0]
    K[1, 0], K[2, 0], K[2, 1] = t[2], -t[1], t[0]
    return K


@njit(cache=True)
def _identity_plus(a: float, K: np.ndarray, b: float, K2: np.ndarray) -> np.ndarray:
    """``I + a K + b K2`` of 3 x 3 matrices."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = (1.0 if i == j else 0.0) + a * K[i, j] + b * K2[i, j]
    return out


@njit(cache=True)
def exp_so3(theta: np.ndarray) -> np.ndarray:
    """Rodrigues' formula, as :func:`onboard.core.so3.exp_so3`."""
    angle = math.sqrt(theta[0] ** 2 + theta[1] ** 2 + theta[2] ** 2)
    K = _skew(theta)
    K2 = _mm(K, K)
    if angle < _SMALL_ANGLE:
        return _identity_plus(1.0, K, 0.5, K2)
    s = math.sin(angle) / angle
    c = (1.0 - math.cos(angle)) / (angle * angle)
    return _identity_plus(s, K, c, K2)


_LOG_NEAR_PI = 1e-4
"""Within this of pi (rad) Log takes the axis from the symmetric part, as
:func:`onboard.core.so3.log_so3`."""
_LOG_EPS = 1e-9
"""Floor of the symmetric part's diagonal entry there (:data:`onboard.core.so3._EPS`)."""


@njit(cache=True)
def log_so3(R: np.ndarray) -> np.ndarray:
    """``Log(R)``, as :func:`onboard.core.so3.log_so3`."""
    half = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    cos_a = half if half < 1.0 else 1.0  # Python's max(-1, min(1, half))
    cos_a = cos_a if cos_a > -1.0 else -1.0
    angle = math.acos(cos_a)
    v = np.empty(3)
    v[0], v[1], v[2] = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    out = np.empty(3)
    if angle < _SMALL_ANGLE:
        for k in range(3):
            out[k] = 0.5 * v[k]
        return out
    if math.pi - angle < _LOG_NEAR_PI:  # the axis from the symmetric part, R = 2 a a^T - I
        i = 0
        for k in range(1, 3):
            if 0.5 * (R[k, k] + 1.0) > 0.5 * (R[i, i] + 1.0):
                i = k
        B_ii = 0.5 * (R[i, i] + 1.0)
        root = math.sqrt(_LOG_EPS if _LOG_EPS > B_ii else B_ii)
        a = np.empty(3)
        for k in range(3):
            a[k] = 0.5 * (R[k, i] + (1.0 if k == i else 0.0)) / root
        sign = -1.0 if a[0] * v[0] + a[1] * v[1] + a[2] * v[2] < 0.0 else 1.0
        norm = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        for k in range(3):
            out[k] = angle * (sign * a[k]) / norm
        return out
    c = angle / (2.0 * math.sin(angle))
    for k in range(3):
        out[k] = c * v[k]
    return out


@njit(cache=True)
def attitude_innovation(x, R_meas, roll, pitch, var_roll_pitch, var_yaw):
    """:meth:`EsesoFilter.update_attitude`'s innovation ``Log(R^T R_meas)`` at the
    nominal state ``x`` and its noise ``J diag(var_roll_pitch, var_roll_pitch, var_yaw)
    J^T`` (``J`` the Euler-rate-to-body-rate matrix at ``roll``, ``pitch``)."""
    R = x[_XR:_XR + 9].copy().reshape((3, 3))
    y = log_so3(_mm(_transpose(R), R_meas))
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    J = np.array([[1.0, 0.0, -sp], [0.0, cr, sr * cp], [0.0, -sr, cr * cp]])
    d = np.array([var_roll_pitch, var_roll_pitch, var_yaw])
    Rm = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += J[i, k] * d[k] * J[j, k]
            Rm[i, j] = acc
    return y, Rm


@njit(cache=True)
def right_jacobian(theta: np.ndarray) -> np.ndarray:
    """``Jr(theta)`` of SO(3), as :func:`onboard.core.so3.right_jacobian`."""
    angle = math.sqrt(theta[0] ** 2 + theta[1] ** 2 + theta[2] ** 2)
    K = _skew(theta)
    K2 = _mm(K, K)
    if angle < _SMALL_ANGLE:
        return _identity_plus(-0.5, K, 1.0 / 6.0, K2)
    a2 = angle * angle
    return _identity_plus(-(1.0 - math.cos(angle)) / a2, K,
                          (angle - math.sin(angle)) / (a2 * angle), K2)


@njit(cache=True)
def _rotated_row(M: np.ndarray, i: int, block: int, dRt: np.ndarray, B: np.ndarray,
                 acc: np.ndarray, out: np.ndarray) -> None:
    """Row ``i`` of the block at ``block`` (the attitude's or the earth-fixed
    disturbance's) of ``F M``: ``dR^T M[block] + B M[BG]`` (``acc`` a scratch row)."""
    cols = M.shape[1]
    for j in range(cols):
        acc[j] = 0.0
    for k in range(3):
        a, b = dRt[i, k], B[i, k]
        for j in range(cols):
            acc[j] += a * M[block + k, j] + b * M[_BG + k, j]
    for j in range(cols):
        out[block + i, j] = acc[j]


@njit(cache=True)
def _transition_rows(M: np.ndarray, dt: float, A: np.ndarray, dRt: np.ndarray,
                     th_bg: np.ndarray, xi_bg: np.ndarray, earth_fixed: bool,
                     phi_ins: float, out: np.ndarray) -> None:
    """``out = F M`` for the 23-row ``M`` (``out`` another array): ``A = [R [f]x, R]``
    (3 x 6, what ``F[V, TH:BA]`` is times ``-dt``), the other blocks of
    :class:`Transition` as named there. Row by row, the inner loops along a row."""
    cols = M.shape[1]
    for r in range(M.shape[0]):
        for j in range(cols):
            out[r, j] = M[r, j]
    acc = np.empty(cols)
    for i in range(3):
        for j in range(cols):  # [R [f]x, R] M[TH:BA]
            acc[j] = 0.0
        for k in range(6):
            a = A[i, k]
            for j in range(cols):
                acc[j] += a * M[_TH + k, j]
        for j in range(cols):
            v_new = M[_V + i, j] + dt * (M[_G + i, j] - acc[j])
            out[_P + i, j] += 0.5 * dt * (M[_V + i, j] + v_new)
            out[_V + i, j] = v_new
        _rotated_row(M, i, _TH, dRt, th_bg, acc, out)
        if earth_fixed:
            _rotated_row(M, i, _XI, dRt, xi_bg, acc, out)
    for j in range(cols):
        out[_BI, j] *= phi_ins
        out[_BI + 1, j] *= phi_ins


@njit(cache=True)
def propagate(x, P, x_prev, f_m, w_m, dt, earth_fixed, phi_ins, q) -> None:
    """:meth:`EsesoFilter.propagate` over ``dt`` (s) at the mean specific force ``f_m``
    (m/s^2) and rate ``w_m`` (rad/s), with the process-noise diagonal ``q``: the nominal
    state ``x`` (the filter's one array; the biases and gravity do not change) and the
    covariance ``P`` written in place, the state before it into ``x_prev`` (what the
    transition is built from when read). One call, no array returned."""
    for i in range(_NX):
        x_prev[i] = x[i]
    p, v, R, b_a, b_g, g, xi, b_ins = _unpack(x)
    f, w_dt = np.empty(3), np.empty(3)
    for i in range(3):
        f[i] = f_m[i] - b_a[i]
        w_dt[i] = (w_m[i] - b_g[i]) * dt
    acc = _mv(R, f)
    dR = exp_so3(w_dt)
    dRt = _transpose(dR)
    Jr = right_jacobian(w_dt)
    R_skew_f = _mm(R, _skew(f))
    A = np.empty((3, 6))  # [R [f]x, R]
    th_bg = np.empty((3, 3))  # -Jr(w dt) dt
    for i in range(3):
        acc[i] += g[i]
        for j in range(3):
            A[i, j], A[i, 3 + j] = R_skew_f[i, j], R[i, j]
            th_bg[i, j] = -Jr[i, j] * dt
    xi_bg = np.zeros((3, 3))
    if earth_fixed:  # -Exp(w dt)^T [xi]x Jr(-w dt) dt, Jr(-w dt) = Jr(w dt)^T
        xi_bg = _mmt(_mm(dRt, _skew(xi)), Jr)
        for i in range(3):
            for j in range(3):
                xi_bg[i, j] *= -dt
    FP = np.empty_like(P)
    _transition_rows(P, dt, A, dRt, th_bg, xi_bg, earth_fixed, phi_ins, FP)
    # F (F P)^T = F P F^T (P symmetric), into P, which is read no more
    _transition_rows(_transpose(FP), dt, A, dRt, th_bg, xi_bg, earth_fixed, phi_ins, P)
    for i in range(P.shape[0]):
        P[i, i] += q[i]
    p_new, v_new = np.empty(3), np.empty(3)
    for i in range(3):
        p_new[i] = p[i] + v[i] * dt + 0.5 * acc[i] * dt * dt
        v_new[i] = v[i] + acc[i] * dt
    xi_new = _mv(dRt, xi) if earth_fixed else xi.copy()
    b_ins_new = np.empty(2)
    for i in range(2):
        b_ins_new[i] = b_ins[i] * phi_ins
    _pack(x, p_new, v_new, _mm(R, dR), b_a, b_g, g, xi_new, b_ins_new)


@njit(cache=True)
def _unpack(x: np.ndarray):
    """The nominal state's ``(p, v, R, b_a, b_g, g, xi, b_ins)`` out of the filter's one
    array ``x`` (copies)."""
    return (x[_XP:_XP + 3].copy(), x[_XV:_XV + 3].copy(), x[_XR:_XR + 9].copy().reshape((3, 3)),
            x[_XBA:_XBA + 3].copy(), x[_XBG:_XBG + 3].copy(), x[_XG:_XG + 3].copy(),
            x[_XXI:_XXI + 3].copy(), x[_XBI:_XBI + 2].copy())


@njit(cache=True)
def _pack(x, p, v, R, b_a, b_g, g, xi, b_ins) -> None:
    """The nominal state into the filter's one array ``x``."""
    for i in range(3):
        x[_XP + i], x[_XV + i] = p[i], v[i]
        x[_XBA + i], x[_XBG + i], x[_XG + i], x[_XXI + i] = b_a[i], b_g[i], g[i], xi[i]
        for j in range(3):
            x[_XR + 3 * i + j] = R[i, j]
    for i in range(2):
        x[_XBI + i] = b_ins[i]


@njit(cache=True)
def _inverse(S: np.ndarray) -> tuple[np.ndarray, bool]:
    """``S^-1`` by Gauss-Jordan elimination with partial pivoting (LU's arithmetic), and
    False when ``S`` is singular."""
    m = S.shape[0]
    a = S.copy()
    inv = np.zeros((m, m))
    for i in range(m):
        inv[i, i] = 1.0
    for c in range(m):
        piv = c
        for r in range(c + 1, m):
            if abs(a[r, c]) > abs(a[piv, c]):
                piv = r
        if a[piv, c] == 0.0:
            return inv, False
        for j in range(m):
            a[c, j], a[piv, j] = a[piv, j], a[c, j]
            inv[c, j], inv[piv, j] = inv[piv, j], inv[c, j]
        d = a[c, c]
        for j in range(m):
            a[c, j] /= d
            inv[c, j] /= d
        for r in range(m):
            e = a[r, c]
            if r != c and e != 0.0:
                for j in range(m):
                    a[r, j] -= e * a[c, j]
                    inv[r, j] -= e * inv[c, j]
    return inv, True


@njit(cache=True)
def _gain(PHt, HPHt, y, Rm, keep_lo, keep_hi):
    """The Kalman gain from ``P H^T`` and ``H P H^T``: ``(S, nis, K, ok)``, ``S``
    symmetrized, the rows of ``K`` outside ``[keep_lo, keep_hi)`` zeroed; ``ok`` False
    (and ``nis``, ``K`` meaningless) when ``S`` is singular."""
    m = y.shape[0]
    S = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            S[i, j] = 0.5 * ((HPHt[i, j] + Rm[i, j]) + (HPHt[j, i] + Rm[j, i]))
    Sinv, ok = _inverse(S)
    if not ok:
        return S, math.nan, PHt, False
    Sinv_y = _mv(Sinv, y)
    nis = 0.0
    for i in range(m):
        nis += y[i] * Sinv_y[i]
    K = _mm(PHt, Sinv)
    for i in range(K.shape[0]):
        if i < keep_lo or i >= keep_hi:
            for j in range(m):
                K[i, j] = 0.0
    return S, nis, K, True


@njit(cache=True)
def _joseph_into(P, H, K, Rm, out) -> None:
    """``out = (I - K H) P (I - K H)^T + K R K^T`` through its rank-``m`` factors (module
    docstring), row by row: ``B = P - K (H P)``, then ``B - (B H^T) K^T + (K R) K^T``.
    Row ``i`` of ``out`` needs row ``i`` of ``P`` alone (``H P`` is made first), so
    ``out`` may be ``P``."""
    n, m = P.shape[0], H.shape[0]
    HP, KR, Kt = _mm(H, P), _mm(K, Rm), _transpose(K)
    B, BHt, BHtKt, KRKt = np.empty(n), np.empty(m), np.empty(n), np.empty(n)
    for i in range(n):
        for j in range(n):  # B[i] = P[i] - K[i] (H P), the inner loops along the rows
            B[j] = 0.0
        for a in range(m):
            k_ia = K[i, a]
            if k_ia != 0.0:
                for j in range(n):
                    B[j] += k_ia * HP[a, j]
        for j in range(n):
            B[j] = P[i, j] - B[j]
        for a in range(m):
            acc = 0.0
            for k in range(n):
                acc += B[k] * H[a, k]
            BHt[a] = acc
        for j in range(n):  # row i of (B H^T) K^T and of (K R) K^T
            BHtKt[j], KRKt[j] = 0.0, 0.0
        for a in range(m):
            bht, kr = BHt[a], KR[i, a]
            for j in range(n):
                BHtKt[j] += bht * Kt[a, j]
            for j in range(n):
                KRKt[j] += kr * Kt[a, j]
        for j in range(n):
            out[i, j] = B[j] - BHtKt[j] + KRKt[j]


@njit(cache=True)
def _reset_into(P: np.ndarray, dtheta: np.ndarray) -> None:
    """``P <- G P G^T`` with ``G = I`` but ``G[TH, TH] = I - [dtheta/2]x``, symmetrized,
    in place: only the attitude rows, then columns, change."""
    n = P.shape[0]
    half = np.empty(3)
    for i in range(3):
        half[i] = 0.5 * dtheta[i]
    K = _skew(half)
    rows = P[_TH:_TH + 3, :].copy()  # G P: the attitude rows mixed
    for i in range(3):
        for j in range(n):
            P[_TH + i, j] = rows[i, j] - (K[i, 0] * rows[0, j] + K[i, 1] * rows[1, j]
                                          + K[i, 2] * rows[2, j])
    cols = P[:, _TH:_TH + 3].copy()  # (G P) G^T: the attitude columns mixed
    for i in range(n):
        for j in range(3):
            P[i, _TH + j] = cols[i, j] - (cols[i, 0] * K[j, 0] + cols[i, 1] * K[j, 1]
                                          + cols[i, 2] * K[j, 2])
    for i in range(n):
        for j in range(i, n):
            sym = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = sym
            P[j, i] = sym


@njit(cache=True)
def _inject_into(x: np.ndarray, dx: np.ndarray) -> None:
    """:meth:`EsesoFilter.inject` of the correction ``dx`` into the filter's nominal
    state ``x`` in place (paper eq. 16d: every component added, the attitude by
    ``R Exp(dtheta)``)."""
    for i in range(3):
        x[_XP + i] += dx[_P + i]
        x[_XV + i] += dx[_V + i]
        x[_XBA + i] += dx[_BA + i]
        x[_XBG + i] += dx[_BG + i]
        x[_XG + i] += dx[_G + i]
        x[_XXI + i] += dx[_XI + i]
    for i in range(2):
        x[_XBI + i] += dx[_BI + i]
    R = _mm(x[_XR:_XR + 9].copy().reshape((3, 3)), exp_so3(dx[_TH:_TH + 3].copy()))
    for i in range(3):
        for j in range(3):
            x[_XR + 3 * i + j] = R[i, j]


ADAPT_NONE, ADAPT_NOISE, ADAPT_PROCESS = 0, 1, 2
"""What an update's innovation adapts (:func:`fuse`): nothing, its channel's noise scale
(:meth:`EsesoFilter._adapt_noise`) or the IMU's (:meth:`EsesoFilter._adapt_process`)."""


@njit(cache=True)
def _adapted(adapt, y, HPHt, Rm, mean, scale, adapt_n, ceiling, cap):
    """The noise scale's exponential ``mean`` (over ``adapt_n`` updates) and the
    ``scale`` (the mean clipped to [1, ``ceiling``]) after the innovation ``y`` of
    covariance ``H P H^T + s R``: a sample of its channel's scale ``(y^T y - tr(H P H^T))
    / tr(R)`` (``ADAPT_NOISE``) or of the IMU's, ``scale (y^T y - tr(R)) / tr(H P H^T)``
    (``ADAPT_PROCESS``: ``P`` already carries the current scale), capped at ``cap``."""
    yy, tr_h, tr_r = 0.0, 0.0, 0.0
    for i in range(y.shape[0]):
        yy += y[i] * y[i]
        tr_h += HPHt[i, i]
        tr_r += Rm[i, i]
    if adapt == ADAPT_NOISE:
        sample = (yy - tr_h) / max(tr_r, 1e-300)
    else:
        sample = scale * ((yy - tr_r) / max(tr_h, 1e-300))
    sample = cap if cap < sample else sample  # Python's min(sample, cap), NaN kept
    mean += (sample - mean) / adapt_n
    scale = 1.0 if 1.0 > mean else mean
    return mean, ceiling if ceiling < scale else scale
GATED, FUSED, RECOVERED, SINGULAR = 0, 1, 2, -1
"""What :func:`fuse` made of an update (the filter's ``Outcome``; ``SINGULAR``: ``S``
could not be inverted, nothing changed)."""


@njit(cache=True)
def _correct(x, P, y, H, K, Rm) -> None:
    """The update with gain ``K``: the Joseph form into ``P``, then the injection of
    ``K y`` into ``x`` and the reset of ``P``, in place."""
    dx = _mv(K, y)
    _joseph_into(P, H, K, Rm, P)
    _inject_into(x, dx)
    _reset_into(P, dx[_TH:_TH + 3].copy())


@njit(cache=True)
def _fuse_gated(x, P, y, H, Rm, PHt, HPHt, keep_lo, keep_hi, gate, may_recover):
    """The Joseph update of ``P`` (with its ``P H^T`` and ``H P H^T``), the gate and the
    injection and reset into ``x`` and ``P`` in place (:func:`fuse`): ``(outcome, nis,
    S)``, the first update's."""
    S, nis, K, ok = _gain(PHt, HPHt, y, Rm, keep_lo, keep_hi)
    if not ok:
        return SINGULAR, nis, S
    outcome = FUSED
    if gate > 0.0 and nis > gate:
        if not may_recover:
            return GATED, nis, S
        outcome = RECOVERED
        Rm = _scaled(Rm, nis / gate)
        _, _, K, ok = _gain(PHt, HPHt, y, Rm, keep_lo, keep_hi)
        if not ok:
            return SINGULAR, nis, S
    _correct(x, P, y, H, K, Rm)
    return outcome, nis, S


@njit(cache=True)
def fuse(x, P, y, H, Rm, keep_lo, keep_hi, gate, may_recover, adapt, adapt_n, mean, scale,
         ceiling, cap):
    """:meth:`EsesoFilter.update` but its bookkeeping, in one call: the noise adaptation
    (``adapt``: its exponential mean ``mean`` over ``adapt_n`` updates, the current
    ``scale``, clipped to [1, ``ceiling``], each sample capped at ``cap``), the Joseph
    update (:func:`_gain`, :func:`_joseph_into`), the gate (``gate`` > 0; beyond it the
    update is rejected unless ``may_recover``, then fused with its noise scaled so that
    its NIS equals the gate) and the injection and reset into ``x`` and ``P`` in place
    (:func:`_correct`). Returns
    ``(outcome, nis, S, mean, scale)``: ``nis`` and ``S`` the first update's, ``mean``
    and ``scale`` the adaptation's new ones."""
    PHt = _mmt(P, H)
    HPHt = _mm(H, PHt)
    if adapt != ADAPT_NONE:
        mean, scale = _adapted(adapt, y, HPHt, Rm, mean, scale, adapt_n, ceiling, cap)
        if adapt == ADAPT_NOISE:
            Rm = _scaled(Rm, scale)
    outcome, nis, S = _fuse_gated(x, P, y, H, Rm, PHt, HPHt, keep_lo, keep_hi, gate,
                                  may_recover)
    return outcome, nis, S, mean, scale


@njit(cache=True)
def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` of two 3-vectors."""
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


@njit(cache=True)
def h_tau(x, f_m, w_m, wdot, with_wdot, m_vec, added, d_l, d_nl, w_minus_b, mass, cg_z):
    """:meth:`EsesoFilter.h_tau` at the nominal state ``x`` (the filter's one array): the
    predicted thruster force (N, body) and its 3 x 23 Jacobian at specific force ``f_m``
    and rate ``w_m``, the centre-of-gravity terms only ``with_wdot`` (angular
    acceleration ``wdot``). ``m_vec`` is the diagonal of ``M``, ``added`` of ``A``,
    ``d_l`` and ``d_nl`` the damping's, ``w_minus_b`` the weight minus the buoyancy (N),
    ``mass`` (kg) and ``cg_z`` (m) the centre of gravity's."""
    _, v, R, b_a, b_g, g, xi, _ = _unpack(x)
    f, w = np.empty(3), np.empty(3)
    for i in range(3):
        f[i] = f_m[i] - b_a[i]
        w[i] = w_m[i] - b_g[i]
    RT = _transpose(R)
    nu, gB = _mv(RT, v), _mv(RT, g)
    zB = RT[:, 2].copy()  # R^T e3
    Anu = np.empty(3)
    for i in range(3):
        Anu[i] = added[i] * nu[i]
    w_nu, w_Anu = _cross(w, nu), _cross(w, Anu)
    h = np.empty(3)
    for i in range(3):
        damp = (d_l[i] + d_nl[i] * abs(nu[i])) * nu[i]
        h[i] = (m_vec[i] * (f[i] + gB[i]) - added[i] * w_nu[i] + w_Anu[i] + damp
                - w_minus_b * zB[i] - xi[i])
    if with_wdot:
        r_g = np.zeros(3)
        r_g[2] = cg_z
        cg = _cross(wdot, r_g)
        ww = _cross(w, _cross(w, r_g))
        for i in range(3):
            h[i] += mass * (cg[i] + ww[i])
    Sw, Snu = _skew(w), _skew(nu)
    J_nu = np.empty((3, 3))  # -A [w]x + [w]x A + diag(d_l + 2 d_nl |nu|)
    for i in range(3):
        for j in range(3):
            J_nu[i, j] = -added[i] * Sw[i, j] + Sw[i, j] * added[j]
        J_nu[i, i] += d_l[i] + 2.0 * d_nl[i] * abs(nu[i])
    J_v, J_nu_nu = _mm(J_nu, RT), _mm(J_nu, Snu)
    SgB, SzB, SAnu = _skew(gB), _skew(zB), _skew(Anu)
    H = np.zeros((3, _N))
    for i in range(3):
        for j in range(3):
            H[i, _V + j] = J_v[i, j]
            # J_nu [nu]x + M [gB]x - (W - B) [zB]x
            H[i, _TH + j] = J_nu_nu[i, j] + m_vec[i] * SgB[i, j] - w_minus_b * SzB[i, j]
            # -J_w = -(A [nu]x - [A nu]x)
            H[i, _BG + j] = -(added[i] * Snu[i, j] - SAnu[i, j])
            H[i, _G + j] = m_vec[i] * RT[i, j]
        H[i, _BA + i] = -m_vec[i]
        H[i, _XI + i] = -1.0
    return h, H


@njit(cache=True)
def mahalanobis(S: np.ndarray, y: np.ndarray) -> float:
    """``y^T S^-1 y`` (``nan`` when ``S`` is singular)."""
    Sinv, ok = _inverse(S)
    if not ok:
        return math.nan
    Sinv_y = _mv(Sinv, y)
    out = 0.0
    for i in range(y.shape[0]):
        out += y[i] * Sinv_y[i]
    return out


(_K_W_MINUS_B, _K_MASS, _K_CG_Z, _K_THRUST_REL, _K_DAMPING_REL, _K_ACCEL_STD, _K_GYRO_STD,
 _K_THRUST_STD, _K_ADAPT_N, _K_SCALE_MAX, _K_CAP, _K_HUBER) = range(12)
"""Where each scalar of :func:`thrust_update`'s ``k`` is (:func:`thrust_constants`): the
weight minus the buoyancy (N), the mass (kg), the centre of gravity (m), the thrust map's
and the damping's relative one-sigmas, the accelerometer's (m/s^2), the gyro's (rad/s)
and the thrusters' (N) noise, ``noise.adapt_updates``, ``noise.thrust_scale_max``, the
noise sample's cap and ``thrust_huber``."""


def thrust_constants(params, sample_cap: float) -> tuple[np.ndarray, np.ndarray]:
    """The constants of :func:`thrust_update` from the filter's ``EsesoParams``, made once
    per filter: the vehicle's diagonals (rows ``M``, ``A``, linear and quadratic damping)
    and the scalars at :data:`_K_W_MINUS_B` ... (the noise sample's cap is the filter's
    constant)."""
    v, n, c = params.vehicle, params.noise, params.process
    added = np.asarray(v.added_mass_kg, float)
    vehicle = np.array([v.mass_kg + added, added, np.asarray(v.damping_linear, float),
                        np.asarray(v.damping_quadratic, float)])
    k = np.array([v.weight_n - v.buoyancy_n, v.mass_kg, v.cg_z_m, c.thrust_rel_std,
                  c.damping_rel_std, n.accel_std_mps2, n.gyro_std_rps, n.thrust_std_n,
                  n.adapt_updates, n.thrust_scale_max, sample_cap, params.thrust_huber], float)
    return vehicle, k


@njit(cache=True)
def thrust_update(x, P, f_m, w_m, wdot, wdot_dt, tau, vehicle, k, model_terms, has_last,
                  R_tau, mean, s_imu, keep_lo, keep_hi):
    """:meth:`EsesoFilter.update_thrust` but its bookkeeping and the published excess's
    learning, in one call (``vehicle`` and ``k`` from :func:`thrust_constants`): the
    thrust model (:func:`h_tau`), the model-change variance into ``P[xi, xi]``
    (``model_terms``, the last update's ``(tau, D(nu) nu)`` rows, read when ``has_last``
    and written), the noise ``R_tau`` (written) at the IMU noise scale ``s_imu``, the
    thrust channel's noise scale (its mean ``mean``) when ``k``'s ``adapt_updates`` > 0,
    the Huber weight, then the update (never gated) into ``x`` and ``P`` in place. Returns
    ``(outcome, nis, S, y, S_model, mean, scale, downweighted)``, ``S_model = H P H^T +
    R_tau`` what :func:`learn_excess` learns from."""
    m_vec, added, d_l, d_nl = vehicle[0], vehicle[1], vehicle[2], vehicle[3]
    h, H = h_tau(x, f_m, w_m, wdot, True, m_vec, added, d_l, d_nl, k[_K_W_MINUS_B],
                 k[_K_MASS], k[_K_CG_Z])
    _, v, R, _, _, _, _, _ = _unpack(x)
    nu = _mv(_transpose(R), v)
    for i in range(3):  # the model change since the last update (model_change_var)
        damp = (d_l[i] + d_nl[i] * abs(nu[i])) * nu[i]
        if has_last:
            P[_XI + i, _XI + i] += ((k[_K_THRUST_REL] * (tau[i] - model_terms[0, i])) ** 2
                                    + (k[_K_DAMPING_REL] * (damp - model_terms[1, i])) ** 2)
        model_terms[0, i], model_terms[1, i] = tau[i], damp
    y, var = np.empty(3), np.empty(3)
    for i in range(3):  # thrust_noise
        y[i] = tau[i] - h[i]
        var[i] = (m_vec[i] * k[_K_ACCEL_STD]) ** 2 * s_imu + k[_K_THRUST_STD] ** 2
    if wdot_dt > 0.0:
        var_wdot = 2.0 * k[_K_GYRO_STD] ** 2 / wdot_dt ** 2 * s_imu
        for i in range(2):
            var[i] += (k[_K_MASS] * k[_K_CG_Z]) ** 2 * var_wdot
    for i in range(3):
        for j in range(3):
            R_tau[i, j] = var[i] if i == j else 0.0
    Rm = R_tau.copy()
    PHt = _mmt(P, H)
    HPHt = _mm(H, PHt)
    S_model = _sum(HPHt, Rm)
    scale = 1.0
    adapt_n = k[_K_ADAPT_N]
    if adapt_n > 0:  # before the Huber weight (it would learn it)
        mean, scale = _adapted(ADAPT_NOISE, y, HPHt, Rm, mean, scale, adapt_n,
                               k[_K_SCALE_MAX], k[_K_CAP])
        Rm = _scaled(Rm, scale)
    downweighted = False
    huber = k[_K_HUBER]
    if huber > 0.0:
        S = _sum(HPHt, Rm)
        nis = mahalanobis(S, y)
        if nis > huber:
            Rm = _scaled(Rm, nis / huber)
            downweighted = True
    S, nis, K, ok = _gain(PHt, HPHt, y, Rm, keep_lo, keep_hi)  # never gated
    if ok:
        _correct(x, P, y, H, K, Rm)
    return FUSED if ok else SINGULAR, nis, S, y, S_model, mean, scale, downweighted


@njit(cache=True)
def learn_excess(y, S_model, excess_ratio, excess_slow, excess_lag, last_u, excess, adapt_n,
                 slow_n, cap) -> None:
    """:meth:`EsesoFilter._learn_disturbance_excess` in place: the thrust innovation
    ``y``'s exponential means ``excess_ratio`` (over ``adapt_n`` updates) and
    ``excess_slow`` (over ``slow_n``) of ``y_i^2 / S_ii`` (each sample capped at ``cap``),
    ``excess_lag`` (over ``adapt_n``) of ``u_i`` times ``last_u_i`` (``u = y_i /
    sqrt(S_ii)``, within +-``cap``; ``last_u`` then set to ``u``) and the ``excess`` they
    make."""
    for i in range(3):
        S_ii = S_model[i, i]
        sample = y[i] * y[i] / _floor(S_ii, 1e-300)
        sample = cap if sample > cap else sample  # np.minimum: NaN kept
        excess_ratio[i] += (sample - excess_ratio[i]) / adapt_n
        excess_slow[i] += (sample - excess_slow[i]) / slow_n
        u = y[i] / math.sqrt(_floor(S_ii, 1e-300))
        lag = u * last_u[i]
        lag = cap if lag > cap else (-cap if lag < -cap else lag)  # np.clip: NaN kept
        last_u[i] = u
        excess_lag[i] += (lag - excess_lag[i]) / adapt_n
        wider = _floor(excess_ratio[i] - 1.0, 0.0)
        shared = _floor(excess_lag[i], 0.0)
        wider = shared if shared < wider or shared != shared else wider  # np.minimum
        narrower = excess_slow[i] - 1.0
        excess[i] = (wider + (0.0 if narrower > 0.0 else narrower)) * S_ii


@njit(cache=True)
def finite(x: np.ndarray, P: np.ndarray) -> bool:
    """Whether ``P`` and the position in the nominal state ``x`` are finite."""
    for i in range(3):
        if not math.isfinite(x[_XP + i]):
            return False
    for i in range(P.shape[0]):
        for j in range(P.shape[1]):
            if not math.isfinite(P[i, j]):
                return False
    return True


@njit(cache=True)
def _floor(x: float, lo: float) -> float:
    """``max(x, lo)``, NaN kept (as ``np.maximum``)."""
    return lo if x < lo else x


@njit(cache=True)
def estimates(x, P, w_m, excess, min_share):
    """The ESESO pipeline's published values in its column order
    (:meth:`onboard.pipelines.eseso.Eseso.estimates`): position, velocity (earth and
    body), roll, pitch, yaw (ZYX, as :func:`onboard.core.so3.matrix_to_euler`), rate,
    disturbance (body and earth), the position's and body velocity's sigmas, the
    disturbance's published sigma
    (:meth:`~onboard.estimators.eseso_filter.EsesoFilter.published_disturbance_var`
    with the thrust innovations' ``excess`` and the floor ``min_share``), the biases and
    gravity's down component, at the nominal state ``x`` (the filter's one array)."""
    p, v, R, b_a, b_g, g, xi, _ = _unpack(x)
    out = np.empty(37)
    RT = _transpose(R)
    nu, xi_e = _mv(RT, v), _mv(R, xi)
    P_nu = _mm(_mm(RT, P[_V:_V + 3, _V:_V + 3].copy()), R)  # R^T P_vv R
    for i in range(3):
        out[i], out[3 + i], out[6 + i] = p[i], v[i], nu[i]
        out[12 + i] = w_m[i] - b_g[i]
        out[15 + i], out[18 + i] = xi[i], xi_e[i]
        out[21 + i] = math.sqrt(_floor(P[_P + i, _P + i], 0.0))
        out[24 + i] = math.sqrt(_floor(P_nu[i, i], 0.0))
        var = _floor(P[_XI + i, _XI + i], 0.0)
        out[27 + i] = math.sqrt(_floor(var + excess[i], min_share * var))
        out[30 + i], out[33 + i] = b_a[i], b_g[i]
    out[9] = math.atan2(R[2, 1], R[2, 2])
    out[10] = -math.asin(max(-1.0, min(1.0, R[2, 0])))
    out[11] = math.atan2(R[1, 0], R[0, 0])
    out[36] = g[2]
    return out
