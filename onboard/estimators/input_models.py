"""The input of an axis filter's forecast: estimated (AIE) or commanded (the KF baseline).

algorithms.md §2.12: the ``aie`` and ``kf`` pipelines run the same increment filter
(:class:`~onboard.estimators.increment_filter.IncrementFilter`) and differ only in the
input ``u`` of its forecast ``x_fc = A x_da + B u``:

* :class:`RcieInput` (AIE, §2.7): ``u = d_hat + u_known``, the input estimate ``d_hat``
  of retrospective-cost input estimation (:class:`~onboard.estimators.rcie.Rcie`) learned
  from the filter's innovations, plus the nominal input of the commands (``known_input``);
* :class:`CommandedInput` (the paper's "standard Kalman filter"): ``u = gain c + offset``,
  the command at nominal scaling, plus an input-bias state where configured.

An input model is called by the filter at fixed points of its step: :meth:`start` when
the filter (re)starts, :meth:`forecast_input` for the step just ended, and
:meth:`after_innovation` between the innovation and the update; the pipeline asks
:meth:`input_ahead` and :meth:`damping` to predict between steps.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Mapping, Protocol

from onboard.estimators.axis_model import Discrete
from onboard.estimators.kalman import BiasIncrementKF, IncrementKF
from onboard.estimators.rcie import Rcie

if TYPE_CHECKING:
    from onboard.estimators.increment_filter import IncrementFilter


class InputModel(Protocol):
    """What an :class:`IncrementFilter` needs of its input."""

    def make_filter(self, q_v: float, correlated: bool) -> IncrementKF:
        """The filter whose state this input needs (the KF's bias state, or none)."""
        ...

    def start(self, f: IncrementFilter, command: float | None, point_var: float) -> None:
        """The filter (re)started on an increment of noise variance ``point_var`` (the
        sum of its two points'), with the step's mean ``command``."""
        ...

    def forecast_input(self, f: IncrementFilter, command: float | None,
                       has_rate: bool) -> float:
        """``u`` over the step just ended (§2.7 step 1), given its mean command."""
        ...

    def after_innovation(self, f: IncrementFilter, k: Discrete,
                         command: float | None) -> None:
        """Between the innovation and the update of an accepted step."""
        ...

    def input_ahead(self, f: IncrementFilter, command: float | None) -> float:
        """``u`` to predict with beyond the last step, given the newest command."""
        ...

    def damping(self, f: IncrementFilter, command: float | None) -> float:
        """The damping rate ``a`` (1/s) of the model over a step with ``command``."""
        ...

    def health(self, f: IncrementFilter) -> dict[str, float]:
        """Diagnostics of the input, by name."""
        ...

    def get_state(self, f: IncrementFilter) -> dict[str, Any]:
        """What the input learned, JSON-safe."""
        ...

    def set_state(self, f: IncrementFilter, state: Mapping[str, Any]) -> None:
        """Restore :meth:`get_state`; ignore what does not fit."""
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

    def start(self, f: IncrementFilter, command: float | None, point_var: float) -> None:
        """The first start fixes the innovation's normalization ``z_scale = sqrt(R_k +
        R_{k-1})`` (§2.3); every start takes the command's nominal input."""
        if not self._z_scale_set:
            self.rcie.z_scale = math.sqrt(point_var)
            self._z_scale_set = True
        if self.known_input and command is not None:
            self.u = f.model.input(command)

    def forecast_input(self, f: IncrementFilter, command: float | None,
                       has_rate: bool) -> float:
        """``u = d_hat_{k-1} + u_known`` over the step just ended (§2.7 step 1)."""
        u = self.d_hat
        if self.known_input and command is not None:
            u += f.model.input(command)
        return u

    def after_innovation(self, f: IncrementFilter, k: Discrete,
                         command: float | None) -> None:
        """§2.7 steps 3-5: the RCIE step, the divergence check, the input for the coming
        step, and optionally ASE (§2.8)."""
        d = self._rcie_step(f, k)
        rc = self.rcie
        if (d is None or abs(rc.d_hat_raw) > self.divergence_input * self.u_max
                or (rc.steps > DIVERGENCE_MIN_STEPS and f.nis_avg > self.divergence_nis)):
            self.rcie.reset()
            f.after_divergence(k)
            d = 0.0
        self.d_hat = d
        self.u = d + (f.model.input(command)
                      if self.known_input and command is not None else 0.0)
        if self.adaptive:
            self._adapt(f, k)

    def _rcie_step(self, f: IncrementFilter, k: Discrete) -> float | None:
        """RCIE on the informative innovation (§2.4, §2.10): with a measured rate its
        forecast innovation ``z_v`` (Markov parameter ``C_v B = c1``, normalized by its
        predicted std), else the increment's ``z`` (``H_1 = c2``, or ``n_f`` taps)."""
        rc = self.rcie
        if f.rate_z is not None:
            rc.z_scale = math.sqrt(f.rate_S)
            return rc.step(f.rate_z, [k.c1])
        H = [k.c2] if rc.n_f == 1 else f.kf.markov(k, rc.n_f)
        return rc.step(f.kf.z, H)

    def _adapt(self, f: IncrementFilter, k: Discrete) -> None:
        """ASE (§2.8): ``V_d`` such that the predicted innovation variance matches the
        sample variance ``S_hat`` of the last ``N_w`` innovations. ``S`` is affine in
        ``V_d`` (``S - V_u c2^2 + V c2^2``), so the match has the closed form
        ``V* = (S_hat - S + V_u c2^2) / c2^2``."""
        w = self._zwin
        w.append(f.kf.z)
        nw = self.adaptive_window
        if len(w) > nw:
            del w[0]
        if len(w) < max(ASE_MIN_FILL, nw // 2):
            return
        m = sum(w) / len(w)
        s_hat = sum((x - m) ** 2 for x in w) / (len(w) - 1)
        c2 = k.c2
        base = f.kf.S - f.V_u * c2 * c2
        v = (s_hat - base) / (c2 * c2)
        lo, hi = ASE_FLOOR * self.u_scale ** 2, ASE_CEILING * self.u_max ** 2
        v = lo if v < lo else hi if v > hi else v
        f.V_u += ASE_GAIN * (v - f.V_u)

    def input_ahead(self, f: IncrementFilter, command: float | None) -> float:
        """``d_hat`` plus the nominal input of the newest command (with
        ``known_input``), else the input of the last step."""
        if self.known_input and command is not None:
            return self.d_hat + f.model.input(command)
        return self.u

    def damping(self, f: IncrementFilter, command: float | None) -> float:
        """The model's ``a``."""
        return f.model.a

    def health(self, f: IncrementFilter) -> dict[str, float]:
        """``input`` (``d_hat``), ``V_d`` (the filter's ``V_u``) and ``theta_norm``."""
        return {"input": self.d_hat, "V_d": f.V_u,
                "theta_norm": math.sqrt(sum(x * x for x in self.rcie.theta))}

    def get_state(self, f: IncrementFilter) -> dict[str, Any]:
        """RCIE's ``theta`` and ``P``, and ``V_d``."""
        return {"rcie": self.rcie.get_state(), "V_d": f.V_u}

    def set_state(self, f: IncrementFilter, state: Mapping[str, Any]) -> None:
        """Restore :meth:`get_state`; a malformed or non-positive ``V_d`` is ignored."""
        if isinstance(state.get("rcie"), dict):
            self.rcie.set_state(state["rcie"])
        v = state.get("V_d")
        if isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0:
            f.V_u = float(v)


# ---------------------------------------------------------------------------------------
# The KF baseline: the commanded input at nominal scaling (§2.12)

CONSTANT_RATE_DAMPING_PER_S = 1e-9
"""The damping rate (1/s) of the constant-rate model the baseline runs without a command
(``a -> 0``: a random-walk rate)."""


class CommandedInput:
    """The baseline's input (§2.12): ``u = gain c + offset`` of the mean command, plus
    an input bias ``b`` estimated as a fourth state where ``bias_q > 0``
    (:class:`~onboard.estimators.kalman.BiasIncrementKF`). Without a command the input
    is zero and the model the constant-rate one (:data:`CONSTANT_RATE_DAMPING_PER_S`).

    Attributes:
        u: the nominal input of the last step's command (unit of ``u``).
        bias_q: the bias's random walk ((unit of ``u``)^2 per second); it walks only over
            steps with a measured rate (the increments alone observe it too weakly).
    """

    def __init__(self, bias_q: float) -> None:
        self.bias_q = bias_q
        self.u = 0.0

    def make_filter(self, q_v: float, correlated: bool) -> IncrementKF:
        """With ``bias_q > 0`` the filter with an input-bias state, starting at 0 with no
        variance (it grows by the random walk)."""
        if self.bias_q > 0.0:
            return BiasIncrementKF(R=1.0, q_v=q_v, correlated=correlated, q_b=0.0, pbb0=0.0)
        return IncrementKF(R=1.0, q_v=q_v, correlated=correlated)

    def start(self, f: IncrementFilter, command: float | None, point_var: float) -> None:
        """The command's nominal input."""
        if command is not None:
            self.u = f.model.input(command)

    def forecast_input(self, f: IncrementFilter, command: float | None,
                       has_rate: bool) -> float:
        """``gain c + offset`` of the step's mean command (0 without one); the bias walks
        only over a step with a measured rate."""
        kf = f.kf
        if isinstance(kf, BiasIncrementKF):
            kf.q_b = self.bias_q if has_rate else 0.0
        self.u = 0.0 if command is None else f.model.input(command)
        return self.u

    def after_innovation(self, f: IncrementFilter, k: Discrete,
                         command: float | None) -> None:
        """Nothing: the input is known."""

    def input_ahead(self, f: IncrementFilter, command: float | None) -> float:
        """The nominal input of the newest command (the last step's without one), plus
        the estimated bias."""
        u = self.u if command is None or f.last_command is None else f.model.input(command)
        kf = f.kf
        return u + kf.b if isinstance(kf, BiasIncrementKF) else u

    def damping(self, f: IncrementFilter, command: float | None) -> float:
        """The model's ``a`` with a command; without one the constant-rate model (the
        damped model with zero input would pull the rate to 0)."""
        return f.model.a if command is not None else CONSTANT_RATE_DAMPING_PER_S

    def health(self, f: IncrementFilter) -> dict[str, float]:
        """Nothing beyond the filter's."""
        return {}

    def get_state(self, f: IncrementFilter) -> dict[str, Any]:
        """Nothing is learned across restarts."""
        return {}

    def set_state(self, f: IncrementFilter, state: Mapping[str, Any]) -> None:
        """Nothing to restore."""
