"""Recursive least squares with forgetting and a bounded covariance (algorithms.md §3.4).

One regression ``a_k = phi_k^T theta + e_k`` per instance; the current pipeline runs one
per degree of freedom of its vehicle model (:mod:`onboard.pipelines.vehicle_models`), and
any other pipeline may reuse it.

Update (algorithms.md §3.4)::

    e_k     = a_k - phi_k^T theta_{k-1}                      (a priori residual)
    S_k     = lambda_k + phi_k^T P_{k-1} phi_k
    K_k     = P_{k-1} phi_k / S_k
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
  ``p0 = 1e6`` (needed when regressors are ~0.01), ``delta = 1e-6`` pulled ``P`` to ~1 and
  froze the parameters at their initial values (measured, spheroid yaw channel).

The residual variance ``sigma2`` is tracked with the same forgetting, so that the caller can
use the model error as process noise (the current pipeline does, for honest uncertainty).
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np


class RecursiveLeastSquares:
    """RLS with forgetting, bounded covariance and a residual-variance estimate.

    Attributes (read them, do not assign):
        theta: parameter estimate, shape (n,).
        P: parameter covariance (in units of ``sigma2``), shape (n, n).
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
        theta0: Sequence[float] | None = None,
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
        self.theta = np.zeros(n) if theta0 is None else np.asarray(theta0, float).copy()
        self.P = np.eye(n) * p0
        self.sigma2 = sigma2_0
        self.e = 0.0
        self.S = sigma2_0
        self.nis = 0.0
        self.n_updates = 0

    def predict(self, phi: np.ndarray) -> float:
        """Model output ``phi^T theta``."""
        return float(phi @ self.theta)

    def prediction_variance(self, phi: np.ndarray) -> float:
        """Variance of ``a`` about ``phi^T theta``: ``sigma2 (1 + phi^T P phi)``."""
        return float(self.sigma2 * (1.0 + phi @ self.P @ phi))

    def update(self, phi: np.ndarray, a: float, weight: float = 1.0) -> float:
        """Fold in one sample ``a = phi^T theta + e``; returns the a priori residual.

        ``weight`` in (0, 1] scales the sample's information (1 / relative variance), so a
        sample taken while the inputs are uncertain counts less.
        """
        P = self.P
        Pphi = P @ phi
        e = float(a - phi @ self.theta)
        tr = float(np.trace(P))
        lam = 1.0 - (1.0 - self.forgetting) * max(0.0, 1.0 - tr / self.tr_max)
        s = lam / max(weight, 1e-9) + float(phi @ Pphi)
        K = Pphi / s
        self.theta = self.theta + K * e
        P = (P - np.outer(K, Pphi)) / lam
        if self.beta or self.delta:
            P = P + self.beta * np.eye(self.n) - self.delta * (P @ P)
        self.P = 0.5 * (P + P.T)
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
            self.theta, self.P = theta, P
            self.sigma2 = float(state.get("sigma2", self.sigma2))
            self.n_updates = int(state.get("n_updates", 0))
        except (KeyError, TypeError, ValueError):
            return
