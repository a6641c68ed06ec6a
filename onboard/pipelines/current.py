"""Pipeline ``current``: water current from over-ground minus through-water velocity
(algorithms.md §3-§4).

Papers: Kim, Fan & Bose, IEEE Access 6 (2018) (model-based high-gain observer, RLS
identification, Gavia AUV); Fan, Xu, Chen & Zhang, OCEANS (~2016) (nonlinear observer,
flow-relative model, pole placement).

The mathematics lives in :mod:`onboard.estimators`; this module is the adapter between
samples and estimates:

* samples to the model inputs (rates, attitude, commands) and to velocity measurements
  (GNSS SOG/COG and ``VelocityOverGround`` in earth axes, DVL bottom and water track in
  body axes), with their one-sigma from ``[sensors]`` (a GNSS fix's reported horizontal
  accuracy scales its velocity one-sigma, ``gnss_nominal_accuracy_m``);
* the joint Kalman filter of ``[nu_r, V_c, theta]``
  (:class:`~onboard.estimators.current_kf.CurrentKalmanFilter`), which always runs: it
  identifies the vehicle model online
  (:class:`~onboard.estimators.model_identification.ModelIdentification`; mode (a):
  coefficients configured in ``[pipelines.current.model.<dof>]``, refined unless
  ``identify = false``; mode (b): none, a weak generic prior);
* the observer whose current is reported, ``[pipelines.current] observer =``:

  - ``"kf"`` (default): the joint Kalman filter itself;
  - ``"hgo"``: the high-gain observer of Kim et al. with the LMI gain and the increasing-gain
    law of Alessandri & Rossi
    (:class:`~onboard.estimators.current_hgo.CurrentHighGainObserver`), on a model it
    identifies itself by RLS from its own through-water velocity
    (:class:`~onboard.estimators.model_identification.VelocityRls`), from the same prior,
    at gamma* of that model (its Lipschitz bound, recomputed when the RLS changes it);
  - ``"flow"``: the nonlinear observer of Fan et al.
    (:class:`~onboard.estimators.flow_observer.FlowObserver`), which observes ``nu_r``
    from the attitude through the yaw dynamics; the current is then ``V_g - R nu_r``;

* the records: current (north, east[, down]), its one-sigma and ``nu_r``; the innovation
  of every measurement update (below); health (counters, calibration, coefficient
  spread, observability, yaw RLS spread, gain); the identified model and the last current
  as persistent state.

Innovation channels (:meth:`CurrentPipeline.innovations`; innovation = measured minus
forecast):

* the joint Kalman filter: ``velocity`` (velocity over ground in earth axes, GNSS SOG/COG
  or ``VelocityOverGround``: 2 or 3 components, m/s), ``dvl`` (DVL bottom track, body
  axes) and ``water_track`` (DVL water track, body axes), gated at ``gate_nis`` (reason
  ``gate``; ``diverged`` when the update reset the filter); a DVL sample that is invalid
  or beyond its figure of merit, or a velocity that is not finite, is a rejected record
  without an innovation (``invalid``, ``nonfinite``);
* with ``observer = "hgo"``: ``hgo.velocity`` and ``hgo.dvl``, the high-gain observer's
  own innovations (no gate; ``diverged`` when it restarts);
* with ``observer = "flow"``: ``flow.heading``, the heading innovation (rad) of each step
  of the flow observer;
* ``yaw_rls``: the a-priori residual of the yaw channel's RLS (rad/s^2, dimension 1) at
  each of its updates.

Without an identified surge model the along-track current is not observable on a straight
line; weak couplings (pitch, heave prior) make the filter's own variance shrink anyway
(docs/current.md, "Why the current is observable"). The reported
one-sigma is then at least the prior along the track, unless the headings of the last
minutes are diverse enough for the sway constraint alone (``heading_diversity``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from mypy_extensions import mypyc_attr

from onboard.core.config import CONFIG_DIR, Config, ConfigError
from onboard.core.messages import Innovation, Sample
from onboard.core.pipeline_config import CurrentConfig, HgoConfig
from onboard.estimators.current_hgo import CurrentHighGainObserver
from onboard.estimators.current_kf import (
    PREDICT_STEP_S,
    CurrentKalmanFilter,
    VelocityMeasurement,
)
from onboard.estimators.flow_observer import FlowObserver
from onboard.estimators.hgo import GainDesign, IncreasingGain, gamma_star, model_lipschitz
from onboard.estimators.model_identification import (
    ModelIdentification,
    VelocityRls,
    floor_along_track,
)
from onboard.estimators.noise_learning import FLOOR, ChannelNoise, NoiseScale
from onboard.estimators.restored_current import RestoredCurrentCheck
from onboard.estimators.vehicle_models import RegressionModel, kind_for_class
from onboard.pipelines.base import LateSampleHold, PipelineDefaults, unused_measurement
from onboard.pipelines.current_health import CurrentHealth, LateHold, PipelineCounters
from onboard.pipelines.current_samples import CHANNELS, CurrentSamples

UNPUBLISHED_CHANNELS = ("dvl", "water_track", "yaw_rls")
"""The innovation channels whose forecast is of a quantity published without a sigma
(algorithms.md §9.2): the DVL rows forecast the velocity through the water plus the
current in body axes, ``nu_r + R^T V_c`` (bottom track) or ``nu_r`` (water track), whose
sum is known far better than either part (on the torpedo AUV, the spheroid and the
BlueROV2 the current's own forecast variance is 5-25 times the bottom-track rows' ``tr S``:
the split between the two is what the published current's sigma carries, and no
innovation sees it); the yaw RLS's equation error is that of the yaw regression, whose
coefficients the joint filter does not use."""

REGRESSION_CHANNELS = ("yaw_rls",)
"""The innovation channels that are a regression's a-priori residuals (algorithms.md §9.2):
the yaw RLS's ``S`` is ``sigma2 (1 + phi^T P phi)``, its ``sigma2`` the forgetting-weighted
mean of its own residuals (``yaw_forgetting``: 2000 updates), which its gain
(``P phi / s``) does not use and no published sigma takes; its residual, a yaw
acceleration through the state-variable filter, is correlated over seconds (lag-1 0.97 at
10 Hz) and larger in turns than on straight legs, so its NIS swings both ways about 1 over
a run (the bench: block means 0.03-8.3, 0.94 over 900 s)."""

GAIN_DIR = CONFIG_DIR / "gains"
"""Precomputed LMI gains for the bundled configs (``onboard design-gain``)."""


VELOCITY_FRESH_S = 1.0
"""The model identifications learn only while a velocity was measured within this long (s)."""
MEAS_INTERVAL_S = (1e-3, 0.1, 1.0)
"""Interval (s) between velocity measurements as the high-gain observer's increasing-gain
law sees it: (floor, the first measurement's, ceiling)."""
GAMMA_RECHECK_S = 10.0
"""After the high-gain observer's RLS changes its model, gamma* is recomputed at most this
often (s)."""
PENDING_INNOVATIONS = 1024
"""Innovation records kept until the engine takes them; older ones are dropped."""
LATE_FUSE_MAX_S = 0.05
"""A velocity measurement at most this much (s) older than the filter's time is fused at
that time; an older one is dropped (``rejected_late``; with ``max_late_hold_s`` 0, fused
at the filter's time)."""
REASONS: dict[str, str] = {"accepted": "", "gated": "gate", "reset": "diverged",
                           "restarted": "restart", "contradicts_start": "restart"}
"""The record's reason for each outcome of a velocity measurement in the joint filter: its
update's (:data:`.current_kf.UpdateOutcome`), or ``restarted`` when the pipeline started the
filter again from it (:meth:`CurrentPipeline._correct`)."""
HEADING_DEPENDENT = ("north", "east", "down", "u_r", "v_r", "w_r")
"""The columns computed by turning a velocity with the heading: the current is the
velocity over ground less the through-water velocity turned to earth axes by it."""


@mypyc_attr(allow_interpreted_subclasses=True)
class CurrentPipeline(PipelineDefaults):
    """Pipeline ``current``: water current with one-sigma, any vehicle class.

    Inspectable attributes (filterpy style): ``kf`` (the joint Kalman filter: ``x``, ``P``,
    ``y``, ``S``, ``nis``), ``identification`` (prior, schedule, yaw RLS), ``hgo`` and
    ``flow`` (the observer of that variant, or None), ``hgo_rls`` (the high-gain observer's
    own model identification, or None), ``restore_check`` (the probation of a restored
    current), ``inp`` (model inputs), ``roll``, ``pitch``, ``yaw`` (rad), ``counters``
    (its own, :class:`PipelineCounters`; each collaborator keeps its own);
    shortcuts ``x``, ``P``, ``thetas`` (model coefficients in use, per channel),
    ``yaw_rls`` and ``gamma`` (HGO gain, 0 without); with the HGO, ``lipschitz`` and
    ``gamma_star`` of the model it runs (:meth:`_gamma_from_model`).

    Roles: the current and the through-water velocity it has of
    :data:`HEADING_DEPENDENT`; ``north``/``east`` its ``current_estimate``, judged
    against the idle drift; :data:`UNPUBLISHED_CHANNELS` its ``unpublished_channels``,
    :data:`REGRESSION_CHANNELS` its ``regression_channels``
    (:class:`~onboard.pipelines.base.Pipeline`).
    """

    name = "current"
    unpublished_channels = UNPUBLISHED_CHANNELS
    regression_channels = REGRESSION_CHANNELS

    def __init__(self, cfg: CurrentConfig, kind: str, sensors: Any,
                 configured: bool, gain: GainDesign | None = None) -> None:
        """Args:
            cfg: the ``[pipelines.current]`` section.
            kind: regression-model kind (:data:`.RegressionModel.KINDS`).
            sensors: the ``[sensors]`` section (measurement one-sigmas, DVL figure of merit,
                surface depth, compass one-sigma).
            configured: whether model coefficients are configured (mode (a)).
            gain: the HGO's LMI gain (``observer = "hgo"``; None: the analytic fallback).
        """
        self.cfg = cfg
        self.model = RegressionModel(kind)
        self.nd = nd = self.model.nd
        self.columns: tuple[str, ...] = ("north", "east") + (("down",) if nd == 3 else ()) + (
            "std_north", "std_east") + (("std_down",) if nd == 3 else ()) + (
            "u_r", "v_r") + (("w_r",) if nd == 3 else ())
        self.heading_dependent = tuple(c for c in HEADING_DEPENDENT if c in self.columns)
        self.current_estimate = ("north", "east")
        self.configured = configured
        self.counters = PipelineCounters()
        self._innovations: deque[Innovation] = deque(maxlen=PENDING_INNOVATIONS)
        self.identification = _identification(cfg, self.model)
        self.kf = _joint_filter(cfg, self.identification)
        self.noise = _learned_noise(self.kf, cfg, sensors)
        """The learned noise of the velocity channels (algorithms.md §9), what the
        published current's sigma implies for the velocity-over-ground rows and whether
        its slow error holds it (§9.1)."""
        # a partial of the class's function, not a method bound to this object: a copy
        # of the pipeline (the GNSS latency's fork) then takes its own copy's factor
        self.noise.published[CHANNELS["earth"]] = partial(type(self).innovation_factor, self)
        self.noise.slow[CHANNELS["earth"]] = partial(type(self).slow_error_holds, self)
        self.events: list[str] = []
        """Human-readable events not yet taken (:meth:`take_events`): a restored current
        discarded or confirmed, a start contradicted."""
        self.observable: list[bool] = [False] * nd
        """Per earth axis: whether the last published component was known (one-sigma at
        most ``unknown_above_std_mps``)."""
        self.restore_check = RestoredCurrentCheck(
            hold_s=cfg.restore_check_s, false_alarm_p=cfg.restore_check_p,
            unknown_above_std=cfg.unknown_above_std_mps,
            init_current_std=cfg.initial_current_std_mps)
        self._init_observers(cfg, sensors, gain)
        self._init_sample_state(cfg, sensors)

    def _init_observers(self, cfg: CurrentConfig, sensors: Any,
                        gain: GainDesign | None) -> None:
        """The reported observer beside the joint filter (``observer``): the high-gain
        observer with its own RLS, or the flow observer."""
        nd = self.nd
        self.gain = gain
        self.hgo: CurrentHighGainObserver | None = None
        self.hgo_rls: VelocityRls | None = None
        if cfg.observer == "hgo":
            # the observer's own model: RLS from its own velocity, from the same prior
            self.hgo_rls = VelocityRls(self.identification,
                                       noise_std=cfg.hgo.rls_noise_std_mps2,
                                       forgetting=cfg.forgetting,
                                       svf_cutoff_hz=cfg.svf_cutoff_hz)
            self.gain = gain or GainDesign.analytic()
            self.hgo = CurrentHighGainObserver(
                self.model, self.gain, _gain_law(cfg.hgo, self.gain), self.kf.P[:2 * nd, :2 * nd],
                accel_std=cfg.accel_std_mps2, model_error_time_s=cfg.model_error_time_s,
                current_walk=cfg.current_walk_mps_rts)
            self.hgo.consider(self.hgo_rls.covariance())
            self._gamma_follows_model = _gain_is_design_fixed(cfg.hgo, self.gain)
            self._gamma_t = -math.inf
            self._gamma_from_model()
        self.flow: FlowObserver | None = None
        if cfg.observer == "flow":
            self.flow = FlowObserver(self.model, poles=cfg.flow.poles or None,
                                     psi_std=sensors.compass.heading_std_rad,
                                     pitch=cfg.flow.pitch, svf_cutoff_hz=cfg.svf_cutoff_hz)

    def _init_sample_state(self, cfg: CurrentConfig, sensors: Any) -> None:
        """The sample adapter (model inputs, attitude, velocity measurements) and the
        stamps of the fusion."""
        self.samples = CurrentSamples(cfg, sensors, self.nd,
                                      self._innovations)
        self.hold = LateSampleHold(cfg.max_late_hold_s)
        self.inp = self.samples.inp
        self._t: float | None = None
        self._last_meas_t: float | None = None
        self._last_velocity_t: float | None = None

    # ------------------------------------------------------------------ shortcuts
    @property
    def x(self) -> np.ndarray:
        """The joint filter's state ``[nu_r, V_c, theta]``."""
        return self.kf.x

    @property
    def P(self) -> np.ndarray:
        """The joint filter's covariance."""
        return self.kf.P

    @property
    def thetas(self) -> list[np.ndarray]:
        """Model coefficients in use, one array per channel of ``model.channels``."""
        return self.identification.thetas

    @property
    def yaw_rls(self) -> Any:
        """The yaw channel's RLS (None without a yaw channel)."""
        return self.identification.yaw_rls

    @property
    def gamma(self) -> float:
        """The high-gain observer's last gain (0 with another observer)."""
        return self.hgo.gamma if self.hgo is not None else 0.0

    # ------------------------------------------------------------------ samples
    @property
    def roll(self) -> float:
        """Roll in use (rad)."""
        return self.samples.roll

    @property
    def pitch(self) -> float:
        """Pitch in use (rad)."""
        return self.samples.pitch

    @property
    def yaw(self) -> float | None:
        """Heading (rad; None before the first)."""
        return self.samples.yaw

    def _R(self) -> np.ndarray:
        """Body-to-earth rotation at the attitude in use."""
        return self.samples.rotation()

    # ------------------------------------------------------------------ protocol
    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        """Advance to tick ``t`` (s) with the new samples; returns the estimates.

        Each velocity measurement is fused at its own time (algorithms.md §3.5): the
        filters are predicted to it with the inputs of that time, updated with the
        attitude of that time, and after the last one predicted to the tick. Samples that
        arrive late are held (:attr:`hold`): the filter is stepped to the hold's horizon
        with the samples up to it."""
        t, samples = self.hold.release(t, samples)
        t_prev = self._t
        check = self.restore_check
        probation = check.active
        for m in self.samples.measurements(t, samples):
            self._fuse(m, probation)
        if self.yaw is None or not self.kf.started:
            return {}
        t_filter = self._t
        assert t_filter is not None  # set when the filter started
        if t > t_filter:  # nothing to predict at the time of the last measurement
            self._predict(t, t - t_filter, probation)
            self._t = t
        dt = t - t_prev if t_prev is not None else 0.0
        if dt > 0:
            self._identify(dt)
        self._step_flow(dt)
        if probation and check.twin is not None and check.twin.started and dt > 0:
            self._check_restored(dt)
        return self._outputs()

    def _fuse(self, m: VelocityMeasurement, probation: bool) -> None:
        """Velocity measurement ``m`` at its own time ``m.t``: the filters predicted to
        it (when it is newer than their time; the first one starts them), then updated
        with the attitude of that time. Without a heading yet it is not used. One older
        than the filter's time by at most ``LATE_FUSE_MAX_S`` is fused at that time;
        older, it is dropped (counted ``rejected_late``, reason ``late``: it came before
        :attr:`hold` grew to cover it, or after a stall longer than the hold)."""
        if self.yaw is None:
            return
        late_by = self._t - m.t if self._t is not None else 0.0
        if late_by > LATE_FUSE_MAX_S and self.cfg.max_late_hold_s > 0.0:
            self.counters.rejected_late += 1
            self._innovations.append(unused_measurement(
                CHANNELS[m.kind], m.t, len(m.z), "late", m.source))
            return
        if not self.kf.started:
            self._start(m)
        elif self._t is not None and m.t > self._t:  # a late one is fused at the filter's time
            self._predict(m.t, m.t - self._t, probation)
            self._t = m.t
        R = self.samples.rotation_at(m.t)
        if probation:
            self.restore_check.update([m], R)
        self._correct(m, R)

    def _predict(self, t: float, dt: float, probation: bool) -> None:
        """The joint filter's (and the twin's) schedule and prediction over ``dt`` (s) to
        time ``t`` (s: a measurement's or the tick's); the high-gain observer's prediction
        and its own RLS step."""
        kf, hgo = self.kf, self.hgo
        yaw = self.yaw
        assert yaw is not None
        kf.advance(t, dt, self.inp, yaw)
        if probation:
            self.restore_check.advance(t, dt, self.inp, yaw)
        if dt > 0 and hgo is not None:
            assert self.hgo_rls is not None
            n_sub = max(1, math.ceil(dt / PREDICT_STEP_S))
            for _ in range(n_sub):
                if not hgo.predict(dt / n_sub, self.inp, self.hgo_rls.thetas):
                    hgo.restart(kf.x, kf.P)
                    hgo.reset_gain()
            self._identify_hgo(t, dt)

    def _correct(self, m: VelocityMeasurement, R: np.ndarray) -> None:
        """Velocity measurement ``m`` into the joint filter and the reported observer;
        ``R`` the body-to-earth rotation at its time."""
        kf, hgo, flow = self.kf, self.hgo, self.flow
        t_min, t_first, t_max = MEAS_INTERVAL_S
        kind, tm, z, std = m.kind, m.t, m.z, m.std
        dt_meas = tm - self._last_meas_t if self._last_meas_t is not None else t_first
        dt_meas = min(max(dt_meas, t_min), t_max)
        self._last_meas_t = tm
        outcome: str = kf.update(kind, z, std, R)  # its learned noise inside
        y, S, nis = kf.y, kf.S, kf.nis  # the record shows the contradiction, if any
        if outcome == "contradicts_start":
            restart = kf.restart_from(kind, z, std, R)
            outcome = "restarted" if restart == "accepted" else restart
        std = kf.noise_std(kind, std)   # the observers take the learned noise too
        m = m._replace(std=std)
        self._record(CHANNELS[kind], m, y, S, nis, kf.gate_nis, outcome)
        if outcome == "reset" and hgo is not None:
            hgo.reset_gain()
        if outcome == "restarted":
            self._restarted(m, nis)
        elif hgo is not None and not self._update_hgo(m, dt_meas, R):
            hgo.restart(kf.x, kf.P)
            hgo.reset_gain()
        if flow is not None:
            flow.observe_velocity(kind, z, std, R, kf.velocity_over_ground(R) if (
                kind == "earth" and len(z) < self.nd) else None)
        self._last_velocity_t = tm

    def _restarted(self, m: VelocityMeasurement, nis: float) -> None:
        """The joint filter started again from ``m``, which contradicted its start (at NIS
        ``nis``): the observer follows, a restored current (now dropped) ends its
        probation, and an event says so."""
        kf = self.kf
        if self.hgo is not None:
            self.hgo.restart(kf.x, kf.P)
            self.hgo.reset_gain()
        dropped = ""
        if self.restore_check.active:
            self.restore_check.end()
            dropped = "; the restored current is dropped"
        self.events.append(
            f"the start was contradicted by a {CHANNELS[m.kind]} measurement (NIS "
            f"{nis:.0f} > {kf.gate_nis:.0f}): started again from it{dropped}")

    def _update_hgo(self, m: VelocityMeasurement, dt_meas: float, R: np.ndarray) -> bool:
        """The high-gain observer's update with ``m`` and its record (channel
        ``hgo.<channel>``); returns False if it diverged (the caller restarts it)."""
        hgo = self.hgo
        assert hgo is not None
        ok = hgo.update(m.kind, m.z, m.std, dt_meas, R, self.inp)
        if hgo.takes(m.kind, len(m.z)):
            channel = "hgo." + CHANNELS[m.kind]
            if ok:
                self._record(channel, m, hgo.y, hgo.S, hgo.nis)
            else:
                self._innovations.append(unused_measurement(channel, m.t, len(m.z),
                                                            "diverged", m.source))
        return ok

    def _record(self, channel: str, m: VelocityMeasurement, y: np.ndarray, S: np.ndarray,
                nis: float, gate: float = math.inf, outcome: str = "accepted") -> None:
        """The innovation record of one velocity update: ``y`` (m/s) and its covariance
        ``S``, NIS ``nis`` against ``gate``."""
        self._innovations.append(Innovation(
            channel=channel, t=m.t, z=tuple(y.tolist()), S=tuple(S.ravel().tolist()),
            nis=nis, dof=len(y), gate=gate, accepted=outcome == "accepted",
            reason=REASONS[outcome], source=m.source))

    def _step_flow(self, dt: float) -> None:
        """The flow observer's step over ``dt`` (s) with the heading in use, once it has a
        velocity over ground; a step corrected by the heading is recorded
        (``flow.heading``)."""
        flow = self.flow
        if flow is None or flow.v_g is None:
            return
        before = flow.heading_updates
        flow.step(dt if dt > 0 else 0.0, self.yaw, self.inp, self.identification.thetas,
                  self.kf.x[: self.nd])
        if flow.heading_updates != before:
            self._innovations.append(Innovation(
                channel="flow.heading", t=self.samples.yaw_t, z=(float(flow.e),),
                S=(float(flow.S),), nis=float(flow.nis), dof=1,
                source=self.samples.yaw_source))

    def _identify(self, dt: float) -> None:
        """The yaw channel's RLS and, with the flow observer's vertical block, its pitch
        channel's, on the joint filter's through-water velocity."""
        kf, flow, cfg = self.kf, self.flow, self.cfg
        fresh = (self._last_velocity_t is not None
                 and not (self._t or 0.0) - self._last_velocity_t > VELOCITY_FRESH_S)
        rls = self.identification.yaw_rls
        before = rls.n_updates if rls is not None else 0
        self.identification.identify_yaw(dt, kf.x[: self.nd].tolist(), self.inp,
                                          velocity_fresh=fresh)
        if rls is not None and rls.n_updates != before:
            self._innovations.append(Innovation(
                channel="yaw_rls", t=self._t if self._t is not None else math.nan,
                z=(float(rls.e),), S=(float(rls.S),), nis=float(rls.nis), dof=1))
        if flow is not None:
            flow.identify_pitch(dt, kf.x[: self.nd].tolist(), self.inp, learn=(
                fresh and cfg.identify and float(kf.x[0]) >= cfg.identify_min_speed_mps))

    def _identify_hgo(self, t: float, dt: float) -> None:
        """One step of the high-gain observer's own RLS (``[pipelines.current.hgo]
        identify``) on its velocity ``nu_r``: learning while a velocity was measured within
        the last second, the through-water speed is above ``identify_min_speed_mps`` and,
        with ``"turns"``, the observer's horizontal current one-sigma from the noises
        (without its model's uncertainty) is at most ``identify_max_current_std_mps``
        within ``identify_after_turn_s`` of a turn (``identify_straight``: anywhere)."""
        hgo, rls, cfg = self.hgo, self.hgo_rls, self.cfg
        assert hgo is not None and rls is not None
        nu = hgo.x[: self.nd].tolist()
        learn = (cfg.identify and self._last_velocity_t is not None
                 and t - self._last_velocity_t <= VELOCITY_FRESH_S
                 and nu[0] >= cfg.identify_min_speed_mps)
        if learn and cfg.hgo.identify == "turns":
            # the noises' part only: the coefficients' part is what learning reduces (with
            # it a loose prior would never let the RLS learn)
            c_var = hgo.current_cov(model=False).diagonal()
            learn = (math.sqrt(max(float(c_var[0]), float(c_var[1])))
                     <= cfg.identify_max_current_std_mps
                     and (cfg.identify_straight or t - self.identification.last_turn_t
                          <= cfg.identify_after_turn_s))
        before = rls.n_updates
        rls.step(dt, nu, self.inp, learn)
        c = self.counters
        c.hgo_rls_updates = (c.hgo_rls_updates or 0) + rls.n_updates - before
        c.hgo_rls_rejected = rls.n_rejected
        if rls.n_updates != before:
            hgo.consider(rls.covariance())
        if rls.n_updates != before and t - self._gamma_t >= GAMMA_RECHECK_S:
            self._gamma_t = t
            self._gamma_from_model()

    def _gamma_from_model(self) -> None:
        """gamma* of the model the high-gain observer runs (its RLS's coefficients):
        ``L_f`` of that model (:func:`.hgo.model_lipschitz`) into ``gamma* = max(1, 2 ||P||
        L_f / lambda)`` of the gain file's LMI solution, kept as ``lipschitz`` and
        ``gamma_star``; the fixed gain of a gain file (``rho = 0``, nothing configured)
        then runs at gamma* times the file's margin (``gamma / gamma_star``), so the
        observer stays at its own sufficient condition when identification changes the
        model."""
        hgo, rls, design = self.hgo, self.hgo_rls, self.gain
        assert hgo is not None and rls is not None and design is not None
        self.lipschitz = model_lipschitz(self.model, rls.thetas)
        self.gamma_star = gamma_star(design.P, design.lam, self.lipschitz)
        if self._gamma_follows_model:
            g = self.gamma_star * design.gamma / design.gamma_star
            hgo.law.gamma = hgo.law.gamma_max = hgo.gamma_init = g

    def _surge_unobservable(self) -> bool:
        """The along-track current is unobservable for the reported observer: its surge
        model is still the generic prior (the high-gain observer's own RLS, else the joint
        filter's) and the recent headings are not diverse, and no glider model measured
        the through-water speed within ``glider.hold_s``."""
        ident = self.identification
        g = self.cfg.glider
        if g is not None and (self._t or 0.0) - self.samples.glider_t <= g.hold_s:
            return False
        if self.hgo_rls is None:
            return ident.surge_unobservable()
        return self.hgo_rls.masked[0] and ident.headings.length() > ident.heading_diversity

    def _check_restored(self, dt: float) -> None:
        """The restored current against the twin filter (``restore_check_s``,
        :class:`.RestoredCurrentCheck`): a discard puts the twin's state in the joint
        filter (and restarts the high-gain observer from it); both end the probation with
        an event."""
        check = self.restore_check
        verdict = check.evaluate(dt, self.yaw or 0.0)
        if verdict == "discard":
            assert check.twin is not None and check.current is not None
            c_twin = check.twin.x[self.nd:2 * self.nd]
            self.kf.adopt(check.twin)
            if self.hgo is not None:
                self.hgo.restart(self.kf.x, self.kf.P)
                self.hgo.reset_gain()
            self.counters.restore_discarded += 1
            self.events.append(
                "restored current (" + ", ".join(f"{v:.2f}" for v in check.current) + ") m/s "
                "contradicts the data (" + ", ".join(f"{v:.2f}" for v in c_twin) + f"; "
                f"chi2 {check.chi2:.1f} on {check.n_axes} axes): discarded")
            check.end()
        elif verdict == "confirm":
            self.counters.restore_confirmed += 1
            self.events.append(f"restored current confirmed by {check.held_s:.0f} s "
                               f"of data (chi2 {check.chi2:.1f})")
            check.end()

    def _start(self, m: VelocityMeasurement) -> None:
        """Start the filters from the first velocity measurement, at its time."""
        R = self.samples.rotation_at(m.t)
        self.kf.start(m.kind, m.z, R)
        self.identification.headings.restart(self.yaw or 0.0)
        if self.restore_check.active:
            self.restore_check.start(m.kind, m.z, R, self.yaw or 0.0)
        if self.hgo is not None:
            self.hgo.restart(self.kf.x, self.kf.P)
        self._t = m.t

    def _outputs(self) -> dict[str, float]:
        nd = self.nd
        obs_src = self.hgo if self.hgo is not None else self.kf
        c, std, nu = obs_src.current_estimate()
        if self._surge_unobservable():
            std = floor_along_track(obs_src.current_cov(), self.yaw or 0.0,
                                    self.cfg.initial_current_std_mps)
        published = self._published_std(std) if obs_src is self.kf else std
        if self.hgo is not None:  # known on the held-sample cycle's largest one-sigma
            std = [max(s, p) for s, p in zip(std, self.hgo.current_std_peak())]
        flow = self.flow
        if flow is not None and flow.ready and flow.v_g is not None:
            c_flow, std_flow, nu_flow = flow.current(self._R())
            std = published = std_flow.tolist()
            nu = nu_flow.tolist()
            if c_flow is not None:
                c = c_flow.tolist()
        # a component the data do not determine is unknown, not a number
        thr = self.cfg.unknown_above_std_mps
        obs = self.observable
        # a through-water velocity beyond physics: the model ran away (health ``runaway``)
        sane = not (obs_src is self.kf and self.kf.runaway)
        out: dict[str, float] = {}
        for i, ax in enumerate(("north", "east", "down")[:nd]):
            obs[i] = sane and std[i] <= thr and math.isfinite(c[i])
            if obs[i]:
                out[ax] = float(c[i])
        if not (obs[0] or obs[1]):
            self.counters.unknown += 1
        # an unknown component keeps the sigma that made it unknown
        std = [p if known else s for p, known, s in zip(published, obs, std)]
        out.update(std_north=float(std[0]), std_east=float(std[1]),
                   u_r=float(nu[0]), v_r=float(nu[1]))
        if nd == 3:
            out.update(std_down=float(std[2]), w_r=float(nu[2]))
        return out

    def forecast_noise(self, channel: str) -> tuple[str, float, str, int] | None:
        """The configuration key whose process noise dominates the forecast of the joint
        filter's ``channel`` (``velocity``, ``dvl``, ``water_track``; None for another):
        ``(key, its value, unit, 2)``, the forecast's variance taken in proportion to the
        key's square (the integrity monitor's remedy, algorithms.md §9.2). Of the
        horizontal DOFs' noise per step, §3.5: ``prior_accel_std_mps2`` on a DOF still on
        the generic prior, ``accel_std_mps2`` on an identified one, against the current's
        ``current_walk_mps_rts``, the largest."""
        if channel not in CHANNELS.values():
            return None
        kf, cfg = self.kf, self.cfg
        masked = self.identification.masked[:2]
        tau = kf.model_error_time_s
        shares = {  # each key's process-noise variance per second on the horizontal rows
            "prior_accel_std_mps2": sum(masked) * kf.prior_accel_std ** 2 * tau,
            "accel_std_mps2": (len(masked) - sum(masked)) * kf.accel_std ** 2 * tau
            * kf.q_scale,
            "current_walk_mps_rts": 2.0 * kf.current_walk ** 2 * kf.q_scale}
        key = max(shares, key=shares.__getitem__)
        unit = "m/s/sqrt(s)" if key == "current_walk_mps_rts" else "m/s^2"
        return f"[pipelines.{self.name}] {key}", float(getattr(cfg, key)), unit, 2

    def published_factor(self) -> float:
        """The variance factor of the joint filter's published current sigma
        (:meth:`_published_std`): the factor of the velocity-over-ground rows' forecast
        their innovations give, at least the filter's block-mean NIS per dimension, at
        most 1."""
        return min(max(self._rows_factor(), self.kf.nis_avg), 1.0)

    def innovation_factor(self) -> float:
        """The variance factor the published current's sigma implies for the
        velocity-over-ground rows' innovations (what the integrity monitor judges them
        against): their measurement noise as the filter's and their forecast times
        :meth:`published_factor`, ``(1 - s) + s f`` with ``s`` the forecast's windowed
        share of ``S``, whitened (:meth:`.CurrentKalmanFilter._observe_whitened`): the
        monitor judges their NIS."""
        s = self.kf.earth_whitened.share
        return (1.0 - s) + s * self.published_factor()

    def _rows_factor(self) -> float:
        """The variance factor of the velocity-over-ground rows' forecast their
        innovations give (:meth:`.Consistency.forecast_factor`), the measurement noise
        taken as the filter's, from the innovations whitened by ``S`` (their NIS per
        dimension and the forecast's whitened share)."""
        return self.kf.earth_whitened.forecast_factor(FLOOR)

    def slow_error_holds(self) -> bool:
        """Whether the published current's sigma is held by the filter's block-mean NIS
        (an error slower than a block, which the velocity-over-ground rows' innovations
        do not show one by one) above the factor their own innovations give."""
        return self.kf.nis_avg > self._rows_factor()

    def _published_std(self, std: list[float]) -> list[float]:
        """The joint filter's current one-sigma ``std`` (m/s) as published: times the
        square root of the factor of the velocity-over-ground rows' forecast, apart from
        the gain (algorithms.md §9.1; :meth:`.Consistency.forecast_factor`), at least the
        filter's block-mean NIS per dimension (``kf.nis_avg``: an error slower than a
        block, a current that changes, survives the block mean), never above ``std``.
        Whether a component is known is decided on ``std`` itself, so the factor changes
        sigmas only, and of the known components only (an unknown one is published with
        ``std``, above ``unknown_above_std_mps``). The along-track floor of a model without
        surge is kept. The down takes the rows' common scale instead
        (:meth:`down_factor`)."""
        f = [self.published_factor()] * 2
        if len(std) == 3:
            f.append(self.down_factor())
        if min(f) >= 1.0:
            return std
        if self._surge_unobservable():   # floored after the factor, never above ``std``
            d = np.sqrt(f)
            return [min(a, b) for a, b in zip(std, floor_along_track(
                self.kf.current_cov() * np.outer(d, d), self.yaw or 0.0,
                self.cfg.initial_current_std_mps))]
        return [x * math.sqrt(k) for x, k in zip(std, f)]

    def down_factor(self) -> float:
        """The variance factor of the published down current's sigma: the
        velocity-over-ground rows' one common scale of ``S`` (:attr:`.NoiseScale.
        published_factor`), at least the block-mean NIS, at most 1. Not their forecast's
        factor: a diving vehicle's down errs by its through-water heave's prior
        (``w_r``), a bias no row shows, which that factor, small where the horizontal
        forecast is timid, would claim known (docs/fleet.md, algorithms.md §9.1)."""
        return min(max(self.kf.noise["earth"].published_factor, self.kf.nis_avg), 1.0)

    def innovations(self) -> list[Innovation]:
        """The records of the measurement updates since the last call (channels in the
        module docstring), in the order they were made; a tick's rejected samples come
        before its updates."""
        out = list(self._innovations)
        self._innovations.clear()
        return out

    def take_events(self) -> list[str]:
        """The events since the last call (:attr:`events`), which it empties."""
        out, self.events = self.events, []
        return out

    def lacks(self) -> str:
        """A velocity over ground, when it fused none and the GNSS fixes it was given
        carried no speed and course (:meth:`Pipeline.lacks`)."""
        no_speed = self.samples.counters.gnss_without_velocity
        if self.kf.counters.updates or not no_speed:
            return ""
        return (f"a velocity over ground: the log's {no_speed} GNSS fixes carry no speed "
                "and course (a receiver or logger that writes positions alone, e.g. GGA "
                "without RMC or VTG) and it has no INS or DVL velocity")

    def health(self) -> CurrentHealth:
        """The counters of the pipeline, its sample adapter, joint filter, model
        identification and observers; the calibration's ``q_scale``, the GNSS velocity
        one-sigma in use, coefficient and yaw-RLS spread, observer diagnostics,
        observability, the late-sample hold and the probation (:class:`CurrentHealth`)."""
        kf, ident, hgo, flow, hold = (self.kf, self.identification, self.hgo, self.flow,
                                      self.hold)
        rls, check = ident.yaw_rls, self.restore_check
        return CurrentHealth(
            samples=replace(self.samples.counters), filter=replace(kf.counters),
            pipeline=replace(self.counters), rls_updates=ident.rls_updates,
            hgo_diverged=hgo.diverged if hgo is not None else 0, q_scale=kf.q_scale,
            gnss_velocity_std=self.samples.gnss_std_used,
            theta_std_max=kf.theta_std_max() if ident.n_theta else None,
            yaw_rls_sigma=math.sqrt(rls.sigma2) if rls is not None else None,
            gamma=hgo.gamma if hgo is not None else None,
            gamma_star=self.gamma_star if hgo is not None else None,
            lipschitz=self.lipschitz if hgo is not None else None,
            flow_gain_kept=flow.unobservable if flow is not None else None,
            flow_diverged=flow.diverged if flow is not None else None,
            observable=tuple(self.observable),
            along_track_unobservable=self._surge_unobservable(),
            heading_diversity=ident.headings.length(),
            late=LateHold(hold.late, hold.hold_s, hold.too_late) if hold.late else None,
            restore_probation_s=check.held_s if check.active else None,
            restore_chi2=check.chi2 if check.active else None, noise=self.noise.health())

    def get_state(self) -> dict[str, Any]:
        """Identified model (coefficients and their covariance) and the last current."""
        nd, o = self.nd, 2 * self.nd
        kf = self.kf
        std = floor_along_track(  # as published: unknown along track without a model
            kf.current_cov(), self.yaw or 0.0, self.cfg.initial_current_std_mps if (
                self.yaw is not None and self.identification.surge_unobservable()) else 0.0)
        st: dict[str, Any] = {"model_kind": self.model.kind,
                              "thetas": self.model.thetas_to_mapping(self.thetas),
                              "current": kf.x[nd:o].tolist(), "current_std": std}
        if self.identification.n_theta:
            st["theta_cov"] = kf.P[o:, o:].tolist()
        if self.identification.yaw_rls is not None:
            st["yaw_rls"] = self.identification.yaw_rls.get_state()
        st["noise"] = self.noise.get_state()
        if self.hgo_rls is not None:
            st["hgo_thetas"] = self.model.thetas_to_mapping(
                self.hgo_rls.thetas + self.thetas[self.nd:])
            st["hgo_theta_cov"] = self.hgo_rls.covariance().tolist()
        return st

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore the identified model; the current restarts from its saved value with
        its saved uncertainty inflated (it may have changed while the service was down)
        and is on probation (``restore_check_s``): a twin filter with the restored model and
        the current at its prior checks it against the first minutes of data."""
        self.noise.set_state(state.get("noise"))
        if state.get("model_kind") != self.model.kind:
            return
        self.restore_check.end()
        nd = self.nd
        ident = self.identification
        try:
            thetas = self.model.thetas_from_mapping(state.get("thetas", {}), self.thetas)
            if not all(np.all(np.isfinite(t)) for t in thetas):
                return
            ident.thetas = thetas
            if ident.n_theta:
                self.kf.restore_coefficients(thetas[:nd], self._saved_theta_cov(state))
            if ident.yaw_rls is not None and "yaw_rls" in state:
                ident.restore_yaw(state["yaw_rls"])
            if self.hgo_rls is not None:
                self._restore_hgo_model(state, thetas)
            before = self.kf.x[nd:2 * nd].copy()
            self.kf.restore_current(state["current"], state.get("current_std", [0.3] * nd))
        except (KeyError, TypeError, ValueError):
            return
        restored = not np.array_equal(before, self.kf.x[nd:2 * nd]) or bool(
            np.any(self.kf.x[nd:2 * nd]))
        if restored and self.cfg.restore_check_s > 0:
            self._start_probation(thetas, self._saved_theta_cov(state))

    def _saved_theta_cov(self, state: Mapping[str, Any]) -> object:
        """The saved coefficients' covariance (``theta_cov``) in the model's term order:
        a state saved by a model with fewer terms (before the surge's turn-loss term,
        vehicle_models.TURN_LOSS_REGRESSORS) keeps its covariance for the terms it has,
        the new ones start at their prior variance. As saved if the terms match or the
        matrix does not fit the saved terms."""
        cov = state.get("theta_cov", [])
        saved = state.get("thetas", {})
        dofs = self.model.dofs
        names = [(ch, k) for ch in dofs for k in saved.get(ch, {})]
        here = [(ch, k) for ch in dofs for k in self.model.terms[ch]]
        c = np.asarray(cov, float)
        if (names == here or c.shape != (len(names), len(names))
                or not set(names) <= set(here)):
            return cov
        idx = [here.index(n) for n in names]
        out = np.diag(np.asarray(self.identification.theta_var0, float))
        out[np.ix_(idx, idx)] = c
        return out

    def _restore_hgo_model(self, state: Mapping[str, Any], thetas: list[np.ndarray]) -> None:
        """The high-gain observer's own model from a persistent state: its own
        coefficients (``hgo_thetas``, with ``hgo_theta_cov``) or, without them, the joint
        filter's ``thetas`` with their covariance (``theta_cov``); the covariance becomes
        its RLS's covariance and the observer's consider covariance
        (:meth:`.CurrentHighGainObserver.consider`). Raises ValueError or TypeError on a
        covariance that is not a matrix of numbers."""
        assert self.hgo is not None and self.hgo_rls is not None
        nd = self.nd
        nt = self.identification.n_theta
        c = np.asarray(state.get("hgo_theta_cov" if "hgo_thetas" in state else "theta_cov",
                                 []), float)
        cov = c if nt and c.shape == (nt, nt) and np.all(np.isfinite(c)) else None
        self.hgo_rls.restart(self.model.thetas_from_mapping(
            state.get("hgo_thetas", state.get("thetas", {})), thetas)[:nd], cov)
        self.hgo.consider(self.hgo_rls.covariance(), fresh=True)
        self._gamma_from_model()

    def _start_probation(self, thetas: list[np.ndarray], theta_cov: object) -> None:
        """The twin filter of the restored-current check: the restored model, the current
        at its prior."""
        nd = self.nd
        ident = _identification(self.cfg, self.model)
        ident.thetas = [t.copy() for t in thetas]
        kf = _joint_filter(self.cfg, ident)
        if ident.n_theta:
            try:
                kf.restore_coefficients(ident.thetas[:nd], theta_cov)
            except (TypeError, ValueError):
                pass
        self.restore_check.begin(kf, self.kf.x[nd:2 * nd].copy(), self.kf.current_cov())


def _identification(cfg: CurrentConfig, model: RegressionModel) -> ModelIdentification:
    """The model identification of ``[pipelines.current]``."""
    return ModelIdentification(
        model, cfg.model, identify=cfg.identify, model_rel_std=cfg.model_rel_std,
        theta_std=cfg.theta_std, theta_std_floor=cfg.theta_std_floor,
        net_weight_std=cfg.net_weight_std, forgetting=cfg.forgetting,
        identify_max_current_std=cfg.identify_max_current_std_mps,
        identify_min_rate=cfg.identify_min_rate_rps,
        identify_after_turn_s=cfg.identify_after_turn_s,
        identify_straight=cfg.identify_straight,
        identify_min_speed=cfg.identify_min_speed_mps,
        yaw_rls_p0=cfg.yaw_rls_p0, yaw_forgetting=cfg.yaw_forgetting,
        svf_cutoff_hz=cfg.svf_cutoff_hz, heading_memory_s=cfg.heading_memory_s,
        heading_diversity=cfg.heading_diversity)


def _learned_noise(kf: CurrentKalmanFilter, cfg: CurrentConfig,
                   sensors: Any) -> ChannelNoise:
    """One :class:`.NoiseScale` per measurement kind of ``kf``, named by its channel and
    the configuration key that declares its noise, given to ``kf`` which learns it; not on
    a glider (``[pipelines.current.glider]``): its velocities come from its flight model
    and a DVL whose errors last a dive, not white, and the matching does not hold (learned,
    the Kolumbo current got worse than zero north, 0.21 -> 0.27 m/s)."""
    gnss = (("[pipelines.current] gnss_velocity_std_mps", cfg.gnss_velocity_std_mps)
            if cfg.gnss_velocity_std_mps else
            ("[sensors.gnss] velocity_std_mps", sensors.gnss.velocity_std_mps))
    dvl = (("[pipelines.current] dvl_velocity_std_mps", cfg.dvl_velocity_std_mps)
           if cfg.dvl_velocity_std_mps else
           ("[sensors.dvl] velocity_std_mps", sensors.dvl.velocity_std_mps))
    for kind, (key, std) in (("earth", gnss), ("bottom", dvl), ("water", dvl)):
        kf.noise[kind] = NoiseScale(CHANNELS[kind], key, std, "m/s")
    kf.learn_noise = cfg.glider is None
    return ChannelNoise(list(kf.noise.values()) if kf.learn_noise else [])


def _joint_filter(cfg: CurrentConfig, ident: ModelIdentification) -> CurrentKalmanFilter:
    """The joint Kalman filter of ``[pipelines.current]`` on ``ident``'s model."""
    return CurrentKalmanFilter(
        ident, init_current_std=cfg.initial_current_std_mps,
        current_walk=cfg.current_walk_mps_rts, accel_std=cfg.accel_std_mps2,
        model_error_time_s=cfg.model_error_time_s, turn_accel_gain=cfg.turn_accel_gain,
        prior_accel_std=cfg.prior_accel_std_mps2, gate_nis=cfg.gate_nis,
        calibrate=cfg.calibrate, calibrate_block=cfg.calibrate_block,
        max_speed_through_water=cfg.max_speed_through_water_mps)


def _gain_is_design_fixed(cfg: HgoConfig, design: GainDesign) -> bool:
    """Whether the observer runs a gain file's fixed gain (``rho = 0``, with a gamma*) and
    nothing in ``[pipelines.current.hgo]`` overrides it: then the gain follows gamma* of
    the model that runs (:meth:`CurrentPipeline._gamma_from_model`)."""
    configured = (cfg.gamma, cfg.gamma_0, cfg.rho, cfg.gamma_max)
    return all(v is None for v in configured) and design.rho == 0.0 and design.gamma_star > 0


def _gain_law(cfg: HgoConfig, design: GainDesign) -> IncreasingGain:
    """The increasing-gain law of ``[pipelines.current.hgo]``: the design's, unless
    ``gamma_0``, ``rho``, ``gamma_max`` or a fixed ``gamma`` (``rho = 0``) are configured."""
    g0 = cfg.gamma_0 if cfg.gamma_0 is not None else (
        cfg.gamma if cfg.gamma is not None else design.gamma_0)
    rho = cfg.rho if cfg.rho is not None else (0.0 if cfg.gamma is not None else design.rho)
    gamma_max = cfg.gamma_max if cfg.gamma_max is not None else (
        cfg.gamma if cfg.gamma is not None else design.gamma_max)
    return IncreasingGain(g0, rho, gamma_max)


def model_kind(cfg: Config, ccfg: CurrentConfig) -> str:
    """The regression-model kind: ``model_kind`` if configured, else from
    ``vehicle.class`` (twin thrusters if both ``inputs.left`` and ``inputs.right`` exist)."""
    has_twin = cfg.inputs.left is not None and cfg.inputs.right is not None
    return ccfg.model_kind or kind_for_class(cfg.vehicle.vehicle_class, has_twin)


def _gain_for(cfg: Config, ccfg: CurrentConfig) -> GainDesign | None:
    """The HGO gain file of this configuration (``[pipelines.current.hgo] gain_file`` or the
    bundled ``config/gains/<class>.json``), None if not ``hgo`` or no bundled file exists."""
    if ccfg.observer != "hgo":
        return None
    default = GAIN_DIR / f"{cfg.vehicle.vehicle_class}.json"
    path = Path(ccfg.hgo.gain_file) if ccfg.hgo.gain_file else default
    if path.exists():
        try:
            return GainDesign.load(path)
        except (OSError, ValueError, KeyError) as err:
            raise ConfigError(f"pipelines.current.hgo.gain_file: {path}: {err}") from None
    if ccfg.hgo.gain_file:
        raise ConfigError(f"pipelines.current.hgo.gain_file: {path}: no such file "
                          "(run `onboard design-gain --config ...`)")
    return None


def create(cfg: Config) -> CurrentPipeline | None:
    """The ``current`` pipeline for this configuration (every vehicle class)."""
    ccfg = cfg.pipelines.current
    if not ccfg.enabled:
        return None
    kind = model_kind(cfg, ccfg)
    try:
        RegressionModel(kind).thetas_from_mapping(ccfg.model)
    except ValueError as err:
        raise ConfigError(f"pipelines.current.{err}") from None
    return CurrentPipeline(ccfg, kind, cfg.sensors, configured=bool(ccfg.model),
                           gain=_gain_for(cfg, ccfg))
