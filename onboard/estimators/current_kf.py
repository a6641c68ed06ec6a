"""Joint Kalman filter of through-water velocity, water current and model coefficients
(algorithms.md §3).

Kim, Fan & Bose, IEEE Access 6 (2018) compute ``V_c = v_OG - R nu_r`` (their eq. 1) with
``nu_r`` from a model-based observer. Here the current is a state of its own, estimated
jointly with the through-water velocity and the coefficients of the vehicle model::

    x = [nu_r (body, nd), V_c (earth, nd), theta]     nd = 3 submerged, 2 surface vehicles
    nu_r'  = f(nu_r, omega, attitude, u; theta)       regression model, vehicle_models.py
    V_c'   = w_c                                      slowly varying (random walk)
    theta' = 0                                        forgetting on its covariance (rls.py)

Velocity measurements (each with its own noise), ``R`` the body-to-earth rotation:

* velocity over ground, earth axes (GNSS SOG/COG, an INS): ``z = R nu_r + V_c`` (Kim eq. 1);
* DVL bottom track, body axes: ``z = nu_r + R^T V_c``;
* DVL water track, body axes: ``z = nu_r``.

A straight line at constant thrust cannot separate a current along the track from a thrust
error; a turn can, because the current is fixed in the earth frame while the model acts in
the body frame (notably: the sway equation says a hull does not crab through water in steady
flight). The covariance says so: the current's one-sigma stays large until the vehicle has
turned. For a known regressor the coefficient part *is* RLS with forgetting; here the
regressor depends on ``nu_r = R^T (v_g - V_c)`` and the joint filter keeps the correlation
between ``theta`` and ``V_c`` (:mod:`.model_identification`).

Innovation-based calibration: a consistent filter has white innovations, so the mean of
``N`` of them has covariance ``~ mean(S) / N``. Model and current errors are slow and survive
the averaging, white sensor noise does not: a running mean of the block-mean NIS inflates the
process noise (``q_scale``, never below 1). It does not deflate it: the innovations measure
the sum ``R nu_r + V_c``, not how the model splits it, so a current error that ``nu_r``
compensates is invisible to them (deflating to 0.1 made the spheroid's 1-sigma coverage
0.24-0.48, docs/current.md, "Calibrated sigma").

Measurement noise learned both ways: each measurement kind's noise ``R = s std^2 I`` has
its own variance scale ``s`` learned from its innovations by covariance matching
(algorithms.md §9, :class:`.NoiseScale`), after the first ``START_UPDATES``.

Model coefficients: their covariance always flows into ``nu_r`` (and so into the current),
also while they are not being identified (consider parameters: the gain rows of ``theta``
are zero, Schmidt 1966), so a model identified elsewhere (its persistent state carries the
covariance) brings its uncertainty into the current's sigma off the conditions it was
identified in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, NamedTuple

from mypy_extensions import mypyc_attr
import numpy as np

from onboard.estimators import kalman
from onboard.estimators.model_identification import ModelIdentification
from onboard.estimators.noise_learning import Consistency, NoiseScale
from onboard.estimators.vehicle_models import ModelInputs

MeasurementKind = Literal["earth", "bottom", "water"]
"""``earth``: velocity over ground in earth axes; ``bottom``: DVL bottom track (over ground,
body axes); ``water``: DVL water track (through water, body axes)."""

UpdateOutcome = Literal["accepted", "gated", "reset", "contradicts_start"]
"""What :meth:`CurrentKalmanFilter.update` did with a measurement: used it (``accepted``),
rejected it at the gate (``gated``), reset the filter (``reset``: a divergence), or left
everything as it was because the measurement contradicts the filter's start
(``contradicts_start``: its owner decides, e.g. :meth:`CurrentKalmanFilter.restart_from`)."""
START_UPDATES = 50
"""The filter's first updates: an innovation beyond the gate in them says the start may be
what is wrong (``contradicts_start``), after them it is an outlier (``gated``)."""
NU_R_PRIOR_VAR = 1.0
"""Prior variance of each through-water velocity component (m^2/s^2) before the first
measurement starts it."""
DIVERGED_ABOVE_MPS = 50.0
"""A through-water velocity or current component beyond this (m/s) after an update is a
divergence: the filter resets."""
RESTORED_CURRENT_STD_FLOOR_MPS = 0.2
"""Smallest one-sigma (m/s) of a restored current: it may have changed while the vehicle was
off."""
MAX_SPEED_THROUGH_WATER_MPS = 10.0
"""Default bound (m/s) of a predicted through-water speed component; beyond it the model
ran away, not the vehicle."""
NIS_AVG_GAIN = 0.1
"""Weight of the newest calibration block's NIS in :attr:`CurrentKalmanFilter.nis_avg`."""
NIS_BLOCK_MAX = 10.0
"""A calibration block's NIS per dimension enters ``nis_avg`` at most this large (one block
of outliers must not inflate the process noise for good)."""
Q_SCALE_RATE = 0.1
"""Log-rate of the process-noise scale per block: ``q_scale *= exp(Q_SCALE_RATE (nis_avg -
1))``."""
Q_SCALE_RANGE = (1.0, 100.0)
"""Bounds of the process-noise scale: never below the configured noise, at most 100 times
it."""


