"""A log as aligned arrays of measured channels, for model closure.

The log is read by the same readers and engine as ``onboard replay`` (validation, input
mapping, surface/submerged gating); a collector pipeline samples the newest value of every
channel at each engine tick. Velocity over ground comes from, in order of preference, an
INS/DVL navigation solution (VelocityOverGround), the receiver's Doppler SOG/COG, or, in a
log with neither, the GNSS positions differenced (:func:`fix_velocity`).

Derived channels, all at the tick rate ``1/dt``:

* ``psi``: measured heading (rad, unwrapped), from the compass or the autopilot attitude;
* ``along``, ``lateral``: velocity over ground projected on the measured heading (m/s),
  ``along = cos(psi) v_n + sin(psi) v_e``, ``lateral = -sin(psi) v_n + cos(psi) v_e``;
* ``r``: yaw rate (rad/s) from the gyro (an IMU's, else an attitude's body rate: ATTITUDE
  ``yawspeed``, a CSV ``yaw_rate`` column) where the log has one, else from the heading;
* ``psi_dot``: time derivative of the measured heading (rad/s);
* ``cmd_surge``, ``cmd_yaw``: normalized commands (throttle and rudder, or the mean and
  half-difference of a skid-steered boat's thrusters);
* ``run``: run label (a directory of CSV runs), used to split fit and held-out data;
* ``u_model``: with a glider's base model, its through-water speed along the heading from
  the steady glide (:func:`glide_speed`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.signal import savgol_filter

from onboard.drivers.base import shortfall
from onboard.drivers.logs import open_log
from onboard.core.config import Config
from onboard.core.geo import LocalFrame
from onboard.core.messages import (
    ActuatorCommand,
    Attitude,
    Depth,
    DvlVelocity,
    GnssFix,
    Heading,
    Imu,
    Sample,
    VelocityOverGround,
)
from onboard.engine import Engine, run
from onboard.engine.inputs import column_names
from onboard.pipelines.base import NoHealth, PipelineDefaults
from onboard.pipelines.current_samples import glider_model


class NotEnoughData(ValueError):
    """The log lacks what model closure needs (a heading, a velocity over ground, enough
    time with both): ``onboard diagnose`` refuses it with one line naming what is
    missing (exit status 2)."""


MIN_TICKS = 50
"""Fewest ticks with both a heading and a velocity over ground :func:`from_log` builds a
dataset of (5 s at the default 10 Hz: the smoothed derivatives need a window)."""

MIN_DATA_S = 50.0
"""Least data (s with both a heading and a velocity over ground) model closure works on:
the test part is the last fifth, and each part needs
:data:`onboard.offline.closure.select.MIN_PART_S` (10 s). Shorter logs are refused with this
figure, by :func:`from_log` below :data:`MIN_TICKS` and by the split above it."""


MIN_YAW_RATE_HZ = 1.0
"""Fewest yaw-rate samples per second (Hz) that are taken as the gyro: rarer ones are spot
values of a rate that changes faster than they come, which integrate to no heading change
(the Kolumbo glider's ``r`` column, one value per 8 s row: its integral over each row
against the heading change correlates at 0.00, the glider yawing back and forth within
the row). Such a log is diagnosed with the rate from its heading, like one without."""


class _Collector(PipelineDefaults):
    """A pipeline that records the newest measured value of each channel per tick."""

    name = "collect"
    columns = ()

    def __init__(self) -> None:
        self.rows: list[tuple] = []
        self.frame: LocalFrame | None = None
        self.heading = math.nan
        self.heading_src_compass = False
        self.gyro_sum = 0.0
        self.gyro_n = 0
        self.gyro_last = math.nan
        self.acc_sum = [0.0, 0.0]
        self.acc_last = (math.nan, math.nan)
        self.vn = self.ve = math.nan
        self.vog_t = -math.inf
        self.gnss_vn = self.gnss_ve = math.nan
        self.north = self.east = math.nan
        self.fix_t = -math.inf
        self.cmd_surge = self.cmd_yaw = self.cmd_quad = self.cmd_rev = math.nan
        self.cmd_left = self.cmd_right = math.nan
        self.run = ""
        self.has_imu = False
        self.has_rate = False
        """A yaw rate of any kind came: an IMU's gyro or an attitude's body rate."""
        self.rate_n = 0
        self.rate_t0 = self.rate_t1 = math.nan
        """How many yaw-rate samples came, the first's and the newest's time (s)."""
        self.fixes: list[tuple[float, float, float]] = []
        """Every fix as (t, north, east) (s, m, m): the velocity of a log without one."""
        self.pitch = self.pump = math.nan
        self.depths: list[tuple[float, float]] = []
        """Every depth sample as (t, depth) (s, m): a glider's depth rate."""
        self.raw: dict[str, list[tuple[float, ...]]] = {
            "heading": [], "attitude_yaw": [], "gnss_velocity": [], "dvl": [],
            "gnss_accuracy": []}
        """Every measurement as it came, for the noise identification
        (:mod:`onboard.offline.closure.noise`): headings (t, rad), GNSS velocities (t,
        north, east; m/s), attitude yaws (t, rad), DVL bottom-track velocities (t, vx, vy; m/s) and the fixes'
        reported accuracies (t, m)."""

    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        for s in samples:
            if isinstance(s, Heading):
                self.heading_src_compass = True
                self.heading = s.heading_rad
                self.raw["heading"].append((s.t, s.heading_rad))
            elif isinstance(s, Attitude):
                if not self.heading_src_compass:
                    self.heading = s.yaw_rad
                if s.yaw_selected:
                    self.raw["attitude_yaw"].append((s.t, s.yaw_rad))
                self.pitch = s.pitch_rad
                if s.yaw_rate_rps is not None:
                    self.has_rate = True
                    self._count_rate(s.t)
                    if not self.has_imu:
                        self.gyro_last = s.yaw_rate_rps
            elif isinstance(s, Imu):
                self.has_imu = self.has_rate = True
                self._count_rate(s.t)
                self.gyro_sum += s.gyro_z
                self.gyro_n += 1
                self.acc_sum[0] += s.accel_x
                self.acc_sum[1] += s.accel_y
            elif isinstance(s, GnssFix):
                if self.frame is None:
                    self.frame = LocalFrame(s.lat_deg, s.lon_deg)
                self.north, self.east = self.frame.to_ne(s.lat_deg, s.lon_deg)
                self.fix_t = s.t
                self.fixes.append((s.t, self.north, self.east))
                if s.sog_mps is not None and s.cog_rad is not None:
                    self.gnss_vn = s.sog_mps * math.cos(s.cog_rad)
                    self.gnss_ve = s.sog_mps * math.sin(s.cog_rad)
                    self.raw["gnss_velocity"].append((s.t, self.gnss_vn, self.gnss_ve))
                if s.h_acc_m is not None and math.isfinite(s.h_acc_m):
                    self.raw["gnss_accuracy"].append((s.t, s.h_acc_m))
                if s.source.startswith("csv:"):
                    self.run = s.source
            elif isinstance(s, VelocityOverGround):
                self.vn, self.ve, self.vog_t = s.v_north_mps, s.v_east_mps, s.t
                if s.source.startswith("csv:"):
                    self.run = s.source
            elif isinstance(s, Depth):
                self.depths.append((s.t, s.depth_m))
            elif isinstance(s, DvlVelocity):
                if s.track == "bottom" and s.valid:
                    self.raw["dvl"].append((s.t, s.vx, s.vy))
            elif isinstance(s, ActuatorCommand):
                if s.pump_cc is not None:
                    self.pump = s.pump_cc
                if s.throttle is not None:
                    self.cmd_surge = s.throttle
                    self.cmd_quad = s.throttle * abs(s.throttle)
                    self.cmd_rev = min(s.throttle, 0.0)
                    self.cmd_yaw = s.rudder_rad if s.rudder_rad is not None else math.nan
                elif s.left is not None and s.right is not None:
                    self.cmd_surge = 0.5 * (s.left + s.right)
                    self.cmd_yaw = 0.5 * (s.left - s.right)
                    self.cmd_quad = 0.5 * (s.left * abs(s.left) + s.right * abs(s.right))
                    self.cmd_rev = 0.5 * (min(s.left, 0.0) + min(s.right, 0.0))
                    self.cmd_left, self.cmd_right = s.left, s.right
        if self.gyro_n:
            self.gyro_last = self.gyro_sum / self.gyro_n
            self.acc_last = (self.acc_sum[0] / self.gyro_n, self.acc_sum[1] / self.gyro_n)
            self.gyro_sum, self.gyro_n = 0.0, 0
            self.acc_sum = [0.0, 0.0]
        vog_fresh = t - self.vog_t < 1.0
        self.rows.append((
            t, self.heading, self.gyro_last,
            self.vn if vog_fresh else self.gnss_vn, self.ve if vog_fresh else self.gnss_ve,
            self.north, self.east, self.fix_t, self.cmd_surge, self.cmd_yaw, self.cmd_quad,
            self.cmd_rev, self.run, self.cmd_left, self.cmd_right, *self.acc_last,
            self.pitch, self.pump,
        ))
        return {}

    def _count_rate(self, t: float) -> None:
        self.rate_n += 1
        self.rate_t1 = t
        if self.rate_n == 1:
            self.rate_t0 = t

    def yaw_rate_hz(self) -> float:
        """The mean rate (Hz) of the yaw-rate samples (0 with fewer than two)."""
        span = self.rate_t1 - self.rate_t0 if self.rate_n > 1 else 0.0
        return (self.rate_n - 1) / span if span > 0 else 0.0

    def innovations(self) -> list:
        return []

    def health(self) -> NoHealth:
        return NoHealth()

    def get_state(self) -> dict[str, Any]:
        return {}

    def set_state(self, state: Mapping[str, Any]) -> None:
        return None


