"""Online identification of a vehicle model for the current observers (algorithms.md §3.3-§3.4).

Kim, Fan & Bose, IEEE Access 6 (2018), §II.B identify the coefficients ``theta`` of the
regression model (:mod:`.vehicle_models`) online by RLS. Here the coefficients of the
velocity DOFs are states of the joint current filter (:mod:`.current_kf`), ``x = [nu_r, V_c,
theta]`` with ``theta' = 0``; this module holds what the filter needs to know about them:

* the prior: configured coefficients (mode (a)) with a tight relative one-sigma, the others
  (mode (b)) at the generic values of :meth:`.RegressionModel.default_thetas` with a loose
  one-sigma, except the net-weight terms, whose one-sigma is physics (``g`` times the net
  weight fraction, :data:`.vehicle_models.NET_WEIGHT_REGRESSORS`);
* the schedule: coefficients are estimated only once the current is known and only around
  turns (:meth:`ModelIdentification.should_identify`);
* the forgetting of their covariance, the variable-rate rule of :mod:`.rls` bounded by the
  prior trace (:meth:`ModelIdentification.forgetting_factor`);
* the prior masks: a DOF whose model is still the generic prior constrains its own DOF only
  (no cross-coupling in the model Jacobian) until its coefficients are learned;
* the excitation: how diverse the recent headings are (:class:`HeadingDiversity`), without
  which the along-track current is not observable while the surge model is unknown;
* the auxiliary yaw channel (needed by the flow observer, :mod:`.flow_observer`): RLS
  (:class:`.rls.RecursiveLeastSquares`) on state-variable-filtered data
  (:class:`StateVariableFilter`), ``r' = phi_yaw(nu_r, r, u)^T theta_yaw`` (algorithms.md §3.4).

Estimating ``theta`` jointly with the current, rather than by RLS on ``v_g - V_c_hat`` in a
separate identify-then-observe loop, keeps the correlation between ``theta`` and ``V_c``: the
separate loop locks in its own errors (on a straight leg after a turn a biased current makes
the sway regressor constant, RLS forgets the sway damping and the bias stays;
docs/current.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from mypy_extensions import mypyc_attr
import numpy as np

from onboard.estimators.rls import RecursiveLeastSquares
from onboard.estimators.vehicle_models import ModelInputs, RegressionModel

GRAVITY = 9.81
"""m/s^2, the scale of the net-weight prior (``net_weight_std``)."""
YAW_RLS_SIGMA2_0 = 1e-3
"""Initial equation-error variance of the yaw channel's RLS ((rad/s^2)^2)."""
MASK_LIFT_FRACTION = 0.25
"""A DOF's prior mask is lifted once the trace of its coefficient covariance is below this
fraction of its prior trace."""
FORGETTING_PERIOD_S = 0.1
"""The forgetting factors are per this period (s): one 10 Hz tick."""


@mypyc_attr(allow_interpreted_subclasses=True)
class StateVariableFilter:
    """``H(s) = w^2 / (s^2 + 2 zeta w s + w^2)`` on a vector of channels; gives the filtered
    value and its derivative, so ``d/dt (H y) = (H phi)^T theta`` holds exactly for constant
    ``theta`` (continuous-time identification without differentiating noisy data).

    Attributes: ``y`` and ``dy`` (lists of floats: the filtered channels and their time
    derivatives, units of the input and per second), ``w`` (rad/s), ``zeta``, ``primed``.
    """

    def __init__(self, n: int, cutoff_hz: float, zeta: float = 0.8) -> None:
        """Args:
            n: number of channels.
            cutoff_hz: natural frequency ``w / (2 pi)`` of the filter (Hz).
            zeta: damping ratio.
        """
        self.w = 2.0 * math.pi * cutoff_hz
        self.zeta = zeta
        self.y = [0.0] * n
        self.dy = [0.0] * n
        self.primed = False

    def update(self, dt: float, u: Sequence[float]) -> None:
        """Advance by ``dt`` (s) with input ``u`` held over the step; the first call sets the
        filter to ``u`` at rest."""
        if not self.primed:
            self.y = [float(a) for a in u]
            self.dy = [0.0] * len(self.y)
            self.primed = True
            return
        w, z = self.w, self.zeta
        n_sub = max(1, math.ceil(dt * w / 0.3))
        h = dt / n_sub
        ww, zw = w * w, 2.0 * z * w
        y, dy = self.y, self.dy
        for _ in range(n_sub):  # semi-implicit Euler, stable for w h < 2
            dy = [d + h * (ww * (a - b) - zw * d) for a, b, d in zip(u, y, dy)]
            y = [b + h * d for b, d in zip(y, dy)]
        self.y, self.dy = y, dy


