"""Sensor models: the true state in, typed samples with realistic errors out.

Each sensor is a small class with a configuration (a frozen dataclass, SI units) and a
``measure(world)`` method that the runner calls at the sensor's rate. Errors are drawn from
the sensor's own :class:`numpy.random.Generator`, seeded from the run seed and the sensor's
name, so the same seed gives the same errors and adding a sensor does not change the
errors of the others.

Error models (all one-sigma figures, per axis unless said otherwise):

* **GNSS** (:class:`Gnss`): horizontal position = truth + white noise ``position_std_m`` +
  a first-order Gauss-Markov drift (stationary std ``drift_std_m``, correlation time
  ``drift_tau_s``); SOG/COG from the true velocity over ground plus white noise
  ``velocity_std_mps``; a fixed ``latency_s`` between the instant measured and the instant
  reported; outages (Poisson onset ``outage_rate_hz``, exponential length of mean
  ``outage_mean_s``); scheduled outages ``outage_windows`` (the ``gnss_outage`` fault);
  no fix at all deeper than ``max_depth_m`` (0.3 m). Without a fix a receiver still
  reports each epoch: with ``report_invalid`` set (the runner sets it for the NMEA outputs)
  such an epoch is a :class:`GnssNoFix`, which no driver turns into a sample.
* **IMU** (:class:`Imu`): specific force and angular rate (body FRD) + turn-on bias +
  random-walk bias + white noise; an injected constant gyro bias on top.
* **Compass/AHRS** (:class:`Compass`): heading error
  ``c + A1 sin(psi + phi1) + A2 sin(2 psi + phi2) + k_motor * thrust`` (hard iron, soft iron,
  constant offset, motor interference) plus white noise, plus scheduled steps ``steps``
  (the ``compass_step`` fault: a magnetic disturbance); the AHRS attitude carries the same
  yaw, roll and pitch with small noise, and the gyro rates; no heading in scheduled
  ``invalid_windows`` (a heading receiver without a solution; with ``report_invalid`` a
  :class:`HeadingInvalid` per heading epoch there, for the NMEA output's empty HDT).
* **DVL** (:class:`Dvl`): bottom-track velocity over ground and (optionally) water-track
  velocity through water, in the instrument = body frame; white noise growing with
  altitude; lock lost above ``max_altitude_m``, below ``min_altitude_m``, in random
  dropouts and in scheduled ``lock_loss_windows`` (the ``dvl_lock_loss`` fault). A lost
  lock is reported the way a Water Linked A50 reports it: ``valid=False``, zero velocity,
  a large figure of merit, no altitude. The figure of merit (and the covariance, its
  square on the diagonal) is by default the noise's std, report by report; with
  :data:`A50_FOM` it is the instrument's estimate, not the noise, and it does not
  know the report's own error: ``fom_scale`` times the noise's std times a log-normal
  factor of log-std ``fom_log_std`` wandering with correlation time ``fom_tau_s`` (mean
  square 1), drawn from a stream of its own; the noise stays white with the configured
  std. A locked report is flagged invalid with probability ``quality_invalid_prob``: its
  beams see the bottom, it carries its altitude and a velocity
  ``quality_invalid_noise_factor`` times noisier, its figure of merit
  ``quality_invalid_fom_factor`` times higher.
  Measured on the A50 capture in ``../shared/data/waterlinked_dvl_a50_json_tank``
  (BlueROV2 in a tank, 1.8 m up, ~8.5 reports/s). At rest (its first 110 reports): the
  velocity scatters 0.00053 m/s per axis about its mean (0.00045 by the report's distance
  to its 6 neighbours' mean), with kurtosis 2.8 (no sign of a wandering noise std); the
  fom's RMS is 0.00028 m/s, 0.53-0.62 of that scatter, its log's std 0.10, lag-1
  correlation 0.68 at 0.117 s (tau 0.30 s), and the correlation of its log with the log of
  the report's distance to its neighbours is -0.20 (n 104): at a given speed the fom does
  not predict the error. Driven (the circle and straight runs, > 0.05 m/s) the fom's log
  follows the log of the speed (correlation 0.71-0.85, fom ~ speed^0.6-0.8, 0.0009 m/s at
  0.3 m/s); about that trend its std is 0.33-0.34, lag-1 0.33-0.39 (tau 0.11-0.12 s). Pooled
  over rest and motion the fom's log has std 0.54-0.77 and correlates 0.66-0.74 with the
  log of the report's distance to its neighbours, but through the speed: the partial
  correlation given the log speed is 0.02-0.34, and moving that distance (0.02-0.05 m/s)
  is the vehicle's own motion more than the noise, 20-50 times the fom. The simulated
  noise does not grow with speed, so neither does its fom. 0.4 % (at rest), 2.5 % and
  4.5 % (driven) of the reports are flagged invalid with four beams on the bottom, their
  velocities 1.2-1.9 times further from their neighbours' than the valid ones', their fom
  a median 1.4-1.7 times the valid ones'.
* **Depth** (:class:`DepthSensor`): pressure = p0 + rho g (depth + white noise).
* **Actuators** (:class:`ActuatorModel`, :class:`RpmSensor`): commanded normalized values
  to PWM pulse widths (integer us, saturated at the end points), the ESC deadband applied
  to what the plant receives; shaft speed with white noise.
* **INS** (:class:`Ins`): the velocity over ground of a DVL-aided INS (torpedo AUVs'
  GLOBAL_POSITION_INT): truth + white noise + Gauss-Markov bias.

Sample times ``t`` are simulation seconds since the start of the scenario (emitters add the
log's epoch).
"""