@dataclass
class Dataset:
    """Aligned measured channels of one log (see the module docstring)."""

    t: np.ndarray
    dt: float
    psi: np.ndarray
    r: np.ndarray
    psi_dot: np.ndarray
    v_n: np.ndarray
    v_e: np.ndarray
    along: np.ndarray
    lateral: np.ndarray
    speed_dot: np.ndarray
    along_s: np.ndarray
    """The along-track speed smoothed like its derivative ``speed_dot`` (m/s)."""
    cmd_surge: np.ndarray
    cmd_yaw: np.ndarray
    thrust_quadratic: np.ndarray
    """Mean of c|c| over the propulsors (c|c| for one, (l|l| + r|r|)/2 for two)."""
    thrust_reverse: np.ndarray
    """Mean of min(c, 0) over the propulsors (the astern part of the command)."""
    run: np.ndarray
    north: np.ndarray
    east: np.ndarray
    has_gyro: bool
    has_commands: bool
    source: str = ""
    cmd_left: np.ndarray | None = None
    """A skid-steered boat's two thruster commands as logged (normalized), else None."""
    cmd_right: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    warnings: list = field(default_factory=list)
    """The engine's warnings while reading the log (``onboard.core.messages.Alert``: time
    outliers and jumps, ...)."""
    actuator_lag_s: float = 0.0
    """Time constant (s) of the first-order lag already applied to the command channels
    (:func:`lag_commands`); 0 for the commands as logged."""
    base_terms: tuple[str, ...] = ()
    """The optional terms of the base model in use (:data:`BASE_TERMS`); set by
    :func:`with_base_terms`, :data:`DEFAULT_BASE_TERMS` unless set."""
    acc_x: np.ndarray | None = None
    """The IMU's forward specific force (m/s^2, body frame, mean over each tick), else
    None."""
    acc_y: np.ndarray | None = None
    """The IMU's starboard specific force (m/s^2), else None."""
    u_model: np.ndarray | None = None
    """The through-water speed along the heading (m/s) that the vehicle class's model
    gives from what it measures (a glider's steady glide: :func:`glide_speed`; NaN where
    it gives none), the along-track channel's base prediction; None for a boat, whose
    speed the surge model predicts from the commands."""
    base_model: str = "surface-boat"
    """The base model the data are for (:mod:`onboard.offline.closure.base_models`)."""
    yaw_rate_hz: float = 0.0
    raw: dict = field(default_factory=dict)
    """The log's measurements as they came (channel -> rows; ``_Collector.raw`` and the
    fixes as (t, north, east)), for :mod:`onboard.offline.closure.noise`."""
    """How often the log's yaw rate came (Hz; 0 without one); below
    :data:`MIN_YAW_RATE_HZ` it is not taken as the gyro (``has_gyro`` false)."""

    def __post_init__(self) -> None:
        if not self.base_terms:
            self.base_terms = DEFAULT_BASE_TERMS

    def __len__(self) -> int:
        return len(self.t)

    def subset(self, mask: np.ndarray) -> "Dataset":
        """The ticks where the boolean ``mask`` (one entry per tick) is true; per-tick
        arrays are indexed, everything else is kept as it is."""
        kw = {}
        for name in self.__dataclass_fields__:
            v = getattr(self, name)
            kw[name] = v[mask] if isinstance(v, np.ndarray) and v.shape[:1] == self.t.shape else v
        return Dataset(**kw)


