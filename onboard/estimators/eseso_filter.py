"""Error-state extended state observer (ESESO): the filter of a BlueROV2-class vehicle.

Paper: L.-Y. Lo, Y. Hu, B. Li, C.-Y. Wen, Y. Yang, "An adaptive model predictive control for
unmanned underwater vehicles subject to external disturbances and measurement noise"
(``../shared/papers/eseso-ampc-bluerov2.txt``), section III; spec: ``algorithms.md`` §5.1.
The pipeline that feeds it samples is :mod:`onboard.pipelines.eseso`.

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
``ins_bias_tau_s``), so as white measurement noise it is wrong whatever its variance: too
small and the filter follows the INS bias, too large and the innovations are far smaller
than S (docs/eseso-mpc.md, "Measurement noise and consistency").

* **Propagation** (:meth:`EsesoFilter.propagate`; paper eqs. 10-13; Sola, "Quaternion
  kinematics for the error-state Kalman filter", 2017, §5) over an interval that the
  interval's mean specific force and rate drive. ``F[dtheta, db_g]`` is the exact
  ``-Jr(w dt) dt``. ``xi`` is propagated either as a constant in the body frame (the
  paper's random walk, ``disturbance_model = "body_fixed"``) or as a force fixed in the
  earth frame whose body components turn with the vehicle (``xi <- Exp(-w dt) xi``,
  ``"earth_fixed"``): a push, a tether or a current drag is earth-fixed, and on the paper's
  2 m circle the body components turn at up to 0.75 rad/s, which a random walk cannot
  follow. The covariance is propagated by the transition's blocks
  (:class:`Transition`, :func:`propagate_covariance`; the dense ``F`` is
  :func:`transition_matrix`, the readable reference).
* **Compiled twins** (:func:`compiled_kernel`): with numba installed (the ``fast`` extra)
  each propagation and each update (its noise adaptation, Kalman update, gate,
  injection and reset; the thrust update whole, its model, noise and Huber weight too;
  the attitude's innovation) is one call of :mod:`.eseso_kernel`, the same equations on
  compiled loops writing the nominal state's one array :attr:`EsesoFilter.x` and ``P``
  in place (tests/test_eseso_kernel.py: to rounding); the bookkeeping (the records, the
  rejections in a row, the adaptation's means) stays here. This module's numpy code is
  their reference and runs without numba or with ``ONBOARD_ESESO_KERNEL=0``.
* **Updates** (paper eqs. 14, 16), each through :meth:`EsesoFilter.update`, Joseph form,
  with the innovation ``y``, its covariance ``S`` and the NIS of each update kept as an
  :class:`~onboard.core.messages.Innovation` record in :attr:`EsesoFilter.innovations`
  until the owner takes them, and a chi-square gate (99.9 %; after
  ``max_consecutive_rejects`` gated updates in a row the channel is fused again,
  down-weighted, so a sensor cannot be locked out for good). The measurement models:
  horizontal position and velocity, INS velocity over ground (``v + b_ins``), depth, DVL
  velocity (body frame), attitude (``Log(R^T R_meas)``, its noise given as roll, pitch and
  yaw variances turned into body axes), heading, and the thrust model ``h_tau`` below.
* **Noise the filter is not told about** (:meth:`EsesoFilter._adapt_noise`,
  :meth:`EsesoFilter._adapt_process`): each sensor channel's configured noise is scaled by
  the exponential mean of its innovations' excess over ``H P H^T`` (covariance matching),
  and the IMU's white noise by the DVL innovations' excess over ``R`` (a fading factor);
  each scale is clipped to [1, ``noise.scale_max``]: noise larger than configured is
  learnt, smaller is not (``noise.adapt_updates`` 0 = off).
* **What ``xi`` is**: the lumped disturbance, the force the thrust model misses: the
  external push plus whatever the model's mass, damping and thrust map get wrong (the
  paper's definition, and what the AMPC adds to its prediction model). Its published
  variance is ``P``'s plus the error variance the thrust innovations show beyond it
  (:meth:`EsesoFilter.published_disturbance_var`), which never enters ``P``, the gain
  or ``xi``: a controller's ``xi`` keeps the filter's tuning. When the commanded or the damping force changes, ``xi`` changes by the thrust
  map's or the damping's relative error times the change: with their configured
  one-sigmas that is process noise of ``xi`` (:meth:`EsesoFilter.model_change_var`). On
  a vehicle circling at one speed under a constant push the push cannot be told from a
  thrust-map error (docs/eseso-mpc.md), so no separate push is estimated.
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
of gravity and ``w'`` the angular acceleration (with z_G = 0.2 m the ``m w' x r_g`` term
reaches 50 N when a thruster step rolls the vehicle; its Jacobian is neglected). ``tau`` is
the thruster force in body axes. The paper's ``M_RB (u_a - b_a)`` misses the ``m g_B``
term, which only cancels against the weight if the restoring term is written with ``B``
alone; here both are explicit.

With ``thrust_states = "disturbance"`` the thrust update corrects the disturbance alone (as
the paper's H, -I on ``dxi`` only) but as a Schmidt-Kalman update (Schmidt 1966; Simon,
"Optimal State Estimation", 2006, section 7.5): the full Jacobian enters ``S`` and the
covariance and only the gain's ``dxi`` rows are kept, so the cross-covariance of ``xi`` with the
attitude and velocity (a tilt error of 3 mrad is 0.4 N through ``M g``, which ``xi``
absorbs) is carried instead of counted as white noise at every update. Through the
damping slope (up to 66 N per m/s) the full update (``"all"``) makes it a velocity
sensor too, which thruster lag or model errors would drag away from the DVL. Its residual
is down-weighted Huber-style above ``thrust_huber``: thruster steps excite roll and pitch
accelerations faster than the IMU rate resolves.

Numbers in, numbers out: no samples, no clock, no configuration file.
"""

from __future__ import annotations

import enum
import functools
import math
import os
from collections import deque
from dataclasses import dataclass
from types import ModuleType
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from onboard.core.geo import wrap_pi
from onboard.core.messages import Innovation
from onboard.core.pipeline_config import (
    EsesoInitialConfig,
    EsesoNoiseConfig,
    EsesoProcessConfig,
    EsesoVehicleConfig,
)
from onboard.core.stats import chi2_quantile
from onboard.core.so3 import (
    cross,
    exp_so3,
    frozen_eye,
    log_so3,
    matrix_to_euler,
    orthonormalize,
    right_jacobian,
    skew,
)
from onboard.estimators import kalman

Array = NDArray[np.float64]

P_, V_, TH, BA, BG, G_, XI = (slice(3 * i, 3 * i + 3) for i in range(7))
"""Error-state blocks (paper eq. 11): position, velocity, attitude, accelerometer bias,
gyro bias, gravity, disturbance."""
BI = slice(XI.stop, XI.stop + 2)
"""Error-state block of the INS velocity bias (north, east)."""
N_ERR = BI.stop
"""Dimension of the error state (23)."""
P_NE = slice(P_.start, P_.start + 2)
"""The horizontal position error (north, east) within :data:`P_`."""
P_D = P_.start + 2
"""The depth error (down) within :data:`P_`."""
V_NE = slice(V_.start, V_.start + 2)
"""The horizontal velocity error (north, east) within :data:`V_`."""
TH_Z = TH.start + 2
"""The attitude error about the body z axis within :data:`TH` (the yaw error of a level
vehicle)."""

E3 = np.array([0.0, 0.0, 1.0])

X_P, X_V = slice(0, 3), slice(3, 6)
X_R = slice(6, 15)
X_BA, X_BG, X_G, X_XI = (slice(15 + 3 * i, 18 + 3 * i) for i in range(4))
X_BI = slice(27, 29)
"""The nominal state's entries in the filter's one array :attr:`EsesoFilter.x`: ``p``,
``v``, ``R`` (row by row), ``b_a``, ``b_g``, ``g``, ``xi``, ``b_ins``."""
N_NOMINAL = X_BI.stop
"""Length of the nominal state's array (29)."""


