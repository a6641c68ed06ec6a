"""The pipelines' configuration: the typed tables of ``[pipelines.<name>]``.

Every pipeline table is decoded with the rest of the configuration
(:class:`onboard.core.config.Config`), so an unknown pipeline name (``[pipelines.aei]``)
or an unknown key inside a pipeline table is an error naming the file and the dotted key.
The structs live here, in the core, because the configuration is loaded before any
pipeline is imported; each pipeline module reads ``cfg.pipelines.<name>``.

* ``[pipelines.nav]``: :class:`NavConfig`;
* ``[pipelines.aie]``, ``[pipelines.aie.surge]``, ``[pipelines.aie.heading]``:
  :class:`AieConfig` (algorithms.md §1-§2);
* ``[pipelines.kf]``, ``[pipelines.kf.surge]``, ``[pipelines.kf.heading]``:
  :class:`KfConfig`, the same measurement handling with the KF baseline's model and noise
  (algorithms.md §2.12);
* ``[pipelines.current]``: :class:`CurrentConfig` (algorithms.md §3-§4), with
  ``[pipelines.current.hgo]`` (:class:`HgoConfig`, §3.1), ``[pipelines.current.flow]``
  (:class:`FlowObserverConfig`, §4.4) and ``[pipelines.current.glider]``
  (:class:`GliderModelConfig`);
* ``[pipelines.eseso]``: :class:`EsesoConfig` (algorithms.md §5), with
  ``[pipelines.eseso.vehicle]``, ``.thrusters``, ``.process``, ``.noise`` and ``.initial``
  (:class:`EsesoVehicleConfig`, :class:`EsesoThrustersConfig`,
  :class:`EsesoProcessConfig`, :class:`EsesoNoiseConfig`, :class:`EsesoInitialConfig`).

Key names follow one rule, the same as the rest of the configuration's (``[sensors]``,
``[engine]``, ``[service]``; README, "Configuration"):

1. A key that holds a dimensional quantity ends in its unit: ``_s``, ``_m``, ``_mps``
   (m/s), ``_mps2`` (m/s^2), ``_rad``, ``_rps`` (rad/s), ``_deg``, ``_n`` (N), ``_kg``,
   ``_hz``, ``_us``, ``_mb``, ``_kgm3`` (kg/m^3), ``_pa``, ``_cc`` (cm^3). A random walk's
   unit is its quantity's unit per square root of a second, written ``<unit>_rts`` ("per
   root second"): ``current_walk_mps_rts`` is m/s/sqrt(s), ``disturbance_walk_n_rts``
   N/sqrt(s). A dimensionless key (a ratio, gain, probability, count, NIS, a relative
   one-sigma such as ``model_rel_std``) has no suffix.
2. A one-sigma is ``<quantity>_std_<unit>`` (``heading_std_rad``); a prior one-sigma
   likewise, ``initial_`` in front where it is the initial state's
   (``initial_current_std_mps``; in ``[pipelines.eseso.initial]`` the table says it).
3. A gate is ``gate_<measure>``: ``gate_nis`` for a NIS threshold, ``gate_sigma`` for
   one in sigmas. A threshold that never rejects is not a gate and keeps its measure
   last (``divergence_nis``: a divergence test; ``thrust_huber``: a down-weighting).
4. A part of a pipeline with its own section in algorithms.md is a nested table
   (``[pipelines.current.hgo]``, ``[pipelines.current.flow]``,
   ``[pipelines.current.glider]``), and so are the ESESO's vehicle, thrusters, process
   noise, measurement noise and initial state; a key in a nested table drops the prefix
   the table now says (``hgo_identify`` is ``[pipelines.current.hgo] identify``).

Where rule 1 is wrong: a key that is the symbol of algorithms.md keeps the symbol, its
unit in its docstring: the axis tables' ``a``, ``gain``, ``offset``, ``u_max``, ``v_d``,
``r_d``, ``q_v``, ``bias_q`` (their unit is the axis's, m/s^2 in ``surge``, rad/s^2 in
``heading``: one field of one struct cannot end in both), the HGO's ``gamma`` and ``rho``,
the flow observer's ``poles``, the glider's ``lift_kl`` ... ``drag_kd``; so do the model
coefficients' priors ``theta_std`` and ``theta_std_floor`` (each coefficient has its own
unit), a compound unit without a short suffix (``damping_linear``, N s/m) and
``rpm_scale`` (its unit, rpm, is its first word).

A renamed key is an error that names its new one
(:data:`onboard.core.config_renames.RENAMED`).
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal, Mapping, NamedTuple

import msgspec


class NavConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """``[pipelines.nav]``: the measured navigation track (no settings of its own)."""

    enabled: bool = True
    """False: the pipeline is not built."""


# ---------------------------------------------------------------------------------------
# [pipelines.aie] and [pipelines.kf]: the surge/heading pipelines

AUTO = "auto"
"""The default of a tuned noise parameter (``v_d``, ``r_d``): the value the common tuning
protocol found for the measurement set present, with or without a Doppler speed
(:class:`TunedPair`; the pipeline switches as fixes with or without a speed over ground
come in: onboard/pipelines/surge_heading.py, docs/aie.md section 2.2). A number in the
configuration is used with either set."""

Tuned = float | Literal["auto"]
"""A tuned noise parameter: a number, or ``"auto"`` (:data:`AUTO`)."""


class TunedPair(NamedTuple):
    """One parameter as tuned with the GNSS Doppler speed row and without it."""

    doppler: float
    """Tuned where fixes carry a speed over ground."""
    no_doppler: float
    """Tuned on the position increments alone (``gnss_velocity = false``)."""

    def pick(self, doppler: bool) -> float:
        """The value for the measurement set: with (``doppler``) or without a speed."""
        return self.doppler if doppler else self.no_doppler


# The tuned sets of the common tuning protocol (`python -m validation tune`, validation/tuning.py),
# read from docs/tuning.json, variants `aie` / `aie-no-doppler` and `kf` / `kf-no-doppler`
# (docs/aie.md section 2.1), rounded to two significant digits; tests/test_tuning.py
# checks them against the file. `bias_q` has no pair: without a Doppler speed the bias
# state does not walk (input_models.CommandedInput), so `kf-no-doppler` leaves it alone.
AIE_SURGE_V_D = TunedPair(0.04, 0.82)
"""AIE surge ``v_d`` ((m/s^2)^2): variants ``aie`` / ``aie-no-doppler``."""
AIE_SURGE_R_D = TunedPair(5.2, 0.084)
"""AIE surge ``r_d``: variants ``aie`` / ``aie-no-doppler``."""
AIE_HEADING_V_D = TunedPair(1.7, 2.5)
"""AIE heading ``v_d`` ((rad/s^2)^2): variants ``aie`` / ``aie-no-doppler``."""
AIE_HEADING_R_D = TunedPair(0.29, 2.0)
"""AIE heading ``r_d``: variants ``aie`` / ``aie-no-doppler``."""
KF_SURGE_V_D = TunedPair(0.0067, 2.7)
"""KF surge ``v_d`` ((m/s^2)^2): variants ``kf`` / ``kf-no-doppler``."""
KF_HEADING_V_D = TunedPair(2.6, 2.5)
"""KF heading ``v_d`` ((rad/s^2)^2): variants ``kf`` / ``kf-no-doppler``."""


class TunedKeys:
    """Mixin of an axis table whose ``"auto"`` keys resolve through ``TUNED``."""

    TUNED: ClassVar[Mapping[str, TunedPair]] = {}
    """The tuned pair of each key whose default is ``"auto"``."""

    def tuned(self, key: str, doppler: bool) -> float:
        """Key ``key``'s value for the measurement set (with or without a Doppler
        speed): the configured number, or for ``"auto"`` the tuned pair's."""
        value = getattr(self, key)
        if value == AUTO:
            return self.TUNED[key].pick(doppler)
        return float(value)