BASE_TERMS = ("actuator_lag", "course_lag", "speed_drift")
"""The base model's optional terms: ``actuator_lag``, the shaft lag of the commands
(:func:`onboard.offline.closure.model.estimate_actuator_lag`); ``course_lag``, the sway's lag
behind the turn rate (``x_pd r'``); ``speed_drift``, the sway that scales with speed times
yaw rate and its lag (``k_ur U r + k_urd (U r)'``, a hull whose sway damping does not grow
with speed). The hull's sway per yaw rate ``x_p r`` is always in. Default:
:data:`DEFAULT_BASE_TERMS`."""

DEFAULT_BASE_TERMS = ("actuator_lag", "course_lag")
"""The terms used unless asked otherwise. ``speed_drift`` is not among them: to first
order it is what a GNSS latency does in turns (``-tau U r``), so with it a latency shows
only in transients; on a hull without such drift (the synthetic hull, the BlueBoat runs)
it costs a true latency its held-out gain and weakens other findings
(docs/diagnose.md)."""

NO_BASE_TERMS = ("none",)
"""The value of :func:`with_base_terms` for none of :data:`BASE_TERMS` (an empty tuple
means all)."""


def with_base_terms(ds: "Dataset", terms: Sequence[str]) -> "Dataset":
    """``ds`` marked to be fitted with the base model's optional ``terms`` only (names from
    :data:`BASE_TERMS`; empty for :data:`DEFAULT_BASE_TERMS`; ``NO_BASE_TERMS``,
    ``["none"]``, for none, to show what the terms do). An unknown name is a
    ValueError."""
    terms = tuple(terms)
    unknown = [t for t in terms if t not in BASE_TERMS + NO_BASE_TERMS]
    if unknown or (NO_BASE_TERMS[0] in terms and len(terms) > 1):
        raise ValueError(f"unknown base model term(s) {unknown or list(terms)}; known: "
                         f"{', '.join(BASE_TERMS)} (or 'none' alone)")
    return Dataset(**{**vars(ds), "base_terms": terms or DEFAULT_BASE_TERMS})


