"""Error-state extended state observer (ESESO) of a BlueROV2-class vehicle.

Paper: L.-Y. Lo, Y. Hu, B. Li, C.-Y. Wen, Y. Yang, "An adaptive model predictive control for
unmanned underwater vehicles subject to external disturbances and measurement noise"
(``../shared/papers/eseso-ampc-bluerov2.txt``), section III; spec: ``algorithms.md`` §5.1.

An error-state Kalman filter on ``R^6 x SO(3) x R^12`` (paper eq. 5). Nominal state::

    p   (3) position, NED earth frame, m
    v   (3) velocity over ground, NED, m/s
    R   SO(3) body(FRD)-to-earth(NED) rotation
    b_a (3) accelerometer bias, body, m/s^2
    b_g (3) gyro bias, body, rad/s
    g   (3) gravity, NED, m/s^2 (nominal [0, 0, +9.81]; the paper's code is z-up and
            starts from [0, 0, -9.81])
    xi  (3) lumped disturbance force, body FRD, N

Error state (21 + 2): ``dx = [dp, dv, dtheta, db_a, db_g, dg, dxi, db_ins]`` with the right
(local) perturbation ``R_true = R Exp(dtheta)`` (paper eqs. 6, 9). ``b_ins`` (north, east,
m/s) is the bias of the INS velocity over ground, not in the paper: an aided INS's velocity
error is correlated over minutes (a first-order Gauss-Markov process, ``ins_bias_std_mps``,
``ins_bias_tau_s``), so as white measurement noise it is wrong whatever R is: too small
and the filter follows the INS bias, too large (the GNSS velocity R of 0.1 m/s it had
before, 20x its total variance) and the innovations are far smaller than S (NIS 0.1 for 2;
docs/fuzzing.md finding 8).

* **Propagation** at every IMU sample (paper eqs. 10-13; Sola, "Quaternion kinematics for
  the error-state Kalman filter", 2017, §5), over the real interval since the previous
  sample, which the sample's mean specific force and rate drive (an IMU's delta-velocity /
  anti-aliased output belongs to the interval ending at its stamp). ``F[dtheta, db_g]`` is
  the exact ``-Jr(w dt) dt``. ``xi`` is propagated either as a constant in the body frame
  (the paper's random walk, ``disturbance_model = "body_fixed"``) or, by default, as a
  force fixed in the earth frame whose body components turn with the vehicle
  (``xi <- Exp(-w dt) xi``): a push, a tether or a current drag is earth-fixed, and on the
  paper's 2 m circle the body components turn at up to 0.75 rad/s, which a random walk
  cannot follow.
* **Updates** (paper eqs. 14, 16), each through :meth:`Eseso._update`, Joseph form, with
  the innovation ``y``, its covariance ``S`` and the NIS kept for :meth:`Eseso.health`
  and a chi-square gate (99.9 %; after ``max_consecutive_rejects`` gated samples in a row
  the channel is fused again, down-weighted, so a sensor cannot be locked out for good):
  GNSS horizontal position and velocity (only at the surface: a fix while the filter is
  deeper than ``gnss_max_depth_m`` is rejected), velocity over ground (INS: ``v + b_ins``,
  R its white noise ``ins_velocity_std_mps``), depth, DVL bottom-track velocity (body
  frame, its figure of merit as sigma), attitude (``Log(R^T R_meas)``, R the roll, pitch
  and yaw noise turned into body axes: roll/pitch ``attitude_std_rad``, yaw the compass
  heading's, which an AHRS reports as its yaw), heading (only without an attitude stream,
  which carries the same yaw), and the thrust model ``h_tau`` below at every IMU sample
  while a thruster command is fresh.
* **Injection and reset** (paper eqs. 16d, 17, 18): every component of ``dx`` is injected
  (``v`` once, biases and gravity too, unlike the public code), then ``P <- G P G^T``
  with the reset Jacobian ``G = blockdiag(I, I, I - [dtheta/2]x, I, I, I, I)``
  (Sola 2017, §6.3).

Thrust model (paper eq. 14b, re-derived in NED/FRD with the Coriolis terms the paper
drops, because on a 2 m circle at 1.5 m/s they are 2-15 N, more than the 4 N target).
With ``f = a_m - b_a`` (specific force), ``w = w_m - b_g``, ``nu = R^T v``,
``g_B = R^T g`` and the translational rigid-body law ``m (nu' + w x nu) = m R^T a_earth
= m (f + g_B)``::

    tau = h_tau(x) = M (f + g_B) - A (w x nu) + w x (A nu) + D(nu) nu - (W - B) R^T e3 - xi
                     + m (w' x r_g + w x (w x r_g))

with ``M = m I + A``, ``A = diag(X_udot, Y_vdot, Z_wdot)`` (positive added masses),
``D(nu) = diag(d_l + d_nl |nu|)`` (positive damping), ``W - B`` the weight minus the
buoyancy (a positively buoyant vehicle has ``W - B < 0``), ``r_g = (0, 0, z_G)`` the centre
of gravity and ``w'`` the angular acceleration from differenced gyro samples (with
z_G = 0.2 m the ``m w' x r_g`` term reaches 50 N when a thruster step rolls the vehicle;
its Jacobian is neglected). ``tau`` is the commanded thruster force in body axes: the
force rows of the allocation matrix times the per-thruster forces of the thrust curve
(``f = f_max c|c|`` for the T200). The paper's ``M_RB (u_a - b_a)`` misses the ``m g_B``
term, which only cancels against the weight if the restoring term is written with ``B``
alone; here both are explicit.

By default (``thrust_states = "disturbance"``, the paper's H with -I on ``dxi`` only) the
thrust update corrects the disturbance alone and carries the other states' uncertainty
in its noise (``R + H_o P_oo H_o^T``): through the damping slope (up to 66 N per m/s) the
full Jacobian makes it a velocity sensor too, which thruster lag or model errors would
drag away from the DVL (on the simulated circle both choices give the same figures,
docs/eseso-mpc.md). Its residual is down-weighted Huber-style above ``thrust_huber``: thruster steps
excite roll and pitch accelerations faster than the IMU rate resolves.

Position: from the first fused GNSS fix (the local origin), or without one from the
configured start point (``initial_north_m``/``initial_east_m``, a surveyed launch), then
dead-reckoned with the DVL; its std grows without GNSS.

All numbers in, numbers out; no I/O and no clock (``bench_step_cost`` is a bench helper
outside the pipeline).
"""