class AxisConfig(TunedKeys, msgspec.Struct, forbid_unknown_fields=True, kw_only=True,
                 frozen=True):
    """One AIE axis: its model (§1.2), the RCIE hyperparameters (§2.10), the AIE noise.

    Units: ``u`` is m/s^2 (surge) or rad/s^2 (heading); commands are normalized. The
    axes' ``v_d`` and ``r_d`` default to ``"auto"``: the values of the common tuning
    protocol (``python -m validation tune aie`` and ``aie-no-doppler``, validation/tuning.py:
    Nelder-Mead on SITL ``jaiabot-turns``, ``twin-thruster-turns`` and ``effect-waves``
    seed 10, held out from the reported seeds; docs/aie.md section 2.1), rounded to two
    digits, for the measurement set present (:data:`AUTO`).
    """

    a: float = 1.0
    """Damping rate a (1/s), identified (§1.2) or the §1.4 default."""
    gain: float = 1.0
    """Nominal input per unit command (the KF baseline's input scaling)."""
    offset: float = 0.0
    """Nominal input at zero command."""
    u_max: float = 5.0
    """Saturation of the input estimate |d_hat| (physical bound)."""
    u_scale: float = 1.0
    """Typical input magnitude: the normalization of d_hat for RLS (§2.10)."""
    n_c: int = 3
    """Input-estimator order (§2.3); l_theta = 2 n_c + 1 coefficients (7, the paper's
    heading count; algorithms.md §2.10 compares the orders)."""
    n_f: int = 1
    """Taps of G_f (§2.4); 1 suffices for the relative-degree-1 increment model."""
    r_z: float = 1.0
    """Retrospective weight R_z (§2.5)."""
    r_d: Tuned = 1.0
    """Input penalty R_d (normalized, §2.5), on the size or the change of d_hat;
    ``"auto"``: tuned, with or without a Doppler speed (:data:`AUTO`)."""
    rate_penalty: bool = True
    """Apply R_d to the change of the input estimate (d_hat_k - d_hat_{k-1}) instead of
    its size: penalizes noise amplification without biasing a nonzero mean input."""
    r_theta: float = 0.01
    """Regularization R_theta; P_0 = I / r_theta (normalized, §2.5)."""
    lam: float = 0.999
    """RLS forgetting factor lambda (§2.6); memory ~ 1/(1 - lambda) steps."""
    v_d: Tuned = 0.3
    """AIE: variance of the input-estimation error V_d (u^2), §2.2; ``"auto"``: tuned,
    with or without a Doppler speed (:data:`AUTO`)."""
    q_v: float = 0.0
    """Extra random walk of the rate per step (m^2/s^2 or rad^2/s^2)."""
    known_input: bool = True
    """AIE: forecast with the nominal commanded input plus the RCIE estimate, so RCIE
    estimates what the nominal map misses (§2.1 "known input"). Without commands, and
    with ``false``, the whole input is unknown, as in the paper."""