def lateral_base_names(ds: "Dataset") -> tuple[str, ...]:
    """The base model's lateral coefficients in use on ``ds``: ``x_p`` (m, sway per yaw
    rate), ``x_pd`` (m s, its course lag), ``k_ur`` (s, sway per speed times yaw rate) and
    ``k_urd`` (s^2, its lag), as :data:`BASE_TERMS` switches them."""
    names = ["x_p"]
    if "course_lag" in ds.base_terms:
        names.append("x_pd")
    if "speed_drift" in ds.base_terms:
        names += ["k_ur", "k_urd"]
    return tuple(names)


def lateral_base_columns(ds: "Dataset") -> np.ndarray:
    """The base model's lateral regressors (m/s per coefficient of
    :func:`lateral_base_names`): ``r``, ``r'``, ``U r``, ``(U r)'``.

    A hull's sway in turns follows ``T_v v' + v = x_p r - k U r`` (a sway damping
    ``Y_v`` that does not grow with speed: ``k = m11 / Y_v``, ``T_v = m22 / Y_v``,
    Fossen 2021 eq. 6.26 linearized); to first order in ``T_v`` the sway is
    ``x_p r - T_v x_p r' - k U r + k T_v (U r)'``, the four columns."""
    names = lateral_base_names(ds)
    cols = [ds.r]
    if "x_pd" in names:
        cols.append(yaw_accel(ds))
    if "k_ur" in names:
        ur = np.nan_to_num(ds.along_s) * ds.r
        cols += [ur, _smooth(ur, max(5, int(round(1.0 / ds.dt)) | 1), 1, ds.dt)]
    return np.column_stack(cols)


def acceleration_delay_cost(ds: "Dataset", taus: np.ndarray,
                            smooth_s: float = 1.0) -> np.ndarray | None:
    """For each candidate GNSS delay in ``taus`` (s), the mean square (m^2/s^4) of the
    acceleration over ground from the GNSS velocity taken that much later, minus the
    IMU's horizontal specific force rotated to north/east by the measured heading (a
    constant body-frame accelerometer bias fitted out); None without an accelerometer.

    The accelerometer and the compass are prompt and need no model of the hull: in turns
    the centripetal acceleration turns with the heading and a late GNSS velocity turns
    behind it, in speed changes it answers late. Both accelerations are smoothed alike
    (Savitzky-Golay over ``smooth_s``, within each segment); a level vehicle is assumed
    (roll and pitch leak gravity into the horizontal axes)."""
    if ds.acc_x is None or ds.acc_y is None or len(ds) < 100:
        return None
    win = max(5, int(round(smooth_s / ds.dt)) | 1)
    s0 = segment_starts(ds)
    starts = np.flatnonzero(s0 == np.arange(len(ds)))
    ends = np.r_[starts[1:], len(ds)]
    gn, ge = np.empty(len(ds)), np.empty(len(ds))
    fx, fy = np.empty(len(ds)), np.empty(len(ds))
    for a, b in zip(starts, ends):
        gn[a:b] = _smooth(ds.v_n[a:b], win, 1, ds.dt)
        ge[a:b] = _smooth(ds.v_e[a:b], win, 1, ds.dt)
        fx[a:b] = _smooth(ds.acc_x[a:b], win, 0, ds.dt)
        fy[a:b] = _smooth(ds.acc_y[a:b], win, 0, ds.dt)
    c, s = np.cos(ds.psi), np.sin(ds.psi)
    imu_n, imu_e = c * fx - s * fy, s * fx + c * fy
    out = []
    for tau in taus:
        k = int(round(float(tau) / ds.dt))
        i = np.concatenate([np.arange(a, b - k) for a, b in zip(starts, ends) if b - a > k]
                           or [np.zeros(0, int)])
        if len(i) < 50:
            out.append(np.inf)
            continue
        y = np.r_[gn[i + k] - imu_n[i], ge[i + k] - imu_e[i]]
        X = np.r_[np.column_stack([c[i], -s[i]]), np.column_stack([s[i], c[i]])]
        ok = np.isfinite(y) & np.isfinite(X).all(axis=1)
        coef, *_ = np.linalg.lstsq(X[ok], y[ok], rcond=None)
        out.append(float(np.mean((y[ok] - X[ok] @ coef) ** 2)))
    return np.asarray(out)


def concat(parts: Sequence["Dataset"]) -> "Dataset":
    """The datasets one after the other (per-tick arrays joined, the rest from the first).
    Their run labels keep the parts' segments apart: give adjacent parts different labels."""
    first = parts[0]
    kw = {}
    for name in first.__dataclass_fields__:
        v = getattr(first, name)
        if isinstance(v, np.ndarray) and v.shape[:1] == first.t.shape:
            kw[name] = np.concatenate([getattr(p, name) for p in parts])
        else:
            kw[name] = v
    return Dataset(**kw)


