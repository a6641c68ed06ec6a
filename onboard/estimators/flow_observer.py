"""Nonlinear observer of the flow-relative velocity from the attitude (Fan et al.).

Source: Fan, Xu, Chen & Zhang, "Nonlinear observer design for current estimation based on
underwater vehicle dynamic model", OCEANS (~2016), eq. (5)-(8); algorithms.md §4. The
vehicle model is written in flow-relative variables (Thomasson & Woolsey 2013; for the
near-uniform flow of the paper the gradient terms are ~1e-3 of the damping, algorithms.md
§4.1, so the uniform-flow relative-velocity model is used).

Observer (Fan eq. 7) on the horizontal-plane state ``z = [psi, r, v_r]``::

    z_hat' = f(z_hat, u_r, u) + L (psi_meas - psi_hat)

with ``psi' = r``, ``r' = phi_yaw^T theta_yaw`` and ``v_r' = phi_sway^T theta_sway`` from
:mod:`.vehicle_models` (the yaw equation carries the Munk and fin moments ``N_uv u v``,
which is what makes ``v_r`` visible in the heading). The gain ``L`` places the poles of the
linearization ``A - L C`` (Fan: "optimized by pole placement") by Ackermann's formula,
recomputed each step at the current through-water speed.

Measurement: the paper's observer has the 9-state ``x = [phi, theta, psi, u_r, v_r, w_r, p,
q, r]`` and measures the three Euler angles, roll, pitch and yaw (Fan eq. 7 with ``C = [I_3
0]``, §III). This implementation is reduced to the horizontal plane, ``z = [psi, r, v_r]``,
and measures the heading only (``C = [1 0 0]``); the heave and pitch/roll channels, which in
the paper make ``w_r`` (and through the pitch moment ``u_r``) visible, are not observed here.
With ``pitch = True`` (``[pipelines.current.flow] pitch``) the vertical block ``zv =
[theta, q, w_r]`` is added with the measured pitch as a second output (its own Ackermann
gain), its pitch channel (:data:`PITCH_TERMS`) identified by RLS
(:meth:`FlowObserver.identify_pitch`); roll is not observed. The vertical block leaves the
north and east current as they are and makes down worse than the joint filter's ``w_r``
(docs/current.md, "Flow observer"), so the heading-only reduction is the default. The
surge speed through water ``u_r`` is not observable from the attitude on a straight line;
it is the surge model run open loop, as in the WVAM (Randeni et al. 2017). The current is then ``V_c = R (v_g - nu_r)`` (Fan, §III.A).

The covariance of ``z`` is propagated for this gain (Joseph form, heading noise
``psi_std``), so the reported one-sigma belongs to this observer. The current's one-sigma
adds the over-ground velocity's measurement noise.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from onboard.core.geo import wrap_pi
from onboard.estimators.model_identification import StateVariableFilter
from onboard.estimators.rls import RecursiveLeastSquares
from onboard.estimators.vehicle_models import ModelInputs, RegressionModel

PITCH_TERMS = ("q", "q|q|", "uw", "uq", "u|u|ds", "sin(theta)")
"""Regressors of the pitch channel of the vertical block (``pitch = True``):
``q' = phi_pitch^T theta_pitch`` with linear and quadratic pitch damping, the Munk moment
``M_uw u w``, the fins' damping ``u q`` and lift ``u|u| ds``, and the restoring moment
``sin(theta)`` (centre of gravity below the centre of buoyancy), all over ``I_yy - M_qdot``
(the torpedo model of :mod:`.vehicle_models` has no pitch channel: pitch is an input to
Kim et al.'s 3-DOF model)."""


def pitch_regressors(u: float, w: float, x: ModelInputs) -> tuple[float, ...]:
    """:data:`PITCH_TERMS` at surge and heave speed through water ``u``, ``w`` (m/s), pitch
    rate ``x.q`` (rad/s), pitch ``x.pitch`` (rad) and stern plane ``x.ds`` (rad)."""
    q = x.q
    return (q, q * abs(q), u * w, u * q, u * abs(u) * x.ds, math.sin(x.pitch))

POLE_FACTORS = (1.5, 1.7, 1.9)
"""Default pole placement: the open-loop eigenvalues' real parts (floored at -0.5 1/s for the
heading integrator) times these factors, re-placed at each step. Fixed poles slower than the
vehicle's own sway/yaw modes (e.g. -0.6, -0.8, -1.0 against -1.9 and -1.4 for the spheroid)
need large gains of the wrong sign to slow the dynamics down, and the observer diverges at
the heading switches of a zig-zag (docs/current.md, "Flow observer")."""


def ackermann_observer_gain(A: np.ndarray, C: np.ndarray, poles: Sequence[float]) -> np.ndarray:
    """``L`` such that ``eig(A - L C) = poles`` for a single output (Ackermann, dual form).

    Raises numpy.linalg.LinAlgError when ``(A, C)`` is not observable.
    """
    n = A.shape[0]
    O = np.vstack([C @ np.linalg.matrix_power(A, k) for k in range(n)])
    coeffs = np.poly(poles)  # s^n + a1 s^(n-1) + ... + an
    phi = np.zeros((n, n))
    for k, a in enumerate(coeffs):
        phi += a * np.linalg.matrix_power(A, n - k)
    e_n = np.zeros(n)
    e_n[-1] = 1.0
    return phi @ np.linalg.solve(O, e_n)


OUTPUT_ROW = np.array([[1.0, 0.0, 0.0]])
"""``C``: each block measures its first state (the heading, or the pitch)."""
POLE_FLOOR = -0.5
"""1/s: the open-loop eigenvalues' real parts are floored here before :data:`POLE_FACTORS`
scales them (the heading and pitch integrators have eigenvalue 0)."""
DIFF_STEP = 1e-4
"""Step of the forward differences of the linearization (state units)."""
INTEGRATION_STEP_S = 0.05
"""Longest explicit-Euler sub-step (s) of the observer's integration."""
Z_COV0 = (0.01, 0.01, 0.25)
"""Initial covariance diagonal of each block: (rad^2, rad^2/s^2, m^2/s^2)."""
U_VAR0 = 0.25
"""Initial variance of ``u_r`` (m^2/s^2)."""
MAX_GAIN = 50.0
"""A placed gain above this (per entry) is refused and the previous gain kept."""
PITCH_RLS_FORGETTING = 0.9995
"""Forgetting factor of the pitch channel's RLS per update."""
PITCH_RLS_P0 = 1e6
"""Initial covariance of the pitch channel's RLS (its regressors are small, the data must
rule)."""
PITCH_RLS_SIGMA2_0 = 1e-3
"""Initial equation-error variance of the pitch channel's RLS ((rad/s^2)^2)."""
RUNAWAY_SPEED = (3.0, 10.0)
"""A block's relative velocity (sway or heave) above the first, or ``u_r`` above the
second (m/s), is a divergence."""


def forward_difference_jacobian(f: Callable[[np.ndarray], np.ndarray],
                                z: np.ndarray) -> np.ndarray:
    """``A = df/dz`` at ``z`` by forward differences of step :data:`DIFF_STEP`; ``f`` is
    called at ``z`` first, then at each perturbed state in turn."""
    f0 = f(z)
    A = np.empty((len(z), len(z)))
    for j in range(len(z)):
        dz = np.zeros(len(z))
        dz[j] = DIFF_STEP
        A[:, j] = (f(z + dz) - f0) / DIFF_STEP
    return A


def placed_gain(A: np.ndarray, poles: Sequence[float] | None,
                max_gain: float) -> np.ndarray | None:
    """The observer gain ``L`` with ``eig(A - L C) = poles`` (:func:`ackermann_observer_gain`,
    ``C`` = :data:`OUTPUT_ROW`); ``poles`` None: the real parts of ``eig(A)`` floored at
    :data:`POLE_FLOOR`, times :data:`POLE_FACTORS`. None when ``(A, C)`` is not observable
    or a gain is not finite or above ``max_gain``."""
    try:
        if poles is None:
            re = np.sort(np.minimum(np.linalg.eigvals(A).real, POLE_FLOOR))
            poles = tuple(re * np.array(POLE_FACTORS))
        L = ackermann_observer_gain(A, OUTPUT_ROW, poles)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(L)) or np.max(np.abs(L)) > max_gain:
        return None
    return L