class SurgeAxisConfig(AxisConfig, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """``[pipelines.aie.surge]`` (m/s^2)."""

    a: float = 1.0
    gain: float = 3.0
    u_max: float = 5.0
    u_scale: float = 1.0
    TUNED: ClassVar[Mapping[str, TunedPair]] = {"v_d": AIE_SURGE_V_D, "r_d": AIE_SURGE_R_D}
    r_d: Tuned = AUTO
    v_d: Tuned = AUTO


class HeadingAxisConfig(AxisConfig, forbid_unknown_fields=True, kw_only=True,
                        frozen=True):
    """``[pipelines.aie.heading]`` (rad/s^2)."""

    a: float = 2.0
    gain: float = 2.0
    u_max: float = 5.0
    u_scale: float = 2.0
    TUNED: ClassVar[Mapping[str, TunedPair]] = {"v_d": AIE_HEADING_V_D,
                                                 "r_d": AIE_HEADING_R_D}
    r_d: Tuned = AUTO
    v_d: Tuned = AUTO


class SurgeHeadingConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True,
                         frozen=True):
    """Measurement handling and reconstruction, the same keys in ``[pipelines.aie]`` and
    ``[pipelines.kf]`` (each pipeline reads its own table)."""

    enabled: bool = True
    """False: the pipeline is not built (:func:`onboard.pipelines.build`)."""
    step_s: float = 0.2
    """The AIE step Ts (s) of the surge axis: GNSS window length (§1.2). A window
    without a fix is no step, so a slower receiver gives longer steps."""
    heading_step_s: float = 0.1
    """The step of the heading axis (compass windows); <= 0: same as step_s."""
    close_at_output: bool = True
    """A surge window holding a fix (and a heading) closes when estimates are asked for
    (the engine's tick) instead of at its end: the newest fix is in the published
    estimate at once (0.1 s less mean latency at 5 Hz fixes and 10 Hz ticks)."""
    max_gap_s: float = 5.0
    """Longer without a measurement point restarts the increment chain."""
    input_mode: Literal["auto", "throttle-rudder", "differential"] = "auto"
    """How commands map to the two axes (see surge_heading.axis_commands)."""
    gnss_position_std_m: float | None = None
    """GNSS position noise, one sigma (m); default [sensors.gnss] position_std_m. The
    noise of fixes without their own accuracy (and of all with ``gnss_accuracy = false``)."""
    gnss_accuracy: bool = True
    """Take each fix's own accuracy (``h_acc_m``: GPS_RAW_INT h_acc, gpsd eph/epx/epy) as
    its position noise, clamped to [``gnss_accuracy_min_m``, ``gnss_accuracy_max_m``],
    and scale the position anchor by ``gnss_position_std_m^2`` over it; and its speed accuracy
    (``speed_acc_mps``: GPS_RAW_INT vel_acc, gpsd eps) as the Doppler speed's noise where
    it is worse than ``gnss_velocity_std_mps`` (down-weighting only, at most 5 m/s)."""
    gnss_accuracy_min_m: float = 0.05
    """Floor of a fix's reported accuracy (m): receivers report centimetres in RTK."""
    gnss_accuracy_max_m: float = 50.0
    """Ceiling of a fix's reported accuracy (m)."""
    gnss_velocity: bool = True
    """Also measure the surge rate with the receiver's speed over ground (Doppler),
    signed by the course against the heading, where the fixes carry it."""
    gnss_velocity_std_mps: float | None = None
    """Speed-over-ground noise, one sigma (m/s); default [sensors.gnss] velocity_std_mps."""
    heading_std_rad: float | None = None
    """Compass noise, one sigma (rad); default [sensors.compass] heading_std_rad."""
    correlated_noise: bool = True
    """Model the MA(1) noise of increments formed from noisy points (kalman.py)."""
    heading_anchor: float = 0.05
    """With ``correlated_noise = false`` only: gain pulling the reconstructed heading
    toward the measured one per step (0: the paper's pure integration of increments)."""
    position_anchor: float = 0.05
    """Gain pulling the reconstructed position toward the GNSS point per surge step
    (0: pure dead reckoning from the estimates, paper §3.3)."""
    gate_nis: float = 400.0
    """An innovation with z^2/S above this is rejected as an outlier (20 sigma)."""
    adaptive_rate_noise: bool = True
    """Raise the input-error variance (the axis's ``v_d``) to what the measured
    rate's innovations show (covariance matching on the Doppler speed row, never below
    the configured value), so a model that predicts the speed worse than it claims gives
    way to the measurement."""
    imu_aiding: bool = True
    """Where the log has an IMU and an attitude (roll, pitch), predict the speed and
    path from the last surge step to the output with the measured path acceleration
    (gravity removed, bias estimated: estimators/path_accel.py) as well as the model,
    blended by the weight that minimises their misses of the Doppler speed."""
    imu_horizon_s: float = 1.0
    """Longest prediction (s) made with the accelerometer; beyond it, the model."""