def segment_starts(ds: "Dataset") -> np.ndarray:
    """For each tick, the index of the first tick of its contiguous segment (run label)."""
    n = len(ds)
    if n == 0:
        return np.zeros(0, int)
    change = np.r_[True, ds.run[1:] != ds.run[:-1]]
    starts = np.flatnonzero(change)
    return starts[np.cumsum(change) - 1]


def heading_drift(ds: "Dataset") -> np.ndarray:
    """Measured heading change minus the integrated gyro yaw rate since the start of each
    segment (rad). Zero for a perfect compass and gyro; ``-b (t - t0)`` for a gyro bias
    ``b``; ``delta(psi) - delta(psi0)`` for a compass deviation ``delta``. Integrating
    keeps the compass's quantization (1 deg in VFR_HUD) from swamping a small rate bias."""
    s0 = segment_starts(ds)
    inc = np.r_[0.0, 0.5 * (ds.r[1:] + ds.r[:-1]) * np.diff(ds.t)]
    cum = np.cumsum(inc)
    return (ds.psi - ds.psi[s0]) - (cum - cum[s0])


LAGGED_COMMANDS = ("cmd_surge", "cmd_yaw", "thrust_quadratic", "thrust_reverse", "cmd_left",
                   "cmd_right")
"""The command channels :func:`lag_commands` filters."""


def first_order_lag(ds: "Dataset", x: np.ndarray, tau: float) -> np.ndarray:
    """``x`` through the first-order lag ``y' = (x - y) / tau`` (s), exact for a held
    input over each tick and restarted at ``x`` at the start of each segment (the
    actuator is taken as settled there). NaN inputs hold the filter."""
    x = np.asarray(x, float)
    if tau <= 0.0 or len(x) == 0:
        return x.copy()
    alpha = 1.0 - math.exp(-ds.dt / tau)
    s0 = segment_starts(ds)
    out = np.empty_like(x)
    xs, starts = x.tolist(), (s0 == np.arange(len(x))).tolist()
    y = math.nan
    for i, xi in enumerate(xs):
        if starts[i] or not math.isfinite(y):
            y = xi
        elif math.isfinite(xi):
            y += alpha * (xi - y)
        out[i] = y
    return out


def lag_commands(ds: "Dataset", tau: float) -> "Dataset":
    """``ds`` with every command channel through a first-order lag of ``tau`` seconds
    (:func:`first_order_lag`): the propeller's shaft speed, hence its thrust, follows the
    command with the motor's spin-up lag (algorithms.md §1.1 reads the surge input as the
    applied thrust). Lagging the commanded thrust terms ``c``, ``c|c|`` and ``min(c, 0)``
    one by one equals lagging any linear thrust law made of them."""
    if tau <= 0.0:
        return ds
    kw = dict(vars(ds))
    for name in LAGGED_COMMANDS:
        v = kw[name]
        if v is not None:
            kw[name] = first_order_lag(ds, v, tau)
    kw["actuator_lag_s"] = ds.actuator_lag_s + tau
    return Dataset(**kw)


def yaw_accel(ds: "Dataset", smooth_s: float = 1.0) -> np.ndarray:
    """Yaw acceleration r' (rad/s^2): the smoothed derivative of the yaw rate."""
    if len(ds) < 3:
        return np.zeros(len(ds))
    win = max(5, int(round(smooth_s / ds.dt)) | 1)
    return _smooth(np.asarray(ds.r, float), win, 1, ds.dt)


def _smooth(x: np.ndarray, window: int, deriv: int = 0, dt: float = 1.0) -> np.ndarray:
    if len(x) < window:
        return np.gradient(x, dt) if deriv else x.copy()
    return savgol_filter(x, window, 2, deriv=deriv, delta=dt, mode="interp")


