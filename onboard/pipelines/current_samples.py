"""The current pipeline's samples: model inputs, attitude and velocity measurements
(algorithms.md §3.5, the measurement table; docs/current.md, "Attitude").

:class:`CurrentSamples` turns the samples of one tick into

* the velocity measurements in time order, each handed over
  (:meth:`CurrentSamples.measurements`) once every other sample stamped at or before it
  has been taken in, so that the inputs and the attitude are those of the measurement's
  own time, not the tick's (the heading carried to that time by the yaw rate,
  :meth:`CurrentSamples.rotation_at`; algorithms.md §3.5, "Measurements at their own
  time");
* the model inputs (:class:`.vehicle_models.ModelInputs`: rates, attitude, commands);
* the attitude in use: roll and pitch from the newest ``Attitude`` sample stamped at or
  before the step time (``DvlPosition``'s as a fallback); the heading of the velocity's
  own navigation solution (``VelocityOverGround.heading_rad``, GLOBAL_POSITION_INT's
  ``hdg``) while it comes, else from ``Attitude`` (when the source selector chose it) or
  ``Heading`` (true north). A DVL-aided INS resolves its velocity in its own heading, so
  rotating the through-water velocity by that heading keeps the two in one frame: another
  heading (an AHRS's magnetic yaw a few degrees off) would put speed times the difference
  into the current (docs/current.md, "Heading");
* the velocity measurements (:class:`.current_kf.VelocityMeasurement`): GNSS SOG/COG and
  ``VelocityOverGround`` in earth axes, DVL bottom and water track in body axes, each with
  its one-sigma (m/s) from ``[sensors]`` (a GNSS fix's reported accuracy scales its own).
* with a glider model (``[pipelines.current.glider]``), the glider's through-water
  velocity from its pitch, depth rate (consecutive ``Depth`` samples) and pump volume
  (``ActuatorCommand.pump_cc``), as a water-track measurement (body axes, source
  :data:`GLIDER_SOURCE`) at each new depth rate, with the model's one-sigma of the
  horizontal speed (:meth:`.vehicle_models.GliderModel.glide_from_depth_rate`); none
  where the model cannot give the speed (an inflection, a shallow glide).

Rejected samples are counted in its own :class:`SampleCounters`; a rejected velocity is
also an innovation record of its channel (:data:`CHANNELS`) with reason ``nonfinite`` or
``invalid`` and no innovation.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from mypy_extensions import mypyc_attr
import numpy as np

from onboard.core.geo import wrap_pi
from onboard.core.messages import (
    ActuatorCommand,
    Attitude,
    Depth,
    DvlPosition,
    DvlVelocity,
    GnssFix,
    Heading,
    Imu,
    Innovation,
    Sample,
    VelocityOverGround,
)
from onboard.core.so3 import euler_to_matrix
from onboard.estimators.current_kf import MeasurementKind, VelocityMeasurement
from onboard.estimators.vehicle_models import GliderModel, ModelInputs
from onboard.pipelines.base import unused_measurement

ATTITUDE_FALLBACK_S = 1.0
"""A ``DvlPosition`` roll/pitch is used only this long (s) after the last ``Attitude``
sample: the vehicle's attitude reference comes first."""
VELOCITY_HEADING_HOLD_S = 1.0
"""While a velocity sample brought its solution's heading within this long (s), the yaws
of ``Attitude`` and ``Heading`` samples are not used (ten periods of a 10 Hz INS; when it
stops, the selected heading source takes over)."""
YAW_RATE_LOWPASS_S = 0.3
"""Without measured rates, the yaw rate is the heading's difference quotient through a
first-order low-pass of this time constant (s)."""
YAW_RATE_MIN_INTERVAL_S = 1e-3
"""Headings closer than this (s) give no difference quotient."""
YAW_CARRY_MAX_S = 0.2
"""Longest time (s) the heading is carried forward by the yaw rate to a measurement's
time (:meth:`CurrentSamples.rotation_at`): two periods of a 10 Hz compass; an older
heading is used as it is."""
ATTITUDE_HELD_MAX = 64
"""Attitude samples stamped after the step time that are held for later ticks (the newest
are kept)."""
GLIDER_SOURCE = "glider_model"
"""The source of the glider model's water-track measurements."""
CHANNELS = {"earth": "velocity", "bottom": "dvl", "water": "water_track"}
"""The innovation channel of each velocity measurement kind: ``velocity`` over ground in
earth axes (GNSS SOG/COG, ``VelocityOverGround``), ``dvl`` bottom track and
``water_track`` (body axes)."""


