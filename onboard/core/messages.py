"""Typed messages: every sensor sample and every estimate the project passes around.

These msgspec Structs are the single source of truth for the data model. Drivers produce
them, the engine orders them, pipelines consume them, publishers encode them. Neither
``drivers`` nor ``onboard.pipelines`` knows the other; both know only this module.

Conventions (everywhere in the project):

* time ``t`` is in seconds. For live data it is the receive time on the service clock;
  for logs it is the log's own time stamp (a tlog's receive time, a DataFlash ``TimeUS``);
* earth frame is NED (north, east, down), body frame FRD (forward, right, down);
* angles in radians, headings clockwise from north in [0, 2*pi) or (-pi, pi];
* SI units; a field name carries its unit when it is not the SI base unit (``_deg``,
  ``_us``, ``_rpm``);
* a quantity that the source did not provide is ``None`` (never 0, never NaN).
"""

from __future__ import annotations

from typing import Literal, Union

import msgspec

SCHEMA_VERSION = 2
"""Version of the wire schema of :class:`EstimateRecord` (2: ``utc``, ``lat_deg`` and
``lon_deg`` on every record, fields a schema-1 reader that ignores unknown fields skips;
:class:`HealthRecord` has its own, :data:`HEALTH_SCHEMA_VERSION`)."""


class Sample(msgspec.Struct, frozen=True, kw_only=True, tag_field="type"):
    """Base of every sensor sample.

    ``t`` is the time of the sample in seconds (see the module docstring);
    ``source`` names where it came from (``"mavlink"``, ``"nmea"``, ``"dvl"``, a log
    channel...), so a vehicle with two GPS receivers keeps them apart.
    """

    t: float
    source: str = ""


class GnssFix(Sample, frozen=True, tag="gnss"):
    """A GNSS position fix, optionally with velocity over ground.

    ``fix_quality`` follows NMEA GGA: 0 none, 1 GPS, 2 DGPS, 4 RTK fixed, 5 RTK float;
    MAVLink ``fix_type`` is mapped onto it by the drivers (3D fix -> 1, DGPS -> 2, RTK
    fixed -> 4, RTK float -> 5). ``sog_mps`` and ``cog_rad`` are speed and course over
    ground; ``h_acc_m`` and ``v_acc_m`` are one-sigma horizontal and vertical accuracies,
    ``speed_acc_mps`` the one-sigma accuracy of ``sog_mps``, as the receiver reports them.
    """

    lat_deg: float
    lon_deg: float
    alt_m: float | None = None
    fix_quality: int = 1
    num_sats: int | None = None
    hdop: float | None = None
    sog_mps: float | None = None
    cog_rad: float | None = None
    h_acc_m: float | None = None
    v_acc_m: float | None = None
    speed_acc_mps: float | None = None


class VelocityOverGround(Sample, frozen=True, tag="vog"):
    """Earth-frame velocity over ground from a navigation solution (INS, EKF, DVL-aided INS).

    MAVLink GLOBAL_POSITION_INT vx/vy/vz and LOCAL_POSITION_NED map here.
    ``heading_rad`` is the heading (rad, true north, clockwise) of the same solution at the
    same instant when the source gives one (GLOBAL_POSITION_INT ``hdg``): the heading in
    whose frame this velocity was resolved (a DVL-aided INS rotates its body-frame DVL
    velocity by it), None otherwise.
    """

    v_north_mps: float
    v_east_mps: float
    v_down_mps: float | None = None
    heading_rad: float | None = None


class Imu(Sample, frozen=True, tag="imu"):
    """Inertial measurement: specific force (m/s^2) and angular rate (rad/s), body FRD."""

    accel_x: float
    accel_y: float
    accel_z: float
    gyro_x: float
    gyro_y: float
    gyro_z: float


class Heading(Sample, frozen=True, tag="heading"):
    """A heading measurement (rad, clockwise from north).

    ``reference`` says whether it is relative to true or magnetic north; a magnetic
    heading needs the declination (``declination_rad`` when the source gives it). The
    engine makes every magnetic heading true before a pipeline sees it
    (:mod:`onboard.engine.declination`): a pipeline's headings are all true.
    """

    heading_rad: float
    reference: Literal["true", "magnetic"] = "true"
    declination_rad: float | None = None