from __future__ import annotations

import math
import zlib
from collections import deque
from dataclasses import dataclass, field
from typing import Protocol, Sequence

import numpy as np

from onboard.core.messages import (
    ActuatorOutputs,
    Attitude,
    Depth,
    DvlPosition,
    DvlVelocity,
    GnssFix,
    Heading,
    PropellerRpm,
    Sample,
    VelocityOverGround,
)
from onboard.core.messages import (
    Imu as ImuSample,
)
from onboard.sitl.frames import GeoOrigin, body_to_ned_fast, wrap_2pi, wrap_pi
from onboard.sitl.truth import TruthRecord

GRAVITY = 9.80665
"""Standard gravity (m/s^2)."""


class GnssNoFix(Sample, frozen=True, tag="sim_gnss_no_fix"):
    """A receiver epoch without a fix (an outage, the antenna under water): what the
    receiver still sends on its protocol outputs (GGA quality 0, RMC status ``V``, VTG
    mode ``N``). Simulator-only: the drivers reject those sentences, so no estimator input
    is one; only simulations asked for them yield it."""


class HeadingInvalid(Sample, frozen=True, tag="sim_heading_invalid"):
    """A heading epoch without a valid heading: what a heading receiver still sends
    (an empty HDT). Simulator-only, as :class:`GnssNoFix`."""


def sensor_rng(seed: int, name: str) -> np.random.Generator:
    """The random generator of sensor ``name`` for run ``seed``: independent, reproducible."""
    return np.random.default_rng(np.random.SeedSequence([int(seed) & 0xFFFFFFFF,
                                                         zlib.crc32(name.encode())]))




class WorldView:
    """What the sensors may look at in one instant: the truth, as the runner provides it.

    ``truth`` is the :class:`TruthRecord`; ``specific_force`` (m/s^2) and
    ``angular_rate`` (rad/s) are body FRD; ``v_ned`` the velocity over ground (m/s, NED,
    derived from the truth when not given); ``thrust`` the signed propulsion level in
    [-1, 1] (drives compass motor interference); ``shaft_rpm`` the true propeller speeds
    (rev/min); ``altitude`` the true range to the bottom (m) or None without a bottom.

    The runner passes ``truth_fn`` and ``specific_force_fn`` instead of values so that
    an instant where only the IMU measures never builds a truth record (and one where
    no IMU measures never computes the specific force).
    """

    __slots__ = ("t", "_truth", "_truth_fn", "_sf", "_sf_fn", "angular_rate", "_v_ned",
                 "thrust", "shaft_rpm", "_altitude", "_bottom")

    def __init__(self, t: float, truth: TruthRecord | None = None,
                 specific_force: tuple[float, float, float] | None = None,
                 angular_rate: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 v_ned: tuple[float, float, float] | None = None, thrust: float = 0.0,
                 shaft_rpm: tuple[float, ...] = (), altitude: float | None = None, *,
                 truth_fn=None, specific_force_fn=None,
                 bottom_depth: float | None = None) -> None:
        self.t = t
        self._truth = truth
        self._truth_fn = truth_fn
        self._sf = specific_force
        self._sf_fn = specific_force_fn
        self.angular_rate = angular_rate
        self._v_ned = v_ned
        self.thrust = thrust
        self.shaft_rpm = shaft_rpm
        self._altitude = altitude
        self._bottom = bottom_depth

    @property
    def truth(self) -> TruthRecord:
        """The true state at ``t`` (built on first use)."""
        if self._truth is None:
            self._truth = self._truth_fn()
        return self._truth

    @property
    def specific_force(self) -> tuple[float, float, float]:
        """What an ideal accelerometer measures at ``t`` (m/s^2, body FRD; level and at rest
        without a plant)."""
        if self._sf is None:
            self._sf = self._sf_fn() if self._sf_fn is not None else (0.0, 0.0, -GRAVITY)
        return self._sf

    @property
    def v_ned(self) -> tuple[float, float, float]:
        """The true velocity over ground (m/s, NED), from the truth's body velocity when not
        given."""
        if self._v_ned is None:
            tr = self.truth
            self._v_ned = body_to_ned_fast(tr.roll, tr.pitch, tr.yaw, (tr.u, tr.v, tr.w))
        return self._v_ned

    @property
    def altitude(self) -> float | None:
        """The true range to the bottom (m), None without a bottom."""
        if self._altitude is None and self._bottom is not None:
            self._altitude = self._bottom - self.truth.down
        return self._altitude


class Sensor(Protocol):
    """A sensor model. ``measure`` is called every ``1/rate_hz`` seconds of simulation."""

    name: str
    rate_hz: float

    def measure(self, world: WorldView) -> list[Sample]:
        """Samples measured at ``world.t`` (may be empty: outage, underwater, latency)."""
        ...

    def due(self, t: float) -> list[Sample]:
        """Samples measured earlier whose report time has come (latency); usually []."""
        ...

    def error_state(self) -> dict[str, float]:
        """The sensor's current hidden error states, for the truth file (``sensor.*``)."""
        ...