def from_arrays(t, psi, v_n, v_e, *, r=None, cmd_surge=None, cmd_yaw=None,
                thrust_quadratic=None, thrust_reverse=None, run=None,
                north=None, east=None, smooth_s: float = 1.0, source: str = "",
                cmd_left=None, cmd_right=None, acc_x=None, acc_y=None, u_model=None,
                base_model: str = "surface-boat") -> Dataset:
    """Build a dataset from uniformly sampled arrays (SI units, heading in rad);
    ``acc_x``, ``acc_y`` the IMU's horizontal specific force (body frame), if any;
    ``u_model`` and ``base_model`` as the :class:`Dataset` fields."""
    t = np.asarray(t, float)
    n = len(t)
    dt = float(np.median(np.diff(t))) if n > 1 else 0.1
    psi = np.unwrap(np.asarray(psi, float))
    win = max(5, int(round(smooth_s / dt)) | 1)
    psi_dot = _smooth(psi, win, 1, dt)
    has_gyro = r is not None and np.isfinite(r).all()
    r = np.asarray(r, float) if has_gyro else psi_dot
    v_n = np.asarray(v_n, float)
    v_e = np.asarray(v_e, float)
    c, s = np.cos(psi), np.sin(psi)
    along = c * v_n + s * v_e
    lateral = -s * v_n + c * v_e
    speed_dot = _smooth(along, win, 1, dt)
    along_s = _smooth(along, win, 0, dt)
    nan = np.full(n, np.nan)
    cmd_surge = nan if cmd_surge is None else np.asarray(cmd_surge, float)
    cmd_yaw = nan if cmd_yaw is None else np.asarray(cmd_yaw, float)
    if thrust_quadratic is None:
        thrust_quadratic = cmd_surge * np.abs(cmd_surge)
    if thrust_reverse is None:
        thrust_reverse = np.minimum(cmd_surge, 0.0)
    return Dataset(
        t=t, dt=dt, psi=psi, r=r, psi_dot=psi_dot, v_n=v_n, v_e=v_e, along=along,
        lateral=lateral, speed_dot=speed_dot, along_s=along_s, cmd_surge=cmd_surge, cmd_yaw=cmd_yaw,
        thrust_quadratic=np.asarray(thrust_quadratic, float),
        thrust_reverse=np.asarray(thrust_reverse, float),
        run=np.asarray(run if run is not None else [""] * n, dtype=object),
        north=nan if north is None else np.asarray(north, float),
        east=nan if east is None else np.asarray(east, float),
        has_gyro=has_gyro, has_commands=bool(np.isfinite(cmd_surge).any()), source=source,
        cmd_left=None if cmd_left is None else np.asarray(cmd_left, float),
        cmd_right=None if cmd_right is None else np.asarray(cmd_right, float),
        acc_x=None if acc_x is None else np.asarray(acc_x, float),
        acc_y=None if acc_y is None else np.asarray(acc_y, float),
        u_model=None if u_model is None else np.asarray(u_model, float), base_model=base_model)


def remeasured(ds: Dataset, *, psi: np.ndarray | None = None, v_n: np.ndarray | None = None,
               v_e: np.ndarray | None = None, keep: np.ndarray | None = None) -> Dataset:
    """``ds`` with another measured heading or velocity over ground, its derived channels
    (along, lateral, derivatives) recomputed; ``keep`` selects the ticks to keep."""
    k = slice(None) if keep is None else keep
    psi = ds.psi if psi is None else psi
    v_n = ds.v_n if v_n is None else v_n
    v_e = ds.v_e if v_e is None else v_e
    out = from_arrays(ds.t[k], psi[k], v_n[k], v_e[k], r=ds.r[k] if ds.has_gyro else None,
                      cmd_surge=ds.cmd_surge[k], cmd_yaw=ds.cmd_yaw[k],
                      thrust_quadratic=ds.thrust_quadratic[k],
                      thrust_reverse=ds.thrust_reverse[k], run=ds.run[k], north=ds.north[k],
                      east=ds.east[k], source=ds.source,
                      cmd_left=None if ds.cmd_left is None else ds.cmd_left[k],
                      cmd_right=None if ds.cmd_right is None else ds.cmd_right[k],
                      acc_x=None if ds.acc_x is None else ds.acc_x[k],
                      acc_y=None if ds.acc_y is None else ds.acc_y[k],
                      u_model=None if ds.u_model is None else ds.u_model[k],
                      base_model=ds.base_model)
    out.actuator_lag_s = ds.actuator_lag_s
    out.base_terms = ds.base_terms
    if not ds.has_gyro:
        out.r = ds.r[k]  # the heading-derived rate, kept as it was
    return out


