"""The ESESO's compiled kernels: its propagation and its Joseph update, in numba.

The readable reference is :mod:`onboard.estimators.eseso_filter` (algorithms.md §5.1);
these functions compute the same equations on plain loops, compiled by numba, because at
23 states numpy's per-call overhead (~1 µs a call, ~50 calls a propagation and ~30 an
update) costs more than the arithmetic (docs/performance.md, "The ESESO's vehicle-day").
:class:`~onboard.estimators.eseso_filter.EsesoFilter` uses them when this module imports
(:func:`~onboard.estimators.eseso_filter.compiled_kernel`: numba installed, the ``fast``
extra, and ``ONBOARD_ESESO_KERNEL`` not ``0``); tests/test_eseso_kernel.py checks that kernel and reference agree to rounding.

* :func:`propagate`: :meth:`EsesoFilter.propagate` whole, the nominal state (paper eq.
  10b) and ``F P F^T + diag(q)`` (eq. 13) with ``F`` applied by the blocks of
  :class:`~onboard.estimators.eseso_filter.Transition`, as
  :func:`~onboard.estimators.eseso_filter.propagate_covariance` does.
* :func:`joseph_update`: :func:`onboard.estimators.kalman.update` as the ESESO calls it
  (error state zero, ``S`` symmetrized and inverted, the gain's rows outside ``keep``
  zeroed), its Joseph form ``(I - K H) P (I - K H)^T + K R K^T`` evaluated through its
  rank-``m`` factors: ``(I - K H) X = X - K (H X)`` is ``m n^2`` multiply-adds where the
  dense product is ``n^3``.
* :func:`reset`: the reset ``G P G^T`` after an injection (paper eq. 17b, Sola eq. 287),
  ``G`` the identity but for its attitude block ``I - [dtheta/2]x``, then symmetrized.

Compiled on first call (not at import: a few seconds once, docs/performance.md) and
cached beside this module (``cache=True``), so a machine compiles once.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# the error-state blocks of eseso_filter (P_, V_, TH, BA, BG, G_, XI, BI), as offsets
_P, _V, _TH, _BA, _BG, _G, _XI, _BI = 0, 3, 6, 9, 12, 15, 18, 21
_N = 23
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
def _mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A @ x`` on plain loops."""
    out = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            out[i] += A[i, k] * x[k]
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
def _skew_sq(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``[t]x`` and ``[t]x^2`` of a 3-vector."""
    K = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    return K, _mm(K, K)


@njit(cache=True)
def exp_so3(theta: np.ndarray) -> np.ndarray:
    """Rodrigues' formula, as :func:`onboard.core.so3.exp_so3`."""
    angle = math.sqrt(theta[0] ** 2 + theta[1] ** 2 + theta[2] ** 2)
    K, K2 = _skew_sq(theta)
    if angle < _SMALL_ANGLE:
        return np.eye(3) + K + 0.5 * K2
    s = math.sin(angle) / angle
    c = (1.0 - math.cos(angle)) / (angle * angle)
    return np.eye(3) + s * K + c * K2


@njit(cache=True)
def right_jacobian(theta: np.ndarray) -> np.ndarray:
    """``Jr(theta)`` of SO(3), as :func:`onboard.core.so3.right_jacobian`."""
    angle = math.sqrt(theta[0] ** 2 + theta[1] ** 2 + theta[2] ** 2)
    K, K2 = _skew_sq(theta)
    if angle < _SMALL_ANGLE:
        return np.eye(3) - 0.5 * K + K2 / 6.0
    a2 = angle * angle
    return (np.eye(3) - (1.0 - math.cos(angle)) / a2 * K
            + (angle - math.sin(angle)) / (a2 * angle) * K2)


@njit(cache=True)
def _transition_rows(M: np.ndarray, dt: float, A: np.ndarray, dRt: np.ndarray,
                     th_bg: np.ndarray, xi_bg: np.ndarray, earth_fixed: bool,
                     phi_ins: float) -> np.ndarray:
    """``F M`` for the 23-row ``M``: ``A = [R [f]x, R]`` (3 x 6, what ``F[V, TH:BA]``
    is times ``-dt``), the other blocks of :class:`Transition` as named there."""
    out = M.copy()
    cols = M.shape[1]
    for i in range(3):
        for j in range(cols):
            mixed = 0.0
            for k in range(6):
                mixed += A[i, k] * M[_TH + k, j]
            v_new = M[_V + i, j] + dt * (M[_G + i, j] - mixed)
            out[_P + i, j] += 0.5 * dt * (M[_V + i, j] + v_new)
            out[_V + i, j] = v_new
            th = 0.0
            for k in range(3):
                th += dRt[i, k] * M[_TH + k, j] + th_bg[i, k] * M[_BG + k, j]
            out[_TH + i, j] = th
            if earth_fixed:
                x = 0.0
                for k in range(3):
                    x += dRt[i, k] * M[_XI + k, j] + xi_bg[i, k] * M[_BG + k, j]
                out[_XI + i, j] = x
    for j in range(cols):
        out[_BI, j] *= phi_ins
        out[_BI + 1, j] *= phi_ins
    return out


@njit(cache=True)
def propagate(p, v, R, b_a, b_g, g, xi, b_ins, P, f_m, w_m, dt, earth_fixed, phi_ins, q):
    """:meth:`EsesoFilter.propagate` over ``dt`` (s) at the mean specific force ``f_m``
    (m/s^2) and rate ``w_m`` (rad/s), with the process-noise diagonal ``q``: the new
    ``(p, v, R, xi, b_ins, P)`` (the biases and gravity do not change)."""
    f = f_m - b_a
    w = w_m - b_g
    acc = _mv(R, f) + g
    dRt = exp_so3(w * dt).T
    Jr = right_jacobian(w * dt)
    K_f, _ = _skew_sq(f)
    A = np.empty((3, 6))
    A[:, :3] = _mm(R, K_f)
    A[:, 3:] = R
    th_bg = -Jr * dt
    xi_bg = np.zeros((3, 3))
    if earth_fixed:
        K_xi, _ = _skew_sq(xi)
        xi_bg = -_mmt(_mm(dRt, K_xi), Jr) * dt  # Jr(-w dt) = Jr(w dt)^T
    FP = _transition_rows(P, dt, A, dRt, th_bg, xi_bg, earth_fixed, phi_ins)
    P_new = _transition_rows(FP.T.copy(), dt, A, dRt, th_bg, xi_bg, earth_fixed, phi_ins)
    for i in range(_N):
        P_new[i, i] += q[i]
    p_new = p + v * dt + 0.5 * acc * dt * dt
    v_new = v + acc * dt
    R_new = _mmt(R, dRt)
    xi_new = _mv(dRt, xi) if earth_fixed else xi.copy()
    return p_new, v_new, R_new, xi_new, b_ins * phi_ins, P_new


@njit(cache=True)
def _inverse(S: np.ndarray) -> tuple[np.ndarray, bool]:
    """``S^-1`` by Gauss-Jordan elimination with partial pivoting (LU's arithmetic), and
    False when ``S`` is singular."""
    m = S.shape[0]
    a = S.copy()
    inv = np.eye(m)
    for c in range(m):
        piv = c
        for r in range(c + 1, m):
            if abs(a[r, c]) > abs(a[piv, c]):
                piv = r
        if a[piv, c] == 0.0:
            return inv, False
        if piv != c:
            for j in range(m):
                a[c, j], a[piv, j] = a[piv, j], a[c, j]
                inv[c, j], inv[piv, j] = inv[piv, j], inv[c, j]
        d = a[c, c]
        for j in range(m):
            a[c, j] /= d
            inv[c, j] /= d
        for r in range(m):
            if r != c and a[r, c] != 0.0:
                e = a[r, c]
                for j in range(m):
                    a[r, j] -= e * a[c, j]
                    inv[r, j] -= e * inv[c, j]
    return inv, True


@njit(cache=True)
def joseph_update(P, y, H, Rm, keep_lo, keep_hi):
    """The ESESO's Kalman update of its error state from zero (:func:`.kalman.update`
    with ``symmetric=True`` and ``keep = slice(keep_lo, keep_hi)``): ``(dx, P+, S, nis,
    ok)``, ``ok`` False (and the rest meaningless) when ``S`` is singular. ``P+`` is the
    Joseph form through its rank-``m`` factors (module docstring)."""
    PHt = _mmt(P, H)
    S = _mm(H, PHt) + Rm
    S = 0.5 * (S + S.T)
    Sinv, ok = _inverse(S)
    if not ok:
        return np.zeros(P.shape[0]), P, S, math.nan, False
    nis = np.sum(y * _mv(Sinv, y))
    K = _mm(PHt, Sinv)
    K[:keep_lo] = 0.0
    K[keep_hi:] = 0.0
    B = P - _mm(K, _mm(H, P))  # (I - K H) P
    P_new = B - _mmt(_mmt(B, H), K) + _mmt(_mm(K, Rm), K)  # ... (I - K H)^T + K R K^T
    return _mv(K, y), P_new, S, nis, True


@njit(cache=True)
def reset(P: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """``G P G^T`` with ``G = I`` but ``G[TH, TH] = I - [dtheta/2]x``, symmetrized."""
    K, _ = _skew_sq(0.5 * dtheta)
    Gth = np.eye(3) - K
    out = P.copy()
    out[_TH:_TH + 3, :] = _mm(Gth, P[_TH:_TH + 3, :])
    out[:, _TH:_TH + 3] = _mmt(out[:, _TH:_TH + 3], Gth)
    return 0.5 * (out + out.T)

