"""The increment filter of one surge or heading axis, with its input model composed in.

algorithms.md §2.2 and §2.7. One axis of the seed paper (Faros & Tanner 2025) is a Kalman
filter of the increment ``y_k`` between two measurement points (path length in m, or
heading change in rad) on the first-order model of §1.1; what the ``aie`` pipeline and its
``kf`` baseline do differently is only the input ``u`` of the forecast, which an
:class:`~onboard.estimators.input_models.InputModel` supplies (§2.12). One step, in the
order of §2.7::

    forecast      x_fc = A x_da + B u,        P_f = A P A^T + V_u B B^T      (step 1)
    innovation    z = C x_fc - y,   S = C P_f C^T + R,   NIS = z^2 / S         (step 2)
    outlier gate  NIS > gate_nis: skipped (at most MAX_CONSECUTIVE_REJECTS in a row)
    input model   AIE: the RCIE step on z (steps 3-5); KF: nothing. It returns its
                  decision (InputStep: V_u from now on, diverged), which the filter applies
    update        x_da = x_fc - L z,   P = (I - L C) P_f                        (step 6)
    rate row      y_v = v + n_v (GNSS Doppler speed), assimilated after the increment

The rate row's forecast innovation ``z_v = v_fc - y_v`` also drives the covariance matching
of ``V_u`` (``adaptive_rate_noise``): ``E[z_v^2] = S_v`` with ``S_v = alpha^2 P_vv + c1^2
V_u + R_v`` affine in ``V_u``, once the rate's own noise has been learned (before, an
excess of Doppler noise would be taken for an input error).

Each measurement row learns its own noise from its innovations (algorithms.md §9,
:class:`~onboard.estimators.noise_learning.NoiseScale`): the increment's point noise
``R = s R_0`` (``noise``) and the rate's ``R_v = s_v R_v0`` (``rate_noise``), both ways.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, Mapping

from mypy_extensions import mypyc_attr

from onboard.core.messages import Innovation
from onboard.estimators.axis_model import AxisModel, Discrete
from onboard.estimators.input_models import AxisInnovation, InputModel
from onboard.estimators.noise_learning import NoiseScale, ProcessScale

RUNNING_MEAN_GAIN = 0.05
"""Weight of the newest value in the running means of the rate innovations (and of the
NIS): a memory of about 20 steps."""
RATE_BIAS_MEAN_GAIN = 0.1
"""Weight of the newest rate innovation in its running mean (about 10 steps)."""
RATE_BIAS_POWER_GAIN = 0.01
"""Weight of the newest squared running mean in its own mean (about 100 steps)."""
MAX_CONSECUTIVE_REJECTS = 5
"""Outliers skipped in a row; the next one is taken (a real jump, not an outlier)."""
NIS_CLIP = 1e6
"""A single NIS enters the running mean at most this large."""
PENDING_INNOVATIONS = 1024
"""Innovation records kept until the pipeline's owner takes them; older ones are dropped."""
DAMPING_FLOOR_PER_S = 0.05
"""Smallest damping rate a (1/s) taken when a persistent input error is turned into a
speed error ``du / a`` (an undamped model would make it unbounded)."""