from __future__ import annotations

import math
from typing import Any, Literal, Mapping, Sequence

import msgspec
import numpy as np
from numpy.typing import NDArray

from onboard.core.config import Config, decode_section
from onboard.core.geo import LocalFrame, wrap_pi
from onboard.core.messages import (
    ActuatorCommand,
    Attitude,
    Depth,
    DvlVelocity,
    EstimateRecord,
    GnssFix,
    Heading,
    Imu,
    Sample,
    VelocityOverGround,
)
from onboard.core.so3 import (
    cross,
    euler_to_matrix,
    exp_so3,
    log_so3,
    matrix_to_euler,
    orthonormalize,
    right_jacobian,
    skew,
)

Array = NDArray[np.float64]

# error-state blocks (paper eq. 11), then the INS velocity bias (north, east)
P_, V_, TH, BA, BG, G_, XI = (slice(3 * i, 3 * i + 3) for i in range(7))
BI = slice(21, 23)
N_ERR = 23

E3 = np.array([0.0, 0.0, 1.0])

# chi-square 99.9 % quantiles for 1, 2, 3 degrees of freedom
CHI2_999 = {1: 10.83, 2: 13.82, 3: 16.27}

# BlueROV2 (standard, vectored frame) force rows of the allocation matrix, FRD body axes,
# per unit thruster force; thrusters 1-4 horizontal at 45 deg, 5-6 vertical. Matches the
# paper's K_alloc (algorithms.md §5.2) turned from its z-up body frame into FRD.
BLUEROV2_FORCE_ALLOCATION: tuple[tuple[float, ...], ...] = (
    (0.7071, 0.7071, -0.7071, -0.7071, 0.0, 0.0),
    (-0.7071, 0.7071, -0.7071, 0.7071, 0.0, 0.0),
    (0.0, 0.0, 0.0, 0.0, -1.0, -1.0),
)


class EsesoConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """``[pipelines.eseso]``: model, thrusters and noise of the ESESO.

    Vehicle parameters default to the paper's Table I (BlueROV2). Noise figures not given
    here come from ``[sensors]``. Defaults marked [DEFAULT] are ours (tuned on the
    ``bluerov2-circle`` scenario), not the paper's Q = 1e-3 I and
    R = diag(0.01 I, 0.02 I, 0.0006 I, 0.012 I), which are per-step numbers of a 50 Hz
    loop in unstated units.
    """

    enabled: bool = True
    vehicle_classes: list[str] = msgspec.field(default_factory=lambda: ["bluerov2"])
    """Vehicle classes the pipeline is built for (any class when ``enabled`` is set
    explicitly in the config)."""
    mass_kg: float = 11.26
    added_mass: list[float] = msgspec.field(default_factory=lambda: [1.7182, 0.0, 5.468])
    """X_udot, Y_vdot, Z_wdot as positive added masses (kg)."""
    damping_linear: list[float] = msgspec.field(default_factory=lambda: [11.7391, 20.0, 31.8678])
    """Positive linear damping d_l (N s/m); the paper lists them negated."""
    damping_quadratic: list[float] = msgspec.field(default_factory=lambda: [18.18, 21.66, 36.99])
    """Positive quadratic damping d_nl (N s^2/m^2)."""
    cg_z_m: float = 0.2
    """Centre of gravity below the body origin (m), paper Table I (the public code has
    0.02); the IMU is taken at the origin."""
    weight_n: float = 112.8
    buoyancy_n: float = 114.8
    gravity_mps2: float = 9.81
    force_allocation: list[list[float]] = msgspec.field(
        default_factory=lambda: [list(r) for r in BLUEROV2_FORCE_ALLOCATION])
    """3 x n_thrusters: body force (N, FRD) per newton of each thruster."""
    thruster_max_forward_n: float = 40.0
    """Thrust (N) at normalized command +1 (T200 at ~14.8 V, as the SITL plant)."""
    thruster_max_reverse_n: float = 30.0
    """Thrust magnitude (N) at normalized command -1."""
    thruster_exponent: float = 2.0
    """Thrust = max * sign(c) |c|^exponent (1 = linear map, 2 = quadratic in command)."""
    thruster_deadband: float = 0.0
    """Normalized commands with |c| below this give no thrust."""
    disturbance_model: Literal["earth_fixed", "body_fixed"] = "earth_fixed"
    # process noise [DEFAULT]
    accel_bias_walk: float = 1e-4
    """Accelerometer bias random walk (m/s^2/sqrt(s))."""
    gyro_bias_walk: float = 1e-5
    """Gyro bias random walk (rad/s/sqrt(s))."""
    gravity_walk: float = 1e-6
    """Gravity random walk (m/s^2/sqrt(s)); it only absorbs a wrong nominal g."""
    disturbance_walk: float = 1.0
    """Disturbance random walk (N/sqrt(s))."""
    position_walk: float = 1e-3
    """Extra position random walk (m/sqrt(s)), keeps P well conditioned."""
    # measurement noise; None = from [sensors]
    ins_velocity_std_mps: float = 0.02
    """White noise of the INS velocity over ground per horizontal axis (m/s) [DEFAULT: the
    simulated DVL-aided INS of ``bluerov2-circle``, ``sitl.sensors.InsConfig``]."""
    ins_bias_std_mps: float = 0.01
    """Stationary std of the INS velocity bias (m/s), a first-order Gauss-Markov process
    carried as two error states (north, east): an aided INS's velocity error is correlated
    over minutes, so it is not white measurement noise."""
    ins_bias_tau_s: float = 300.0
    """Correlation time of the INS velocity bias (s)."""
    gnss_position_std_m: float | None = None
    gnss_velocity_std_mps: float | None = None
    depth_std_m: float | None = None
    dvl_velocity_std_mps: float | None = None
    attitude_std_rad: float = 0.01
    """Roll and pitch noise of the AHRS attitude (rad)."""
    attitude_yaw_std_rad: float | None = None
    """Yaw noise of the AHRS attitude (rad); None = the compass heading noise
    (``heading_std_rad``, else ``[sensors.compass]``): an AHRS reports the compass heading
    as its yaw."""
    heading_std_rad: float | None = None
    thrust_std_n: float = 3.0
    """Thrust-model error besides accelerometer noise (thruster lag, model error), N."""
    accel_std_mps2: float | None = None
    gyro_std_rps: float | None = None
    gnss_max_depth_m: float | None = None
    """Fixes received deeper than this are rejected (default sensors.depth.surface_depth_m)."""
    command_timeout_s: float = 0.5
    """A thruster command older than this is not used by the thrust update."""
    gate_sigma: float = 0.0
    """0 = chi-square 99.9 % gates; else the NIS gate is ``gate_sigma**2 * dof``."""
    thrust_states: Literal["disturbance", "all"] = "disturbance"
    """Which error states the thrust update corrects. ``"disturbance"`` (the paper's H,
    -I on dxi only): the other states' uncertainty is added to the update's noise
    instead (``R + H_o P_oo H_o^T``), so thruster and model errors cannot move the
    velocity. ``"all"``: the full Jacobian."""
    max_consecutive_rejects: int = 5
    """After this many gated samples in a row a channel is fused again, down-weighted by
    NIS / gate, so one bad spell cannot lock a sensor out for good."""
    thrust_huber: float = 16.0
    """Above this NIS the thrust update is down-weighted (R scaled by NIS / thrust_huber,
    a Huber-type robust update) instead of rejected: thruster steps excite roll and pitch
    accelerations faster than the IMU rate resolves, while a new push must still get in.
    0 = plain update."""
    initial_north_m: float = 0.0
    initial_east_m: float = 0.0
    """Start position (m) when no GNSS fix precedes the start (a surveyed launch point);
    positions are then relative to this point until a fix arrives."""
    # initial uncertainty
    initial_position_std_m: float = 1.0
    initial_velocity_std_mps: float = 0.3
    initial_attitude_std_rad: float = 0.05
    initial_accel_bias_std: float = 0.05
    initial_gyro_bias_std: float = 0.005
    initial_gravity_std: float = 0.01
    initial_disturbance_std_n: float = 40.0
    max_imu_gap_s: float = 0.5
    """A longer gap between IMU samples restarts the propagation clock (counted)."""


def _thrust(cmd: float, c: EsesoConfig) -> float:
    """Per-thruster force (N) of a normalized command in [-1, 1]."""
    if abs(cmd) <= c.thruster_deadband:
        return 0.0
    mag = min(abs(cmd), 1.0) ** c.thruster_exponent
    return mag * (c.thruster_max_forward_n if cmd > 0 else -c.thruster_max_reverse_n)


