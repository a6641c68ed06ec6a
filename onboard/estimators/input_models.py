"""The input of an axis filter's forecast: estimated (AIE) or commanded (the KF baseline).

algorithms.md §2.12: the ``aie`` and ``kf`` pipelines run the same increment filter
(:class:`~onboard.estimators.increment_filter.IncrementFilter`) and differ only in the
input ``u`` of its forecast ``x_fc = A x_da + B u``:

* :class:`RcieInput` (AIE, §2.7): ``u = d_hat + u_known``, the input estimate ``d_hat``
  of retrospective-cost input estimation (:class:`~onboard.estimators.rcie.Rcie`) learned
  from the filter's innovations, plus the nominal input of the commands (``known_input``);
* :class:`CommandedInput` (the paper's "standard Kalman filter"): ``u = gain c + offset``,
  the command at nominal scaling, plus an input-bias state where configured.

An input model is called by the filter at fixed points of its step, with numbers, never
with the filter: :meth:`~InputModel.start` when the filter (re)starts,
:meth:`~InputModel.forecast_input` for the step just ended, and
:meth:`~InputModel.after_innovation` between the innovation and the update, which returns
its decision (:class:`InputStep`: the input-error variance from now on, and whether the
estimator diverged) for the filter to act on; the filter asks
:meth:`~InputModel.input_ahead` and :meth:`~InputModel.damping` to predict between steps.
``u_known`` is the command's nominal input ``gain c + offset`` of the axis model (None
without a command).
"""

from __future__ import annotations

import math
from typing import Any, Mapping, NamedTuple, Protocol

from mypy_extensions import mypyc_attr

from onboard.estimators.axis_model import Discrete
from onboard.estimators.kalman import BiasIncrementKF, IncrementKF
from onboard.estimators.rcie import Rcie


class AxisInnovation(NamedTuple):
    """What an input model is shown of an accepted step (§2.7 step 2), before the update."""

    kf: IncrementKF
    """The axis filter after the forecast and the innovation (its ``z``, ``S`` and Markov
    parameters, :meth:`.IncrementKF.markov`); read, not changed."""
    rate_z: float | None
    """The forecast innovation of the measured rate (m/s or rad/s; None without one)."""
    rate_S: float
    """Its variance."""
    nis_avg: float
    """The running mean of the accepted increment NIS."""
    V_u: float
    """The forecast's input-error variance (unit of ``u`` squared)."""


class InputStep(NamedTuple):
    """An input model's decision after an accepted innovation (§2.7 steps 3-5), which the
    filter acts on."""

    V_u: float
    """The input-error variance from the next forecast on (unit of ``u`` squared)."""
    diverged: bool
    """The input estimator diverged and restarted (§2.7 step 4): the filter counts it and
    widens its rate."""


class InputModel(Protocol):
    """What an :class:`~onboard.estimators.increment_filter.IncrementFilter` needs of its
    input."""

    def make_filter(self, q_v: float, correlated: bool) -> IncrementKF:
        """The filter whose state this input needs (the KF's bias state, or none)."""
        ...

    def start(self, u_known: float | None, point_var: float) -> None:
        """The filter (re)started on an increment of noise variance ``point_var`` (the
        sum of its two points'), with the nominal input ``u_known`` of the step."""
        ...

    def forecast_input(self, kf: IncrementKF, u_known: float | None,
                       has_rate: bool) -> float:
        """``u`` over the step just ended (§2.7 step 1), given its nominal input, for the
        filter ``kf`` this model made."""
        ...

    def after_innovation(self, inn: AxisInnovation, k: Discrete,
                         u_known: float | None) -> InputStep:
        """Between the innovation and the update of an accepted step: the decision."""
        ...

    def input_ahead(self, kf: IncrementKF, u_known: float | None) -> float:
        """``u`` to predict with beyond the last step, given the newest command's nominal
        input."""
        ...

    def damping(self, a: float, commanded: bool) -> float:
        """The damping rate (1/s) to predict with over a step, the model's being ``a``;
        ``commanded``: the step has a command."""
        ...

    def health(self, V_u: float) -> dict[str, float]:
        """Diagnostics of the input, by name, at the filter's input-error variance."""
        ...

    def get_state(self, V_u: float) -> dict[str, Any]:
        """What the input learned, JSON-safe, with the filter's input-error variance."""
        ...

    def set_state(self, state: Mapping[str, Any]) -> float | None:
        """Restore :meth:`get_state` (ignore what does not fit); returns the input-error
        variance to restore, or None."""
        ...


# ---------------------------------------------------------------------------------------
# AIE: the RCIE input estimate (§2.7)

DIVERGENCE_MIN_STEPS = 30
"""RCIE steps before a high mean NIS counts as divergence (§2.7 step 4)."""
ASE_MIN_FILL = 10
"""Fewest innovations (or half the window, if more) before ASE adapts ``V_d`` (§2.8)."""
ASE_GAIN = 0.1
"""Step of ``V_d`` toward the matched value per update (§2.8)."""
ASE_FLOOR = 1e-6
"""Lower clip of the matched ``V_d``, times ``u_scale^2`` (§2.8)."""
ASE_CEILING = 10.0
"""Upper clip of the matched ``V_d``, times ``u_max^2`` (§2.8)."""