class _Base:
    """Shared plumbing: name, rate, generator; no latency, no hidden state."""

    name: str = "sensor"

    def __init__(self, rate_hz: float, rng: np.random.Generator, name: str | None = None):
        if rate_hz <= 0:
            raise ValueError(f"{name or self.name}: rate_hz must be > 0, got {rate_hz}")
        self.rate_hz = float(rate_hz)
        self.rng = rng
        if name:
            self.name = name

    def measure(self, world: WorldView) -> list[Sample]:
        """Samples measured at ``world.t`` (may be empty: outage, underwater, latency)."""
        raise NotImplementedError

    def due(self, t: float) -> list[Sample]:
        """Samples measured earlier whose report time has come (latency); usually []."""
        return []

    def error_state(self) -> dict[str, float]:
        """The sensor's current hidden error states, for the truth file (``sensor.*``)."""
        return {}


def in_windows(t: float, windows: Sequence[tuple[float, float]]) -> bool:
    """Whether ``t`` falls in one of the ``(start, duration)`` windows (s): start <= t <
    start + duration."""
    for start, dur in windows:
        if start <= t < start + dur:
            return True
    return False


def _gauss_markov(x: np.ndarray, dt: float, tau: float, std: float,
                  rng: np.random.Generator) -> np.ndarray:
    """Exact discrete step of a first-order Gauss-Markov process of stationary ``std``."""
    if std <= 0.0:
        return x * 0.0
    if tau <= 0.0:
        return std * rng.standard_normal(x.shape)
    phi = math.exp(-dt / tau)
    return phi * x + std * math.sqrt(1.0 - phi * phi) * rng.standard_normal(x.shape)


class _Outages:
    """Two-state renewal process: Poisson onsets at ``rate_hz``, exponential lengths."""

    __slots__ = ("rate_hz", "mean_s", "until", "rng", "count")

    def __init__(self, rate_hz: float, mean_s: float, rng: np.random.Generator) -> None:
        self.rate_hz = rate_hz
        self.mean_s = mean_s
        self.until = -math.inf
        self.rng = rng
        self.count = 0

    def active(self, t: float, dt: float) -> bool:
        """Whether the sensor is out at ``t``; ``dt`` is the time since the last call."""
        if t < self.until:
            return True
        if self.rate_hz > 0.0 and self.rng.random() < -math.expm1(-self.rate_hz * dt):
            self.until = t + self.rng.exponential(self.mean_s)
            self.count += 1
            return True
        return False


# --------------------------------------------------------------------------- GNSS


@dataclass(frozen=True, kw_only=True)
class GnssConfig:
    """GNSS receiver error model (m, m/s, s, Hz).

    Defaults are a consumer receiver with SBAS: ~1 m white, ~1 m slowly wandering drift.
    """

    rate_hz: float = 5.0
    position_std_m: float = 0.8
    """White horizontal noise per axis (m)."""
    drift_std_m: float = 0.8
    """Stationary std of the Gauss-Markov horizontal drift per axis (m)."""
    drift_tau_s: float = 120.0
    """Correlation time of the drift (s)."""
    altitude_std_m: float = 2.0
    velocity_std_mps: float = 0.05
    """White noise on each earth-frame velocity component (m/s); SOG/COG derive from it."""
    latency_s: float = 0.0
    """Time between the instant measured and the report (s)."""
    outage_rate_hz: float = 0.0
    """Mean number of outage onsets per second."""
    outage_mean_s: float = 10.0
    max_depth_m: float = 0.3
    """No fix when the antenna is deeper than this (m)."""
    outage_windows: tuple[tuple[float, float], ...] = ()
    """Scheduled outages ``(start_s, duration_s)``: no fix at all in them (the
    ``gnss_outage`` fault: antenna cable, jamming, a bridge)."""
    degraded_windows: tuple[tuple[float, float, float], ...] = ()
    """Scheduled degraded accuracy ``(start_s, duration_s, factor)``: the white position
    noise is ``factor`` times ``position_std_m`` in them and the reported ``h_acc_m`` says
    so (code multipath near a harbour wall or under trees; the Doppler velocity, from the
    carrier, keeps its noise)."""
    num_sats: int = 12
    hdop: float = 0.9
    time_jitter_std_s: float = 0.0
    """Std of a normal error of each fix's time tag (s), zero mean: a receiver whose time
    tags are not locked to its measurement epochs (the ``gnss_jitter`` effect)."""
    reported_accuracy_m: float | None = None
    """The ``h_acc_m`` the receiver reports (m); None: its true ``hypot(white, drift)``. A
    receiver whose accuracy estimate is not its noise (the noise-scale scenarios)."""