@mypyc_attr(allow_interpreted_subclasses=True)
class IncrementFilter:
    """One axis: the §2.2 filter, its outlier gate, the rate row and the input model.

    Attributes (read them to debug):
        kf: the filter (:class:`~onboard.estimators.kalman.IncrementKF`, or the
            bias-augmented one the input model asks for).
        model: the axis model of §1.1 (``a``, ``gain``, ``offset``).
        input: the input model (:mod:`onboard.estimators.input_models`).
        V_u: the forecast's input-error variance ((m/s^2)^2 or (rad/s^2)^2): the
            configured ``V_u0``, raised by the rate innovations (``adaptive_rate_noise``)
            or adapted by the input model (ASE, §2.8).
        last_command: mean normalized command over the last step (None without one).
        nis_avg: running mean of the accepted increment NIS (expected 1).
        rate_z, rate_S: forecast innovation of the measured rate at this step and its
            variance (None and 0 without one); rate_nis: its NIS after the update.
        steps, rejected, diverged, restarts: updates, skipped outliers, input-model
            divergences, restarts after a gap; rate_steps, rate_rejected: the same for the
            rate row.
        innovations: the records of the updates not yet taken (channels
            ``<name>.increment`` and ``<name>.rate``; innovation = measured - forecast).
        noise, rate_noise: the learned noise scales of the increment's points and of the
            rate (:class:`.NoiseScale`); the ``R``, ``R_prev`` and ``R_v`` a step is
            given are the declared ones, multiplied by them.
    """

    def __init__(self, model: AxisModel, input_model: InputModel, *, input_error_var: float,
                 u_max: float, q_v: float, correlated: bool, gate_nis: float,
                 adaptive_rate_noise: bool, name: str = "axis") -> None:
        """Args:
            model: the axis model (§1.1).
            input_model: supplies the forecast's input (§2.12).
            input_error_var: the configured ``V_u`` (unit of ``u`` squared).
            u_max: the physical bound of the input (unit of ``u``): the first rate's
                prior spread is ``u_max dt``, and ``V_u`` stays below ``(2 u_max)^2``.
            q_v: extra random walk of the rate per step.
            correlated: model the MA(1) noise of increments (§2.2).
            gate_nis: NIS beyond which a measurement is an outlier.
            adaptive_rate_noise: covariance matching of ``V_u`` on the rate row.
            name: the axis (``surge``, ``heading``): the prefix of its channels.
        """
        self.name = name
        self.model = model
        self.input = input_model
        self.u_max = u_max
        self.gate_nis = gate_nis
        self.adaptive_rate_noise = adaptive_rate_noise
        self.V_u = self.V_u0 = input_error_var
        self.kf = input_model.make_filter(q_v, correlated)
        self.last_command: float | None = None
        self.steps = self.rejected = self.diverged = self.restarts = 0
        self.nis_avg = 1.0
        self.rate_nis = 0.0
        self.rate_steps = self.rate_rejected = 0
        self.rate_z: float | None = None
        self.rate_S = 0.0
        self._consecutive_rejects = 0
        self._rate_consecutive_rejects = 0
        self._rate_ms = 0.0     # running mean of z_v^2 ((m/s)^2)
        self._rate_pred = 0.0   # running mean of S_v ((m/s)^2)
        self._rate_mean = 0.0   # running mean of z_v (m/s)
        self._rate_bias2 = 0.0  # running mean of its square ((m/s)^2)
        self._c1 = 0.0          # c1 (s) of the last step with a rate
        self.innovations: deque[Innovation] = deque(maxlen=PENDING_INNOVATIONS)
        self._increment_channel = f"{name}.increment"   # the innovation records' channels
        self._rate_channel = f"{name}.rate"
        self.noise = NoiseScale(f"{name}.increment", "", 0.0, "")
        self.rate_noise = NoiseScale(f"{name}.rate", "", 0.0, "")
        self.process: ProcessScale | None = None
        """The learned scale of ``V_u`` from the increments (algorithms.md §9.3; None: the
        axis does not learn it): the forecast takes ``q V_u``."""

    # -- §2.7, one step ------------------------------------------------------------------

    def step(self, k: Discrete, y: float, R: float, R_prev: float,
             command: float | None, y_v: float | None = None, R_v: float = 0.0, *,
             t: float = math.nan, source: str = "", R_drift: float = 0.0) -> None:
        """One step over ``k.dt`` (§2.7).

        ``y``: the increment (m or rad) between two points of noise variances ``R`` and
        ``R_prev``; ``command``: the mean normalized command over the step (None if
        unknown); ``y_v``: the rate measured at the newer point (m/s, the window's mean
        Doppler speed; None without one), of noise variance ``R_v``; ``t``, ``source``:
        the newer point's time (s) and sample source, for the innovation records;
        ``R_drift``: the variance of the receiver's drift's change over the step, part of
        the increment's noise that does not carry to the next (``IncrementKF``). The
        variances are the declared ones: the learned scales multiply them.
        """
        kf = self.kf
        s = self.noise.applied
        R, R_prev, R_v = s * R, s * R_prev, self.rate_noise.applied * R_v
        q_drift = s * R_drift
        self.last_command = command
        kf.R = R if kf.correlated else R + R_prev
        if not kf.initialized:
            self._start(k, y, R, R_prev, command, y_v, R_v, t, source)
            return
        kf.forecast(k, self.input.forecast_input(kf, self._u_known(command), y_v is not None),
                    self.forecast_var_u)
        self.rate_z = None if y_v is None else self._rate_innovation(k, y_v, R_v)
        kf.innovation(y, q_drift)
        gate = (self.gate_nis if self._consecutive_rejects < MAX_CONSECUTIVE_REJECTS
                else math.inf)
        accepted = not kf.nis > gate
        self.innovations.append(Innovation(
            channel=self._increment_channel, t=t, z=(-kf.z,), S=(kf.S,), nis=kf.nis,
            dof=1, gate=self.gate_nis, accepted=accepted,
            reason="" if accepted else "gate", source=source))
        if not accepted:
            self.rejected += 1
            self._consecutive_rejects += 1
            kf.skip()
        else:
            self._consecutive_rejects = 0
            self.nis_avg += RUNNING_MEAN_GAIN * (min(kf.nis, NIS_CLIP) - self.nis_avg)
            self.noise.observe(kf.z, kf.S, kf.R)
            if self.process is not None:
                self.process.observe(self.noise)
            decision = self.input.after_innovation(
                AxisInnovation(kf, self.rate_z, self.rate_S, self.nis_avg, self.V_u), k,
                self._u_known(command))
            if decision.diverged:
                self.after_divergence(k)
            self.V_u = decision.V_u
            kf.update()
            self.steps += 1
        if y_v is not None:
            self._rate_update(y_v, R_v, t, source)

    def _start(self, k: Discrete, y: float, R: float, R_prev: float,
               command: float | None, y_v: float | None, R_v: float, t: float,
               source: str) -> None:
        """The first increment starts the filter: ``v = y / dt``, its variance the
        input's bound over the step plus both points' noise, ``(u_max dt)^2 + (R +
        R_prev) / dt^2`` (§2.2). That first update is no test of the filter: it makes
        no innovation record."""
        var_v = (self.u_max * k.dt) ** 2 + (R + R_prev) / (k.dt * k.dt)
        self.kf.init(y, k.dt, R_prev, var_v)
        self.input.start(self._u_known(command), R + R_prev)
        if y_v is not None:
            self._rate_update(y_v, R_v, t, source)

    @property
    def forecast_var_u(self) -> float:
        """The input-error variance the forecast takes: ``q V_u``, ``q`` the learned
        process-noise scale (:attr:`process`; 1 without one)."""
        return self.V_u if self.process is None else self.process.scale * self.V_u

    def set_input_error_var(self, input_error_var: float) -> None:
        """Use ``input_error_var`` as the configured ``V_u`` from the next step on (the
        pipeline's measurement set changed): ``V_u0`` and ``V_u`` both take it, so an
        adaptation starts again from it; the state and what the input model learned are
        kept."""
        self.V_u = self.V_u0 = input_error_var

    def restart(self) -> None:
        """Forget the state (a gap in the measurements); keep what the input model and
        the model have learned."""
        self.kf.initialized = False
        self.restarts += 1

    # -- the rate row ----------------------------------------------------------------------

    def _rate_innovation(self, k: Discrete, y_v: float, R_v: float) -> float:
        """The forecast innovation ``z_v = v_fc - y_v`` of the measured rate and its
        variance ``S_v = P_vv + R_v``; inside the gate they update the running means
        behind :meth:`speed_bias_var` and the covariance matching of ``V_u``."""
        kf = self.kf
        z_v = kf.v - y_v
        S_v = self.rate_S = kf.P[3] + R_v
        if z_v * z_v <= self.gate_nis * S_v:
            self._rate_ms += RUNNING_MEAN_GAIN * (z_v * z_v - self._rate_ms)
            self._rate_pred += RUNNING_MEAN_GAIN * (S_v - self._rate_pred)
            self._rate_mean += RATE_BIAS_MEAN_GAIN * (z_v - self._rate_mean)
            m2 = self._rate_mean * self._rate_mean
            self._rate_bias2 += RATE_BIAS_POWER_GAIN * (m2 - self._rate_bias2)
            self._c1 = k.c1
            self.rate_noise.observe(z_v, S_v, R_v)
            if self.adaptive_rate_noise and self.rate_noise.learned:
                self._match_input_error_var(z_v * z_v - S_v, k.c1)
        return z_v

    def _match_input_error_var(self, excess: float, c1: float) -> None:
        """Covariance matching on the rate innovation: one stochastic-approximation step
        ``V_u += g (z_v^2 - S_v) / c1^2`` (``S_v`` affine in ``V_u`` with slope ``c1^2``),
        kept in [configured ``V_u0``, ``(2 u_max)^2``]."""
        v = self.V_u + RUNNING_MEAN_GAIN * excess / (c1 * c1)
        hi = 4.0 * self.u_max * self.u_max
        self.V_u = self.V_u0 if v < self.V_u0 else hi if v > hi else v

    def _rate_update(self, y_v: float, R_v: float, t: float, source: str) -> None:
        """Assimilate the measured rate (``IncrementKF.update_rate``, after the increment;
        its record's innovation is ``y_v - v``, measured minus forecast); an outlier beyond ``gate_nis`` is left
        out and counted, at most MAX_CONSECUTIVE_REJECTS in a row."""
        gate = (self.gate_nis if self._rate_consecutive_rejects < MAX_CONSECUTIVE_REJECTS
                else math.inf)
        kf = self.kf
        self.rate_nis = kf.update_rate(y_v, R_v, gate)
        self.rate_steps += 1
        accepted = self.rate_nis <= gate
        self.innovations.append(Innovation(
            channel=self._rate_channel, t=t, z=(-kf.z_v,), S=(kf.S_v,), nis=self.rate_nis,
            dof=1, gate=self.gate_nis, accepted=accepted, reason="" if accepted else "gate",
            source=source))
        if not accepted:
            self.rate_rejected += 1
            self._rate_consecutive_rejects += 1
        else:
            self._rate_consecutive_rejects = 0

    # -- what the pipeline asks ------------------------------------------------------------

    def damping(self, command: float | None) -> float:
        """The damping rate ``a`` (1/s) of the model over a step with ``command``."""
        return self.input.damping(self.model.a, command is not None)

    def input_ahead(self, command: float | None) -> float:
        """The input (unit of ``u``) to predict with beyond the last step, given the
        newest command."""
        return self.input.input_ahead(self.kf, self._u_known(command))

    def _u_known(self, command: float | None) -> float | None:
        """The nominal input ``gain c + offset`` of ``command`` (None without one)."""
        return None if command is None else self.model.input(command)

    def input_health(self) -> dict[str, float]:
        """What the input model reports (:meth:`.InputModel.health`)."""
        return self.input.health(self.V_u)

    def input_state(self) -> dict[str, Any]:
        """What the input model learned, with ``V_u`` where it adapts it (JSON-safe)."""
        return self.input.get_state(self.V_u)

    def set_input_state(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`input_state`; a ``V_u`` the input model returns is taken."""
        V_u = self.input.set_state(state)
        if V_u is not None:
            self.V_u = V_u

    def speed_bias_var(self) -> float:
        """Variance ((m/s)^2) of a rate error that persists while no measurement comes
        (dead reckoning): the rate's variance now plus the input error the rate
        innovations show beyond what the filter predicts (their mean square less the mean
        predicted ``S_v``, plus the square of their running mean, over ``c1^2``) held as
        a constant bias, which the first-order model turns into a rate error ``du / a``.
        Without measured rates ``V_u`` is taken as that bias."""
        a = max(self.model.a, DAMPING_FLOOR_PER_S)
        if self._c1 > 0.0:
            excess = self._rate_ms - self._rate_pred
            var_u = ((excess if excess > 0.0 else 0.0) + self._rate_bias2) / (
                self._c1 * self._c1)
        else:
            var_u = self.V_u
        return self.kf.P[3] + var_u / (a * a)

    def published_rate_factor(self) -> float:
        """The variance factor (at most 1) of the published rate's sigma, apart from the
        gain (algorithms.md §9.1): the consistency factor of the Doppler row where it has
        one, else of the increment row; never below what either row's learned noise
        supports (:attr:`.NoiseScale.supported_floor`)."""
        row = self.rate_noise if self.rate_noise.consistency.n else self.noise
        floor = max(self.noise.supported_floor, self.rate_noise.supported_floor)
        return row.consistency.factor(floor)

    def after_divergence(self, k: Discrete) -> None:
        """The input model diverged and restarted (its :class:`.InputStep` says so, §2.7
        step 4): count it, forget the NIS history and widen the rate by the input's bound
        over one step, ``(u_max dt)^2``."""
        self.diverged += 1
        self.nis_avg = 1.0
        self.kf.pvv += (self.u_max * k.dt) ** 2