def _nominal(block: slice, doc: str) -> property:
    """The part ``block`` of :attr:`EsesoFilter.x` as an attribute: read, a view (written
    in place, it writes the state); assigned, a new array with the value (what was read
    before keeps its values, as any rebound attribute). The compiled kernels write
    :attr:`EsesoFilter.x` in place: a view read before one of their propagations or
    updates shows the state after it."""
    shape = (3, 3) if block == X_R else (block.stop - block.start,)

    def get(self: "EsesoFilter") -> Array:
        return self.x[block].reshape(shape)

    def put(self: "EsesoFilter", value: Array) -> None:
        x = self.x.copy()
        x[block] = np.ravel(value)
        self.x = x

    return property(get, put, doc=doc)


_I2, _I3, _I_N = frozen_eye(2), frozen_eye(3), frozen_eye(N_ERR)
"""Identities made once (read-only) for every propagation and update."""
_NO_ERROR = np.zeros(N_ERR)
_NO_ERROR.setflags(write=False)
"""The error state before an update: zero (the nominal state carries the estimate)."""


def _jacobian(rows: int, *blocks: tuple[slice | int, Array | float]) -> Array:
    """A constant ``rows`` x 23 measurement Jacobian: zero but for the given ``(columns,
    value)`` blocks. Left writable, as the state's Jacobians are (numba compiles a kernel
    again for a read-only argument: 2-3 s more of the first compile), and never written:
    the update and the kernels only read ``H``."""
    H = np.zeros((rows, N_ERR))
    for cols, value in blocks:
        H[:, cols] = value
    return H


_H_POSITION_NE = _jacobian(2, (P_NE, _I2))
_H_VELOCITY_NE = _jacobian(2, (V_NE, _I2))
_H_ZERO_VELOCITY = _jacobian(3, (V_, _I3))
_H_INS_VELOCITY = _jacobian(2, (V_NE, _I2), (BI, _I2))
_H_DEPTH = _jacobian(1, (P_D, 1.0))
_H_ATTITUDE = _jacobian(3, (TH, _I3))
"""The measurement models' Jacobians that do not depend on the state, made once."""

GATE_PROBABILITY = 0.999
"""Probability of a consistent innovation's NIS inside the default gate: the gate of a
``dof``-dimensional update is ``chi2_quantile(GATE_PROBABILITY, dof)`` (10.83, 13.82,
16.27 for 1, 2, 3)."""
PENDING_INNOVATIONS = 1024
"""Innovation records kept until the owner takes them; older ones are dropped."""


@dataclass(frozen=True)
class EsesoParams:
    """Vehicle model, noise and gating of :class:`EsesoFilter` (SI units, NED/FRD): the
    typed tables of ``[pipelines.eseso]`` (:mod:`onboard.core.pipeline_config`, where
    each number's meaning is), built by :func:`onboard.pipelines.eseso.filter_params`.
    """

    vehicle: EsesoVehicleConfig
    """Mass, added mass, damping, centre of gravity, weight and buoyancy."""
    process: EsesoProcessConfig
    """The disturbance's axes, the random walks and the model-change noise."""
    noise: EsesoNoiseConfig
    """Measurement noise and its adaptation; ``accel_std_mps2`` and ``gyro_std_rps`` set
    (from ``[sensors.imu]`` where the table leaves them unset): the IMU's white noise,
    also the thrust update's noise through M."""
    initial: EsesoInitialConfig
    """Nominal gravity and the initial one-sigmas (the start position is the pipeline's)."""
    thrust_states: Literal["disturbance", "all"]
    """The error states the thrust update corrects."""
    thrust_huber: float
    """NIS above which the thrust update is down-weighted; 0 = plain update."""
    gate_sigma: float
    """0 = chi-square 99.9 % gates; else the NIS gate is ``gate_sigma**2 * dof``."""
    max_consecutive_rejects: int
    """Gated updates in a row after which a channel is fused again, down-weighted."""


NOISE_ADAPT_CHANNELS = frozenset({"attitude", "heading", "depth", "vog", "gnss_pos",
                                  "gnss_vel"})
"""Sensor channels whose noise is scaled from their innovations (:meth:`EsesoFilter.update`);
the thrust channel's is scaled likewise in :meth:`EsesoFilter.update_thrust`, before its
Huber weight (a real thruster's force error, lag and thrust curve against battery
voltage, is not the simulator's and nobody measures it on the vehicle); the zero-velocity
update is a pseudo-measurement and the DVL's excess goes to the process noise
(:data:`PROCESS_ADAPT_CHANNEL`)."""
PROCESS_ADAPT_CHANNEL = "dvl"
"""The channel whose innovations scale the IMU's white noise (the process noise of velocity
and attitude; :meth:`EsesoFilter._adapt_process`): the DVL is the filter's velocity
reference and reports its own noise per ping (its figure of merit, floored), while the
IMU's noise is a configured number nobody measures on the vehicle, so DVL innovations
larger than ``H P H^T + R`` say the propagated velocity is too confident, unless they say
the figure of merit is what is too small (:data:`DVL_OWN_NOISE_LAG1`)."""
DVL_OWN_NOISE_LAG1 = -0.2
"""Below this correlation of successive normalized DVL innovations (their windowed lag-1,
:meth:`EsesoFilter._adapt_dvl_noise`) the DVL's own noise is taken as larger than its
figure of merit says, and learnt: a measurement noise set too small against the
forecast's makes the gain too high and successive innovations correlate negatively, a
process noise set too small positively (Mehra 1970). Measured on the 60-s closed loop
(docs/eseso-mpc.md, "DVL"): -0.09 to -0.10 with a figure of merit that is the noise's
sigma, -0.32 with a Water Linked A50's (0.55 of it); 0.1 is the standard error of a
100-update mean of white innovations."""
DVL_OWN_NOISE_RELEASE_LAG1 = 0.0
"""Once :data:`DVL_OWN_NOISE_LAG1` has said the excess is the DVL's, it is until the lag-1
turns positive (a process noise set too small): its scale learnt to the full excess takes
the lag only back to the closed loop's own -0.1, not to zero."""
NARROWING_MEMORY = 10
"""The thrust innovations' ratio that narrows the published disturbance sigma is their
exponential mean over this many times ``noise.adapt_updates`` (the one that widens it
takes ``noise.adapt_updates``): a sigma narrowed on a noisy mean is too confident
wherever the mean dips (on the simulated BlueROV2, the fast mean alone covered 0.43-0.60
of the errors at 1 sigma)."""
PUBLISHED_VAR_MIN_SHARE = 0.25
"""The published disturbance variance is at least this share of ``P[xi, xi]`` (its sigma
at least half of the covariance's) where the thrust innovations say ``P`` carries more
than the error (:meth:`EsesoFilter.published_disturbance_var`): a bound, not the
estimator (on the simulated BlueROV2 at 0.01 the nominal 1-sigma coverage is 0.72-0.82,
as with it)."""
NOISE_SAMPLE_CAP = 100.0
"""Ceiling of one update's contribution to a channel's noise-scale mean (the ratio of
excess innovation power to the configured noise power, dimensionless): one outlier moves
the mean by at most this over ``noise.adapt_updates``."""


class Outcome(enum.Enum):
    """What became of one measurement update (:meth:`EsesoFilter.update`); true when the
    measurement was fused. The owner counts them."""

    FUSED = "fused"
    """Fused as it came."""
    GATED = "gated"
    """Rejected by the gate."""
    RECOVERED = "recovered"
    """Beyond the gate after ``max_consecutive_rejects`` rejections in a row: fused,
    down-weighted so that its NIS equals the gate."""

    def __bool__(self) -> bool:
        return self is not Outcome.GATED