class Gnss(_Base):
    """GNSS receiver: :class:`GnssFix` samples with position, SOG and COG (see module doc)."""

    name = "gnss"

    def __init__(self, cfg: GnssConfig, origin: GeoOrigin, rng: np.random.Generator,
                 name: str | None = None) -> None:
        super().__init__(cfg.rate_hz, rng, name)
        self.cfg = cfg
        self.origin = origin
        self.drift = cfg.drift_std_m * rng.standard_normal(2)
        self._t_last: float | None = None
        self._queue: deque[tuple[float, Sample]] = deque()
        self._outages = _Outages(cfg.outage_rate_hz, cfg.outage_mean_s, rng)
        self._out = False
        self.report_invalid = False
        """Report each epoch without a fix as a :class:`GnssNoFix` (after ``latency_s``,
        in order with the fixes); False: nothing."""

    def measure(self, world: WorldView) -> list[Sample]:
        c = self.cfg
        t = world.t
        dt = 1.0 / self.rate_hz if self._t_last is None else t - self._t_last
        self._t_last = t
        self.drift = _gauss_markov(self.drift, dt, c.drift_tau_s, c.drift_std_m, self.rng)
        n = self.rng.standard_normal(5).tolist()
        drift = self.drift.tolist()
        out = self._outages.active(t, dt) or in_windows(t, c.outage_windows)
        self._out = out
        tr = world.truth
        if out or tr.down > c.max_depth_m:
            if self.report_invalid:
                self._enqueue(t, t + c.latency_s, GnssNoFix(t=t + c.latency_s,
                                                            source=self.name))
            return self.due(t)
        pos_std = c.position_std_m
        for start, dur, factor in c.degraded_windows:
            if start <= t < start + dur:
                pos_std *= factor
                break
        north = tr.north + drift[0] + pos_std * n[0]
        east = tr.east + drift[1] + pos_std * n[1]
        lat, lon = self.origin.to_latlon(north, east)
        vn = world.v_ned[0] + c.velocity_std_mps * n[2]
        ve = world.v_ned[1] + c.velocity_std_mps * n[3]
        t_report = t + c.latency_s
        if c.time_jitter_std_s > 0.0:
            t_report += c.time_jitter_std_s * float(self.rng.standard_normal())
        fix = GnssFix(
            t=t_report, source=self.name, lat_deg=lat, lon_deg=lon,
            alt_m=-tr.down + c.altitude_std_m * n[4], fix_quality=1,
            num_sats=c.num_sats, hdop=c.hdop,
            sog_mps=math.hypot(vn, ve), cog_rad=wrap_2pi(math.atan2(ve, vn)),
            h_acc_m=(math.hypot(pos_std, c.drift_std_m) if c.reported_accuracy_m is None
                     else c.reported_accuracy_m),
            v_acc_m=c.altitude_std_m,
        )
        self._enqueue(t, t_report, fix)
        return self.due(t)

    def _enqueue(self, t: float, t_report: float, sample: Sample) -> None:
        """Queue ``sample`` reported at ``t_report``: delivered in order, and never before
        the instant ``t`` measured."""
        due = max(t_report, t, self._queue[-1][0] if self._queue else -math.inf)
        self._queue.append((due, sample))

    def due(self, t: float) -> list[Sample]:
        q = self._queue
        out: list[Sample] = []
        while q and q[0][0] <= t + 1e-9:
            out.append(q.popleft()[1])
        return out

    def error_state(self) -> dict[str, float]:
        return {"sensor.gnss_drift_north": float(self.drift[0]),
                "sensor.gnss_drift_east": float(self.drift[1]),
                "sensor.gnss_outage": 1.0 if self._out else 0.0}


# --------------------------------------------------------------------------- IMU


@dataclass(frozen=True, kw_only=True)
class ImuConfig:
    """MEMS IMU error model, per axis (SI units).

    Defaults: a hobby-grade MEMS IMU after the autopilot's boot-time gyro calibration.
    """

    rate_hz: float = 50.0
    accel_noise_std: float = 0.03
    """White noise per sample (m/s^2)."""
    accel_bias_std: float = 0.02
    """Turn-on accelerometer bias, drawn once per run (m/s^2)."""
    accel_bias_walk: float = 2e-4
    """Accelerometer bias random walk (m/s^2/sqrt(s))."""
    gyro_noise_std: float = 0.003
    """White noise per sample (rad/s)."""
    gyro_bias_std: float = 2e-4
    """Turn-on gyro bias left after calibration (rad/s)."""
    gyro_bias_walk: float = 1e-5
    """Gyro bias random walk (rad/s/sqrt(s))."""
    gyro_bias_injected: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """A constant gyro bias injected by the ``gyro_bias`` effect (rad/s)."""


class Imu(_Base):
    """IMU: :class:`onboard.core.messages.Imu` samples of specific force and angular rate."""

    name = "imu"

    def __init__(self, cfg: ImuConfig, rng: np.random.Generator, name: str | None = None):
        super().__init__(cfg.rate_hz, rng, name)
        self.cfg = cfg
        self.accel_bias = cfg.accel_bias_std * rng.standard_normal(3)
        self.gyro_bias = cfg.gyro_bias_std * rng.standard_normal(3)
        self._injected = np.asarray(cfg.gyro_bias_injected, dtype=float)
        self._sq = math.sqrt(1.0 / cfg.rate_hz)

    @property
    def total_gyro_bias(self) -> np.ndarray:
        """The gyro bias right now, calibration residue plus injected (rad/s, body)."""
        return self.gyro_bias + self._injected

    def measure(self, world: WorldView) -> list[Sample]:
        c = self.cfg
        nv = self.rng.standard_normal(12)
        self.accel_bias += c.accel_bias_walk * self._sq * nv[6:9]
        self.gyro_bias += c.gyro_bias_walk * self._sq * nv[9:12]
        n = nv.tolist()
        f = world.specific_force
        w = world.angular_rate
        ab = self.accel_bias.tolist()
        gb = (self.gyro_bias + self._injected).tolist()
        an, gn = c.accel_noise_std, c.gyro_noise_std
        return [ImuSample(
            t=world.t, source=self.name,
            accel_x=f[0] + ab[0] + an * n[0], accel_y=f[1] + ab[1] + an * n[1],
            accel_z=f[2] + ab[2] + an * n[2],
            gyro_x=w[0] + gb[0] + gn * n[3], gyro_y=w[1] + gb[1] + gn * n[4],
            gyro_z=w[2] + gb[2] + gn * n[5],
        )]

    def error_state(self) -> dict[str, float]:
        gb = self.total_gyro_bias
        ab = self.accel_bias
        return {"sensor.gyro_bias_x": float(gb[0]), "sensor.gyro_bias_y": float(gb[1]),
                "sensor.gyro_bias_z": float(gb[2]), "sensor.accel_bias_x": float(ab[0]),
                "sensor.accel_bias_y": float(ab[1]), "sensor.accel_bias_z": float(ab[2])}


