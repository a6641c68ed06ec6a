"""Configuration: TOML files under ``config/`` decoded into typed msgspec Structs.

One file per vehicle class (``rudder-boat.toml``, ``twin-thruster-boat.toml``,
``bluerov2.toml``, ``torpedo-auv.toml``, ...) and per deployment. A bad file is reported
with the dotted key and what was expected, e.g.::

    config/mine.toml: inputs.throttle.channel: expected int, got str

Every ``[pipelines.<name>]`` table is decoded here too, into its struct of
:mod:`onboard.core.pipeline_config`: an unknown pipeline name or key is an error naming the
file and the key, e.g. ``overlay.toml: pipelines.aei: unknown key (misspelt?)``; a
renamed key is an error naming its new one, e.g. ``my.toml: pipelines.aie.nis_gate:
renamed to pipelines.aie.gate_nis`` (:mod:`onboard.core.config_renames`).

Several files make one configuration with :func:`load_all` (``--config base.toml
--config overlay.toml``): later files win key by key, tables are merged recursively,
lists and values are replaced whole (:func:`merge`). ``onboard diagnose --write-config``
writes such an overlay (:mod:`onboard.offline.closure.overlay`).
"""

from __future__ import annotations

import re
import tomllib
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, Sequence

import msgspec

from onboard.core.config_renames import renamed_key
from onboard.core.errors import UsageError
from onboard.core.pipeline_config import Pipelines
from onboard.core.vehicles import VehicleClass

BUNDLED_PACKAGE = "onboard.bundled"
"""The package of the bundled configs and gains: the repository's ``config/`` folder,
installed inside ``onboard`` (pyproject.toml ``package-dir``), data only."""


def _package_dir(package: str) -> Path:
    """The folder of ``package`` (:mod:`importlib.resources`): inside the installed package,
    or the source folder an editable install maps it to. pip installs unpacked, so it is a
    folder on the file system; anything else is an ImportError naming it."""
    root = resources.files(package)
    if not isinstance(root, Path):
        raise ImportError(f"{package}: its data is not a folder on the file system ({root})")
    return root


CONFIG_DIR = _package_dir(BUNDLED_PACKAGE)
"""Where the bundled vehicle configs live (``gains/`` under it): ``onboard/bundled/`` of the
installed package, the checkout's ``config/`` in an editable install."""


class ConfigError(UsageError, ValueError):
    """A configuration file is missing, unreadable or does not match the schema."""


