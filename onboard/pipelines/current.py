"""Water current from over-ground minus through-water velocity (algorithms.md §3-§4).

Papers: Kim, Fan & Bose, IEEE Access 6 (2018) (model-based high-gain observer, RLS
identification, Gavia AUV); Fan, Xu, Chen & Zhang, OCEANS (~2016) (nonlinear observer,
flow-relative model, pole placement).

Both papers compute ``V_c = v_OG - R nu_r`` (Kim eq. 1) with ``nu_r`` the body-frame
velocity through water from a model-based observer. Here the current is not a difference
of two separately estimated quantities but a state of its own, estimated jointly with the
through-water velocity:

    x = [nu_r (body, nd), V_c (earth, nd)]        nd = 3 submerged vehicles, 2 surface boats
    nu_r' = f(nu_r, omega, attitude, u; theta)    regression model, vehicle_models.py
    V_c'  = w_c                                   slowly varying (random walk)

Measurements (each with its own noise):

* velocity over ground in earth axes (``VelocityOverGround``; GNSS SOG/COG at the surface):
  ``z = R nu_r + V_c`` (Kim eq. 1);
* DVL bottom track, body axes: ``z = nu_r + R^T V_c``;
* DVL water track, body axes: ``z = nu_r`` (direct through-water measurement).

A straight line at constant thrust cannot separate a current along the track from a thrust
error; a turn can, because the current is fixed in the earth frame while the model acts in
the body frame (notably: the sway equation says a hull does not crab through water in steady
flight). The filter's covariance says so honestly: ``std_*`` stays large until the vehicle
has turned.

Three gains for the same model and state, ``[pipelines.current] observer =``:

* ``"kf"`` (default): the Kalman gain (extended KF);
* ``"hgo"``: the high-gain observer of Kim et al. with the LMI gain and the increasing-gain
  law of Alessandri & Rossi (:mod:`.hgo`);
* ``"flow"``: the nonlinear observer of Fan et al. (:mod:`.flow_observer`), which observes
  ``nu_r`` from the attitude through the yaw dynamics; the current is then ``V_g - R nu_r``.

Whatever the gain, the covariance is propagated for that gain (Joseph form), so the
one-sigma values are those of the observer actually running, and a running mean of the
innovation NIS rescales the process noise (innovation-based calibration).

Online identification (Kim et al. §II.B use RLS). The coefficients ``theta`` of the
velocity DOFs are appended to the state, ``x = [nu_r, V_c, theta]``, with
``theta' = 0`` and the RLS forgetting/bounded-covariance rule of :mod:`.rls` applied to
their covariance block. For a known regressor this *is* RLS with forgetting; here the
regressor depends on ``nu_r = R^T (v_g - V_c)``, and the joint filter keeps the
correlation between ``theta`` and ``V_c``. A separate identify-then-observe loop (RLS on
``v_g - V_c_hat``) was tried first and locks in its own errors: on a straight leg after a
turn a biased current makes the sway regressor constant, RLS forgets the sway damping and
the bias stays (measured: 0.14 m/s bias, 0.03 m/s claimed sigma, synthetic boat). The
auxiliary yaw channel (needed by the flow observer) uses :class:`.rls.RecursiveLeastSquares`
on state-variable-filtered data, with ``nu_r`` from this filter. Mode (a): coefficients
configured in ``[pipelines.current.model.<dof>]`` (tight prior, refined unless
``identify = false``); mode (b): no coefficients, a weak generic prior (vehicle_models.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

import msgspec
import numpy as np

from onboard.core.config import CONFIG_DIR, Config, ConfigError, decode_section
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
    Sample,
    VelocityOverGround,
)
from onboard.estimators.hgo import GainDesign, IncreasingGain, current_hgo_gain
from onboard.estimators.rls import RecursiveLeastSquares
from onboard.estimators.vehicle_models import ModelInputs, RegressionModel, kind_for_class

GRAVITY = 9.81
"""m/s^2, for the net-weight prior (``CurrentConfig.net_weight_std``)."""

GAIN_DIR = CONFIG_DIR / "gains"
"""Precomputed LMI gains for the bundled configs (``onboard design-gain``)."""


class CurrentConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """``[pipelines.current]``: hyperparameters of the current pipeline (SI units)."""

    enabled: bool = True
    observer: Literal["kf", "hgo", "flow"] = "kf"
    model_kind: Literal["", "torpedo", "surface-rudder", "surface-twin", "rov"] = ""
    """Regression model; empty: from ``vehicle.class``."""
    model: dict[str, dict[str, float]] = {}
    """Configured coefficients by DOF and term (vehicle_models.py names), mode (a)."""
    identify: bool = True
    """Identify the model online (joint state). False: keep the configured model fixed."""
    model_rel_std: float = 0.2
    """Prior one-sigma of configured coefficients, relative (plus ``theta_std_floor``)."""
    theta_std: float = 1.0
    """Prior one-sigma of unconfigured coefficients (mode (b)), except the net-weight ones."""
    net_weight_std: Annotated[float, msgspec.Meta(gt=0.0)] = 0.02
    """Prior one-sigma of the net weight ``(W - B) / W`` of the vehicle (fraction of its
    weight), for the unconfigured surge and sway net-weight coefficients (``sin(theta)``,
    ``cos(theta)sin(phi)``: ``+-(W - B) / (m - X_idot)``, vehicle_models.
    NET_WEIGHT_REGRESSORS; not the heave constant ``cos(theta)cos(phi)``, which keeps
    ``theta_std``): their prior one-sigma is ``g * net_weight_std`` (m/s^2), an upper
    bound on every DOF since its mass term is at least ``m``. 0.02: an underwater vehicle
    is trimmed within a few percent of neutral (the SITL REMUS, Prestero 2001: 7 N positive
    on 299 N, 2.3 %; the BlueROV2 of algorithms.md §5.4: 0.66 N, 0.6 %). Without it
    (``theta_std``, 1 m/s^2 ~ 10 %) a steady roll makes the sway term an unknown side force
    that trades against a cross-track current (docs/current.md, "Net-weight prior")."""
    theta_std_floor: float = 0.02
    forgetting: float = 0.9995
    """Forgetting of the coefficient covariance per tick (0.9995 at 10 Hz: 200 s memory),
    variable-rate: none once the covariance is back at its prior (bounded, rls.py)."""
    rpm_scale: float = 1000.0
    """Propeller rpm divided by this gives the normalized propulsion ``n``."""
    svf_cutoff_hz: float = 0.3
    """State-variable filter cut-off for the yaw-channel RLS (algorithms.md §3.4)."""
    current_walk: float = 0.01
    """Random walk of the current, m/s per sqrt(s), before calibration (0.01: 0.08 m/s in a
    minute, 1 sigma; turbulence and tides; the innovation calibration raises it)."""
    accel_std: float = 0.02
    """Model acceleration error (process noise) per DOF, m/s^2 over ``model_error_time_s``."""
    model_error_time_s: float = 1.0
    heading_diversity: float = 0.85
    heading_memory_s: float = 300.0
    """Without a surge model the along-track sigma is floored at the prior unless the
    headings of the last ``heading_memory_s`` are diverse: the mean of the doubled-angle
    unit vector (cos 2psi, sin 2psi) shorter than ``heading_diversity``. Doubled, because
    reversing course (a glider's back-and-forth, a lawnmower survey) keeps the same lateral
    axis and adds nothing to the sway constraint. 0.85: e.g. two headings 35 deg apart; a
    +-15 deg zig-zag gives 0.87 and keeps the floor."""
    turn_accel_gain: float = 1.0
    """Extra model acceleration error in turns, m/s^2 per (m/s * rad/s) of ``u_r r``."""
    prior_accel_std: float = 0.3
    """Model acceleration error of a DOF that has only the generic prior (mode (b), not yet
    identified), m/s^2: the prior says "no crabbing", not how much."""
    init_current_std: float = 1.0
    """Prior one-sigma of the current (m/s) before any turn has made it observable."""
    identify_max_current_std: float = 0.1
    """The coefficients are updated only once the current's one-sigma is below this (m/s)."""
    identify_min_rate: float = 0.03
    """A yaw rate (rad/s) above this marks a turn, which makes the model identifiable."""
    identify_after_turn_s: float = 30.0
    """Coefficients are updated during turns and this long after them (s)."""
    yaw_rls_p0: float = 1e6
    """Initial covariance of the yaw-channel RLS: large, because its regressors (u v,
    u^2 dr at small rates) are O(0.001-0.01) and ``lambda + phi^T P phi`` must be ruled by
    the data (p0 = 100 gave coefficients 6x too small, spheroid)."""
    yaw_forgetting: float = 0.9995
    identify_straight: bool = False
    """Identify on straight lines too: only where the current is known (a calm-water
    identification run with ``init_current_std`` ~ 0 and ``current_walk`` ~ 0)."""
    identify_min_speed: float = 0.2
    """Below this through-water speed the yaw RLS does not learn."""
    gnss_velocity_std: float | None = None
    """One-sigma of GNSS velocity components (m/s); default from ``[sensors.gnss]``."""
    dvl_velocity_std: float | None = None
    gate_nis: float = 30.0
    """Innovations with a larger NIS are rejected (counted in health)."""
    calibrate: bool = True
    """Inflate the process noise when the innovation NIS says it is too small."""
    calibrate_block: int = 50
    """Innovations averaged per calibration block (whiteness test)."""
    gain_file: str = ""
    """HGO gain JSON (``onboard design-gain``); default ``config/gains/<class>.json``."""
    gamma: float | None = None
    gamma_0: float | None = None
    rho: float | None = None
    gamma_max: float | None = None
    flow_poles: list[float] = []
    """Flow-observer poles (1/s, negative); empty: the defaults of flow_observer.py."""


def _rot(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Body-to-earth rotation (ZYX Euler), NED/FRD."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def _inv_small(S: np.ndarray) -> np.ndarray | None:
    """Inverse of a 2x2 or 3x3 matrix (the innovation covariance) by the adjugate, or
    None if it is singular; larger sizes by numpy. ``np.linalg.inv`` costs several µs of
    call overhead at these sizes."""
    m = len(S)
    if m == 2:
        (a, b), (c, d) = S.tolist()
        det = a * d - b * c
        if det == 0.0:
            return None
        return np.array([[d / det, -b / det], [-c / det, a / det]])
    if m == 3:
        (a, b, c), (d, e, f), (g, h, i) = S.tolist()
        A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
        det = a * A + b * B + c * C
        if det == 0.0:
            return None
        return np.array([[A / det, (c * h - b * i) / det, (b * f - c * e) / det],
                         [B / det, (a * i - c * g) / det, (c * d - a * f) / det],
                         [C / det, (b * g - a * h) / det, (a * e - b * d) / det]])
    try:
        return np.linalg.inv(S)
    except np.linalg.LinAlgError:
        return None


class StateVariableFilter:
    """``H(s) = w^2 / (s^2 + 2 zeta w s + w^2)`` on a vector; gives the filtered value and
    its derivative, so ``d/dt (H y) = (H phi)^T theta`` holds exactly for constant theta.

    ``y`` and ``dy`` are lists of floats (a handful of channels: cheaper than numpy).
    """

    def __init__(self, n: int, cutoff_hz: float, zeta: float = 0.8) -> None:
        self.w = 2.0 * math.pi * cutoff_hz
        self.zeta = zeta
        self.y = [0.0] * n
        self.dy = [0.0] * n
        self.primed = False

    def update(self, dt: float, u: Sequence[float]) -> None:
        """Advance by ``dt`` (s) with input ``u`` held over the step."""
        if not self.primed:
            self.y = [float(a) for a in u]
            self.dy = [0.0] * len(self.y)
            self.primed = True
            return
        w, z = self.w, self.zeta
        n_sub = max(1, math.ceil(dt * w / 0.3))
        h = dt / n_sub
        ww, zw = w * w, 2.0 * z * w
        y, dy = self.y, self.dy
        for _ in range(n_sub):  # semi-implicit Euler, stable for w h < 2
            dy = [d + h * (ww * (a - b) - zw * d) for a, b, d in zip(u, y, dy)]
            y = [b + h * d for b, d in zip(y, dy)]
        self.y, self.dy = y, dy


class CurrentPipeline:
    """Pipeline ``current``: water current with one-sigma, any vehicle class.

    Inspectable attributes (filterpy style): ``x`` (state ``[nu_r, V_c, theta]``), ``P``
    (covariance), ``y`` (last velocity innovation), ``S`` (its covariance), ``nis``,
    ``thetas`` (model coefficients in use, per channel), ``yaw_rls`` (aux yaw channel),
    ``gamma`` (HGO gain).
    """

    name = "current"

    def __init__(self, cfg: CurrentConfig, kind: str, sensors: Any,
                 configured: bool, gain: GainDesign | None = None) -> None:
        self.cfg = cfg
        self.model = RegressionModel(kind)
        self.nd = nd = self.model.nd
        self.columns: tuple[str, ...] = ("north", "east") + (("down",) if nd == 3 else ()) + (
            "std_north", "std_east") + (("std_down",) if nd == 3 else ()) + (
            "u_r", "v_r") + (("w_r",) if nd == 3 else ())
        self.configured = configured
        base = self.model.default_thetas()
        self.thetas = (self.model.thetas_from_mapping(cfg.model, base) if cfg.model else base)
        # coefficient prior: configured terms tight, the others loose, except the net-weight
        # terms, whose scale is physics (net_weight_std)
        prior_sd: list[np.ndarray] = []
        sd_nw = GRAVITY * cfg.net_weight_std
        for ch, th in zip(self.model.channels, self.thetas):
            given = cfg.model.get(ch, {})
            nw = self.model.net_weight_terms[ch]
            sd = np.array([cfg.model_rel_std * abs(v) + cfg.theta_std_floor if k in given
                           else sd_nw if k in nw else cfg.theta_std
                           for k, v in zip(self.model.terms[ch], th)])
            prior_sd.append(sd)
        self._sizes = [len(self.model.terms[c]) for c in self.model.dofs]
        self._prior_dof = [c not in cfg.model for c in self.model.dofs]
        # an assumed (prior) model constrains its own DOF only: its cross-coupling terms
        # (u v, u w, ...) would otherwise "measure" the surge speed from made-up
        # coefficients (measured: 1.3 m/s along-track error claimed at 0.06, Gavia, mode b).
        # The mask is lifted once the DOF's coefficients are identified (trace of their
        # covariance below a quarter of the prior's). ``_masked[i]``: DOF i is still the
        # generic prior, its row of the model Jacobian keeps only the diagonal.
        self._masked: list[bool] = list(self._prior_dof)
        self.n_theta = sum(self._sizes) if cfg.identify else 0
        n = 2 * nd + self.n_theta
        self.x = np.zeros(n)
        if self.n_theta:
            self.x[2 * nd:] = np.concatenate(self.thetas[:nd])
        p_diag = [1.0] * nd + [cfg.init_current_std ** 2] * nd
        if self.n_theta:
            p_diag += list(np.concatenate(prior_sd[:nd]) ** 2)
        self.P = np.diag(p_diag)
        # prior trace of each DOF's coefficients (the mask is lifted below a quarter of it);
        # the generic prior's variances (a reset without finite coefficients)
        self._tr_theta0 = [float(np.sum(sd ** 2)) for sd in prior_sd[:nd]]
        self._theta_var_generic = np.concatenate([
            [sd_nw ** 2 if k in self.model.net_weight_terms[c] else cfg.theta_std ** 2
             for k in self.model.terms[c]] for c in self.model.dofs])
        self._tr_theta_max = float(np.sum(p_diag[2 * nd:])) if self.n_theta else 0.0
        self.yaw_rls = None
        if "yaw" in self.model.aux:
            i = self.model.channels.index("yaw")
            self.yaw_rls = RecursiveLeastSquares(
                len(self.thetas[i]), forgetting=cfg.yaw_forgetting, p0=cfg.yaw_rls_p0,
                theta0=self.thetas[i], names=self.model.terms["yaw"], sigma2_0=1e-3)
            if "yaw" in cfg.model:
                self.yaw_rls.P = np.diag(prior_sd[i] ** 2)
        self.gnss_std = cfg.gnss_velocity_std or sensors.gnss.velocity_std_mps
        self.dvl_std = cfg.dvl_velocity_std or sensors.dvl.velocity_std_mps
        self.dvl_max_fom = sensors.dvl.max_fom_mps
        self.surface_depth = sensors.depth.surface_depth_m
        self.y = np.zeros(nd)
        self.S = np.eye(nd)
        self.nis = 0.0
        self.q_scale = 1.0
        self._nis_avg = 1.0
        self._blk_y = np.zeros(nd)
        self._blk_S = np.zeros((nd, nd))
        self._blk_n = 0
        self._eye_n = np.eye(2 * nd + self.n_theta)
        # measurement matrices without the rotation, per (kind, dimension): earth
        # z = R nu_r + V_c, bottom track z = nu_r + R^T V_c, water track z = nu_r
        self._H0: dict[tuple[str, int], np.ndarray] = {}
        for meas_kind in ("earth", "bottom", "water"):
            for m in {2, nd}:
                H = np.zeros((m, 2 * nd + self.n_theta))
                H[:, :nd] = 0.0 if meas_kind == "earth" else np.eye(nd)[:m]
                H[:, nd:2 * nd] = np.eye(nd)[:m] if meas_kind == "earth" else 0.0
                self._H0[(meas_kind, m)] = H
        self._i_yaw = self.model.channels.index("yaw") if "yaw" in self.model.channels else -1
        # vehicle state from samples
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
        self._have_rates = False
        self._yaw_prev: tuple[float, float] | None = None
        self.depth: float | None = None
        self._t: float | None = None
        self._last_turn_t = -math.inf
        self._hvec = (1.0, 0.0)
        self._identifying = False
        self._started = False
        # (t, body-frame over-ground velocity (the measurement itself without the flow
        # observer), kind)
        self._last_vg: tuple[float, np.ndarray, str] | None = None
        self._last_meas_t: float | None = None
        self._last_vg_std = 0.0
        self._svf = (StateVariableFilter(1 + len(self.model.terms["yaw"]), cfg.svf_cutoff_hz)
                     if self.yaw_rls is not None else None)
        # HGO
        self.gain = gain
        self.gamma = 0.0
        self._law: IncreasingGain | None = None
        if cfg.observer == "hgo":
            g = gain or GainDesign.analytic()
            self.gain = g
            self._k = g.chain_gain(0) / g.time_scale_s ** np.arange(1, 3)
            g0 = cfg.gamma_0 if cfg.gamma_0 is not None else (
                cfg.gamma if cfg.gamma is not None else g.gamma_0)
            self._law = IncreasingGain(g0, cfg.rho if cfg.rho is not None else (
                0.0 if cfg.gamma is not None else g.rho),
                cfg.gamma_max if cfg.gamma_max is not None else (
                    cfg.gamma if cfg.gamma is not None else g.gamma_max))
            self.gamma = self._gamma_init = self._law.gamma
            self.hx = np.zeros(2 * nd)
            self.hP = self.P[:2 * nd, :2 * nd].copy()
            self._hJ = -np.eye(nd)
        self.flow = None
        if cfg.observer == "flow":
            from onboard.estimators.flow_observer import FlowObserver
            self.flow = FlowObserver(self.model, poles=cfg.flow_poles or None,
                                     psi_std=sensors.compass.heading_std_rad)
        self.counters: dict[str, float] = {"rejected_invalid_dvl": 0, "rejected_gate": 0,
                                           "rejected_nonfinite": 0, "updates": 0,
                                           "rls_updates": 0}
        # sample handlers by exact class (the sample classes have no subclasses): one dict
        # look-up per sample instead of a chain of isinstance tests
        self._handlers: dict[type, Callable[[Any, list], None]] = {
            Attitude: self._on_attitude, Heading: self._on_heading, Imu: self._on_imu,
            ActuatorCommand: self._on_command, Depth: self._on_depth,
            VelocityOverGround: self._on_vog, DvlVelocity: self._on_dvl,
            DvlPosition: self._on_dvl_position, GnssFix: self._on_gnss}

    # ------------------------------------------------------------------ samples
    def _on_attitude(self, s: Attitude, meas: list) -> None:
        if not (math.isfinite(s.roll_rad) and math.isfinite(s.pitch_rad)
                and math.isfinite(s.yaw_rad)):
            self.counters["rejected_nonfinite"] += 1
            return
        self._set_attitude(s.t, s.roll_rad, s.pitch_rad, True)
        self._set_yaw(s.t, s.yaw_rad)
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
            self.counters["rejected_nonfinite"] += 1
            return
        self._set_attitude(s.t, s.roll_rad, s.pitch_rad, False)

    ATTITUDE_FALLBACK_S = 1.0
    """A ``DvlPosition`` roll/pitch is used only this long (s) after the last
    ``Attitude`` sample: the vehicle's attitude reference comes first."""

    def _set_attitude(self, t: float, roll: float, pitch: float, primary: bool) -> None:
        """Take roll and pitch (rad, ZYX Euler, FRD/NED: pitch positive nose up, roll
        positive starboard down) stamped ``t`` if it is the newest at or before the step
        time; a sample stamped after the step time is held until a step reaches it."""
        if t > self._step_t:
            if len(self._att_later) >= 64:  # stamps far ahead of the ticks: keep the newest
                del self._att_later[0]
            self._att_later.append((t, roll, pitch, primary))
            return
        if primary:
            self._ahrs_t = max(self._ahrs_t, t)
        elif t - self._ahrs_t <= self.ATTITUDE_FALLBACK_S:
            return
        if t < self._att_t:
            return
        self._att_t = t
        self.roll = self.inp.roll = roll
        self.pitch = self.inp.pitch = pitch

    def _on_heading(self, s: Heading, meas: list) -> None:
        if not math.isfinite(s.heading_rad):
            self.counters["rejected_nonfinite"] += 1
            return
        h = s.heading_rad + ((s.declination_rad or 0.0) if s.reference == "magnetic" else 0.0)
        self._set_yaw(s.t, h)

    def _on_imu(self, s: Imu, meas: list) -> None:
        if math.isfinite(s.gyro_z):
            self.inp.p, self.inp.q, self.inp.r = s.gyro_x, s.gyro_y, s.gyro_z
            self._have_rates = True

    def _on_command(self, s: ActuatorCommand, meas: list) -> None:
        x = self.inp
        if s.propeller_rpm is not None:
            x.n = s.propeller_rpm / self.cfg.rpm_scale
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

    def _on_depth(self, s: Depth, meas: list) -> None:
        self.depth = s.depth_m

    def _on_vog(self, s: VelocityOverGround, meas: list) -> None:
        z = [s.v_north_mps, s.v_east_mps] + ([s.v_down_mps] if (
            self.nd == 3 and s.v_down_mps is not None) else [])
        if not all(math.isfinite(v) for v in z):
            self.counters["rejected_nonfinite"] += 1
            return
        meas.append(("earth", s.t, np.array(z), self.dvl_std))

    def _on_dvl(self, s: DvlVelocity, meas: list) -> None:
        if not s.valid or (s.fom_mps is not None and s.fom_mps > self.dvl_max_fom):
            self.counters["rejected_invalid_dvl"] += 1
            return
        z = [s.vx, s.vy, s.vz][: self.nd]
        if not all(math.isfinite(v) for v in z):
            self.counters["rejected_nonfinite"] += 1
            return
        std = max(self.dvl_std, s.fom_mps or 0.0)
        meas.append(("bottom" if s.track == "bottom" else "water", s.t, np.array(z), std))

    def _on_gnss(self, s: GnssFix, meas: list) -> None:
        if s.sog_mps is None or s.cog_rad is None or s.fix_quality == 0:
            return
        if self.depth is not None and self.depth > self.surface_depth:
            return
        if not (math.isfinite(s.sog_mps) and math.isfinite(s.cog_rad)):
            self.counters["rejected_nonfinite"] += 1
            return
        z = np.array([s.sog_mps * math.cos(s.cog_rad), s.sog_mps * math.sin(s.cog_rad)])
        meas.append(("earth", s.t, z, self.gnss_std))

    def _set_yaw(self, t: float, yaw: float) -> None:
        if not self._have_rates and self._yaw_prev is not None:
            t0, y0 = self._yaw_prev
            if t - t0 > 1e-3:
                r = wrap_pi(yaw - y0) / (t - t0)
                self.inp.r += min(1.0, (t - t0) / 0.3) * (r - self.inp.r)
        self._yaw_prev = (t, yaw)
        self.yaw = yaw

    # ------------------------------------------------------------------ filter
    def _R(self) -> np.ndarray:
        if self.nd == 3:
            return _rot(self.roll, self.pitch, self.yaw or 0.0)
        c, s = math.cos(self.yaw or 0.0), math.sin(self.yaw or 0.0)
        return np.array([[c, -s], [s, c]])

    def _unpack_thetas(self) -> None:
        """Copy the coefficient part of the state into ``thetas`` (velocity DOFs)."""
        if not self.n_theta:
            return
        o = 2 * self.nd
        for i, k in enumerate(self._sizes):
            self.thetas[i] = self.x[o:o + k]
            o += k

    def _predict(self, dt: float) -> None:
        """x <- x + dt f(x); P <- D (F P F^T + Q) D with the coefficient forgetting
        ``D = diag(1 (nu_r, V_c), 1/sqrt(lam) (theta))`` (rls.py rule).

        ``Q`` has no coefficient part, so this is ``(D F) P (D F)^T + Q``: the forgetting
        rides on the transition. The regressors, ``f`` and its Jacobian are plain floats
        (:meth:`RegressionModel.linearize`); numpy does only the covariance product.
        """
        nd, nt = self.nd, self.n_theta
        n = 2 * nd + nt
        o = 2 * nd
        nu = self.x[:nd].tolist()
        phis, f, J = self.model.linearize(nu, self.inp, [t.tolist() for t in self.thetas[:nd]])
        # F = I + dt [[J, 0, Phi], 0, 0]: only the first nd rows differ from I
        rows = []
        col = o
        for i, k in enumerate(self._sizes):
            row = [0.0] * n
            if self._masked[i]:  # generic prior: no cross-coupling (see __init__)
                row[i] = dt * J[i][i]
            else:
                row[:nd] = [dt * a for a in J[i]]
            row[i] += 1.0
            if nt and (self._identifying or self._prior_dof[i]):
                # coefficient uncertainty flows into nu_r while identifying, and always for
                # a DOF whose model is only the generic prior (mode (b)): an assumed sway
                # damping must not pin the sideslip in a turn (measured without this:
                # 0.28 m/s error at 4 sigma after the first circle, effect-current)
                row[col:col + k] = [dt * a for a in phis[i]]
            col += k
            rows.append(row)
        F = self._eye_n.copy()
        F[:nd] = rows
        cfg = self.cfg
        if nt and self._identifying:
            # variable-rate forgetting on the coefficient block, bounded by its prior
            # trace (F leaves that block of P as it is): the block by 1/lam, its
            # cross-covariances by 1/sqrt(lam)
            tr = sum(self.P.diagonal()[o:].tolist())
            lam = 1.0 - (1.0 - cfg.forgetting) * max(0.0, 1.0 - tr / self._tr_theta_max)
            lam = lam ** (dt / 0.1)
            if lam < 1.0:
                F.ravel()[o * (n + 1)::n + 1] = 1.0 / math.sqrt(lam)
        nu = [a + dt * b for a, b in zip(nu, f)]
        self.x[:nd] = nu
        # model error grows in manoeuvres (couplings the regression gets only roughly):
        # a turn-rate term, so that the sigma widens at heading changes (the paper's burrs)
        turn = cfg.turn_accel_gain * abs(self.inp.r * nu[0])
        q_nu = (cfg.accel_std ** 2 + turn * turn) * cfg.model_error_time_s * self.q_scale
        q = [q_nu * dt] * nd
        for i in range(nd):
            if self._masked[i]:  # still the generic prior
                q[i] = max(q[i], cfg.prior_accel_std ** 2 * cfg.model_error_time_s * dt)
        q += [cfg.current_walk ** 2 * dt * self.q_scale] * nd
        P = F @ self.P @ F.T
        P.ravel()[:o * (n + 1):n + 1] += q  # a view: the product is C-contiguous
        self.P = P

    def _update(self, kind: str, t: float, z: np.ndarray, std: float, R: np.ndarray) -> None:
        """Kalman update with one velocity measurement (table in the module docstring),
        NIS gate, Joseph-form covariance for the gain actually used, calibration."""
        nd = self.nd
        m = len(z)
        H = self._H0[(kind, m)].copy()
        if kind == "earth":
            H[:, :nd] = R[:m]
        elif kind == "bottom":
            H[:, nd:2 * nd] = R.T[:m]
        var = std * std
        y = z - H @ self.x
        PHt = self.P @ H.T
        S = H @ PHt
        S.ravel()[::m + 1] += var
        Sinv = _inv_small(S)
        if Sinv is None:
            self._reset("diverged")
            return
        nis = float(y @ Sinv @ y)
        if nis > self.cfg.gate_nis and self._started and self.counters["updates"] > 50:
            self.counters["rejected_gate"] += 1
            return
        K = PHt @ Sinv
        if self.n_theta and not self._identifying:
            K[2 * nd:] = 0.0
        x_new = self.x + K @ y
        IKH = self._eye_n - K @ H
        P_new = IKH @ self.P @ IKH.T + (K * var) @ K.T
        # a NaN or inf anywhere makes the sums non-finite (a sum overflowing from finite
        # entries would need |P| ~ 1e308: a divergence too)
        if not (math.isfinite(float(x_new.sum()) + float(P_new.sum()))
                and max(map(abs, x_new[:2 * nd].tolist())) < 50.0):
            self._reset("diverged")
            return
        self.x, self.P = x_new, P_new
        self._unpack_thetas()
        self.y, self.S, self.nis = y, S, nis
        self.counters["updates"] += 1
        if self.cfg.calibrate and self._started:
            # innovation-based calibration on block means: a consistent filter has white
            # innovations, so the mean of N of them has covariance ~ mean(S)/N. Model and
            # current errors are slow and survive the averaging while white sensor noise
            # does not; the per-sample NIS is blind to them (measured: NIS 0.95 while the
            # current's 2-sigma coverage was 0.5, Gavia). Process noise is only inflated.
            if m == nd:
                self._blk_y += y
                self._blk_S += S
                self._blk_n += 1
                if self._blk_n >= self.cfg.calibrate_block:
                    nb = self._blk_n
                    yb = self._blk_y / nb
                    Sb = self._blk_S / (nb * nb)
                    nis_b = float(yb @ np.linalg.solve(Sb, yb)) / m
                    self._nis_avg += 0.1 * (min(nis_b, 10.0) - self._nis_avg)
                    self.q_scale = float(np.clip(
                        self.q_scale * math.exp(0.1 * (self._nis_avg - 1.0)), 1.0, 100.0))
                    self._blk_y[:] = 0.0
                    self._blk_S[:] = 0.0
                    self._blk_n = 0

    # ------------------------------------------------------------------ HGO
    def _hgo_predict(self, dt: float) -> None:
        """The HGO's own copy of ``[nu_r, V_c]`` runs the same model (Kim eq. 11, model part)."""
        nd = self.nd
        nu = self.hx[:nd]
        _, f, J = self.model.linearize(nu.tolist(), self.inp,
                                       [t.tolist() for t in self.thetas[:nd]])
        self._hJ = J = np.array(J)
        self.hx[:nd] = nu + dt * np.array(f)
        F = np.eye(2 * nd)
        F[:nd, :nd] += dt * J
        q = np.concatenate([np.full(nd, self.cfg.accel_std ** 2 * self.cfg.model_error_time_s
                                    * self.q_scale), np.full(nd, self.cfg.current_walk ** 2)])
        self.hP = F @ self.hP @ F.T + np.diag(q * dt)

    def _hgo_update(self, kind: str, z: np.ndarray, std: float, dt_meas: float) -> None:
        """Output injection ``G(gamma) (y - C x_hat)`` (Kim eq. 11) for one velocity sample,
        with the increasing-gain law; the covariance of this gain in Joseph form."""
        nd = self.nd
        if self._law is None or kind == "water" or len(z) != nd:
            return
        R = self._R()
        H = np.hstack([R, np.eye(nd)]) if kind == "earth" else np.hstack([np.eye(nd), R.T])
        y = z - H @ self.hx
        e_earth = y if kind == "earth" else R @ y
        gamma = self._law.update(dt_meas, float(e_earth @ e_earth) / (std * std) / nd)
        self.gamma = gamma
        G = current_hgo_gain(float(self._k[0]), float(self._k[1]), gamma, self._hJ, R,
                             np.array([self.inp.p, self.inp.q, self.inp.r]))
        K = G * dt_meas
        if kind == "bottom":
            K = K @ R
        x_new = self.hx + K @ y
        IKH = np.eye(2 * nd) - K @ H
        P_new = IKH @ self.hP @ IKH.T + (K * std * std) @ K.T
        if not (np.all(np.isfinite(x_new)) and float(np.max(np.abs(x_new))) < 50.0):
            self.counters["hgo_diverged"] = self.counters.get("hgo_diverged", 0) + 1
            self.hx = self.x[:2 * nd].copy()
            self.hP = self.P[:2 * nd, :2 * nd].copy()
            self._law.gamma = self._gamma_init
            return
        self.hx, self.hP = x_new, P_new

    def _reset(self, reason: str) -> None:
        """Back to the prior (keeps the identified coefficients if they are finite)."""
        self.counters[reason] = self.counters.get(reason, 0) + 1
        nd, o = self.nd, 2 * self.nd
        self.x[:o] = 0.0
        keep = np.all(np.isfinite(self.x[o:])) and np.all(np.isfinite(self.P[o:, o:]))
        P = np.diag([1.0] * nd + [self.cfg.init_current_std ** 2] * nd + [0.0] * self.n_theta)
        if self.n_theta:
            if keep:
                P[o:, o:] = self.P[o:, o:]
            else:
                self.x[o:] = np.concatenate(self.model.default_thetas()[:nd])
                P[o:, o:] = np.diag(self._theta_var_generic)
        self.P = P
        self._unpack_thetas()
        if self._law is not None:
            self._law.gamma = self._gamma_init
        self._started = False

    def _start(self, kind: str, z: np.ndarray) -> None:
        """Initialize nu_r from the first velocity, assuming no current (P says so)."""
        nd = self.nd
        R = self._R()
        zz = np.zeros(nd)
        zz[: len(z)] = z
        nu = R.T @ zz if kind == "earth" else zz
        self.x[:nd] = nu
        self._hvec = (math.cos(2.0 * (self.yaw or 0.0)), math.sin(2.0 * (self.yaw or 0.0)))
        if self._law is not None:
            self.hx = self.x[:2 * nd].copy()
            self.hP = self.P[:2 * nd, :2 * nd].copy()
        self._started = True

    # ------------------------------------------------------------------ identification
    def _update_prior_mask(self) -> None:
        """Lift the cross-coupling mask of DOFs whose coefficients have been learned.

        Their covariance block changes only while identifying (forgetting, gain) or on a
        restored state, so the step calls this only after an identifying tick."""
        if not self.n_theta or not any(self._masked):
            return
        o = 2 * self.nd
        var = self.P.diagonal()[o:].tolist()
        o = 0
        for i, k in enumerate(self._sizes):
            if self._masked[i] and sum(var[o:o + k]) < 0.25 * self._tr_theta0[i]:
                self._masked[i] = False
            o += k

    def _is_identifying(self, t: float) -> bool:
        """Whether the coefficients are estimated at this tick.

        Only once the current is known (``identify_max_current_std``): before that the
        innovation says "model or current wrong" and the coefficients would take the blame
        (measured: u_r 1.47 -> 0.17 m/s in the first second, Gavia). And only around turns
        (``identify_after_turn_s``): on a straight line a current along the track and a
        thrust coefficient are the same thing to the data, and the linearized joint filter
        drifts along that direction while its covariance shrinks (measured: -0.75 vs
        -0.93 m/s with sigma 0.033, Gavia straight run). While not identifying, the
        coefficients are held as known (their uncertainty is not propagated into ``nu_r``,
        which otherwise makes the model worthless and the current drift: +0.2 vs -0.93 m/s).
        """
        if not self.n_theta or not self._started:
            return False
        nd = self.nd
        c_sd = math.sqrt(max(self.P[nd, nd], self.P[nd + 1, nd + 1]))
        return (c_sd <= self.cfg.identify_max_current_std
                and (self.cfg.identify_straight
                     or t - self._last_turn_t <= self.cfg.identify_after_turn_s))

    def _identify_yaw(self, dt: float) -> None:
        """RLS on the auxiliary yaw channel: r' = phi_yaw(nu_r, r, u)^T theta_yaw, with both
        sides through the same state-variable filter (algorithms.md §3.4)."""
        if self.yaw_rls is None or self._svf is None:
            return
        i = self._i_yaw
        phi = self.model.regressor_rows(self.x[: self.nd].tolist(), self.inp)[i]
        self._svf.update(dt, (self.inp.r,) + phi)
        if (not self.cfg.identify or "yaw" in self.cfg.model
                or self.x[0] < self.cfg.identify_min_speed):
            return  # a configured yaw model is kept (the flow observer's gain rests on it)
        if self._last_vg is None or (self._t or 0.0) - self._last_vg[0] > 1.0:
            return
        self.yaw_rls.update(self._svf.y[1:], self._svf.dy[0])
        self.thetas[i] = self.yaw_rls.theta
        self.counters["rls_updates"] += 1

    # ------------------------------------------------------------------ protocol
    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        """Advance to tick ``t`` (s) with the new samples; returns the estimates."""
        meas: list = []
        handlers = self._handlers
        self._step_t = t
        if self._att_later:  # attitude stamped after an earlier tick, now due
            due = sorted(a for a in self._att_later if a[0] <= t)
            if due:
                self._att_later = [a for a in self._att_later if a[0] > t]
                for a in due:
                    self._set_attitude(*a)
        for s in samples:
            h = handlers.get(type(s))
            if h is not None:
                h(s, meas)
        if self.yaw is None:
            return {}
        if not self._started:
            if not meas:
                return {}
            self._start(meas[-1][0], meas[-1][2])
            self._t = t
        dt = t - (self._t if self._t is not None else t)
        if abs(self.inp.r) > self.cfg.identify_min_rate:
            self._last_turn_t = t
        if dt > 0 and self.yaw is not None:
            a = min(1.0, dt / self.cfg.heading_memory_s)
            self._hvec = ((1 - a) * self._hvec[0] + a * math.cos(2.0 * self.yaw),
                          (1 - a) * self._hvec[1] + a * math.sin(2.0 * self.yaw))
        if self._identifying:  # the coefficient covariance moves only while identifying
            self._update_prior_mask()
        self._identifying = self._is_identifying(t)
        if dt > 0:
            n_sub = max(1, math.ceil(dt / 0.2))
            for _ in range(n_sub):
                self._predict(dt / n_sub)
                if self._law is not None:
                    self._hgo_predict(dt / n_sub)
        self._t = t if dt >= 0 else self._t
        R = self._R() if meas else None  # the attitude is fixed within the tick
        for kind, tm, z, std in meas:
            dt_meas = tm - self._last_meas_t if self._last_meas_t is not None else 0.1
            dt_meas = min(max(dt_meas, 1e-3), 1.0)
            self._last_meas_t = tm
            self._update(kind, tm, z, std, R)
            self._hgo_update(kind, z, std, dt_meas)
            if self.flow is None:  # the body-frame velocity is for the flow observer only
                self._last_vg = (tm, z, kind)
            elif kind == "earth":
                zz = np.zeros(self.nd)
                zz[: len(z)] = z
                if len(z) < self.nd:  # no vertical: take the filter's own
                    zz[2:] = (R @ self.x[: self.nd] + self.x[self.nd:2 * self.nd])[2:]
                self._last_vg = (tm, R.T @ zz, kind)
            else:
                self._last_vg = (tm, z.copy(), kind)
            self._last_vg_std = std
        if dt > 0:
            self._identify_yaw(dt)
        if self.flow is not None and self._last_vg is not None:
            self.flow.step(dt if dt > 0 else 0.0, self.yaw, self.inp, self.thetas,
                           self.x[: self.nd])
        return self._outputs()

    def _outputs(self) -> dict[str, float]:
        nd = self.nd
        if self._law is None:
            c = self.x[nd:2 * nd].tolist()
            nu = self.x[:nd].tolist()
            std = np.sqrt(self.P.diagonal()[nd:2 * nd]).tolist()
        else:
            c, nu = self.hx[nd:].tolist(), self.hx[:nd].tolist()
            std = np.sqrt(np.maximum(self.hP.diagonal()[nd:], 0.0)).tolist()
        if self._masked[0] and math.hypot(*self._hvec) > self.cfg.heading_diversity:
            # No surge model yet (mode (b), not identified): the current along the track is
            # not observable on a straight line; weak couplings (pitch, heave prior) make
            # the filter's own variance shrink anyway (measured: 1.2 m/s error at 3.3
            # sigma after 270 s, Gavia straight run). Report at least the prior along track,
            # unless the headings of the last minutes are diverse enough for the sway
            # constraint alone (|mean heading vector| below ``heading_diversity``).
            yaw = self.yaw or 0.0
            for i, a in enumerate((math.cos(yaw), math.sin(yaw))):
                a *= self.cfg.init_current_std
                std[i] = math.sqrt(std[i] * std[i] + a * a)
        if self.flow is not None and self.flow.ready and self._last_vg is not None:
            # Fan et al.: V_c = R (v - v_r); v from the last over-ground velocity.
            R = self._R()
            nu = self.flow.nu_r(nd)
            _, nu_g, kind = self._last_vg
            if kind != "water":
                c = R @ (nu_g - nu)
            std = np.sqrt(np.maximum(np.diag(R @ self.flow.nu_cov(nd) @ R.T), 0.0)
                          + self._last_vg_std ** 2)
        out = {"north": float(c[0]), "east": float(c[1]),
               "std_north": float(std[0]), "std_east": float(std[1]),
               "u_r": float(nu[0]), "v_r": float(nu[1])}
        if nd == 3:
            out.update(down=float(c[2]), std_down=float(std[2]), w_r=float(nu[2]))
        return out

    def health(self) -> Mapping[str, float]:
        """Velocity innovation, its variance and NIS; RLS residuals; counters."""
        h: dict[str, float] = dict(self.counters)
        for i, ax in enumerate(("n", "e", "d")[: len(self.y)]):
            h[f"velocity.innovation_{ax}"] = float(self.y[i])
            h[f"velocity.S_{ax}"] = float(self.S[i, i])
        h["velocity.nis"] = self.nis
        h["velocity.nis_avg"] = self._nis_avg
        h["q_scale"] = self.q_scale
        if self.n_theta:
            o = 2 * self.nd
            h["theta.std_max"] = float(np.sqrt(np.max(np.diag(self.P)[o:])))
        if self.yaw_rls is not None:
            h["rls.yaw.residual"] = self.yaw_rls.e
            h["rls.yaw.sigma"] = math.sqrt(self.yaw_rls.sigma2)
            h["rls.yaw.nis"] = self.yaw_rls.nis
        if self._law is not None:
            h["gamma"] = self.gamma
        return h

    def get_state(self) -> dict[str, Any]:
        """Identified model (coefficients and their covariance) and the last current."""
        nd, o = self.nd, 2 * self.nd
        st: dict[str, Any] = {"model_kind": self.model.kind,
                              "thetas": self.model.thetas_to_mapping(self.thetas),
                              "current": self.x[nd:o].tolist(),
                              "current_std": np.sqrt(np.diag(self.P)[nd:o]).tolist()}
        if self.n_theta:
            st["theta_cov"] = self.P[o:, o:].tolist()
        if self.yaw_rls is not None:
            st["yaw_rls"] = self.yaw_rls.get_state()
        return st

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore the identified model; the current restarts from its saved value with
        its saved uncertainty inflated (it may have changed while the service was down)."""
        if state.get("model_kind") != self.model.kind:
            return
        nd, o = self.nd, 2 * self.nd
        try:
            thetas = self.model.thetas_from_mapping(state.get("thetas", {}), self.thetas)
            if not all(np.all(np.isfinite(t)) for t in thetas):
                return
            self.thetas = thetas
            if self.n_theta:
                self.x[o:] = np.concatenate(thetas[:nd])
                cov = np.asarray(state.get("theta_cov", []), float)
                if cov.shape == (self.n_theta, self.n_theta) and np.all(np.isfinite(cov)):
                    self.P[o:, :] = 0.0
                    self.P[:, o:] = 0.0
                    self.P[o:, o:] = cov
                    self._update_prior_mask()
            if self.yaw_rls is not None and "yaw_rls" in state:
                self.yaw_rls.set_state(state["yaw_rls"])
                self.thetas[self.model.channels.index("yaw")] = self.yaw_rls.theta.copy()
            c = np.asarray(state["current"], float)
            if c.shape == (nd,) and np.all(np.isfinite(c)):
                self.x[nd:o] = c
                sd = np.asarray(state.get("current_std", [0.3] * nd), float)
                self.P[nd:o, :] = 0.0
                self.P[:, nd:o] = 0.0
                self.P[nd:o, nd:o] = np.diag(np.maximum(sd, 0.2) ** 2)
        except (KeyError, TypeError, ValueError):
            return


def _gain_for(cfg: Config, ccfg: CurrentConfig) -> GainDesign | None:
    if ccfg.observer != "hgo":
        return None
    default = GAIN_DIR / f"{cfg.vehicle.vehicle_class}.json"
    path = Path(ccfg.gain_file) if ccfg.gain_file else default
    if path.exists():
        try:
            return GainDesign.load(path)
        except (OSError, ValueError, KeyError) as err:
            raise ConfigError(f"pipelines.current.gain_file: {path}: {err}") from None
    if ccfg.gain_file:
        raise ConfigError(f"pipelines.current.gain_file: {path}: no such file "
                          "(run `onboard design-gain --config ...`)")
    return None


def create(cfg: Config) -> CurrentPipeline | None:
    """The ``current`` pipeline for this configuration (every vehicle class)."""
    ccfg = decode_section(cfg, "current", CurrentConfig)
    if not ccfg.enabled:
        return None
    has_twin = cfg.inputs.left is not None and cfg.inputs.right is not None
    kind = ccfg.model_kind or kind_for_class(cfg.vehicle.vehicle_class, has_twin)
    try:
        RegressionModel(kind).thetas_from_mapping(ccfg.model)
    except ValueError as err:
        raise ConfigError(f"pipelines.current.{err}") from None
    return CurrentPipeline(ccfg, kind, cfg.sensors, configured=bool(ccfg.model),
                           gain=_gain_for(cfg, ccfg))