# --------------------------------------------------------------------------- compass / AHRS


@dataclass(frozen=True, kw_only=True)
class CompassConfig:
    """Magnetic compass (AHRS heading) error model (rad, Hz).

    Heading error = ``offset_rad + hard_iron_rad sin(psi + hard_iron_phase_rad)
    + soft_iron_rad sin(2 psi + soft_iron_phase_rad) + motor_rad_per_thrust * thrust``
    + white noise ``noise_std_rad``. ``compass_deviation`` sets the hard-iron term,
    ``heading_bias`` adds to ``offset_rad``.
    """

    rate_hz: float = 10.0
    noise_std_rad: float = 0.01
    offset_rad: float = 0.0
    hard_iron_rad: float = 0.0
    hard_iron_phase_rad: float = 0.0
    soft_iron_rad: float = 0.0
    soft_iron_phase_rad: float = 0.0
    motor_rad_per_thrust: float = 0.0
    """Heading error at full thrust (rad), from the motor current's magnetic field."""
    attitude_noise_std_rad: float = 0.005
    """White noise on the AHRS roll and pitch (rad)."""
    emit_attitude: bool = True
    """Also emit :class:`Attitude` (roll, pitch, the same yaw, gyro rates)."""
    steps: tuple[tuple[float, float, float], ...] = ()
    """Scheduled heading steps ``(start_s, duration_s, radians)``: the heading reads
    ``radians`` more while in the window (the ``compass_step`` fault: a magnetic
    disturbance, a steel hull alongside; ``duration_s`` inf = permanent)."""
    invalid_windows: tuple[tuple[float, float], ...] = ()
    """Scheduled windows ``(start_s, duration_s)`` without a valid heading: no
    :class:`Heading` in them (the AHRS attitude goes on), on the NMEA output an empty HDT
    per epoch, as the Shenzhen USV's dual-antenna receiver in ``../shared/data`` sends
    ``$GPHDT,,T`` for 4 of its 3230 epochs (once 3 in a row). No scenario sets it."""


class Compass(_Base):
    """Compass and AHRS: :class:`Heading` and :class:`Attitude` samples.

    The AHRS reports the compass heading as yaw and the IMU's gyro (with its bias) as rates,
    so ``imu`` (an :class:`Imu`) is passed in to share its bias.
    """

    name = "compass"

    def __init__(self, cfg: CompassConfig, rng: np.random.Generator, imu: Imu | None = None,
                 name: str | None = None) -> None:
        super().__init__(cfg.rate_hz, rng, name)
        self.cfg = cfg
        self.imu = imu
        self.last_error = 0.0
        self.report_invalid = False
        """Report each heading epoch in ``invalid_windows`` as a :class:`HeadingInvalid`;
        False: nothing."""

    def deviation(self, psi: float, thrust: float) -> float:
        """Deterministic heading error (rad) at true heading ``psi`` and ``thrust``."""
        c = self.cfg
        return (c.offset_rad + c.hard_iron_rad * math.sin(psi + c.hard_iron_phase_rad)
                + c.soft_iron_rad * math.sin(2.0 * psi + c.soft_iron_phase_rad)
                + c.motor_rad_per_thrust * thrust)

    def measure(self, world: WorldView) -> list[Sample]:
        c = self.cfg
        tr = world.truth
        n = self.rng.standard_normal(6).tolist()
        err = self.deviation(tr.yaw, world.thrust) + c.noise_std_rad * n[0]
        for start, dur, rad in c.steps:
            if start <= world.t < start + dur:
                err += rad
        self.last_error = err
        psi = wrap_2pi(tr.yaw + err)
        out: list[Sample] = []
        if not in_windows(world.t, c.invalid_windows):
            out.append(Heading(t=world.t, source=self.name, heading_rad=psi))
        elif self.report_invalid:
            out.append(HeadingInvalid(t=world.t, source=self.name))
        if c.emit_attitude:
            w = world.angular_rate
            if self.imu is not None:
                gb = self.imu.total_gyro_bias.tolist()
                gn = self.imu.cfg.gyro_noise_std
            else:
                gb, gn = (0.0, 0.0, 0.0), 0.0
            an = c.attitude_noise_std_rad
            out.append(Attitude(
                t=world.t, source="ahrs",
                roll_rad=wrap_pi(tr.roll + an * n[1]), pitch_rad=tr.pitch + an * n[2],
                yaw_rad=wrap_pi(psi),
                roll_rate_rps=w[0] + gb[0] + gn * n[3],
                pitch_rate_rps=w[1] + gb[1] + gn * n[4],
                yaw_rate_rps=w[2] + gb[2] + gn * n[5],
            ))
        return out

    def error_state(self) -> dict[str, float]:
        return {"sensor.heading_error": float(self.last_error)}


# --------------------------------------------------------------------------- DVL