class _Strict(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """Base for config tables: unknown keys are errors (they are almost always typos)."""


class Vehicle(_Strict):
    """``[vehicle]``: identity and class."""

    id: str = "vehicle"
    """Vehicle name: in the Zenoh keys and the saved adaptive state."""
    vehicle_class: VehicleClass = msgspec.field(default="unknown", name="class")
    """Vehicle class (``class`` in the file): chooses the pipelines and their models
    through its traits (:mod:`onboard.core.vehicles`)."""
    system_id: int = 1
    """MAVLink system id the estimates are sent as."""
    description: str = ""
    """Free text."""


class EngineConfig(_Strict):
    """``[engine]``: the fixed-rate tick that drives the pipelines."""

    rate_hz: Annotated[float, msgspec.Meta(gt=0.0)] = 10.0
    """Rate (Hz) of the tick at which the pipelines give estimates."""
    max_sample_age_s: float = 2.0
    """Samples older than this relative to the newest one are rejected as late."""
    time_jump_s: Annotated[float, msgspec.Meta(gt=0.0)] = 10.0
    """A stamp this far (s) from the newest in a log, or from its receive time live, either
    way, is a jump or an outlier, not the next sample (onboard/engine/timeline.py); a log
    silent longer between samples in its normal course (a Slocum's ``.sbd``, a cycle every
    4-60 s) needs more."""


class ChannelMap(_Strict):
    """How one actuator role is read from a log or telemetry field.

    ``source`` is ``servo`` (SERVO_OUTPUT_RAW / RCOU), ``rc`` (RC_CHANNELS / RCIN),
    ``rpm`` (RPM message) or ``column`` (the CSV column named by ``column``, in the log's
    own units: the ``*_us`` keys are then in that unit; docs/formats-text.md).
    PWM is normalized as ``(pwm - neutral_us) / half_range_us`` with ``deadband_us``
    around neutral set to zero, clipped to [-1, 1], negated when ``reverse``; then
    multiplied by ``full_scale`` (e.g. 0.2618 rad for a +-15 deg rudder, or the rpm at
    full throttle). A ``rpm`` source is multiplied by ``full_scale`` directly (1 = rpm).
    """

    source: Literal["servo", "rc", "rpm", "column"] = "servo"
    channel: int = 1
    """Output, RC or RPM channel (1 = the first); not used by ``column``."""
    column: str = ""
    """The log column a ``column`` source reads."""
    neutral_us: float = 1500.0
    """Value read at zero command (us for PWM; the column's unit for ``column``)."""
    half_range_us: float = 400.0
    """Distance from neutral to full command, same unit."""
    deadband_us: float = 0.0
    """Values within this of neutral read as zero, same unit."""
    reverse: bool = False
    """Negate the normalized value."""
    full_scale: float = 1.0
    """The command at full deflection (rad, rpm, or 1 for a normalized one)."""


class Inputs(_Strict):
    """``[inputs]``: which field is which actuator. Roles match ActuatorCommand."""

    throttle: ChannelMap | None = None
    """A single propulsor (rudder boats, torpedo AUVs)."""
    rudder: ChannelMap | None = None
    """Rudder (``full_scale`` in rad)."""
    left: ChannelMap | None = None
    """Port thruster of a differential-drive boat."""
    right: ChannelMap | None = None
    """Starboard thruster of a differential-drive boat."""
    propeller_rpm: ChannelMap | None = None
    """Measured or commanded propeller speed (rpm)."""
    stern_plane: ChannelMap | None = None
    """Stern plane of a torpedo AUV (``full_scale`` in rad)."""
    thrusters: list[ChannelMap] = []
    """Thrusters of an ROV, in the order of the allocation matrix."""
    pump: ChannelMap | None = None
    """A glider's buoyancy-pump volume (``full_scale`` in cm^3: e.g. a ``column`` source
    with ``neutral_us = 0``, ``half_range_us = full_scale = 1000`` reads cm^3 as logged)."""
    battery: ChannelMap | None = None
    """A glider's moving-battery position (``full_scale`` in m, forward positive)."""
    from_autopilot: bool = True
    """Move a servo-mapped role to the output the autopilot's ``SERVOn_FUNCTION``
    parameters name for it (in a log or read live), as ``onboard.offline.autodetect`` does."""


class GnssNoise(_Strict):
    """``[sensors.gnss]``: position (m) and velocity (m/s) noise, one sigma; rate (Hz)."""

    position_std_m: float = 2.0
    """Position noise, one sigma (m)."""
    velocity_std_mps: float = 0.1
    """Velocity noise, one sigma (m/s)."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0.0)] = 5.0
    """Fix rate (Hz)."""
    drift_share: Annotated[float, msgspec.Meta(ge=0.0, le=0.9)] = 0.0
    """The share of a fix's position noise variance (``position_std_m`` squared, or its
    reported accuracy squared) that wanders slowly: multipath and atmosphere, correlated
    over far longer than a surge step, so the same in consecutive fixes and cancelled in a
    path increment. The ``aie``/``kf`` increment filters take the rest, white, as a fix's
    noise; positions keep the whole. 0: all of it white. The simulator's consumer
    receiver: 1.0 m white and 1.1 m drift per axis, ``1.1^2 / (1.0^2 + 1.1^2) = 0.55``."""
    drift_tau_s: Annotated[float, msgspec.Meta(gt=0.0)] = 120.0
    """Correlation time (s) of that wandering share (a first-order Gauss-Markov error):
    its change over a surge step of ``dt`` s, of variance ``2 drift_share R (1 -
    exp(-dt / drift_tau_s))``, is part of each path increment's noise and does not carry
    to the next (algorithms.md §2.2). Unused with ``drift_share = 0``. The simulator's
    consumer receiver: 120 s."""


class ImuNoise(_Strict):
    """``[sensors.imu]``: accelerometer (m/s^2) and gyro (rad/s) noise, one sigma; rate
    (Hz)."""

    accel_std_mps2: float = 0.05
    """Accelerometer noise, one sigma (m/s^2)."""
    gyro_std_rps: float = 0.005
    """Gyro noise, one sigma (rad/s)."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0.0)] = 50.0
    """Sample rate (Hz)."""


class CompassNoise(_Strict):
    """``[sensors.compass]``: heading noise (rad, one sigma); rate (Hz)."""

    heading_std_rad: float = 0.02
    """Heading noise, one sigma (rad)."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0.0)] = 10.0
    """Sample rate (Hz)."""


class DvlNoise(_Strict):
    """``[sensors.dvl]``: velocity noise (m/s, one sigma), the figure of merit and the
    altitude (m) above which a report is not fused; rate (Hz)."""

    velocity_std_mps: float = 0.01
    """Velocity noise, one sigma (m/s)."""
    max_fom_mps: float = 0.05
    """Reports with a larger figure of merit are not fused."""
    max_altitude_m: float = 50.0
    """Reports from higher above the bottom (m) are not fused."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0.0)] = 5.0
    """Report rate (Hz)."""


