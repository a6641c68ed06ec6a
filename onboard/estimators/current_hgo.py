"""High-gain observer of through-water velocity and water current (algorithms.md §3.1).

Kim, Fan & Bose, IEEE Access 6 (2018), eq. (10)-(16), with the increasing-gain law of
Alessandri & Rossi, Automatica 49 (2013) (:mod:`.hgo`). The observer runs the same vehicle
model as the joint Kalman filter (:mod:`.current_kf`) on its own copy of ``x = [nu_r (body),
V_c (earth)]``, with the coefficients its caller passes to :meth:`predict` (in the pipeline
those of the observer's own RLS, :class:`.model_identification.VelocityRls`, not the joint
filter's), and corrects it with the
output injection ``G(gamma) (y - C x_hat)`` (Kim eq. 11) written in that state
(:func:`.hgo.current_hgo_gain`). The covariance is propagated for this gain (Joseph form),
so the one-sigma is that of the observer actually running.

The model's coefficients are uncertain: their covariance (:meth:`consider`, from the
observer's own identification) is carried as consider parameters (Schmidt 1966): the
coefficient error ``dtheta`` drives ``nu_r`` through the regressors, ``nu_r' += Phi^T
dtheta``, and the cross-covariance ``C = E[x_err dtheta^T]`` is propagated beside ``P``;
the gain is unchanged (it is the LMI design, not a Kalman gain), so only the published
one-sigma sees them (docs/current.md, "The HGO's sigma").

The one-sigma swings with the phase of the held sample (a new sample's step rings through
the observer's poles, ``gamma sqrt(k2)`` rad/s); whether a component is known is decided on
its largest one-sigma over the last ``SIGMA_PEAK_WINDOW_S`` (:meth:`current_std_peak`), not
on the trough the tick happens to fall in.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from onboard.estimators.current_kf import MeasurementKind
from onboard.estimators.hgo import GainDesign, IncreasingGain, current_hgo_gain
from onboard.estimators.kalman import inv_small
from onboard.estimators.vehicle_models import ModelInputs, RegressionModel

DIVERGED_ABOVE = 50.0
"""m/s: a state component above this (or a non-finite one) is a divergence."""

HOLD_MAX_S = 1.0
"""s: a velocity sample is injected (held) for at most this long; without a newer one the
observer then runs on the model alone (a GNSS or DVL gap)."""

SIGMA_PEAK_WINDOW_S = HOLD_MAX_S
"""s: :meth:`CurrentHighGainObserver.current_std_peak` is the largest current one-sigma over
this window, the longest a sample is held: at least one whole cycle of the held samples
(docs/current.md, "The HGO at its own design rpm")."""


def repeated_step(F: np.ndarray, U: np.ndarray, q: np.ndarray, n: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` steps of ``e <- F e + U w + v`` with ``w`` held constant and ``v`` white of
    covariance ``diag(q)`` added after each step: ``(F^n, sum_k F^k U, sum_k F^k diag(q)
    F^kT)`` (``k`` from 0 to ``n - 1``), by repeated squaring (``~2 log2 n`` compositions
    instead of ``n`` steps)."""
    m = len(F)
    res = (np.eye(m), np.zeros_like(U), np.zeros((m, m)))
    base = (F, U, np.diag(q))
    while True:
        if n & 1:
            res = _then(res, base)
        n >>= 1
        if not n:
            return res
        base = _then(base, base)