@mypyc_attr(allow_interpreted_subclasses=True)
class HeadingDiversity:
    """Running mean of the doubled-angle heading vector ``(cos 2 psi, sin 2 psi)``.

    Doubled, because reversing course (a glider's back-and-forth, a lawnmower survey) keeps
    the same lateral axis and adds nothing to the sway constraint. The mean's length is 1 on
    a straight line and falls as the headings spread (two headings 35 deg apart: 0.82; a
    +-15 deg zig-zag: 0.87).

    Attributes: ``vector`` (the mean, a pair of floats), ``memory_s`` (s).
    """

    def __init__(self, memory_s: float) -> None:
        """Args:
            memory_s: time constant of the running mean (s).
        """
        self.memory_s = memory_s
        self.vector = (1.0, 0.0)

    def restart(self, yaw: float) -> None:
        """Forget the past: the mean is the heading ``yaw`` (rad) alone."""
        self.vector = (math.cos(2.0 * yaw), math.sin(2.0 * yaw))

    def update(self, dt: float, yaw: float) -> None:
        """Blend in heading ``yaw`` (rad) held for ``dt`` (s, > 0)."""
        a = min(1.0, dt / self.memory_s)
        self.vector = ((1 - a) * self.vector[0] + a * math.cos(2.0 * yaw),
                       (1 - a) * self.vector[1] + a * math.sin(2.0 * yaw))

    def length(self) -> float:
        """Length of the mean vector: 1 for one heading (or its reverse), 0 for headings
        spread evenly."""
        return math.hypot(*self.vector)


def floor_along_track(cov: np.ndarray, yaw: float, sigma: float) -> list[float]:
    """One-sigma (m/s) of the current whose covariance ``cov`` (m^2/s^2, earth axes, 2x2 or
    3x3) has its variance along the heading ``yaw`` (rad) raised to at least ``sigma^2``:
    ``cov + d a a^T`` with ``a = (cos yaw, sin yaw[, 0])``, ``d = max(0, sigma^2 -
    a^T cov a)`` (the rule of :meth:`.CurrentKalmanFilter.inflate_current_along`)."""
    a = np.zeros(len(cov))
    a[0], a[1] = math.cos(yaw), math.sin(yaw)
    d = max(0.0, sigma * sigma - float(a @ cov @ a))
    return np.sqrt(np.maximum(np.diagonal(cov) + d * a * a, 0.0)).tolist()


