"""A log as aligned arrays of measured channels, for model closure.

The log is read by the same readers and engine as ``onboard replay`` (validation, input
mapping, surface/submerged gating); a collector pipeline samples the newest value of every
channel at each engine tick. Velocity over ground comes from, in order of preference, an
INS/DVL navigation solution (VelocityOverGround), the receiver's Doppler SOG/COG, or
differenced GNSS positions.

Derived channels, all at the tick rate ``1/dt``:

* ``psi``: measured heading (rad, unwrapped), from the compass or the autopilot attitude;
* ``along``, ``lateral``: velocity over ground projected on the measured heading (m/s),
  ``along = cos(psi) v_n + sin(psi) v_e``, ``lateral = -sin(psi) v_n + cos(psi) v_e``;
* ``r``: yaw rate (rad/s) from the gyro where there is one, else from the heading;
* ``psi_dot``: time derivative of the measured heading (rad/s);
* ``cmd_surge``, ``cmd_yaw``: normalized commands (throttle and rudder, or the mean and
  half-difference of a skid-steered boat's thrusters);
* ``run``: run label (a directory of CSV runs), used to split fit and held-out data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.signal import savgol_filter

from drivers.logs import open_log
from onboard.core.config import Config
from onboard.core.geo import LocalFrame
from onboard.core.messages import (
    ActuatorCommand,
    Attitude,
    GnssFix,
    Heading,
    Imu,
    Sample,
    VelocityOverGround,
)
from onboard.engine import Engine, run


class _Collector:
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
        self.vn = self.ve = math.nan
        self.vog_t = -math.inf
        self.gnss_vn = self.gnss_ve = math.nan
        self.north = self.east = math.nan
        self.fix_t = -math.inf
        self.cmd_surge = self.cmd_yaw = self.cmd_quad = self.cmd_rev = math.nan
        self.cmd_left = self.cmd_right = math.nan
        self.run = ""
        self.has_gyro = False

    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        for s in samples:
            if isinstance(s, Heading):
                self.heading_src_compass = True
                self.heading = s.heading_rad + (s.declination_rad or 0.0)
            elif isinstance(s, Attitude):
                if not self.heading_src_compass:
                    self.heading = s.yaw_rad
                if s.yaw_rate_rps is not None and not self.has_gyro:
                    self.gyro_last = s.yaw_rate_rps
            elif isinstance(s, Imu):
                self.has_gyro = True
                self.gyro_sum += s.gyro_z
                self.gyro_n += 1
            elif isinstance(s, GnssFix):
                if self.frame is None:
                    self.frame = LocalFrame(s.lat_deg, s.lon_deg)
                self.north, self.east = self.frame.to_ne(s.lat_deg, s.lon_deg)
                self.fix_t = s.t
                if s.sog_mps is not None and s.cog_rad is not None:
                    self.gnss_vn = s.sog_mps * math.cos(s.cog_rad)
                    self.gnss_ve = s.sog_mps * math.sin(s.cog_rad)
                if s.source.startswith("csv:"):
                    self.run = s.source
            elif isinstance(s, VelocityOverGround):
                self.vn, self.ve, self.vog_t = s.v_north_mps, s.v_east_mps, s.t
                if s.source.startswith("csv:"):
                    self.run = s.source
            elif isinstance(s, ActuatorCommand):
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
            self.gyro_sum, self.gyro_n = 0.0, 0
        vog_fresh = t - self.vog_t < 1.0
        self.rows.append((
            t, self.heading, self.gyro_last,
            self.vn if vog_fresh else self.gnss_vn, self.ve if vog_fresh else self.gnss_ve,
            self.north, self.east, self.fix_t, self.cmd_surge, self.cmd_yaw, self.cmd_quad,
            self.cmd_rev, self.run, self.cmd_left, self.cmd_right,
        ))
        return {}

    def health(self) -> Mapping[str, float]:
        return {}

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
    actuator_lag_s: float = 0.0
    """Time constant (s) of the first-order lag already applied to the command channels
    (:func:`lag_commands`); 0 for the commands as logged."""

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
                cmd_left=None, cmd_right=None) -> Dataset:
    """Build a dataset from uniformly sampled arrays (SI units, heading in rad)."""
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
        cmd_right=None if cmd_right is None else np.asarray(cmd_right, float))


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
                      cmd_right=None if ds.cmd_right is None else ds.cmd_right[k])
    out.actuator_lag_s = ds.actuator_lag_s
    if not ds.has_gyro:
        out.r = ds.r[k]  # the heading-derived rate, kept as it was
    return out


def from_log(path: str, cfg: Config, *, rate_hz: float = 10.0) -> Dataset:
    """Read ``path`` through the engine and collect its channels at ``rate_hz``."""
    import msgspec

    cfg = msgspec.structs.replace(cfg, engine=msgspec.structs.replace(cfg.engine, rate_hz=rate_hz))
    _, reader = open_log(path, cfg.csv)
    col = _Collector()
    engine = Engine(cfg, [col], select_sources=False, fresh_estimates=False)
    run(engine, reader, lambda t, r: None, gap_s=2.0)
    if not col.rows:
        raise ValueError(f"{path}: no samples")
    cols = list(zip(*col.rows))
    t, psi, gyro, v_n, v_e, north, east, fix_t, cmd_s, cmd_y, cmd_q, cmd_r, runs, cl, cr = (
        np.array(c) for c in cols)
    t = t.astype(float)
    ok = np.isfinite(psi.astype(float)) & np.isfinite(v_n.astype(float)) & np.isfinite(
        v_e.astype(float))
    if ok.sum() < 50:
        raise ValueError(f"{path}: fewer than 50 ticks with both heading and velocity over ground")
    idx = np.flatnonzero(ok)
    # Keep the longest stretches; breaks in time become separate runs.
    t = t[idx]
    runs = runs[idx].astype(object)
    gap = np.r_[False, np.diff(t) > 2.5 / rate_hz]
    seg = np.cumsum(gap)
    labels = np.array([f"{r}#{k}" for r, k in zip(runs, seg)], dtype=object)
    gyro = gyro[idx].astype(float)
    ds = from_arrays(
        t, psi[idx].astype(float), v_n[idx].astype(float), v_e[idx].astype(float),
        r=gyro if col.has_gyro and np.isfinite(gyro).all() else None,
        cmd_surge=cmd_s[idx].astype(float), cmd_yaw=cmd_y[idx].astype(float),
        thrust_quadratic=cmd_q[idx].astype(float), thrust_reverse=cmd_r[idx].astype(float),
        run=labels,
        north=north[idx].astype(float), east=east[idx].astype(float), source=str(path),
        cmd_left=cl[idx].astype(float) if np.isfinite(cl.astype(float)).any() else None,
        cmd_right=cr[idx].astype(float) if np.isfinite(cr.astype(float)).any() else None)
    return ds