class Eseso:
    """The ESESO pipeline (``eseso``): state, disturbance force and their covariance.

    Inspectable attributes, filterpy-style: ``p, v, R, b_a, b_g, g, xi`` (nominal state),
    ``P`` (21 x 21 error covariance), and per channel the last innovation ``y``, its
    covariance ``S`` and ``nis`` in :attr:`last`.
    """

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
        self.m_vec = c.mass_kg + np.asarray(c.added_mass, float)  # diag of M, kg
        self.A = np.diag(np.asarray(c.added_mass, float))
        self.d_l = np.asarray(c.damping_linear, float)
        self.d_nl = np.asarray(c.damping_quadratic, float)
        self.K_alloc = np.asarray(c.force_allocation, float)
        if self.K_alloc.shape[0] != 3:
            raise ValueError("pipelines.eseso.force_allocation: expected 3 rows")

        def pick(v: float | None, default: float) -> float:
            return float(default if v is None else v)

        self.sig_a = pick(c.accel_std_mps2, s.imu.accel_std_mps2 if s else 0.05)
        self.sig_g = pick(c.gyro_std_rps, s.imu.gyro_std_rps if s else 0.005)
        self.r_gnss_p = pick(c.gnss_position_std_m, s.gnss.position_std_m if s else 2.0) ** 2
        self.r_gnss_v = pick(c.gnss_velocity_std_mps, s.gnss.velocity_std_mps if s else 0.1) ** 2
        self.r_depth = pick(c.depth_std_m, s.depth.depth_std_m if s else 0.02) ** 2
        self.r_dvl = pick(c.dvl_velocity_std_mps, s.dvl.velocity_std_mps if s else 0.01) ** 2
        self.r_head = pick(c.heading_std_rad, s.compass.heading_std_rad if s else 0.02) ** 2
        self.r_att = c.attitude_std_rad ** 2
        self.r_att_yaw = pick(c.attitude_yaw_std_rad, math.sqrt(self.r_head)) ** 2
        self.r_ins = c.ins_velocity_std_mps ** 2
        self.dvl_max_fom = s.dvl.max_fom_mps if s else 0.05
        self.gnss_max_depth = pick(c.gnss_max_depth_m, s.depth.surface_depth_m if s else 0.3)
        # thrust-update noise: accelerometer noise through M plus model error (N^2)
        self.R_tau = np.diag((self.m_vec * self.sig_a) ** 2 + c.thrust_std_n ** 2)

        self.initialized = False
        self.p = np.zeros(3)
        self.v = np.zeros(3)
        self.R = np.eye(3)
        self.b_a = np.zeros(3)
        self.b_g = np.zeros(3)
        self.g = np.array([0.0, 0.0, c.gravity_mps2])
        self.xi = np.zeros(3)
        self.b_ins = np.zeros(2)  # INS velocity bias, north/east (m/s)
        self.P = np.eye(N_ERR)
        self.F = np.eye(N_ERR)
        """The last propagation's error-state transition (for inspection and tests)."""
        self.frame: LocalFrame | None = None
        self._gnss_offset = np.zeros(2)
        self.t_imu: float | None = None
        self.f_m: Array | None = None  # last specific force (m/s^2)
        self.w_m: Array | None = None  # last angular rate (rad/s)
        self.wdot = np.zeros(3)  # angular acceleration from differenced gyro (rad/s^2)
        self.tau: Array | None = None  # last commanded body force (N)
        self.t_tau = -math.inf
        self._tau_hist: list[tuple[float, Array]] = []  # (t, body force) of held commands
        self._imu_hist: list[tuple[float, Array, Array]] = []  # last IMU (t, f, w), <= 2
        self.t_sensor: float | None = None
        self._pending_depth: float | None = None
        self._pending_att: Array | None = None
        self._accel_sum = np.zeros(3)
        self._accel_n = 0
        self.last: dict[str, dict[str, Array | float]] = {}
        self._consecutive: dict[str, int] = {}
        self._have_attitude = False
        self.counters: dict[str, int] = {}

    # ------------------------------------------------------------------ bookkeeping
    def _count(self, key: str) -> None:
        self.counters[key] = self.counters.get(key, 0) + 1

    def _initialize(self, R0: Array) -> None:
        """Start the filter at attitude ``R0``; position/velocity from what is known."""
        c = self.cfg
        self.R = orthonormalize(R0)
        self.p[0:2] = (c.initial_north_m, c.initial_east_m)
        if self._pending_depth is not None:
            self.p[2] = self._pending_depth
        sd = [c.initial_position_std_m] * 3 + [c.initial_velocity_std_mps] * 3
        sd += [c.initial_attitude_std_rad] * 3 + [c.initial_accel_bias_std] * 3
        sd += [c.initial_gyro_bias_std] * 3 + [c.initial_gravity_std] * 3
        sd += [c.initial_disturbance_std_n] * 3 + [c.ins_bias_std_mps] * 2
        self.P = np.diag(np.square(sd))
        self.initialized = True

    # ------------------------------------------------------------------ propagation
    def propagate(self, f_m: Array, w_m: Array, dt: float) -> None:
        """IMU propagation over ``dt`` (s): nominal state by paper eq. (10b), covariance by
        eqs. (11)-(13) with the Jacobian F of algorithms.md §5.1."""
        c = self.cfg
        f = f_m - self.b_a
        w = w_m - self.b_g
        Rf = self.R @ f
        acc = Rf + self.g
        dR = exp_so3(w * dt)
        dRt = dR.T
        F = np.eye(N_ERR)
        F[P_, V_] = np.eye(3) * dt
        F[P_, TH] = -0.5 * (self.R @ skew(f)) * dt * dt
        F[P_, BA] = -0.5 * self.R * dt * dt
        F[P_, G_] = 0.5 * np.eye(3) * dt * dt
        F[V_, TH] = -(self.R @ skew(f)) * dt
        F[V_, BA] = -self.R * dt
        F[V_, G_] = np.eye(3) * dt
        F[TH, TH] = dRt
        # exact in the gyro-bias error: Exp((w - db) dt) = Exp(w dt) Exp(-Jr(w dt) db dt)
        F[TH, BG] = -right_jacobian(w * dt) * dt
        if c.disturbance_model == "earth_fixed":
            F[XI, XI] = dRt
            F[XI, BG] = -(dRt @ skew(self.xi) @ right_jacobian(-w * dt)) * dt
        # INS velocity bias: first-order Gauss-Markov, exact discretization
        phi_ins = math.exp(-dt / c.ins_bias_tau_s) if c.ins_bias_tau_s > 0 else 0.0
        F[BI, BI] = np.eye(2) * phi_ins
        q = np.empty(N_ERR)
        q[P_] = c.position_walk ** 2 * dt
        q[V_] = (self.sig_a * dt) ** 2
        q[TH] = (self.sig_g * dt) ** 2
        q[BA] = c.accel_bias_walk ** 2 * dt
        q[BG] = c.gyro_bias_walk ** 2 * dt
        q[G_] = c.gravity_walk ** 2 * dt
        q[XI] = c.disturbance_walk ** 2 * dt
        q[BI] = c.ins_bias_std_mps ** 2 * (1.0 - phi_ins * phi_ins)
        # nominal state (10b)
        self.p = self.p + self.v * dt + 0.5 * acc * dt * dt
        self.v = self.v + acc * dt
        self.R = self.R @ dR
        if c.disturbance_model == "earth_fixed":
            self.xi = dRt @ self.xi
        self.b_ins = self.b_ins * phi_ins
        self.P = F @ self.P @ F.T
        self.P[np.diag_indices(N_ERR)] += q
        self.F = F

    # ------------------------------------------------------------------ update
    def _update(
        self, channel: str, y: Array, H: Array, Rm: Array, gate: float | None = None
    ) -> bool:
        """One Kalman update on the error state (paper eq. 16), Joseph form, then error
        injection (16d) and reset with its Jacobian (17, 18). ``y`` is the innovation
        (measurement minus prediction); returns False when the NIS gate rejects it."""
        PHt = self.P @ H.T
        S = H @ PHt + Rm
        S = 0.5 * (S + S.T)
        Sinv = np.linalg.inv(S)
        nis = float(y @ Sinv @ y)
        self.last[channel] = {"y": y.copy(), "S": np.diag(S).copy(), "nis": nis}
        if gate is None:
            if self.cfg.gate_sigma > 0:
                gate = self.cfg.gate_sigma ** 2 * len(y)
            else:
                gate = CHI2_999.get(len(y), 3.0 * len(y) + 8.0)
        if gate > 0 and nis > gate:
            self._count(f"rejected.{channel}.gate")
            n_rej = self._consecutive.get(channel, 0) + 1
            self._consecutive[channel] = n_rej
            if n_rej <= self.cfg.max_consecutive_rejects:
                return False
            # recover: fuse, down-weighted so that the NIS equals the gate
            self._count(f"recovered.{channel}")
            Rm = Rm * (nis / gate)
            S = H @ PHt + Rm
            Sinv = np.linalg.inv(0.5 * (S + S.T))
        self._consecutive[channel] = 0
        K = PHt @ Sinv
        dx = K @ y
        IKH = np.eye(N_ERR) - K @ H
        P = IKH @ self.P @ IKH.T + K @ Rm @ K.T
        self._inject(dx)
        # reset (17b): G = I except the attitude block, I - [dtheta/2]x (Sola eq. 287)
        G = np.eye(N_ERR)
        G[TH, TH] -= skew(0.5 * dx[TH])
        P = G @ P @ G.T
        self.P = 0.5 * (P + P.T)
        self._count(f"fused.{channel}")
        return True

    def _inject(self, dx: Array) -> None:
        """Error injection (paper eq. 16d): every component, velocity once."""
        self.p = self.p + dx[P_]
        self.v = self.v + dx[V_]
        self.R = self.R @ exp_so3(dx[TH])
        self.b_a = self.b_a + dx[BA]
        self.b_g = self.b_g + dx[BG]
        self.g = self.g + dx[G_]
        self.xi = self.xi + dx[XI]
        self.b_ins = self.b_ins + dx[BI]

    # ------------------------------------------------------------------ thrust model
    def h_tau(self, f_m: Array, w_m: Array, wdot: Array | None = None) -> tuple[Array, Array]:
        """Predicted thruster force (N, body) and its 3 x 21 Jacobian (module docstring).
        ``wdot`` is the angular acceleration (rad/s^2), zero when not given."""
        f = f_m - self.b_a
        w = w_m - self.b_g
        RT = self.R.T
        nu = RT @ self.v
        gB = RT @ self.g
        zB = RT @ E3
        Anu = self.A @ nu
        W_B = self.cfg.weight_n - self.cfg.buoyancy_n
        damp = (self.d_l + self.d_nl * np.abs(nu)) * nu
        h = (self.m_vec * (f + gB) - self.A @ cross(w, nu) + cross(w, Anu)
             + damp - W_B * zB - self.xi)
        r_g = np.array([0.0, 0.0, self.cfg.cg_z_m])
        if wdot is not None:
            h = h + self.cfg.mass_kg * (cross(wdot, r_g) + cross(w, cross(w, r_g)))
        J_nu = (-self.A @ skew(w) + skew(w) @ self.A
                + np.diag(self.d_l + 2.0 * self.d_nl * np.abs(nu)))
        J_w = self.A @ skew(nu) - skew(Anu)
        M = np.diag(self.m_vec)
        H = np.zeros((3, N_ERR))
        H[:, V_] = J_nu @ RT
        H[:, TH] = J_nu @ skew(nu) + M @ skew(gB) - W_B * skew(zB)
        H[:, BA] = -M
        H[:, BG] = -J_w
        H[:, G_] = M @ RT
        H[:, XI] = -np.eye(3)
        return h, H

    def _tau_mean(self, t0: float, t1: float) -> Array | None:
        """Time average (N, body) over [t0, t1] of the held thruster commands."""
        hist = self._tau_hist
        if not hist or t1 - hist[-1][0] > self.cfg.command_timeout_s:
            return None
        if t1 <= t0:
            return hist[-1][1]
        acc = np.zeros(3)
        covered = 0.0
        for i, (tc, tau) in enumerate(hist):
            start = max(tc, t0)
            end = min(hist[i + 1][0], t1) if i + 1 < len(hist) else t1
            if end > start:
                acc += tau * (end - start)
                covered += end - start
        if covered <= 0.0:
            return hist[-1][1]
        return acc / covered

    def _thrust_update_at_imu(self) -> None:
        """The thrust update for the IMU sample just received: its mean specific force and
        rate, the angular acceleration from the last two gyro samples, and the thruster
        force averaged over the sample's interval (commands are held between updates and
        may change within an IMU interval)."""
        hist = self._imu_hist
        if len(hist) < 2:
            return
        (t0, _, w0), (t1, f1, w1) = hist[-2:]
        tau = self._tau_mean(t0, t1)
        if tau is None:
            return
        self._thrust_update(f1, w1, (w1 - w0) / (t1 - t0), tau)

    def _thrust_update(self, f_m: Array, w_m: Array, wdot: Array, tau: Array) -> None:
        """Update on ``tau`` (N, body) = h_tau at specific force ``f_m``, rate ``w_m`` and
        angular acceleration ``wdot``."""
        h, H = self.h_tau(f_m, w_m, wdot)
        y = tau - h
        Rm = self.R_tau
        if self.cfg.thrust_states == "disturbance":
            Ho = H.copy()
            Ho[:, XI] = 0.0
            Rm = Rm + Ho @ self.P @ Ho.T
            H = np.zeros_like(H)
            H[:, XI] = -np.eye(3)
        k = self.cfg.thrust_huber
        if k > 0:
            S = H @ self.P @ H.T + Rm
            nis = float(y @ np.linalg.solve(S, y))
            if nis > k:
                Rm = Rm * (nis / k)
                self._count("thrust.downweighted")
        self._update("thrust", y, H, Rm, gate=0.0)

    # ------------------------------------------------------------------ samples
    def _on_imu(self, s: Imu) -> None:
        f_m = np.array([s.accel_x, s.accel_y, s.accel_z])
        w_m = np.array([s.gyro_x, s.gyro_y, s.gyro_z])
        if not (np.all(np.isfinite(f_m)) and np.all(np.isfinite(w_m))):
            self._count("rejected.imu.nonfinite")
            return
        if not self.initialized:
            if self._pending_att is not None:
                self._initialize(self._pending_att)
            else:
                # level from gravity after 1 s of samples, yaw unknown (std pi)
                self._accel_sum += f_m
                self._accel_n += 1
                if self._accel_n < 50:
                    self.t_imu = s.t
                    return
                a = -self._accel_sum / self._accel_n  # points down in body axes
                roll = math.atan2(a[1], a[2])
                pitch = math.atan2(-a[0], math.hypot(a[1], a[2]))
                self._initialize(euler_to_matrix(roll, pitch, 0.0))
                self.P[8, 8] = math.pi ** 2
            self.t_imu = s.t
            self.f_m, self.w_m = f_m, w_m
            return
        if self.t_imu is None:
            self.t_imu = s.t
        dt = s.t - self.t_imu
        if dt <= 0.0:
            self._count("rejected.imu.time")
            return
        if dt > self.cfg.max_imu_gap_s:
            self._count("imu_gap")
            dt = self.cfg.max_imu_gap_s
        # the sample is the mean over the interval ending at its stamp (an IMU's
        # delta-velocity / delta-angle, or its anti-aliasing filter): it drives [t_prev, t]
        self.propagate(f_m, w_m, dt)
        self.t_imu = s.t
        if self.w_m is not None:
            self.wdot = (w_m - self.w_m) / dt
        self.f_m, self.w_m = f_m, w_m
        self._imu_hist.append((s.t, f_m, w_m))
        if len(self._imu_hist) > 2:
            del self._imu_hist[0]
        self._thrust_update_at_imu()

    def _on_command(self, s: ActuatorCommand) -> None:
        if s.thrusters is None:
            return
        n = self.K_alloc.shape[1]
        if len(s.thrusters) != n:
            self._count("rejected.command.thruster_count")
            return
        forces = np.array([_thrust(float(cmd), self.cfg) for cmd in s.thrusters])
        if not np.all(np.isfinite(forces)):
            self._count("rejected.command.nonfinite")
            return
        self.tau = self.K_alloc @ forces
        self.t_tau = s.t
        self._tau_hist.append((s.t, self.tau))
        # keep what the last IMU intervals can still need
        while len(self._tau_hist) > 2 and self._tau_hist[1][0] <= s.t - 1.0:
            del self._tau_hist[0]
        if len(self._tau_hist) > 50:
            del self._tau_hist[0]

    def _on_gnss(self, s: GnssFix) -> None:
        if s.fix_quality <= 0:
            self._count("rejected.gnss.no_fix")
            return
        if self.p[2] > self.gnss_max_depth and self.P[2, 2] < 1.0:
            self._count("rejected.gnss.submerged")
            return
        if self.frame is None:
            self.frame = LocalFrame(s.lat_deg, s.lon_deg)
            self._gnss_offset = self.p[:2].copy()
        n, e = self.frame.to_ne(s.lat_deg, s.lon_deg)
        z = np.array([n, e]) + self._gnss_offset
        r_p = (s.h_acc_m ** 2) if s.h_acc_m else self.r_gnss_p
        H = np.zeros((2, N_ERR))
        H[:, 0:2] = np.eye(2)
        self._update("gnss_pos", z - self.p[:2], H, np.eye(2) * r_p)
        if s.sog_mps is not None and s.cog_rad is not None:
            vz = s.sog_mps * np.array([math.cos(s.cog_rad), math.sin(s.cog_rad)])
            Hv = np.zeros((2, N_ERR))
            Hv[:, 3:5] = np.eye(2)
            self._update("gnss_vel", vz - self.v[:2], Hv, np.eye(2) * self.r_gnss_v)

    def _on_vog(self, s: VelocityOverGround) -> None:
        # z = v_NE + b_ins + white noise: the INS's correlated error is a state (BI), only
        # its white part is R (docs/eseso-mpc.md, "Measurement noise and consistency")
        vz = np.array([s.v_north_mps, s.v_east_mps])
        if not np.all(np.isfinite(vz)):
            self._count("rejected.vog.nonfinite")
            return
        H = np.zeros((2, N_ERR))
        H[:, 3:5] = np.eye(2)
        H[:, BI] = np.eye(2)
        self._update("vog", vz - self.v[:2] - self.b_ins, H, np.eye(2) * self.r_ins)

    def _on_depth(self, s: Depth) -> None:
        H = np.zeros((1, N_ERR))
        H[0, 2] = 1.0
        self._update("depth", np.array([s.depth_m - self.p[2]]), H, np.array([[self.r_depth]]))

    def _on_dvl(self, s: DvlVelocity) -> None:
        if not s.valid:
            self._count("rejected.dvl.invalid")
            return
        if s.track != "bottom":
            self._count("rejected.dvl.water_track")
            return
        if s.fom_mps is not None and s.fom_mps > self.dvl_max_fom:
            self._count("rejected.dvl.fom")
            return
        nu = self.R.T @ self.v
        H = np.zeros((3, N_ERR))
        H[:, V_] = self.R.T
        H[:, TH] = skew(nu)
        r = (s.fom_mps ** 2) if s.fom_mps else self.r_dvl
        self._update("dvl", np.array([s.vx, s.vy, s.vz]) - nu, H, np.eye(3) * r)

    def _on_attitude(self, s: Attitude) -> None:
        R_meas = euler_to_matrix(s.roll_rad, s.pitch_rad, s.yaw_rad)
        H = np.zeros((3, N_ERR))
        H[:, TH] = np.eye(3)
        # independent roll, pitch, yaw noise into the body-frame rotation vector: the
        # Euler-rate-to-body-rate matrix (Fossen eq. 2.41 inverted)
        sr, cr = math.sin(s.roll_rad), math.cos(s.roll_rad)
        sp, cp = math.sin(s.pitch_rad), math.cos(s.pitch_rad)
        J = np.array([[1.0, 0.0, -sp], [0.0, cr, sr * cp], [0.0, -sr, cr * cp]])
        Rm = J @ np.diag([self.r_att, self.r_att, self.r_att_yaw]) @ J.T
        self._update("attitude", log_so3(self.R.T @ R_meas), H, Rm)

    def _on_heading(self, s: Heading) -> None:
        roll, pitch, yaw = matrix_to_euler(self.R)
        meas = s.heading_rad + (s.declination_rad or 0.0)
        H = np.zeros((1, N_ERR))
        # yaw rate from body rates: last row of T_Theta (Fossen eq. 2.41)
        cp = max(math.cos(pitch), 1e-3)
        H[0, TH] = [0.0, math.sin(roll) / cp, math.cos(roll) / cp]
        self._update("heading", np.array([wrap_pi(meas - yaw)]), H, np.array([[self.r_head]]))

    # ------------------------------------------------------------------ Pipeline API
    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        """Consume the samples (time-ordered) and return the estimates at tick ``t`` (s).

        IMU samples propagate the state (and trigger the thrust update while a thruster
        command is fresh); every other supported sample is one measurement update.
        """
        for s in samples:
            if isinstance(s, Imu):
                self._on_imu(s)
            elif isinstance(s, ActuatorCommand):
                self._on_command(s)
            elif not self.initialized:
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
                self._have_attitude = True
                self._on_attitude(s)
            elif isinstance(s, Heading):
                if self._have_attitude:
                    continue  # an AHRS reports the same yaw: do not count it twice
                self._on_heading(s)
            else:
                continue
            self.t_sensor = s.t
        if not self.initialized:
            return {}
        if not np.all(np.isfinite(self.P)) or not np.all(np.isfinite(self.p)):
            self._count("diverged")
            self.__init__(self.cfg, self._sensors)  # type: ignore[misc]
            return {}
        return self.estimates()

    def estimates(self) -> dict[str, float]:
        """The current estimates by column name (SI, NED/FRD, rad)."""
        roll, pitch, yaw = matrix_to_euler(self.R)
        nu = self.R.T @ self.v
        xi_e = self.R @ self.xi
        d = np.sqrt(np.maximum(np.diag(self.P), 0.0))
        # body-velocity std: R^T P_vv R
        P_nu = self.R.T @ self.P[V_, V_] @ self.R
        s_nu = np.sqrt(np.maximum(np.diag(P_nu), 0.0))
        w = (self.w_m if self.w_m is not None else np.zeros(3)) - self.b_g
        vals = (
            *self.p, *self.v, *nu, roll, pitch, yaw, *w, *self.xi, *xi_e,
            *d[P_], *s_nu, *d[XI], *self.b_a, *self.b_g, self.g[2],
        )
        return {k: float(v) for k, v in zip(self.columns, vals)}

    def std(self) -> dict[str, float]:
        """One-sigma uncertainties keyed like the values (``std_<q>`` columns -> ``<q>``),
        as the engine fills ``EstimateRecord.std``."""
        return {k[4:]: v for k, v in self.estimates().items() if k.startswith("std_")}

    def record(self, vehicle: str, t: float) -> EstimateRecord:
        """The published estimate record of this pipeline at tick ``t``."""
        return EstimateRecord(vehicle=vehicle, pipeline=self.name, t=t,
                              values=self.estimates() if self.initialized else {},
                              std=self.std() if self.initialized else {},
                              t_sensor=self.t_sensor)

    def health(self) -> Mapping[str, float]:
        """Innovations (``<channel>.innovation_<i>``), their variances (``.S_<i>``) and
        ``<channel>.nis`` of the last update of each channel, plus event counters."""
        out: dict[str, float] = {}
        for ch, d in self.last.items():
            y = np.atleast_1d(d["y"])
            S = np.atleast_1d(d["S"])
            for i in range(len(y)):
                out[f"{ch}.innovation_{i}"] = float(y[i])
                out[f"{ch}.S_{i}"] = float(S[i])
            out[f"{ch}.nis"] = float(d["nis"])  # type: ignore[arg-type]
        out.update({k: float(v) for k, v in self.counters.items()})
        return out

    def get_state(self) -> dict[str, Any]:
        """Sensor biases, gravity and the disturbance (worth keeping across a restart)."""
        return {"b_a": self.b_a.tolist(), "b_g": self.b_g.tolist(),
                "g": self.g.tolist(), "xi": self.xi.tolist()}

    def set_state(self, state: Mapping[str, Any]) -> None:
        for key in ("b_a", "b_g", "g", "xi"):
            val = state.get(key)
            if isinstance(val, (list, tuple)) and len(val) == 3:
                try:
                    arr = np.array([float(x) for x in val])
                except (TypeError, ValueError):
                    continue
                if np.all(np.isfinite(arr)):
                    setattr(self, key, arr)