@mypyc_attr(allow_interpreted_subclasses=True)
class ModelIdentification:
    """Prior, schedule and forgetting of the vehicle-model coefficients; the yaw channel.

    Attributes:
        model: the :class:`.RegressionModel`.
        thetas: coefficients in use, one array per channel (``model.channels``): the
            velocity DOFs' are views of the joint filter's state while it identifies them.
        prior_sd: prior one-sigma of every coefficient, one array per channel.
        sizes: number of coefficients of each velocity DOF.
        n_theta: number of coefficients in the joint state (0 when not identifying).
        prior_dof: per velocity DOF, True if none of its coefficients is configured.
        masked: per velocity DOF, True while its model is still the generic prior (its row
            of the model Jacobian keeps only the diagonal).
        theta_var0: prior variances of the joint state's coefficients, in state order.
        theta_var_generic: the generic prior's variances (a reset without finite
            coefficients).
        tr_theta0: prior trace of each velocity DOF's coefficients.
        tr_theta_max: prior trace of all of them (the forgetting stops there).
        identifying: whether the coefficients are estimated at this tick.
        last_turn_t: time of the last yaw rate above ``identify_min_rate`` (s).
        headings: the :class:`HeadingDiversity` of the recent headings.
        yaw_rls: the yaw channel's :class:`.RecursiveLeastSquares` (None without a yaw
            channel).
        svf: the yaw channel's :class:`StateVariableFilter` (None without a yaw channel).
        rls_updates: updates of the yaw RLS so far.
    """

    def __init__(self, model: RegressionModel, configured: Mapping[str, Mapping[str, float]],
                 *, identify: bool, model_rel_std: float, theta_std: float,
                 theta_std_floor: float, net_weight_std: float, forgetting: float,
                 identify_max_current_std: float, identify_min_rate: float,
                 identify_after_turn_s: float, identify_straight: bool,
                 identify_min_speed: float, yaw_rls_p0: float, yaw_forgetting: float,
                 svf_cutoff_hz: float, heading_memory_s: float,
                 heading_diversity: float) -> None:
        """Args:
            model: the regression model.
            configured: configured coefficients by channel and term (mode (a)); empty for
                none.
            identify: estimate the velocity DOFs' coefficients (False: keep them fixed).
            model_rel_std: prior one-sigma of configured coefficients, relative.
            theta_std: prior one-sigma of unconfigured coefficients.
            theta_std_floor: added to the relative prior one-sigma.
            net_weight_std: prior one-sigma of the net weight as a fraction of the weight
                (unconfigured net-weight terms: ``GRAVITY * net_weight_std``, m/s^2).
            forgetting: forgetting factor of the coefficient covariance per 0.1 s.
            identify_max_current_std: current one-sigma (m/s) below which to identify.
            identify_min_rate: yaw rate (rad/s) above which the vehicle is turning.
            identify_after_turn_s: identify this long after a turn (s).
            identify_straight: identify on straight lines too.
            identify_min_speed: through-water speed (m/s) below which the yaw RLS waits.
            yaw_rls_p0: initial covariance of the yaw RLS.
            yaw_forgetting: forgetting factor of the yaw RLS.
            svf_cutoff_hz: cut-off of the yaw channel's state-variable filter (Hz).
            heading_memory_s: memory of the heading diversity (s).
            heading_diversity: mean doubled-heading length above which the headings count
                as one line.
        """
        self.model = model
        self.configured = configured
        self.identify = identify
        self.forgetting = forgetting
        self.identify_max_current_std = identify_max_current_std
        self.identify_min_rate = identify_min_rate
        self.identify_after_turn_s = identify_after_turn_s
        self.identify_straight = identify_straight
        self.identify_min_speed = identify_min_speed
        self.heading_diversity = heading_diversity
        self.rls_updates = 0
        self._init_prior(configured, identify, model_rel_std, theta_std, theta_std_floor,
                         net_weight_std)
        self.identifying = False
        self.last_turn_t = -math.inf
        self.headings = HeadingDiversity(heading_memory_s)
        self._init_yaw_channel(configured, yaw_rls_p0, yaw_forgetting, svf_cutoff_hz)

    def _init_prior(self, configured: Mapping[str, Mapping[str, float]], identify: bool,
                    model_rel_std: float, theta_std: float, theta_std_floor: float,
                    net_weight_std: float) -> None:
        """The coefficients' prior: configured terms tight (``model_rel_std |theta| +
        theta_std_floor``), the others loose (``theta_std``), except the net-weight terms,
        whose scale is physics (``GRAVITY * net_weight_std``); the prior masks and traces."""
        model = self.model
        nd = model.nd
        base = model.default_thetas()
        self.thetas = model.thetas_from_mapping(configured, base) if configured else base
        sd_nw = GRAVITY * net_weight_std
        self.prior_sd: list[np.ndarray] = []
        for ch, th in zip(model.channels, self.thetas):
            given = configured.get(ch, {})
            nw = model.net_weight_terms[ch]
            self.prior_sd.append(np.array([
                model_rel_std * abs(v) + theta_std_floor if k in given
                else sd_nw if k in nw else theta_std
                for k, v in zip(model.terms[ch], th)]))
        self.sizes = [len(model.terms[c]) for c in model.dofs]
        self.prior_dof = [c not in configured for c in model.dofs]
        # an assumed (prior) model constrains its own DOF only: its cross-coupling terms
        # (u v, u w, ...) would otherwise "measure" the surge speed from made-up
        # coefficients (docs/current.md). The mask is lifted once the DOF's coefficients
        # are identified (:meth:`lift_masks`).
        self.masked: list[bool] = list(self.prior_dof)
        self.n_theta = sum(self.sizes) if identify else 0
        self.theta_var0: list[Any] = (list(np.concatenate(self.prior_sd[:nd]) ** 2)
                                      if self.n_theta else [])
        self.tr_theta0 = [float(np.sum(sd ** 2)) for sd in self.prior_sd[:nd]]
        self.theta_var_generic = np.concatenate([
            [sd_nw ** 2 if k in model.net_weight_terms[c] else theta_std ** 2
             for k in model.terms[c]] for c in model.dofs])
        self.tr_theta_max = float(np.sum(self.theta_var0)) if self.n_theta else 0.0

    def _init_yaw_channel(self, configured: Mapping[str, Mapping[str, float]],
                          yaw_rls_p0: float, yaw_forgetting: float,
                          svf_cutoff_hz: float) -> None:
        """The yaw channel's RLS and state-variable filter (models with an auxiliary yaw
        channel); a configured yaw model starts with its prior covariance."""
        model = self.model
        self.yaw_rls: RecursiveLeastSquares | None = None
        self.svf: StateVariableFilter | None = None
        self._i_yaw = model.channels.index("yaw") if "yaw" in model.channels else -1
        if "yaw" in model.aux:
            i = self._i_yaw
            self.yaw_rls = RecursiveLeastSquares(
                len(self.thetas[i]), forgetting=yaw_forgetting, p0=yaw_rls_p0,
                theta0=self.thetas[i], names=model.terms["yaw"], sigma2_0=YAW_RLS_SIGMA2_0)
            if "yaw" in configured:
                self.yaw_rls.P = np.diag(self.prior_sd[i] ** 2)
            self.svf = StateVariableFilter(1 + len(model.terms["yaw"]), svf_cutoff_hz)

    # ------------------------------------------------------------------ schedule
    def observe_motion(self, t: float, dt: float, yaw_rate: float, yaw: float) -> None:
        """Note a turn (``|yaw_rate|`` above ``identify_min_rate``, rad/s) at tick ``t`` (s)
        and blend heading ``yaw`` (rad) into the heading diversity when ``dt > 0`` (s)."""
        if abs(yaw_rate) > self.identify_min_rate:
            self.last_turn_t = t
        if dt > 0:
            self.headings.update(dt, yaw)

    def should_identify(self, t: float, started: bool, current_var_north: float,
                        current_var_east: float) -> bool:
        """Whether the coefficients are estimated at tick ``t`` (s), given the current's
        horizontal variances (m^2/s^2) in a ``started`` filter.

        Only once the current is known (``identify_max_current_std``): before that the
        innovation says "model or current wrong" and the coefficients would take the blame.
        And only around turns (``identify_after_turn_s``): on a straight line a current
        along the track and a thrust coefficient are the same thing to the data, and the
        linearized joint filter drifts along that direction while its covariance shrinks.
        While not identifying, the coefficients are held as known (their uncertainty is not
        propagated into ``nu_r``, which would make the model worthless and the current
        drift). Figures: docs/current.md, "Why the current is observable".
        """
        if not self.n_theta or not started:
            return False
        c_sd = math.sqrt(max(current_var_north, current_var_east))
        return (c_sd <= self.identify_max_current_std
                and (self.identify_straight
                     or t - self.last_turn_t <= self.identify_after_turn_s))

    def forgetting_factor(self, trace: float, dt: float) -> float:
        """Forgetting of the coefficient covariance over ``dt`` (s) at covariance trace
        ``trace``: ``lambda = 1 - (1 - forgetting) max(0, 1 - trace / tr_theta_max)`` per
        0.1 s, none once the trace is back at the prior's (the bounded rule of :mod:`.rls`)."""
        lam = 1.0 - (1.0 - self.forgetting) * max(0.0, 1.0 - trace / self.tr_theta_max)
        return lam ** (dt / FORGETTING_PERIOD_S)

    def lift_masks(self, theta_var: np.ndarray) -> None:
        """Lift the cross-coupling mask of the DOFs whose coefficients have been learned:
        the sum of their variances ``theta_var`` (the joint state's coefficient variances,
        in state order) below a quarter of their prior trace."""
        if not self.n_theta or not any(self.masked):
            return
        var = theta_var.tolist()
        o = 0
        for i, k in enumerate(self.sizes):
            if self.masked[i] and sum(var[o:o + k]) < MASK_LIFT_FRACTION * self.tr_theta0[i]:
                self.masked[i] = False
            o += k

    def surge_unobservable(self) -> bool:
        """True while the surge model is still the generic prior and the recent headings
        are not diverse: the current along the track is then not observable (a straight line
        cannot separate it from the through-water speed)."""
        return self.masked[0] and self.headings.length() > self.heading_diversity

    # ------------------------------------------------------------------ yaw channel
    def identify_yaw(self, dt: float, nu: Sequence[float], inputs: ModelInputs,
                     velocity_fresh: bool) -> None:
        """One RLS step of the yaw channel, ``r' = phi_yaw^T theta_yaw``, with both sides
        through the same state-variable filter (algorithms.md §3.4).

        Args:
            dt: time since the previous step (s).
            nu: through-water velocity (m/s, body) from the joint filter.
            inputs: the model inputs (``inputs.r`` the yaw rate, rad/s).
            velocity_fresh: a velocity was measured within the last second (the yaw RLS
                learns only then).
        """
        if self.yaw_rls is None or self.svf is None:
            return
        i = self._i_yaw
        phi = self.model.regressor_rows(nu, inputs)[i]
        self.svf.update(dt, (inputs.r,) + phi)
        if (not self.identify or "yaw" in self.configured
                or nu[0] < self.identify_min_speed):
            return  # a configured yaw model is kept (the flow observer's gain rests on it)
        if not velocity_fresh:
            return
        self.yaw_rls.update(self.svf.y[1:], self.svf.dy[0])
        self.thetas[i] = self.yaw_rls.theta
        self.rls_updates += 1

    def restore_yaw(self, state: Mapping[str, Any]) -> None:
        """Restore the yaw RLS from :meth:`.RecursiveLeastSquares.get_state` and use its
        coefficients."""
        if self.yaw_rls is None:
            return
        self.yaw_rls.set_state(state)
        self.thetas[self.model.channels.index("yaw")] = self.yaw_rls.theta.copy()