def glider_model(g: Any) -> GliderModel:
    """The steady-glide model of a ``[pipelines.current.glider]`` table
    (:class:`onboard.core.pipeline_config.GliderModelConfig`)."""
    return GliderModel(
        k_l=g.lift_kl, k_l0=g.lift_kl0, k_d0=g.drag_kd0, k_d=g.drag_kd,
        density=g.water_density_kgm3, neutral_pump_cc=g.neutral_pump_cc,
        vertical_water_std=g.vertical_water_std_mps, gamma_std=g.glide_angle_std_rad,
        min_glide=g.min_glide_angle_rad)


@mypyc_attr(allow_interpreted_subclasses=True)
@dataclass
class SampleCounters:
    """What :class:`CurrentSamples` counted."""

    rejected_invalid_dvl: int = 0
    """DVL velocities flagged invalid or beyond the largest figure of merit."""
    rejected_nonfinite: int = 0
    """Samples with a value that is not finite."""
    glider_measurements: int = 0
    """Through-water velocities of the glider model."""
    gnss_without_velocity: int = 0
    """GNSS fixes without a speed and course over ground (a GGA-only receiver or logger),
    which give the current no velocity."""


@mypyc_attr(allow_interpreted_subclasses=True)
class CurrentSamples:
    """Samples to model inputs, attitude and velocity measurements (module docstring).

    Attributes:
        inp: the model inputs (:class:`.ModelInputs`), updated in place.
        roll, pitch: the attitude in use (rad, ZYX Euler, FRD/NED).
        yaw: the heading (rad; None before the first).
        depth: the newest depth (m; None before the first).
        gnss_std: one-sigma of GNSS velocity (m/s) at the receiver's nominal accuracy
            ``gnss_nominal_acc`` (m).
        gnss_std_used: the velocity one-sigma (m/s) of the newest fused GNSS fix.
        dvl_std: one-sigma of DVL velocity (m/s); ``dvl_max_fom`` the largest figure of
            merit accepted (m/s).
        surface_depth: GNSS is used only at most this deep (m).
        counters: its counts (:class:`SampleCounters`).
        innovations: the owner's pending innovation records (rejected velocities go in).
        yaw_t, yaw_source: time (s) and sample source of the heading in use.
    """

    def __init__(self, cfg: Any, sensors: Any, nd: int,
                 innovations: deque[Innovation]) -> None:
        """Args:
            cfg: the ``[pipelines.current]`` section (``rpm_scale`` and the one-sigmas
                ``gnss_velocity_std_mps``, ``gnss_nominal_accuracy_m``, ``dvl_velocity_std_mps``).
            sensors: the ``[sensors]`` section (defaults of those, DVL figure of merit,
                surface depth).
            nd: velocity dimension of the model (2 surface, 3 underwater).
            innovations: the records of rejected velocities are appended here.
        """
        self.nd = nd
        self.counters = SampleCounters()
        self.innovations = innovations
        self.rpm_scale = cfg.rpm_scale
        self.gnss_std = cfg.gnss_velocity_std_mps or sensors.gnss.velocity_std_mps
        self.gnss_nominal_acc = (cfg.gnss_nominal_accuracy_m
                                 if cfg.gnss_nominal_accuracy_m is not None
                                 else sensors.gnss.position_std_m)
        self.gnss_std_used = self.gnss_std
        self.dvl_std = cfg.dvl_velocity_std_mps or sensors.dvl.velocity_std_mps
        self.dvl_max_fom = sensors.dvl.max_fom_mps
        self.surface_depth = sensors.depth.surface_depth_m
        self.inp = ModelInputs()
        # roll and pitch (rad) for the rotation R and the model's gravity/buoyancy
        # regressors (``inp.roll``, ``inp.pitch``): the newest attitude stamped at or
        # before the step time (:meth:`_set_attitude`)
        self.roll = self.pitch = 0.0
        self._att_t = -math.inf  # stamp of the attitude in use
        self._ahrs_t = -math.inf  # stamp of the newest Attitude sample
        self._att_later: list[tuple[float, float, float, bool]] = []  # stamped after a tick
        self._step_t = math.inf
        self.yaw: float | None = None
        self.yaw_t = math.nan
        self.yaw_source = ""
        self._vel_heading_t = -math.inf  # stamp of the newest velocity's own heading
        self._have_rates = False
        self._yaw_prev: tuple[float, float] | None = None
        self.depth: float | None = None
        self._init_glider(cfg)
        # sample handlers by exact class (the sample classes have no subclasses); the
        # class's functions, not methods bound to this object, so that a copy of it
        # (the GNSS latency's fork) handles its samples itself
        cls = CurrentSamples
        self._handlers: dict[type, Callable[[CurrentSamples, Any, list], None]] = {
            Attitude: cls._on_attitude, Heading: cls._on_heading, Imu: cls._on_imu,
            ActuatorCommand: cls._on_command, Depth: cls._on_depth,
            VelocityOverGround: cls._on_vog, DvlVelocity: cls._on_dvl,
            DvlPosition: cls._on_dvl_position, GnssFix: cls._on_gnss}

    def _init_glider(self, cfg: Any) -> None:
        """The glider model of ``cfg.glider`` (None without) and its inputs: the pump
        volume (cm^3), the previous depth sample, the pending depth rate, the time of the
        model's last measurement (``glider_t``, s)."""
        g = cfg.glider
        self.glider: GliderModel | None = None if g is None else glider_model(g)
        self.glider_max_dt = g.max_depth_interval_s if g is not None else 0.0
        self.pump_cc: float | None = None
        self._depth_prev: tuple[float, float] | None = None
        self._depth_rate: tuple[float, float] | None = None  # (t, m/s) not yet used
        self.glider_t = -math.inf

    def measurements(self, t: float, samples: Sequence[Sample]
                     ) -> Iterator[VelocityMeasurement]:
        """Take the tick's samples (time-ordered, up to the step time ``t``, s) into the
        model inputs and the attitude, yielding each velocity measurement among them when
        every sample stamped at or before it has been taken and none after it: while the
        caller holds a measurement, :attr:`inp`, the attitude and :meth:`rotation_at` are
        those of its time. Run it to the end: then the tick's samples are all taken."""
        handlers = self._handlers
        self._step_t = t
        if self._att_later:  # attitude stamped after an earlier tick, now due
            due = sorted(a for a in self._att_later if a[0] <= t)
            if due:
                self._att_later = [a for a in self._att_later if a[0] > t]
                for a in due:
                    self._set_attitude(*a)
        pending: list[VelocityMeasurement] = []  # stamped at the newest time taken
        for s in samples:
            if pending and s.t > pending[0].t:
                yield from pending
                pending.clear()
            h = handlers.get(type(s))
            if h is not None:
                h(self, s, pending)
        if self._depth_rate is not None:  # the glider model's measurement of this tick
            self._glide(pending)
        yield from pending

    def _glide(self, meas: list) -> None:
        """The glider model's through-water velocity at the pending depth rate, the pitch
        in use and the newest pump volume (neutral if none came), as a water-track
        measurement."""
        glider = self.glider
        assert glider is not None and self._depth_rate is not None
        tr, rate = self._depth_rate
        self._depth_rate = None
        pump = self.pump_cc if self.pump_cc is not None else glider.neutral_pump_cc
        g = glider.glide_from_depth_rate(self.pitch, rate, pump)
        if g is None:
            return
        u, v, w = g.body_velocity(self.pitch)
        z = [u, v, w] if self.nd == 3 else [g.u_h, 0.0]
        self.glider_t = tr
        self.counters.glider_measurements += 1
        meas.append(VelocityMeasurement("water", tr, np.array(z), g.std_u_h, GLIDER_SOURCE))

    def _on_attitude(self, s: Attitude, meas: list) -> None:
        if not (math.isfinite(s.roll_rad) and math.isfinite(s.pitch_rad)
                and math.isfinite(s.yaw_rad)):
            self.counters.rejected_nonfinite += 1
            return
        self._set_attitude(s.t, s.roll_rad, s.pitch_rad, True)
        # yaw_selected False: the source selector chose another heading source
        if s.yaw_selected and not self._velocity_heading_fresh(s.t):
            self._set_yaw(s.t, s.yaw_rad, s.source)
        if s.yaw_rate_rps is not None:
            self.inp.p = s.roll_rate_rps or 0.0
            self.inp.q = s.pitch_rate_rps or 0.0
            self.inp.r = s.yaw_rate_rps
            self._have_rates = True

    def _on_dvl_position(self, s: DvlPosition, meas: list) -> None:
        """The DVL's own roll and pitch: a fallback when no ``Attitude`` sample came
        within ``ATTITUDE_FALLBACK_S`` (its yaw is not used: heading sources are
        ``Attitude`` and ``Heading``)."""
        if s.roll_rad is None or s.pitch_rad is None:
            return
        if not (math.isfinite(s.roll_rad) and math.isfinite(s.pitch_rad)):
            self.counters.rejected_nonfinite += 1
            return
        self._set_attitude(s.t, s.roll_rad, s.pitch_rad, False)

    def _set_attitude(self, t: float, roll: float, pitch: float, primary: bool) -> None:
        """Take roll and pitch (rad, ZYX Euler, FRD/NED: pitch positive nose up, roll
        positive starboard down) stamped ``t`` if it is the newest at or before the step
        time; a sample stamped after the step time is held until a step reaches it."""
        if t > self._step_t:
            if len(self._att_later) >= ATTITUDE_HELD_MAX:  # far ahead of the ticks
                del self._att_later[0]
            self._att_later.append((t, roll, pitch, primary))
            return
        if primary:
            self._ahrs_t = max(self._ahrs_t, t)
        elif t - self._ahrs_t <= ATTITUDE_FALLBACK_S:
            return
        if t < self._att_t:
            return
        self._att_t = t
        self.roll = self.inp.roll = roll
        self.pitch = self.inp.pitch = pitch

    def _on_heading(self, s: Heading, meas: list) -> None:
        if not math.isfinite(s.heading_rad):
            self.counters.rejected_nonfinite += 1
            return
        if self._velocity_heading_fresh(s.t):
            return
        self._set_yaw(s.t, s.heading_rad, s.source)

    def _velocity_heading_fresh(self, t: float) -> bool:
        """Whether a velocity sample brought its own heading within
        ``VELOCITY_HEADING_HOLD_S`` of time ``t`` (s): that heading is the one in use."""
        return t - self._vel_heading_t <= VELOCITY_HEADING_HOLD_S

    def _on_imu(self, s: Imu, meas: list) -> None:
        if math.isfinite(s.gyro_z):
            self.inp.p, self.inp.q, self.inp.r = s.gyro_x, s.gyro_y, s.gyro_z
            self._have_rates = True

    def _on_command(self, s: ActuatorCommand, meas: list) -> None:
        x = self.inp
        if s.propeller_rpm is not None:
            x.n = s.propeller_rpm / self.rpm_scale
        elif s.throttle is not None:
            x.n = s.throttle
        if s.rudder_rad is not None:
            x.dr = s.rudder_rad
        if s.stern_plane_rad is not None:
            x.ds = s.stern_plane_rad
        if s.left is not None:
            x.left = s.left
        if s.right is not None:
            x.right = s.right
        if s.thrusters is not None:
            x.thrusters = s.thrusters
        if s.pump_cc is not None:
            self.pump_cc = s.pump_cc

    def _on_depth(self, s: Depth, meas: list) -> None:
        self.depth = s.depth_m
        if self.glider is None or not math.isfinite(s.depth_m):
            return
        prev, self._depth_prev = self._depth_prev, (s.t, s.depth_m)
        if prev is not None and 0.0 < s.t - prev[0] <= self.glider_max_dt:
            self._depth_rate = (s.t, (s.depth_m - prev[1]) / (s.t - prev[0]))

    def _on_vog(self, s: VelocityOverGround, meas: list) -> None:
        z = [s.v_north_mps, s.v_east_mps] + ([s.v_down_mps] if (
            self.nd == 3 and s.v_down_mps is not None) else [])
        if not all(math.isfinite(v) for v in z):
            self.counters.rejected_nonfinite += 1
            self._reject(s, "earth", len(z), "nonfinite")
            return
        psi = s.heading_rad
        if psi is not None and math.isfinite(psi):  # the frame of this velocity
            self._set_yaw(s.t, psi, s.source)
            self._vel_heading_t = max(self._vel_heading_t, s.t)
        meas.append(VelocityMeasurement("earth", s.t, np.array(z), self.dvl_std, s.source))

    def _on_dvl(self, s: DvlVelocity, meas: list) -> None:
        kind: MeasurementKind = "bottom" if s.track == "bottom" else "water"
        if not s.valid or (s.fom_mps is not None and s.fom_mps > self.dvl_max_fom):
            self.counters.rejected_invalid_dvl += 1
            self._reject(s, kind, self.nd, "invalid")
            return
        z = [s.vx, s.vy, s.vz][: self.nd]
        if not all(math.isfinite(v) for v in z):
            self.counters.rejected_nonfinite += 1
            self._reject(s, kind, self.nd, "nonfinite")
            return
        std = max(self.dvl_std, s.fom_mps or 0.0)
        meas.append(VelocityMeasurement(kind, s.t, np.array(z), std, s.source))

    def _on_gnss(self, s: GnssFix, meas: list) -> None:
        if s.sog_mps is None or s.cog_rad is None or s.fix_quality == 0:
            if s.fix_quality != 0:
                self.counters.gnss_without_velocity += 1
            return
        if self.depth is not None and self.depth > self.surface_depth:
            return
        if not (math.isfinite(s.sog_mps) and math.isfinite(s.cog_rad)):
            self.counters.rejected_nonfinite += 1
            self._reject(s, "earth", 2, "nonfinite")
            return
        z = np.array([s.sog_mps * math.cos(s.cog_rad), s.sog_mps * math.sin(s.cog_rad)])
        std = self.gnss_std
        sacc, acc, nominal = s.speed_acc_mps, s.h_acc_m, self.gnss_nominal_acc
        if nominal > 0 and sacc is not None and math.isfinite(sacc) and sacc > 0:
            std = max(std, sacc)  # the receiver's speed accuracy, down-weighting only
        elif nominal > 0 and acc is not None and math.isfinite(acc) and acc > 0:
            std *= max(1.0, acc / nominal)  # its position accuracy as a proxy
        self.gnss_std_used = std
        meas.append(VelocityMeasurement("earth", s.t, z, std, s.source))

    def _reject(self, s: Sample, kind: str, dof: int, reason: str) -> None:
        """Record a velocity sample that cannot be used as a rejected measurement of its
        channel (the caller counts it)."""
        self.innovations.append(unused_measurement(CHANNELS[kind], s.t, dof, reason,
                                                   s.source))

    def _set_yaw(self, t: float, yaw: float, source: str) -> None:
        """Take the heading (rad) of time ``t`` (s) from ``source``; without measured
        rates, the yaw rate follows its difference quotient (a 0.3 s low-pass)."""
        if not self._have_rates and self._yaw_prev is not None:
            t0, y0 = self._yaw_prev
            if t - t0 > YAW_RATE_MIN_INTERVAL_S:
                r = wrap_pi(yaw - y0) / (t - t0)
                self.inp.r += min(1.0, (t - t0) / YAW_RATE_LOWPASS_S) * (r - self.inp.r)
        self._yaw_prev = (t, yaw)
        self.yaw = yaw
        self.yaw_t, self.yaw_source = t, source

    def rotation(self) -> np.ndarray:
        """Body-to-earth rotation at the attitude in use (the yaw alone for a surface
        vehicle's 2-D model)."""
        return self._rotation(self.yaw or 0.0)

    def rotation_at(self, t: float) -> np.ndarray:
        """Body-to-earth rotation at time ``t`` (s, at or after the attitude in use): the
        heading carried from its own time by the yaw rate in use, ``psi + r (t - t_psi)``
        (at most ``YAW_CARRY_MAX_S``; roll and pitch as they are)."""
        yaw = self.yaw or 0.0
        lag = t - self.yaw_t
        if 0.0 < lag <= YAW_CARRY_MAX_S:
            yaw += self.inp.r * lag
        return self._rotation(yaw)

    def _rotation(self, yaw: float) -> np.ndarray:
        """Body-to-earth rotation at the roll and pitch in use and heading ``yaw`` (rad)."""
        if self.nd == 3:
            return euler_to_matrix(self.roll, self.pitch, yaw)
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([[c, -s], [s, c]])
