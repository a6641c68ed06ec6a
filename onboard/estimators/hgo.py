"""High-gain observer with an LMI gain and the increasing-gain variant (algorithms.md §3.1).

Sources: Kim, Fan & Bose, "Estimating water current velocities by using a model-based
high-gain observer for an autonomous underwater vehicle", IEEE Access 6 (2018), eq. (10)-(16);
Alessandri & Rossi, "Time-varying increasing-gain observers for nonlinear systems",
Automatica 49 (2013).

The system in observable chain form, ``p`` channels of ``n_c`` states each::

    x' = A x + f(x, u),   y = C x                                   (Kim eq. 10)
    x_hat' = A x_hat + f(x_hat, u) + G(gamma) (y - C x_hat)          (Kim eq. 11)
    G(gamma) = Theta(gamma) K,  Theta = diag(gamma, ..., gamma^n_c) per channel

``K`` comes from the LMI ``A^T P + P A - C^T Y^T - Y C + lambda I < 0``, ``K = P^-1 Y``
(Kim eq. 16), solved offline by :mod:`onboard.apps.design_gain` and read from a JSON file; this
module never imports cvxpy. With ``L_f`` the Lipschitz constant of a lower-triangular
``f``, convergence holds for ``gamma > gamma* = max(1, 2 ||P|| L_f / lambda)``
(algorithms.md §3.1, derived from Kim eq. 14).

Increasing gain (Alessandri & Rossi): ``gamma`` starts at ``gamma_0`` and grows while the
output error exceeds a threshold, ``gamma' = rho max(0, |e_n|^2 - e_thr^2)`` (``e_n`` the
innovation divided by its noise standard deviation, per component), up to ``gamma_max``.
A large initial error then meets a small gain, which removes the peaking of a fixed high
gain; measurement noise alone (``|e_n| ~ 1``) does not pump the gain up.

Two uses:

* :class:`ChainHGO`, the generic observer above (RK4 between samples);
* :func:`current_hgo_gain`, the same observer for the water current, written in the state
  ``x = [nu_r (body), V_c (earth)]`` of :mod:`onboard.pipelines.current`. Per earth axis the
  chain is ``z1 = V_g`` (velocity over ground, measured) and ``z2 = V_g'``; the model gives
  ``z2' = J_e z2`` with ``J_e = R (J_b + S(omega)) R^T`` (lower triangular, ``L_f = ||J_e||``).
  Mapping the chain correction ``(gamma k1 e, gamma^2 k2 e)`` back through
  ``V_g = R nu_r + V_c`` and ``z2 = R (f(nu_r) + omega x nu_r)`` gives::

      nu_r' += gamma^2 k2 Jt^-1 R^T e
      V_c'  += gamma k1 e - gamma^2 k2 R Jt^-1 R^T e          (Jt = J_b + S(omega))
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from onboard.core.so3 import skew


def chain_matrices(n_c: int, p: int) -> tuple[np.ndarray, np.ndarray]:
    """Block-diagonal shift matrix ``A`` (n x n) and output matrix ``C`` (p x n)."""
    n = n_c * p
    A = np.zeros((n, n))
    C = np.zeros((p, n))
    for ch in range(p):
        o = ch * n_c
        for i in range(n_c - 1):
            A[o + i, o + i + 1] = 1.0
        C[ch, o] = 1.0
    return A, C


def theta_scaling(gamma: float, n_c: int, p: int) -> np.ndarray:
    """Diagonal of ``Theta(gamma)``: ``gamma, gamma^2, ..., gamma^n_c`` per channel."""
    return np.tile(gamma ** np.arange(1, n_c + 1, dtype=float), p)


def gamma_star(P: np.ndarray, lam: float, lipschitz: float) -> float:
    """``max(1, 2 ||P||_2 L_f / lambda)`` (algorithms.md §3.1)."""
    return max(1.0, 2.0 * float(np.linalg.norm(P, 2)) * lipschitz / lam)


LIPSCHITZ_SPEEDS = (0.3, 1.0, 2.0)
"""Surge speeds (m/s) over which :func:`model_lipschitz` bounds the model's Jacobian."""