class AieConfig(SurgeHeadingConfig, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """``[pipelines.aie]``: measurement handling, reconstruction, both axes."""

    adaptive: bool = False
    """Adapt V_d to the innovation statistics (ASE, §2.8)."""
    adaptive_window: int = 50
    """Window N_w of the innovation sample variance (steps)."""
    divergence_input: float = 3.0
    """Input estimate beyond this multiple of u_max (before saturation) is divergence."""
    divergence_nis: float = 25.0
    """Mean NIS over ~20 steps above this is divergence (expected value ~1)."""
    surge: SurgeAxisConfig = SurgeAxisConfig()
    """``[pipelines.aie.surge]``."""
    heading: HeadingAxisConfig = HeadingAxisConfig()
    """``[pipelines.aie.heading]``."""


class KfAxisConfig(TunedKeys, msgspec.Struct, forbid_unknown_fields=True, kw_only=True,
                   frozen=True):
    """One axis of the KF baseline: its model (§1.2) and the noise of its commanded input
    (§2.12). Units: ``u`` is m/s^2 (surge) or rad/s^2 (heading); commands are normalized."""

    a: float = 1.0
    """Damping rate a (1/s), identified (§1.2) or the §1.4 default."""
    gain: float = 1.0
    """Nominal input per unit command: the forecast input is ``gain * command + offset``."""
    offset: float = 0.0
    """Nominal input at zero command."""
    u_max: float = 5.0
    """Physical bound of the input (u): the first rate's variance ``(u_max dt)^2`` and
    the ceiling ``(2 u_max)^2`` of the adapted input-error variance."""
    q_v: float = 0.0
    """Extra random walk of the rate per step (m^2/s^2 or rad^2/s^2)."""
    v_d: Tuned = 1.0
    """Variance of the commanded input's error (u^2); ``"auto"``: tuned, with or without a
    Doppler speed (:data:`AUTO`)."""
    bias_q: float = 0.0
    """Random walk of the input-bias state ((u^2)/s; 0: no bias state). The forecast
    input is the nominal one plus a bias the filter estimates with the rest of its state
    (kalman.BiasIncrementKF)."""


class KfSurgeConfig(KfAxisConfig, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """``[pipelines.kf.surge]`` (m/s^2). ``v_d`` and ``bias_q`` of both axes: the common
    tuning protocol (``python -m validation tune kf`` and ``kf-no-doppler``, the same search, budget
    and runs as the AIE's; docs/aie.md section 2.1), rounded to two digits; ``v_d`` for
    the measurement set present (:data:`AUTO`)."""

    a: float = 1.0
    gain: float = 3.0
    TUNED: ClassVar[Mapping[str, TunedPair]] = {"v_d": KF_SURGE_V_D}
    v_d: Tuned = AUTO
    bias_q: float = 0.00086


class KfHeadingConfig(KfAxisConfig, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """``[pipelines.kf.heading]`` (rad/s^2)."""

    a: float = 2.0
    gain: float = 2.0
    TUNED: ClassVar[Mapping[str, TunedPair]] = {"v_d": KF_HEADING_V_D}
    v_d: Tuned = AUTO
    bias_q: float = 7.4e-5


class KfConfig(SurgeHeadingConfig, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """``[pipelines.kf]``: the KF baseline's measurement handling (the keys of
    ``[pipelines.aie]`` without the AIE's own), reconstruction, both axes."""

    surge: KfSurgeConfig = KfSurgeConfig()
    """``[pipelines.kf.surge]``."""
    heading: KfHeadingConfig = KfHeadingConfig()
    """``[pipelines.kf.heading]``."""


# ---------------------------------------------------------------------------------------
# [pipelines.current]


class GliderModelConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """``[pipelines.current.glider]``: the steady-glide model of a buoyancy-driven glider
    (:class:`onboard.estimators.vehicle_models.GliderModel`, docs/current.md, "Glider
    model"). When present, the current pipeline takes the glider's through-water velocity
    from its pitch, depth rate and pump volume (``[inputs] pump``) as a water-track
    measurement at each new depth sample. Defaults: the Slocum's published coefficients
    (Merckelbach et al. 2019 at 1027 kg/m^3, calibrated against a profiling DVL:
    ``vehicle_models.SLOCUM_LIFT_KL``, ``SLOCUM_DRAG_KD0``, ``SLOCUM_DRAG_KD``, the same
    numbers)."""

    lift_kl: float = 386.9
    """Lift per angle of attack ``K_L`` (kg/(m rad)): ``L = (K_L0 + K_L alpha) U^2``."""
    lift_kl0: float = 0.0
    """Lift at zero angle of attack ``K_L0`` (kg/m)."""
    drag_kd0: float = 7.70
    """Parasite drag ``K_D0`` (kg/m): ``D = (K_D0 + K_D alpha^2) U^2``."""
    drag_kd: float = 538.8
    """Induced drag ``K_D`` (kg/(m rad^2))."""
    water_density_kgm3: Annotated[float, msgspec.Meta(gt=0.0)] = 1027.0
    """Sea-water density (kg/m^3)."""
    neutral_pump_cc: float = 0.0
    """Pump volume (cm^3) at which the glider is neutrally buoyant."""
    vertical_water_std_mps: Annotated[float, msgspec.Meta(ge=0.0)] = 0.02
    """One-sigma (m/s) of the vertical water velocity (internal waves, convection) that
    the depth rate cannot tell from the glider's own sinking or rising."""
    glide_angle_std_rad: Annotated[float, msgspec.Meta(ge=0.0)] = 0.035
    """One-sigma (rad) of the flight-path angle: the pitch sensor's error and the angle
    of attack's (0.035 rad = 2 deg), for the current pipeline's through-water velocity.
    A dive's current (pipeline ``dac``) takes them apart: ``[pipelines.dac]
    lift_rel_std`` and ``pitch_bias_std_rad``."""
    min_glide_angle_rad: Annotated[float, msgspec.Meta(gt=0.0)] = 0.21
    """Below this pitch (rad; 0.21 = 12 deg) the depth rate says nothing usable about the
    horizontal speed (``u_h = dz/dt / tan(gamma)``): no measurement."""
    max_depth_interval_s: Annotated[float, msgspec.Meta(gt=0.0)] = 30.0
    """Depth samples further apart than this (s) give no depth rate."""
    hold_s: Annotated[float, msgspec.Meta(ge=0.0)] = 300.0
    """The along-track current counts as observed for this long (s) after the model's
    last measurement (through an inflection); afterwards it is floored at the prior like
    any current without a surge model (``heading_memory_s``)."""


class HgoConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """``[pipelines.current.hgo]``: the high-gain observer (algorithms.md §3.1,
    :mod:`onboard.estimators.current_hgo`): its gain law and its own model identification.
    The gain law's keys default to the gain file's (``onboard design-gain``)."""

    gain_file: str = ""
    """HGO gain JSON (``onboard design-gain``); default ``config/gains/<class>.json``."""
    gamma: float | None = None
    """A fixed high gain (``rho = 0``); default: the gain file's law."""
    gamma_0: float | None = None
    """Initial gain of the increasing-gain law; default the gain file's."""
    rho: float | None = None
    """Growth rate (1/s) of the increasing-gain law; default the gain file's."""
    gamma_max: float | None = None
    """Ceiling of the increasing gain; default the gain file's."""
    identify: Literal["turns", "always"] = "turns"
    """When the high-gain observer's own RLS (``observer = "hgo"``,
    :class:`~onboard.estimators.model_identification.VelocityRls`) learns: ``"turns"``
    under the joint filter's schedule (the observer's current one-sigma at most
    ``[pipelines.current] identify_max_current_std_mps``, within ``identify_after_turn_s``
    of a turn, or always with ``identify_straight``), ``"always"`` at every tick with a
    fresh velocity, as in Kim et al. (on a straight line the along-track current then
    trades against the thrust coefficient, docs/current.md, HGO). ``[pipelines.current]
    identify = false`` disables it."""
    rls_noise_std_mps2: Annotated[float, msgspec.Meta(gt=0.0)] = 0.2
    """One-sigma (m/s^2) of the equation error of the high-gain observer's RLS, against
    which the coefficient prior is weighed: the observer's velocity at ``gamma*`` carries
    the sensor noise through the injection, so a small value lets that noise drag the
    coefficients (docs/current.md, "The HGO's own model", compares 0.02, 0.05 and 0.2)."""


class FlowObserverConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True,
                         frozen=True):
    """``[pipelines.current.flow]``: the flow observer of Fan et al. (algorithms.md §4.4,
    :mod:`onboard.estimators.flow_observer`), used with ``observer = "flow"``."""

    pitch: bool = False
    """3-D models: add the vertical block ``[theta, q, w_r]`` observed from the measured
    pitch, its pitch channel identified online by RLS (flow_observer.py,
    ``PITCH_TERMS``); False: Fan et al.'s observer reduced to the heading output, ``w_r``
    from the joint filter (docs/current.md, "Flow observer")."""
    poles: list[float] = []
    """Flow-observer poles (1/s, negative); empty: the defaults of flow_observer.py."""


class CurrentConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """``[pipelines.current]``: hyperparameters of the current pipeline (SI units)."""

    enabled: bool = True
    """False: the pipeline is not built."""
    observer: Literal["kf", "hgo", "flow"] = "kf"
    """Whose current is reported: the joint Kalman filter, the high-gain observer or the
    flow observer."""
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
    """Absolute floor added to the relative prior one-sigma of configured coefficients."""
    forgetting: float = 0.9995
    """Forgetting of the coefficient covariance per tick (0.9995 at 10 Hz: 200 s memory),
    variable-rate: none once the covariance is back at its prior (bounded, rls.py)."""
    rpm_scale: float = 1000.0
    """Propeller rpm divided by this gives the normalized propulsion ``n``."""
    svf_cutoff_hz: Annotated[float, msgspec.Meta(gt=0.0)] = 0.3
    """State-variable filter cut-off for the yaw-channel RLS (algorithms.md §3.4)."""
    current_walk_mps_rts: float = 0.01
    """Random walk of the current, m/s per sqrt(s), before calibration (0.01: 0.08 m/s in a
    minute, 1 sigma; turbulence and tides; the innovation calibration raises it)."""
    accel_std_mps2: float = 0.02
    """Model acceleration error (process noise) per DOF, m/s^2 over ``model_error_time_s``."""
    model_error_time_s: float = 1.0
    """Time (s) over which ``accel_std_mps2`` is the model's velocity error."""
    heading_diversity: float = 0.85
    """See ``heading_memory_s``."""
    heading_memory_s: float = 300.0
    """Without a surge model the along-track sigma is floored at the prior unless the
    headings of the last ``heading_memory_s`` are diverse: the mean of the doubled-angle
    unit vector (cos 2psi, sin 2psi) shorter than ``heading_diversity``. Doubled, because
    reversing course (a glider's back-and-forth, a lawnmower survey) keeps the same lateral
    axis and adds nothing to the sway constraint. 0.85: e.g. two headings 35 deg apart; a
    +-15 deg zig-zag gives 0.87 and keeps the floor."""
    turn_accel_gain: float = 1.0
    """Extra model acceleration error in turns, m/s^2 per m/s^2 of each DOF's own
    centripetal acceleration (surge ``|v_r r|``, sway ``|u_r r|``, ...; current_kf.py)."""
    max_speed_through_water_mps: Annotated[float, msgspec.Meta(gt=0.0)] = 10.0
    """A predicted through-water velocity component beyond this (m/s) flags the joint
    filter (health ``runaway``, counted per episode): its current is published as unknown
    until the velocity is back within it (an update that leaves the state non-finite or
    beyond 50 m/s resets the filter, ``diverged``). No vehicle this service serves moves
    at 10 m/s through water; a model that identified an anti-damping can."""
    prior_accel_std_mps2: float = 0.3
    """Model acceleration error of a DOF that has only the generic prior (mode (b), not yet
    identified), m/s^2: the prior says "no crabbing", not how much."""
    initial_current_std_mps: float = 1.0
    """Prior one-sigma of the current (m/s) before any turn has made it observable."""
    identify_max_current_std_mps: float = 0.1
    """The coefficients are updated only once the current's one-sigma is below this (m/s)."""
    identify_min_rate_rps: float = 0.03
    """A yaw rate (rad/s) above this marks a turn, which makes the model identifiable."""
    identify_after_turn_s: float = 30.0
    """Coefficients are updated during turns and this long after them (s)."""
    yaw_rls_p0: float = 1e6
    """Initial covariance of the yaw-channel RLS: large, because its regressors (u v,
    u^2 dr at small rates) are O(0.001-0.01) and ``lambda + phi^T P phi`` must be ruled by
    the data (with p0 = 100 the spheroid's coefficients stay 6x too small)."""
    yaw_forgetting: float = 0.9995
    """Forgetting factor of the yaw-channel RLS per update."""
    identify_straight: bool = False
    """Identify on straight lines too: only where the current is known (a calm-water
    identification run with ``initial_current_std_mps`` ~ 0 and ``current_walk_mps_rts``
    ~ 0)."""
    identify_min_speed_mps: float = 0.2
    """Below this through-water speed (m/s) the yaw RLS does not learn."""
    gnss_velocity_std_mps: float | None = None
    """One-sigma of GNSS velocity components (m/s) at the receiver's nominal accuracy;
    default from ``[sensors.gnss]``."""
    gnss_nominal_accuracy_m: Annotated[float, msgspec.Meta(ge=0.0)] | None = None
    """Receiver accuracy as noise: a fix reporting its speed accuracy ``speed_acc_mps``
    (m/s, one sigma) has that as its velocity one-sigma; one reporting only a horizontal
    accuracy ``h_acc_m`` (m, one sigma) worse than this has its velocity one-sigma scaled
    by ``h_acc_m / nominal`` (both scale with the satellite geometry and signal quality).
    Never below ``gnss_velocity_std_mps`` (a fix claiming better, RTK say, does not make its
    Doppler velocity better). Default ``[sensors.gnss] position_std_m``; 0: the configured
    one-sigma for every fix. A fix without a finite positive accuracy takes the
    configured one-sigma."""
    dvl_velocity_std_mps: float | None = None
    """One-sigma of DVL velocity components (m/s); default from ``[sensors.dvl]``."""
    gate_nis: float = 30.0
    """Innovations with a larger NIS are rejected (counted in health)."""
    max_late_hold_s: Annotated[float, msgspec.Meta(ge=0.0, le=2.0)] = 0.5
    """The pipeline fuses its samples in time order up to ``tick - hold``, ``hold`` the
    largest lateness of a sample in the last minute, at most this (s; 0: every sample at
    the tick it arrives, a late one fused at the filter's time): a DVL's report stamped at
    its time of validity arrives after the autopilot's frames of that instant, and fused
    out of order it reads as information about the current (docs/current.md, "Late
    measurements"). The published current is then that of the horizon."""
    calibrate: bool = True
    """Inflate the process noise when the innovation NIS says it is too small."""
    calibrate_block: int = 50
    """Innovations averaged per calibration block (whiteness test)."""
    hgo: HgoConfig = msgspec.field(default_factory=HgoConfig)
    """``[pipelines.current.hgo]``: the high-gain observer."""
    flow: FlowObserverConfig = msgspec.field(default_factory=FlowObserverConfig)
    """``[pipelines.current.flow]``: the flow observer."""
    unknown_above_std_mps: Annotated[float, msgspec.Meta(gt=0.0)] = 0.3
    """A component of the current whose one-sigma exceeds this (m/s) is published as
    unknown: absent from the estimates (an empty cell in estimates.csv, no ``CUR_N`` or
    ``WIND_COV`` on MAVLink), its ``std_`` still published, ``observable.<axis> = 0`` in
    health. 0.3: a 2-sigma band of +-0.6 m/s says nothing about a small vehicle's current
    (the along-track current without a surge model has a one-sigma of at least
    ``initial_current_std_mps``, 1 m/s, and is never published)."""
    restore_check_s: Annotated[float, msgspec.Meta(ge=0.0)] = 120.0
    """A restored current is on probation: a twin filter runs beside the pipeline from the
    restored model with the current at its prior, and the restored current must agree with
    the twin's (chi-square at ``restore_check_p`` on the components the twin observes) for
    this long (s of data) while the twin observes every horizontal component; a
    disagreement discards the restored current (an event, ``restore_discarded``)."""
    restore_check_p: Annotated[float, msgspec.Meta(gt=0.0, lt=0.5)] = 0.001
    """False-alarm probability of the restored-current test per evaluation."""
    glider: GliderModelConfig | None = None
    """The steady-glide model of a glider (``[pipelines.current.glider]``); None (absent):
    no glider model."""



# ---------------------------------------------------------------------------------------
# [pipelines.eseso]

# BlueROV2 (standard, vectored frame) force rows of the allocation matrix, FRD body axes,
# per unit thruster force; thrusters 1-4 horizontal at 45 deg, 5-6 vertical. Matches the
# paper's K_alloc (algorithms.md §5.2) turned from its z-up body frame into FRD.
BLUEROV2_FORCE_ALLOCATION: tuple[tuple[float, ...], ...] = (
    (0.7071, 0.7071, -0.7071, -0.7071, 0.0, 0.0),
    (-0.7071, 0.7071, -0.7071, 0.7071, 0.0, 0.0),
    (0.0, 0.0, 0.0, 0.0, -1.0, -1.0),
)


class EsesoVehicleConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True,
                         frozen=True):
    """``[pipelines.eseso.vehicle]``: the rigid body and its hydrodynamics (algorithms.md
    §5.1, §5.4). Defaults: the paper's Table I (BlueROV2)."""

    mass_kg: float = 11.26
    """Vehicle mass (kg)."""
    added_mass_kg: list[float] = msgspec.field(default_factory=lambda: [1.7182, 0.0, 5.468])
    """X_udot, Y_vdot, Z_wdot as positive added masses (kg)."""
    damping_linear: list[float] = msgspec.field(default_factory=lambda: [11.7391, 20.0, 31.8678])
    """Positive linear damping d_l (N s/m); the paper lists them negated."""
    damping_quadratic: list[float] = msgspec.field(default_factory=lambda: [18.18, 21.66, 36.99])
    """Positive quadratic damping d_nl (N s^2/m^2)."""
    cg_z_m: float = 0.2
    """Centre of gravity below the body origin (m), paper Table I (the public code has
    0.02); the IMU is taken at the origin."""
    weight_n: float = 112.8
    """Weight (N)."""
    buoyancy_n: float = 114.8
    """Buoyancy (N)."""


class EsesoThrustersConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True,
                           frozen=True):
    """``[pipelines.eseso.thrusters]``: normalized thruster commands into a body force
    (algorithms.md §5.2): the allocation times each thruster's thrust curve
    ``max * sign(c) |c|^exponent`` outside the deadband."""

    allocation: list[list[float]] = msgspec.field(
        default_factory=lambda: [list(r) for r in BLUEROV2_FORCE_ALLOCATION])
    """3 x n_thrusters: body force (N, FRD) per newton of each thruster."""
    max_forward_n: float = 40.0
    """Thrust (N) at normalized command +1 (T200 at ~14.8 V, as the SITL plant)."""
    max_reverse_n: float = 30.0
    """Thrust magnitude (N) at normalized command -1."""
    exponent: float = 2.0
    """Thrust = max * sign(c) |c|^exponent (1 = linear map, 2 = quadratic in command)."""
    deadband: float = 0.0
    """Normalized commands with |c| below this give no thrust."""
    command_timeout_s: float = 0.5
    """A thruster command older than this is not used by the thrust update."""


class EsesoProcessConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True,
                         frozen=True):
    """``[pipelines.eseso.process]``: the process noise of the error states
    (``EsesoFilter.propagate``) and of the lumped disturbance's model changes
    (``EsesoFilter.model_change_var``) [DEFAULT]."""

    disturbance_model: Literal["earth_fixed", "body_fixed"] = "earth_fixed"
    """Axes in which the disturbance force is a random walk."""
    accel_bias_walk_mps2_rts: float = 1e-4
    """Accelerometer bias random walk (m/s^2/sqrt(s))."""
    gyro_bias_walk_rps_rts: float = 1e-5
    """Gyro bias random walk (rad/s/sqrt(s))."""
    gravity_walk_mps2_rts: float = 1e-6
    """Gravity random walk (m/s^2/sqrt(s)); it only absorbs a wrong nominal g."""
    disturbance_walk_n_rts: float = 1.0
    """Disturbance random walk (N/sqrt(s))."""
    position_walk_m_rts: float = 1e-3
    """Extra position random walk (m/sqrt(s)), keeps P well conditioned."""
    damping_rel_std: float = 0.3
    """Relative one-sigma of the damping coefficients (dimensionless) [DEFAULT: identified
    drag coefficients are rarely better than 30 %]. The lumped disturbance carries the
    damping's error, so when the damping force ``D(nu) nu`` changes, the disturbance
    changes by this times the change: added to its process noise at each thrust update
    (``EsesoFilter.model_change_var``). 0 = the random walk alone."""
    thrust_rel_std: float = 0.05
    """Relative one-sigma of each change of the commanded body force (dimensionless), added
    to the lumped disturbance's process noise like ``damping_rel_std`` [DEFAULT: measured in
    the closed loop, docs/mismatch.md: a T200's map varies by ~20 % over the battery's
    12-16 V, but slowly; at 0.2 per change the AMPC's own thrust swings under a 0.15 s
    thruster lag made the disturbance chase the lag (bluerov2-circle, 30 s, seed 1: xi error
    38.7 N, tracking 0.091 m), at 0.05 2.75 N and 0.055 m, nominal unchanged (0.015 m)]."""


class EsesoNoiseConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True,
                       frozen=True):
    """``[pipelines.eseso.noise]``: the measurement noise of each channel (None: from
    ``[sensors]``) and its adaptation from the innovations (covariance matching)."""

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
    """GNSS position noise (m); default ``[sensors.gnss]``."""
    gnss_velocity_std_mps: float | None = None
    """GNSS velocity noise (m/s); default ``[sensors.gnss]``."""
    depth_std_m: float | None = None
    """Depth noise (m); default ``[sensors.depth]``."""
    dvl_velocity_std_mps: float | None = None
    """DVL velocity noise (m/s) when a report has no figure of merit; default
    ``[sensors.dvl]``."""
    attitude_std_rad: float = 0.01
    """Roll and pitch noise of the AHRS attitude (rad)."""
    attitude_yaw_std_rad: float | None = None
    """Yaw noise of the AHRS attitude (rad); None = the compass heading noise
    (``heading_std_rad``, else ``[sensors.compass]``): an AHRS reports the compass heading
    as its yaw."""
    heading_std_rad: float | None = None
    """Compass heading noise (rad); default ``[sensors.compass]``."""
    thrust_std_n: float = 0.0
    """The thrusters' own force error (N, one-sigma per body axis) besides what the IMU's
    noise puts into the thrust model (``EsesoFilter.thrust_noise``) [DEFAULT: the
    simulated thrusters have none; a real thruster's larger error is learnt by the thrust
    channel's noise scale, ``adapt_updates``]."""
    accel_std_mps2: float | None = None
    """Accelerometer noise (m/s^2); default ``[sensors.imu]``."""
    gyro_std_rps: float | None = None
    """Gyro noise (rad/s); default ``[sensors.imu]``."""
    adapt_updates: int = 100
    """Updates over which each sensor channel's noise scale is averaged (the time constant
    of its exponential mean, in updates); 0 = no adaptation, the configured noise always."""
    scale_max: float = 9.0
    """Ceiling of the measurement-noise variance scale (dimensionless; 9 = three times the
    configured sigma). Its floor is 1: the adaptation only ever inflates the noise, so a
    channel is never trusted more than configured."""
    thrust_scale_max: float = 100.0
    """Ceiling of the thrust channel's noise variance scale (dimensionless; 100 = ten
    times the ~1 N the IMU's noise puts into the thrust model): a real thruster's force
    error (lag, thrust curve against battery voltage; 3-4 N on the ArduSub tlog of
    ``/work/shared/data``) is several times what the IMU explains, and unlike a sensor's
    it is configured by nobody."""


class EsesoInitialConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True,
                         frozen=True):
    """``[pipelines.eseso.initial]``: the initial state the filter does not measure at its
    start, and the initial one-sigma of each error state."""

    north_m: float = 0.0
    """See ``east_m``."""
    east_m: float = 0.0
    """Start position (m) when no GNSS fix precedes the start (a surveyed launch point);
    positions are then relative to this point until a fix arrives."""
    gravity_mps2: float = 9.81
    """Nominal gravity (m/s^2): the gravity state's start."""
    position_std_m: float = 1.0
    """Initial one-sigma of the position (m)."""
    velocity_std_mps: float = 0.3
    """Initial one-sigma of the velocity (m/s)."""
    attitude_std_rad: float = 0.05
    """Initial one-sigma of the attitude (rad)."""
    accel_bias_std_mps2: float = 0.05
    """Initial one-sigma of the accelerometer bias (m/s^2)."""
    gyro_bias_std_rps: float = 0.005
    """Initial one-sigma of the gyro bias (rad/s)."""
    gravity_std_mps2: float = 0.01
    """Initial one-sigma of gravity (m/s^2)."""
    disturbance_std_n: float = 40.0
    """Initial one-sigma of the disturbance force (N)."""


class EsesoConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """``[pipelines.eseso]``: when the ESESO is built, how its updates are gated, and its
    nested tables: ``[pipelines.eseso.vehicle]``, ``.thrusters``, ``.process``, ``.noise``
    and ``.initial``.

    Vehicle parameters default to the paper's Table I (BlueROV2). Noise figures not given
    here come from ``[sensors]``. Defaults marked [DEFAULT] are ours (tuned on the
    ``bluerov2-circle`` scenario), not the paper's Q = 1e-3 I and
    R = diag(0.01 I, 0.02 I, 0.0006 I, 0.012 I), which are per-step numbers of a 50 Hz
    loop in unstated units.
    """

    enabled: bool | None = None
    """Unset: built for ``vehicle_classes``; true: built for any vehicle class; false:
    never built."""
    vehicle_classes: list[str] = msgspec.field(default_factory=lambda: ["bluerov2"])
    """Vehicle classes the pipeline is built for (any class with ``enabled = true``)."""
    gnss_max_depth_m: float | None = None
    """Fixes received deeper than this are rejected (default sensors.depth.surface_depth_m)."""
    gate_sigma: float = 0.0
    """0 = chi-square 99.9 % gates; else the NIS gate is ``gate_sigma**2 * dof``."""
    thrust_states: Literal["disturbance", "all"] = "disturbance"
    """Which error states the thrust update corrects. ``"disturbance"`` (as the paper's
    H, the disturbance alone): a Schmidt-Kalman update, the full Jacobian in the
    innovation covariance and the covariance, the gain's other rows zeroed, so thruster
    and model errors cannot move the velocity. ``"all"``: a full update."""
    max_consecutive_rejects: int = 5
    """After this many gated samples in a row a channel is fused again, down-weighted by
    NIS / gate, so one bad spell cannot lock a sensor out for good."""
    thrust_huber: float = 16.0
    """Above this NIS the thrust update is down-weighted (R scaled by NIS / thrust_huber,
    a Huber-type robust update) instead of rejected: thruster steps excite roll and pitch
    accelerations faster than the IMU rate resolves, while a new push must still get in.
    0 = plain update."""
    max_imu_gap_s: float = 0.5
    """A longer gap between IMU samples restarts the propagation clock (counted)."""
    vehicle: EsesoVehicleConfig = msgspec.field(default_factory=EsesoVehicleConfig)
    """``[pipelines.eseso.vehicle]``."""
    thrusters: EsesoThrustersConfig = msgspec.field(default_factory=EsesoThrustersConfig)
    """``[pipelines.eseso.thrusters]``."""
    process: EsesoProcessConfig = msgspec.field(default_factory=EsesoProcessConfig)
    """``[pipelines.eseso.process]``."""
    noise: EsesoNoiseConfig = msgspec.field(default_factory=EsesoNoiseConfig)
    """``[pipelines.eseso.noise]``."""
    initial: EsesoInitialConfig = msgspec.field(default_factory=EsesoInitialConfig)
    """``[pipelines.eseso.initial]``."""