class DepthNoise(_Strict):
    """``[sensors.depth]``: depth noise (m, one sigma), the depth taken as the surface,
    and the water density (kg/m^3) and surface pressure (Pa) that turn a pressure into a
    depth."""

    depth_std_m: float = 0.02
    """Depth noise, one sigma (m)."""
    surface_depth_m: float = 0.3
    """Shallower than this the vehicle is at the surface and GNSS is accepted."""
    water_density_kgm3: float = 1025.0
    """Water density (kg/m^3) for pressure to depth."""
    surface_pressure_pa: float = 101325.0
    """Air pressure at the surface (Pa) for pressure to depth."""


class Sensors(_Strict):
    """``[sensors]``: noise figures the pipelines use for their R matrices."""

    gnss: GnssNoise = GnssNoise()
    """``[sensors.gnss]``."""
    imu: ImuNoise = ImuNoise()
    """``[sensors.imu]``."""
    compass: CompassNoise = CompassNoise()
    """``[sensors.compass]``."""
    dvl: DvlNoise = DvlNoise()
    """``[sensors.dvl]``."""
    depth: DepthNoise = DepthNoise()
    """``[sensors.depth]``."""


class CsvFormat(_Strict):
    """``[csv]``: column mapping of the generic CSV reader (see docs/formats-text.md).

    ``time`` is the time column and ``time_scale`` turns it into seconds (0.001 for ms).
    Each other entry maps a sample field to a column name; a sample type is produced for
    each row where all of its required columns are present and numeric.
    """

    time: str = "t"
    time_scale: float = 1.0
    lat_deg: str = ""
    """Column of the latitude (deg)."""
    lon_deg: str = ""
    """Column of the longitude (deg)."""
    north_m: str = ""
    """Column of the north position (m from ``origin_lat_deg``/``origin_lon_deg``)."""
    east_m: str = ""
    """Column of the east position (m)."""
    heading: str = ""
    """Column of the heading (``heading_unit``)."""
    heading_unit: Literal["rad", "deg"] = "rad"
    """Unit of the ``heading``, ``roll`` and ``pitch`` columns."""
    yaw_rate: str = ""
    """Column of the yaw rate (``yaw_rate_unit``)."""
    yaw_rate_unit: Literal["rad/s", "deg/s"] = "rad/s"
    """Unit of the ``yaw_rate`` column."""
    surge_mps: str = ""
    """Column of the surge velocity over ground (m/s, body axes)."""
    sway_mps: str = ""
    """Column of the sway velocity over ground (m/s, body axes)."""
    sog_mps: str = ""
    """Column of the GNSS speed over ground (m/s)."""
    north_mps: str = ""
    """Column of the velocity over ground north (m/s, earth axes); with ``east_mps`` a
    VelocityOverGround (a navigation solution's, e.g. a glider's differenced track)."""
    east_mps: str = ""
    """Column of the velocity over ground east (m/s, earth axes)."""
    depth_m: str = ""
    """Column of the depth (m, down positive)."""
    pwm_columns: list[str] = []
    """Columns that form ActuatorOutputs.pwm_us, channel 1 first."""
    run_column: str = ""
    """Optional column naming the run; a directory of CSV files uses the file name."""
    alt_m: str = ""
    """Column of the GNSS altitude (m), put into GnssFix.alt_m."""
    heading_reference: Literal["true", "magnetic"] = "true"
    """Whether the ``heading`` column is relative to true or magnetic north."""
    roll: str = ""
    """Column of the roll angle (``heading_unit``); with ``pitch``, heading and yaw rate
    make an Attitude sample."""
    pitch: str = ""
    """Column of the pitch angle (``heading_unit``)."""
    heading_spike_deg: Annotated[float, msgspec.Meta(ge=0.0)] = 0.0
    """A row whose heading is more than this (deg) from both the last accepted heading and
    the next row's, while those two agree within it, loses its Heading and Attitude
    samples (rejected ``heading_spike``): an angle interpolated across 0/360 the long way
    round (a resampled log). 0: off. The reader then holds each row until the next."""
    assume_level: bool = False
    """Emit Attitude (roll = pitch = 0, yaw = heading, yaw rate) when the log has heading
    and yaw rate but no roll/pitch: an explicit approximation for surface boats."""
    origin_lat_deg: float = 0.0
    """Latitude (deg) of the ``north_m``/``east_m`` origin, used when lat/lon are absent."""
    origin_lon_deg: float = 0.0
    """Longitude (deg) of the ``north_m``/``east_m`` origin."""
    run_gap_s: float = 10.0
    """Gap (s) put between consecutive runs when they are joined on one time line."""
    position_kind: Literal["gnss", "navigation", "unstated"] = "unstated"
    """What the position columns hold: a GNSS receiver's fixes (``gnss``), the vehicle's
    own navigation solution (``navigation``: an INS, or a glider's dead-reckoned track
    corrected at the surface), or ``unstated``. Replay's track.png labels the measured
    track by it (``onboard.offline.plots.position_label``); the estimators use the
    positions alike."""