def model_lipschitz(model: Any, thetas: Any,
                    speeds: tuple[float, ...] = LIPSCHITZ_SPEEDS) -> float:
    """``L_f = max ||d nu_r'/d nu_r||_2`` of ``model`` (a
    :class:`~onboard.estimators.vehicle_models.RegressionModel`) with coefficients
    ``thetas`` over ``speeds`` (m/s, surge), with small sway/heave (0.05, 0.02 m/s), unit
    propulsion and the yaw rate of a turn (0.1 rad/s): the Lipschitz bound of gamma*."""
    from onboard.estimators.vehicle_models import ModelInputs

    x = ModelInputs()
    x.r = 0.1
    x.n = 1.0
    lf = 0.0
    for u in speeds:
        nu = np.array([u, 0.05, 0.02][: model.nd])
        lf = max(lf, float(np.linalg.norm(model.jacobian(nu, x, thetas), 2)))
    return lf


class GainDesign:
    """An LMI gain as stored by ``onboard design-gain`` (JSON).

    Attributes: ``n_c``, ``p``, ``K`` (n x p), ``P`` (n x n), ``lam``, ``lipschitz``,
    ``gamma_star``, ``gamma`` (design gain = margin * gamma_star), ``gamma_0``, ``rho``,
    ``gamma_max`` (increasing-gain law), ``time_scale_s`` (the chain's time unit).
    """

    def __init__(self, data: Mapping[str, Any]) -> None:
        self.n_c = int(data["n_c"])
        self.p = int(data["p"])
        self.K = np.asarray(data["K"], float).reshape(self.n_c * self.p, self.p)
        self.P = np.asarray(data["P"], float)
        self.lam = float(data["lambda"])
        self.lipschitz = float(data.get("lipschitz", 0.0))
        self.gamma_star = float(data.get("gamma_star", 1.0))
        self.gamma = float(data.get("gamma", self.gamma_star))
        self.gamma_0 = float(data.get("gamma_0", 1.0))
        self.rho = float(data.get("rho", 1.0))
        self.gamma_max = float(data.get("gamma_max", 5.0 * self.gamma_star))
        self.time_scale_s = float(data.get("time_scale_s", 1.0))

    @classmethod
    def load(cls, path: str | Path) -> "GainDesign":
        """Read a gain file; raises OSError / ValueError with the path."""
        with open(path, encoding="utf-8") as fh:
            return cls(json.load(fh))

    @classmethod
    def analytic(cls, zeta: float = 0.8, time_scale_s: float = 1.0) -> "GainDesign":
        """Fallback n_c = 2, p = 1 gain ``k1 = 2 zeta, k2 = 1`` (poles at unit frequency).

        ``P`` solves the Lyapunov equation with ``lambda = 1``; used when no gain file
        exists, so the pipeline never needs cvxpy.
        """
        K = np.array([[2.0 * zeta], [1.0]])
        A, C = chain_matrices(2, 1)
        Acl = A - K @ C
        # (A-KC)^T P + P (A-KC) = -I, solved as a linear system (2x2: 3 unknowns).
        n = 2
        M = np.kron(np.eye(n), Acl.T) + np.kron(Acl.T, np.eye(n))
        P = np.linalg.solve(M, -np.eye(n).ravel()).reshape(n, n)
        P = 0.5 * (P + P.T)
        return cls({"n_c": 2, "p": 1, "K": K.tolist(), "P": P.tolist(), "lambda": 1.0,
                    "gamma": 1.0, "gamma_star": 1.0, "gamma_0": 0.2, "rho": 0.05,
                    "gamma_max": 1.0, "time_scale_s": time_scale_s})

    def chain_gain(self, channel: int = 0) -> np.ndarray:
        """``K`` restricted to one channel's chain (length n_c)."""
        o = channel * self.n_c
        return self.K[o:o + self.n_c, channel]