def from_log(path: str, cfg: Config, *, rate_hz: float = 10.0,
             base_model: str = "surface-boat") -> Dataset:
    """Read ``path`` through the engine and collect its channels at ``rate_hz``, for the
    base model named ``base_model`` (a ``"glider"``'s: its steady-glide speed as
    ``u_model``, from ``cfg``'s ``[pipelines.current.glider]``, and no commands)."""
    import msgspec

    cfg = msgspec.structs.replace(cfg, engine=msgspec.structs.replace(cfg.engine, rate_hz=rate_hz))
    _, reader = open_log(path, cfg.csv, column_names(cfg.inputs))
    col = _Collector()
    engine = Engine(cfg, [col], select_sources=False, fresh_estimates=False)
    run(engine, reader, lambda t, r: None, gap_s=2.0)
    little = shortfall(reader.stats, Path(path).name, engine.time_outliers())
    if little:   # said beside the fit, or with the refusal: the log is mostly unread
        engine.alerts.warn("log_mostly_unread", little)
    try:
        if not col.rows:
            raise NotEnoughData(f"{path}: no samples in time (no time-stamped heading, "
                                "position, velocity or command the engine could use)")
        cols = list(zip(*col.rows))
        (t, psi, gyro, v_n, v_e, north, east, fix_t, cmd_s, cmd_y, cmd_q, cmd_r, runs, cl,
         cr, ax, ay, pitch, pump) = (np.array(c) for c in cols)
        t = t.astype(float)
        v_n, v_e = v_n.astype(float), v_e.astype(float)
        if not (np.isfinite(v_n) & np.isfinite(v_e)).any() and col.fixes:
            v_n, v_e = fix_velocity(col.fixes, t)
        rate_hz_log = col.yaw_rate_hz()
        has_rate = col.has_rate and rate_hz_log >= MIN_YAW_RATE_HZ
        ok = _usable_ticks(path, psi.astype(float), v_n, v_e, rate_hz,
                           gyro.astype(float) if has_rate else None, len(col.fixes),
                           engine.rejections().get("heading:no_declination", 0))
    except NotEnoughData as err:
        raise NotEnoughData(f"{little}; in what could: {err}" if little else str(err)) from None
    idx = np.flatnonzero(ok)
    # Keep the longest stretches; breaks in time become separate runs.
    t = t[idx]
    runs = runs[idx].astype(object)
    gap = np.r_[False, np.diff(t) > 2.5 / rate_hz]
    seg = np.cumsum(gap)
    labels = np.array([f"{r}#{k}" for r, k in zip(runs, seg)], dtype=object)
    ax, ay = ax[idx].astype(float), ay[idx].astype(float)
    has_acc = bool(np.isfinite(ax).all() and np.isfinite(ay).all())
    glider = base_model == "glider"
    u_model = glide_speed(cfg, t, pitch[idx].astype(float), pump[idx].astype(float),
                          col.depths) if glider else None
    cmd = {} if glider else dict(
        cmd_surge=cmd_s[idx].astype(float), cmd_yaw=cmd_y[idx].astype(float),
        thrust_quadratic=cmd_q[idx].astype(float), thrust_reverse=cmd_r[idx].astype(float),
        cmd_left=cl[idx].astype(float) if np.isfinite(cl.astype(float)).any() else None,
        cmd_right=cr[idx].astype(float) if np.isfinite(cr.astype(float)).any() else None)
    ds = from_arrays(
        t, psi[idx].astype(float), v_n[idx], v_e[idx],
        r=gyro[idx].astype(float) if has_rate else None, run=labels,
        north=north[idx].astype(float), east=east[idx].astype(float), source=str(path),
        acc_x=ax if has_acc else None, acc_y=ay if has_acc else None, u_model=u_model,
        base_model=base_model, **cmd)
    ds.warnings = list(engine.alerts)
    ds.yaw_rate_hz = rate_hz_log
    ds.raw = {"fixes": col.fixes, **col.raw}
    return ds


FIX_VELOCITY_SPAN_S = 4.0
"""Span (s) of the straight line through the fixes whose slope is the velocity over
ground of a log without one (:func:`fix_velocity`): five fixes at 1 Hz; on the DDBoat's
positions, rounded to 1e-4 arc minute (0.19 m north, 0.12 m east), the slope's rounding
noise is about 0.02 m/s."""

FIX_GAP_S = 3.0
"""Fixes further apart than this (s) are not differenced across: the velocity between
them is unknown."""


