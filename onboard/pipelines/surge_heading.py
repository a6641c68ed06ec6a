"""The surge/heading pipeline shared by ``aie`` and its ``kf`` baseline: samples in,
measurement points to the two axis filters, the reconstructed track out.

Everything but the input of the axis filters is common to the two pipelines, so the
comparison of the seed paper (Faros & Tanner 2025, §3) is like for like (algorithms.md
§2.12). This module is the adapter from samples to the estimators:

* measurement points (§1.3, :mod:`onboard.estimators.measurement_points`): GNSS fixes in
  windows of ``step_s`` for the surge axis, headings in windows of ``heading_step_s`` for
  the heading axis, each window averaged to one point; consecutive points give the heading
  increment and the path increment (with the circular-arc correction); steps are as long
  as the time between points, and past ``max_gap_s`` the chain restarts;
* two axis filters (:class:`~onboard.estimators.increment_filter.IncrementFilter`), each
  with the input model its pipeline gives it (AIE: RCIE; KF: the commanded input);
* the trajectory reconstruction of §2.11 and the estimates at the tick
  (:class:`~onboard.estimators.reconstruction.TrackReconstruction`): the heading and
  position rebuilt from the increments, predicted from the last steps with the model and
  the newest command (or the accelerometer, ``imu_aiding``), dead reckoned through a GNSS
  outage.

Inputs: :class:`GnssFix`, :class:`Heading` or :class:`Attitude` yaw, :class:`Imu`, and
:class:`ActuatorCommand` (optional: without it AIE runs unchanged and the KF baseline
runs with zero input). The engine's source selector lets one heading source through; an
``Attitude`` whose yaw it did not select (``yaw_selected`` False) gives no heading, and
without the selector a ``Heading`` sample within ``HEADING_HOLD_S`` wins over the yaw.
Without any heading source (a GNSS-only log) the surge axis runs on the path along the
course over ground (course mode).

The tuned noise parameters (``v_d``, ``r_d``) left at ``"auto"`` follow the measurement
set (docs/aie.md section 2.2): the values tuned with the Doppler speed row while fixes
carry a speed over ground, those tuned without it once no fix has carried one for
:data:`DOPPLER_HOLD_S`. The set is decided at each fix; a switch changes both axes'
parameters from their next step on and keeps their state.
"""

from __future__ import annotations

import math
from collections import deque
from functools import partial
from typing import Any, Callable, Literal, Mapping, Sequence

import msgspec
from mypy_extensions import mypyc_attr

from onboard.core.config import Config
from onboard.core.geo import LocalFrame, wrap_pi
from onboard.core.messages import (
    ActuatorCommand,
    Attitude,
    GnssFix,
    Heading,
    Imu,
    Innovation,
    Sample,
)
from onboard.core.pipeline_config import AieConfig, KfConfig
from onboard.estimators.axis_model import (
    AxisModel,
    Discretization,
    axis_commands,
    path_increment,
)
from onboard.estimators.increment_filter import PENDING_INNOVATIONS, IncrementFilter
from onboard.estimators.measurement_points import (
    CommandHistory,
    HeadingUnwrapper,
    Window,
    clamp,
    finite_positive,
)
from onboard.estimators.noise_learning import WINDOW as NOISE_WINDOW
from onboard.estimators.noise_learning import ChannelNoise, NoiseScale, ProcessScale
from onboard.estimators.reconstruction import Point, TrackReconstruction
from onboard.pipelines.base import PipelineDefaults, unused_measurement

HEADING_HOLD_S = 1.0
"""An ``Attitude`` yaw within this long (s) after a ``Heading`` sample is not used."""

# ---------------------------------------------------------------------------------------
# The pipeline

SPEED_ACCURACY_MAX_MPS = 5.0
"""Ceiling of a fix's reported speed accuracy (m/s)."""
CRAB_MIN_SPEED_MPS = 0.5
"""Below this speed over ground (m/s) the course is too noisy for the crab angle."""
DOPPLER_SIGN_MIN_SPEED_MPS = 0.1
"""Below this speed over ground (m/s), the default GNSS speed sigma, a fix's course has
~1 rad of noise and cannot tell ahead from astern: its Doppler speed is not used (0.2
and 0.3 m/s were measured too and cost the AIE on slow turns: docs/aie.md)."""
SIGN_UNKNOWN = "sign_unknown"
"""The ``surge.rate`` rejection reason of a Doppler speed whose sign is unknown."""
SAME_POINT_S = 1e-3
"""Two points closer in time than this (s) are one point: the newer is not used."""
WINDOW_END_AFTER_FIX = 0.25
"""Surge windows end this fraction of a step after the fixes (a regular receiver): each
closes with the first sample after its fix, not a step later."""
COURSE_MODE_ANCHOR = 0.3
"""Least anchor gain in course mode: the course lags the track by half its baseline."""
DOPPLER_HOLD_S = 5.0
"""The Doppler set of the ``"auto"`` parameters holds this long (s) after the newest fix
with a speed over ground (the default ``max_gap_s``: a few fixes without one, or a slow
speed-message rate, are no switch); at a fix later than that, the no-Doppler set."""

