"""High-gain observer of through-water velocity and water current (algorithms.md §3.1).

Kim, Fan & Bose, IEEE Access 6 (2018), eq. (10)-(16), with the increasing-gain law of
Alessandri & Rossi, Automatica 49 (2013) (:mod:`.hgo`). The observer runs the same vehicle
model as the joint Kalman filter (:mod:`.current_kf`) on its own copy of ``x = [nu_r (body),
V_c (earth)]``, with the model coefficients the filter identifies, and corrects it with the
output injection ``G(gamma) (y - C x_hat)`` (Kim eq. 11) written in that state
(:func:`.hgo.current_hgo_gain`). The covariance is propagated for this gain (Joseph form),
so the one-sigma is that of the observer actually running.
"""

from __future__ import annotations

import math

import numpy as np

from onboard.estimators.current_kf import MeasurementKind, inv_small
from onboard.estimators.hgo import GainDesign, IncreasingGain, current_hgo_gain
from onboard.estimators.vehicle_models import ModelInputs, RegressionModel

DIVERGED_ABOVE = 50.0
"""m/s: a state component above this (or a non-finite one) is a divergence."""


class CurrentHighGainObserver:
    """Kim et al.'s model-based high-gain observer of ``[nu_r, V_c]``.

    Attributes (filterpy style):
        x: state ``[nu_r (m/s, body), V_c (m/s, earth)]``.
        P: covariance of the state's error under this gain.
        y: last velocity innovation (m/s, the measurement's axes).
        S: its covariance ``H P H^T + std^2 I`` before the correction (m^2/s^2).
        nis: its normalized innovation squared (NaN if ``S`` is singular).
        gamma: the gain used by the last correction (the initial one before any).
        gamma_init: the gain the law starts from (and restarts from).
        law: the :class:`.IncreasingGain` law.
        counters: event counts (``hgo_diverged``), shared with the owner's health.
    """

    def __init__(self, model: RegressionModel, design: GainDesign, law: IncreasingGain,
                 P0: np.ndarray, *, accel_std: float, model_error_time_s: float,
                 current_walk: float, counters: dict[str, float] | None = None) -> None:
        """Args:
            model: the regression model.
            design: the LMI gain (its first channel's chain gain ``k1, k2`` is used on each
                earth axis).
            law: the increasing-gain law (``gamma``).
            P0: initial covariance of ``[nu_r, V_c]`` (copied).
            accel_std: model acceleration error per DOF (m/s^2 over
                ``model_error_time_s``).
            model_error_time_s: correlation time of the model error (s).
            current_walk: random walk of the current (m/s per sqrt(s)).
            counters: event counts to add to (a new dict by default).
        """
        self.model = model
        self.nd = nd = model.nd
        self.accel_std = accel_std
        self.model_error_time_s = model_error_time_s
        self.current_walk = current_walk
        self.counters: dict[str, float] = counters if counters is not None else {}
        self._k = design.chain_gain(0) / design.time_scale_s ** np.arange(1, 3)
        self.law = law
        self.gamma = self.gamma_init = law.gamma
        self.x = np.zeros(2 * nd)
        self.P = np.array(P0, float)
        self.y = np.zeros(nd)
        self.S = np.eye(nd)
        self.nis = 0.0
        self._J = -np.eye(nd)

    def restart(self, x: np.ndarray, P: np.ndarray) -> None:
        """Take ``[nu_r, V_c]`` and its covariance from the leading block of ``x`` and ``P``
        (the joint filter's)."""
        o = 2 * self.nd
        self.x = x[:o].copy()
        self.P = P[:o, :o].copy()

    def reset_gain(self) -> None:
        """Restart the increasing-gain law from ``gamma_init``."""
        self.law.gamma = self.gamma_init

    def predict(self, dt: float, inputs: ModelInputs, thetas: list[np.ndarray],
                q_scale: float) -> None:
        """Run the model over ``dt`` (s) (Kim eq. 11, model part) with coefficients
        ``thetas``; the covariance with process noise scaled by ``q_scale``."""
        nd = self.nd
        nu = self.x[:nd]
        _, f, J = self.model.linearize(nu.tolist(), inputs, [t.tolist() for t in thetas[:nd]])
        self._J = J = np.array(J)
        self.x[:nd] = nu + dt * np.array(f)
        F = np.eye(2 * nd)
        F[:nd, :nd] += dt * J
        q = np.concatenate([np.full(nd, self.accel_std ** 2 * self.model_error_time_s
                                    * q_scale), np.full(nd, self.current_walk ** 2)])
        self.P = F @ self.P @ F.T + np.diag(q * dt)

    def update(self, kind: MeasurementKind, z: np.ndarray, std: float, dt_meas: float,
               R: np.ndarray, inputs: ModelInputs) -> bool:
        """Output injection ``G(gamma) (y - C x_hat)`` (Kim eq. 11) for one velocity sample
        over ``dt_meas`` (s), with the increasing-gain law; the covariance of this gain in
        Joseph form. Water track is skipped (no current in it); an over-ground velocity
        with fewer components than the state (GNSS SOG/COG at the surface: north and east)
        corrects through those components only.

        Args:
            kind: ``earth`` (over ground, earth axes) or ``bottom`` (over ground, body axes).
            z: the measurement (m/s).
            std: its one-sigma per component (m/s).
            dt_meas: time since the previous measurement (s).
            R: body-to-earth rotation.
            inputs: the model inputs (body rates for the gain).

        Returns False if the state diverged (it is left as it was; restart it).
        """
        nd = self.nd
        m = len(z)
        if kind == "water" or (kind == "bottom" and m != nd):
            return True
        H = (np.hstack([R, np.eye(nd)]) if kind == "earth"
             else np.hstack([np.eye(nd), R.T]))[:m]
        y = z - H @ self.x
        self.y = y
        self.S = S = H @ self.P @ H.T + std * std * np.eye(m)
        Sinv = inv_small(S)
        self.nis = float(y @ Sinv @ y) if Sinv is not None else math.nan
        e_earth = y if kind == "earth" else R @ y
        gamma = self.law.update(dt_meas, float(e_earth @ e_earth) / (std * std) / m)
        self.gamma = gamma
        G = current_hgo_gain(float(self._k[0]), float(self._k[1]), gamma, self._J, R,
                             np.array([inputs.p, inputs.q, inputs.r]))
        K = G[:, :m] * dt_meas if kind == "earth" else (G * dt_meas) @ R
        x_new = self.x + K @ y
        IKH = np.eye(2 * nd) - K @ H
        P_new = IKH @ self.P @ IKH.T + (K * std * std) @ K.T
        if not (np.all(np.isfinite(x_new)) and float(np.max(np.abs(x_new))) < DIVERGED_ABOVE):
            self.counters["hgo_diverged"] = self.counters.get("hgo_diverged", 0) + 1
            return False
        self.x, self.P = x_new, P_new
        return True

    def current_cov(self) -> np.ndarray:
        """Covariance of the current (m^2/s^2, earth axes), a copy."""
        nd = self.nd
        return self.P[nd:, nd:].copy()

    def current_estimate(self) -> tuple[list[float], list[float], list[float]]:
        """(current (m/s, earth), its one-sigma (m/s), ``nu_r`` (m/s, body)) as lists."""
        nd = self.nd
        return (self.x[nd:].tolist(), np.sqrt(np.maximum(self.P.diagonal()[nd:], 0.0)).tolist(),
                self.x[:nd].tolist())