class VelocityMeasurement(NamedTuple):
    """One velocity measurement of the table in the module docstring."""

    kind: MeasurementKind
    t: float
    """Its time (s)."""
    z: np.ndarray
    """The velocity (m/s; earth axes for ``earth``, else body axes)."""
    std: float
    """Its one-sigma per component (m/s)."""
    source: str = ""
    """The sample source it came from."""

PREDICT_STEP_S = 0.2
"""Longest prediction sub-step (s): a tick longer than this is predicted in equal steps."""


@mypyc_attr(allow_interpreted_subclasses=True)
@dataclass
class FilterCounters:
    """What a :class:`CurrentKalmanFilter` counted."""

    updates: int = 0
    """Velocity updates fused."""
    rejected_gate: int = 0
    """Velocity updates rejected by the gate (after the first ``START_UPDATES``)."""
    diverged: int = 0
    """Resets to the prior after a singular or non-finite update."""
    restarted: int = 0
    """Starts again from a measurement that contradicted the first one."""
    runaway: int = 0
    """Episodes of a through-water velocity beyond ``max_speed_through_water``."""


@mypyc_attr(allow_interpreted_subclasses=True)
class CurrentKalmanFilter:
    """The joint extended Kalman filter of the module docstring.

    Attributes (filterpy style, read them; the owner may assign ``x`` and ``P``):
        x: state ``[nu_r (m/s, body), V_c (m/s, earth), theta]``.
        P: its covariance.
        y: last velocity innovation, measured minus forecast (m/s, the measurement's axes),
            accepted or not (:meth:`update` returns which).
        S: its covariance (m^2/s^2).
        nis: its normalized innovation squared ``y^T S^-1 y`` (NaN if ``S`` is singular).
        nis_avg: running mean of the block-mean NIS per dimension (calibration).
        q_scale: process-noise scale from the calibration (``Q_SCALE_RANGE``).
        started: False until the first velocity measurement (and after a reset).
        runaway: the last prediction's through-water velocity left physical bounds
            (``max_speed_through_water``): its current is not a number to publish.
        identification: the :class:`.ModelIdentification` of the coefficients.
        counters: its event counts (:class:`FilterCounters`).
        noise: per measurement kind its learned noise scale (:class:`.NoiseScale`; the
            owner may replace them with ones that name their configuration keys).
        learn_noise: whether the updates teach them (the owner may turn it off).
    """

    def __init__(self, identification: ModelIdentification, *, init_current_std: float,
                 current_walk: float, accel_std: float, model_error_time_s: float,
                 turn_accel_gain: float, prior_accel_std: float, gate_nis: float,
                 calibrate: bool, calibrate_block: int,
                 max_speed_through_water: float = MAX_SPEED_THROUGH_WATER_MPS) -> None:
        """Args:
            identification: prior and schedule of the coefficients (and the model).
            init_current_std: prior one-sigma of the current (m/s).
            current_walk: random walk of the current (m/s per sqrt(s)).
            accel_std: model acceleration error per DOF (m/s^2 over ``model_error_time_s``).
            model_error_time_s: correlation time of the model error (s).
            turn_accel_gain: extra model acceleration error in turns (m/s^2 per m/s^2 of
                each DOF's own centripetal acceleration, :meth:`_model_error`).
            prior_accel_std: model acceleration error of a DOF with only the generic prior
                (m/s^2).
            gate_nis: innovations with a larger NIS are rejected (in the first
                ``START_UPDATES``: they contradict the start, :meth:`update`).
            calibrate: inflate the process noise when the block-mean NIS says so.
            calibrate_block: innovations per calibration block.
            max_speed_through_water: a predicted through-water speed component beyond
                this (m/s) sets ``runaway`` (counted once per episode): the model ran
                away, not the vehicle; the owner publishes no current meanwhile.
        """
        self.identification = ident = identification
        self.model = ident.model
        self.nd = nd = ident.model.nd
        self.init_current_std = init_current_std
        self.current_walk = current_walk
        self.accel_std = accel_std
        self.model_error_time_s = model_error_time_s
        self.turn_accel_gain = turn_accel_gain
        self.prior_accel_std = prior_accel_std
        self.gate_nis = gate_nis
        self.calibrate = calibrate
        self.calibrate_block = calibrate_block
        self.max_speed_through_water = max_speed_through_water
        self.runaway = False
        self.counters = FilterCounters()
        n = 2 * nd + ident.n_theta
        self.x = np.zeros(n)
        if ident.n_theta:
            self.x[2 * nd:] = np.concatenate(ident.thetas[:nd])
        self.P = self._prior_cov(ident.theta_var0)
        self.y, self.S, self.nis = np.zeros(nd), np.eye(nd), 0.0
        self.q_scale = self.nis_avg = 1.0
        self.started = False
        self.noise: dict[str, NoiseScale] = {
            k: NoiseScale(k, "", 0.0, "m/s") for k in ("earth", "bottom", "water")}
        self.learn_noise = True
        self.earth_whitened = Consistency()
        """The velocity-over-ground rows' innovations whitened by their ``S``
        (:meth:`_observe_whitened`): what the published current's factor is read from."""
        self._blk_y, self._blk_S, self._blk_n = np.zeros(nd), np.zeros((nd, nd)), 0
        self._eye_n = np.eye(n)
        self._H0 = _unrotated_measurement_matrices(nd, n)

    def _prior_cov(self, theta_var: list[float]) -> np.ndarray:
        """The prior covariance: ``NU_R_PRIOR_VAR`` per through-water component,
        ``init_current_std^2`` per current component, ``theta_var`` for the coefficients."""
        nd = self.nd
        return np.diag([NU_R_PRIOR_VAR] * nd + [self.init_current_std ** 2] * nd
                       + list(theta_var))

    # ------------------------------------------------------------------ state
    def start(self, kind: MeasurementKind, z: np.ndarray, rot: np.ndarray) -> None:
        """Initialize ``nu_r`` from the first velocity ``z`` (m/s) given the current in the
        state (zero unless restored; the covariance says how well it is known); ``rot``
        the body-to-earth rotation ``R``."""
        nd = self.nd
        zz = np.zeros(nd)
        zz[: len(z)] = z
        c = self.x[nd:2 * nd]
        if kind == "earth":
            zz[len(z):] = c[len(z):]  # an unmeasured vertical: no relative vertical motion
            self.x[:nd] = rot.T @ (zz - c)
        elif kind == "bottom":
            self.x[:nd] = zz - rot.T @ c
        else:
            self.x[:nd] = zz
        self.started = True

    def reset(self, reason: Literal["diverged", "restarted"]) -> None:
        """Back to the prior, counted as ``reason``; the identified coefficients are kept
        if they and their covariance are finite."""
        if reason == "diverged":
            self.counters.diverged += 1
        else:
            self.counters.restarted += 1
        nd, o = self.nd, 2 * self.nd
        nt = self.identification.n_theta
        self.x[:o] = 0.0
        keep = np.all(np.isfinite(self.x[o:])) and np.all(np.isfinite(self.P[o:, o:]))
        P = self._prior_cov([0.0] * nt)
        if nt:
            if keep:
                P[o:, o:] = self.P[o:, o:]
            else:
                self.x[o:] = np.concatenate(self.model.default_thetas()[:nd])
                P[o:, o:] = np.diag(self.identification.theta_var_generic)
        self.P = P
        self._unpack_coefficients()
        self.started = False
        self.runaway = False

    def _unpack_coefficients(self) -> None:
        """Point the identification's coefficients of the velocity DOFs at the state."""
        ident = self.identification
        if not ident.n_theta:
            return
        o = 2 * self.nd
        for i, k in enumerate(ident.sizes):
            ident.thetas[i] = self.x[o:o + k]
            o += k

    def restore_coefficients(self, thetas: list[np.ndarray], cov: object) -> None:
        """Put the velocity DOFs' coefficients ``thetas`` into the state and, if ``cov`` is
        a finite matrix of the right shape, their covariance (uncorrelated with the rest);
        raises ValueError or TypeError if ``cov`` is not a matrix of numbers."""
        o = 2 * self.nd
        nt = self.identification.n_theta
        self.x[o:] = np.concatenate(thetas)
        cov = np.asarray(cov, float)
        if cov.shape == (nt, nt) and np.all(np.isfinite(cov)):
            self.P[o:, :] = 0.0
            self.P[:, o:] = 0.0
            self.P[o:, o:] = cov
            self.identification.lift_masks(self.P.diagonal()[o:])

    def restore_current(self, current: object, std: object) -> None:
        """Restart the current (m/s) from a saved value with its saved one-sigma ``std``
        (m/s) floored at ``RESTORED_CURRENT_STD_FLOOR_MPS``; ignored unless both are
        finite (the variance too) and of the state's dimension. Raises ValueError or
        TypeError on non-numbers."""
        nd, o = self.nd, 2 * self.nd
        c = np.asarray(current, float)
        with np.errstate(over="ignore"):   # an absurd saved sigma: inf, then ignored
            var = np.maximum(np.asarray(std, float), RESTORED_CURRENT_STD_FLOOR_MPS) ** 2
        if c.shape == var.shape == (nd,) and np.all(np.isfinite(c)) and np.all(np.isfinite(var)):
            self.x[nd:o] = c
            self.P[nd:o, :] = 0.0
            self.P[:, nd:o] = 0.0
            self.P[nd:o, nd:o] = np.diag(var)

    def inflate_current_along(self, direction: list[float], var_min: float) -> None:
        """Raise the current's variance along the unit vector ``direction`` (earth axes) to
        at least ``var_min`` (m^2/s^2): ``P_cc <- P_cc + d a a^T``, ``d = max(0, var_min -
        a^T P_cc a)``. For a direction the data cannot observe (the along-track current
        without a surge model, :meth:`.ModelIdentification.surge_unobservable`): the
        linearized filter would otherwise let weak couplings shrink it and drift along it
        with a small variance, and carry that false confidence into the next turn."""
        nd = self.nd
        a = np.zeros(nd)
        a[: len(direction)] = direction
        blk = self.P[nd:2 * nd, nd:2 * nd]
        d = var_min - float(a @ blk @ a)
        if d > 0.0:
            self.P[nd:2 * nd, nd:2 * nd] = blk + d * np.outer(a, a)

    def adopt(self, other: CurrentKalmanFilter) -> None:
        """Take ``other``'s state, covariance, calibration and coefficient masks (a twin
        filter on the same model whose current replaces this one's)."""
        self.x[:] = other.x
        self.P = other.P.copy()
        self.q_scale, self.nis_avg = other.q_scale, other.nis_avg
        self._unpack_coefficients()
        self.identification.masked = list(other.identification.masked)

    def current_cov(self) -> np.ndarray:
        """Covariance of the current (m^2/s^2, earth axes), a copy."""
        nd = self.nd
        return self.P[nd:2 * nd, nd:2 * nd].copy()

    def current_estimate(self) -> tuple[list[float], list[float], list[float]]:
        """(current (m/s, earth), its one-sigma (m/s), ``nu_r`` (m/s, body)) as lists."""
        nd = self.nd
        return (self.x[nd:2 * nd].tolist(), np.sqrt(self.P.diagonal()[nd:2 * nd]).tolist(),
                self.x[:nd].tolist())

    def velocity_over_ground(self, rot: np.ndarray) -> np.ndarray:
        """The filter's velocity over ground ``R nu_r + V_c`` (m/s, earth), ``rot`` the
        body-to-earth rotation ``R``."""
        nd = self.nd
        return rot @ self.x[:nd] + self.x[nd:2 * nd]

    # ------------------------------------------------------------------ filter
    def advance(self, t: float, dt: float, inputs: ModelInputs, yaw: float) -> None:
        """The identification's schedule and the prediction to tick ``t`` (s), ``dt`` (s)
        after the previous one, at heading ``yaw`` (rad).

        On the first leg (no turn yet) without a surge model the along-track current is
        unobservable and its variance along the heading is kept at the prior
        (:meth:`inflate_current_along`): otherwise the filter drifts there with a shrinking
        variance and meets the first turn overconfident (docs/current.md). Later straight
        legs are not inflated: that would erase what the earlier headings' sway constraint
        says about the cross-track part of the new heading (the published one-sigma is
        floored instead, :func:`.model_identification.floor_along_track`)."""
        ident = self.identification
        ident.observe_motion(t, dt, inputs.r, yaw)
        if ident.identifying:  # the coefficient covariance moves only while identifying
            ident.lift_masks(self.P.diagonal()[2 * self.nd:])
        ident.identifying = ident.should_identify(t, self.started,
                                                  *self.current_var_horizontal())
        if dt > 0:
            n_sub = max(1, math.ceil(dt / PREDICT_STEP_S))
            for _ in range(n_sub):
                self.predict(dt / n_sub, inputs)
        if self.started and ident.surge_unobservable() and ident.last_turn_t == -math.inf:
            psi = yaw or 0.0
            self.inflate_current_along([math.cos(psi), math.sin(psi)],
                                       self.init_current_std ** 2)

    def predict(self, dt: float, inputs: ModelInputs) -> None:
        """``x <- x + dt f(x)``; ``P <- D (F P F^T + Q) D`` with the coefficient forgetting
        ``D = diag(1 (nu_r, V_c), 1/sqrt(lam) (theta))`` (rls.py rule).

        ``Q`` has no coefficient part, so this is ``(D F) P (D F)^T + Q``: the forgetting
        rides on the transition. The regressors, ``f`` and its Jacobian are plain floats
        (:meth:`.RegressionModel.linearize`); numpy does only the covariance product.
        """
        ident = self.identification
        nd, nt = self.nd, ident.n_theta
        n = 2 * nd + nt
        o = 2 * nd
        nu = self.x[:nd].tolist()
        phis, f, J = self.model.linearize(nu, inputs,
                                          [t.tolist() for t in ident.thetas[:nd]])
        # F = I + dt [[J, 0, Phi], 0, 0]: only the first nd rows differ from I
        rows = []
        col = o
        for i, k in enumerate(ident.sizes):
            row = [0.0] * n
            if ident.masked[i]:  # generic prior: no cross-coupling
                row[i] = dt * J[i][i]
            else:
                row[:nd] = [dt * a for a in J[i]]
            row[i] += 1.0
            if nt:
                # the coefficients' uncertainty always flows into nu_r (and so into the
                # current): while not identifying they are consider parameters (their gain
                # rows are zero, Schmidt), so a model identified elsewhere carries its own
                # covariance to the current's sigma; an assumed sway damping must not pin
                # the sideslip in a turn either
                row[col:col + k] = [dt * a for a in phis[i]]
            col += k
            rows.append(row)
        F = self._eye_n.copy()
        F[:nd] = rows
        if nt and ident.identifying:
            # variable-rate forgetting on the coefficient block, bounded by its prior trace
            # (F leaves that block of P as it is): the block by 1/lam, its cross-covariances
            # by 1/sqrt(lam)
            lam = ident.forgetting_factor(sum(self.P.diagonal()[o:].tolist()), dt)
            if lam < 1.0:
                F.ravel()[o * (n + 1)::n + 1] = 1.0 / math.sqrt(lam)
        nu = [a + dt * b for a, b in zip(nu, f)]
        # beyond physics: the model, not the vehicle, ran away (flagged, counted per episode)
        runaway = self.started and max(map(abs, nu)) > self.max_speed_through_water
        if runaway and not self.runaway:
            self.counters.runaway += 1
        self.runaway = runaway
        self.x[:nd] = nu
        q = self._model_error(nu, inputs, dt)
        for i in range(nd):
            if ident.masked[i]:  # still the generic prior
                q[i] = max(q[i], self.prior_accel_std ** 2 * self.model_error_time_s * dt)
        q += [self.current_walk ** 2 * dt * self.q_scale] * nd
        P = F @ self.P @ F.T
        P.ravel()[:o * (n + 1):n + 1] += q  # a view: the product is C-contiguous
        self.P = P

    def _model_error(self, nu: list[float], inputs: ModelInputs, dt: float) -> list[float]:
        """Process-noise variance of each DOF of ``nu_r`` over ``dt`` (s): ``accel_std``
        plus a turn term that grows in manoeuvres (couplings the regression gets only
        roughly), so that the one-sigma widens at heading changes (the paper's burrs).

        On the surface boats each DOF's turn term is ``turn_accel_gain`` times its own
        centripetal acceleration (Fossen's ``C_RB(nu) nu``): surge ``|v r| + |w q|``, sway
        ``|u r| + |w p|``, heave ``|u q| + |v p|``; their surge's speed loss in a turn is a
        regressor of its own (:data:`.vehicle_models.TURN_LOSS_REGRESSORS`), whose
        coefficient's uncertainty flows into ``nu_r`` like every coefficient's. The other
        models have no such regressor, and ``|u r|`` stands in for it on every DOF (the
        split made the Kolumbo glider's current worse, docs/current.md)."""
        nd = self.nd
        u, v = nu[0], nu[1]
        w = nu[2] if nd > 2 else 0.0
        p, q, r = inputs.p, inputs.q, inputs.r
        if self.model.kind.startswith("surface"):
            own = (abs(v * r) + abs(w * q), abs(u * r) + abs(w * p), abs(u * q) + abs(v * p))
        else:  # no turn-loss regressors: |u r| stands in on every DOF
            own = (abs(u * r),) * 3
        k = self.turn_accel_gain
        scale = self.model_error_time_s * self.q_scale * dt
        return [(self.accel_std ** 2 + (k * a) ** 2) * scale for a in own[:nd]]

    def _project_drag(self) -> None:
        """Project the state onto the physical sign of the drag coefficients (``<= 0``,
        :data:`.vehicle_models.DRAG_REGRESSORS`): the estimate projection of Simon & Chia
        (2002) weighted by ``P^-1``, ``x <- x - P_:A P_AA^-1 x_A`` over the violated
        coefficients ``A``, which moves the states correlated with them too (a quadratic
        damping traded against the linear one); the covariance is kept. An anti-damping
        estimate makes the through-water speed run away between measurements."""
        o = 2 * self.nd
        active: list[int] = []
        for k, drag in zip(self.identification.sizes, self.model.drag_terms):
            active += [o + j for j in drag if self.x[o + j] > 0.0]
            o += k
        if not active:
            return
        P_a = self.P[:, active]
        try:
            self.x = self.x - P_a @ np.linalg.solve(P_a[active], self.x[active])
        except np.linalg.LinAlgError:
            pass
        self.x[active] = 0.0

    def update(self, kind: MeasurementKind, z: np.ndarray, std: float,
               rot: np.ndarray) -> UpdateOutcome:
        """Kalman update (:func:`.kalman.update`) with one velocity measurement ``z`` (m/s,
        one-sigma ``std`` per component; the module docstring's table), ``rot`` the
        body-to-earth rotation ``R``.

        A NIS above ``gate_nis`` rejects the measurement (``gated``, counted); within the
        first ``START_UPDATES`` it says the measurement contradicts the start instead
        (``contradicts_start``: nothing is changed, the owner decides, e.g.
        :meth:`restart_from`). The covariance is in Joseph form for the gain actually used
        (the coefficient rows of the gain are zero while not identifying); a singular
        innovation covariance or a non-finite or runaway state resets the filter
        (``reset``). ``std`` is the declared one-sigma: the learned scale of ``kind``
        multiplies its variance (:meth:`noise_std`).
        """
        m = len(z)
        ident = self.identification
        keep = slice(0, 2 * self.nd) if ident.n_theta and not ident.identifying else None
        std = self.noise_std(kind, std)
        up = kalman.update(self.x, self.P, z, std * std * kalman.identity(m),
                           self._measurement_matrix(kind, m, rot), keep=keep)
        self.y, self.S, self.nis = up.y, up.S, up.nis
        if up.K is None:
            return self._diverged()
        if up.nis > self.gate_nis and self.started:
            if self.counters.updates > START_UPDATES:
                self.counters.rejected_gate += 1
                return "gated"
            return "contradicts_start"
        if not self._plausible(up.x, up.P):
            return self._diverged()
        self.x, self.P = up.x, up.P
        if ident.n_theta and ident.identifying:
            self._project_drag()
        self._unpack_coefficients()
        self.counters.updates += 1
        if self.learn_noise and self.started and self.counters.updates > START_UPDATES:
            self.noise[kind].observe(up.y.copy(), float(np.trace(up.S)),
                                     m * std * std)
            if kind == "earth":
                self._observe_whitened(up.y, up.S, std * std)
        if self.calibrate and self.started and m == self.nd:
            self._calibrate(up.y, up.S)
        return "accepted"

    def _observe_whitened(self, y: np.ndarray, S: np.ndarray, r_var: float) -> None:
        """Observe the innovation ``y`` whitened, ``w = L^-1 y`` with ``S = L L^T``, into
        :attr:`earth_whitened`: its ``S`` is the identity and its measurement noise
        ``L^-1 R L^-T`` (``R = r_var I``, of trace ``r_var |L^-1|_F^2``). Its ratio is then
        the NIS per dimension and its forecast share ``tr(S^-1 H P_f H^T) / m``: every
        direction of ``S`` weighs alike, where ``y^T y / tr S`` is the widest direction's
        (a current well known across the track and loosely along it). An ``S`` that
        rounding left not positive definite gives no sample."""
        try:
            L_inv = np.linalg.inv(np.linalg.cholesky(S))
        except np.linalg.LinAlgError:
            return
        self.earth_whitened.observe(L_inv @ y, float(len(y)), r_var * float(np.sum(L_inv ** 2)))

    def noise_std(self, kind: MeasurementKind, std: float) -> float:
        """The one-sigma (m/s) a ``kind`` measurement declared at ``std`` is taken with:
        ``std sqrt(s)``, ``s`` its learned variance scale."""
        return std * math.sqrt(self.noise[kind].applied)

    def restart_from(self, kind: MeasurementKind, z: np.ndarray, std: float,
                     rot: np.ndarray) -> UpdateOutcome:
        """Start again from the measurement ``z`` (counted ``restarted``) and update with
        it, as :meth:`update`: what an owner does when :meth:`update` says
        ``contradicts_start`` and it trusts the measurement over the start (a first sample
        stamped before the clocks settled, in a hard acceleration). The filter's ``y``,
        ``S`` and ``nis`` are then those of this update."""
        self.reset("restarted")
        self.start(kind, z, rot)
        return self.update(kind, z, std, rot)

    def _measurement_matrix(self, kind: MeasurementKind, m: int,
                            rot: np.ndarray) -> np.ndarray:
        """``H`` of a ``kind`` measurement of ``m`` components at the body-to-earth
        rotation ``rot`` (the module docstring's table)."""
        nd = self.nd
        H = self._H0[(kind, m)].copy()
        if kind == "earth":
            H[:, :nd] = rot[:m]
        elif kind == "bottom":
            H[:, nd:2 * nd] = rot.T[:m]
        return H

    def _plausible(self, x: np.ndarray, P: np.ndarray) -> bool:
        """Whether an updated ``x`` and ``P`` are finite and every through-water and
        current component is within ``DIVERGED_ABOVE_MPS``. (A NaN or inf anywhere makes
        the sums non-finite; a sum overflowing from finite entries needs ``|P| ~ 1e308``:
        a divergence too.)"""
        return (math.isfinite(float(x.sum()) + float(P.sum()))
                and max(map(abs, x[:2 * self.nd].tolist())) < DIVERGED_ABOVE_MPS)

    def _diverged(self) -> UpdateOutcome:
        """Reset on a divergence (counted ``diverged``)."""
        self.reset("diverged")
        return "reset"

    def _calibrate(self, y: np.ndarray, S: np.ndarray) -> None:
        """Fold one full-dimension innovation into the calibration block; at the end of a
        block, move ``nis_avg`` towards the block-mean NIS and rescale ``q_scale``.

        The per-sample NIS is blind to slow model and current errors (docs/current.md,
        "Honest sigma"); the block mean is not."""
        m = len(y)
        self._blk_y += y
        self._blk_S += S
        self._blk_n += 1
        if self._blk_n >= self.calibrate_block:
            nb = self._blk_n
            yb = self._blk_y / nb
            Sb = self._blk_S / (nb * nb)
            nis_b = float(yb @ np.linalg.solve(Sb, yb)) / m
            self.nis_avg += NIS_AVG_GAIN * (min(nis_b, NIS_BLOCK_MAX) - self.nis_avg)
            self.q_scale = float(np.clip(
                self.q_scale * math.exp(Q_SCALE_RATE * (self.nis_avg - 1.0)), *Q_SCALE_RANGE))
            self._blk_y[:] = 0.0
            self._blk_S[:] = 0.0
            self._blk_n = 0

    def current_var_horizontal(self) -> tuple[float, float]:
        """Variances of the current's north and east components (m^2/s^2)."""
        nd = self.nd
        return self.P[nd, nd], self.P[nd + 1, nd + 1]

    def theta_std_max(self) -> float:
        """Largest one-sigma among the coefficients in the state."""
        return float(np.sqrt(np.max(np.diag(self.P)[2 * self.nd:])))


def _unrotated_measurement_matrices(nd: int, n: int) -> dict[tuple[str, int], np.ndarray]:
    """The measurement matrices of an ``n``-state filter with ``nd`` velocity DOFs without
    the rotation, per (kind, number of components): ``earth`` sees ``V_c``, ``bottom`` and
    ``water`` see ``nu_r`` (:meth:`CurrentKalmanFilter._measurement_matrix` puts the
    rotation in)."""
    out: dict[tuple[str, int], np.ndarray] = {}
    for kind in ("earth", "bottom", "water"):
        for m in {2, nd}:
            H = np.zeros((m, n))
            H[:, :nd] = 0.0 if kind == "earth" else np.eye(nd)[:m]
            H[:, nd:2 * nd] = np.eye(nd)[:m] if kind == "earth" else 0.0
            out[(kind, m)] = H
    return out