AxisFactory = Callable[[AxisModel, Any, Any, str], IncrementFilter]
"""``factory(model, axis_config, pipeline_config, name)``: one axis filter with its
input, named ``surge`` or ``heading``, with the Doppler set's tuned parameters."""
AxisRetune = Callable[[IncrementFilter, Any, bool], None]
"""``retune(filter, axis_config, doppler)``: give an axis filter the tuned parameters of
the measurement set, with (``doppler``) or without a Doppler speed."""


class AxisHealth(msgspec.Struct, frozen=True):
    """One axis filter's counters (:class:`IncrementFilter`)."""

    steps: int
    """Increment updates."""
    rejected: int
    """Increments skipped as outliers (beyond ``gate_nis``)."""
    diverged: int
    """Divergences of its input model (each restarts the input estimate)."""
    restarts: int
    """Restarts of its chain (a silence longer than ``max_gap_s``)."""

    @classmethod
    def of(cls, f: IncrementFilter) -> AxisHealth:
        """The counters of axis filter ``f``."""
        return cls(f.steps, f.rejected, f.diverged, f.restarts)


class SurgeHeadingHealth(msgspec.Struct, frozen=True):
    """The health of an ``aie`` or ``kf`` pipeline (:meth:`SurgeHeadingPipeline.health`)."""

    surge: AxisHealth
    heading: AxisHealth
    rate_steps: int
    """Doppler speed updates of the surge axis."""
    rate_rejected: int
    """Doppler speeds skipped as outliers or left out (sign unknown)."""
    accuracy_rejected: int
    """Fixes and speeds whose reported accuracy was not a positive number."""
    doppler_set: bool
    """The ``"auto"`` parameters in use are the Doppler set (else the no-Doppler set)."""
    set_switches: int
    """Switches of the measurement set so far."""
    surge_input: dict[str, float]
    """What the surge axis's input model reports (AIE: ``input``, ``V_d``,
    ``theta_norm``)."""
    heading_input: dict[str, float]
    """What the heading axis's input model reports."""
    noise: dict[str, float] = {}
    """The learned measurement noise (:meth:`.ChannelNoise.health`: ``noise.<channel>.scale``
    and ``noise.<channel>.std``)."""

    def flat(self) -> dict[str, float]:
        """``surge.steps`` ... ``heading.restarts``, ``surge.rate_steps``,
        ``surge.rate_rejected``, ``surge.accuracy_rejected``, ``tuned_set.doppler`` (1 or
        0), ``tuned_set.switches``, then each axis's input model's by
        ``<axis>.<name>``."""
        h: dict[str, float] = {}
        for nm, ax in (("surge", self.surge), ("heading", self.heading)):
            h[f"{nm}.steps"] = float(ax.steps)
            h[f"{nm}.rejected"] = float(ax.rejected)
            h[f"{nm}.diverged"] = float(ax.diverged)
            h[f"{nm}.restarts"] = float(ax.restarts)
        h["surge.rate_steps"] = float(self.rate_steps)
        h["surge.rate_rejected"] = float(self.rate_rejected)
        h["surge.accuracy_rejected"] = float(self.accuracy_rejected)
        h["tuned_set.doppler"] = float(self.doppler_set)
        h["tuned_set.switches"] = float(self.set_switches)
        for nm, inp in (("surge", self.surge_input), ("heading", self.heading_input)):
            h.update({f"{nm}.{k}": v for k, v in inp.items()})
        h.update(self.noise)
        return h