class Attitude(Sample, frozen=True, tag="attitude"):
    """Attitude as ZYX Euler angles (rad) and optionally the body rates (rad/s).

    ``yaw_selected`` is False when the source selector (onboard/engine/sources.py) chose another
    source for the heading: roll, pitch and the rates are to be used, the yaw is not.
    """

    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    roll_rate_rps: float | None = None
    pitch_rate_rps: float | None = None
    yaw_rate_rps: float | None = None
    yaw_selected: bool = True


class DvlVelocity(Sample, frozen=True, tag="dvl"):
    """A Doppler velocity log report, instrument/body frame (m/s).

    ``track`` is ``"bottom"`` (velocity over ground) or ``"water"`` (velocity through
    water). ``valid`` is the instrument's own validity flag: an invalid report is kept
    (it is information: the DVL lost lock) but never fused. ``fom_mps`` is the figure of
    merit (one-sigma velocity error), ``covariance`` the row-major 3x3 covariance
    (m^2/s^2), ``altitude_m`` the range to the bottom.
    """

    vx: float
    vy: float
    vz: float
    track: Literal["bottom", "water"] = "bottom"
    valid: bool = True
    fom_mps: float | None = None
    covariance: tuple[float, ...] | None = None
    altitude_m: float | None = None


class DvlPosition(Sample, frozen=True, tag="dvl_position"):
    """A DVL's own dead-reckoned position (m, NED from its reset point) and attitude."""

    north_m: float
    east_m: float
    down_m: float
    roll_rad: float | None = None
    pitch_rad: float | None = None
    yaw_rad: float | None = None
    std_m: float | None = None


class Depth(Sample, frozen=True, tag="depth"):
    """Depth below the surface (m, positive down), optionally with the absolute pressure."""

    depth_m: float
    pressure_pa: float | None = None
    temperature_c: float | None = None


class Pressure(Sample, frozen=True, tag="pressure"):
    """An absolute pressure reading (Pa) that has not yet been turned into depth.

    The engine converts it with the configured water density and surface pressure.
    """

    pressure_pa: float
    temperature_c: float | None = None


class Altitude(Sample, frozen=True, tag="altitude"):
    """Range to the bottom (m), from an echo sounder or DISTANCE_SENSOR."""

    altitude_m: float


class ActuatorOutputs(Sample, frozen=True, tag="actuators"):
    """Raw actuator outputs: PWM pulse widths (us) per output channel, channel 1 first.

    Which channel drives which actuator is configuration (``[inputs]`` in the vehicle
    config), applied by the engine, not by the drivers.
    """

    pwm_us: tuple[float, ...]


class RcChannels(Sample, frozen=True, tag="rc"):
    """RC input pulse widths (us) per channel, channel 1 first."""

    pwm_us: tuple[float, ...]


class PropellerRpm(Sample, frozen=True, tag="rpm"):
    """Measured shaft speeds (rev/min), one per sensor (MAVLink RPM.rpm1, rpm2)."""

    rpm: tuple[float, ...]


class ActuatorColumn(Sample, frozen=True, tag="column"):
    """One actuator value read from a named column of a log (a CSV or glider-style log),
    in the log's own units (a rudder angle in degrees, a normalized command, a power
    level). The ``[inputs]`` roles with ``source = "column"`` and this ``column`` map it to
    a command with the same normalization as a pulse width (``ChannelMap``)."""

    column: str
    value: float


class ActuatorCommand(Sample, frozen=True, tag="command"):
    """Normalized actuator command, the vehicle-independent input to the pipelines.

    Produced from raw outputs by the configured input mapping. Normalized values are in
    [-1, 1] (1 = full ahead / full right); angles in rad; ``None`` where the vehicle has
    no such actuator.

    * ``throttle``: a single propulsor (rudder boats, torpedo AUVs);
    * ``rudder_rad``: rudder deflection, positive turns the bow to starboard;
    * ``left``, ``right``: the two thrusters of a skid-steered boat;
    * ``propeller_rpm``: commanded or measured shaft speed;
    * ``stern_plane_rad``: stern/dive plane deflection, positive pitches the nose down;
    * ``thrusters``: per-thruster commands of a multi-thruster vehicle (BlueROV2 order);
    * ``pump_cc``: a glider's buoyancy-pump (ballast) volume (cm^3, positive buoyant);
    * ``battery_m``: a glider's moving-battery position (m, forward positive).
    """

    throttle: float | None = None
    rudder_rad: float | None = None
    left: float | None = None
    right: float | None = None
    propeller_rpm: float | None = None
    stern_plane_rad: float | None = None
    thrusters: tuple[float, ...] | None = None
    pump_cc: float | None = None
    battery_m: float | None = None