@dataclass(frozen=True, kw_only=True)
class DvlConfig:
    """Doppler velocity log (m/s, m, Hz). Defaults: a Water Linked A50-class instrument."""

    rate_hz: float = 5.0
    velocity_std_mps: float = 0.005
    """White noise per axis at zero altitude (m/s)."""
    velocity_std_per_m: float = 0.0002
    """Noise growth with altitude (m/s per m)."""
    min_altitude_m: float = 0.05
    max_altitude_m: float = 50.0
    """Beyond this range the bottom is lost (m)."""
    altitude_std_m: float = 0.02
    dropout_rate_hz: float = 0.002
    """Random lock losses per second (bubbles, fish, steep slopes)."""
    dropout_mean_s: float = 2.0
    water_track: bool = False
    """Also report velocity through water (track ``"water"``)."""
    dead_reckoning: bool = True
    """Also report the DVL's own dead-reckoned position (:class:`DvlPosition`)."""
    invalid_fom_mps: float = 2.0
    """Figure of merit reported without lock (the A50 reports a large value)."""
    fom_scale: float = 1.0
    """RMS of the reported figure of merit over the noise's std (1: the noise's own std,
    the default; the A50 at rest: 0.53-0.62, :data:`A50_FOM`; module docstring)."""
    fom_log_std: float = 0.0
    """Std of the log of the figure of merit about ``fom_scale`` times the noise's std (0:
    none, the default; the A50: 0.10 at rest, 0.33-0.34 driven about its speed trend)."""
    fom_tau_s: float = 0.15
    """Correlation time of that log (s; the A50: 0.30 s at rest, 0.11-0.12 s driven)."""
    quality_invalid_prob: float = 0.0
    """Probability that a locked bottom-track report is flagged invalid (0, the default;
    the capture, driven: 2.5-4.5 %)."""
    quality_invalid_noise_factor: float = 2.5
    """Velocity noise of such a report, in multiples of the noise's std."""
    quality_invalid_fom_factor: float = 1.5
    """Figure of merit of such a report over a valid one's (the capture: a median 1.4-1.7)."""
    lock_loss_windows: tuple[tuple[float, float], ...] = ()
    """Scheduled bottom-lock losses ``(start_s, duration_s)`` (the ``dvl_lock_loss``
    fault: soft mud, a steep slope, aeration)."""


A50_FOM: dict[str, float] = {"fom_scale": 0.55, "fom_log_std": 0.3, "fom_tau_s": 0.15,
                             "quality_invalid_prob": 0.03}
"""The :class:`DvlConfig` fields of a figure of merit as the Water Linked A50's (module
docstring: its scale, wander and memory, and its reports flagged invalid while locked,
from the capture in ``../shared/data``): ``DvlConfig(**A50_FOM)``. Not the default: the
default figure of merit is the noise's own std, which the ESESO takes as each report's
variance (docs/eseso-mpc.md, "DVL": what this one does to its closed loop)."""


class Dvl(_Base):
    """DVL: :class:`DvlVelocity` (body frame) and :class:`DvlPosition` samples."""

    name = "dvl"

    def __init__(self, cfg: DvlConfig, rng: np.random.Generator, name: str | None = None):
        super().__init__(cfg.rate_hz, rng, name)
        self.cfg = cfg
        self._outages = _Outages(cfg.dropout_rate_hz, cfg.dropout_mean_s, rng)
        self._t_last: float | None = None
        self.pos = np.zeros(3)
        self.locked = False
        self.lock_losses = 0
        self._fom_rng = rng.spawn(1)[0]
        """The figure of merit's and quality flags' own stream (spawning draws nothing from
        ``rng``: the velocity noise is the same with or without them)."""
        self._fom_x = float(self._fom_rng.standard_normal())
        """The unit Gauss-Markov state of the figure of merit's log."""
        self.quality_invalid = 0
        """Locked reports flagged invalid so far."""

    def measure(self, world: WorldView) -> list[Sample]:
        c = self.cfg
        t = world.t
        dt = 1.0 / self.rate_hz if self._t_last is None else t - self._t_last
        self._t_last = t
        tr = world.truth
        alt = world.altitude
        n = self.rng.standard_normal(7).tolist()
        dropped = self._outages.active(t, dt) or in_windows(t, c.lock_loss_windows)
        valid = (alt is not None and c.min_altitude_m <= alt <= c.max_altitude_m
                 and not dropped)
        if self.locked and not valid:
            self.lock_losses += 1
        self.locked = valid
        phi = math.exp(-dt / c.fom_tau_s) if c.fom_tau_s > 0.0 else 0.0
        self._fom_x = (phi * self._fom_x
                       + math.sqrt(1.0 - phi * phi) * float(self._fom_rng.standard_normal()))
        # fom = fom_scale * std * exp(s x - s^2), x a unit Gauss-Markov: its mean square is
        # (fom_scale * std)^2; x is independent of the velocity noise n
        fom_factor = c.fom_scale * math.exp(c.fom_log_std * self._fom_x - c.fom_log_std ** 2)
        flagged = float(self._fom_rng.random()) < c.quality_invalid_prob
        out: list[Sample] = []
        if valid:
            std = c.velocity_std_mps + c.velocity_std_per_m * alt
            fom = std * fom_factor
            k = 1.0
            if flagged:
                self.quality_invalid += 1
                k, fom = c.quality_invalid_noise_factor, c.quality_invalid_fom_factor * fom
            vx = tr.u + k * std * n[0]
            vy = tr.v + k * std * n[1]
            vz = tr.w + k * std * n[2]
            var = fom * fom
            out.append(DvlVelocity(
                t=t, source=self.name, vx=vx, vy=vy, vz=vz, track="bottom", valid=not flagged,
                fom_mps=fom, covariance=(var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, var),
                altitude_m=max(0.0, alt + c.altitude_std_m * n[6]),
            ))
            if c.dead_reckoning and not flagged:
                self.pos += dt * np.array(body_to_ned_fast(tr.roll, tr.pitch, tr.yaw, (vx, vy, vz)))
        else:
            out.append(DvlVelocity(t=t, source=self.name, vx=0.0, vy=0.0, vz=0.0,
                                   track="bottom", valid=False, fom_mps=c.invalid_fom_mps,
                                   altitude_m=None))
        if c.water_track:
            if not dropped:
                std = c.velocity_std_mps * 2.0
                out.append(DvlVelocity(
                    t=t, source=self.name, vx=tr.u_r + std * n[3], vy=tr.v_r + std * n[4],
                    vz=tr.w_r + std * n[5], track="water", valid=True,
                    fom_mps=std * fom_factor))
            else:
                out.append(DvlVelocity(t=t, source=self.name, vx=0.0, vy=0.0, vz=0.0,
                                       track="water", valid=False,
                                       fom_mps=c.invalid_fom_mps))
        if c.dead_reckoning:
            out.append(DvlPosition(t=t, source=self.name, north_m=float(self.pos[0]),
                                   east_m=float(self.pos[1]), down_m=float(self.pos[2]),
                                   roll_rad=tr.roll, pitch_rad=tr.pitch, yaw_rad=tr.yaw))
        return out

    def error_state(self) -> dict[str, float]:
        return {"sensor.dvl_locked": 1.0 if self.locked else 0.0}