@mypyc_attr(allow_interpreted_subclasses=True)
class SurgeHeadingPipeline(PipelineDefaults):
    """Surge and heading filters with trajectory reconstruction (``aie`` or ``kf``).

    ``columns``: north, east (m from the first fix), heading (rad, [0, 2 pi)), speed
    (m/s), yaw_rate (rad/s), their one-sigma ``std_*``, and for AIE surge_input (m/s^2)
    and yaw_input (rad/s^2). Roles: ``north``/``east`` a position, ``speed`` the path
    speed over ground, ``heading`` its ``heading_estimate``
    (:class:`~onboard.pipelines.base.Pipeline`).

    Attributes:
        surge, yaw: the axis filters (:class:`IncrementFilter`).
        track: the reconstructed track and its estimates (:class:`TrackReconstruction`).
        commands: the command history (:class:`CommandHistory`).
        frame: the local frame about the first fix (None before it).
    """

    position = ("north", "east")
    speed = ("speed",)
    heading_estimate = ("heading",)

    def __init__(self, name: str, columns: tuple[str, ...], cfg: AieConfig | KfConfig,
                 gnss_position_std_m: float, heading_std_rad: float, factory: AxisFactory,
                 gnss_velocity_std_mps: float = 0.1, *, retune: AxisRetune,
                 gnss_drift_share: float = 0.0, gnss_drift_tau_s: float = 120.0) -> None:
        """``cfg``: the pipeline's table (``[pipelines.aie]`` or ``[pipelines.kf]``);
        ``gnss_position_std_m``, ``heading_std_rad`` and ``gnss_velocity_std_mps``: the
        ``[sensors]`` noise, unless ``cfg`` sets its own; ``gnss_drift_share``: the
        slowly wandering share of a fix's noise variance (``[sensors.gnss]
        drift_share``), left out of the increments' noise but for its change over a step,
        of correlation time ``gnss_drift_tau_s`` (``drift_tau_s``); ``factory`` builds
        each axis filter with its input model, ``retune`` switches its measurement set."""
        if not 0.0 < cfg.gnss_accuracy_min_m <= cfg.gnss_accuracy_max_m:
            raise ValueError(f"[pipelines.{name}] needs 0 < gnss_accuracy_min_m <= "
                             f"gnss_accuracy_max_m, got {cfg.gnss_accuracy_min_m}, "
                             f"{cfg.gnss_accuracy_max_m}")
        self.name, self.columns, self.cfg = name, columns, cfg
        self.sigma_p = (cfg.gnss_position_std_m if cfg.gnss_position_std_m is not None
                        else gnss_position_std_m)
        """Position noise of one fix without its own accuracy (m)."""
        self.sigma_v = (cfg.gnss_velocity_std_mps if cfg.gnss_velocity_std_mps is not None
                        else gnss_velocity_std_mps)
        """Speed-over-ground noise of one fix (m/s)."""
        self.sigma_h = (cfg.heading_std_rad if cfg.heading_std_rad is not None
                        else heading_std_rad)
        """Noise of one heading (rad)."""
        self.drift_share = gnss_drift_share
        """Slowly wandering share of a fix's noise variance: not in an increment."""
        self.drift_tau_s = gnss_drift_tau_s
        """Its correlation time (s): its change over a step is in the increment."""
        s, h = cfg.surge, cfg.heading
        self.surge = factory(AxisModel(s.a, s.gain, s.offset), s, cfg, "surge")
        self.yaw = factory(AxisModel(h.a, h.gain, h.offset), h, cfg, "heading")
        self.noise = self._learned_noise()
        """The learned noise of the three measurement channels (algorithms.md §9)."""
        self.commands = CommandHistory()
        self.track = TrackReconstruction(
            self.surge, self.yaw, self.commands, var_fix=self.sigma_p ** 2,
            var_heading0=self.sigma_h ** 2, max_gap_s=cfg.max_gap_s,
            imu_aiding=cfg.imu_aiding, imu_horizon_s=cfg.imu_horizon_s)
        self.frame: LocalFrame | None = None
        self.doppler = True
        """The measurement set of the ``"auto"`` parameters: True (also before the first
        fix) with a Doppler speed, False without (:meth:`_select_measurement_set`)."""
        self.set_switches = 0
        """Switches of the measurement set so far."""
        self._retune = retune
        self._t_doppler = -math.inf          # time (s) of the newest fix with a speed
        self._unused_rate: deque[Innovation] = deque(maxlen=PENDING_INNOVATIONS)
        """Doppler speeds left out before any update (sign unknown), as records."""
        self._publish_inputs = "surge_input" in columns
        self._disc = Discretization()
        self._unwrap = HeadingUnwrapper()
        self._acc_bad = 0                    # fixes whose reported accuracy was not > 0
        self._n_reported = 0                 # fixes whose own accuracy was their noise
        self._init_windows()

    def _learned_noise(self) -> ChannelNoise:
        """One :class:`.NoiseScale` per measurement row, named by the configuration key
        that declares its noise, given to the axis filter that learns it."""
        cfg, name = self.cfg, self.name

        def key(own: object, sensor: str, field: str) -> str:
            return (f"[pipelines.{name}] {field}" if own is not None
                    else f"[sensors.{sensor}] {field.split('_', 1)[1]}")
        surge, yaw = self.surge, self.yaw
        surge.noise = NoiseScale(f"{surge.name}.increment", key(
            cfg.gnss_position_std_m, "gnss", "gnss_position_std_m"), self.sigma_p, "m")
        surge.rate_noise = NoiseScale(f"{surge.name}.rate", key(
            cfg.gnss_velocity_std_mps, "gnss", "gnss_velocity_std_mps"), self.sigma_v, "m/s")
        yaw.noise = NoiseScale(f"{yaw.name}.increment", (
            f"[pipelines.{name}] heading_std_rad" if cfg.heading_std_rad is not None
            else "[sensors.compass] heading_std_rad"), self.sigma_h, "rad", narrows=True)
        yaw.process = ProcessScale()   # the heading's input error, algorithms.md §9.3
        # the published speed's sigma takes the surge filter's factor (its Doppler row's,
        # else its increment row's): both rows are judged against it; a partial of the
        # class's function, so that a copy of the pipeline takes its own copy's factor
        rate_factor = partial(type(surge).published_rate_factor, surge)
        return ChannelNoise([surge.noise, surge.rate_noise, yaw.noise], published={
            surge.noise.channel: rate_factor, surge.rate_noise.channel: rate_factor},
            processes={yaw.noise.channel: yaw.process})

    def forecast_noise(self, channel: str) -> tuple[str, float, str, int] | None:
        """The configuration key whose process noise sets ``channel``'s forecast: its
        axis's input-error variance ``[pipelines.<name>.<axis>] v_d`` with the value the
        forecast takes now (``q V_u``, algorithms.md §9.3), its unit and power 1 (a
        variance); None for another channel (the integrity monitor's remedy, §9.2)."""
        for axis, unit in ((self.surge, "(m/s^2)^2"), (self.yaw, "(rad/s^2)^2")):
            if channel.startswith(axis.name + "."):
                return (f"[pipelines.{self.name}.{axis.name}] v_d", axis.forecast_var_u,
                        unit, 1)
        return None

    def _init_windows(self) -> None:
        """The measurement windows and the previous points of both axes."""
        cfg = self.cfg
        self._t0: float | None = None        # first measurement: both windows start
        self._step_h = cfg.heading_step_s if cfg.heading_step_s > 0 else cfg.step_s
        self._w = Window()                   # surge window: fixes and the headings among them
        self._hw = Window()                  # heading window
        self._w_end = self._hw_end = math.inf
        self._next_end = math.inf            # the earlier of the two ends
        self._w_early = False                # the surge window was closed at an output
        self._handlers: dict[type, Callable[[SurgeHeadingPipeline, Any], None] | None] = {}
        self._t_heading = -math.inf          # time (s) of the newest Heading sample
        self._pt_prev: tuple[float, float, float, float] | None = None  # t, N, E, psi
        self._h_prev: tuple[float, float] | None = None                 # t, psi
        self._R_prev = self.sigma_p ** 2     # noise variance of the previous point (m^2)
        self._R_inc_prev = increment_variance(self._R_prev, self.drift_share)  # its white part
        self._R_h_prev = self.sigma_h ** 2   # of the previous heading point (rad^2)

    # -- samples in ------------------------------------------------------------------------

    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        """Consume ``samples`` (time-ordered) and return the estimates at time ``t``.

        Every sample first closes the windows ending at or before its time; its handler
        (:meth:`_handler`) then adds it. With ``close_at_output`` a surge window holding
        a fix (and a heading) closes at ``t``, so the newest fix is in the estimate."""
        handlers = self._handlers
        for s in samples:
            if s.t >= self._next_end:
                self._advance(s.t)
            cls = type(s)
            h = handlers[cls] if cls in handlers else self._handler(cls)
            if h is not None:
                h(self, s)
        w = self._w
        if w.n_fix and self.cfg.close_at_output and (w.n_h or self._unwrap.last is None):
            self._close_surge_window(t)
            self._w_early = True
        return self._output(t)

    def _handler(self, cls: type) -> Callable[[SurgeHeadingPipeline, Any], None] | None:
        """The intake function for a sample class (None: not an input), cached per class;
        subclasses of the input messages get their base's handler. The class's functions,
        not methods bound to this object, so that a copy of it (the GNSS latency's fork)
        handles its samples itself."""
        c = SurgeHeadingPipeline
        h: Callable[[SurgeHeadingPipeline, Any], None] | None = None
        for base, fn in ((GnssFix, c._on_fix), (Heading, c._on_heading),
                         (Attitude, c._on_attitude), (ActuatorCommand, c._on_command),
                         (Imu, c._on_imu)):
            if issubclass(cls, base):
                h = fn
                break
        self._handlers[cls] = h
        return h

    def _start(self, t: float) -> None:
        """The first measurement (at ``t`` s) starts both windows."""
        self._t0 = t
        self._w_end = t + self.cfg.step_s
        self._hw_end = t + self._step_h
        self._next_end = min(self._hw_end, self._w_end)

    def _advance(self, t: float) -> None:
        """Close every window that ends at or before ``t`` (s), heading windows first."""
        if self._t0 is None:
            return
        self._hw_end = self._close_until(t, self._hw_end, self._step_h,
                                         lambda end: self._close_heading_window())
        self._w_end = self._close_until(t, self._w_end, self.cfg.step_s,
                                        self._close_surge_window)
        self._next_end = min(self._hw_end, self._w_end)

    def _close_until(self, t: float, end: float, step: float,
                     close: Callable[[float], None]) -> float:
        """Close the windows of length ``step`` from the one ending at ``end`` up to
        ``t``; across a silence longer than ``max_gap_s`` jump to the window holding
        ``t``. Returns the end of the open window."""
        assert self._t0 is not None
        while t >= end:
            close(end)
            end += step
            if t - end > self.cfg.max_gap_s:
                end = self._t0 + step * (math.floor((t - self._t0) / step) + 1)
        return end

    def _on_fix(self, s: GnssFix) -> None:
        if self._t0 is None:
            self._start(s.t)
        if s.fix_quality <= 0:
            return
        if self.frame is None:
            self.frame = LocalFrame(s.lat_deg, s.lon_deg)
            self._w_end = s.t + WINDOW_END_AFTER_FIX * self.cfg.step_s
            self._next_end = min(self._hw_end, self._w_end)
        n, e = self.frame.to_ne(s.lat_deg, s.lon_deg)
        self._w.add_fix(s.t, n, e, self._fix_variance(s.h_acc_m), s.source)
        self._add_speed(s)
        self._select_measurement_set(s.t)

    def _select_measurement_set(self, t: float) -> None:
        """At a fix at ``t`` (s): the Doppler set if a fix within :data:`DOPPLER_HOLD_S`
        carried a speed over ground (used or not), else the no-Doppler set. On a switch
        both axes take the set's ``"auto"`` parameters from their next step on; their
        state (rate, covariance, learned input) is kept."""
        doppler = t - self._t_doppler <= DOPPLER_HOLD_S
        if doppler == self.doppler:
            return
        self.doppler = doppler
        self.set_switches += 1
        self._retune(self.surge, self.cfg.surge, doppler)
        self._retune(self.yaw, self.cfg.heading, doppler)

    def _fix_variance(self, acc: float | None) -> float:
        """A fix's position noise variance (m^2): its reported accuracy, clamped to
        [``gnss_accuracy_min_m``, ``gnss_accuracy_max_m``], with ``gnss_accuracy``; else
        (and for an accuracy that is not a positive number, counted) ``sigma_p^2``."""
        cfg = self.cfg
        if cfg.gnss_accuracy and finite_positive(acc):
            acc = clamp(acc, cfg.gnss_accuracy_min_m, cfg.gnss_accuracy_max_m)  # type: ignore
            self._reported_accuracy(acc)
            return acc * acc
        if acc is not None and cfg.gnss_accuracy:
            self._acc_bad += 1
        return self.sigma_p ** 2

    def _reported_accuracy(self, acc: float) -> None:
        """A fix's own accuracy ``acc`` (m) is its noise, not ``sigma_p``: the position
        increments' learned noise is named against the fixes' reported accuracy (its root
        mean square over the learning's window) and by the keys that would give every fix
        the learned value (``gnss_accuracy = false`` and the position noise key): a
        remedy on ``position_std_m`` alone changes nothing while fixes report their own."""
        n = self.surge.noise
        if n.basis != "reported":
            n.basis, n.declared = "reported", acc
            n.key = f"[pipelines.{self.name}] gnss_accuracy = false, {n.key}"
            self._n_reported = 0
        self._n_reported = min(self._n_reported + 1, NOISE_WINDOW)
        var = n.declared * n.declared
        n.declared = math.sqrt(var + (acc * acc - var) / self._n_reported)

    def _add_speed(self, s: GnssFix) -> None:
        """The fix's speed over ground as the signed path speed (astern when the course
        is more than 90 deg off the newest heading; always ahead without a heading), of
        noise the configured ``sigma_v`` or the fix's worse reported accuracy; its course
        against the heading is the accelerometer's crab angle. With a heading, a speed
        below ``DOPPLER_SIGN_MIN_SPEED_MPS`` has no known sign (its course is noise): it is
        not used, and recorded as a ``surge.rate`` rejection (``sign_unknown``). Any
        finite speed (``gnss_velocity`` on) counts for the measurement set."""
        sog, cog, psi = s.sog_mps, s.cog_rad, self._unwrap.last
        imu = self.track.imu
        if (imu is not None and sog is not None and cog is not None
                and psi is not None and abs(sog) > CRAB_MIN_SPEED_MPS):
            imu.crab(cog - psi)
        if sog is None or not self.cfg.gnss_velocity or not math.isfinite(sog):
            return
        self._t_doppler = s.t
        if cog is not None and psi is not None:
            if abs(sog) < DOPPLER_SIGN_MIN_SPEED_MPS:
                self._unused_rate.append(unused_measurement(
                    f"{self.surge.name}.rate", s.t, 1, SIGN_UNKNOWN, s.source))
                return
            if math.cos(cog - psi) < 0.0:
                sog = -sog
        extra = 0.0
        sacc = s.speed_acc_mps
        if sacc is not None and self.cfg.gnss_accuracy:
            if not finite_positive(sacc):
                self._acc_bad += 1
            elif sacc > self.sigma_v:
                sacc = min(sacc, SPEED_ACCURACY_MAX_MPS)
                extra = sacc * sacc - self.sigma_v ** 2
        self._w.add_speed(sog, extra)

    def _on_heading(self, s: Heading) -> None:
        if self._t0 is None:
            self._start(s.t)
        self._t_heading = s.t
        self._add_heading(s.t, s.heading_rad, s.source)

    def _on_attitude(self, s: Attitude) -> None:
        if self.track.imu is not None:
            self.track.imu.attitude(s.t, s.roll_rad, s.pitch_rad)
        if self._t0 is None:
            self._start(s.t)
        if s.yaw_selected and s.t - self._t_heading > HEADING_HOLD_S:
            self._add_heading(s.t, s.yaw_rad, s.source)

    def _add_heading(self, t: float, psi: float, source: str) -> None:
        u = self._unwrap(psi)
        self._w.add_heading(t, u, source)
        self._hw.add_heading(t, u, source)

    def _on_imu(self, s: Imu) -> None:
        if self.track.imu is not None:
            self.track.imu.add(s.t, s.accel_x, s.accel_y, s.gyro_x, s.gyro_y, s.gyro_z)

    def _on_command(self, s: ActuatorCommand) -> None:
        self.commands.add(s.t, *axis_commands(s, self.cfg.input_mode))
        self.track.invalidate()

    def _trim_commands(self) -> None:
        """Keep the commands from the one in force at the older previous point on."""
        ts = [p[0] for p in (self._pt_prev, self._h_prev) if p is not None]
        if ts:
            self.commands.trim(min(ts))

    # -- the heading axis: one step per heading window ---------------------------------------

    def _close_heading_window(self) -> None:
        """One heading step: the window's mean heading is the new point; its increment
        over the previous point goes to the heading filter, then the heading track."""
        self.track.invalidate()
        w, self._hw = self._hw, Window()
        if w.n_h == 0:
            return
        th, psi = w.heading_point()
        R_h = self.sigma_h ** 2 / w.n_h   # declared; the filter and the track scale it
        R_h_prev, self._R_h_prev = self._R_h_prev, R_h
        hp = self._h_prev
        if hp is not None and th - hp[0] <= SAME_POINT_S:
            return
        self._h_prev = (th, psi)
        if hp is not None and th - hp[0] > self.cfg.max_gap_s:
            self.yaw.restart()
            hp = None
        if hp is None:
            self.track.heading.restart(th, psi, R_h * self.yaw.noise.applied)
            return
        cmd = self.commands.mean(hp[0], th, 2)
        self.yaw.step(self._disc(self.yaw.damping(cmd), th - hp[0]), wrap_pi(psi - hp[1]),
                      R_h, R_h_prev, cmd, t=th, source=w.heading_source)
        self.track.heading.step(th, psi, R_h * self.yaw.noise.applied, self.yaw.kf,
                                self.cfg.heading_anchor, hp[1])
        self._trim_commands()

    # -- the surge axis: one step per GNSS window --------------------------------------------

    def _close_surge_window(self, t_end: float) -> None:
        """One surge step with the window ending at ``t_end`` (s): its fixes averaged to
        one point; a window without a fix advances the dead reckoning instead."""
        self.track.invalidate()
        w, self._w = self._w, Window()
        early, self._w_early = self._w_early, False
        if w.n_fix == 0:
            if not early:   # the rest of a window closed at an output is no gap
                self.track.dead_reckon(t_end)
            return
        self.track.fix_arrived()
        course_mode = self._unwrap.last is None
        if w.n_h == 0 and not course_mode:
            return
        tp, n, e, R_s = w.fix_point()
        pp = self._pt_prev
        if pp is not None and tp - pp[0] <= SAME_POINT_S:
            return
        self._pt_prev = (tp, n, e, w.sh / w.n_h if w.n_h else math.nan)
        R_s_prev, self._R_prev = self._R_prev, R_s
        R_inc = increment_variance(R_s, self.drift_share)
        R_inc_prev, self._R_inc_prev = self._R_inc_prev, R_inc
        if pp is None or tp - pp[0] > self.cfg.max_gap_s:
            self._restart_surge_chain(pp, tp, n, e, R_s, R_s_prev)
        else:
            self._surge_step(w, pp, R_s, (R_inc, R_inc_prev), course_mode)

    def _restart_surge_chain(self, pp: Point | None, tp: float, n: float, e: float,
                             R_s: float, R_s_prev: float) -> None:
        """The first point, or the first after a gap: the filter restarts, the track
        starts from the point (or follows the measured displacement across the gap)."""
        if pp is not None:
            self.surge.restart()
        self.track.restart_position(pp, tp, n, e, R_s, R_s_prev)

    def _surge_step(self, w: Window, pp: Point, R_s: float, R_inc: tuple[float, float],
                    course_mode: bool) -> None:
        """The path increment from the previous point to the new one (§1.3) through the
        surge filter (§2.7, with the window's mean Doppler speed as the rate), then the
        track (§2.11). ``R_s``: the new point's noise variance (m^2); ``R_inc``: the
        white part of it and of the previous point's (:func:`increment_variance`), the
        noise the increment carries."""
        point = self._pt_prev
        assert point is not None
        tp, n, e, psi = point
        dpsi = 0.0
        if course_mode:
            y = self.track.course_increment(n, e, pp, R_s)
        else:   # a previous point from before the first heading has none: no turn
            psi_prev = psi if math.isnan(pp[3]) else pp[3]
            dpsi = wrap_pi(psi - psi_prev)
            y = path_increment(n - pp[1], e - pp[2], psi_prev, dpsi)
            pp = (pp[0], pp[1], pp[2], psi_prev)   # the track's mid heading reads it
        cmd = self.commands.mean(pp[0], tp, 1)
        y_v, R_v = w.speed_point(self.sigma_v)
        surge = self.surge
        v_prev = surge.kf.v if surge.kf.initialized else None
        dt = tp - pp[0]
        surge.step(self._disc(surge.damping(cmd), dt), y, R_inc[0], R_inc[1], cmd,
                   y_v, R_v, t=tp, source=w.fix_source,
                   R_drift=drift_change_variance(R_s, self.drift_share, self.drift_tau_s, dt))
        if self.track.imu is not None and v_prev is not None and y_v is not None:
            self.track.learn_imu_forecast(pp[0], tp, v_prev, y_v)
        self.track.surge_step(pp, point, R_s, self._anchor_gain(w, R_s, course_mode),
                              course_mode, dpsi)
        self._trim_commands()

    def _anchor_gain(self, w: Window, R_s: float, course_mode: bool) -> float:
        """The position anchor (§2.11), at least :data:`COURSE_MODE_ANCHOR` in course
        mode. A small fixed gain is about ``P / R``: with the fixes' own accuracy and a
        Doppler speed in the window it is lowered by the configured over the point's
        noise variance when the fixes are worse than configured."""
        ka = self.cfg.position_anchor
        if course_mode:
            ka = max(ka, COURSE_MODE_ANCHOR)
        if self.cfg.gnss_accuracy and w.n_v:
            ratio = self.sigma_p ** 2 / (w.n_fix * R_s)
            if ratio < 1.0:
                ka *= ratio
        return ka

    # -- estimates at the tick ----------------------------------------------------------------

    def _output(self, t: float) -> dict[str, float]:
        """The estimates at ``t`` (s): the track's (:meth:`TrackReconstruction.estimates`)
        and, for AIE, the input estimates."""
        out = self.track.estimates(t)
        if out:
            self._input_outputs(out)
        return out

    def _input_outputs(self, out: dict[str, float]) -> None:
        """AIE's input estimates now (``surge_input`` m/s^2, ``yaw_input`` rad/s^2): the
        input each axis would predict with, given the newest command."""
        if not self._publish_inputs:
            return
        if self.surge.kf.initialized:
            out["surge_input"] = self.surge.input_ahead(self.commands.latest(1))
        if self.yaw.kf.initialized and "heading" in out:
            out["yaw_input"] = self.yaw.input_ahead(self.commands.latest(2))

    # -- health and state ---------------------------------------------------------------------

    def _axes(self) -> tuple[tuple[str, IncrementFilter], ...]:
        return (("surge", self.surge), ("heading", self.yaw))

    def innovations(self) -> list[Innovation]:
        """The innovation records of both axes' updates since the last call (channels
        ``surge.increment``, ``surge.rate`` (the Doppler speed) and
        ``heading.increment``)."""
        out: list[Innovation] = list(self._unused_rate)
        self._unused_rate.clear()
        for _, ax in self._axes():
            out.extend(ax.innovations)
            ax.innovations.clear()
        return out

    def health(self) -> SurgeHeadingHealth:
        """Per axis its counters and the Doppler row's, the fixes of unusable accuracy,
        the measurement set of the ``"auto"`` parameters and its switches, and what each
        input model reports."""
        surge, yaw = self.surge, self.yaw
        return SurgeHeadingHealth(
            AxisHealth.of(surge), AxisHealth.of(yaw), surge.rate_steps, surge.rate_rejected,
            self._acc_bad, self.doppler, self.set_switches, surge.input_health(),
            yaw.input_health(), self.noise.health())

    def get_state(self) -> dict[str, Any]:
        """The axis models in use and what the input models learned (JSON-safe)."""
        st: dict[str, Any] = {}
        for nm, ax in self._axes():
            m = ax.model
            st[nm] = {"model": {"a": m.a, "gain": m.gain, "offset": m.offset}}
            st[nm].update(ax.input_state())
        st["noise"] = self.noise.get_state()
        return st

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`get_state`; a model that is missing, malformed, not finite or
        not damped (``a <= 0``) is ignored, and so is what does not fit an input model."""
        self.track.invalidate()
        self.noise.set_state(state.get("noise"))
        for nm, ax in self._axes():
            sub = state.get(nm)
            if not isinstance(sub, dict):
                continue
            model = _restored_model(sub.get("model"))
            if model is not None:
                ax.model = model
            ax.set_input_state(sub)

    def set_model(self, axis: Literal["surge", "heading"], model: AxisModel) -> None:
        """Use an identified model (e.g. from :func:`axis_model.identify_surge`)."""
        self.track.invalidate()
        (self.surge if axis == "surge" else self.yaw).model = model


def _restored_model(m: object) -> AxisModel | None:
    """The :class:`AxisModel` of a persisted ``{"a", "gain", "offset"}``, or None if it
    is malformed, not finite or not damped."""
    if not isinstance(m, dict):
        return None
    try:
        a, g, o = float(m["a"]), float(m["gain"]), float(m.get("offset", 0.0))
    except (KeyError, TypeError, ValueError):
        return None
    if math.isfinite(a) and a > 0 and math.isfinite(g) and math.isfinite(o):
        return AxisModel(a, g, o)
    return None


def sensor_noise(cfg: Config) -> tuple[float, float, float, float, float]:
    """``(gnss_position_std_m, heading_std_rad, gnss_velocity_std_mps, gnss_drift_share,
    gnss_drift_tau_s)`` from ``[sensors]``."""
    g = cfg.sensors.gnss
    return (g.position_std_m, cfg.sensors.compass.heading_std_rad, g.velocity_std_mps,
            g.drift_share, g.drift_tau_s)


def increment_variance(R: float, drift_share: float) -> float:
    """The noise variance (m^2) of a point of noise variance ``R`` as a path increment
    sees it: ``R`` less the slowly wandering share ``drift_share`` (``[sensors.gnss]
    drift_share``, the same share of every fix's variance, so of the window mean's too)."""
    return R * (1.0 - drift_share)


def drift_change_variance(R: float, drift_share: float, drift_tau_s: float,
                          dt: float) -> float:
    """The variance (m^2) of the drift's change over a step of ``dt`` s at a point of
    noise variance ``R``: the wandering share ``drift_share R`` as a first-order
    Gauss-Markov error of correlation time ``drift_tau_s``, ``2 drift_share R (1 -
    exp(-dt / drift_tau_s))`` (``[sensors.gnss] drift_share``, ``drift_tau_s``)."""
    return 2.0 * drift_share * R * -math.expm1(-dt / drift_tau_s)
