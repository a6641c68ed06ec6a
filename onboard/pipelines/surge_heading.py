"""The surge/heading estimation pipeline shared by ``aie`` and its ``kf`` baseline.

Everything except the input of the Kalman filter is common to the two pipelines, so the
comparison of the seed paper (Faros & Tanner 2025, §3) is like for like:

* measurement windows: ``step_s`` seconds for surge (the AIE step Ts, algorithms.md
  §1.2), ``heading_step_s`` for heading. All GNSS fixes (headings) in a window are
  averaged to one point at the window's mean time (a 1 Hz receiver gives the plain fix; a
  5 Hz one five times less variance). Consecutive points give the heading increment
  (§1.2, wrapped) and the path increment (§1.3, with the circular-arc correction). Steps
  are as long as the actual time between points, so irregular and missing fixes only
  change ``dt``; past ``max_gap_s`` the chain restarts;
* two independent axis filters (surge, heading) of :mod:`onboard.estimators.kalman`, fed
  by an :class:`AxisFilter` subclass that chooses the input (AIE: estimated; KF: command);
* trajectory reconstruction of the paper's §3.3: ``N += y_s cos(psi)``, ``E += y_s
  sin(psi)`` from the estimated increments (``psi`` at the chord's mid heading), and
  ``psi += y_psi``. The common mode of increments is unobservable, so the position is
  pulled toward the GNSS point by a small gain (``position_anchor``); the heading comes
  out exactly as the measured point minus its estimated noise when the MA(1) noise is
  modelled (``correlated_noise``), else it is pulled with ``heading_anchor``;
* estimates between steps are predicted with the model and the current input.

Inputs: :class:`GnssFix`, :class:`Heading` or :class:`Attitude` yaw, and
:class:`ActuatorCommand` (optional: without it AIE runs unchanged and the KF baseline
runs with zero input). The engine's source selector lets one heading source through; an
``Attitude`` whose yaw it did not select (``yaw_selected`` False) gives no heading, and
without the selector a ``Heading`` sample within ``HEADING_HOLD_S`` wins over the yaw.
"""

from __future__ import annotations

import math
from math import sqrt
from typing import Any, Callable, Literal, Mapping, Sequence

from onboard.core.config import Config
from onboard.core.geo import LocalFrame, wrap_2pi, wrap_pi
from onboard.core.messages import ActuatorCommand, Attitude, GnssFix, Heading, Imu, Sample
from onboard.core.pipeline_config import AieConfig, AxisConfig
from onboard.estimators.axis_model import (
    AxisModel,
    Discrete,
    axis_commands,
    discretize,
    path_increment,
)
from onboard.estimators.dead_reckoning import DeadReckoner
from onboard.estimators.kalman import IncrementKF
from onboard.estimators.path_accel import ForecastBlend, PathAccelerometer

HEADING_HOLD_S = 1.0
"""An ``Attitude`` yaw within this long (s) after a ``Heading`` sample is not used."""

# ---------------------------------------------------------------------------------------
# One axis: Kalman filter plus the choice of its input