def _then(a: tuple[np.ndarray, np.ndarray, np.ndarray],
          b: tuple[np.ndarray, np.ndarray, np.ndarray]
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segment ``a`` followed by segment ``b`` (:func:`repeated_step`'s triples)."""
    Fa, Ua, Qa = a
    Fb, Ub, Qb = b
    return Fb @ Fa, Fb @ Ua + Ub, Fb @ Qa @ Fb.T + Qb


class CurrentHighGainObserver:
    """Kim et al.'s model-based high-gain observer of ``[nu_r, V_c]``.

    Attributes (filterpy style):
        x: state ``[nu_r (m/s, body), V_c (m/s, earth)]``.
        P: covariance of the state's error under this gain from the noises (measurement,
            model acceleration, current walk).
        P_model: the part the coefficients' uncertainty adds (:meth:`consider`); the
            published covariance is ``P + P_model`` (:meth:`covariance`).
        theta_cov: covariance of the model coefficients (consider parameters, the
            concatenated velocity DOFs' coefficients; None: known exactly).
        y: last velocity innovation (m/s, the measurement's axes).
        S: its covariance ``H (P + P_model) H^T + std^2 I`` before the correction
            (m^2/s^2).
        nis: its normalized innovation squared (NaN if ``S`` is singular).
        gamma: the gain used by the last correction (the initial one before any).
        gamma_init: the gain the law starts from (and restarts from).
        law: the :class:`.IncreasingGain` law.
        diverged: divergences so far (a prediction or innovation beyond bounds; the
            owner restarts it).
        clock: time integrated by :meth:`predict` (s).
    """

    def __init__(self, model: RegressionModel, design: GainDesign, law: IncreasingGain,
                 P0: np.ndarray, *, accel_std: float, model_error_time_s: float,
                 current_walk: float, innovation_max: float = 1.0) -> None:
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
            innovation_max: saturation of the injected innovation (m/s per component,
                anti-peaking).
        """
        self.model = model
        self.nd = nd = model.nd
        self.accel_std = accel_std
        self.model_error_time_s = model_error_time_s
        self.current_walk = current_walk
        self.diverged = 0
        self._k = design.chain_gain(0) / design.time_scale_s ** np.arange(1, 3)
        self.law = law
        self.gamma = self.gamma_init = law.gamma
        self.x = np.zeros(2 * nd)
        self.P = np.array(P0, float)
        self.P_model = np.zeros_like(self.P)
        self.y = np.zeros(nd)
        self.S = np.eye(nd)
        self.nis = 0.0
        self.innovation_max = innovation_max
        self._J = -np.eye(nd)
        # the held sample (z, H, G, noise variance), its age (s), and the sensitivity of
        # the state to the held sample's noise
        self._hold: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None
        self._hold_age = 0.0
        self._psi = np.zeros((2 * nd, nd))
        self.theta_cov: np.ndarray | None = None
        # cross-covariance of the state's error with the coefficients' error
        self._C: np.ndarray | None = None
        self.clock = 0.0
        # (clock (s), current variances (m^2/s^2)) after each prediction, the last
        # SIGMA_PEAK_WINDOW_S of them
        self._current_vars: deque[tuple[float, np.ndarray]] = deque()

    def consider(self, cov: np.ndarray, *, fresh: bool = False) -> None:
        """Take ``cov`` as the covariance of the coefficients passed to :meth:`predict`
        (consider parameters; concatenated in DOF order). A new covariance of the same
        coefficients (an identification update ``dtheta+ = M dtheta``, ``M = cov
        cov_old^-1`` for RLS) carries the cross-covariance along: ``C <- C M^T``; with
        ``fresh`` (other coefficients, e.g. a restored model) it starts from zero."""
        cov = np.array(cov, float)
        old, C = self.theta_cov, self._C
        if fresh or C is None or old is None or old.shape != cov.shape:
            self._C = np.zeros((2 * self.nd, len(cov)))
        elif not np.array_equal(old, cov):
            try:
                self._C = np.linalg.solve(old, C.T).T @ cov  # C old^-1 cov (symmetric)
            except np.linalg.LinAlgError:
                self._C = np.zeros_like(C)
        self.theta_cov = cov

    def restart(self, x: np.ndarray, P: np.ndarray) -> None:
        """Take ``[nu_r, V_c]`` and its covariance from the leading block of ``x`` and ``P``
        (the joint filter's)."""
        o = 2 * self.nd
        self.x = x[:o].copy()
        self.P = P[:o, :o].copy()
        self.P_model = np.zeros_like(self.P)
        self._hold = None
        self._hold_age = 0.0
        self._psi = np.zeros((o, self.nd))
        if self._C is not None:
            self._C = np.zeros_like(self._C)
        self._current_vars.clear()

    def reset_gain(self) -> None:
        """Restart the increasing-gain law from ``gamma_init``."""
        self.law.gamma = self.gamma_init

    def predict(self, dt: float, inputs: ModelInputs, thetas: list[np.ndarray]) -> bool:
        """Integrate Kim eq. (11) over ``dt`` (s): the model with coefficients ``thetas``
        (linearized at the start of the step) plus the output injection ``G(gamma) (y -
        H x_hat)`` of the newest velocity sample, held (zero-order hold) for at most
        ``HOLD_MAX_S``. Sub-steps keep ``h |eig| <= 0.2`` whatever ``gamma``: a high gain is
        integrated, never applied as one discrete jump (``G dt`` is unstable once
        ``gamma k1 dt > 2``). The covariance follows the same linear dynamics; the held
        sample's noise enters every sub-step with the same value, so its contribution is
        carried as ``Psi`` (``x_err += Psi v``) and added as ``Psi r Psi^T``. The
        coefficients' covariance (:meth:`consider`) enters through the regressors ``B =
        [Phi^T; 0]``: per sub-step ``[P C; C^T P_theta] <- F_a [P C; C^T P_theta] F_a^T``,
        ``F_a = [[F, h B], [0, I]]``; the covariances are carried over all sub-steps at once
        (:meth:`_propagate_covariance`). Returns False (state left as it was, counted) on a
        divergence."""
        nd = self.nd
        n = 2 * nd
        nu = self.x[:nd]
        phis, f, J = self.model.linearize(nu.tolist(), inputs,
                                          [t.tolist() for t in thetas[:nd]])
        self._J = Jm = np.array(J)
        A = np.zeros((n, n))
        A[:nd, :nd] = Jm
        b = np.zeros(n)
        b[:nd] = np.array(f) - Jm @ nu
        hold = self._hold
        if hold is not None and self._hold_age > HOLD_MAX_S:
            self._fold_hold()
            hold = None
        G = None
        if hold is not None:
            z, H, G, _var = hold
            A = A - G @ H
            b = b + G @ z
            self._hold_age += dt
        rate = float(np.max(np.sum(np.abs(A), axis=1)))  # >= every |eigenvalue|
        n_sub = max(1, math.ceil(dt * rate / 0.2))
        h = dt / n_sub
        F = np.eye(n) + h * A
        q = np.concatenate([np.full(nd, self.accel_std ** 2 * self.model_error_time_s),
                            np.full(nd, self.current_walk ** 2)]) * h
        x = self.x.copy()
        for _ in range(n_sub):
            x = x + h * (A @ x + b)
        if not (np.all(np.isfinite(x)) and float(np.max(np.abs(x))) < DIVERGED_ABOVE):
            self.diverged += 1
            return False
        self.x = x
        self._propagate_covariance(F, q, n_sub, phis, h * G if G is not None else None, h)
        self._remember_current_var(dt)
        return True

    def _remember_current_var(self, dt: float) -> None:
        """Advance :attr:`clock` by ``dt`` (s) and keep the current's variances of now
        for :meth:`current_std_peak`, dropping those older than ``SIGMA_PEAK_WINDOW_S``."""
        self.clock += dt
        kept = self._current_vars
        kept.append((self.clock, self.covariance().diagonal()[self.nd:].copy()))
        while kept and kept[0][0] < self.clock - SIGMA_PEAK_WINDOW_S:
            kept.popleft()

    def _propagate_covariance(self, F: np.ndarray, q: np.ndarray, n_sub: int,
                              phis: list[tuple[float, ...]], hG: np.ndarray | None,
                              h: float) -> None:
        """``P``, ``Psi`` and the coefficients' cross-covariance ``C`` over ``n_sub``
        sub-steps of ``e <- F e + h B dtheta + h G v + w`` (``cov w = diag(q)``), in closed
        form (:func:`repeated_step`) rather than sub-step by sub-step."""
        nd = self.nd
        C = self._C
        hB = self._coefficient_input(phis, h) if C is not None else None
        inputs = [u for u in (hB, hG) if u is not None]
        U = np.hstack(inputs) if inputs else np.zeros((2 * nd, 0))
        Phi, Gam, Q = repeated_step(F, U, q, n_sub)
        self.P = Phi @ self.P @ Phi.T + Q
        if hB is not None:
            assert C is not None and self.theta_cov is not None
            nt = hB.shape[1]
            PhiC, GPt = Phi @ C, Gam[:, :nt] @ self.theta_cov
            self.P_model = (Phi @ self.P_model @ Phi.T + PhiC @ Gam[:, :nt].T
                            + Gam[:, :nt] @ PhiC.T + GPt @ Gam[:, :nt].T)
            self._C = PhiC + GPt
        if hG is not None:
            self._psi = Phi @ self._psi + Gam[:, U.shape[1] - hG.shape[1]:]

    def _coefficient_input(self, phis: list[tuple[float, ...]], h: float) -> np.ndarray:
        """``h B``: the sensitivity of ``x`` to the coefficients' error over a sub-step of
        ``h`` (s), the regressor of DOF ``i`` on row ``i`` in that DOF's columns."""
        assert self._C is not None
        hB = np.zeros_like(self._C)
        col = 0
        for i, phi in enumerate(phis[: self.nd]):
            hB[i, col:col + len(phi)] = phi
            col += len(phi)
        return h * hB

    def _fold_hold(self) -> None:
        """End the held sample: its noise contribution joins ``P``."""
        if self._hold is not None:
            var = self._hold[3]
            self.P = self.P + var * (self._psi @ self._psi.T)
            self._psi = np.zeros_like(self._psi)
        self._hold = None
        self._hold_age = 0.0

    def update(self, kind: MeasurementKind, z: np.ndarray, std: float, dt_meas: float,
               R: np.ndarray, inputs: ModelInputs) -> bool:
        """A new velocity sample: its innovation, NIS and the increasing-gain law; the
        output injection ``G(gamma) (y - H x_hat)`` (Kim eq. 11) is then held and
        integrated by :meth:`predict`. Water track is skipped (no current in it); an
        over-ground velocity of fewer components than the state (GNSS at the surface:
        north and east) injects on those components only.

        Anti-peaking by saturation (Khalil): the held sample is moved to within
        ``innovation_max`` (m/s per component) of the estimate, so a large initial or
        outlier error meets a bounded injection whatever ``gamma``.

        Args:
            kind: ``earth`` (over ground, earth axes) or ``bottom`` (over ground, body axes).
            z: the measurement (m/s).
            std: its one-sigma per component (m/s).
            dt_meas: time since the previous measurement (s).
            R: body-to-earth rotation.
            inputs: the model inputs (body rates for the gain).

        Returns False if the innovation is not finite (nothing is changed; restart).
        """
        nd = self.nd
        m = len(z)
        if not self.takes(kind, m):
            return True
        H = (np.hstack([R, np.eye(nd)]) if kind == "earth"
             else np.hstack([np.eye(nd), R.T]))[:m]
        y = z - H @ self.x
        if not np.all(np.isfinite(y)) or float(np.max(np.abs(y))) > DIVERGED_ABOVE:
            self.diverged += 1
            return False
        self._fold_hold()
        self.y = y
        var = std * std
        self.S = S = H @ (self.P + self.P_model) @ H.T + var * np.eye(m)
        Sinv = inv_small(S)
        self.nis = float(y @ Sinv @ y) if Sinv is not None else math.nan
        e_earth = y if kind == "earth" else R @ y
        gamma = self.law.update(dt_meas, float(e_earth @ e_earth) / var / m)
        self.gamma = gamma
        G = current_hgo_gain(float(self._k[0]), float(self._k[1]), gamma, self._J, R,
                             np.array([inputs.p, inputs.q, inputs.r]))
        G = G[:, :m] if kind == "earth" else G @ R
        z_held = H @ self.x + np.clip(y, -self.innovation_max, self.innovation_max)
        self._hold = (z_held, H, G, var)
        self._hold_age = 0.0
        self._psi = np.zeros((2 * nd, m))
        return True

    def takes(self, kind: MeasurementKind, m: int) -> bool:
        """Whether :meth:`update` uses a ``kind`` measurement of ``m`` components: neither
        water track (no current in it) nor a bottom track of fewer components than the
        state."""
        return not (kind == "water" or (kind == "bottom" and m != self.nd))

    def covariance(self, model: bool = True) -> np.ndarray:
        """Covariance of ``x`` including the held sample's noise (m^2/s^2) and, with
        ``model``, the coefficients' uncertainty."""
        P = self.P + self.P_model if model else self.P
        if self._hold is None:
            return P
        return P + self._hold[3] * (self._psi @ self._psi.T)

    def current_cov(self, model: bool = True) -> np.ndarray:
        """Covariance of the current (m^2/s^2, earth axes), a copy; ``model`` as
        :meth:`covariance`."""
        nd = self.nd
        return self.covariance(model)[nd:, nd:].copy()

    def current_std_peak(self) -> list[float]:
        """The current's largest one-sigma per earth axis (m/s) over the last
        ``SIGMA_PEAK_WINDOW_S`` of predictions and now, with the coefficients' part."""
        nd = self.nd
        peak = self.covariance().diagonal()[nd:].copy()
        for _, var in self._current_vars:
            peak = np.maximum(peak, var)
        return np.sqrt(np.maximum(peak, 0.0)).tolist()

    def current_estimate(self) -> tuple[list[float], list[float], list[float]]:
        """(current (m/s, earth), its one-sigma (m/s), ``nu_r`` (m/s, body)) as lists."""
        nd = self.nd
        return (self.x[nd:].tolist(),
                np.sqrt(np.maximum(self.covariance().diagonal()[nd:], 0.0)).tolist(),
                self.x[:nd].tolist())