class ZenohOut(_Strict):
    """``[service.zenoh]``: estimates published over Zenoh: the session mode, the
    endpoints to connect to and listen on, the key prefix."""

    enabled: bool = True
    """Publish over Zenoh."""
    mode: Literal["peer", "client", "router"] = "peer"
    """Zenoh session mode."""
    connect: list[str] = []
    """Endpoints to connect to (``tcp/host:7447``)."""
    listen: list[str] = []
    """Endpoints to listen on."""
    key_prefix: str = "onboard"
    """First part of every key the estimates are published on."""
    config_file: str = ""
    """An optional Zenoh JSON5 config (TLS, user/password, access control)."""
    tls_root_ca_certificate: str = ""
    """The CA certificate that signed the router's (a path, or ``credential:NAME``: a
    systemd credential, docs/security.md); applied on top of ``config_file``."""
    tls_private_key: str = ""
    """This vehicle's TLS private key (path or ``credential:NAME``, private): for ``tls/``
    listen endpoints, and the client key when ``config_file`` enables mutual TLS."""
    tls_certificate: str = ""
    """The certificate that goes with ``tls_private_key``."""
    user_password_file: str = ""
    """One line ``user:password`` (path or ``credential:NAME``, private): the session's
    Zenoh user/password authentication."""


class MavlinkOut(_Strict):
    """``[service.mavlink]``: MAVLink out, and MAVLink 2 signing of the whole service
    (outgoing frames and the MAVLink inputs; docs/security.md)."""

    enabled: bool = True
    """Send MAVLink."""
    url: str = "udpout:127.0.0.1:14550"
    """Where to send it (pymavlink URL, or ``zenoh:PREFIX``: on ``PREFIX/in`` of the
    ``[service.zenoh]`` session, for BlueOS's mavlink-server)."""
    component_id: int = 191
    """Our MAVLink component id."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0.0)] = 5.0
    """Rate (Hz) of the MAVLink estimate messages."""
    signing_key_file: str = ""
    """The 32-byte secret (raw, 64 hex digits or a passphrase), mode 0600 or stricter:
    every outgoing frame is signed with it."""
    require_signing: bool = False
    """Needs ``signing_key_file``; then every frame on the MAVLink inputs must be signed
    with that key and fresh, or it is rejected and counted (``parse:<input>:<reason>``)."""
    signing_state_file: str = "state/mavlink-signing.json"
    """Signing timestamps kept across restarts (relative to the service state directory)."""
    signing_max_future_s: float = 0.0
    """Reject incoming timestamps more than this far (s) ahead of the local timestamp;
    0 = no bound (the MAVLink spec sets none; a vehicle computer without a clock lags)."""
    odometry: bool = False
    """Also send ODOMETRY."""


class SourceConfig(_Strict):
    """One live input: ``kind`` is the protocol, ``url`` the transport.

    URLs: ``serial:/dev/ttyUSB0:115200``, ``udp:0.0.0.0:14551``, ``tcp:192.168.2.95:16171``,
    ``pty:/tmp/gps`` (a pseudo-terminal path), ``gpsd://127.0.0.1:2947`` (kind ``gpsd``),
    ``zenoh:mavlink_raw`` (MAVLink over the ``[service.zenoh]`` session, as BlueOS's
    mavlink-server publishes it; kind ``mavlink``).
    """

    kind: Literal["mavlink", "nmea", "dvl-json", "pd6", "gpsd"]
    url: str
    name: str = ""
    """Name of the input in sources, counters and events; default from the URL."""
    idle_timeout_s: Annotated[float, msgspec.Meta(ge=0.0)] | None = None
    """A connection that delivers no byte for this long (s) is closed and opened again
    (a TCP DVL that power-cycled, a half-open peer, a serial device re-enumerated
    silently); 0 never. Default: 10 s for TCP and gpsd, never for serial, pty and UDP."""
    # MAVLink sources only (docs/service.md, "The autopilot link"):
    target_system: Annotated[int, msgspec.Meta(ge=0, le=255)] = 0
    """The autopilot's system id; 0: the first autopilot whose HEARTBEAT is heard."""
    target_component: Annotated[int, msgspec.Meta(ge=0, le=255)] = 0
    """The autopilot's component id; 0: component 1 (MAV_COMP_ID_AUTOPILOT1)."""
    request_streams: bool = True
    """Ask the autopilot for the messages the pipelines need (SET_MESSAGE_INTERVAL, else
    REQUEST_DATA_STREAM); false: take what it sends (a router or a GCS already asked)."""
    streams: dict[str, float] = {}
    """Rates (Hz) per MAVLink message name that replace the derived ones; 0 drops one."""
    autopilot_time: bool = True
    """Stamp samples with the autopilot's boot time mapped to the service clock (else
    with their receive time)."""
    filter_components: bool = True
    """Decode only the autopilot's frames (other systems and components are counted and
    ignored); false decodes every component's."""