def propagate_gain_covariance(P: np.ndarray, A: np.ndarray, L: np.ndarray, dt: float,
                              accel_std: float, meas_std: float) -> np.ndarray:
    """Covariance of a block under its gain over ``dt`` (s): ``z' = (A - L C) z + w - L n``,
    so ``P <- F P F^T + Q`` with ``F = I + dt (A - L C)``, ``Q = diag(0, q, q) +
    L L^T (meas_std dt)^2`` and ``q = accel_std^2 dt``."""
    Acl = A - np.outer(L, OUTPUT_ROW[0])
    F = np.eye(3) + dt * Acl
    q = accel_std ** 2 * dt
    Q = np.diag([0.0, q, q]) + np.outer(L, L) * (meas_std * dt) ** 2
    return F @ P @ F.T + Q


class FlowObserver:
    """Fan et al.'s observer of the flow-relative velocity, and the current from it.

    Attributes (filterpy style):
        z: state ``[psi (rad), r (rad/s), v_r (m/s)]``.
        u_r: surge speed through water (m/s), the surge model run open loop.
        w_r: heave speed through water (m/s), taken from the caller.
        Pz: covariance of ``z`` under the gain ``L``.
        var_u: variance of ``u_r`` (m^2/s^2).
        L: the observer gain (pole placement).
        e: last heading innovation (rad).
        S: its variance ``Pz[0, 0] + psi_std^2`` before the correction (rad^2).
        nis: its normalized innovation squared ``e^2 / S``.
        heading_updates: steps corrected by a measured heading (each one sets ``e``,
            ``S`` and ``nis``).
        ready: False until the first step (and after a divergence).
        v_g: newest velocity over ground in body axes (m/s; None before the first).
        v_g_kind: its measurement kind (``earth``, ``bottom`` or ``water``).
        v_g_std: its one-sigma per component (m/s).
        unobservable: steps whose pole placement failed (the previous gain was kept), both
            blocks.
        pitch: whether the vertical block runs.
        zv: its state ``[theta (rad), q (rad/s), w_r (m/s)]``; ``Pv`` its covariance,
            ``Lv`` its gain.
        pitch_rls: the pitch channel's :class:`.rls.RecursiveLeastSquares`
            (:data:`PITCH_TERMS`).
        diverged: divergences (each restarts the observer from the caller's velocity).
    """

    def __init__(self, model: RegressionModel, poles: Sequence[float] | None = None,
                 psi_std: float = 0.005, accel_std: float = 0.02, pitch: bool = False,
                 svf_cutoff_hz: float = 0.3) -> None:
        """Args:
            model: the regression model (it needs a yaw channel).
            poles: fixed observer poles (1/s, negative); None: placed from the open-loop
                eigenvalues times :data:`POLE_FACTORS` at each step.
            psi_std: heading (and pitch) measurement one-sigma (rad).
            accel_std: model acceleration error (m/s^2) of the yaw rate and sway channels.
            pitch: add the vertical block ``[theta, q, w_r]`` observed from the measured
                pitch (3-D models only; :meth:`identify_pitch` identifies its pitch
                channel); False: ``w_r`` from the caller.
            svf_cutoff_hz: cut-off of the pitch channel's state-variable filter (Hz).
        """
        if "yaw" not in model.channels:
            raise ValueError("the flow observer needs a model with a yaw channel")
        self.model = model
        self.poles = tuple(poles) if poles else None
        self.psi_std = psi_std
        self.accel_std = accel_std
        self.z = np.zeros(3)
        self.u_r = 0.0
        self.w_r = 0.0
        self.Pz = np.diag(Z_COV0)
        self.var_u = U_VAR0
        self.L = np.zeros(3)
        self.e = 0.0
        self.S = psi_std * psi_std
        self.nis = 0.0
        self.heading_updates = 0
        self.ready = False
        self.v_g: np.ndarray | None = None
        self.v_g_kind = ""
        self.v_g_std = 0.0
        self.unobservable = 0
        self.diverged = 0
        self.max_gain = MAX_GAIN
        self._iyaw = model.channels.index("yaw")
        self.pitch = pitch and model.nd == 3
        self.zv = np.zeros(3)
        self.Pv = np.diag(Z_COV0)
        self.Lv = np.zeros(3)
        self.pitch_rls = RecursiveLeastSquares(
            len(PITCH_TERMS), forgetting=PITCH_RLS_FORGETTING, p0=PITCH_RLS_P0,
            names=PITCH_TERMS, sigma2_0=PITCH_RLS_SIGMA2_0)
        self.pitch_svf = StateVariableFilter(1 + len(PITCH_TERMS), svf_cutoff_hz)

    def identify_pitch(self, dt: float, nu: Sequence[float], x: ModelInputs,
                       learn: bool) -> None:
        """One RLS step of the pitch channel, ``q' = phi_pitch^T theta_pitch``, both sides
        through the state-variable filter (as the yaw channel, algorithms.md §3.4), at the
        through-water velocity ``nu`` (m/s, the caller's) and the measured pitch rate
        ``x.q``; ``learn`` False: filter only."""
        if not self.pitch or dt <= 0:
            return
        phi = pitch_regressors(float(nu[0]), float(nu[2]), x)
        self.pitch_svf.update(dt, (x.q,) + phi)
        if learn:
            self.pitch_rls.update(self.pitch_svf.y[1:], self.pitch_svf.dy[0])

    def _fv(self, zv: np.ndarray, u: float, v: float, x: ModelInputs,
            thetas: Sequence[np.ndarray], th_pitch: np.ndarray) -> np.ndarray:
        """Vertical block ``[theta' = q cos(phi) - r sin(phi), q', w_r']`` at ``zv``."""
        q_meas, pitch_meas = x.q, x.pitch
        x.q, x.pitch = float(zv[1]), float(zv[0])
        wdot = self.model.accel([u, v, float(zv[2])], x, thetas)[2]
        qdot = float(np.dot(pitch_regressors(u, float(zv[2]), x), th_pitch))
        x.q, x.pitch = q_meas, pitch_meas
        return np.array([zv[1] * math.cos(x.roll) - self.z[1] * math.sin(x.roll), qdot, wdot])

    def _step_vertical(self, dt: float, x: ModelInputs, thetas: Sequence[np.ndarray]) -> None:
        """The vertical block's pole placement, integration with the pitch innovation held,
        and covariance (as the horizontal block in :meth:`step`)."""
        th = self.pitch_rls.theta
        u, v = self.u_r, float(self.z[2])
        A = forward_difference_jacobian(lambda zv: self._fv(zv, u, v, x, thetas, th), self.zv)
        L = placed_gain(A, None, self.max_gain)
        if L is None:
            self.unobservable += 1
        else:
            self.Lv = L
        n_sub = max(1, math.ceil(dt / INTEGRATION_STEP_S))
        h = dt / n_sub
        for _ in range(n_sub):
            e = x.pitch - self.zv[0]
            self.zv = self.zv + h * (self._fv(self.zv, u, v, x, thetas, th) + self.Lv * e)
        self.Pv = propagate_gain_covariance(self.Pv, A, self.Lv, dt, self.accel_std,
                                            self.psi_std)
        self.w_r = float(self.zv[2])

    def _f(self, z: np.ndarray, u: float, x: ModelInputs,
           thetas: Sequence[np.ndarray]) -> np.ndarray:
        nd = self.model.nd
        nu = [u, z[2], self.w_r][:nd]
        x.r = z[1]
        phis = self.model.regressors(nu, x)
        return np.array([z[1], phis[self._iyaw] @ thetas[self._iyaw], phis[1] @ thetas[1]])

    def step(self, dt: float, psi_meas: float | None, x: ModelInputs,
             thetas: Sequence[np.ndarray], nu_init: np.ndarray) -> None:
        """Advance by ``dt`` (s) and correct with the measured heading ``psi_meas`` (rad):
        pole placement at the linearization, Fan eq. (7) integrated, the surge model open
        loop, the covariance under the gain. ``x`` the model inputs (``x.r`` the measured
        yaw rate, restored on return), ``thetas`` the model coefficients, ``nu_init`` the
        caller's through-water velocity (m/s: the start, and ``w_r`` without the vertical
        block)."""
        if psi_meas is None:
            return
        if not self.ready:
            self._start(psi_meas, x, nu_init)
            return
        if dt <= 0:
            return
        r_meas = x.r
        nd = self.model.nd
        # surge open loop (WVAM); heave from the caller (not observed by the heading) or
        # from the vertical block
        if not self.pitch:
            self.w_r = float(nu_init[2]) if len(nu_init) > 2 else 0.0
        fu = self.model.accel([self.u_r, self.z[2], self.w_r][:nd], x, thetas)[0]
        # linearization and pole placement
        A = forward_difference_jacobian(lambda z: self._f(z, self.u_r, x, thetas), self.z)
        L = placed_gain(A, self.poles, self.max_gain)
        if L is None:
            self.unobservable += 1  # keep the previous gain
        else:
            self.L = L
        x.r = r_meas
        self._integrate(dt, psi_meas, x, thetas)
        x.r = r_meas
        if self.pitch:
            self._step_vertical(dt, x, thetas)
        self.u_r += dt * fu
        if self._runaway():
            self._restart_after_divergence()
            return
        self.Pz = propagate_gain_covariance(self.Pz, A, self.L, dt, self.accel_std,
                                            self.psi_std)
        # var(u_r) <- (1 + dt df_u/du)^2 var(u_r) + q, the surge model open loop
        J = self.model.jacobian(np.array([self.u_r, self.z[2], self.w_r][:nd]), x, thetas)
        a = 1.0 + dt * J[0, 0]
        self.var_u = a * a * self.var_u + self.accel_std ** 2 * dt

    def _start(self, psi_meas: float, x: ModelInputs, nu_init: np.ndarray) -> None:
        """Start at the measured heading (rad) and yaw rate, the caller's through-water
        velocity ``nu_init`` (m/s) and the measured pitch and pitch rate."""
        self.z = np.array([psi_meas, x.r, float(nu_init[1])])
        self.u_r = float(nu_init[0])
        self.w_r = float(nu_init[2]) if len(nu_init) > 2 else 0.0
        self.zv = np.array([x.pitch, x.q, self.w_r])
        self.Pv = np.diag(Z_COV0)
        self.ready = True

    def _integrate(self, dt: float, psi_meas: float, x: ModelInputs,
                   thetas: Sequence[np.ndarray]) -> None:
        """Fan eq. (7), ``z' = f(z, u_r, u) + L (psi_meas - psi)``, by explicit Euler over
        ``dt`` (s) with the heading measurement held; the innovation, its variance and NIS
        at the start of the step."""
        n_sub = max(1, math.ceil(dt / INTEGRATION_STEP_S))
        h = dt / n_sub
        self.e = wrap_pi(psi_meas - self.z[0])
        self.S = float(self.Pz[0, 0]) + self.psi_std * self.psi_std
        self.nis = self.e * self.e / self.S if self.S > 0.0 else 0.0
        self.heading_updates += 1
        for _ in range(n_sub):
            e = wrap_pi(psi_meas - self.z[0])
            self.z = self.z + h * (self._f(self.z, self.u_r, x, thetas) + self.L * e)
            self.z[0] = wrap_pi(self.z[0])

    def _runaway(self) -> bool:
        """A non-finite state or a relative velocity beyond :data:`RUNAWAY_SPEED`."""
        v_max, u_max = RUNAWAY_SPEED
        return not (np.all(np.isfinite(self.z)) and abs(self.z[2]) < v_max
                    and np.all(np.isfinite(self.zv)) and abs(self.zv[2]) < v_max
                    and math.isfinite(self.u_r) and abs(self.u_r) < u_max)

    def _restart_after_divergence(self) -> None:
        """Count a divergence; the next step restarts from the caller's velocity."""
        self.diverged += 1
        self.ready = False
        self.Pz = np.diag(Z_COV0)
        self.var_u = U_VAR0

    def nu_r(self, nd: int) -> np.ndarray:
        """Through-water velocity ``[u_r, v_r(, w_r)]`` (m/s, body)."""
        return np.array([self.u_r, self.z[2], self.w_r][:nd])

    def nu_cov(self, nd: int) -> np.ndarray:
        """Covariance of :meth:`nu_r` (u_r and v_r uncorrelated here)."""
        C = np.zeros((nd, nd))
        C[0, 0] = self.var_u
        C[1, 1] = self.Pz[2, 2]
        if nd == 3:
            C[2, 2] = self.Pv[2, 2] if self.pitch else 0.01 ** 2
        return C

    def observe_velocity(self, kind: str, z: np.ndarray, std: float, R: np.ndarray,
                         v_g_estimate: np.ndarray | None = None) -> None:
        """Keep the newest velocity measurement ``z`` (m/s, one-sigma ``std``) in body axes
        for :meth:`current`; ``R`` the body-to-earth rotation. An earth-axes measurement
        without the vertical (GNSS at the surface) takes its vertical from ``v_g_estimate``
        (m/s, earth axes: the joint filter's velocity over ground)."""
        if kind == "earth":
            nd = self.model.nd
            zz = np.zeros(nd)
            zz[: len(z)] = z
            if len(z) < nd and v_g_estimate is not None:
                zz[2:] = v_g_estimate[2:]
            self.v_g = R.T @ zz
        else:
            self.v_g = z.copy()
        self.v_g_kind = kind
        self.v_g_std = std

    def current(self, R: np.ndarray) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
        """(current, its one-sigma, ``nu_r``), Fan et al.: ``V_c = R (v_g - nu_r)`` (m/s,
        earth) from the newest velocity over ground; the current is None after a water-track
        measurement (through water: no current in it). ``R`` the body-to-earth rotation.
        Raises ValueError before the first :meth:`observe_velocity`."""
        nd = self.model.nd
        if self.v_g is None:
            raise ValueError("no velocity over ground observed yet")
        nu = self.nu_r(nd)
        c = R @ (self.v_g - nu) if self.v_g_kind != "water" else None
        std = np.sqrt(np.maximum(np.diag(R @ self.nu_cov(nd) @ R.T), 0.0) + self.v_g_std ** 2)
        return c, std, nu
