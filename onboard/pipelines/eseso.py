"""The ESESO pipeline (``eseso``): samples of a BlueROV2-class vehicle into the ESESO.

Paper: L.-Y. Lo, Y. Hu, B. Li, C.-Y. Wen, Y. Yang, "An adaptive model predictive control for
unmanned underwater vehicles subject to external disturbances and measurement noise"
(``../shared/papers/eseso-ampc-bluerov2.txt``), section III; spec: ``algorithms.md`` §5.1.
The filter itself (nominal state, propagation, measurement models, reset, thrust model) is
:class:`onboard.estimators.eseso_filter.EsesoFilter`; this module is its adapter:
configuration (:class:`EsesoConfig`), sample handling, estimate records and health.

* **IMU**: each sample drives the propagation over the real interval since the previous
  sample (an IMU's delta-velocity / anti-aliased output belongs to the interval ending at
  its stamp); a gap longer than ``max_imu_gap_s`` is propagated as that long (counted
  ``imu_gap``). The first IMU sample after a new thruster command triggers the thrust
  update (while the command is fresh, ``thrusters.command_timeout_s``): the sample's
  specific force and rate, the angular acceleration from the last two gyro samples, and
  the thruster force averaged over the sample's interval (commands are held between
  updates and may change within it). The update runs at the actuator's rate, not the
  IMU's: the thrust is a measurement (paper eq. 14b) only when the controller sends it
  (the paper's controller at 20 Hz, its IMU at 50 Hz); a held command fused again at the
  next IMU sample would count the thrusters' force error (``noise.thrust_std_n``, the
  same for as long as the command is held) as new information each time.
* **Thruster commands** (normalized, [-1, 1]) become a body force: the force rows of the
  allocation matrix times the per-thruster forces of the thrust curve
  (``f = f_max c|c|`` for the T200).
* **Start**: at the first IMU sample after an attitude sample (position from the
  configured start point ``initial.north_m``/``initial.east_m``, a surveyed launch, and
  the last depth); without an attitude stream, levelled from gravity after 50 IMU samples
  with the yaw unknown (std pi).
* **Measurements**: GNSS horizontal position and velocity (only at the surface: a fix
  while the filter is deeper than ``gnss_max_depth_m`` is rejected), INS velocity over
  ground (R its white noise ``noise.ins_velocity_std_mps``, its correlated error the filter's
  ``b_ins`` state), depth, DVL bottom-track velocity (its figure of merit as sigma, no
  less than ``DVL_FOM_FLOOR_MPS``; a fix's reported accuracy no less than
  ``GNSS_H_ACC_FLOOR_M``),
  attitude (roll/pitch noise ``noise.attitude_std_rad``, yaw the compass heading's, which an
  AHRS reports as its yaw), heading (only without an attitude stream, which carries the
  same yaw). Samples that cannot be used are counted ``rejected.<stream>.<reason>``.
* **Innovations** (:meth:`Eseso.innovations`): one record per update, channels ``thrust``
  (the thrust model, never gated), ``attitude`` (3, rad, body rotation vector),
  ``heading`` (1, rad), ``dvl`` (3, m/s body, bottom track), ``depth`` (1, m), ``vog``
  (2, m/s, INS velocity over ground), ``gnss_pos`` (2, m), ``gnss_vel`` (2, m/s) and
  ``zupt`` (3, m/s, the zero-velocity update);
  gated updates with reason ``gate``, and a DVL sample that is invalid or beyond the
  figure of merit (``invalid``, ``fom``), a non-finite velocity over ground
  (``nonfinite``) and a fix while submerged (``submerged``) as rejected records without
  an innovation.
* **Zero velocity**: dead reckoning with nothing to bound its velocity integrates the
  accelerometer bias into a runaway (a disarmed ROV on a bench, ``small.BIN``: 100 m in
  24 s, 6.2 m/s, a 97 N disturbance). With no position or velocity source for
  ``ZUPT_AFTER_S`` and the thrusters idle (every command within ``ZUPT_IDLE_COMMAND`` of
  neutral, or none fresh), the velocity over ground is measured as zero with
  ``ZUPT_STD_MPS`` every ``ZUPT_INTERVAL_S`` (channel ``zupt``; a zero-velocity update).
* **Published disturbance**: the lumped disturbance ``xi`` (``dist_*``, body;
  ``dist_north`` ... earth), the force the thrust model misses: the external push plus
  whatever the model's mass, damping and thrust map get wrong, the paper's definition and
  what the AMPC adds to its model; off the design point it is not the push alone.
* **Published sigmas**: the filter's covariance; the disturbance's plus the error
  variance its thrust innovations show beyond that covariance (per body axis, learnt by
  covariance matching, ``EsesoFilter.disturbance_excess``), which the filter's gain does
  not use: the ``xi`` a controller consumes keeps its tuning, the sigma says how wrong
  it is (docs/eseso-mpc.md). The noise scales the filter learns from its innovations are
  in health (``noise_scale.<channel>``, ``noise_scale.imu``; the thrust channel's and the
  DVL's too: a DVL noisier than its figure of merit says, algorithms.md §5).
* **Position**: from the first fused GNSS fix (the local origin), or without one from the
  configured start point, then dead-reckoned with the DVL; its std grows without GNSS.

All numbers in, numbers out; no I/O and no clock.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import msgspec
import numpy as np
from numpy.typing import NDArray

from onboard.core.config import Config
from onboard.core.geo import LocalFrame
from onboard.core.messages import (
    ActuatorCommand,
    Attitude,
    Depth,
    DvlVelocity,
    EstimateRecord,
    GnssFix,
    Heading,
    Imu,
    Innovation,
    Sample,
    VelocityOverGround,
)
from onboard.core.pipeline_config import EsesoConfig, EsesoThrustersConfig
from onboard.core.so3 import euler_to_matrix, matrix_to_euler
from onboard.estimators.eseso_filter import (
    P_,
    P_D,
    PUBLISHED_VAR_MIN_SHARE,
    V_,
    EsesoFilter,
    EsesoParams,
    Outcome,
    warm_kernels,
)
from onboard.pipelines.base import PipelineDefaults, unused_measurement

Array = NDArray[np.float64]

LEVELLING_SAMPLES = 50
"""IMU samples averaged to level the filter from gravity when no attitude arrives."""
COMMAND_HISTORY_S = 1.0
"""Thruster commands older than this (s) are dropped from the history the thrust update
averages over (the one before it is kept: it holds at the interval's start)."""
COMMAND_HISTORY_MAX = 50
"""At most this many thruster commands are kept."""
IMU_HISTORY = 2
"""IMU samples kept (the last two: the angular acceleration's difference)."""

ZUPT_AFTER_S = 2.0
"""Without a position or velocity source (GNSS fix, INS velocity, valid DVL bottom track)
for this long (s) and with the thrusters idle, the filter holds still (module docstring,
"Zero velocity")."""
ZUPT_STD_MPS = 0.1
"""One sigma (m/s) of the zero-velocity pseudo-measurement, per axis: an idle vehicle
drifts with the water, whose speed nothing here measures; 0.1 m/s bounds a still-water
drift and lets a moving vehicle show in the gate."""
ZUPT_INTERVAL_S = 0.2
"""The zero-velocity pseudo-measurement is applied at most this often (s), whatever the
IMU rate."""
ZUPT_IDLE_COMMAND = 0.05
"""Thrusters whose normalized commands are all within this of neutral are idle."""

HEADING_HOLD_S = 1.0
"""A ``Heading`` sample within this long (s) after an ``Attitude`` with its yaw is not
used (an AHRS reports the same yaw); the engine's source selector lets one through."""
DVL_FOM_FLOOR_MPS = 0.003
"""Smallest one-sigma (m/s) a DVL's figure of merit may give its bottom-track velocity: a
FOM of a few mm/s is the sensor's short-term scatter, not its error (scale factor,
alignment and sound speed add ~0.1-0.3 % of the speed), and a FOM near zero would make the
update a hard constraint."""
GNSS_H_ACC_FLOOR_M = 0.02
"""Smallest one-sigma (m) a receiver's reported horizontal accuracy may give its fix: an
RTK fix (1-2 cm) keeps its weight, a reported 0 or a few mm does not pin the filter."""
YAW_UNSELECTED_VAR = 1.0e4
"""Yaw variance (rad^2) of an ``Attitude`` whose yaw the source selector did not choose:
its roll and pitch are used, its yaw carries no information."""


def _or(value: float | None, default: float) -> float:
    """``value``, or ``default`` when it is None, as a float."""
    return float(default if value is None else value)


def filter_params(c: EsesoConfig, sensors: Any | None = None) -> EsesoParams:
    """The filter's parameters: the tables of ``[pipelines.eseso]``, the IMU noise that
    ``[pipelines.eseso.noise]`` leaves unset from ``[sensors.imu]`` (``sensors`` None:
    0.05 m/s^2 and 0.005 rad/s)."""
    n = c.noise
    noise = msgspec.structs.replace(
        n, accel_std_mps2=_or(n.accel_std_mps2, sensors.imu.accel_std_mps2 if sensors else 0.05),
        gyro_std_rps=_or(n.gyro_std_rps, sensors.imu.gyro_std_rps if sensors else 0.005))
    return EsesoParams(
        vehicle=c.vehicle, process=c.process, noise=noise, initial=c.initial,
        thrust_states=c.thrust_states, thrust_huber=c.thrust_huber, gate_sigma=c.gate_sigma,
        max_consecutive_rejects=c.max_consecutive_rejects)


def thruster_force(cmd: float, c: EsesoThrustersConfig) -> float:
    """Per-thruster force (N) of a normalized command in [-1, 1]: the thrust curve
    ``max * sign(c) |c|^exponent`` of ``[pipelines.eseso.thrusters]`` with its deadband."""
    if abs(cmd) <= c.deadband:
        return 0.0
    mag = min(abs(cmd), 1.0) ** c.exponent
    return mag * (c.max_forward_n if cmd > 0 else -c.max_reverse_n)


class EsesoCounters:
    """The ESESO's event counts in the order each first occurred: those of its sample
    handling and the outcomes of its filter's updates (module docstring, "Innovations").

    Counted as ``fused.<channel>``, ``rejected.<channel>.gate`` (a recovered update
    too), ``recovered.<channel>``, ``thrust.downweighted``, ``rejected.<stream>.<reason>``,
    ``imu_gap`` and ``diverged``.
    """

    def __init__(self) -> None:
        self._n: dict[str, int] = {}

    def _add(self, key: str) -> None:
        self._n[key] = self._n.get(key, 0) + 1

    def update(self, channel: str, outcome: Outcome) -> None:
        """One update of ``channel`` and what became of it."""
        if outcome is Outcome.FUSED:  # most updates
            self._add(f"fused.{channel}")
            return
        self._add(f"rejected.{channel}.gate")
        if outcome is Outcome.RECOVERED:
            self._add(f"recovered.{channel}")
            self._add(f"fused.{channel}")

    def downweighted(self) -> None:
        """A thrust update down-weighted (``thrust_huber``)."""
        self._add("thrust.downweighted")

    def rejected(self, stream: str, reason: str) -> None:
        """A sample of ``stream`` (``imu``, ``gnss``, ...) not used, for ``reason``."""
        self._add(f"rejected.{stream}.{reason}")

    def imu_gap(self) -> None:
        """An IMU interval longer than ``max_imu_gap_s``."""
        self._add("imu_gap")

    def diverged(self) -> None:
        """The filter diverged and started again."""
        self._add("diverged")

    def get(self, key: str) -> int:
        """The count of ``key`` (0 if never counted)."""
        return self._n.get(key, 0)

    def as_dict(self) -> dict[str, int]:
        """Every count by its name, in the order each first occurred."""
        return dict(self._n)


class EsesoHealth(msgspec.Struct, frozen=True):
    """The health of pipeline ``eseso`` (:meth:`Eseso.health`)."""

    counts: dict[str, int]
    """The event counts (:class:`EsesoCounters`), in the order each first occurred."""
    noise_scale: dict[str, float]
    """Per sensor channel, the variance scale the innovations put on its configured
    noise (1 = as configured)."""
    imu_noise_scale: float
    """The variance scale of the IMU's noise (from the DVL's innovations)."""

    def flat(self) -> dict[str, float]:
        """The counts, then ``noise_scale.<channel>`` and ``noise_scale.imu``."""
        out = {k: float(v) for k, v in self.counts.items()}
        out.update({f"noise_scale.{ch}": v for ch, v in self.noise_scale.items()})
        out["noise_scale.imu"] = self.imu_noise_scale
        return out


class Eseso(PipelineDefaults):
    """The ESESO pipeline (``eseso``): state, disturbance force and their covariance.

    Attributes:
        filter: the :class:`~onboard.estimators.eseso_filter.EsesoFilter` (nominal state,
            covariance, innovations, NIS).
        r_gnss_p, r_gnss_v, r_depth, r_dvl, r_head, r_att, r_att_yaw, r_ins: measurement
            variances (SI units squared) resolved from ``[pipelines.eseso]`` and
            ``[sensors]``.
        counters: its event counts (:class:`EsesoCounters`).

    Roles: ``north``/``east`` a position in its own frame (``frame_offset``), ``u``/``v``
    its forward and sideways speed (:class:`~onboard.pipelines.base.Pipeline`).
    """

    position = ("north", "east")
    speed = ("u", "v")
    calibrating_channels = ("thrust",)

    name = "eseso"
    columns = (
        "north", "east", "down",
        "vel_north", "vel_east", "vel_down",
        "u", "v", "w",
        "roll", "pitch", "yaw",
        "rate_p", "rate_q", "rate_r",
        "dist_x", "dist_y", "dist_z",
        "dist_north", "dist_east", "dist_down",
        "std_north", "std_east", "std_down",
        "std_u", "std_v", "std_w",
        "std_dist_x", "std_dist_y", "std_dist_z",
        "accel_bias_x", "accel_bias_y", "accel_bias_z",
        "gyro_bias_x", "gyro_bias_y", "gyro_bias_z",
        "gravity_down",
    )

    def __init__(self, config: EsesoConfig, sensors: Any | None = None) -> None:
        c = self.cfg = config
        s = self._sensors = sensors
        self.K_alloc = np.asarray(c.thrusters.allocation, float)
        if self.K_alloc.shape[0] != 3:
            raise ValueError("pipelines.eseso.thrusters.allocation: expected 3 rows")

        n = c.noise
        self.r_gnss_p = _or(n.gnss_position_std_m, s.gnss.position_std_m if s else 2.0) ** 2
        self.r_gnss_v = _or(n.gnss_velocity_std_mps, s.gnss.velocity_std_mps if s else 0.1) ** 2
        self.r_depth = _or(n.depth_std_m, s.depth.depth_std_m if s else 0.02) ** 2
        self.r_dvl = _or(n.dvl_velocity_std_mps, s.dvl.velocity_std_mps if s else 0.01) ** 2
        self.r_head = _or(n.heading_std_rad, s.compass.heading_std_rad if s else 0.02) ** 2
        self.r_att = n.attitude_std_rad ** 2
        self.r_att_yaw = _or(n.attitude_yaw_std_rad, math.sqrt(self.r_head)) ** 2
        self.r_ins = n.ins_velocity_std_mps ** 2
        self.dvl_max_fom = s.dvl.max_fom_mps if s else 0.05
        self.gnss_max_depth = _or(c.gnss_max_depth_m, s.depth.surface_depth_m if s else 0.3)

        self.filter = EsesoFilter(filter_params(c, s))
        # numba's cache loaded now, not in the service's first ticks
        warm_kernels(self.filter.params)
        self.counters = EsesoCounters()
        self.frame: LocalFrame | None = None
        self._gnss_offset = np.zeros(2)
        self.t_imu: float | None = None
        self.f_m: Array | None = None  # last specific force (m/s^2)
        self.w_m: Array | None = None  # last angular rate (rad/s)
        self.tau: Array | None = None  # last commanded body force (N)
        self.t_tau = -math.inf
        self._tau_source = ""  # source of the last thruster command
        self._tau_hist: list[tuple[float, Array]] = []  # (t, body force) of held commands
        self._t_tau_fused = -math.inf  # time (s) of the newest command a thrust update used
        self._imu_hist: list[tuple[float, Array, Array]] = []  # last IMU (t, f, w), <= 2
        self.t_sensor: float | None = None
        self._pending_depth: float | None = None
        self._pending_att: Array | None = None
        self._accel_sum = np.zeros(3)
        self._accel_n = 0
        self._t_att_yaw = -math.inf  # time (s) of the newest Attitude with its yaw
        self._t_aided: float | None = None  # newest position/velocity sample (s)
        self._t_zupt = -math.inf  # newest zero-velocity update (s)
        self._cmd_max = 0.0  # largest |command| of the newest thruster command

    @property
    def frame_offset(self) -> tuple[float, float]:
        """Where the local frame's origin (the first fused fix) lies in the published
        position (north, east; m): the position the filter had reached then."""
        return float(self._gnss_offset[0]), float(self._gnss_offset[1])

    @property
    def initialized(self) -> bool:
        """True once the filter has started (it has an attitude)."""
        return self.filter.initialized

    def _unused(self, s: Sample, channel: str, dof: int, reason: str) -> None:
        """Record the sample as a measurement of ``channel`` rejected for ``reason``
        before any update (its innovation unknown)."""
        self.filter.innovations.append(unused_measurement(channel, s.t, dof, reason,
                                                          s.source))

    def _initialize(self, R0: Array, yaw_std_rad: float | None = None) -> None:
        """Start the filter at attitude ``R0``, at the configured start point and the last
        depth received."""
        start = self.cfg.initial
        depth = self._pending_depth if self._pending_depth is not None else 0.0
        self.filter.initialize(R0, np.array([start.north_m, start.east_m, depth]),
                               yaw_std_rad)

    # ------------------------------------------------------------------ thrust
    def _tau_mean(self, t0: float, t1: float) -> Array | None:
        """Time average (N, body) over [t0, t1] of the held thruster commands."""
        hist = self._tau_hist
        if not hist or t1 - hist[-1][0] > self.cfg.thrusters.command_timeout_s:
            return None
        if t1 <= t0:
            return hist[-1][1]
        first = len(hist) - 1  # the command held at t0; those before it ended by then
        while first > 0 and hist[first][0] > t0:
            first -= 1
        acc = np.zeros(3)
        covered = 0.0
        for i in range(first, len(hist)):
            tc, tau = hist[i]
            start = max(tc, t0)
            end = min(hist[i + 1][0], t1) if i + 1 < len(hist) else t1
            if end > start:
                acc += tau * (end - start)
                covered += end - start
        if covered <= 0.0:
            return hist[-1][1]
        return acc / covered

    def _thrust_update_at_imu(self) -> None:
        """The thrust update for the IMU sample just received when a thruster command
        arrived since the last one (module docstring)."""
        hist = self._imu_hist
        if len(hist) < 2:
            return
        (t0, _, w0), (t1, f1, w1) = hist[-2:]
        tau = self._tau_mean(t0, t1)
        if tau is None:
            return
        self._t_tau_fused = self._tau_hist[-1][0]
        outcome = self.filter.update_thrust(f1, w1, (w1 - w0) / (t1 - t0), tau,
                                            wdot_dt=t1 - t0, t=t1, source=self._tau_source)
        if self.filter.downweighted:
            self.counters.downweighted()
        self.counters.update("thrust", outcome)

    # ------------------------------------------------------------------ samples
    def _on_imu(self, s: Imu) -> None:
        accel, gyro = (s.accel_x, s.accel_y, s.accel_z), (s.gyro_x, s.gyro_y, s.gyro_z)
        if not all(map(math.isfinite, accel + gyro)):  # floats: cheaper than numpy's
            self.counters.rejected("imu", "nonfinite")
            return
        f_m, w_m = np.array(accel), np.array(gyro)
        if not self.filter.initialized:
            if self._pending_att is not None:
                self._initialize(self._pending_att)
            elif not self._level_from_gravity(f_m):
                self.t_imu = s.t
                return
            self.t_imu = s.t
            self.f_m, self.w_m = f_m, w_m
            return
        if self.t_imu is None:
            self.t_imu = s.t
        dt = s.t - self.t_imu
        if dt <= 0.0:
            self.counters.rejected("imu", "time")
            return
        if dt > self.cfg.max_imu_gap_s:
            self.counters.imu_gap()
            dt = self.cfg.max_imu_gap_s
        self.filter.propagate(f_m, w_m, dt)
        self.t_imu = s.t
        self.f_m, self.w_m = f_m, w_m
        self._imu_hist.append((s.t, f_m, w_m))
        if len(self._imu_hist) > IMU_HISTORY:
            del self._imu_hist[0]
        if self._tau_hist and self._tau_hist[-1][0] > self._t_tau_fused:  # a new command
            self._thrust_update_at_imu()
        self._zero_velocity(s.t)

    def _zero_velocity(self, t: float) -> None:
        """The zero-velocity update at ``t`` (s) when due (module docstring)."""
        if self._t_aided is None:
            self._t_aided = t  # the filter's start: count the silence from here
        if t - self._t_aided < ZUPT_AFTER_S or t - self._t_zupt < ZUPT_INTERVAL_S:
            return
        fresh = t - self.t_tau <= self.cfg.thrusters.command_timeout_s
        if fresh and self._cmd_max > ZUPT_IDLE_COMMAND:
            return
        self._t_zupt = t
        self.counters.update("zupt", self.filter.update_zero_velocity(ZUPT_STD_MPS ** 2, t=t))

    def _level_from_gravity(self, f_m: Array) -> bool:
        """Average the specific force ``f_m`` (m/s^2) of :data:`LEVELLING_SAMPLES` IMU
        samples; then start the filter levelled from it (``g`` points down in body axes:
        roll ``atan2(a_y, a_z)``, pitch ``atan2(-a_x, hypot(a_y, a_z))``), yaw unknown
        (std pi). Returns whether the filter started."""
        self._accel_sum += f_m
        self._accel_n += 1
        if self._accel_n < LEVELLING_SAMPLES:
            return False
        a = -self._accel_sum / self._accel_n  # points down in body axes
        roll = math.atan2(a[1], a[2])
        pitch = math.atan2(-a[0], math.hypot(a[1], a[2]))
        self._initialize(euler_to_matrix(roll, pitch, 0.0), yaw_std_rad=math.pi)
        return True

    def _on_command(self, s: ActuatorCommand) -> None:
        if s.thrusters is None:
            return
        n = self.K_alloc.shape[1]
        if len(s.thrusters) != n:
            self.counters.rejected("command", "thruster_count")
            return
        thrusters = self.cfg.thrusters
        forces = [thruster_force(float(cmd), thrusters) for cmd in s.thrusters]
        if not all(map(math.isfinite, forces)):  # floats: cheaper than numpy's
            self.counters.rejected("command", "nonfinite")
            return
        self.tau = self.K_alloc @ np.array(forces)
        self._cmd_max = max((abs(float(c)) for c in s.thrusters), default=0.0)
        self.t_tau = s.t
        self._tau_source = s.source
        self._tau_hist.append((s.t, self.tau))
        # keep what the last IMU intervals can still need
        while len(self._tau_hist) > 2 and self._tau_hist[1][0] <= s.t - COMMAND_HISTORY_S:
            del self._tau_hist[0]
        if len(self._tau_hist) > COMMAND_HISTORY_MAX:
            del self._tau_hist[0]

    def _on_gnss(self, s: GnssFix) -> None:
        if s.fix_quality <= 0:
            self.counters.rejected("gnss", "no_fix")
            return
        f = self.filter
        if f.p[2] > self.gnss_max_depth and f.P[P_D, P_D] < 1.0:
            self.counters.rejected("gnss", "submerged")
            self._unused(s, "gnss_pos", 2, "submerged")
            if s.sog_mps is not None and s.cog_rad is not None:
                self._unused(s, "gnss_vel", 2, "submerged")
            return
        self._t_aided = s.t
        if self.frame is None:
            self.frame = LocalFrame(s.lat_deg, s.lon_deg)
            self._gnss_offset = f.p[:2].copy()
        n, e = self.frame.to_ne(s.lat_deg, s.lon_deg)
        z = np.array([n, e]) + self._gnss_offset
        r_p = max(s.h_acc_m, GNSS_H_ACC_FLOOR_M) ** 2 if s.h_acc_m else self.r_gnss_p
        self.counters.update("gnss_pos", f.update_position_ne(z, r_p, t=s.t, source=s.source))
        if s.sog_mps is not None and s.cog_rad is not None:
            vz = s.sog_mps * np.array([math.cos(s.cog_rad), math.sin(s.cog_rad)])
            self.counters.update("gnss_vel", f.update_velocity_ne(
                vz, self.r_gnss_v, t=s.t, source=s.source))

    def _on_vog(self, s: VelocityOverGround) -> None:
        vz = np.array([s.v_north_mps, s.v_east_mps])
        if not np.all(np.isfinite(vz)):
            self.counters.rejected("vog", "nonfinite")
            self._unused(s, "vog", 2, "nonfinite")
            return
        self._t_aided = s.t
        self.counters.update("vog", self.filter.update_ins_velocity(
            vz, self.r_ins, t=s.t, source=s.source))

    def _on_depth(self, s: Depth) -> None:
        self.counters.update("depth", self.filter.update_depth(
            s.depth_m, self.r_depth, t=s.t, source=s.source))

    def _on_dvl(self, s: DvlVelocity) -> None:
        if not s.valid:
            self.counters.rejected("dvl", "invalid")
            self._unused(s, "dvl", 3, "invalid")
            return
        if s.track != "bottom":
            self.counters.rejected("dvl", "water_track")
            return
        if s.fom_mps is not None and s.fom_mps > self.dvl_max_fom:
            self.counters.rejected("dvl", "fom")
            self._unused(s, "dvl", 3, "fom")
            return
        self._t_aided = s.t
        r = max(s.fom_mps, DVL_FOM_FLOOR_MPS) ** 2 if s.fom_mps else self.r_dvl
        self.counters.update("dvl", self.filter.update_body_velocity(
            np.array([s.vx, s.vy, s.vz]), r, t=s.t, source=s.source))

    def _on_attitude(self, s: Attitude) -> None:
        """Roll, pitch and yaw; the yaw with the variance ``YAW_UNSELECTED_VAR`` (no
        information) when the source selector chose another heading source."""
        R_meas = euler_to_matrix(s.roll_rad, s.pitch_rad, s.yaw_rad)
        self.counters.update("attitude", self.filter.update_attitude(
            R_meas, s.roll_rad, s.pitch_rad, self.r_att,
            self.r_att_yaw if s.yaw_selected else YAW_UNSELECTED_VAR, t=s.t, source=s.source))

    def _on_heading(self, s: Heading) -> None:
        meas = s.heading_rad
        self.counters.update("heading", self.filter.update_heading(
            meas, self.r_head, t=s.t, source=s.source))

    # ------------------------------------------------------------------ Pipeline API
    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        """Consume the samples (time-ordered) and return the estimates at tick ``t`` (s).

        IMU samples propagate the state (the first after a new, fresh thruster command
        triggers the thrust update); every other supported sample is one measurement
        update.
        """
        for s in samples:
            if isinstance(s, Imu):
                self._on_imu(s)
            elif isinstance(s, ActuatorCommand):
                self._on_command(s)
            elif not self.filter.initialized:
                if isinstance(s, Attitude):
                    self._pending_att = euler_to_matrix(s.roll_rad, s.pitch_rad, s.yaw_rad)
                elif isinstance(s, Depth):
                    self._pending_depth = s.depth_m
                continue
            elif isinstance(s, GnssFix):
                self._on_gnss(s)
            elif isinstance(s, VelocityOverGround):
                self._on_vog(s)
            elif isinstance(s, Depth):
                self._on_depth(s)
            elif isinstance(s, DvlVelocity):
                self._on_dvl(s)
            elif isinstance(s, Attitude):
                if s.yaw_selected:
                    self._t_att_yaw = s.t
                self._on_attitude(s)
            elif isinstance(s, Heading):
                if s.t - self._t_att_yaw <= HEADING_HOLD_S:
                    continue  # an AHRS reports the same yaw: do not count it twice
                self._on_heading(s)
            else:
                continue
            self.t_sensor = s.t
        f = self.filter
        if not f.initialized:
            return {}
        if not f.finite():
            self.counters.diverged()
            self.__init__(self.cfg, self._sensors)  # type: ignore[misc]
            return {}
        return self.estimates()

    def estimates(self) -> dict[str, float]:
        """The current estimates by column name (SI, NED/FRD, rad); where the filter runs
        its compiled kernels, the same values (to rounding) in one call of
        :func:`onboard.estimators.eseso_kernel.estimates`."""
        f = self.filter
        w_m = self.w_m if self.w_m is not None else np.zeros(3)
        if f.compiled:
            # imported here: a process whose filter does not compile never imports numba
            from onboard.estimators import eseso_kernel
            return dict(zip(self.columns, eseso_kernel.estimates(
                f.x, f.P, w_m, f.disturbance_excess, PUBLISHED_VAR_MIN_SHARE).tolist()))
        RT = f.R.T
        nu = RT @ f.v
        xi_e = f.R @ f.xi
        d = np.sqrt(np.maximum(f.P.diagonal()[P_], 0.0))
        # body-velocity std: R^T P_vv R
        P_nu = RT @ f.P[V_, V_] @ f.R
        s_nu = np.sqrt(np.maximum(P_nu.diagonal(), 0.0))
        w = w_m - f.b_g
        vals = np.concatenate((
            f.p, f.v, nu, matrix_to_euler(f.R), w, f.xi, xi_e,
            d, s_nu, self._disturbance_std(), f.b_a, f.b_g, f.g[2:]))
        return dict(zip(self.columns, vals.tolist()))

    def _disturbance_std(self) -> Array:
        """One-sigma (N, body) of the lumped disturbance ``xi`` (the external force plus
        whatever the model gets wrong, module docstring): the filter's covariance plus
        the excess its thrust innovations show
        (:meth:`~onboard.estimators.eseso_filter.EsesoFilter.published_disturbance_var`)."""
        return np.sqrt(self.filter.published_disturbance_var())

    def std(self) -> dict[str, float]:
        """One-sigma uncertainties keyed like the values (``std_<q>`` columns -> ``<q>``),
        as the engine fills ``EstimateRecord.std``."""
        return {k[4:]: v for k, v in self.estimates().items() if k.startswith("std_")}

    def record(self, vehicle: str, t: float) -> EstimateRecord:
        """The published estimate record of this pipeline at tick ``t``."""
        ready = self.filter.initialized
        return EstimateRecord(vehicle=vehicle, pipeline=self.name, t=t,
                              values=self.estimates() if ready else {},
                              std=self.std() if ready else {},
                              t_sensor=self.t_sensor)

    def innovations(self) -> list[Innovation]:
        """The records of the updates since the last call (module docstring,
        "Innovations")."""
        pending = self.filter.innovations
        out = list(pending)
        pending.clear()
        return out

    def health(self) -> EsesoHealth:
        """The event counts (:class:`EsesoCounters`: ``fused.<channel>``,
        ``rejected.<channel>.gate``, ``recovered.<channel>``, ``thrust.downweighted``,
        ``rejected.<stream>.<reason>`` of the sample handling, ``imu_gap``, ``diverged``)
        and the noise scales the filter learnt from its innovations."""
        f = self.filter
        return EsesoHealth(self.counters.as_dict(), dict(f.noise_scale), f.process_scale)

    def get_state(self) -> dict[str, Any]:
        """Sensor biases, gravity and the disturbance (worth keeping across a restart)."""
        f = self.filter
        return {"b_a": f.b_a.tolist(), "b_g": f.b_g.tolist(),
                "g": f.g.tolist(), "xi": f.xi.tolist()}

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore ``b_a``, ``b_g``, ``g`` and ``xi`` (3 finite numbers each); ignore the
        rest."""
        for key in ("b_a", "b_g", "g", "xi"):
            val = state.get(key)
            if isinstance(val, (list, tuple)) and len(val) == 3:
                try:
                    arr = np.array([float(x) for x in val])
                except (TypeError, ValueError):
                    continue
                if np.all(np.isfinite(arr)):
                    setattr(self.filter, key, arr)


def create(cfg: Config) -> Eseso | None:
    """The ESESO for a BlueROV2-class vehicle, or for any vehicle whose config sets
    ``[pipelines.eseso] enabled = true``."""
    c = cfg.pipelines.eseso
    if c.enabled is False:
        return None
    if cfg.vehicle.vehicle_class not in c.vehicle_classes and c.enabled is not True:
        return None
    return Eseso(c, cfg.sensors)