# --------------------------------------------------------------------------- depth


@dataclass(frozen=True, kw_only=True)
class DepthConfig:
    """Pressure depth sensor (Bar30 class): m, Pa, kg/m^3, Hz."""

    rate_hz: float = 10.0
    depth_std_m: float = 0.02
    water_density_kgm3: float = 1025.0
    surface_pressure_pa: float = 101325.0
    temperature_c: float = 12.0


class DepthSensor(_Base):
    """Depth: :class:`Depth` samples with the absolute pressure that gave them."""

    name = "depth"

    def __init__(self, cfg: DepthConfig, rng: np.random.Generator, name: str | None = None):
        super().__init__(cfg.rate_hz, rng, name)
        self.cfg = cfg

    def measure(self, world: WorldView) -> list[Sample]:
        c = self.cfg
        d = world.truth.down + c.depth_std_m * float(self.rng.standard_normal())
        p = c.surface_pressure_pa + c.water_density_kgm3 * GRAVITY * d
        return [Depth(t=world.t, source=self.name, depth_m=d, pressure_pa=p,
                      temperature_c=c.temperature_c)]


# --------------------------------------------------------------------------- INS


@dataclass(frozen=True, kw_only=True)
class InsConfig:
    """Velocity over ground of a DVL-aided INS (m/s, s, Hz)."""

    rate_hz: float = 10.0
    velocity_std_mps: float = 0.01
    bias_std_mps: float = 0.005
    bias_tau_s: float = 300.0
    heading_std_rad: float | None = None
    """With a value, the INS reports its own heading (true, white noise of this one-sigma,
    rad) with each velocity (``VelocityOverGround.heading_rad``; GLOBAL_POSITION_INT
    ``hdg``); None: no heading of its own (``hdg`` is then the AHRS yaw)."""


class Ins(_Base):
    """DVL-aided INS: :class:`VelocityOverGround` samples (earth frame)."""

    name = "ins"

    def __init__(self, cfg: InsConfig, rng: np.random.Generator, name: str | None = None):
        super().__init__(cfg.rate_hz, rng, name)
        self.cfg = cfg
        self.bias = cfg.bias_std_mps * rng.standard_normal(3)

    def measure(self, world: WorldView) -> list[Sample]:
        c = self.cfg
        self.bias = _gauss_markov(self.bias, 1.0 / self.rate_hz, c.bias_tau_s,
                                  c.bias_std_mps, self.rng)
        n = self.rng.standard_normal(3).tolist()
        b = self.bias.tolist()
        v = world.v_ned
        s = c.velocity_std_mps
        psi = None
        if c.heading_std_rad is not None:
            psi = wrap_2pi(world.truth.yaw + c.heading_std_rad * float(self.rng.standard_normal()))
        return [VelocityOverGround(
            t=world.t, source=self.name,
            v_north_mps=v[0] + b[0] + s * n[0],
            v_east_mps=v[1] + b[1] + s * n[1],
            v_down_mps=v[2] + b[2] + s * n[2], heading_rad=psi)]

    def error_state(self) -> dict[str, float]:
        return {"sensor.ins_bias_north": float(self.bias[0]),
                "sensor.ins_bias_east": float(self.bias[1])}


# --------------------------------------------------------------------------- actuators