class AxisFilter:
    """One axis (surge or heading): the §2.2 filter, outlier gate, counters.

    Subclasses define :meth:`forecast_input` (the input over the step just ended) and
    :meth:`after_innovation` (AIE: the RCIE step). Units: ``y`` in m or rad per step.
    """

    def __init__(self, model: AxisModel, cfg: AxisConfig, top: AieConfig, V_u: float) -> None:
        self.model = model
        self.cfg = cfg
        self.top = top
        self.V_u = V_u
        """Input-error variance of the forecast (u^2): the configured one, raised by the
        rate innovations with ``adaptive_rate_noise``."""
        self.V_u0 = V_u
        self.kf = IncrementKF(R=1.0, q_v=cfg.q_v, correlated=top.correlated_noise)
        self.u = 0.0
        """Input applied over the coming step (m/s^2 or rad/s^2)."""
        self.last_command: float | None = None
        self.steps = 0
        self.rejected = 0
        self.diverged = 0
        self.restarts = 0
        self._consecutive_rejects = 0
        self.nis_avg = 1.0
        self.rate_nis = 0.0
        self.rate_steps = 0
        self.rate_rejected = 0
        self.rate_z: float | None = None
        """Forecast innovation of the measured rate at this step (m/s), None without."""
        self.rate_S = 0.0
        self._rate_ms = 0.0     # running mean of rate_z^2 ((m/s)^2, ~20 steps)
        self._rate_pred = 0.0   # running mean of rate_S
        self._c1 = 0.0          # c1 of the last step (s)
        self._rate_rejects = 0  # consecutive rejected rates (the 6th is taken)
        self._rate_mean = 0.0   # running mean of rate_z (m/s, ~10 steps)
        self._rate_bias2 = 0.0  # running mean of its square ((m/s)^2, ~100 steps)

    def restart(self) -> None:
        """Forget the state (a gap in the measurements); keep adaptive coefficients."""
        self.kf.initialized = False
        self.restarts += 1

    def speed_bias_var(self) -> float:
        """Variance ((m/s)^2) of a speed error that persists while no measurement
        comes (dead reckoning): the rate's variance now, plus the input error the
        rate innovations show beyond what the filter predicts (their mean square
        minus the mean predicted ``S``, divided by ``c1^2``) held as a constant bias,
        which a first-order model turns into a speed error ``du / a``. Without
        measured rates, the input-error variance ``V_u`` is taken as that bias."""
        a = max(self.model.a, 0.05)
        if self._c1 > 0.0:
            excess = self._rate_ms - self._rate_pred
            var_u = ((excess if excess > 0.0 else 0.0) + self._rate_bias2) / (
                self._c1 * self._c1)
        else:
            var_u = self.V_u
        return self.kf.P[3] + var_u / (a * a)

    def _adapt_rate_noise(self, excess: float, c1: float) -> None:
        """Covariance matching on the rate innovation (``E[z_v^2] = S_v``, with ``S_v =
        alpha^2 P_vv + c1^2 V_u + R_v`` affine in ``V_u``): one stochastic-approximation
        step of ``V_u`` by ``excess = z_v^2 - S_v`` over ``c1^2`` (gain 0.05, ~20 steps),
        kept in [configured, ``(2 u_max)^2``]."""
        v = self.V_u + _RESIDUAL_GAIN * excess / (c1 * c1)
        hi = 4.0 * self.cfg.u_max * self.cfg.u_max
        self.V_u = self.V_u0 if v < self.V_u0 else hi if v > hi else v

    def damping(self, command: float | None) -> float:
        """The damping rate ``a`` (1/s) of the model used over a step."""
        return self.model.a

    def forecast_input(self, command: float | None) -> float:
        """The input ``u`` (m/s^2 or rad/s^2) of the forecast over the step just ended, given
        the mean normalized command over it (None without one); also kept as ``self.u``."""
        raise NotImplementedError

    def input_ahead(self, command: float | None) -> float:
        """The input to predict with beyond the last step, given the newest command."""
        return self.u

    def after_innovation(self, k: Discrete, command: float | None) -> None:
        """Hook between innovation and update (AIE computes d_hat here, §2.7)."""

    def _rate_update(self, y_v: float, R_v: float) -> None:
        """Assimilate the measured rate ``y_v`` (``IncrementKF.update_rate``); an outlier
        beyond ``nis_gate`` is left out and counted in ``rate_rejected``."""
        gate = self.top.nis_gate if self._rate_rejects < 5 else math.inf
        self.rate_nis = self.kf.update_rate(y_v, R_v, gate)
        self.rate_steps += 1
        if not self.rate_nis <= gate:
            self.rate_rejected += 1
            self._rate_rejects += 1
        else:
            self._rate_rejects = 0

    def step(self, k: Discrete, y: float, R: float, R_prev: float,
             command: float | None, y_v: float | None = None, R_v: float = 0.0) -> None:
        """One step: forecast over ``k.dt`` with the input, innovation, update (§2.7).

        ``y``: increment (m or rad); ``R``, ``R_prev``: noise variances of the two
        points it was formed from; ``command``: mean normalized command over the step
        (None if unknown); ``y_v``: the rate measured at the newer point (m/s, the
        window's mean GNSS Doppler speed; None without one) of noise variance ``R_v``.
        With ``y_v`` its forecast innovation ``rate_z = v_fc - y_v`` (variance
        ``rate_S``) is set before :meth:`after_innovation`, and the rate is assimilated
        after the increment.
        """
        kf = self.kf
        self.last_command = command
        kf.R = R if kf.correlated else R + R_prev
        if not kf.initialized:
            # the first rate is y / dt: its variance includes both points' noise
            var_v = (self.cfg.u_max * k.dt) ** 2 + (R + R_prev) / (k.dt * k.dt)
            kf.init(y, k.dt, R_prev, var_v)
            if self.cfg.known_input and command is not None:
                self.u = self.model.input(command)
            if y_v is not None:
                self._rate_update(y_v, R_v)
            return
        kf.forecast(k, self.forecast_input(command), self.V_u)
        if y_v is not None:
            z_v = self.rate_z = kf.v - y_v
            S_v = self.rate_S = kf.P[3] + R_v
            if z_v * z_v <= self.top.nis_gate * S_v:
                self._rate_ms += _RESIDUAL_GAIN * (z_v * z_v - self._rate_ms)
                self._rate_pred += _RESIDUAL_GAIN * (S_v - self._rate_pred)
                self._rate_mean += 0.1 * (z_v - self._rate_mean)
                m2 = self._rate_mean * self._rate_mean
                self._rate_bias2 += 0.01 * (m2 - self._rate_bias2)
                self._c1 = k.c1
                if self.top.adaptive_rate_noise:
                    self._adapt_rate_noise(z_v * z_v - S_v, k.c1)
        else:
            self.rate_z = None
        kf.innovation(y)
        if kf.nis > self.top.nis_gate and self._consecutive_rejects < 5:
            self.rejected += 1
            self._consecutive_rejects += 1
            kf.skip()
        else:
            self._consecutive_rejects = 0
            self.nis_avg += 0.05 * (min(kf.nis, 1e6) - self.nis_avg)
            self.after_innovation(k, command)
            kf.update()
            self.steps += 1
        if y_v is not None:
            self._rate_update(y_v, R_v)


SPEED_ACCURACY_MAX_MPS = 5.0
"""Ceiling of a fix's reported speed accuracy (m/s)."""


# ---------------------------------------------------------------------------------------
# The pipeline


class _Window:
    """Running sums of one measurement window."""

    __slots__ = ("n_fix", "st_fix", "sn", "se", "sr", "n_v", "sv", "svx", "n_h", "st_h",
                 "sh")

    def __init__(self) -> None:
        self.n_fix = 0
        self.st_fix = self.sn = self.se = 0.0
        self.sr = 0.0   # sum of the fixes' position noise variances (m^2)
        self.n_v = 0
        self.sv = 0.0
        self.svx = 0.0  # sum of the Doppler speeds' noise variances above the configured
        self.n_h = 0
        self.st_h = self.sh = 0.0


_RESIDUAL_GAIN = 0.05
"""Weight of the newest anchor residual in its running mean square (~20 surge steps)."""

_CRAB_MIN_SPEED = 0.5
"""Below this speed over ground (m/s) the course is too noisy for the crab angle."""

AxisFactory = Callable[[AxisModel, AxisConfig, AieConfig], AxisFilter]