@mypyc_attr(allow_interpreted_subclasses=True)
class VelocityRls:
    """The velocity DOFs' coefficients identified by recursive least squares from an
    observer's own through-water velocity (Kim et al. §II.B, eq. 6-9; algorithms.md §3.4):
    the identification the paper pairs with its high-gain observer, independent of the joint
    filter's coefficient states.

    Per DOF ``i``, ``nu_r,i' = phi_i(nu_r, omega, attitude, u)^T theta_i`` with both sides
    through one state-variable filter (:class:`StateVariableFilter`), so ``d/dt (H nu_r,i) =
    (H phi_i)^T theta_i`` holds for constant coefficients without differentiating the
    observer's velocity; one :class:`.rls.RecursiveLeastSquares` per DOF. The prior is the
    identification's (:class:`ModelIdentification`: configured coefficients tight, the
    generic ones loose, the net-weight ones physically scaled), as a covariance in units of
    the equation error's variance ``noise_std^2``. Forgetting is the trace-bounded rule of
    :mod:`.rls` (none once the covariance is back at the prior trace) and EFRA.

    Attributes:
        thetas: coefficients in use, one array per velocity DOF (a new array after each
            update of that DOF).
        rls: the per-DOF estimators.
        prior_dof: per DOF, True if none of its coefficients is configured (mode (b)).
        masked: per DOF, True while its coefficients are still the generic prior (the sum
            of their variances above a quarter of the prior's; as
            :meth:`ModelIdentification.lift_masks`).
        noise_std: one-sigma of the filtered equation error (m/s^2).
        n_updates: RLS updates applied (all DOFs at one tick count once).
        n_rejected: per-DOF updates undone by the damping projection (:meth:`step`).

    Cost: one RLS update per DOF and two model linearizations per learning tick.
    """

    def __init__(self, ident: ModelIdentification, *, noise_std: float, forgetting: float,
                 svf_cutoff_hz: float) -> None:
        """Args:
            ident: the prior (its coefficients at construction, ``prior_sd``,
                ``prior_dof``); nothing else of it is used.
            noise_std: one-sigma of the equation error (m/s^2) the prior is weighed
                against.
            forgetting: forgetting factor per update (0.1 s).
            svf_cutoff_hz: cut-off of the state-variable filter (Hz).
        """
        model = ident.model
        self.model = model
        self.nd = nd = model.nd
        self.noise_std = noise_std
        v = noise_std * noise_std
        self.thetas: list[np.ndarray] = [np.array(t, float) for t in ident.thetas[:nd]]
        self.rls: list[RecursiveLeastSquares] = []
        self._tr0: list[float] = []
        for ch, th, sd in zip(model.dofs, self.thetas, ident.prior_sd[:nd]):
            var = sd * sd / v
            est = RecursiveLeastSquares(
                len(th), forgetting=forgetting, p0=float(np.max(var)),
                tr_max=float(np.sum(var)), theta0=th, names=model.terms[ch], sigma2_0=v)
            est.P = np.diag(var)
            self.rls.append(est)
            self._tr0.append(float(np.sum(var)))
        self.prior_dof = list(ident.prior_dof)
        self.masked = list(ident.prior_dof)
        self._sizes = [len(t) for t in self.thetas]
        self.svf = StateVariableFilter(nd + sum(self._sizes), svf_cutoff_hz)
        self.n_updates = 0
        self.n_rejected = 0

    def restart(self, thetas: Sequence[np.ndarray], cov: np.ndarray | None = None) -> None:
        """Continue from the coefficients ``thetas`` (a restored model); with ``cov``
        (their covariance, concatenated in DOF order, as :meth:`covariance`) each DOF's
        block becomes its RLS's covariance, else the covariance is kept."""
        o = 0
        for i, (est, th) in enumerate(zip(self.rls, thetas)):
            k = self._sizes[i]
            if len(th) == est.n and np.all(np.isfinite(th)):
                st = {**est.get_state(), "theta": np.asarray(th, float).tolist()}
                if cov is not None:
                    st["P"] = (cov[o:o + k, o:o + k] / (self.noise_std * self.noise_std)
                               ).tolist()
                est.set_state(st)
                self.thetas[i] = est.theta
            o += k

    def covariance(self) -> np.ndarray:
        """Covariance of the velocity DOFs' coefficients (concatenated in DOF order):
        each DOF's RLS covariance in units of the equation error's variance times
        ``noise_std^2`` (the scale its prior was weighed against), DOFs uncorrelated."""
        out = np.zeros((sum(self._sizes), sum(self._sizes)))
        o = 0
        for est, k in zip(self.rls, self._sizes):
            out[o:o + k, o:o + k] = est.P * (self.noise_std * self.noise_std)
            o += k
        return out

    def step(self, dt: float, nu: Sequence[float], inputs: ModelInputs,
             learn: bool) -> None:
        """Filter the observer's velocity ``nu`` (m/s, body) and the regressors at it over
        ``dt`` (s); with ``learn``, one RLS update per DOF."""
        nd = self.nd
        rows = self.model.regressor_rows(nu, inputs, dofs_only=True)
        self.svf.update(dt, [float(a) for a in nu[:nd]] + [a for r in rows for a in r])
        if not learn:
            return
        y, dy = self.svf.y, self.svf.dy
        saved = [est.get_state() for est in self.rls]
        nu_f = [float(a) for a in nu[:nd]]
        _, _, J0 = self.model.linearize(nu_f, inputs, [t.tolist() for t in self.thetas])
        o = nd
        for i, (est, k) in enumerate(zip(self.rls, self._sizes)):
            est.update(y[o:o + k], dy[i])
            self.thetas[i] = est.theta
            o += k
        # projection onto damped models: an update that leaves a DOF's own damping
        # d nu_i' / d nu_i non-negative at this velocity and less damped than before (or
        # non-finite coefficients) is undone; the observer integrates this model, and an
        # undamped one makes it run away (a generic surge prior starts at zero damping)
        _, _, J = self.model.linearize(nu_f, inputs, [t.tolist() for t in self.thetas])
        for i, est in enumerate(self.rls):
            if not (np.all(np.isfinite(self.thetas[i]))
                    and (J[i][i] < 0.0 or J[i][i] <= J0[i][i])):
                est.set_state(saved[i])
                self.thetas[i] = est.theta
                self.n_rejected += 1
            elif self.masked[i] and float(np.trace(est.P)) < MASK_LIFT_FRACTION * self._tr0[i]:
                self.masked[i] = False
        self.n_updates += 1