class RecorderConfig(_Strict):
    """``[service.recorder]``: the recording of every input (directory, flush interval
    in s, file rotation size and total size kept, in MB)."""

    enabled: bool = True
    """Record every input."""
    directory: str = "recordings"
    """Where (relative to the state directory)."""
    flush_interval_s: Annotated[float, msgspec.Meta(ge=0.0)] = 0.5
    """Flush interval (s); 0 flushes every record as it is written."""
    rotate_mb: float = 64.0
    """A new file after this size (MB)."""
    max_total_mb: float = 2048.0
    """The oldest recordings are deleted beyond this total (MB)."""
    min_free_mb: float = 200.0
    """Free space (MB) left on the recordings' file system: below it the oldest
    recordings are deleted, then recording pauses (an event; records counted in the
    health record's ``dropped["recorder"]``); 0 = no check."""


class WebOut(_Strict):
    """``[service.web]``: the web page (live map, estimates, health; docs/service.md,
    "Web page") and BlueOS's discovery of it."""

    listen: str = ""
    """``HOST:PORT`` to serve the page on (``0.0.0.0:8110``); empty: no page."""
    edit_config: bool = False
    """Let the page edit the last ``--config`` file: the text is validated as the
    service would load it before it is saved, and applies at the next start."""


UDP_URL = r"^udp:[^\s]+:[0-9]{1,5}$"
"""``udp:HOST:PORT``: the form of the chart plotter outputs' ``url``."""


class NmeaVdrOut(_Strict):
    """``[service.nmea_vdr]``: the current's set and drift as NMEA 0183 ``VDR`` sentences
    over UDP, for chart plotters (OpenCPN, a Signal K server's NMEA 0183 input;
    docs/chartplotters.md)."""

    enabled: bool = False
    """Send VDR."""
    url: Annotated[str, msgspec.Meta(pattern=UDP_URL)] = "udp:127.0.0.1:10110"
    """Where (``udp:HOST:PORT``, a host name or address, a broadcast address too; 10110 is
    the NMEA-over-IP port OpenCPN listens on)."""
    talker: Annotated[str, msgspec.Meta(pattern="^[A-Z]{2}$")] = "II"
    """The sentence's talker (two capital letters; ``II`` integrated instrumentation)."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0.0)] = 1.0
    """At most this many sentences a second (the newest known current)."""
    max_std_mps: Annotated[float, msgspec.Meta(ge=0.0)] = 0.0
    """Send nothing while the current's larger one-sigma (m/s) is above this; 0: no bound."""


class SignalKOut(_Strict):
    """``[service.signalk]``: the current's set and drift as Signal K
    ``environment.current`` deltas over UDP, to a Signal K server's "Signal K" UDP data
    connection (docs/chartplotters.md)."""

    enabled: bool = False
    """Send Signal K deltas."""
    url: Annotated[str, msgspec.Meta(pattern=UDP_URL)] = "udp:127.0.0.1:8375"
    """Where (``udp:HOST:PORT``: the server's Signal K UDP input)."""
    context: str = "vessels.self"
    """The delta's context: ``vessels.self``, or ``vessels.urn:mrn:imo:mmsi:...`` when the
    server belongs to another vessel."""
    label: str = "onboard"
    """The delta's source label."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0.0)] = 1.0
    """At most this many deltas a second (the newest known current)."""
    max_std_mps: Annotated[float, msgspec.Meta(ge=0.0)] = 0.0
    """Send nothing while the current's larger one-sigma (m/s) is above this; 0: no bound."""