@dataclass(frozen=True, slots=True)
class Transition:
    """The blocks of one propagation's error-state transition ``F`` (paper eq. 12;
    algorithms.md §5.1) that are not identity or zero, over ``dt`` (s)::

        F[P, V]  = I dt          F[P, TH] = -R [f]x dt^2/2   F[P, BA] = -R dt^2/2
        F[P, G]  = I dt^2/2      F[V, TH] = -R [f]x dt       F[V, BA] = -R dt
        F[V, G]  = I dt          F[TH, TH] = Exp(w dt)^T     F[TH, BG] = -Jr(w dt) dt
        F[XI, XI] = Exp(w dt)^T  F[XI, BG] = -Exp(w dt)^T [xi]x Jr(-w dt) dt  (earth-fixed)
        F[BI, BI] = phi_ins I

    Every other diagonal block is the identity (biases, gravity; ``xi`` when body-fixed)
    and every other off-diagonal block zero. :func:`transition_matrix` is the dense ``F``
    (the readable reference), :func:`propagate_covariance` applies it by blocks.
    """

    dt: float
    """The interval (s)."""
    R_skew_f: Array
    """``R [f]x`` (m/s^2): attitude times the skew matrix of the bias-corrected specific
    force."""
    R: Array
    """The body-to-earth rotation at the interval's start."""
    dRt: Array
    """``Exp(w dt)^T``."""
    th_bg: Array
    """``F[TH, BG] = -Jr(w dt) dt`` (s)."""
    xi_bg: Array | None
    """``F[XI, BG]`` (N s) with the earth-fixed disturbance (``F[XI, XI] = Exp(w dt)^T``);
    None with the body-fixed one (``F[XI, XI] = I``)."""
    phi_ins: float
    """The INS bias's decay over ``dt``."""


def transition_matrix(tr: Transition) -> Array:
    """The dense 23 x 23 error-state transition ``F`` of :class:`Transition` (the
    readable reference of :func:`propagate_covariance`)."""
    dt = tr.dt
    F = _I_N.copy()
    F[P_, V_] = _I3 * dt
    F[P_, TH] = -0.5 * tr.R_skew_f * dt * dt
    F[P_, BA] = -0.5 * tr.R * dt * dt
    F[P_, G_] = 0.5 * _I3 * dt * dt
    F[V_, TH] = -tr.R_skew_f * dt
    F[V_, BA] = -tr.R * dt
    F[V_, G_] = _I3 * dt
    F[TH, TH] = tr.dRt
    F[TH, BG] = tr.th_bg
    if tr.xi_bg is not None:
        F[XI, XI] = tr.dRt
        F[XI, BG] = tr.xi_bg
    F[BI, BI] = _I2 * tr.phi_ins
    return F


def transition(R: Array, f: Array, w: Array, xi: Array, dt: float, phi_ins: float,
               earth_fixed: bool) -> Transition:
    """The :class:`Transition` over ``dt`` (s) from attitude ``R``, the bias-corrected
    specific force ``f`` (m/s^2) and rate ``w`` (rad/s), the disturbance ``xi`` (N, body;
    its block only when ``earth_fixed``) and the INS bias's decay ``phi_ins``."""
    dRt = exp_so3(w * dt).T
    # exact in the gyro-bias error: Exp((w - db) dt) = Exp(w dt) Exp(-Jr(w dt) db dt)
    Jr = right_jacobian(w * dt)
    # Jr(-w dt) = Jr(w dt)^T
    xi_bg = -(dRt @ skew(xi) @ Jr.T) * dt if earth_fixed else None
    return Transition(dt, R @ skew(f), R, dRt, -Jr * dt, xi_bg, phi_ins)


def propagate_covariance(P: Array, tr: Transition, q: Array) -> Array:
    """``F P F^T + diag(q)`` (paper eq. 13) with ``F`` applied by its blocks: as ``F (F
    P)^T`` (``P`` symmetric), each product changing only the rows of position, velocity,
    attitude, ``xi`` and the INS bias (:func:`_transition_rows`). Agrees with the dense
    ``transition_matrix(tr) @ P @ transition_matrix(tr).T`` to rounding (tested to 1e-12)
    at a fifth of its numpy calls."""
    out = _transition_rows(_transition_rows(P, tr).T, tr)
    out.ravel()[:: N_ERR + 1] += q
    return out


_TH_TO_BA = slice(TH.start, BA.stop)
"""The attitude and accelerometer-bias rows, adjacent (what ``F[V, :]`` mixes in)."""
_TH_TO_BG = slice(TH.start, BG.stop)
"""Attitude to gyro bias (what ``F[TH, :]`` mixes in)."""
_BG_TO_XI = slice(BG.start, XI.stop)
"""Gyro bias to disturbance (what ``F[XI, :]`` mixes in)."""


def _transition_rows(M: Array, tr: Transition) -> Array:
    """``F M`` for the 23-row ``M``, by blocks: ``F[V, :] M = M[V] + dt (M[G] - [R[f]x,
    R] M[TH:BA])`` and, since ``F[P, TH:G] = F[V, TH:G] dt / 2``, ``F[P, :] M = M[P] +
    dt (M[V] + (F M)[V]) / 2``; the attitude, ``xi`` and INS-bias rows by their blocks;
    the bias and gravity rows unchanged."""
    dt = tr.dt
    out = M.copy()
    v_new = M[V_] + dt * (M[G_] - np.concatenate((tr.R_skew_f, tr.R), axis=1) @ M[_TH_TO_BA])
    out[P_] += 0.5 * dt * (M[V_] + v_new)
    out[V_] = v_new
    out[TH] = tr.dRt @ M[TH] + tr.th_bg @ M[BG]
    if tr.xi_bg is not None:
        out[XI] = tr.dRt @ M[XI] + tr.xi_bg @ M[BG]
    out[BI] *= tr.phi_ins
    return out


def reset_covariance(P: Array, dtheta: Array) -> Array:
    """The covariance after injecting the attitude error ``dtheta`` (rad; paper eq. 17b):
    ``G P G^T`` with ``G = I`` but its attitude block ``I - [dtheta/2]x`` (Sola eq. 287),
    symmetrized."""
    G = _I_N.copy()
    G[TH, TH] -= skew(0.5 * dtheta)
    P = G @ P @ G.T
    return 0.5 * (P + P.T)


KERNEL_ENV = "ONBOARD_ESESO_KERNEL"
"""Environment variable: ``0`` keeps the numpy reference even where numba is installed
(to time or compare the two paths); read when a filter is made."""


@functools.cache
def _import_kernel() -> ModuleType | None:
    """:mod:`.eseso_kernel`, or None when numba does not import (once a process)."""
    try:
        from onboard.estimators import eseso_kernel
    except ImportError:
        return None
    return eseso_kernel


def _kernel() -> ModuleType:
    """:mod:`.eseso_kernel`, for a filter whose :attr:`EsesoFilter.compiled` says it
    imported."""
    kernel = _import_kernel()
    assert kernel is not None
    return kernel


def compiled_kernel() -> ModuleType | None:
    """The compiled twins of the propagation and of the update (:mod:`.eseso_kernel`, the
    ``fast`` extra) when numba imports and ``ONBOARD_ESESO_KERNEL`` is not ``0``, else
    None: the numpy code of this module is the reference and the default without it."""
    if os.environ.get(KERNEL_ENV, "1").strip() == "0":
        return None
    return _import_kernel()


def warm_kernels(params: EsesoParams) -> None:
    """Each compiled twin called once, on a throwaway filter at rest with ``params``, so
    that a filter made afterwards runs without a pause: numba loads each kernel from its
    cache at its first call (0.55 s for them all here, docs/performance.md), which a
    live service would otherwise spend inside its first ticks. Once a process; nothing
    without the compiled kernels."""
    global _kernels_warm
    if _kernels_warm or compiled_kernel() is None:
        return
    f = EsesoFilter(params)
    f.initialize(np.eye(3), np.zeros(3))
    rest, still = -f.g, np.zeros(3)  # the specific force and rate of a vehicle at rest
    f.propagate(rest, still, 0.02)
    f.update_attitude(np.eye(3), 0.0, 0.0, 1e-4, 1e-3)
    f.update_depth(0.0, 1e-2)
    f.update_body_velocity(still, 1e-2)
    f.update_thrust(rest, still, still, still, wdot_dt=0.02)
    f.finite()
    _kernel().estimates(f.x, f.P, still, f.disturbance_excess, 0.0)
    _kernels_warm = True


_kernels_warm = False