def fix_velocity(fixes: Sequence[tuple[float, float, float]], t: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Velocity over ground (north, east; m/s) at the ticks ``t`` from the GNSS positions
    alone: at each fix the slope of the least-squares line through the fixes within
    :data:`FIX_VELOCITY_SPAN_S` centred on it (at least three, spanning half of it, none
    across a gap of :data:`FIX_GAP_S`); at a tick between two fixes of one stretch, the
    linear interpolation of theirs, else NaN. ``fixes`` are (t, north, east).

    A fix that repeats the previous position exactly is not a new position: a receiver's
    fixes wander by more than their last digit even at rest, so a repeat is a position
    held (the DDBoat's receiver holds one for 4-64 s at a time, 46 % of its fixes, while
    both motors run at 200/255 and the compass turns through 80-210 deg, then jumps 1-5
    m). Such a stretch is a gap: its velocity is unknown, not zero."""
    tf, n, e = (np.asarray(c, float) for c in zip(*fixes))
    keep = np.r_[True, (np.diff(tf) > 0.0) & ((np.diff(n) != 0.0) | (np.diff(e) != 0.0))]
    tf, n, e = tf[keep], n[keep], e[keep]
    seg = np.cumsum(np.r_[0, np.diff(tf) > FIX_GAP_S])
    vn, ve = np.full(len(tf), math.nan), np.full(len(tf), math.nan)
    half = 0.5 * FIX_VELOCITY_SPAN_S
    for i in range(len(tf)):
        m = (np.abs(tf - tf[i]) <= half + 1e-6) & (seg == seg[i])
        if m.sum() >= 3 and np.ptp(tf[m]) >= half:
            dt = tf[m] - tf[m].mean()
            vn[i] = float(dt @ n[m] / (dt @ dt))
            ve[i] = float(dt @ e[m] / (dt @ dt))
    k = np.clip(np.searchsorted(tf, t, side="right") - 1, 0, max(0, len(tf) - 2))
    nxt = np.minimum(k + 1, len(tf) - 1)
    inside = (t >= tf[0]) & (t <= tf[-1]) & (seg[k] == seg[nxt])
    w = np.clip((t - tf[k]) / np.maximum(tf[nxt] - tf[k], 1e-9), 0.0, 1.0)
    out_n = vn[k] + w * (vn[nxt] - vn[k])
    out_e = ve[k] + w * (ve[nxt] - ve[k])
    return np.where(inside, out_n, math.nan), np.where(inside, out_e, math.nan)


def glide_speed(cfg: Config, t: np.ndarray, pitch: np.ndarray, pump: np.ndarray,
                depths: Sequence[tuple[float, float]]) -> np.ndarray:
    """A glider's through-water speed along its heading (m/s) at the ticks ``t``: the
    steady glide (:meth:`onboard.estimators.vehicle_models.GliderModel.glide_from_depth_rate`,
    with ``cfg``'s ``[pipelines.current.glider]`` coefficients, as the current pipeline
    uses it) at the tick's pitch (rad) and pump volume (cm^3; the neutral volume where
    none came) and the depth rate of the newest depth sample (m/s: the centred difference
    of the depth samples either side, none across more than the table's
    ``max_depth_interval_s``). NaN where the glide gives no speed (a shallow pitch, an
    inflection)."""
    g = cfg.pipelines.current.glider
    model = glider_model(g)
    out = np.full(len(t), math.nan)
    if len(depths) < 2:
        return out
    td, z = (np.asarray(c, float) for c in zip(*depths))
    rate = np.full(len(td), math.nan)
    lo, hi = np.r_[0, np.arange(len(td) - 1)], np.r_[np.arange(1, len(td)), len(td) - 1]
    span = td[hi] - td[lo]
    close = (span > 0) & (np.maximum(td - td[lo], td[hi] - td) <= g.max_depth_interval_s)
    rate[close] = (z[hi] - z[lo])[close] / span[close]
    k = np.searchsorted(td, t, side="right") - 1
    pump = np.where(np.isfinite(pump), pump, g.neutral_pump_cc)
    for i in np.flatnonzero(k >= 0):
        glide = model.glide_from_depth_rate(float(pitch[i]), float(rate[k[i]]),
                                            float(pump[i]))
        if glide is not None:
            out[i] = glide.u_h
    return out


def _usable_ticks(path: str, psi: np.ndarray, v_n: np.ndarray, v_e: np.ndarray,
                  rate_hz: float, rate: np.ndarray | None = None,
                  n_fixes: int = 0, waiting_headings: int = 0) -> np.ndarray:
    """The ticks with both a heading and a velocity over ground, and a yaw rate when the
    log has one (``rate``: its first ticks may come before the first rate), as a boolean
    mask; a :class:`NotEnoughData` naming what is missing when the log has no heading
    (``waiting_headings``: magnetic ones the engine rejected for want of a declination),
    no velocity over ground (``n_fixes``: the GNSS fixes it has, too few or too far apart
    to difference), or fewer than :data:`MIN_TICKS` ticks with both."""
    has_psi = np.isfinite(psi)
    has_v = np.isfinite(v_n) & np.isfinite(v_e)
    if not has_psi.any() and waiting_headings:
        raise NotEnoughData(
            f"{path}: no heading: its {waiting_headings} magnetic heading(s) waited for a "
            "GNSS fix to give their declination and none came (set [corrections] "
            "declination_deg); model closure needs one")
    if not has_psi.any():
        raise NotEnoughData(f"{path}: no heading (no compass, attitude or true heading in "
                            "the log); model closure needs one")
    if not has_v.any() and n_fixes:
        raise NotEnoughData(
            f"{path}: no velocity over ground (no Doppler or INS/DVL velocity, and its "
            f"{n_fixes} GNSS fix(es) are too few or too far apart to difference: three "
            f"within {FIX_VELOCITY_SPAN_S:.0f} s, no gap over {FIX_GAP_S:.0f} s); model "
            "closure needs one")
    if not has_v.any():
        raise NotEnoughData(f"{path}: no velocity over ground (no GNSS fix, Doppler or "
                            "INS/DVL velocity in the log); model closure needs one")
    ok = has_psi & has_v
    if rate is not None:
        ok &= np.isfinite(rate)
    if ok.sum() < MIN_TICKS:
        raise NotEnoughData(too_short(path, ok.sum() / rate_hz,
                                      f" (heading {has_psi.sum() / rate_hz:.0f} s, velocity "
                                      f"{has_v.sum() / rate_hz:.0f} s)"))
    return ok


def too_short(path: str, seconds: float, detail: str = "") -> str:
    """The one line that refuses ``path`` for holding only ``seconds`` of data with both
    heading and velocity over ground (``detail`` follows the figure)."""
    return (f"{path}: too short: {seconds:.1f} s with both heading and velocity over "
            f"ground{detail}; model closure needs at least {MIN_DATA_S:.0f} s")