class ServiceConfig(_Strict):
    """``[service]``: live inputs, publishers, recorder and persistence."""

    sources: list[SourceConfig] = []
    """The live inputs (``[[service.sources]]``)."""
    zenoh: ZenohOut = ZenohOut()
    """``[service.zenoh]``."""
    mavlink: MavlinkOut = MavlinkOut()
    """``[service.mavlink]``."""
    recorder: RecorderConfig = RecorderConfig()
    """``[service.recorder]``."""
    web: WebOut = WebOut()
    """``[service.web]``."""
    nmea_vdr: NmeaVdrOut = NmeaVdrOut()
    """``[service.nmea_vdr]``."""
    signalk: SignalKOut = SignalKOut()
    """``[service.signalk]``."""
    state_file: str = "state/adaptive.json"
    """Where the adaptive state is kept across restarts (relative to the state
    directory)."""
    state_save_interval_s: Annotated[float, msgspec.Meta(ge=0.0)] = 30.0
    """Interval (s) between saves of the adaptive state; 0: saved only when the service
    stops."""
    queue_size: int = 4096
    """Bound of the samples waiting for the next tick (and of each input's queue);
    beyond it new samples are dropped and counted."""
    watchdog: bool = True
    """Notify the systemd watchdog."""
    tick_wait_s: Annotated[float, msgspec.Meta(ge=0.0)] = 0.05
    """After its grid time a tick waits up to this long (s, capped at half the tick
    period) for the next sample, so that it carries the freshest data (the sensor-to-shore
    latency is then the step, not the wait for the grid); 0 ticks exactly on the grid."""


class SourcePriorities(_Strict):
    """``[sources]``: which source gives each quantity (onboard/engine/sources.py).

    Each list is a priority, best first, of glob patterns on a sample's ``source``
    (``mavlink:1/ATTITUDE``, an NMEA or gpsd input's name, ``mavlink:*/GPS*``); a pattern
    ``mavlink:NAME`` without a ``/`` means that message from any system, and ``!PATTERN``
    excludes the sources it matches. Sources no pattern matches rank after every listed
    one, in the order they first appear. Of the fresh sources of a quantity the
    best-ranked one is used, and only it: a source that has been silent for ``stale_s``
    is replaced by the best fresh one (failover), and a better source that has been fresh
    again for ``failback_s`` takes over (failback).
    """

    position: list[str] = msgspec.field(
        default_factory=lambda: ["mavlink:GPS_RAW_INT", "mavlink:GPS2_RAW"])
    """Position sources."""
    velocity: list[str] = msgspec.field(
        default_factory=lambda: ["mavlink:GLOBAL_POSITION_INT", "mavlink:LOCAL_POSITION_NED"])
    """Velocity over ground: ``VelocityOverGround`` samples and the speed and course of
    ``GnssFix`` samples compete here."""
    heading: list[str] = msgspec.field(
        default_factory=lambda: ["mavlink:ATTITUDE", "mavlink:GLOBAL_POSITION_INT",
                                 "mavlink:VFR_HUD"])
    """Heading sources: ``Attitude`` (its yaw) and ``Heading`` samples compete here;
    VFR_HUD's whole-degree heading comes last."""
    attitude: list[str] = msgspec.field(default_factory=lambda: ["mavlink:ATTITUDE"])
    """Attitude (roll, pitch) sources."""
    imu: list[str] = msgspec.field(
        default_factory=lambda: ["mavlink:SCALED_IMU", "mavlink:RAW_IMU",
                                 "mavlink:SCALED_IMU2", "mavlink:SCALED_IMU3"])
    """IMU sources."""
    depth: list[str] = msgspec.field(
        default_factory=lambda: ["mavlink:SCALED_PRESSURE2", "mavlink:SCALED_PRESSURE3",
                                 "!mavlink:SCALED_PRESSURE"])
    """ArduSub's SCALED_PRESSURE is the autopilot's own barometer (the enclosure's air),
    never a depth."""
    dvl: list[str] = []
    """DVL sources."""
    altitude: list[str] = []
    """Altitude (above the bottom) sources."""
    stale_s: Annotated[float, msgspec.Meta(gt=0.0)] = 2.0
    """A source silent this long (s, sample time) is replaced by the best fresh one."""
    failback_s: Annotated[float, msgspec.Meta(ge=0.0)] = 3.0
    """A better source must deliver for this long (s) without a gap of ``stale_s``
    before it takes over again (no flapping on a source that comes and goes)."""