@mypyc_attr(allow_interpreted_subclasses=True)
class RcieInput:
    """AIE's input (§2.7): ``u = d_hat + u_known``, ``d_hat`` from RCIE.

    Attributes:
        rcie: the input estimator (§2.3-§2.6).
        d_hat: its estimate after the last accepted step (unit of ``u``).
        u: the input applied over the coming step.
    """

    def __init__(self, rcie: Rcie, *, u_max: float, u_scale: float, known_input: bool,
                 divergence_input: float, divergence_nis: float, adaptive: bool,
                 adaptive_window: int) -> None:
        """Args:
            rcie: the estimator, built with this axis's hyperparameters (§2.10).
            u_max: the saturation of ``d_hat`` (unit of ``u``).
            u_scale: the normalization of ``d_hat`` (§2.10).
            known_input: add the commands' nominal input ``gain c + offset`` (§2.1).
            divergence_input: a raw estimate beyond this multiple of ``u_max`` diverged.
            divergence_nis: a mean NIS above this diverged (§2.7 step 4).
            adaptive: adapt ``V_d`` to the innovations (ASE, §2.8).
            adaptive_window: ``N_w``, the innovations ASE averages (steps).
        """
        self.rcie = rcie
        self.u_max = u_max
        self.u_scale = u_scale
        self.known_input = known_input
        self.divergence_input = divergence_input
        self.divergence_nis = divergence_nis
        self.adaptive = adaptive
        self.adaptive_window = adaptive_window
        self.d_hat = 0.0
        self.u = 0.0
        self._z_scale_set = False
        self._zwin: list[float] = []

    def make_filter(self, q_v: float, correlated: bool) -> IncrementKF:
        """The plain increment filter (§2.2)."""
        return IncrementKF(R=1.0, q_v=q_v, correlated=correlated)

    def start(self, u_known: float | None, point_var: float) -> None:
        """The first start fixes the innovation's normalization ``z_scale = sqrt(R_k +
        R_{k-1})`` (§2.3); every start takes the command's nominal input."""
        if not self._z_scale_set:
            self.rcie.z_scale = math.sqrt(point_var)
            self._z_scale_set = True
        if self.known_input and u_known is not None:
            self.u = u_known

    def forecast_input(self, kf: IncrementKF, u_known: float | None,
                       has_rate: bool) -> float:
        """``u = d_hat_{k-1} + u_known`` over the step just ended (§2.7 step 1)."""
        u = self.d_hat
        if self.known_input and u_known is not None:
            u += u_known
        return u

    def after_innovation(self, inn: AxisInnovation, k: Discrete,
                         u_known: float | None) -> InputStep:
        """§2.7 steps 3-5: the RCIE step, the divergence check (the estimator restarts),
        the input for the coming step, and optionally ASE (§2.8)."""
        d = self._rcie_step(inn, k)
        rc = self.rcie
        diverged = (d is None or abs(rc.d_hat_raw) > self.divergence_input * self.u_max
                    or (rc.steps > DIVERGENCE_MIN_STEPS and inn.nis_avg > self.divergence_nis))
        if d is None or diverged:
            rc.reset()
            d = 0.0
        self.d_hat = d
        self.u = d + (u_known if self.known_input and u_known is not None else 0.0)
        V_u = self._adapt(inn, k) if self.adaptive else inn.V_u
        return InputStep(V_u, diverged)

    def _rcie_step(self, inn: AxisInnovation, k: Discrete) -> float | None:
        """RCIE on the informative innovation (§2.4, §2.10): with a measured rate its
        forecast innovation ``z_v`` (Markov parameter ``C_v B = c1``, normalized by its
        predicted std), else the increment's ``z`` (``H_1 = c2``, or ``n_f`` taps)."""
        rc = self.rcie
        if inn.rate_z is not None:
            rc.z_scale = math.sqrt(inn.rate_S)
            return rc.step(inn.rate_z, [k.c1])
        H = [k.c2] if rc.n_f == 1 else inn.kf.markov(k, rc.n_f)
        return rc.step(inn.kf.z, H)

    def _adapt(self, inn: AxisInnovation, k: Discrete) -> float:
        """ASE (§2.8): the input-error variance ``V_d`` after this step, moved towards the
        one whose predicted innovation variance matches the sample variance ``S_hat`` of
        the last ``N_w`` innovations. ``S`` is affine in ``V_d`` (``S - V_u c2^2 + V
        c2^2``), so the match has the closed form ``V* = (S_hat - S + V_u c2^2) / c2^2``.
        Unchanged until the window holds enough innovations."""
        w = self._zwin
        w.append(inn.kf.z)
        nw = self.adaptive_window
        if len(w) > nw:
            del w[0]
        if len(w) < max(ASE_MIN_FILL, nw // 2):
            return inn.V_u
        m = sum(w) / len(w)
        s_hat = sum((x - m) ** 2 for x in w) / (len(w) - 1)
        c2 = k.c2
        base = inn.kf.S - inn.V_u * c2 * c2
        v = (s_hat - base) / (c2 * c2)
        lo, hi = ASE_FLOOR * self.u_scale ** 2, ASE_CEILING * self.u_max ** 2
        v = lo if v < lo else hi if v > hi else v
        return inn.V_u + ASE_GAIN * (v - inn.V_u)

    def input_ahead(self, kf: IncrementKF, u_known: float | None) -> float:
        """``d_hat`` plus the nominal input of the newest command (with
        ``known_input``), else the input of the last step."""
        if self.known_input and u_known is not None:
            return self.d_hat + u_known
        return self.u

    def damping(self, a: float, commanded: bool) -> float:
        """The model's ``a``."""
        return a

    def health(self, V_u: float) -> dict[str, float]:
        """``input`` (``d_hat``), ``V_d`` (the filter's ``V_u``) and ``theta_norm``."""
        return {"input": self.d_hat, "V_d": V_u,
                "theta_norm": math.sqrt(sum(x * x for x in self.rcie.theta))}

    def get_state(self, V_u: float) -> dict[str, Any]:
        """RCIE's ``theta`` and ``P``, and ``V_d`` (the filter's ``V_u``)."""
        return {"rcie": self.rcie.get_state(), "V_d": V_u}

    def set_state(self, state: Mapping[str, Any]) -> float | None:
        """Restore :meth:`get_state`; returns ``V_d`` (None if malformed or not
        positive)."""
        if isinstance(state.get("rcie"), dict):
            self.rcie.set_state(state["rcie"])
        v = state.get("V_d")
        if isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0:
            return float(v)
        return None


# ---------------------------------------------------------------------------------------
# The KF baseline: the commanded input at nominal scaling (§2.12)

CONSTANT_RATE_DAMPING_PER_S = 1e-9
"""The damping rate (1/s) of the constant-rate model the baseline runs without a command
(``a -> 0``: a random-walk rate)."""


@mypyc_attr(allow_interpreted_subclasses=True)
class CommandedInput:
    """The baseline's input (§2.12): ``u = gain c + offset`` of the mean command, plus
    an input bias ``b`` estimated as a fourth state where ``bias_q > 0``
    (:class:`~onboard.estimators.kalman.BiasIncrementKF`). Without a command the input
    is zero and the model the constant-rate one (:data:`CONSTANT_RATE_DAMPING_PER_S`).

    Attributes:
        u: the nominal input of the last step's command (unit of ``u``).
        commanded: whether the last step had a command.
        bias_q: the bias's random walk ((unit of ``u``)^2 per second); it walks only over
            steps with a measured rate (the increments alone observe it too weakly).
    """

    def __init__(self, bias_q: float) -> None:
        self.bias_q = bias_q
        self.u = 0.0
        self.commanded = False

    def make_filter(self, q_v: float, correlated: bool) -> IncrementKF:
        """With ``bias_q > 0`` the filter with an input-bias state, starting at 0 with no
        variance (it grows by the random walk)."""
        if self.bias_q > 0.0:
            return BiasIncrementKF(R=1.0, q_v=q_v, correlated=correlated, q_b=0.0, pbb0=0.0)
        return IncrementKF(R=1.0, q_v=q_v, correlated=correlated)

    def start(self, u_known: float | None, point_var: float) -> None:
        """The command's nominal input."""
        self.commanded = u_known is not None
        if u_known is not None:
            self.u = u_known

    def forecast_input(self, kf: IncrementKF, u_known: float | None,
                       has_rate: bool) -> float:
        """``gain c + offset`` of the step's mean command (0 without one); the bias of the
        filter ``kf`` walks only over a step with a measured rate."""
        if isinstance(kf, BiasIncrementKF):
            kf.q_b = self.bias_q if has_rate else 0.0
        self.commanded = u_known is not None
        self.u = 0.0 if u_known is None else u_known
        return self.u

    def after_innovation(self, inn: AxisInnovation, k: Discrete,
                         u_known: float | None) -> InputStep:
        """Nothing to decide: the input is known."""
        return InputStep(inn.V_u, False)

    def input_ahead(self, kf: IncrementKF, u_known: float | None) -> float:
        """The nominal input of the newest command (the last step's without one, or
        after a step without a command), plus the bias estimated by ``kf``."""
        u = self.u if u_known is None or not self.commanded else u_known
        return u + kf.b if isinstance(kf, BiasIncrementKF) else u

    def damping(self, a: float, commanded: bool) -> float:
        """The model's ``a`` with a command; without one the constant-rate model (the
        damped model with zero input would pull the rate to 0)."""
        return a if commanded else CONSTANT_RATE_DAMPING_PER_S

    def health(self, V_u: float) -> dict[str, float]:
        """Nothing beyond the filter's."""
        return {}

    def get_state(self, V_u: float) -> dict[str, Any]:
        """Nothing is learned across restarts."""
        return {}

    def set_state(self, state: Mapping[str, Any]) -> float | None:
        """Nothing to restore."""
        return None