@dataclass(frozen=True, kw_only=True)
class PwmChannel:
    """One PWM output: normalized command in [-1, 1] to a pulse width (us).

    ``pwm = neutral_us + x * half_range_us`` (negated when ``reverse``), rounded to an
    integer microsecond and saturated to ``[min_us, max_us]``. The ESC/servo sees the pulse;
    within ``deadband_us`` of neutral it does nothing (the plant receives 0).
    """

    channel: int
    """Output channel number, 1 first (SERVOn)."""
    function: int = 0
    """ArduPilot SERVOn_FUNCTION (26 steering, 70 throttle, 73/74 left/right, 33.. motors)."""
    neutral_us: float = 1500.0
    half_range_us: float = 400.0
    min_us: float = 1100.0
    max_us: float = 1900.0
    deadband_us: float = 0.0
    reverse: bool = False


@dataclass(frozen=True, kw_only=True)
class ActuatorConfig:
    """The vehicle's PWM outputs and the rate SERVO_OUTPUT_RAW is reported at (Hz)."""

    channels: tuple[PwmChannel, ...] = ()
    rate_hz: float = 10.0


class ActuatorModel(_Base):
    """Commanded normalized values -> PWM -> what the plant actually receives.

    :meth:`apply` is called by the runner at every control step: it returns the effective
    normalized values (quantized to 1 us, saturated, deadband applied) that drive the
    plant. :meth:`measure` reports the PWM outputs as :class:`ActuatorOutputs` (channels
    1..max, unused channels 0).
    """

    name = "actuators"

    def __init__(self, cfg: ActuatorConfig, rng: np.random.Generator,
                 name: str | None = None) -> None:
        super().__init__(cfg.rate_hz, rng, name)
        self.cfg = cfg
        n = max((ch.channel for ch in cfg.channels), default=0)
        self.pwm = [0.0] * max(n, 8)
        for ch in cfg.channels:
            self.pwm[ch.channel - 1] = ch.neutral_us

    def apply(self, values: Sequence[float]) -> tuple[float, ...]:
        """PWM for each configured channel from ``values`` (same order); effective values."""
        eff = []
        for ch, x in zip(self.cfg.channels, values):
            sgn = -1.0 if ch.reverse else 1.0
            pwm = float(round(ch.neutral_us + sgn * x * ch.half_range_us))
            pwm = min(max(pwm, ch.min_us), max(ch.max_us, ch.min_us))
            self.pwm[ch.channel - 1] = pwm
            d = pwm - ch.neutral_us
            if abs(d) <= ch.deadband_us:
                eff.append(0.0)
            else:
                eff.append(max(-1.0, min(1.0, sgn * d / ch.half_range_us)))
        return tuple(eff)

    def measure(self, world: WorldView) -> list[Sample]:
        return [ActuatorOutputs(t=world.t, source=self.name, pwm_us=tuple(self.pwm))]


@dataclass(frozen=True, kw_only=True)
class RpmConfig:
    """Shaft-speed sensor (rev/min, Hz)."""

    rate_hz: float = 10.0
    noise_std_rpm: float = 5.0


class RpmSensor(_Base):
    """Propeller speed: :class:`PropellerRpm` from the true shaft speed plus white noise."""

    name = "rpm"

    def __init__(self, cfg: RpmConfig, rng: np.random.Generator, name: str | None = None):
        super().__init__(cfg.rate_hz, rng, name)
        self.cfg = cfg

    def measure(self, world: WorldView) -> list[Sample]:
        if not world.shaft_rpm:
            return []
        n = self.rng.standard_normal(len(world.shaft_rpm))
        return [PropellerRpm(t=world.t, source=self.name, rpm=tuple(
            float(round(r + self.cfg.noise_std_rpm * e, 1)) for r, e in zip(world.shaft_rpm, n)))]


# --------------------------------------------------------------------------- the suite


@dataclass(frozen=True, kw_only=True)
class SensorSuiteConfig:
    """Which sensors a vehicle carries and their error models (None = not fitted)."""

    gnss: GnssConfig | None = None
    imu: ImuConfig | None = None
    compass: CompassConfig | None = None
    dvl: DvlConfig | None = None
    depth: DepthConfig | None = None
    ins: InsConfig | None = None
    rpm: RpmConfig | None = None
    actuators: ActuatorConfig = field(default_factory=ActuatorConfig)


def build_sensors(cfg: SensorSuiteConfig, origin: GeoOrigin,
                  seed: int) -> tuple[list[Sensor], ActuatorModel]:
    """Instantiate the suite for one run; each sensor seeded from ``seed`` and its name."""
    sensors: list[Sensor] = []
    imu = None
    if cfg.imu is not None:
        imu = Imu(cfg.imu, sensor_rng(seed, "imu"))
        sensors.append(imu)
    if cfg.gnss is not None:
        sensors.append(Gnss(cfg.gnss, origin, sensor_rng(seed, "gnss")))
    if cfg.compass is not None:
        sensors.append(Compass(cfg.compass, sensor_rng(seed, "compass"), imu=imu))
    if cfg.dvl is not None:
        sensors.append(Dvl(cfg.dvl, sensor_rng(seed, "dvl")))
    if cfg.depth is not None:
        sensors.append(DepthSensor(cfg.depth, sensor_rng(seed, "depth")))
    if cfg.ins is not None:
        sensors.append(Ins(cfg.ins, sensor_rng(seed, "ins")))
    if cfg.rpm is not None:
        sensors.append(RpmSensor(cfg.rpm, sensor_rng(seed, "rpm")))
    actuators = ActuatorModel(cfg.actuators, sensor_rng(seed, "actuators"))
    sensors.append(actuators)
    return sensors, actuators