class Corrections(_Strict):
    """``[corrections]``: known sensor errors taken out of every validated sample before
    the pipelines see it (live and replay alike; ``onboard.engine.corrections.SampleCorrector``).
    The values ``onboard diagnose --write-config`` measures go here.

    Heading: the sensor reads ``true + offset + sum_k (sin_k sin(k psi) + cos_k cos(k
    psi))`` (``psi`` the true heading, ``k = 1, 2, ...``: the compass deviation card as
    harmonics), or the same error interpolated in ``heading_deviation_table``; one of the
    two, not both.
    """

    gnss_latency_s: Annotated[float, msgspec.Meta(ge=0.0, le=5.0)] = 0.0
    """Time (s) between the instant a GNSS fix measures and its time stamp: every
    ``GnssFix`` is re-stamped this much earlier. The engine then fuses the samples up to
    ``tick - gnss_latency_s`` at each tick, so that a fix arriving late is still fused in
    time order with the compass and the commands (the estimates are predicted to the
    tick)."""
    gyro_bias_rps: Annotated[list[float], msgspec.Meta(min_length=3, max_length=3)] = \
        msgspec.field(default_factory=lambda: [0.0, 0.0, 0.0])
    """Gyro bias (rad/s, body x, y, z), subtracted from ``Imu`` gyro rates and
    ``Attitude`` body rates."""
    heading_offset_rad: float = 0.0
    """Constant heading error (rad): a misaligned compass or GNSS-compass baseline."""
    heading_harmonics_sin: list[float] = []
    """Coefficients (rad) of ``sin(k psi)``, ``k = 1, 2, ...`` of the heading error."""
    heading_harmonics_cos: list[float] = []
    """Coefficients (rad) of ``cos(k psi)``, ``k = 1, 2, ...`` of the heading error."""
    heading_deviation_table: list[
        Annotated[list[float], msgspec.Meta(min_length=2, max_length=2)]] = []
    """Deviation card: ``[heading_deg, error_deg]`` pairs, interpolated linearly and
    periodically over the true heading (degrees, as the card is written)."""
    heading_sources: list[str] = []
    """Glob patterns of the sample ``source`` the heading corrections apply to (the
    compass; ``[sources]`` syntax); empty: every heading and attitude source."""
    declination_deg: float | Literal["auto"] = "auto"
    """Magnetic declination (degrees, east positive: ``true = magnetic + declination``)
    added to every heading marked magnetic (NMEA HDM/HDG, a compass-only log) before the
    pipelines see it; ``"auto"``: the heading's own (HDG's variation), else the World
    Magnetic Model at the first GNSS fix (:mod:`onboard.engine.declination`). Headings marked
    true pass unchanged."""


class DiagnoseConfig(_Strict):
    """``[diagnose]``: options of ``onboard diagnose`` (model closure on a log)."""

    declared: list[str] = []
    """Effects the model already contains (e.g. a known sideslip), not to be searched."""
    known: dict[str, list[float]] = {}
    """Effects that are part of this vehicle's model with fixed parameters (internal
    parameter order of each effect module), e.g. from a calm-water calibration run:
    ``known = { surge_yaw_coupling = [0.3] }``."""
    holdout_metric: str = ""
    """``surge_speed_open_loop_rmse_mps``, ``ground_velocity_rmse_mps`` or
    ``lateral_velocity_rmse_mps``; default: the ground velocity when commands exist."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0.0)] = 10.0
    """Rate (Hz) of the grid the log is resampled on for the fits."""
    base_terms: list[str] = []
    """The base model's optional terms to use (onboard.offline.closure.dataset.BASE_TERMS:
    ``actuator_lag``, ``course_lag``, ``speed_drift``; ``["none"]`` for none); default
    ``actuator_lag`` and ``course_lag``. Switching them off shows what each one keeps
    from being named an effect."""


class Config(_Strict):
    """A whole configuration file."""

    vehicle: Vehicle = Vehicle()
    """``[vehicle]``."""
    engine: EngineConfig = EngineConfig()
    """``[engine]``."""
    sources: SourcePriorities = SourcePriorities()
    """``[sources]``."""
    inputs: Inputs = Inputs()
    """``[inputs]``."""
    sensors: Sensors = Sensors()
    """``[sensors]``."""
    csv: CsvFormat = CsvFormat()
    """``[csv]``."""
    service: ServiceConfig = ServiceConfig()
    """``[service]``."""
    pipelines: Pipelines = msgspec.field(default_factory=Pipelines)
    """``[pipelines.<name>]``: each pipeline's table (:mod:`onboard.core.pipeline_config`)."""
    corrections: Corrections = Corrections()
    """``[corrections]``."""
    diagnose: DiagnoseConfig = DiagnoseConfig()
    """``[diagnose]``."""

    def __post_init__(self) -> None:
        c = self.corrections
        if c.heading_deviation_table and (c.heading_harmonics_sin or c.heading_harmonics_cos):
            raise msgspec.ValidationError(
                "heading_deviation_table and heading_harmonics_* both given: one deviation "
                "model only - at `$.corrections`")
        if c.gnss_latency_s >= self.engine.max_sample_age_s:
            raise msgspec.ValidationError(
                f"gnss_latency_s {c.gnss_latency_s} s must be below engine.max_sample_age_s "
                f"({self.engine.max_sample_age_s} s), else every re-stamped fix is late - "
                "at `$.corrections`")


_PATH_RE = re.compile(r" - at `\$(?P<path>[^`]*)`")


