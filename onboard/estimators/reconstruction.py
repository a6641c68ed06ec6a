"""The track reconstruction of algorithms.md §2.11 and the estimates it gives at a tick.

The seed paper (Faros & Tanner 2025, §3.3) rebuilds the track from the two axis filters'
increments: the heading from the heading filter's (:class:`~onboard.estimators.track.
HeadingTrack`), the position from the surge filter's path increments laid along the
mid-step heading (:class:`~onboard.estimators.track.PositionTrack`, with the anchor toward
the GNSS point). :class:`TrackReconstruction` holds both, and what the published estimates
between steps need:

* the estimates at a tick: heading and yaw rate predicted from the last heading step with
  the model and the newest command; speed and position predicted from the last surge step
  the same way, or blended with the accelerometer's path acceleration (``imu_aiding``,
  :mod:`onboard.estimators.path_accel`) by the weight their misses of the Doppler speed
  give; one sigma of each (:func:`~onboard.estimators.track.position_std`; the speed's
  scaled by the surge filter's consistency factor, apart from its gain,
  :meth:`~onboard.estimators.increment_filter.IncrementFilter.published_rate_factor`);
* dead reckoning through a GNSS outage longer than ``max_gap_s``
  (:class:`~onboard.estimators.dead_reckoning.DeadReckoner`);
* course mode (no heading source at all): the path along the course over ground.
"""

from __future__ import annotations

import math

from mypy_extensions import mypyc_attr

from onboard.core.geo import wrap_2pi
from onboard.estimators.axis_model import Discretization
from onboard.estimators.dead_reckoning import DeadReckoner
from onboard.estimators.increment_filter import IncrementFilter
from onboard.estimators.measurement_points import CommandHistory, clamp
from onboard.estimators.path_accel import ForecastBlend, PathAccelerometer
from onboard.estimators.track import HeadingTrack, PositionTrack, position_std

SHORTEST_PREDICTION_S = 1e-6
"""A prediction over less time than this (s) is none."""
COURSE_POINTS = 4
"""Points whose baseline gives the course over ground in course mode (§1.3)."""

Point = tuple[float, float, float, float]
"""A surge measurement point: time (s), north, east (m), heading (rad; NaN without one)."""