class Parameter(Sample, frozen=True, tag="param"):
    """An autopilot parameter (PARAM_VALUE, DataFlash PARM)."""

    name: str
    value: float


class VehicleInfo(Sample, frozen=True, tag="vehicle"):
    """What a HEARTBEAT says about the sender: MAV_TYPE and MAV_AUTOPILOT numbers."""

    system_id: int
    component_id: int
    mav_type: int
    autopilot: int


AnySample = Union[
    GnssFix,
    VelocityOverGround,
    Imu,
    Heading,
    Attitude,
    DvlVelocity,
    DvlPosition,
    Depth,
    Pressure,
    Altitude,
    ActuatorOutputs,
    RcChannels,
    PropellerRpm,
    ActuatorColumn,
    ActuatorCommand,
    Parameter,
    VehicleInfo,
]
"""Every concrete sample type; a tagged union for msgspec decoding."""


class EstimateRecord(msgspec.Struct, frozen=True, kw_only=True):
    """One pipeline's estimates at one tick, as published on ``onboard/<id>/est/<pipeline>``.

    ``values`` maps quantity name (the part after ``<pipeline>.`` in estimates.csv) to its
    value in SI units; ``std`` gives one-sigma uncertainties where the pipeline has them.
    ``t_sensor`` is the time of the newest input sample that contributed, so consumers can
    measure latency. ``sources`` maps each selected quantity (``position``, ``heading``,
    ...) to the source in use at this tick (onboard/engine/sources.py). ``utc`` is the
    tick's time in UTC (POSIX s: the log's UTC in a replay, the system clock live; null
    when unknown) and ``lat_deg``, ``lon_deg`` the vehicle's best position at the tick
    (null when unknown; :mod:`onboard.engine.whereabouts`), ``position_std_m`` its
    one-sigma per horizontal axis (m; null when unknown; an AUV's dead-reckoned position
    grows it; added after ``lon_deg``, issue 33). A schema-1 record decodes with the four
    null.
    """

    schema: int = SCHEMA_VERSION
    vehicle: str
    pipeline: str
    t: float
    values: dict[str, float]
    std: dict[str, float] = {}
    t_sensor: float | None = None
    sources: dict[str, str] = {}
    utc: float | None = None
    lat_deg: float | None = None
    lon_deg: float | None = None
    position_std_m: float | None = None


class Innovation(msgspec.Struct, frozen=True, kw_only=True):
    """One measurement update of one estimator: what was measured against what was
    forecast (filterpy's ``y`` and ``S``, statsmodels' ``forecasts_error`` and
    ``forecasts_error_cov``).

    Attributes:
        channel: the measurement channel within its pipeline (``surge.increment``,
            ``surge.speed``, ``velocity``, ``dvl`` ...; docs/architecture.md §4.4).
        t: time of the measurement (s).
        z: the innovation, measurement minus forecast (the measurement's unit).
        S: its predicted covariance, row-major ``dof x dof``.
        nis: normalized innovation squared ``z' S^-1 z`` (chi-square with ``dof`` degrees
            of freedom for a consistent filter).
        dof: the measurement's dimension.
        gate: the NIS beyond which the measurement is rejected (infinite: no gate).
        accepted: whether the update used it.
        reason: why it was not used (``gate``, ...); empty when accepted.
        source: the sample source it came from (empty when the pipeline does not know).
    """

    channel: str
    t: float
    z: tuple[float, ...]
    S: tuple[float, ...]
    nis: float
    dof: int
    gate: float = float("inf")
    accepted: bool = True
    reason: str = ""
    source: str = ""

    @property
    def test_ratio(self) -> float:
        """``nis / gate``, as MAVLink's ESTIMATOR_STATUS defines its test ratios: above 1
        the measurement is rejected (0 without a gate)."""
        return self.nis / self.gate