def _explain(err: msgspec.ValidationError, prefix: str = "") -> str:
    """Turn msgspec's message into ``dotted.key: what was expected``."""
    msg = str(err)
    m = _PATH_RE.search(msg)
    path = ""
    if m:
        path = m.group("path").lstrip(".")
        path = re.sub(r"\[(\d+)\]", r"[\1]", path)
        msg = msg[: m.start()]
    key = ".".join(p for p in (prefix, path) if p)
    unknown = re.match(r"Object contains unknown field `(\w+)`", msg)
    if unknown:
        key = ".".join(p for p in (key, unknown.group(1)) if p)
        return f"{key}: unknown key (misspelt?)"
    if msg.startswith("Invalid enum value") and key:
        allowed = _enum_choices(key)
        if allowed:
            msg += f"; expected one of {', '.join(allowed)}"
    msg = msg[0].lower() + msg[1:] if msg else msg
    msg = msg.replace("`", "")
    return f"{key}: {msg}" if key else msg


def _enum_choices(key: str) -> list[str]:
    """The allowed values of a Literal-typed config key, for error messages."""
    import typing

    node: Any = Config
    for part in re.sub(r"\[\d+\]", "", key).split("."):
        hints = typing.get_type_hints(node) if isinstance(node, type) else {}
        fields = {f.encode_name: f.name for f in msgspec.structs.fields(node)} if hints else {}
        node = hints.get(fields.get(part, part))
        while typing.get_origin(node) in (list, typing.Union) or (
            node is not None and type(node).__name__ == "UnionType"
        ):
            node = next(a for a in typing.get_args(node) if a is not type(None))
        if node is None:
            return []
    return [str(a) for a in typing.get_args(node)] if typing.get_origin(node) is Literal else []


def from_dict(data: dict[str, Any], origin: str = "<dict>") -> Config:
    """Decode a configuration from a plain mapping; raises ConfigError naming the key. A
    renamed key is an error naming its new one, looked for before decoding
    (:data:`onboard.core.config_renames.RENAMED`)."""
    renamed = renamed_key(data)
    if renamed is not None:
        raise ConfigError(f"{origin}: {renamed[0]}: renamed to {renamed[1]}")
    try:
        return msgspec.convert(data, Config)
    except msgspec.ValidationError as err:
        raise ConfigError(f"{origin}: {_explain(err)}") from None


def load(path: str | Path) -> Config:
    """Read and validate a TOML configuration file.

    A bare name such as ``rudder-boat`` is looked up in the bundled ``config/`` directory.
    """
    p = resolve(path)
    return from_dict(_read_toml(p), str(p))


def _read_toml(p: Path) -> dict[str, Any]:
    """The TOML table of file ``p``; :class:`ConfigError` naming it when unreadable."""
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{p}: cannot read: {err.strerror}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{p}: not valid TOML: {err}") from None


def merge(base: dict[str, Any], overlay: dict[str, Any]) -> dict[str, Any]:
    """``overlay`` on top of ``base`` (neither is changed): a key in both whose values are
    both tables is merged recursively; otherwise the overlay's value (a list, a number,
    a string, a table over a value) replaces the base's whole."""
    out = dict(base)
    for k, v in overlay.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = merge(out[k], v)
        else:
            out[k] = v
    return out


def load_all(paths: str | Path | Sequence[str | Path],
             base: Config | None = None) -> Config:
    """One configuration from several files applied in order (:func:`merge`; later keys
    win). Each file must be valid on its own (an unknown key is an error naming that
    file), and so must the result. One path behaves exactly as :func:`load`.

    ``base``: a configuration to apply the files on (e.g. one detected from a log);
    default: the defaults."""
    if isinstance(paths, (str, Path)):
        paths = [paths]
    if not paths:
        raise ConfigError("no configuration file given")
    if len(paths) == 1 and base is None:
        return load(paths[0])
    data: dict[str, Any] = to_dict(base) if base is not None else {}
    names = []
    for path in paths:
        p = resolve(path)
        layer = _read_toml(p)
        from_dict(layer, str(p))
        data = merge(data, layer)
        names.append(str(p))
    return from_dict(data, " + ".join(names))


def to_dict(cfg: Config) -> dict[str, Any]:
    """``cfg`` as the plain tables a TOML file would hold (keys as spelled in files)."""
    return msgspec.to_builtins(cfg)


def resolve(path: str | Path) -> Path:
    """A config path as given, or a bundled config by name (with or without ``.toml``)."""
    p = Path(path)
    if p.exists():
        return p
    for cand in (CONFIG_DIR / p.name, CONFIG_DIR / f"{p.name}.toml"):
        if cand.exists():
            return cand
    raise ConfigError(f"{path}: no such config file (bundled: {', '.join(bundled())})")


def bundled() -> list[str]:
    """Names of the configs shipped in ``config/`` (:data:`CONFIG_DIR`)."""
    return sorted(p.stem for p in CONFIG_DIR.glob("*.toml"))