def create(cfg: Config) -> Eseso | None:
    """The ESESO for a BlueROV2-class vehicle, or for any vehicle whose config sets
    ``[pipelines.eseso] enabled = true``."""
    section = cfg.pipelines.get("eseso", {})
    c = decode_section(cfg, "eseso", EsesoConfig)
    if not c.enabled:
        return None
    if cfg.vehicle.vehicle_class not in c.vehicle_classes and section.get("enabled") is not True:
        return None
    return Eseso(c, cfg.sensors)


def bench_step_cost(duration_s: float = 20.0, tick_hz: float = 20.0) -> dict[str, float]:
    """Bench helper (not part of the pipeline): cost of :meth:`Eseso.step` on a synthetic
    50 Hz IMU + 20 Hz command + 5 Hz DVL/depth/attitude stream.

    Returns ``{"per_tick_us_p50", "per_tick_us_p99", "per_imu_sample_us", "ticks"}``.
    """
    import time

    rng = np.random.default_rng(0)
    f = Eseso(EsesoConfig())
    samples: list[Sample] = []
    n_imu = int(duration_s * 50)
    for k in range(n_imu):
        t = k / 50.0
        samples.append(Imu(t=t, accel_x=rng.normal(0, 0.05), accel_y=rng.normal(0, 0.05),
                           accel_z=-9.81 + rng.normal(0, 0.05), gyro_x=0.0, gyro_y=0.0,
                           gyro_z=0.0))
        if k % 10 == 0:
            samples.append(Attitude(t=t, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0))
            samples.append(Depth(t=t, depth_m=20.0))
            samples.append(DvlVelocity(t=t, vx=0.0, vy=0.0, vz=0.0))
        if k % 5 == 0:
            samples.append(ActuatorCommand(t=t, thrusters=(0.0,) * 6))
    costs = []
    i = 0
    n_ticks = int(duration_s * tick_hz)
    for k in range(n_ticks):
        t = (k + 1) / tick_hz
        batch = []
        while i < len(samples) and samples[i].t <= t:
            batch.append(samples[i])
            i += 1
        t0 = time.perf_counter()
        f.step(t, batch)
        costs.append(time.perf_counter() - t0)
    c = np.array(costs) * 1e6
    return {"per_tick_us_p50": float(np.percentile(c, 50)),
            "per_tick_us_p99": float(np.percentile(c, 99)),
            "per_imu_sample_us": float(c.sum() / n_imu), "ticks": float(n_ticks)}