class SurgeHeadingPipeline:
    """Surge and heading filters with trajectory reconstruction (``aie`` or ``kf``).

    ``columns``: north, east (m from the first fix), heading (rad, [0, 2 pi)), speed
    (m/s), yaw_rate (rad/s), and for AIE surge_input (m/s^2), yaw_input (rad/s^2).

    The surge axis steps every ``step_s`` (GNSS windows), the heading axis every
    ``heading_step_s`` (compass windows); each window's points are averaged.
    """

    def __init__(self, name: str, columns: tuple[str, ...], cfg: AieConfig,
                 gnss_std_m: float, heading_std_rad: float, factory: AxisFactory,
                 gnss_velocity_std_mps: float = 0.1) -> None:
        self.name = name
        self.columns = columns
        self.cfg = cfg
        self.sigma_p = cfg.gnss_std_m if cfg.gnss_std_m is not None else gnss_std_m
        self.sigma_v = (cfg.gnss_velocity_std_mps if cfg.gnss_velocity_std_mps is not None
                        else gnss_velocity_std_mps)
        """Speed-over-ground noise of one fix (m/s)."""
        self.sigma_h = (cfg.heading_std_rad if cfg.heading_std_rad is not None
                        else heading_std_rad)
        s, h = cfg.surge, cfg.heading
        self.surge = factory(AxisModel(s.a, s.gain, s.offset), s, cfg)
        self.yaw = factory(AxisModel(h.a, h.gain, h.offset), h, cfg)
        self.frame: LocalFrame | None = None
        self._t0: float | None = None
        self._step_h = cfg.heading_step_s if cfg.heading_step_s > 0 else cfg.step_s
        self._w = _Window()          # surge window: fixes and the headings among them
        self._hw = _Window()         # heading-axis window
        self._w_end = self._hw_end = math.inf
        self._w_early = False        # the surge window was closed early (close_at_output)
        self._next_end = math.inf    # min(_w_end, _hw_end): the next window to close
        self._handlers: dict[type, Callable[[Any], None] | None] = {}
        self._t_heading = -math.inf  # time (s) of the newest Heading sample
        self._psi_last: float | None = None       # last raw heading (unwrapped, rad)
        self._cmds: list[tuple[float, float | None, float | None]] = []
        # previous points
        self._pt_prev: tuple[float, float, float, float] | None = None  # t, N, E, psi
        self._h_prev: tuple[float, float] | None = None                 # t, psi
        # reconstruction: heading at _t_h, position at _t_s
        self._t_h: float | None = None
        self._t_s: float | None = None
        self._n = self._e = 0.0
        self._psi: float | None = None
        self._psi_s: float | None = None
        """Cache of ``_heading_at(_t_s)`` (rad) for the output; None when stale (reset
        whenever a window closes, a command arrives or the model changes)."""
        self._have_pos = False
        self._R_prev = self.sigma_p ** 2   # noise variance of the previous point (m^2)
        self._acc_lo, self._acc_hi = cfg.gnss_accuracy_min_m, cfg.gnss_accuracy_max_m
        self._acc_bad = 0   # fixes whose h_acc_m was not a positive number
        if not 0.0 < self._acc_lo <= self._acc_hi:
            raise ValueError("[pipelines.aie] needs 0 < gnss_accuracy_min_m <= "
                             f"gnss_accuracy_max_m, got {self._acc_lo}, {self._acc_hi}")
        self._course: float | None = None     # course over ground (GNSS-only logs)
        self._course_pts: list[tuple[float, float]] = []
        self._R_h_prev = self.sigma_h ** 2
        # one-sigma figures (see _output): variances of the reconstruction
        self._var_n = self._var_e = 0.0     # position at _t_s (m^2)
        self._var_psi = self.sigma_h ** 2   # heading at _t_h (rad^2)
        self._var_course = 0.0              # course of the GNSS-only mode (rad^2)
        self._r2n = self._r2e = 0.0         # mean square anchor residual less R (m^2)
        self._var_fix = self.sigma_p ** 2   # slowly varying fix error (m^2), see _std_outputs
        self._disc_cache: dict[tuple[float, float], Discrete] = {}
        self._dr: DeadReckoner | None = None
        """Dead reckoning since the last surge step, while windows pass without a fix."""
        self._psi_dr = 0.0  # heading (rad, unwrapped) at the dead reckoning's time
        self._imu: PathAccelerometer | None = PathAccelerometer() if cfg.imu_aiding else None
        """The accelerometer's path acceleration, integrated (``imu_aiding``)."""
        self._blend = ForecastBlend()
        """Weight of the accelerometer's speed forecast against the model's, from their
        misses of the Doppler speed at each surge step."""

    # -- helpers -----------------------------------------------------------------------

    def _disc(self, a: float, dt: float) -> Discrete:
        key = (a, round(dt, 4))
        d = self._disc_cache.get(key)
        if d is None:
            if len(self._disc_cache) > 64:
                self._disc_cache.clear()
            d = self._disc_cache[key] = discretize(a, key[1])
        return d

    def _mean_command(self, t_a: float, t_b: float, j: int) -> float | None:
        """Time-weighted mean of command ``j`` (1 surge, 2 yaw) over [t_a, t_b] (ZOH)."""
        cmds = self._cmds
        if not cmds:
            return None
        if t_b <= t_a:
            return cmds[-1][j]
        acc = tot = 0.0
        for i, c in enumerate(cmds):
            t_s = max(c[0], t_a)
            t_e = min(cmds[i + 1][0] if i + 1 < len(cmds) else t_b, t_b)
            v = c[j]
            if t_e <= t_s or v is None:
                continue
            acc += v * (t_e - t_s)
            tot += t_e - t_s
        return acc / tot if tot > 0.0 else None

    def _trim_commands(self) -> None:
        """Drop commands no future step needs (keep the one in force at the oldest
        previous point)."""
        ts = [p[0] for p in (self._pt_prev, self._h_prev) if p is not None]
        if not ts or not self._cmds:
            return
        t_keep = min(ts)
        keep = 0
        for i, c in enumerate(self._cmds):
            if c[0] <= t_keep:
                keep = i
            else:
                break
        if keep:
            del self._cmds[:keep]

    # -- sample intake -----------------------------------------------------------------

    def _add_heading(self, t: float, psi: float) -> None:
        u = psi if self._psi_last is None else self._psi_last + wrap_pi(psi - self._psi_last)
        self._psi_last = u
        for w in (self._w, self._hw):
            w.n_h += 1
            w.st_h += t
            w.sh += u

    def _advance(self, t: float) -> None:
        """Close every window that ends at or before ``t`` (heading first)."""
        if self._t0 is None:
            return
        gap = self.cfg.max_gap_s
        for which in ("h", "s"):
            step = self._step_h if which == "h" else self.cfg.step_s
            end = self._hw_end if which == "h" else self._w_end
            while t >= end:
                if which == "h":
                    self._close_heading_window()
                else:
                    self._close_surge_window(end)
                end += step
                if t - end > gap:   # jump across a long silence
                    end = self._t0 + step * (math.floor((t - self._t0) / step) + 1)
            if which == "h":
                self._hw_end = end
            else:
                self._w_end = end
        self._next_end = min(self._hw_end, self._w_end)

    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        """Consume samples (time-ordered) and return the estimates at time ``t``.

        Every sample, whatever its type, first closes the windows ending at or before its
        time (``_next_end`` caches the earlier of the two ends, so a sample inside both
        windows costs one comparison); its handler (:meth:`_handler`) then adds it.
        """
        handlers = self._handlers
        for s in samples:
            st = s.t
            if st >= self._next_end:
                self._advance(st)
            cls = type(s)
            h = handlers[cls] if cls in handlers else self._handler(cls)
            if h is not None:
                h(s)
        w = self._w
        if w.n_fix and self.cfg.close_at_output and (w.n_h or self._psi_last is None):
            self._close_surge_window(t)
            self._w_early = True
        return self._output(t)

    def _handler(self, cls: type) -> Callable[[Any], None] | None:
        """The intake method for a sample class (None: not an input), cached per class;
        subclasses of the input messages get their base's handler."""
        h = None
        for base, fn in ((GnssFix, self._on_fix), (Heading, self._on_heading),
                         (Attitude, self._on_attitude), (ActuatorCommand, self._on_command),
                         (Imu, self._on_imu)):
            if issubclass(cls, base):
                h = fn
                break
        self._handlers[cls] = h
        return h

    def _start(self, t: float) -> None:
        """The first measurement (fix, heading or attitude, at ``t`` s) starts both windows."""
        self._t0 = t
        self._w_end = t + self.cfg.step_s
        self._hw_end = t + self._step_h
        self._next_end = min(self._hw_end, self._w_end)

    def _on_fix(self, s: GnssFix) -> None:
        if self._t0 is None:
            self._start(s.t)
        if s.fix_quality <= 0:
            return
        if self.frame is None:
            self.frame = LocalFrame(s.lat_deg, s.lon_deg)
            # surge windows end a quarter step after the fixes (a regular receiver):
            # each closes with the first sample after its fix, not a step later
            self._w_end = s.t + 0.25 * self.cfg.step_s
            self._next_end = min(self._hw_end, self._w_end)
        n, e = self.frame.to_ne(s.lat_deg, s.lon_deg)
        w = self._w
        w.n_fix += 1
        w.st_fix += s.t
        w.sn += n
        w.se += e
        acc = s.h_acc_m
        if acc is not None and self.cfg.gnss_accuracy and acc > 0.0 and math.isfinite(acc):
            acc = self._acc_lo if acc < self._acc_lo else (
                self._acc_hi if acc > self._acc_hi else acc)
            w.sr += acc * acc
        else:
            if acc is not None and self.cfg.gnss_accuracy:   # NaN, 0 or negative
                self._acc_bad += 1
            w.sr += self.sigma_p ** 2
        sog = s.sog_mps
        cog, psi = s.cog_rad, self._psi_last
        if (self._imu is not None and sog is not None and cog is not None
                and psi is not None and abs(sog) > _CRAB_MIN_SPEED):
            self._imu.crab(cog - psi)   # course over ground minus heading
        if sog is not None and self.cfg.gnss_velocity and math.isfinite(sog):
            # signed path speed: astern when the course is more than 90 deg off the
            # heading (the newest compass reading; GNSS-only logs: always ahead)
            if cog is not None and psi is not None and math.cos(cog - psi) < 0.0:
                sog = -sog
            w.n_v += 1
            w.sv += sog
            sacc = s.speed_acc_mps
            if sacc is not None and self.cfg.gnss_accuracy:
                if not (sacc > 0.0 and math.isfinite(sacc)):
                    self._acc_bad += 1
                elif sacc > self.sigma_v:
                    sacc = sacc if sacc < SPEED_ACCURACY_MAX_MPS else SPEED_ACCURACY_MAX_MPS
                    w.svx += sacc * sacc - self.sigma_v ** 2

    def _on_heading(self, s: Heading) -> None:
        if self._t0 is None:
            self._start(s.t)
        self._t_heading = s.t
        dec = (s.declination_rad or 0.0) if s.reference == "magnetic" else 0.0
        self._add_heading(s.t, s.heading_rad + dec)

    def _on_attitude(self, s: Attitude) -> None:
        if self._imu is not None:
            self._imu.attitude(s.t, s.roll_rad, s.pitch_rad)
        if self._t0 is None:
            self._start(s.t)
        if s.yaw_selected and s.t - self._t_heading > HEADING_HOLD_S:
            self._add_heading(s.t, s.yaw_rad)

    def _on_imu(self, s: Imu) -> None:
        imu = self._imu
        if imu is not None:
            imu.add(s.t, s.accel_x, s.accel_y, s.gyro_x, s.gyro_y, s.gyro_z)

    def _on_command(self, s: ActuatorCommand) -> None:
        sc, yc = axis_commands(s, self.cfg.input_mode)
        self._cmds.append((s.t, sc, yc))
        self._psi_s = None
        if len(self._cmds) > 4096:   # no measurements for a long time
            del self._cmds[:2048]

    # -- one step per window -----------------------------------------------------------

    def _close_heading_window(self) -> None:
        self._psi_s = None
        w = self._hw
        self._hw = _Window()
        if w.n_h == 0:
            return
        th = w.st_h / w.n_h
        psi = w.sh / w.n_h
        R_h = self.sigma_h ** 2 / w.n_h
        R_h_prev, self._R_h_prev = self._R_h_prev, R_h
        hp = self._h_prev
        if hp is not None and th - hp[0] <= 1e-3:
            return
        self._h_prev = (th, psi)
        if hp is not None and th - hp[0] > self.cfg.max_gap_s:
            self.yaw.restart()
            hp = None
        if hp is None:   # (re)start the reconstruction from the measurement
            self._psi = psi
            self._t_h = th
            self._var_psi = R_h
            return
        dt = th - hp[0]
        cmd = self._mean_command(hp[0], th, 2)
        self.yaw.step(self._disc(self.yaw.damping(cmd), dt), wrap_pi(psi - hp[1]), R_h,
                      R_h_prev, cmd)
        # §3.3 heading: integrate the estimated increment ...
        kfy = self.yaw.kf
        pred = (self._psi if self._psi is not None else hp[1]) + kfy.d
        n_hat = kfy.point_noise()
        if n_hat is not None:
            # ... which with the MA(1) noise model equals the measured point minus its
            # estimated noise (the e-state makes the absolute heading observable)
            self._psi = pred + wrap_pi(psi - n_hat - pred)
            # its error is that of n_hat = y - d + e: Var = P_dd - 2 P_de + P_ee (rad^2)
            P = kfy.P
            self._var_psi = P[0] - 2.0 * P[2] + P[5]
        else:   # white-noise increments: pull toward the measurement
            kh = self.cfg.heading_anchor
            self._psi = pred + kh * wrap_pi(psi - pred)
            self._var_psi = ((1.0 - kh) ** 2 * (self._var_psi + kfy.P[0])
                             + kh * kh * R_h)
        self._t_h = th
        self._trim_commands()

    def _heading_at(self, t: float) -> float:
        """The reconstructed heading (rad, unwrapped) predicted to time ``t``."""
        assert self._psi is not None and self._t_h is not None
        tau = min(max(t - self._t_h, 0.0), self.cfg.max_gap_s)
        yaw = self.yaw
        if not yaw.kf.initialized or tau <= 1e-6:
            return self._psi
        dpsi, _ = yaw.kf.predict_ahead(self._disc(yaw.damping(yaw.last_command), tau),
                                       yaw.input_ahead(self._latest_command(2)))
        return self._psi + dpsi

    def _latest_command(self, j: int) -> float | None:
        return self._cmds[-1][j] if self._cmds else None

    def _close_surge_window(self, t_end: float) -> None:
        """One surge step with the window ending at ``t_end`` (s): its fixes averaged to
        one point; a window without a fix advances the dead reckoning instead."""
        self._psi_s = None
        w = self._w
        self._w = _Window()
        early, self._w_early = self._w_early, False
        if w.n_fix == 0:
            if not early:   # the rest of a window closed early is no gap
                self._dead_reckon(t_end)
            return
        self._dr = None
        # Without any heading source (a GNSS-only log) the surge axis runs on the chord
        # length along the course over ground; reversing is then not detectable.
        course_mode = self._psi_last is None
        if w.n_h == 0 and not course_mode:
            return
        tp = w.st_fix / w.n_fix
        n, e = w.sn / w.n_fix, w.se / w.n_fix
        psi = w.sh / w.n_h if w.n_h else math.nan
        pp = self._pt_prev
        if pp is not None and tp - pp[0] <= 1e-3:
            return
        self._pt_prev = (tp, n, e, psi)
        # the point's noise variance: the mean of independent fixes' (each its own
        # accuracy, or the configured sigma)
        R_s = w.sr / (w.n_fix * w.n_fix)
        R_s_prev, self._R_prev = self._R_prev, R_s
        if pp is None or tp - pp[0] > self.cfg.max_gap_s:
            R_fix = R_s
            if pp is not None:
                self.surge.restart()
            if not self._have_pos or pp is None:
                self._n, self._e = n, e
                self._var_n = self._var_e = R_fix
            else:  # across a gap: follow the measured displacement (noise of both fixes)
                self._n += n - pp[1]
                self._e += e - pp[2]
                dv = R_fix + R_s_prev
                self._var_n += dv
                self._var_e += dv
            self._have_pos = True
            self._t_s = tp
            return
        dt = tp - pp[0]
        if course_mode:   # project on the course over a ~5-point baseline (unbiased)
            dpsi = 0.0
            hist = self._course_pts
            hist.append((n, e))
            if len(hist) > 4:
                del hist[0]
            n0, e0 = hist[0]
            course = math.atan2(e - e0, n - n0) if len(hist) > 1 else 0.0
            y = math.cos(course) * (n - pp[1]) + math.sin(course) * (e - pp[2])
            # course from two points of variance R_s over the baseline L: 2 R_s / L^2
            base2 = (n - n0) ** 2 + (e - e0) ** 2
            self._var_course = min(2.0 * R_s / base2, 1.0) if base2 > 0.0 else 1.0
        else:  # a previous point from before the first heading has none: no turn
            psi_prev = psi if math.isnan(pp[3]) else pp[3]
            dpsi = wrap_pi(psi - psi_prev)
            y = path_increment(n - pp[1], e - pp[2], psi_prev, dpsi)
        cmd = self._mean_command(pp[0], tp, 1)
        # the window's mean Doppler speed: the rate at the point's time tp
        y_v = w.sv / w.n_v if w.n_v else None
        v_prev = self.surge.kf.v if self.surge.kf.initialized else None
        self.surge.step(self._disc(self.surge.damping(cmd), dt), y, R_s, R_s_prev, cmd,
                        y_v, self.sigma_v ** 2 / w.n_v + w.svx / (w.n_v * w.n_v)
                        if w.n_v else 0.0)
        imu = self._imu
        if imu is not None and v_prev is not None and y_v is not None:
            # both forecasts of the speed at tp against the measured one: the model's
            # (the filter's forecast) and the accelerometer's from the last estimate
            acc = imu.delta(pp[0], tp)
            rz = self.surge.rate_z
            if acc is not None and rz is not None:
                self._blend.add(rz, v_prev + acc[0] - y_v)
            imu.update_bias(pp[0], tp, self.surge.kf.v - v_prev)
        # §3.3 position from the estimated increment along the mid-chord heading
        ys = self.surge.kf.d
        if course_mode:
            mid = self._course = course
        elif self._psi is not None and self._t_h is not None:
            self._psi_dr = self._heading_at(tp)
            mid = 0.5 * (self._heading_at(pp[0]) + self._psi_dr)
        else:
            mid = pp[3] + 0.5 * dpsi
        self._n += ys * math.cos(mid)
        self._e += ys * math.sin(mid)
        # the course lags the track by half its baseline: anchor harder without a compass
        ka = self.cfg.position_anchor if not course_mode else max(self.cfg.position_anchor,
                                                                   0.3)
        # A small fixed gain is ~ P / R: with the fixes' own accuracy it is lowered by the
        # configured over the point's noise variance when the fixes are worse than
        # configured (the anchor was tuned at the configured sigma; a stiffer anchor for
        # better fixes passes more of their drift: measured worse, docs/aie.md). Only
        # where the window has a Doppler speed: the dead reckoning between anchors is
        # then good; without it the track rests on the fixes (measured 4x worse).
        rn, re = n - self._n, e - self._e
        g = _RESIDUAL_GAIN
        self._r2n += g * (rn * rn - R_s - self._r2n)
        self._r2e += g * (re * re - R_s - self._r2e)
        rn2, re2 = self._r2n, self._r2e
        if self.cfg.gnss_accuracy and w.n_v:
            ratio = self.sigma_p ** 2 / (w.n_fix * R_s)
            if ratio < 1.0:
                ka *= ratio
        self._n += ka * rn
        self._e += ka * re
        # its variance (see _std_outputs): increment along track, heading across, or
        # what the anchor residuals show if more, then the anchor's fixed-gain blend
        var_a = self.surge.kf.P[0]
        var_x = ys * ys * (self._var_course if course_mode else self._var_psi)
        c, s_ = math.cos(mid), math.sin(mid)
        vn = self._var_n + c * c * var_a + s_ * s_ * var_x
        ve = self._var_e + s_ * s_ * var_a + c * c * var_x
        f = (1.0 - ka) ** 2
        fr = ka * ka * R_s
        self._var_n = f * (vn if vn > rn2 else rn2) + fr
        self._var_e = f * (ve if ve > re2 else re2) + fr
        self._t_s = tp
        self._trim_commands()

    def _dead_reckon(self, t_end: float) -> None:
        """Advance the dead reckoning to ``t_end`` (s) through a window without a fix
        (:class:`DeadReckoner`): the surge filter's speed and input along the heading
        filter's heading. Started at the last surge step; used for the published
        position once the gap exceeds ``max_gap_s``; dropped at the next fix (within
        ``max_gap_s`` the increment over the longer step then replaces it)."""
        surge = self.surge
        if (not surge.kf.initialized or self._t_s is None or self._psi is None
                or self._t_h is None or self._psi_last is None):
            return
        dr = self._dr
        if dr is None:
            var_psi = self._var_psi
            dr = self._dr = DeadReckoner(
                self._t_s, self._n, self._e, surge.kf.v, surge.kf.P[3], self._var_n,
                self._var_e, math.sqrt(surge.speed_bias_var()), math.sqrt(var_psi))
        dt = t_end - dr.t
        if dt <= 1e-6:
            return
        cmd = self._mean_command(dr.t, t_end, 1)
        k = self._disc(surge.damping(cmd), dt)
        psi1 = self._heading_at(t_end)
        dr.advance(k, surge.input_ahead(cmd), 0.5 * (self._psi_dr + psi1), surge.V_u)
        self._psi_dr = psi1

    # -- output ------------------------------------------------------------------------

    def _output(self, t: float) -> dict[str, float]:
        out: dict[str, float] = {}
        yaw, surge = self.yaw, self.surge
        if self._psi is None or self._t_h is None:   # no heading source (yet)
            if self._course is not None and surge.kf.initialized and self._t_s is not None:
                tau = min(max(t - self._t_s, 0.0), self.cfg.max_gap_s)
                ds, v = surge.kf.predict_ahead(
                    self._disc(surge.damping(surge.last_command), max(tau, 1e-6)),
                    surge.input_ahead(self._latest_command(1)))
                out["speed"] = v
                out["north"] = self._n + ds * math.cos(self._course)
                out["east"] = self._e + ds * math.sin(self._course)
                k = self._disc(surge.damping(surge.last_command), max(tau, 1e-6))
                P, V_u = surge.kf.P, surge.V_u
                var_v = k.alpha * k.alpha * P[3] + k.c1 * k.c1 * V_u
                self._std_outputs(out, t, math.cos(self._course), math.sin(self._course),
                                  ds, v,
                                  k.c1 * k.c1 * P[3] + k.c2 * k.c2 * V_u, var_v,
                                  self._var_course)
                self._extra_outputs(out)
            return out
        # The heading and yaw rate (as _heading_at: one prediction for both), then the
        # speed and position, predicted from the last steps to t with the newest command.
        # Inline min/max and cache look-ups: this runs every tick.
        gap = self.cfg.max_gap_s
        cmds = self._cmds
        last = cmds[-1] if cmds else None
        psi = self._psi
        ykf = yaw.kf
        var_h = self._var_psi
        if ykf.initialized:
            tau = t - self._t_h
            tau = 0.0 if tau < 0.0 else gap if tau > gap else tau
            r = ykf.v
            if tau > 1e-6:
                k = self._disc(yaw.damping(yaw.last_command), tau)
                dpsi, r = ykf.predict_ahead(
                    k, yaw.input_ahead(last[2] if last is not None else None))
                psi = psi + dpsi
                var_h += k.c1 * k.c1 * ykf.P[3] + k.c2 * k.c2 * yaw.V_u
            out["heading"] = wrap_2pi(psi)
            out["yaw_rate"] = r
        else:
            out["heading"] = wrap_2pi(psi)
        out["std_heading"] = sqrt(var_h)
        skf = surge.kf
        dr = self._dr
        if dr is not None and self._t_s is not None and t - self._t_s > gap:
            self._dr_output(out, t, psi, var_h, last)
        elif skf.initialized and self._t_s is not None:
            tau_raw = tau = t - self._t_s
            tau = 0.0 if tau < 0.0 else gap if tau > gap else tau
            ds, v = skf.v * tau, skf.v
            P = skf.P
            var_ds, var_v = P[3] * tau * tau, P[3]
            if tau > 1e-6:
                k = self._disc(surge.damping(surge.last_command), tau)
                ds, v = skf.predict_ahead(
                    k, surge.input_ahead(last[1] if last is not None else None))
                V_u = surge.V_u
                var_ds = k.c1 * k.c1 * P[3] + k.c2 * k.c2 * V_u
                var_v = k.alpha * k.alpha * P[3] + k.c1 * k.c1 * V_u
                # the accelerometer's forecast (path_accel.py), blended with the model's
                # by the weight their misses of the Doppler speed give (none at weight 0)
                imu, wi = self._imu, self._blend.w
                acc = (imu.delta(self._t_s, t) if imu is not None and wi > 0.0
                       and tau_raw <= self.cfg.imu_horizon_s else None)
                if acc is not None:
                    wm = 1.0 - wi
                    V_a = imu.bias_var  # type: ignore[union-attr]
                    ds = wm * ds + wi * (skf.v * tau + acc[1])
                    v = wm * v + wi * (skf.v + acc[0])
                    var_ds = wm * var_ds + wi * tau * tau * (P[3] + 0.25 * tau * tau * V_a)
                    var_v = wm * var_v + wi * (P[3] + tau * tau * V_a)
            out["speed"] = v
            psi_s = self._psi_s
            if psi_s is None:   # changes only when a window closes or a command arrives
                psi_s = self._psi_s = self._heading_at(self._t_s)
            mid = 0.5 * (psi_s + psi)
            c, s = math.cos(mid), math.sin(mid)
            out["north"] = self._n + ds * c
            out["east"] = self._e + ds * s
            # _std_outputs inlined (this runs every tick)
            ex = tau_raw - gap
            var_p = self._var_fix + (0.5 * (v * v + var_v) * ex * ex if ex > 0.0 else 0.0)
            var_x = ds * ds * var_h
            cc, ss = c * c, s * s
            out["std_north"] = sqrt(self._var_n + cc * var_ds + ss * var_x + var_p)
            out["std_east"] = sqrt(self._var_e + ss * var_ds + cc * var_x + var_p)
            out["std_speed"] = sqrt(var_v)
        elif self._have_pos:
            out["north"], out["east"] = self._n, self._e
            out["std_north"] = math.sqrt(self._var_n + self._var_fix)
            out["std_east"] = math.sqrt(self._var_e + self._var_fix)
        self._extra_outputs(out)
        return out

    def _dr_output(self, out: dict[str, float], t: float, psi: float, var_h: float,
                   last: tuple[float, float | None, float | None] | None) -> None:
        """Speed, position and their sigmas from the dead reckoning (a GNSS gap longer
        than ``max_gap_s``), predicted from its time to ``t`` with the newest command."""
        dr, surge = self._dr, self.surge
        assert dr is not None
        tau = t - dr.t
        u = surge.input_ahead(last[1] if last is not None else None)
        ds, v, var_ds = 0.0, dr.v, 0.0
        var_v = dr.p_vv
        if tau > 1e-6:
            k = self._disc(surge.damping(surge.last_command), tau)
            ds, v = k.c1 * dr.v + k.c2 * u, k.alpha * dr.v + k.c1 * u
            var_ds = k.c1 * k.c1 * dr.p_vv + k.c2 * k.c2 * surge.V_u
            var_v = k.alpha * k.alpha * dr.p_vv + k.c1 * k.c1 * surge.V_u
        mid = 0.5 * (self._psi_dr + psi)
        c, s = math.cos(mid), math.sin(mid)
        vn, ve = dr.variances()
        var_x = ds * ds * var_h
        out["speed"] = v
        out["north"] = dr.n + ds * c
        out["east"] = dr.e + ds * s
        out["std_north"] = sqrt(vn + c * c * var_ds + s * s * var_x + self._var_fix)
        out["std_east"] = sqrt(ve + s * s * var_ds + c * c * var_x + self._var_fix)
        out["std_speed"] = sqrt(var_v)

    def _std_outputs(self, out: dict[str, float], t: float, c: float, s: float,
                     ds: float, v: float, var_ds: float, var_v: float, var_x: float
                     ) -> None:
        """``std_north``, ``std_east`` (m) and ``std_speed`` (m/s): one sigma of the
        published position and speed at ``t`` (``c, s``: cos and sin of the heading the
        path ``ds`` (m) since the last surge step is laid along; ``var_x``: that
        heading's variance, rad^2).

        Position variance per axis (m^2), first order, cross-covariances between steps
        and between north and east neglected. Kept at the last surge step ``t_s``
        (:meth:`_close_surge_window`), for the dead-reckoned part of the error:

        * the step's increment adds ``P_dd`` (m^2, the surge filter's increment variance
          after its update) along the mid-chord heading and ``y_s^2 var(psi)`` across it
          (``var(psi)`` the heading filter's variance of the reconstructed heading,
          ``P_dd - 2 P_de + P_ee`` of its point-noise estimate), rotated into north/east;
        * model error (sideslip in turns, a wrong thrust map: errors correlated over many
          steps) is not in those covariances, so the predicted variance is raised to what
          the anchor residuals show when larger: ``mean(r^2) - R`` (``r`` = window's mean
          fix minus the dead-reckoned position, per axis, running mean over ~20 steps,
          ``R = gnss_std_m^2 / n_fix`` the white part of ``r``);
        * the anchor's fixed-gain blend with that fix: ``var <- (1 - k)^2 var + k^2 R``;
          it starts at ``R`` with the first fix and adds both fixes' ``R`` across a gap,
          where the position follows the measured displacement.

        Published at ``t``:

        * plus the prediction from ``t_s`` (``tau <= max_gap_s``): ``c1^2 P_vv + c2^2 V_u``
          along (the surge filter's forecast variance of the increment over ``tau``;
          ``V_u`` its input-error variance, (m/s^2)^2) and ``ds^2 var(psi)`` across;
        * plus, beyond ``max_gap_s`` without a surge step (a GNSS outage), where the
          published position is held while the vehicle moves on, ``(v^2 + var(v))
          (t - t_s - max_gap_s)^2 / 2`` on each axis: the displacement not followed,
          direction unknown, so the sigma grows about linearly with the time without
          fixes (conservative for a vehicle that turns back) and drops when they return;
        * plus ``gnss_std_m^2``: the fix error is mostly slowly varying (receiver drift),
          which the anchor passes unaveraged; the whole configured one-fix sigma is taken
          (conservative where part of it is white).

        ``std_speed`` is the surge filter's rate sigma forecast over ``tau``
        (``alpha^2 P_vv + c1^2 V_u``), with no model-error term. Coverage against SITL
        truth: docs/aie.md, "Published uncertainty".
        """
        var_x = ds * ds * var_x
        cc, ss = c * c, s * s
        vn = self._var_n + cc * var_ds + ss * var_x
        ve = self._var_e + ss * var_ds + cc * var_x
        ex = t - self._t_s - self.cfg.max_gap_s if self._t_s is not None else 0.0
        if ex > 0.0:
            held = 0.5 * (v * v + var_v) * ex * ex
            vn += held
            ve += held
        out["std_north"] = math.sqrt(vn + self._var_fix)
        out["std_east"] = math.sqrt(ve + self._var_fix)
        out["std_speed"] = math.sqrt(var_v)

    def _extra_outputs(self, out: dict[str, float]) -> None:
        """Hook for subclasses (AIE adds the input estimates)."""

    # -- health and state --------------------------------------------------------------

    def health(self) -> Mapping[str, float]:
        """Innovation ``z = C x_fc - y``, its variance S and NIS per axis, counters."""
        h: dict[str, float] = {}
        for nm, ax in (("surge", self.surge), ("heading", self.yaw)):
            kf = ax.kf
            h[f"{nm}.innovation"] = kf.z
            h[f"{nm}.S"] = kf.S
            h[f"{nm}.nis"] = kf.nis
            h[f"{nm}.nis_mean"] = ax.nis_avg
            h[f"{nm}.steps"] = float(ax.steps)
            h[f"{nm}.rejected"] = float(ax.rejected)
            h[f"{nm}.diverged"] = float(ax.diverged)
            h[f"{nm}.restarts"] = float(ax.restarts)
        h["surge.rate_nis"] = self.surge.rate_nis
        h["surge.rate_steps"] = float(self.surge.rate_steps)
        h["surge.rate_rejected"] = float(self.surge.rate_rejected)
        h["surge.accuracy_rejected"] = float(self._acc_bad)
        return h

    def get_state(self) -> dict[str, Any]:
        """The models in use (JSON-safe: finite floats only)."""
        def model(m: AxisModel) -> dict[str, float]:
            return {"a": m.a, "gain": m.gain, "offset": m.offset}
        return {"surge": {"model": model(self.surge.model)},
                "heading": {"model": model(self.yaw.model)}}

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore the axis models of :meth:`get_state`; a model that is missing, malformed,
        not finite or not damped (``a <= 0``) is ignored."""
        self._psi_s = None
        for nm, ax in (("surge", self.surge), ("heading", self.yaw)):
            m = state.get(nm, {}).get("model") if isinstance(state.get(nm), dict) else None
            if isinstance(m, dict):
                try:
                    a, g, o = float(m["a"]), float(m["gain"]), float(m.get("offset", 0.0))
                except (KeyError, TypeError, ValueError):
                    continue
                if math.isfinite(a) and a > 0 and math.isfinite(g) and math.isfinite(o):
                    ax.model = AxisModel(a, g, o)

    def set_model(self, axis: Literal["surge", "heading"], model: AxisModel) -> None:
        """Use an identified model (e.g. from surge_heading.identify_surge)."""
        self._psi_s = None
        (self.surge if axis == "surge" else self.yaw).model = model


def sensor_noise(cfg: Config) -> tuple[float, float, float]:
    """``(gnss_std_m, heading_std_rad, gnss_velocity_std_mps)`` from ``[sensors]``."""
    g = cfg.sensors.gnss
    return g.position_std_m, cfg.sensors.compass.heading_std_rad, g.velocity_std_mps