class IncreasingGain:
    """``gamma' = rho max(0, |e_n|^2 - e_thr^2)``, ``gamma_0 <= gamma <= gamma_max``
    (Alessandri & Rossi 2013). With ``rho = 0`` it is the fixed gain ``gamma_0``."""

    def __init__(self, gamma_0: float, rho: float, gamma_max: float,
                 e_thr: float = 2.0) -> None:
        self.gamma = gamma_0
        self.rho = rho
        self.gamma_max = max(gamma_max, gamma_0)
        self.e_thr2 = e_thr * e_thr

    def update(self, dt: float, e_norm2: float) -> float:
        """Advance by ``dt`` (s) with the squared normalized output error; returns gamma."""
        if self.rho > 0.0:
            growth = self.rho * max(0.0, e_norm2 - self.e_thr2) * dt
            self.gamma = min(self.gamma_max, self.gamma + growth)
        return self.gamma


class ChainHGO:
    """The generic high-gain observer of Kim eq. (11), integrated with RK4.

    Attributes: ``x`` (state estimate), ``e`` (last output error ``y - C x``), ``gamma``.
    """

    def __init__(self, design: GainDesign, f: Callable[[np.ndarray, Any], np.ndarray],
                 x0: np.ndarray, gain_law: IncreasingGain | None = None) -> None:
        self.design = design
        self.A, self.C = chain_matrices(design.n_c, design.p)
        self.f = f
        self.x = np.asarray(x0, float).copy()
        self.law = gain_law or IncreasingGain(design.gamma, 0.0, design.gamma)
        self.e = np.zeros(design.p)
        eig = np.linalg.eigvals(self.A - design.K @ self.C)
        self._eig_max = float(np.max(np.abs(eig)))

    @property
    def gamma(self) -> float:
        """The current high gain ``gamma`` of the gain law."""
        return self.law.gamma

    def _rhs(self, x: np.ndarray, y: np.ndarray, u: Any, G: np.ndarray) -> np.ndarray:
        return self.A @ x + self.f(x, u) + G @ (y - self.C @ x)

    def step(self, dt: float, y: np.ndarray, u: Any = None, e_scale: float = 1.0) -> np.ndarray:
        """Advance by ``dt`` with output ``y`` held; substeps keep
        ``dt_sub <= 0.1 / (gamma max|eig(A - K C)|)`` (algorithms.md §3.1)."""
        y = np.asarray(y, float)
        self.e = y - self.C @ self.x
        gamma = self.law.update(dt, float(self.e @ self.e) / (e_scale * e_scale))
        G = theta_scaling(gamma, self.design.n_c, self.design.p)[:, None] * self.design.K
        n_sub = max(1, math.ceil(dt * gamma * self._eig_max / 0.1))
        h = dt / n_sub
        x = self.x
        for _ in range(n_sub):
            k1 = self._rhs(x, y, u, G)
            k2 = self._rhs(x + 0.5 * h * k1, y, u, G)
            k3 = self._rhs(x + 0.5 * h * k2, y, u, G)
            k4 = self._rhs(x + h * k3, y, u, G)
            x = x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        self.x = x
        return x


def current_hgo_gain(k1: float, k2: float, gamma: float, J_b: np.ndarray, R: np.ndarray,
                     omega: np.ndarray | None = None, reg: float = 0.03) -> np.ndarray:
    """Continuous-time HGO gain in ``x = [nu_r, V_c]`` for an earth-frame velocity innovation.

    Returns ``G`` of shape (2 nd, nd) such that ``x' += G e`` (module docstring). ``J_b`` is
    the model Jacobian ``d nu_r'/d nu_r`` (nd x nd), ``R`` body-to-earth rotation (nd x nd),
    ``omega`` the body rates (used when nd = 3). Only the damping diagonal of ``J_b`` is used,
    floored at ``reg`` (1/s), so that ``Jt`` stays invertible with the right sign while an
    identified model is still wrong (a full identified Jacobian made the observer diverge at
    gamma = 0.3 on the synthetic boat).
    """
    nd = J_b.shape[0]
    Jt = -np.diag(np.maximum(-np.diag(J_b), reg))
    if omega is not None and nd == 3:
        Jt = Jt + skew(omega)
    elif omega is not None and nd == 2:
        Jt = Jt + np.array([[0.0, -omega[2]], [omega[2], 0.0]])
    Jinv_Rt = np.linalg.solve(Jt, R.T)
    g2 = gamma * gamma * k2
    G_nu = g2 * Jinv_Rt
    G_c = gamma * k1 * np.eye(nd) - g2 * (R @ Jinv_Rt)
    return np.vstack([G_nu, G_c])