@mypyc_attr(allow_interpreted_subclasses=True)
class TrackReconstruction:
    """The reconstructed track (§2.11) of a surge and a heading filter, and its estimates.

    Attributes:
        heading, position: the reconstructed heading and position.
        course, var_course: the course over ground (rad) of course mode and its variance
            (None and 0 outside course mode).
        dr: the dead reckoning since the last surge step (None while fixes come).
        imu: the accelerometer's path acceleration (None without ``imu_aiding``);
            blend: the weight of its speed forecast against the model's.
        psi_s: the heading at the last surge step (rad), cached for the estimates; None
            when stale (:meth:`invalidate`).
    """

    def __init__(self, surge: IncrementFilter, yaw: IncrementFilter, commands: CommandHistory,
                 *, var_fix: float, var_heading0: float, max_gap_s: float,
                 imu_aiding: bool, imu_horizon_s: float) -> None:
        """Args:
            surge, yaw: the axis filters whose increments build the track.
            commands: the command history the predictions take the newest command from.
            var_fix: the fix's slowly varying error (m^2), added to every position.
            var_heading0: the heading's variance before the first point (rad^2).
            max_gap_s: longest prediction (s) from a step; beyond it an outage.
            imu_aiding: forecast the speed with the accelerometer too.
            imu_horizon_s: longest forecast (s) made with the accelerometer.
        """
        self.surge, self.yaw, self.commands = surge, yaw, commands
        self.var_fix = var_fix
        self.max_gap_s = max_gap_s
        self.imu_horizon_s = imu_horizon_s
        self.heading = HeadingTrack(var_heading0)
        self.position = PositionTrack()
        self.disc = Discretization()
        self.course: float | None = None
        self._course_pts: list[tuple[float, float]] = []
        self.var_course = 0.0
        self.psi_s: float | None = None
        self.dr: DeadReckoner | None = None
        self._psi_dr = 0.0                   # heading (rad) at the dead reckoning's time
        self.imu = PathAccelerometer() if imu_aiding else None
        self.blend = ForecastBlend()

    def fix_arrived(self) -> None:
        """A window with a fix closed: the dead reckoning, if any, ends."""
        self.dr = None

    def invalidate(self) -> None:
        """The cached heading at the last surge step is stale (a window closed, a command
        arrived, a model changed)."""
        self.psi_s = None

    def heading_at(self, t: float) -> float:
        """The reconstructed heading (rad, unwrapped) predicted to time ``t`` (s)."""
        h, yaw = self.heading, self.yaw
        assert h.psi is not None and h.t is not None
        tau = min(max(t - h.t, 0.0), self.max_gap_s)
        if not yaw.kf.initialized or tau <= SHORTEST_PREDICTION_S:
            return h.psi
        dpsi, _ = yaw.kf.predict_ahead(self.disc(yaw.damping(yaw.last_command), tau),
                                       yaw.input_ahead(self.commands.latest(2)))
        return h.psi + dpsi

    def restart_position(self, pp: Point | None, tp: float, n: float, e: float, R_s: float,
                         R_s_prev: float) -> None:
        """The first point, or the first after a gap: the position starts at the point,
        or follows the measured displacement across the gap (both points' noise)."""
        if not self.position.have or pp is None:
            self.position.restart(tp, n, e, R_s)
        else:
            self.position.follow(tp, n - pp[1], e - pp[2], R_s + R_s_prev)

    def surge_step(self, pp: Point, point: Point, R_s: float, anchor: float,
                   course_mode: bool, dpsi: float) -> None:
        """After the surge filter's step from ``pp`` to ``point``: the position along the
        mid-step heading (the course in course mode), then the anchor toward the point of
        noise variance ``R_s`` (m^2) with gain ``anchor`` (§2.11)."""
        tp, n, e, _ = point
        if course_mode:
            mid, var_mid = self.course, self.var_course
        else:
            mid, var_mid = self.mid_heading(pp, tp, dpsi), self.heading.var
        surge = self.surge
        self.position.step(tp, surge.kf.d, mid, surge.kf.P[0], var_mid,  # type: ignore
                           (n, e), R_s, anchor)

    def course_increment(self, n: float, e: float, pp: Point, R_s: float) -> float:
        """Course mode: the displacement projected on the course over ground of the last
        :data:`COURSE_POINTS` points (unbiased; astern motion is not detectable), whose
        variance from two points of variance ``R_s`` over the baseline ``L`` is ``2 R_s /
        L^2``."""
        hist = self._course_pts
        hist.append((n, e))
        if len(hist) > COURSE_POINTS:
            del hist[0]
        n0, e0 = hist[0]
        course = math.atan2(e - e0, n - n0) if len(hist) > 1 else 0.0
        base2 = (n - n0) ** 2 + (e - e0) ** 2
        self.var_course = min(2.0 * R_s / base2, 1.0) if base2 > 0.0 else 1.0
        self.course = course
        return math.cos(course) * (n - pp[1]) + math.sin(course) * (e - pp[2])

    def mid_heading(self, pp: Point, tp: float, dpsi: float) -> float:
        """The reconstructed heading (rad) in the middle of the step from ``pp[0]`` to
        ``tp``, the mean of its two ends (the measured one before any reconstruction)."""
        if self.heading.psi is None or self.heading.t is None:
            return pp[3] + 0.5 * dpsi
        self._psi_dr = self.heading_at(tp)
        return 0.5 * (self.heading_at(pp[0]) + self._psi_dr)

    def learn_imu_forecast(self, t_prev: float, tp: float, v_prev: float, y_v: float) -> None:
        """The model's and the accelerometer's forecasts of the speed at ``tp`` against
        the measured one (the blend's weight), and the accelerometer's bias from the
        filter's speed change over the step."""
        imu = self.imu
        assert imu is not None
        acc = imu.delta(t_prev, tp)
        rz = self.surge.rate_z
        if acc is not None and rz is not None:
            self.blend.add(rz, v_prev + acc[0] - y_v)
        imu.update_bias(t_prev, tp, self.surge.kf.v - v_prev)

    def dead_reckon(self, t_end: float) -> None:
        """Advance the dead reckoning to ``t_end`` (s) through a window without a fix
        (:class:`DeadReckoner`): the surge filter's speed and input along the heading
        track. Started at the last surge step; published once the gap exceeds
        ``max_gap_s``; dropped at the next fix."""
        surge, pos, h = self.surge, self.position, self.heading
        if not surge.kf.initialized or pos.t is None or h.psi is None or h.t is None:
            return
        dr = self.dr
        if dr is None:
            dr = self.dr = DeadReckoner(
                pos.t, pos.n, pos.e, surge.kf.v, surge.kf.P[3], pos.var_n, pos.var_e,
                math.sqrt(surge.speed_bias_var()), math.sqrt(h.var))
        dt = t_end - dr.t
        if dt <= SHORTEST_PREDICTION_S:
            return
        cmd = self.commands.mean(dr.t, t_end, 1)
        psi1 = self.heading_at(t_end)
        dr.advance(self.disc(surge.damping(cmd), dt), surge.input_ahead(cmd),
                   0.5 * (self._psi_dr + psi1), surge.V_u)
        self._psi_dr = psi1

    def estimates(self, t: float) -> dict[str, float]:
        """The estimates at ``t`` (s), predicted from the last steps with the newest
        command: heading first, then speed and position from the track, from the dead
        reckoning through an outage, or the held position before the filter runs."""
        out: dict[str, float] = {}
        if self.heading.psi is None:   # no heading source (yet)
            self._course_output(out, t)
            return out
        psi, var_h = self._heading_output(out, t)
        pos = self.position
        if self.dr is not None and pos.t is not None and t - pos.t > self.max_gap_s:
            self._dr_output(out, t, psi, var_h)
        elif self.surge.kf.initialized and pos.t is not None:
            self._track_output(out, t, psi, var_h)
        elif pos.have:
            out["north"], out["east"] = pos.n, pos.e
            out["std_north"] = math.sqrt(pos.var_n + self.var_fix)
            out["std_east"] = math.sqrt(pos.var_e + self.var_fix)
        return out

    def _heading_output(self, out: dict[str, float], t: float) -> tuple[float, float]:
        """Heading, yaw rate and heading sigma predicted to ``t``; returns the heading
        (rad, unwrapped) and its variance (rad^2)."""
        h, yaw = self.heading, self.yaw
        psi, var_h = h.psi, h.var
        assert psi is not None and h.t is not None
        if yaw.kf.initialized:
            tau = clamp(t - h.t, 0.0, self.max_gap_s)
            r = yaw.kf.v
            if tau > SHORTEST_PREDICTION_S:
                k = self.disc(yaw.damping(yaw.last_command), tau)
                dpsi, r = yaw.kf.predict_ahead(k, yaw.input_ahead(self.commands.latest(2)))
                psi = psi + dpsi
                var_h += k.c1 * k.c1 * yaw.kf.P[3] + k.c2 * k.c2 * yaw.forecast_var_u
            out["heading"] = wrap_2pi(psi)
            out["yaw_rate"] = r
        else:
            out["heading"] = wrap_2pi(psi)
        out["std_heading"] = math.sqrt(var_h)
        return psi, var_h

    def _track_output(self, out: dict[str, float], t: float, psi: float,
                      var_h: float) -> None:
        """Speed and position predicted from the last surge step to ``t`` along the mean
        of the headings at both ends, with their sigmas (:func:`position_std`, plus the
        displacement not followed beyond ``max_gap_s``)."""
        surge, pos = self.surge, self.position
        t_s = pos.t
        assert t_s is not None
        skf = surge.kf
        tau_raw = t - t_s
        tau = clamp(tau_raw, 0.0, self.max_gap_s)
        ds, v = skf.v * tau, skf.v
        var_ds, var_v = skf.P[3] * tau * tau, skf.P[3]
        if tau > SHORTEST_PREDICTION_S:
            k = self.disc(surge.damping(surge.last_command), tau)
            ds, v = skf.predict_ahead(k, surge.input_ahead(self.commands.latest(1)))
            var_ds = k.c1 * k.c1 * skf.P[3] + k.c2 * k.c2 * surge.V_u
            var_v = k.alpha * k.alpha * skf.P[3] + k.c1 * k.c1 * surge.V_u
            ds, v, var_ds, var_v = self._imu_forecast(t_s, t, tau, tau_raw, ds, v, var_ds,
                                                      var_v)
        out["speed"] = v
        if self.psi_s is None:
            self.psi_s = self.heading_at(t_s)
        mid = 0.5 * (self.psi_s + psi)
        c, s = math.cos(mid), math.sin(mid)
        out["north"] = pos.n + ds * c
        out["east"] = pos.e + ds * s
        out["std_north"], out["std_east"] = position_std(
            pos.var_n, pos.var_e, c, s, var_ds, ds * ds * var_h,
            self._held_var(tau_raw, v, var_v))
        out["std_speed"] = math.sqrt(var_v * surge.published_rate_factor())

    def _imu_forecast(self, t_s: float, t: float, tau: float, tau_raw: float, ds: float,
                      v: float, var_ds: float, var_v: float
                      ) -> tuple[float, float, float, float]:
        """The model's forecast of path, speed and their variances over ``tau`` (s)
        blended with the accelerometer's (``v_s tau + int int a``, ``v_s + int a``, its
        bias variance integrated) by the learned weight, within ``imu_horizon_s``."""
        imu, wi = self.imu, self.blend.w
        if imu is None or wi <= 0.0 or tau_raw > self.imu_horizon_s:
            return ds, v, var_ds, var_v
        acc = imu.delta(t_s, t)
        if acc is None:
            return ds, v, var_ds, var_v
        wm = 1.0 - wi
        V_a = imu.bias_var
        skf = self.surge.kf
        P_vv = skf.P[3]
        return (wm * ds + wi * (skf.v * tau + acc[1]),
                wm * v + wi * (skf.v + acc[0]),
                wm * var_ds + wi * tau * tau * (P_vv + 0.25 * tau * tau * V_a),
                wm * var_v + wi * (P_vv + tau * tau * V_a))

    def _held_var(self, tau_raw: float, v: float, var_v: float) -> float:
        """The variance (m^2, per axis) added to a published position ``tau_raw`` (s)
        after the last surge step: the fix's ``sigma_p^2``, and beyond ``max_gap_s``,
        where the position is held while the vehicle moves on, ``(v^2 + var(v)) ex^2 /
        2`` for the time ``ex`` past it (direction unknown: conservative for a vehicle
        that turns back)."""
        ex = tau_raw - self.max_gap_s
        return self.var_fix + (0.5 * (v * v + var_v) * ex * ex if ex > 0.0 else 0.0)

    def _dr_output(self, out: dict[str, float], t: float, psi: float, var_h: float) -> None:
        """Speed, position and their sigmas from the dead reckoning (a GNSS gap longer
        than ``max_gap_s``), predicted from its time to ``t`` with the newest command."""
        dr, surge = self.dr, self.surge
        assert dr is not None
        tau = t - dr.t
        u = surge.input_ahead(self.commands.latest(1))
        ds, v, var_ds, var_v = 0.0, dr.v, 0.0, dr.p_vv
        if tau > SHORTEST_PREDICTION_S:
            k = self.disc(surge.damping(surge.last_command), tau)
            ds, v = k.c1 * dr.v + k.c2 * u, k.alpha * dr.v + k.c1 * u
            var_ds = k.c1 * k.c1 * dr.p_vv + k.c2 * k.c2 * surge.V_u
            var_v = k.alpha * k.alpha * dr.p_vv + k.c1 * k.c1 * surge.V_u
        mid = 0.5 * (self._psi_dr + psi)
        c, s = math.cos(mid), math.sin(mid)
        vn, ve = dr.variances()
        out["speed"] = v
        out["north"] = dr.n + ds * c
        out["east"] = dr.e + ds * s
        out["std_north"], out["std_east"] = position_std(vn, ve, c, s, var_ds,
                                                         ds * ds * var_h, self.var_fix)
        out["std_speed"] = math.sqrt(var_v)

    def _course_output(self, out: dict[str, float], t: float) -> None:
        """Course mode (no heading source): speed and position predicted along the
        course over ground, with their sigmas."""
        surge, pos, course = self.surge, self.position, self.course
        if course is None or not surge.kf.initialized or pos.t is None:
            return
        tau_raw = t - pos.t
        tau = max(clamp(tau_raw, 0.0, self.max_gap_s), SHORTEST_PREDICTION_S)
        k = self.disc(surge.damping(surge.last_command), tau)
        ds, v = surge.kf.predict_ahead(k, surge.input_ahead(self.commands.latest(1)))
        c, s = math.cos(course), math.sin(course)
        out["speed"] = v
        out["north"] = pos.n + ds * c
        out["east"] = pos.e + ds * s
        P_vv, V_u = surge.kf.P[3], surge.V_u
        var_v = k.alpha * k.alpha * P_vv + k.c1 * k.c1 * V_u
        out["std_north"], out["std_east"] = position_std(
            pos.var_n, pos.var_e, c, s, k.c1 * k.c1 * P_vv + k.c2 * k.c2 * V_u,
            ds * ds * self.var_course, self._held_var(tau_raw, v, var_v))
        out["std_speed"] = math.sqrt(var_v * surge.published_rate_factor())
