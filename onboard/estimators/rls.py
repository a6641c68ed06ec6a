"""Recursive least squares with forgetting and a bounded covariance (algorithms.md §3.4).

One regression ``a_k = phi_k^T theta + e_k`` per instance; the current pipeline runs one
per degree of freedom of its vehicle model (:mod:`onboard.estimators.vehicle_models`), and
any other pipeline may reuse it.

Update (algorithms.md §3.4), sample weight ``w`` in (0, 1]::

    e_k     = a_k - phi_k^T theta_{k-1}                      (a priori residual)
    s_k     = lambda_k / w + phi_k^T P_{k-1} phi_k
    K_k     = P_{k-1} phi_k / s_k
    theta_k = theta_{k-1} + K_k e_k
    P_k     = (P_{k-1} - K_k phi_k^T P_{k-1}) / lambda_k

Plain exponential forgetting (``lambda_k = lambda``) makes ``P`` grow without bound when the
regressor is not exciting (a vehicle on a straight line): "covariance wind-up", after which
one noisy sample throws the parameters away. Two guards keep ``P`` bounded:

* variable-rate forgetting: ``lambda_k = 1 - (1 - lambda) * (1 - tr(P)/tr_max)``, i.e. full
  forgetting when the covariance is small and none as its trace approaches ``tr_max``
  (Fortescue-type, in trace form);
* exponential resetting (EFRA, Salgado, Goodwin & Middleton 1988): after the update
  ``P <- P + beta I - delta P^2``, which keeps ``P`` between about ``p_min`` and ``p_max``
  without any excitation assumption. The defaults scale with ``p0``:
  ``delta = (1/lambda - 1) / p_max`` (the equilibrium of an unexcited direction is then
  ``p_max``) and ``beta = (1 - lambda) p_min``. A fixed ``delta`` ignores the scale: with
  ``p0 = 1e6`` (needed when regressors are ~0.01), ``delta = 1e-6`` pulls ``P`` to ~1 and
  freezes the parameters at their initial values (the spheroid's yaw channel).

The residual variance ``sigma2`` is tracked with the same forgetting, so that the caller can
use the model error as process noise (the current pipeline does, for honest uncertainty).

Two forms of the update
-----------------------
:func:`reference_rls_update` is the update above in numpy, line for line.
:func:`rls_update`, which :class:`RecursiveLeastSquares` runs, is the same arithmetic on
Python floats: at the 4-9 parameters of the pipelines numpy's per-call overhead costs more
than the arithmetic, and numpy's summation order changes the last bits of the estimates
that the golden replays record. It computes the upper triangle of each symmetric product
and mirrors it, so ``P`` is symmetric by construction. The tests compare the two on random
inputs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from mypy_extensions import mypyc_attr
import numpy as np

Rows = list[list[float]]
"""A matrix as a list of rows of floats."""


def reference_rls_update(
    P: np.ndarray, theta: np.ndarray, phi: np.ndarray, a: float, weight: float,
    forgetting: float, tr_max: float, beta: float, delta: float,
) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """One update of algorithms.md §3.4 in numpy: ``(P, theta, e, lam, s)`` after the
    sample ``a = phi^T theta + e`` of weight ``weight`` (see the module docstring)."""
    e = a - phi @ theta                                   # e_k = a_k - phi_k^T theta_k-1
    lam = 1.0 - (1.0 - forgetting) * max(0.0, 1.0 - np.trace(P) / tr_max)   # lambda_k
    s = lam / weight + phi @ P @ phi                      # s_k = lambda_k / w + phi^T P phi
    K = P @ phi / s                                       # K_k = P phi / s_k
    theta = theta + K * e                                 # theta_k = theta_k-1 + K_k e_k
    P = (P - np.outer(K, phi @ P)) / lam                  # P_k = (P - K phi^T P) / lambda_k
    P = P + beta * np.eye(len(P)) - delta * P @ P         # EFRA: P + beta I - delta P^2
    return P, theta, float(e), float(lam), float(s)


def dot(x: list[float], y: list[float]) -> float:
    """``x . y`` summed left to right from the first product. (``sum`` starts from the
    integer 0, which turns a product of -0.0 into 0.0, and from Python 3.12 on it
    compensates the rounding of float sums: both change the last bits.) An indexed loop, on
    which the compiled build multiplies and adds unboxed floats."""
    total = x[0] * y[0]
    for i in range(1, min(len(x), len(y))):
        total += x[i] * y[i]
    return total


def trace(P: Rows) -> float:
    """``tr(P)``, summed from the first diagonal entry."""
    total = P[0][0]
    for i in range(1, len(P)):
        total += P[i][i]
    return total


def rls_update(
    P: Rows, theta: list[float], phi: list[float], a: float, weight: float,
    forgetting: float, tr_max: float, beta: float, delta: float,
) -> tuple[Rows, list[float], float, float, float]:
    """:func:`reference_rls_update` on floats: ``P`` a symmetric matrix as rows; returns
    ``(P+, theta+, e, lam, s)`` with ``P+`` symmetric (new lists, inputs unchanged)."""
    n = len(theta)
    g = [dot(row, phi) for row in P]                      # P phi
    e = a - dot(phi, theta)                               # e_k
    lam = 1.0 - (1.0 - forgetting) * max(0.0, 1.0 - trace(P) / tr_max)   # lambda_k
    s = lam / weight + dot(phi, g)                        # s_k
    K = [gi / s for gi in g]                              # K_k = P phi / s_k
    Q = [[0.0] * n for _ in range(n)]                     # (P - K (P phi)^T) / lambda_k
    for i in range(n):
        for j in range(i, n):
            Q[i][j] = Q[j][i] = (P[i][j] - K[i] * g[j]) / lam
    P_new = [[0.0] * n for _ in range(n)]                 # EFRA: Q + beta I - delta Q^2
    for i in range(n):
        for j in range(i, n):
            q = Q[i][j] + beta if i == j else Q[i][j]
            P_new[i][j] = P_new[j][i] = q - delta * dot(Q[i], Q[j])
    return P_new, [t + k * e for t, k in zip(theta, K)], e, lam, s


@mypyc_attr(allow_interpreted_subclasses=True)
class RecursiveLeastSquares:
    """RLS with forgetting, bounded covariance and a residual-variance estimate.

    Attributes (read them, do not assign, except ``P`` to set a prior):
        theta: parameter estimate, shape (n,) (a new array on each read).
        P: parameter covariance (in units of ``sigma2``), shape (n, n) (a new array on
            each read; kept as rows of floats).
        e: last a priori residual ``a - phi^T theta`` (units of ``a``).
        S: last residual variance predicted from ``P`` and ``sigma2``.
        nis: last normalized residual ``e^2 / S`` (about 1 when consistent).
        sigma2: forgetting-weighted residual variance (units of ``a`` squared).
        n_updates: number of updates applied.
    """

    def __init__(
        self,
        n: int,
        *,
        forgetting: float = 0.995,
        p0: float = 1e3,
        tr_max: float | None = None,
        p_min: float | None = None,
        p_max: float | None = None,
        beta: float | None = None,
        delta: float | None = None,
        sigma2_0: float = 1e-2,
        theta0: Sequence[float] | np.ndarray | None = None,
        names: Sequence[str] | None = None,
    ) -> None:
        """Args:
            n: number of parameters.
            forgetting: lambda in (0, 1]; 0.995 at 10 Hz is a 20 s memory.
            p0: initial covariance ``p0 * I`` (regressors should be normalized to O(1)).
            tr_max: covariance trace at which forgetting stops (default ``n * p0``).
            p_min, p_max: EFRA bounds (default ``1e-6 p0`` and ``p0``).
            beta, delta: explicit EFRA terms (override p_min / p_max; 0 disables).
            sigma2_0: initial residual variance.
            theta0: initial parameters (zeros by default).
            names: optional parameter names, for :meth:`as_dict` and the saved state.
        """
        if not 0.0 < forgetting <= 1.0:
            raise ValueError("forgetting must be in (0, 1]")
        self.n = n
        self.forgetting = forgetting
        self.p0 = p0
        self.tr_max = tr_max if tr_max is not None else n * p0
        p_min = p0 * 1e-6 if p_min is None else p_min
        p_max = p0 if p_max is None else p_max
        self.beta = (1.0 - forgetting) * p_min if beta is None else beta
        self.delta = (1.0 / forgetting - 1.0) / p_max if delta is None else delta
        self.names = tuple(names) if names is not None else tuple(f"p{i}" for i in range(n))
        self._theta: list[float] = [0.0] * n if theta0 is None else [
            float(v) for v in theta0]
        self._P: Rows = []
        self.P = np.eye(n) * p0
        self.sigma2 = sigma2_0
        self.e = 0.0
        self.S = sigma2_0
        self.nis = 0.0
        self.n_updates = 0

    @property
    def theta(self) -> np.ndarray:
        """The parameter estimate, shape (n,) (a new array)."""
        return np.array(self._theta)

    @property
    def P(self) -> np.ndarray:
        """The parameter covariance in units of ``sigma2``, shape (n, n) (a new array)."""
        return np.array(self._P)

    @P.setter
    def P(self, P: np.ndarray) -> None:
        """Set the covariance (its symmetric part)."""
        P = np.asarray(P, float)
        self._P = [[0.5 * (float(P[i, j]) + float(P[j, i])) for j in range(self.n)]
                   for i in range(self.n)]

    def predict(self, phi: Sequence[float]) -> float:
        """Model output ``phi^T theta``."""
        return float(np.asarray(phi, float) @ self.theta)

    def prediction_variance(self, phi: Sequence[float]) -> float:
        """Variance of ``a`` about ``phi^T theta``: ``sigma2 (1 + phi^T P phi)``."""
        x = np.asarray(phi, float)
        return float(self.sigma2 * (1.0 + x @ self.P @ x))

    def update(self, phi: Sequence[float], a: float, weight: float = 1.0) -> float:
        """Fold in one sample ``a = phi^T theta + e``; returns the a priori residual.

        ``weight`` in (0, 1] scales the sample's information (1 / relative variance), so a
        sample taken while the inputs are uncertain counts less.
        """
        self._P, self._theta, e, lam, s = rls_update(
            self._P, self._theta, [float(v) for v in phi], float(a),
            max(weight, 1e-9), self.forgetting, self.tr_max, self.beta, self.delta)
        self.S = self.sigma2 * s / lam
        self.e = e
        self.nis = e * e / self.S if self.S > 0 else 0.0
        # a posteriori residual variance, forgetting-weighted (innovation / s is the
        # a posteriori residual of the standard RLS identity).
        self.sigma2 = self.forgetting * self.sigma2 + (1.0 - self.forgetting) * e * e * lam / s
        self.n_updates += 1
        return e

    def as_dict(self) -> dict[str, float]:
        """Parameters by name."""
        return {k: float(v) for k, v in zip(self.names, self.theta)}

    def get_state(self) -> dict[str, Any]:
        """JSON-serializable state (parameters, covariance, residual variance)."""
        return {
            "names": list(self.names),
            "theta": self.theta.tolist(),
            "P": self.P.tolist(),
            "sigma2": self.sigma2,
            "n_updates": self.n_updates,
        }

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`get_state`; ignored if the parameter names do not match."""
        try:
            if tuple(state["names"]) != self.names:
                return
            theta = np.asarray(state["theta"], float)
            P = np.asarray(state["P"], float)
            if theta.shape != (self.n,) or P.shape != (self.n, self.n):
                return
            if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(P))):
                return
            self._theta = theta.tolist()
            self.P = P
            self.sigma2 = float(state.get("sigma2", self.sigma2))
            self.n_updates = int(state.get("n_updates", 0))
        except (KeyError, TypeError, ValueError):
            return