class EsesoFilter:
    """The ESESO error-state Kalman filter (module docstring).

    Attributes (filterpy-style, read them to debug):
        x: the nominal state in one array (:data:`X_P` ... :data:`X_BI`), which the
            compiled kernels write in place.
        p, v, R, b_a, b_g, g, xi, b_ins: the nominal state (see the module docstring),
            views of :attr:`x`.
        P: the 23 x 23 error covariance, ordered as :data:`P_` ... :data:`BI`.
        F: the last propagation's error-state transition (:attr:`transition`, dense).
        compiled: whether the propagation and the updates run the compiled kernels
            (:func:`compiled_kernel`; the same equations, to rounding).
        y, S, nis: innovation, its covariance and the NIS of the last update (any channel,
            gated or not).
        innovations: the records of the updates not yet taken, one per update (channels
            ``thrust``, ``attitude``, ``heading``, ``dvl``, ``depth``, ``vog``,
            ``gnss_pos``, ``gnss_vel``; innovation = measured - predicted; a gated update
            has ``accepted`` False and reason ``gate``).
        downweighted: whether the last thrust update was down-weighted
            (``thrust_huber``).
        initialized: False until :meth:`initialize`.
        R_tau: the thrust update's noise covariance at the last thrust update
            (:meth:`thrust_noise`, N^2), before the other states' share and the scales.
        noise_scale: per sensor channel, the variance scale its noise is multiplied by
            (1 to ``noise.scale_max``; :meth:`update`; the DVL's,
            :meth:`_adapt_dvl_noise`).
        process_scale: the variance scale of the IMU's white noise in the propagation
            (1 to ``noise.scale_max``; :data:`PROCESS_ADAPT_CHANNEL`).
        disturbance_excess: per body axis, the error variance of ``xi`` (N^2) that the
            thrust innovations show beyond ``P`` (:meth:`_learn_disturbance_excess`); added
            to the published sigma (:meth:`published_disturbance_var`), not to ``P``.
    """

    p = _nominal(X_P, "Position, NED, m.")
    v = _nominal(X_V, "Velocity over ground, NED, m/s.")
    R = _nominal(X_R, "Body(FRD)-to-earth(NED) rotation.")
    b_a = _nominal(X_BA, "Accelerometer bias, body, m/s^2.")
    b_g = _nominal(X_BG, "Gyro bias, body, rad/s.")
    g = _nominal(X_G, "Gravity, NED, m/s^2.")
    xi = _nominal(X_XI, "Lumped disturbance force, body FRD, N.")
    b_ins = _nominal(X_BI, "INS velocity bias (north, east), m/s.")

    def __init__(self, params: EsesoParams) -> None:
        self.params = params
        c = params.vehicle
        self.m_vec = c.mass_kg + np.asarray(c.added_mass_kg, float)  # diag of M, kg
        self.d_a = np.asarray(c.added_mass_kg, float)  # diag of A, kg
        self.A = np.diag(self.d_a)
        self.d_l = np.asarray(c.damping_linear, float)
        self.d_nl = np.asarray(c.damping_quadratic, float)
        self._earth_fixed = params.process.disturbance_model == "earth_fixed"
        self.initialized = False
        self.x = np.zeros(N_NOMINAL)  # p, v, b_a, b_g, xi, b_ins zero
        self.R = np.eye(3)
        self.g = np.array([0.0, 0.0, params.initial.gravity_mps2])
        self.P = np.eye(N_ERR)
        self._transition: Transition | None = None  # the last propagation's (:attr:`F`)
        self._interval_key: tuple[float, float] | None = None  # :meth:`_interval_noise`'s
        self._interval: tuple[float, Array] = (0.0, _NO_ERROR)
        # what the compiled propagation's transition is built from when it is read: the
        # state before it (written by the kernel) and its inputs
        self._x_prev = np.zeros(N_NOMINAL)
        self._transition_inputs: tuple | None = None
        self.compiled = compiled_kernel() is not None
        self.y: Array | None = None
        self.S: Array | None = None
        self.nis: float | None = None
        self.innovations: deque[Innovation] = deque(maxlen=PENDING_INNOVATIONS)
        self.downweighted = False
        self._consecutive: dict[str, int] = {}
        self.noise_scale: dict[str, float] = {}
        self.process_scale = 1.0
        self._noise_mean: dict[str, float] = {}
        self._dvl_w: Array | None = None  # the last DVL update's y / sqrt(tr S)
        self._dvl_lag = 0.0  # E[w_k . w_(k-1)] of the DVL updates
        self._dvl_power = 0.0  # E[w_k . w_k]
        self._dvl_updates = 0
        self.dvl_own_noise = False
        """Whether the DVL's innovations say its own noise is larger than its figure of merit
        (:meth:`_adapt_dvl_noise`): then its scale is learnt and the IMU's relaxes
        (:meth:`_relax_process`), else the DVL's excess scales the IMU's noise."""
        self._model_terms: Array | None = None  # rows tau, D(nu) nu at the last update
        self.disturbance_excess = np.zeros(3)
        self._excess_ratio = np.ones(3)  # E[y_i^2] / S_ii of the thrust innovations
        self._excess_ratio_slow = np.ones(3)  # the same over NARROWING_MEMORY times longer
        self._excess_lag = np.zeros(3)  # E[u_k u_(k-1)], u_k = y_i / sqrt(S_ii) at update k
        self._last_thrust_u = np.zeros(3)  # the last thrust update's u
        # thrust-update noise (N^2), :meth:`thrust_noise`; updated at every thrust update
        self.R_tau = self.thrust_noise(None)
        # the compiled thrust update's constants (eseso_kernel.thrust_constants), once
        self._thrust_constants: tuple[Array, Array] | None = None

    def initialize(self, R0: Array, position: Array, yaw_std_rad: float | None = None) -> None:
        """Start at attitude ``R0`` (projected onto SO(3)) and NED ``position`` (m), at rest,
        with the configured initial standard deviations; ``yaw_std_rad`` replaces the
        attitude std about the body z axis (an attitude levelled from gravity alone)."""
        c = self.params.initial
        self.R = orthonormalize(R0)
        self.p[:] = position
        sd = [c.position_std_m] * 3 + [c.velocity_std_mps] * 3
        sd += [c.attitude_std_rad] * 3 + [c.accel_bias_std_mps2] * 3
        sd += [c.gyro_bias_std_rps] * 3 + [c.gravity_std_mps2] * 3
        sd += [c.disturbance_std_n] * 3 + [self.params.noise.ins_bias_std_mps] * 2
        self.P = np.diag(np.square(sd))
        if yaw_std_rad is not None:
            self.P[TH_Z, TH_Z] = yaw_std_rad ** 2
        self.initialized = True

    # ------------------------------------------------------------------ propagation
    def propagate(self, f_m: Array, w_m: Array, dt: float) -> None:
        """Propagate over ``dt`` (s) driven by the interval's mean specific force ``f_m``
        (m/s^2) and rate ``w_m`` (rad/s), body axes: nominal state by paper eq. (10b),
        covariance by eqs. (11)-(13) with the Jacobian F of algorithms.md §5.1, its
        non-identity blocks (:func:`transition`) applied by :func:`propagate_covariance`;
        with :attr:`compiled`, the same in :func:`.eseso_kernel.propagate`."""
        earth_fixed = self._earth_fixed
        phi_ins, q = self._interval_noise(dt)
        if self.compiled:  # x and P written in place; the transition built when read
            self._transition = None
            self._transition_inputs = (f_m, w_m, dt, phi_ins, earth_fixed)
            _kernel().propagate(self.x, self.P, self._x_prev, f_m, w_m, dt, earth_fixed,
                                phi_ins, q)
            return
        f = f_m - self.b_a
        w = w_m - self.b_g
        acc = self.R @ f + self.g
        tr = transition(self.R, f, w, self.xi, dt, phi_ins, earth_fixed)
        # nominal state (10b)
        self.p = self.p + self.v * dt + 0.5 * acc * dt * dt
        self.v = self.v + acc * dt
        self.R = self.R @ tr.dRt.T
        if earth_fixed:
            self.xi = tr.dRt @ self.xi
        self.b_ins = self.b_ins * phi_ins
        self.P = propagate_covariance(self.P, tr, q)
        self._transition = tr

    def _interval_noise(self, dt: float) -> tuple[float, Array]:
        """The INS bias's decay over ``dt`` (s) (first-order Gauss-Markov, exact
        discretization) and the process noise's diagonal (:meth:`_process_noise`), kept
        while ``dt`` and :attr:`process_scale` stay the same (a steady IMU rate: most
        intervals; the diagonal is read, never written)."""
        key = (dt, self.process_scale)
        if key != self._interval_key:
            tau = self.params.noise.ins_bias_tau_s
            phi_ins = math.exp(-dt / tau) if tau > 0 else 0.0
            self._interval_key = key
            self._interval = (phi_ins, self._process_noise(dt, phi_ins))
        return self._interval

    def _process_noise(self, dt: float, phi_ins: float) -> Array:
        """The diagonal of the discrete process noise ``Q`` over ``dt`` (s) (paper eq. 13):
        random walks times ``dt``, the IMU's white noise (times :attr:`process_scale`) over
        the interval, the INS bias's Gauss-Markov variance with decay ``phi_ins``."""
        c, n = self.params.process, self.params.noise
        q = np.empty(N_ERR)
        q[P_] = c.position_walk_m_rts ** 2 * dt
        q[V_] = (n.accel_std_mps2 * dt) ** 2 * self.process_scale
        q[TH] = (n.gyro_std_rps * dt) ** 2 * self.process_scale
        q[BA] = c.accel_bias_walk_mps2_rts ** 2 * dt
        q[BG] = c.gyro_bias_walk_rps_rts ** 2 * dt
        q[G_] = c.gravity_walk_mps2_rts ** 2 * dt
        q[XI] = c.disturbance_walk_n_rts ** 2 * dt
        q[BI] = n.ins_bias_std_mps ** 2 * (1.0 - phi_ins * phi_ins)
        return q

    def finite(self) -> bool:
        """Whether ``P`` and the position are finite (else the filter diverged); with
        :attr:`compiled`, :func:`.eseso_kernel.finite`."""
        if self.compiled:
            return _kernel().finite(self.x, self.P)
        return bool(np.isfinite(self.P).all() and np.isfinite(self.p).all())

    @property
    def transition(self) -> Transition | None:
        """The last propagation's :class:`Transition` (None before the first)."""
        if self._transition is None and self._transition_inputs is not None:
            f_m, w_m, dt, phi_ins, earth_fixed = self._transition_inputs
            x = self._x_prev.copy()
            self._transition = transition(x[X_R].reshape(3, 3), f_m - x[X_BA], w_m - x[X_BG],
                                          x[X_XI], dt, phi_ins, earth_fixed)
        return self._transition

    @property
    def F(self) -> Array:
        """The last propagation's error-state transition, dense (:func:`transition_matrix`;
        the identity before the first)."""
        tr = self.transition
        return _I_N.copy() if tr is None else transition_matrix(tr)

    # ------------------------------------------------------------------ update
    def update(self, channel: str, y: Array, H: Array, Rm: Array,
               gate: float | None = None, *, t: float = math.nan, source: str = "",
               only: slice | None = None) -> Outcome:
        """One Kalman update on the error state (paper eq. 16), Joseph form, then error
        injection (16d) and reset with its Jacobian (17, 18).

        Args:
            channel: the measurement's name in the records.
            y: the innovation (measurement minus prediction).
            H: its Jacobian with respect to the error state (``len(y)`` x 23).
            Rm: its noise covariance.
            gate: the NIS above which the update is rejected; None = the configured gate
                (:meth:`gate`), 0 = no gate.
            t, source: the measurement's time (s) and sample source, for its record.
            only: the error-state block the update may correct (a Schmidt-Kalman update,
                Schmidt 1966: the other rows of the gain are zeroed, the Joseph form keeps
                the covariance right for that gain); None = all.

        Returns:
            What became of it (:class:`Outcome`; false when the gate rejects it).
        """
        if gate is None:
            gate = self.gate(len(y))
        if self.compiled:
            return self._fuse(channel, y, H, Rm, gate, t, source, only)
        outcome = Outcome.FUSED
        if self.params.noise.adapt_updates > 0:
            if channel in NOISE_ADAPT_CHANNELS:
                Rm = Rm * self._adapt_noise(channel, y, self._project(H), Rm)
            elif channel == PROCESS_ADAPT_CHANNEL and self.dvl_own_noise:
                self._relax_process()
            elif channel == PROCESS_ADAPT_CHANNEL:
                self._adapt_process(y, self._project(H), Rm)
        up = self._kalman(y, H, Rm, only)
        self.y, self.S, self.nis = y, up.S, up.nis
        if gate > 0 and up.nis > gate:
            n_rej = self._consecutive.get(channel, 0) + 1
            self._consecutive[channel] = n_rej
            if n_rej <= self.params.max_consecutive_rejects:
                self._record(channel, t, source, gate, accepted=False)
                return Outcome.GATED
            # recover: fuse, down-weighted so that the NIS equals the gate
            outcome = Outcome.RECOVERED
            up = self._kalman(y, H, Rm * (up.nis / gate), only)
        self._consecutive[channel] = 0
        self._record(channel, t, source, gate, accepted=True)
        self._inject_and_reset(up.x, up.P)
        return outcome

    def _fuse(self, channel: str, y: Array, H: Array, Rm: Array, gate: float, t: float,
              source: str, only: slice | None) -> Outcome:
        """:meth:`update` with :attr:`compiled`: its noise adaptation, Kalman update, gate
        and injection in one call of :func:`.eseso_kernel.fuse` (:attr:`x` and :attr:`P`
        written in place), the bookkeeping (the adaptation's means, the rejections in a
        row, the record) here."""
        kernel = _kernel()
        c = self.params.noise
        adapt, key = kernel.ADAPT_NONE, channel
        if c.adapt_updates > 0 and channel in NOISE_ADAPT_CHANNELS:
            adapt = kernel.ADAPT_NOISE
        elif c.adapt_updates > 0 and channel == PROCESS_ADAPT_CHANNEL:
            if self.dvl_own_noise:
                self._relax_process()
            else:
                adapt, key = kernel.ADAPT_PROCESS, "process"
        n_rej = self._consecutive.get(channel, 0) + 1
        lo, hi = (0, N_ERR) if only is None else (only.start, only.stop)
        outcome, nis, S, mean, scale = kernel.fuse(
            self.x, self.P, y, H, Rm, lo, hi, gate,
            n_rej > self.params.max_consecutive_rejects, adapt, c.adapt_updates,
            self._noise_mean.get(key, 1.0), self.process_scale, c.scale_max, NOISE_SAMPLE_CAP)
        if adapt != kernel.ADAPT_NONE:
            self._noise_mean[key] = mean
            if adapt == kernel.ADAPT_NOISE:
                self.noise_scale[channel] = scale
            else:
                self.process_scale = scale
        return self._settle(channel, outcome, y, S, nis, gate, n_rej, t, source)

    def _settle(self, channel: str, outcome: int, y: Array, S: Array, nis: float,
                gate: float, n_rej: int, t: float, source: str) -> Outcome:
        """The bookkeeping of a compiled update (:meth:`_fuse`, the thrust's) whose
        ``outcome`` (:data:`.eseso_kernel.FUSED` ...) is known: the last innovation, the
        rejections in a row (``n_rej`` with this one), the record."""
        kernel = _kernel()
        if outcome == kernel.SINGULAR:
            raise np.linalg.LinAlgError("Singular matrix")
        self.y, self.S, self.nis = y, S, nis
        if outcome == kernel.GATED:
            self._consecutive[channel] = n_rej
            self._record(channel, t, source, gate, accepted=False)
            return Outcome.GATED
        self._consecutive[channel] = 0
        self._record(channel, t, source, gate, accepted=True)
        return Outcome.RECOVERED if outcome == kernel.RECOVERED else Outcome.FUSED

    def _kalman(self, y: Array, H: Array, Rm: Array, only: slice | None
                ) -> kalman.KalmanUpdate:
        """The Kalman update (:func:`.kalman.update`) of the error state from zero with the
        innovation ``y``, Jacobian ``H`` and noise ``Rm``; ``only`` the block it may correct
        (None = all). ``S`` is symmetrized and inverted by LU (``np.linalg.inv``); its
        ``x`` is the correction ``dx``."""
        return kalman.update(_NO_ERROR, self.P, y, Rm, H, keep=only, symmetric=True,
                             inverse=np.linalg.inv)

    def _inject_and_reset(self, dx: Array, P: Array) -> None:
        """:meth:`inject` the correction ``dx`` and reset the updated covariance ``P``
        (17b: ``G = I`` except the attitude block, ``I - [dtheta/2]x``, Sola eq. 287;
        :func:`reset_covariance`)."""
        self.inject(dx)
        self.P = reset_covariance(P, dx[TH])

    def _project(self, H: Array) -> Array:
        """``H P H^T``."""
        return H @ (self.P @ H.T)

    def _adapt_noise(self, channel: str, y: Array, HPHt: Array, Rm: Array) -> float:
        """The variance scale of ``channel``'s configured noise ``Rm`` after this update's
        innovation ``y`` (covariance matching, Mehra 1970; Mohamed & Schwarz 1999):
        ``E[y y^T] = H P H^T + s R``, so ``(y^T y - tr(H P H^T)) / tr(R)`` is a sample of
        ``s``; its exponential mean over ``noise.adapt_updates`` updates (each sample
        capped at :data:`NOISE_SAMPLE_CAP`), clipped to [1, ``noise.scale_max``] (the
        thrust channel's to [1, ``noise.thrust_scale_max``]), is the scale. One-sided:
        noise larger than configured is learnt, smaller is not."""
        c = self.params.noise
        sample = (float(y @ y) - float(HPHt.trace())) / max(float(Rm.trace()), 1e-300)
        sample = min(sample, NOISE_SAMPLE_CAP)
        mean = self._noise_mean.get(channel, 1.0)
        mean += (sample - mean) / c.adapt_updates
        self._noise_mean[channel] = mean
        ceiling = c.thrust_scale_max if channel == "thrust" else c.scale_max
        scale = min(max(mean, 1.0), ceiling)
        self.noise_scale[channel] = scale
        return scale

    def _learn_disturbance_excess(self, y: Array, S_model: Array) -> None:
        """Learn :attr:`disturbance_excess` from the thrust innovation ``y`` (N) and its
        covariance ``S_model = H P H^T + R_tau`` as the filter's model gives it (the
        configured thrust noise, before the learnt scale and the Huber weight). With
        ``H[:, XI] = -I`` the innovation carries the prior error of ``xi`` one to one, so
        covariance matching (Mehra 1972) on each body axis, ``E[y_i^2] = r_i S_ii`` with
        ``r_i = 1 + D_ii / S_ii``, makes ``y_i^2 / S_ii`` a sample of ``r_i``, and ``D_ii``
        is the error variance of ``xi`` that ``P`` does not carry (a lumped disturbance
        moving faster than its process noise allows), or, negative, that ``P`` carries in
        excess (its process noise set for the controller, above the disturbance's own).
        ``r_i`` is the exponential mean of its samples (each capped at
        :data:`NOISE_SAMPLE_CAP`; a ratio, so the start, whose ``S`` is the initial
        disturbance sigma's 1600 N^2, weighs no more than any other update): over
        ``noise.adapt_updates`` updates where it is above 1, over
        :data:`NARROWING_MEMORY` times as many where it is below.

        An excess of ``E[y_i^2]`` is the disturbance's only as far as successive
        innovations share it: an error of ``xi`` that ``P`` does not carry persists from
        one update to the next, while sensor noise beyond ``R_tau`` is white and shows in
        ``E[y_i^2]`` alone (Mehra 1970's correlation method: ``R`` enters only the lag-0
        covariance). So the widening is at most ``c_i``, the exponential mean (over
        ``noise.adapt_updates``) of the lag-1 products ``u_k u_(k-1)`` of ``u = y_i /
        sqrt(S_ii)`` (each within +-:data:`NOISE_SAMPLE_CAP`): the excess is ``(min(max(r_fast
        - 1, 0), max(c, 0)) + min(r_slow - 1, 0)) S_ii`` at this update. With
        :attr:`compiled`, the same in :func:`.eseso_kernel.learn_excess` (the means, the
        last ``u`` and the excess written in place)."""
        n = self.params.noise.adapt_updates
        if self.compiled:
            _kernel().learn_excess(y, S_model, self._excess_ratio, self._excess_ratio_slow,
                                   self._excess_lag, self._last_thrust_u,
                                   self.disturbance_excess, n, NARROWING_MEMORY * n,
                                   NOISE_SAMPLE_CAP)
            return
        S_ii = S_model.diagonal()
        sample = np.minimum(y * y / np.maximum(S_ii, 1e-300), NOISE_SAMPLE_CAP)
        self._excess_ratio += (sample - self._excess_ratio) / n
        self._excess_ratio_slow += (sample - self._excess_ratio_slow) / (NARROWING_MEMORY * n)
        u = y / np.sqrt(np.maximum(S_ii, 1e-300))
        lag = np.clip(u * self._last_thrust_u, -NOISE_SAMPLE_CAP, NOISE_SAMPLE_CAP)
        self._last_thrust_u = u
        self._excess_lag += (lag - self._excess_lag) / n
        wider = np.minimum(np.maximum(self._excess_ratio - 1.0, 0.0),
                           np.maximum(self._excess_lag, 0.0))
        self.disturbance_excess = (wider + np.minimum(self._excess_ratio_slow - 1.0, 0.0)) * S_ii

    def published_disturbance_var(self) -> Array:
        """Variance (N^2, body, per axis) of the published lumped disturbance: the
        covariance's ``P[xi, xi]`` plus :attr:`disturbance_excess`, the error variance
        the thrust innovations show beyond it. The filter's own gain, and so ``xi``
        (what a controller consumes), keeps ``P`` alone (docs/eseso-mpc.md, "What the
        controller needs and what the sigma claims")."""
        p = np.maximum(np.diag(self.P)[XI], 0.0)
        return np.maximum(p + self.disturbance_excess, PUBLISHED_VAR_MIN_SHARE * p)

    def _adapt_dvl_noise(self, var: float) -> None:
        """Learn the DVL's own noise scale from the update just fused (:attr:`y`, :attr:`S`;
        its noise ``var`` per axis before the scale): the windowed lag-1 correlation of
        ``w = y / sqrt(tr S)`` over ``noise.adapt_updates`` updates; once that many are in
        and it is below :data:`DVL_OWN_NOISE_LAG1` (:attr:`dvl_own_noise`, until it is above
        :data:`DVL_OWN_NOISE_RELEASE_LAG1`), covariance matching on the DVL's noise as on
        the other sensors' (:meth:`_adapt_noise`, ``H P H^T = S - s R_0``), its scale that
        of the next updates. Held otherwise: the excess is then the process noise's
        (:meth:`_adapt_process`, which takes the DVL's noise with this scale; while the
        DVL's, :meth:`_relax_process`)."""
        y, S = self.y, self.S
        assert y is not None and S is not None
        c = self.params.noise
        S_trace = float(S.trace())
        w = y / math.sqrt(S_trace)
        gain = 1.0 / c.adapt_updates
        self._dvl_power += gain * (float(w @ w) - self._dvl_power)
        if self._dvl_w is not None:
            self._dvl_lag += gain * (float(w @ self._dvl_w) - self._dvl_lag)
        self._dvl_w = w
        self._dvl_updates += 1
        if self._dvl_updates >= c.adapt_updates and self._dvl_power > 0.0:
            lag1 = self._dvl_lag / self._dvl_power
            if lag1 < DVL_OWN_NOISE_LAG1:
                self.dvl_own_noise = True
            elif lag1 > DVL_OWN_NOISE_RELEASE_LAG1:
                self.dvl_own_noise = False
        scale = self.noise_scale.get("dvl", 1.0)
        if self.dvl_own_noise:
            R0 = _I3 * var
            self._adapt_noise("dvl", y, S - scale * R0, R0)
        else:
            self.noise_scale["dvl"] = scale

    def _relax_process(self) -> None:
        """A DVL update whose excess is the DVL's own (:attr:`dvl_own_noise`): the IMU's
        noise scale's mean takes a sample of 1 instead of :meth:`_adapt_process`'s, so a
        scale the DVL's excess had raised returns to the configured noise."""
        self._process_sample(1.0)

    def _adapt_process(self, y: Array, HPHt: Array, Rm: Array) -> None:
        """Scale the IMU's white noise from the DVL innovation ``y`` (a fading factor, Xia
        et al. 1994): ``(y^T y - tr(R)) / tr(H P H^T)`` is a sample of how much larger the
        prior covariance should be, and times the current scale a sample of the scale
        (the prior already carries it); its exponential mean over ``noise.adapt_updates``
        updates, clipped to [1, ``noise.scale_max``], multiplies the accelerometer and
        gyro noise variances of the next propagations (:attr:`process_scale`)."""
        ratio = (float(y @ y) - float(Rm.trace())) / max(float(HPHt.trace()), 1e-300)
        # P already carries the current scale: the sample is the scale times the ratio
        self._process_sample(min(self.process_scale * ratio, NOISE_SAMPLE_CAP))

    def _process_sample(self, sample: float) -> None:
        """One sample of the IMU's noise scale into its exponential mean over
        ``noise.adapt_updates``; :attr:`process_scale` the mean clipped to [1,
        ``noise.scale_max``]."""
        c = self.params.noise
        mean = self._noise_mean.get("process", 1.0)
        mean += (sample - mean) / c.adapt_updates
        self._noise_mean["process"] = mean
        self.process_scale = min(max(mean, 1.0), c.scale_max)

    def gate(self, dof: int) -> float:
        """The configured NIS gate of a ``dof``-dimensional update: ``gate_sigma**2 * dof``,
        or without ``gate_sigma`` the chi-square quantile of :data:`GATE_PROBABILITY`."""
        if self.params.gate_sigma > 0:
            return self.params.gate_sigma ** 2 * dof
        return chi2_quantile(GATE_PROBABILITY, dof)

    def _record(self, channel: str, t: float, source: str, gate: float,
                accepted: bool) -> None:
        """The innovation record of the update just computed (``y``, ``S``, ``nis``); a
        gate of 0 is no gate (infinite)."""
        y, S = self.y, self.S
        assert y is not None and S is not None and self.nis is not None
        self.innovations.append(Innovation(
            channel=channel, t=t, z=tuple(y.tolist()), S=tuple(S.ravel().tolist()),
            nis=self.nis, dof=len(y), gate=gate if gate > 0 else math.inf,
            accepted=accepted, reason="" if accepted else "gate", source=source))

    def inject(self, dx: Array) -> None:
        """Error injection (paper eq. 16d), ``x <- x [+] dx``: every component, velocity
        once, the attitude by right multiplication with ``Exp(dtheta)``."""
        self.p = self.p + dx[P_]
        self.v = self.v + dx[V_]
        self.R = self.R @ exp_so3(dx[TH])
        self.b_a = self.b_a + dx[BA]
        self.b_g = self.b_g + dx[BG]
        self.g = self.g + dx[G_]
        self.xi = self.xi + dx[XI]
        self.b_ins = self.b_ins + dx[BI]

    # ------------------------------------------------------------------ measurement models
    def update_position_ne(self, z: Array, var: float, *,
                           t: float = math.nan, source: str = "") -> Outcome:
        """Horizontal position ``z`` (north, east; m) with variance ``var`` (m^2) per axis;
        channel ``gnss_pos``."""
        return self.update("gnss_pos", z - self.p[:2], _H_POSITION_NE, _I2 * var, t=t,
                           source=source)

    def update_velocity_ne(self, z: Array, var: float, *,
                           t: float = math.nan, source: str = "") -> Outcome:
        """Horizontal velocity over ground ``z`` (north, east; m/s) with variance ``var``
        (m^2/s^2) per axis; channel ``gnss_vel``."""
        return self.update("gnss_vel", z - self.v[:2], _H_VELOCITY_NE, _I2 * var, t=t,
                           source=source)

    def update_zero_velocity(self, var: float, *, t: float = math.nan,
                             source: str = "") -> Outcome:
        """Zero velocity over ground (north, east, down), each with variance ``var``
        (m^2/s^2): the pseudo-measurement of a vehicle left idle with nothing else to
        bound its velocity (a ZUPT, Foxlin 2005); channel ``zupt``."""
        return self.update("zupt", -self.v, _H_ZERO_VELOCITY, _I3 * var, t=t,
                           source=source)

    def update_ins_velocity(self, z: Array, var: float, *,
                            t: float = math.nan, source: str = "") -> Outcome:
        """INS velocity over ground ``z`` (north, east; m/s) = ``v + b_ins`` + white noise
        of variance ``var`` (m^2/s^2) per axis; channel ``vog``."""
        return self.update("vog", z - self.v[:2] - self.b_ins, _H_INS_VELOCITY, _I2 * var,
                           t=t, source=source)

    def update_depth(self, depth_m: float, var: float, *,
                     t: float = math.nan, source: str = "") -> Outcome:
        """Depth (m, positive down) with variance ``var`` (m^2); channel ``depth``."""
        return self.update("depth", np.array([depth_m - self.p[2]]), _H_DEPTH,
                           np.array([[var]]), t=t, source=source)

    def update_body_velocity(self, z: Array, var: float, *,
                             t: float = math.nan, source: str = "") -> Outcome:
        """Velocity over ground in body axes ``z`` (m/s, a DVL's bottom track) with variance
        ``var`` (m^2/s^2) per axis; channel ``dvl``."""
        nu = self.R.T @ self.v
        H = np.zeros((3, N_ERR))
        H[:, V_] = self.R.T
        H[:, TH] = skew(nu)
        scale = self.noise_scale.get("dvl", 1.0)
        outcome = self.update("dvl", z - nu, H, _I3 * (var * scale), t=t, source=source)
        if outcome is Outcome.FUSED and self.params.noise.adapt_updates > 0:
            self._adapt_dvl_noise(var)
        return outcome

    def update_attitude(self, R_meas: Array, roll: float, pitch: float,
                        var_roll_pitch: float, var_yaw: float, *,
                        t: float = math.nan, source: str = "") -> Outcome:
        """Attitude ``R_meas`` (body to NED; from ``roll``, ``pitch`` in rad) with
        independent roll and pitch noise ``var_roll_pitch`` and yaw noise ``var_yaw``
        (rad^2), turned into the body-frame rotation vector; channel ``attitude``. With
        :attr:`compiled`, the innovation and its noise by
        :func:`.eseso_kernel.attitude_innovation`."""
        if self.compiled:
            y, Rm = _kernel().attitude_innovation(self.x, R_meas, roll, pitch,
                                                  var_roll_pitch, var_yaw)
            return self.update("attitude", y, _H_ATTITUDE, Rm, t=t, source=source)
        # the Euler-rate-to-body-rate matrix (Fossen eq. 2.41 inverted)
        sr, cr = math.sin(roll), math.cos(roll)
        sp, cp = math.sin(pitch), math.cos(pitch)
        J = np.array([[1.0, 0.0, -sp], [0.0, cr, sr * cp], [0.0, -sr, cr * cp]])
        Rm = J @ np.diag([var_roll_pitch, var_roll_pitch, var_yaw]) @ J.T
        return self.update("attitude", log_so3(self.R.T @ R_meas), _H_ATTITUDE, Rm, t=t,
                           source=source)

    def update_heading(self, heading_rad: float, var: float, *,
                       t: float = math.nan, source: str = "") -> Outcome:
        """True heading (rad from north) with variance ``var`` (rad^2); channel
        ``heading``."""
        roll, pitch, yaw = matrix_to_euler(self.R)
        H = np.zeros((1, N_ERR))
        # yaw rate from body rates: last row of T_Theta (Fossen eq. 2.41)
        cp = max(math.cos(pitch), 1e-3)
        H[0, TH] = [0.0, math.sin(roll) / cp, math.cos(roll) / cp]
        return self.update("heading", np.array([wrap_pi(heading_rad - yaw)]), H,
                           np.array([[var]]), t=t, source=source)

    # ------------------------------------------------------------------ thrust model
    def h_tau(self, f_m: Array, w_m: Array, wdot: Array | None = None) -> tuple[Array, Array]:
        """Predicted thruster force (N, body) at specific force ``f_m`` (m/s^2) and rate
        ``w_m`` (rad/s), and its 3 x 23 Jacobian (paper eq. 14b as re-derived in the
        module docstring). ``wdot`` is the angular acceleration (rad/s^2); without it the
        centre-of-gravity terms are left out. With :attr:`compiled`, the same in
        :func:`.eseso_kernel.h_tau`."""
        c = self.params.vehicle
        if self.compiled:
            kernel = _kernel()
            return kernel.h_tau(self.x, np.asarray(f_m, float), np.asarray(w_m, float),
                                np.zeros(3) if wdot is None else np.asarray(wdot, float),
                                wdot is not None, self.m_vec, self.d_a, self.d_l, self.d_nl,
                                c.weight_n - c.buoyancy_n, c.mass_kg, c.cg_z_m)
        f = f_m - self.b_a
        w = w_m - self.b_g
        RT = self.R.T
        nu = RT @ self.v
        gB = RT @ self.g
        zB = RT @ E3
        Anu = self.A @ nu
        W_B = c.weight_n - c.buoyancy_n
        damp = (self.d_l + self.d_nl * np.abs(nu)) * nu
        h = (self.m_vec * (f + gB) - self.A @ cross(w, nu) + cross(w, Anu)
             + damp - W_B * zB - self.xi)
        r_g = np.array([0.0, 0.0, c.cg_z_m])
        if wdot is not None:
            h = h + c.mass_kg * (cross(wdot, r_g) + cross(w, cross(w, r_g)))
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
        H[:, XI] = -_I3
        return h, H

    def model_change_var(self, tau: Array) -> Array:
        """Variance (N^2, body) the lumped disturbance gains since the last thrust update
        from the model's uncertain coefficients, at the commanded force ``tau`` (N): ``xi``
        carries ``-dk_t tau + dk_d D(nu) nu`` (relative errors of the thrust map and the
        damping), so when the thrust or the damping force changes, ``xi`` changes by those
        errors times the change. With their configured one-sigmas, per axis::

            q_model = (thrust_rel_std (tau - tau_prev))^2
                      + (damping_rel_std (D(nu) nu - D(nu_prev) nu_prev))^2

        added to ``P[xi, xi]`` before the update (zero at the first update). The mass term
        is left out: its force is the measured acceleration, whose noise is not a change of
        the model's error."""
        c = self.params.process
        nu = self.R.T @ self.v
        terms = np.array((np.asarray(tau, float), (self.d_l + self.d_nl * np.abs(nu)) * nu))
        last, self._model_terms = self._model_terms, terms
        if last is None:
            return np.zeros(3)
        return ((c.thrust_rel_std * (terms[0] - last[0])) ** 2
                + (c.damping_rel_std * (terms[1] - last[1])) ** 2)

    def thrust_noise(self, wdot_dt: float | None) -> Array:
        """Noise covariance (N^2, body) of the thrust update: what the IMU's white noise puts
        into :meth:`h_tau`, plus the thrusters' own force error ``thrust_std_n``::

            R_tau = diag((M_ii sigma_a)^2) s_imu
                    + (m z_G)^2 2 sigma_g^2 / dt_w^2 s_imu   on x and y
                    + thrust_std_n^2 I

        The second term is the centre-of-gravity force ``m w' x r_g`` with ``w'`` the
        difference of two gyro samples ``dt_w`` (s, ``wdot_dt``) apart: each carries the
        gyro's white noise ``sigma_g``, so ``w'`` carries ``sqrt(2) sigma_g / dt_w`` (0.35
        rad/s^2 at 50 Hz, 0.80 N through ``m z_G`` = 2.25 kg m on the simulated BlueROV2:
        more than the accelerometer's 0.56-0.84 N). ``s_imu`` is the learnt IMU noise
        scale (:attr:`process_scale`). Without ``wdot_dt`` (no angular acceleration) the
        second term is left out, as the force is."""
        n, v = self.params.noise, self.params.vehicle
        s_imu = self.process_scale
        var = (self.m_vec * n.accel_std_mps2) ** 2 * s_imu + n.thrust_std_n ** 2
        if wdot_dt is not None and wdot_dt > 0.0:
            var_wdot = 2.0 * n.gyro_std_rps ** 2 / wdot_dt ** 2 * s_imu
            var[:2] += (v.mass_kg * v.cg_z_m) ** 2 * var_wdot
        return np.diag(var)

    def update_thrust(self, f_m: Array, w_m: Array, wdot: Array, tau: Array, *,
                      wdot_dt: float | None = None, t: float = math.nan,
                      source: str = "") -> Outcome:
        """Update on the thruster force ``tau`` (N, body) = :meth:`h_tau` at specific force
        ``f_m``, rate ``w_m`` and angular acceleration ``wdot`` (the difference of two gyro
        samples ``wdot_dt`` s apart; its noise in :meth:`thrust_noise`); channel
        ``thrust``, never gated, down-weighted above ``thrust_huber``. The lumped
        disturbance's model-change variance (:meth:`model_change_var`) is added to its
        covariance first. With ``thrust_states = "disturbance"`` a Schmidt-Kalman update:
        the full Jacobian in ``S`` and in the covariance, the gain's rows other than
        ``dxi`` zeroed (:meth:`update`'s ``only``). With :attr:`compiled`, all of it but
        the bookkeeping in one call of :func:`.eseso_kernel.thrust_update`."""
        if self.compiled:
            return self._update_thrust_compiled(f_m, w_m, wdot, tau, wdot_dt, t, source)
        h, H = self.h_tau(f_m, w_m, wdot)
        self.P[XI, XI] += np.diag(self.model_change_var(tau))
        y = tau - h
        Rm = self.R_tau = self.thrust_noise(wdot_dt)
        HPHt = H @ self.P @ H.T  # (H P) H^T, not :meth:`_project`'s H (P H^T)
        if self.params.noise.adapt_updates > 0:  # before the Huber weight (it would learn it)
            self._learn_disturbance_excess(y, HPHt + Rm)
            Rm = Rm * self._adapt_noise("thrust", y, HPHt, Rm)
        only = XI if self.params.thrust_states == "disturbance" else None
        k = self.params.thrust_huber
        self.downweighted = False
        if k > 0:
            S = HPHt + Rm
            nis = float(y @ np.linalg.solve(S, y))
            if nis > k:
                Rm = Rm * (nis / k)
                self.downweighted = True
        return self.update("thrust", y, H, Rm, gate=0.0, t=t, source=source, only=only)

    def _update_thrust_compiled(self, f_m: Array, w_m: Array, wdot: Array, tau: Array,
                                wdot_dt: float | None, t: float, source: str) -> Outcome:
        """:meth:`update_thrust` by :func:`.eseso_kernel.thrust_update` (:attr:`x`,
        :attr:`P` and :attr:`R_tau` written in place); the bookkeeping and
        :meth:`_learn_disturbance_excess` here."""
        kernel = _kernel()
        if self._thrust_constants is None:
            self._thrust_constants = kernel.thrust_constants(self.params, NOISE_SAMPLE_CAP)
        vehicle, k = self._thrust_constants
        has_last = self._model_terms is not None
        if not has_last:
            self._model_terms = np.empty((2, 3))
        keep = XI if self.params.thrust_states == "disturbance" else slice(0, N_ERR)
        outcome, nis, S, y, S_model, mean, scale, self.downweighted = kernel.thrust_update(
            self.x, self.P, np.asarray(f_m, float), np.asarray(w_m, float),
            np.asarray(wdot, float), 0.0 if wdot_dt is None else wdot_dt,
            np.asarray(tau, float), vehicle, k, self._model_terms, has_last, self.R_tau,
            self._noise_mean.get("thrust", 1.0), self.process_scale, keep.start, keep.stop)
        if self.params.noise.adapt_updates > 0:
            self._learn_disturbance_excess(y, S_model)  # it changes neither P nor the gain
            self._noise_mean["thrust"] = mean
            self.noise_scale["thrust"] = scale
        return self._settle("thrust", outcome, y, S, nis, 0.0, 1, t, source)