class DacConfig(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """``[pipelines.dac]``: a glider's depth-averaged current, dive by dive
    (onboard/pipelines/dac.py, algorithms.md §3.7). Its glider model is
    ``[pipelines.current.glider]``."""

    enabled: bool = False
    """True: the pipeline is built (a glider's config: config/slocum-glider.toml)."""
    min_dive_s: Annotated[float, msgspec.Meta(gt=0.0)] = 600.0
    """A dive shorter than this (s) between its two surface fixes gives no current."""
    lift_rel_std: Annotated[float, msgspec.Meta(ge=0.0)] = 0.25
    """Relative one-sigma of the glide model's lift, one error for a whole dive (a hull,
    its fouling and trim against ``[pipelines.current.glider] lift_kl``)."""
    pitch_bias_std_rad: Annotated[float, msgspec.Meta(ge=0.0)] = 0.0087
    """One-sigma (rad; 0.0087 = 0.5 deg) of the pitch sensor's bias over a dive. The
    compass's error is ``[sensors.compass] heading_std_rad``."""
    trim_std_cc: Annotated[float, msgspec.Meta(ge=0.0)] = 30.0
    """One-sigma (cm^3) of the neutral pump volume against ``[pipelines.current.glider]
    neutral_pump_cc`` over a dive: the ballasting's error, and water of another density
    than the ballasting's (0.5 kg/m^3 on a 60-L hull)."""
    vertical_displacement_std_m: Annotated[float, msgspec.Meta(ge=0.0)] = 5.0
    """One-sigma (m) of the water's vertical displacement by internal waves at each of a
    dive's inflections (algorithms.md §3.7; the Garrett-Munk spectrum's is about 7 m in
    the deep thermocline, less on a shelf)."""
    vertical_displacement_time_s: Annotated[float, msgspec.Meta(gt=0.0)] = 600.0
    """Its correlation time (s) between inflections: a shallow glider's yos, minutes
    apart, see nearly the same displacement."""


VELOCITY_PIPELINES = frozenset({"current", "dac"})
"""Pipelines whose ``north``/``east`` are a water velocity (m/s), not a position: no track
is drawn or exported from them (onboard/offline/plots.py, exports.py)."""


class Pipelines(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """``[pipelines]``: one table per pipeline of :data:`onboard.pipelines.MODULES`."""

    nav: NavConfig = msgspec.field(default_factory=NavConfig)
    """``[pipelines.nav]``."""
    aie: AieConfig = msgspec.field(default_factory=AieConfig)
    """``[pipelines.aie]``."""
    kf: KfConfig = msgspec.field(default_factory=KfConfig)
    """``[pipelines.kf]``."""
    current: CurrentConfig = msgspec.field(default_factory=CurrentConfig)
    """``[pipelines.current]``."""
    dac: DacConfig = msgspec.field(default_factory=DacConfig)
    """``[pipelines.dac]``."""
    eseso: EsesoConfig = msgspec.field(default_factory=EsesoConfig)
    """``[pipelines.eseso]``."""