class ChannelHealth(msgspec.Struct, frozen=True, kw_only=True):
    """The innovations of one channel of one pipeline, summarized (HealthRecord,
    summary.json). A quantity with no value yet is null.

    Attributes:
        n: measurements offered; rejected: of those, not used (by ``reasons``).
        dof: the measurement's dimension.
        nis_mean: mean NIS of the accepted ones since the start (expected ``dof``).
        nis_recent: running mean of the accepted ones over about
            ``onboard.monitor.innovations.RECENT_STEPS`` updates.
        nis: the newest NIS; test_ratio: its ``nis / gate``; test_ratio_max: the largest
            since the previous record.
        z, S: the newest innovation and its covariance (row-major).
        t: time (s) of the newest measurement.
        source: its sample source.
        by_source: when the channel has had measurements from more than one source (two
            GNSS receivers, two DVLs), the same summary per source (each with an empty
            ``by_source``); empty otherwise.
    """

    n: int
    rejected: int = 0
    reasons: dict[str, int] = {}
    dof: int
    nis_mean: float | None = None
    nis_recent: float | None = None
    nis: float | None = None
    test_ratio: float | None = None
    test_ratio_max: float | None = None
    z: list[float | None] = []
    S: list[float | None] = []
    t: float | None = None
    source: str = ""
    by_source: dict[str, ChannelHealth] = {}


class Alert(msgspec.Struct, frozen=True, kw_only=True):
    """A warning a user reads first (summary.json's ``warnings``; docs/architecture.md
    §4.2): ``code`` for programs; ``message`` for people, one line: what happened, where,
    and the config key or command that changes it; ``details`` after it (why, what was
    measured; may be empty); about ``pipeline`` (empty: the log or the engine), from
    ``t_start`` to ``t_end`` (s; null: the whole run), raised ``n`` times in that span."""

    code: str
    pipeline: str = ""
    message: str
    details: str = ""
    t_start: float | None = None
    t_end: float | None = None
    n: int = 1


class DeclinationReport(msgspec.Struct, frozen=True, kw_only=True):
    """The magnetic declination the engine applies to magnetic headings
    (:mod:`onboard.engine.declination`; HealthRecord, summary.json's ``declination``).

    ``deg`` east positive (``true = magnetic + deg``; null: none known); ``source``:
    ``wmm`` (the World Magnetic Model at ``lat_deg``, ``lon_deg`` on the decimal
    ``year``, taken from the log's UTC time stamps or today's date: ``date_from``
    ``log`` or ``today``; ``model`` its name, e.g. ``WMM-2025``), ``config``
    (``[corrections] declination_deg``), ``sensor`` (the heading's own, NMEA HDG's
    variation) or ``none`` (magnetic headings used as they are).
    """

    deg: float | None = None
    source: Literal["wmm", "config", "sensor", "none"] = "none"
    model: str = ""
    lat_deg: float | None = None
    lon_deg: float | None = None
    year: float | None = None
    date_from: Literal["log", "today", ""] = ""


HEALTH_SCHEMA_VERSION = 3
"""Version of the wire schema of :class:`HealthRecord` (3: each channel's summary also per
source, ``ChannelHealth.by_source``, and the ``declination``: fields a schema-2 reader that
ignores unknown fields skips; 2: typed innovations and counters apart; 1 had flat
``innovations`` and ``nis`` dictionaries)."""


class HealthRecord(msgspec.Struct, frozen=True, kw_only=True):
    """Service health, published on ``onboard/<id>/health``.

    ``rates_hz`` per source, ``rejected`` counts of the inputs refused per reason (and
    the pipelines' failures), ``withheld`` counts of the estimate values left out of the
    records (not finite, or withheld by an integrity check), ``innovations`` per pipeline
    and channel (:class:`ChannelHealth`), ``counters`` per pipeline (its steps, restarts,
    adaptive quantities: :meth:`onboard.pipelines.base.Pipeline.health`), ``events``
    recent human-readable events, ``sources`` the active source of each selected quantity
    (onboard/engine/sources.py), ``declination`` the one applied to magnetic headings
    (:class:`DeclinationReport`).
    """

    schema: int = HEALTH_SCHEMA_VERSION
    vehicle: str
    t: float
    rates_hz: dict[str, float] = {}
    rejected: dict[str, int] = {}
    withheld: dict[str, int] = {}
    dropped: dict[str, int] = {}
    innovations: dict[str, dict[str, ChannelHealth]] = {}
    counters: dict[str, dict[str, float | None]] = {}
    events: list[str] = []
    mode: str = ""
    sources: dict[str, str] = {}
    flags: dict[str, list[str]] = {}
    declination: DeclinationReport = DeclinationReport()
