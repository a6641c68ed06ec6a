"""Scenarios: a vehicle, its sea, its sensors, its mission and the effects injected.

``sitl.scenarios.get(name)`` returns a :class:`Scenario`; :data:`SCENARIOS` lists them all
(``onboard sitl --list``). The names are a contract (tests and docs use them):

* the four papers' experiments: ``jaiabot-turns`` (AIE paper), ``bluerov2-circle``
  (ESESO paper), ``gavia-tidal`` (HGO paper), ``spheroid-sawtooth`` (nonlinear-observer
  paper), and ``twin-thruster-turns`` (a BlueBoat doing skid-steering manoeuvres);
* ``remus-ins-steps``: a REMUS 100 (Prestero's coefficients) logged as an ArduSub-like INS
  (velocity and its own heading in GLOBAL_POSITION_INT, an AHRS yaw a few degrees off in
  ATTITUDE) with propeller and heading steps in a 0.3 m/s current;
* the model-closure material, one undeclared effect each on a rudder boat whose nominal
  dynamics are the linear surge model of algorithms.md §1 (linear thrust, linear drag):
  ``effect-current``, ``effect-compass-deviation``, ``effect-heading-bias``,
  ``effect-gyro-bias``, ``effect-gps-latency``, ``effect-thrust-nonlinearity``,
  ``effect-quadratic-drag``, ``effect-surge-yaw-coupling``, ``effect-sideslip``,
  ``effect-waves``, ``effect-two`` (current and compass deviation at once) and ``clean``
  (the same boat and mission, nothing injected); ``clean-twin-thruster`` is the
  twin-thruster boat's clean log (effect sensors, 600 s); ``cat-clean`` is an Otter-class
  catamaran's (speed-independent sway damping: it drifts out of its turns by ~0.5 s times
  speed times yaw rate) and ``cat-gps-latency`` the same with an undeclared 0.6 s GNSS
  latency;
* the fault-injection material, a paper scenario with one *declared* sensor fault
  (:mod:`sitl.effects`): ``fault-gnss-outage`` (no GNSS for 120 s), ``fault-gnss-submerged``
  (a torpedo AUV diving from the surface with a receiver that keeps reporting fixes under
  water), ``fault-dvl-lock-loss`` and ``fault-dvl-lock-loss-rov`` (30 s without bottom
  lock), ``fault-compass-step`` (the compass reads 30 deg off for 5 s);
* a world whose noise the configuration does not know (:func:`noise_scaled`): the true
  sensor noise ``k`` times what the vehicle's bundled config declares (GNSS position and
  its drift, Doppler velocity, compass, DVL; the receiver keeps reporting the declared
  accuracy), ``k`` in :data:`NOISE_SCALES`, for a boat in a current (``noise-boat-0.3x``,
  ``noise-boat-1x``, ``noise-boat-3x``, config ``rudder-boat``) and a torpedo AUV
  (``noise-auv-0.3x`` ... on ``gavia-tidal``, config ``torpedo-auv``).

What the estimator may know of a scenario is :meth:`Scenario.metadata` (vehicle class,
sensor rates and noise figures, the *declared* effects); the injected effects'
parameters are only in the truth file.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from onboard.core.errors import UsageError
from onboard.core.messages import Parameter
from onboard.sitl.effects import Effect
from onboard.sitl.emitters import MAV_TYPE_SUBMARINE, MAV_TYPE_SURFACE_BOAT
from onboard.sitl.environment import CurrentField, Environment
from onboard.sitl.guidance import (
    AuvAutopilot,
    BoatAutopilot,
    CircleReference,
    Controller,
    HeadingSchedule,
    Leg,
    RovCirclePid,
)
from onboard.sitl.plants.base import Command, Plant
from onboard.sitl.plants.catamaran import Catamaran, CatamaranParams
from onboard.sitl.plants.rudder_boat import RudderBoat, RudderBoatParams
from onboard.sitl.plants.twin_thruster import TwinThrusterBoat, TwinThrusterParams
from onboard.sitl.sensors import (
    CompassConfig,
    DepthConfig,
    DvlConfig,
    GnssConfig,
    ImuConfig,
    InsConfig,
    PwmChannel,
    RpmConfig,
    SensorSuiteConfig,
)

DEG = math.pi / 180.0

# ArduPilot SERVOn_FUNCTION numbers
FN_GROUND_STEERING = 26
FN_THROTTLE = 70
FN_THROTTLE_LEFT = 73
FN_THROTTLE_RIGHT = 74
FN_ELEVATOR = 19
FN_RUDDER = 21
FN_MOTOR1 = 33
"""Motor1..Motor6 are 33..38 (ArduSub vectored frame)."""

# ArduPilot custom modes carried in HEARTBEAT
ROVER_MODE_AUTO = 10
SUB_MODE_GUIDED = 4
SUB_MODE_AUTO = 3


# --------------------------------------------------------------------------- vehicles


@dataclass(frozen=True)
class VehicleSpec:
    """A vehicle class as the simulator needs it.

    ``make_plant()`` builds the plant; ``channels`` are its PWM outputs (SERVO_OUTPUT_RAW
    order and SERVOn_FUNCTION); ``to_channels(cmd)`` the normalized value of each channel
    for a command and ``from_channels(values, cmd)`` the command the plant receives from
    the effective channel values (after PWM quantization, saturation and ESC deadband);
    ``thrust_level(cmd)`` the signed propulsion level in [-1, 1] (compass interference);
    ``shaft_rpm(plant, cmd)`` the true propeller speeds (rev/min) for the RPM sensor;
    ``surge_mass(plant)`` the effective surge mass (kg) for force effects.
    """

    vehicle_class: str
    mav_type: int
    custom_mode: int
    make_plant: Callable[[], Plant]
    channels: tuple[PwmChannel, ...]
    to_channels: Callable[[Command], tuple[float, ...]]
    from_channels: Callable[[tuple[float, ...], Command], Command]
    thrust_level: Callable[[Command], float]
    shaft_rpm: Callable[[Any, Command], tuple[float, ...]] = lambda plant, cmd: ()
    surge_mass: Callable[[Any], float] = lambda plant: 1.0

    def parameters(self) -> list[Parameter]:
        """SERVOn_FUNCTION parameters of the outputs, as the autopilot would report them."""
        return [Parameter(t=0.0, source="autopilot", name=f"SERVO{ch.channel}_FUNCTION",
                          value=float(ch.function)) for ch in self.channels]


RUDDER_FULL_RAD = 0.5236
"""Rudder angle at full PWM deflection (+-500 us = +-30 deg, config/rudder-boat.toml)."""
FIN_FULL_RAD = 0.2618
"""Fin angle at full PWM deflection (+-500 us = +-15 deg, config/torpedo-auv.toml)."""


@dataclass(frozen=True)
class NominalRudderBoatParams(RudderBoatParams):
    """Rudder-boat parameters with a configurable thrust law ``T = k sign(th) |th|^e``
    (``thrust_exponent`` e; the plant's own law is e = 2)."""

    thrust_exponent: float = 2.0

    def thrust(self, throttle: float) -> float:
        th = min(1.0, max(-1.0, throttle))
        k = self.t_max if th >= 0.0 else self.k_rev * self.t_max
        return k * math.copysign(abs(th) ** self.thrust_exponent, th)

    def steady_speed(self, throttle: float) -> float:
        """Straight-line speed (m/s), root of d_uu u^2 + d_u u = T (also for d_uu = 0)."""
        t = self.thrust(throttle)
        if self.d_uu == 0.0:
            return t / self.d_u
        return (-self.d_u + math.sqrt(self.d_u**2 + 4.0 * self.d_uu * t)) / (2.0 * self.d_uu)


NOMINAL_BOAT = NominalRudderBoatParams()
"""The effect scenarios' boat: the Jaiabot-class hull as it is (sitl/plants/rudder_boat.py):
thrust quadratic in a shaft speed that lags the throttle by 0.3 s, linear plus quadratic
surge drag, rudder drag, a shallow keel (sway damping 2 + 6 |u| N s/m, so the boat crabs
and its course lags its heading in turns) and the sway-yaw Coriolis coupling that slows
it in turns. ``onboard diagnose`` must tell an injected effect from this hull's own
physics, as it must on a real boat."""


class ForcedRudderBoat(RudderBoat):
    """The rudder boat with ``command.external_force_world`` (N, NED) applied at the origin
    (used by the force effects; the base plant reports but does not apply it), and with
    ``thrust_loss`` = (start s, fraction): from ``start`` the propeller gives ``1 -
    fraction`` of its thrust (the ``thrust_loss`` effect; None: never)."""

    thrust_loss: tuple[float, float] | None = None

    def _rhs(self, t: float, x: np.ndarray, command: Command) -> np.ndarray:
        xd = super()._rhs(t, x, command)
        if self.thrust_loss is not None and t >= self.thrust_loss[0]:
            xd[6] -= self.thrust_loss[1] * self._inputs(command, x[12])[0] / self.params.m11
        f = command.external_force_world
        if f is not None:
            p = self.params
            c, s = math.cos(x[5]), math.sin(x[5])
            xd[6] += (c * f[0] + s * f[1]) / p.m11
            xd[7] += (-s * f[0] + c * f[1]) / p.m22
        return xd


class ForcedTwinThrusterBoat(TwinThrusterBoat):
    """The twin-thruster boat with ``command.external_force_world`` applied."""

    def _rhs(self, t: float, x: np.ndarray, command: Command) -> np.ndarray:
        xd = super()._rhs(t, x, command)
        f = command.external_force_world
        if f is not None:
            p = self.params
            c, s = math.cos(x[5]), math.sin(x[5])
            xd[6] += (c * f[0] + s * f[1]) / p.m11
            xd[7] += (-s * f[0] + c * f[1]) / p.m22
        return xd


def _rudder_boat(params: RudderBoatParams | None = None) -> VehicleSpec:
    p = params or RudderBoatParams()
    return VehicleSpec(
        vehicle_class="rudder-boat",
        mav_type=MAV_TYPE_SURFACE_BOAT,
        custom_mode=ROVER_MODE_AUTO,
        make_plant=lambda: ForcedRudderBoat(p),
        channels=(PwmChannel(channel=1, function=FN_GROUND_STEERING, half_range_us=500,
                             min_us=1000, max_us=2000),
                  PwmChannel(channel=3, function=FN_THROTTLE, half_range_us=500,
                             min_us=1000, max_us=2000)),
        to_channels=lambda c: ((c.rudder_rad or 0.0) / RUDDER_FULL_RAD, c.throttle or 0.0),
        from_channels=lambda v, c: Command(rudder_rad=v[0] * RUDDER_FULL_RAD, throttle=v[1]),
        thrust_level=lambda c: c.throttle or 0.0,
        surge_mass=lambda plant: plant.params.m11,
    )


def _twin_thruster() -> VehicleSpec:
    return VehicleSpec(
        vehicle_class="twin-thruster-boat",
        mav_type=MAV_TYPE_SURFACE_BOAT,
        custom_mode=ROVER_MODE_AUTO,
        make_plant=lambda: ForcedTwinThrusterBoat(),
        channels=(PwmChannel(channel=1, function=FN_THROTTLE_LEFT, deadband_us=25),
                  PwmChannel(channel=3, function=FN_THROTTLE_RIGHT, deadband_us=25)),
        to_channels=lambda c: (c.left or 0.0, c.right or 0.0),
        from_channels=lambda v, c: Command(left=v[0], right=v[1]),
        thrust_level=lambda c: 0.5 * ((c.left or 0.0) + (c.right or 0.0)),
        shaft_rpm=lambda plant, c: tuple(n * 60.0 for n in plant.shaft_speeds),
        surge_mass=lambda plant: plant.params.m11,
    )


def _twin_thruster_miswired() -> VehicleSpec:
    """The twin-thruster boat with its ESCs miswired against the autopilot's outputs:
    output 1 (SERVO1, ``ThrottleLeft``) drives the starboard thruster reversed, output 3
    (``ThrottleRight``) the port one. The autopilot compensates (it learned the wiring),
    so the boat flies its mission; a log read with the nominal channel map sees the
    wrong thrusters."""
    spec = _twin_thruster()
    return dataclasses.replace(
        spec,
        to_channels=lambda c: (-(c.right or 0.0), c.left or 0.0),
        from_channels=lambda v, c: Command(left=v[1], right=-v[0]))


def _catamaran() -> VehicleSpec:
    """The Otter-class catamaran (sitl/plants/catamaran.py): two thrusters on ArduPilot's
    ThrottleLeft/ThrottleRight outputs, wired as the twin-thruster boat's; its shafts
    turn in rad/s (the twin's in rev/s)."""
    return dataclasses.replace(
        _twin_thruster(),
        make_plant=lambda: Catamaran(),
        shaft_rpm=lambda plant, c: tuple(n * 60.0 / (2.0 * math.pi) for n in plant.shaft_speeds))


def _bluerov2() -> VehicleSpec:
    from onboard.sitl.plants.bluerov2 import BlueROV2

    return VehicleSpec(
        vehicle_class="bluerov2",
        mav_type=MAV_TYPE_SUBMARINE,
        custom_mode=SUB_MODE_GUIDED,
        make_plant=lambda: BlueROV2(),
        channels=tuple(PwmChannel(channel=i + 1, function=FN_MOTOR1 + i, deadband_us=25)
                       for i in range(6)),
        to_channels=lambda c: tuple(c.thrusters or (0.0,) * 6),
        from_channels=lambda v, c: Command(thrusters=tuple(v)),
        thrust_level=lambda c: float(np.mean(np.abs(c.thrusters))) if c.thrusters else 0.0,
        surge_mass=lambda plant: float(plant.params.mass_matrix[0, 0]),
    )


def _auv(kind: str) -> VehicleSpec:
    """A torpedo-shaped AUV (``"torpedo"`` or ``"spheroid"``): rudder on SERVO1, stern
    plane on SERVO2 (1500 us neutral, +-500 us = +-15 deg), propeller speed on SERVO3
    (throttle, 1500 + 500 rpm / max_rpm us) and reported by RPM.rpm1."""
    if kind == "torpedo":
        from onboard.sitl.plants.torpedo_auv import REMUS100, TorpedoAUV

        max_rpm, make, cls = REMUS100.max_rpm, TorpedoAUV, "torpedo-auv"
    else:
        from onboard.sitl.plants.spheroid import SpheroidAUV, SpheroidParams

        max_rpm, make, cls = SpheroidParams().max_rpm, SpheroidAUV, "spheroid"
    return VehicleSpec(
        vehicle_class=cls,
        mav_type=MAV_TYPE_SUBMARINE,
        custom_mode=SUB_MODE_AUTO,
        make_plant=lambda: make(),
        channels=(PwmChannel(channel=1, function=FN_RUDDER, half_range_us=500,
                             min_us=1000, max_us=2000),
                  PwmChannel(channel=2, function=FN_ELEVATOR, half_range_us=500,
                             min_us=1000, max_us=2000),
                  PwmChannel(channel=3, function=FN_THROTTLE, half_range_us=500,
                             min_us=1000, max_us=2000)),
        to_channels=lambda c: ((c.rudder_rad or 0.0) / FIN_FULL_RAD,
                               (c.stern_plane_rad or 0.0) / FIN_FULL_RAD,
                               (c.propeller_rpm or 0.0) / max_rpm),
        from_channels=lambda v, c: Command(rudder_rad=v[0] * FIN_FULL_RAD,
                                           stern_plane_rad=v[1] * FIN_FULL_RAD,
                                           propeller_rpm=v[2] * max_rpm),
        thrust_level=lambda c: (c.propeller_rpm or 0.0) / max_rpm,
        shaft_rpm=lambda plant, c: (plant.rpm,),
        surge_mass=lambda plant: float(plant.params.mass_matrix()[0, 0]),
    )


def _speed_to_command(speed_of: Callable[[float], float]) -> Callable[[float], float]:
    """Invert a monotonic steady-speed map ``speed_of(command)`` on [0, 1] by bisection."""
    table = np.linspace(0.0, 1.0, 201)
    speeds = np.array([speed_of(float(c)) for c in table])

    def f(v: float) -> float:
        return float(np.interp(v, speeds, table)) if v > 0 else 0.0
    return f


# --------------------------------------------------------------------------- sea


class TurbulentCurrent(CurrentField):
    """Small-scale turbulence of an estuary: a deterministic sum of ``modes`` frozen
    sinusoidal eddies advected past the vehicle, zero mean, ``std`` (m/s) per horizontal
    axis and ``std * vertical_ratio`` vertically; length scales 5-40 m, periods 20-120 s.
    Deterministic (fixed internal seed): part of the scenario, not of the sensor noise."""

    def __init__(self, std: float = 0.05, vertical_ratio: float = 0.5, modes: int = 8,
                 seed: int = 7) -> None:
        rng = np.random.default_rng(seed)
        k = rng.uniform(2 * math.pi / 40.0, 2 * math.pi / 5.0, (modes, 3))
        k *= rng.choice([-1.0, 1.0], (modes, 3))
        w = rng.uniform(2 * math.pi / 120.0, 2 * math.pi / 20.0, modes)
        phase = rng.uniform(0.0, 2 * math.pi, (modes, 3))
        amp = std * math.sqrt(2.0 / modes)
        self.amp = (amp, amp, amp * vertical_ratio)
        # plain floats: this is evaluated at every integration sub-step
        self._modes = [(*k[i].tolist(), float(w[i]), *phase[i].tolist()) for i in range(modes)]

    def velocity_ned(self, t: float, position_ned: np.ndarray) -> np.ndarray:
        n, e, d = float(position_ned[0]), float(position_ned[1]), float(position_ned[2])
        cos = math.cos
        vn = ve = vd = 0.0
        for kn, ke, kd, w, pn, pe, pd in self._modes:
            a = kn * n + ke * e + kd * d - w * t
            vn += cos(a + pn)
            ve += cos(a + pe)
            vd += cos(a + pd)
        return np.array([self.amp[0] * vn, self.amp[1] * ve, self.amp[2] * vd])


# --------------------------------------------------------------------------- scenario


@dataclass(frozen=True)
class Initial:
    """Initial pose (m, rad) and surge speed through water (m/s)."""

    north: float = 0.0
    east: float = 0.0
    down: float = 0.0
    yaw: float = 0.0
    u: float = 0.0


@dataclass(frozen=True)
class Scenario:
    """Everything that defines a simulated run except the seed and the duration.

    ``controller`` is a factory (a fresh controller per run); ``reference(t)`` the
    reference trajectory a tracking controller follows (None for missions);
    ``injected`` the effects added to the world, ``declared`` the names of those the
    estimator is told about; ``bottom_depth_m`` the flat sea floor (for the DVL), None
    for no bottom in range; ``origin`` the (lat, lon) in degrees of the local frame.
    """

    name: str
    description: str
    reproduces: str
    vehicle: VehicleSpec
    sensors: SensorSuiteConfig
    controller: Callable[[], Controller]
    duration_s: float
    environment: Callable[[], Environment] = Environment
    injected: tuple[Effect, ...] = ()
    declared: tuple[str, ...] = ()
    initial: Initial = Initial()
    origin: tuple[float, float] = (41.49, -71.42)
    bottom_depth_m: float | None = None
    reference: Callable[[float], Any] | None = None
    system_id: int = 1

    def metadata(self) -> dict[str, Any]:
        """What an estimator may read about this scenario (JSON-ready): the vehicle class,
        the sensors and their configured noise and rates, the declared effects with their
        parameters. Undeclared effects are not here."""
        declared = [{"name": e.name, "params": dict(e.params)} for e in self.injected
                    if e.name in self.declared]
        sensors = {k: (dataclasses.asdict(v) if v is not None else None)
                   for k, v in ((f.name, getattr(self.sensors, f.name))
                                for f in dataclasses.fields(self.sensors))}
        # the sensor error knobs that effects drive are not declared unless the effect is
        for k in ("gyro_bias_injected",):
            if sensors.get("imu"):
                sensors["imu"].pop(k, None)
        return {
            "scenario": self.name,
            "description": self.description,
            "vehicle_class": self.vehicle.vehicle_class,
            "origin_deg": list(self.origin),
            "duration_s": self.duration_s,
            "declared_effects": declared,
            "sensors": sensors,
        }


# --------------------------------------------------------------------------- sensors


def _boat_sensors(gnss_hz: float = 5.0) -> SensorSuiteConfig:
    """A small boat: consumer GNSS (total ~1.5 m), MEMS IMU at 50 Hz, magnetic compass."""
    return SensorSuiteConfig(
        gnss=GnssConfig(rate_hz=gnss_hz, position_std_m=1.0, drift_std_m=1.1,
                        drift_tau_s=120.0, velocity_std_mps=0.1),
        imu=ImuConfig(rate_hz=50.0, accel_noise_std=0.05, gyro_noise_std=0.005),
        compass=CompassConfig(rate_hz=10.0, noise_std_rad=0.03),
    )


def _effect_sensors() -> SensorSuiteConfig:
    """The effect scenarios' sensors: a good GNSS at 5 Hz, a quiet compass and a MEMS IMU
    with the bias every one has (turn-on bias left after calibration, drawn per seed, and
    a random walk: ImuConfig's defaults), so that one injected effect at a time stands out
    of what every log carries."""
    return SensorSuiteConfig(
        gnss=GnssConfig(rate_hz=5.0, position_std_m=0.5, drift_std_m=0.3, drift_tau_s=120.0,
                        velocity_std_mps=0.05),
        imu=ImuConfig(rate_hz=50.0, accel_noise_std=0.03, gyro_noise_std=0.003),
        compass=CompassConfig(rate_hz=10.0, noise_std_rad=0.015),
    )


# --------------------------------------------------------------------------- missions


JAIABOT_LEGS = (
    Leg(30.0, 0.0, speed_mps=1.0),
    Leg(25.0, 90 * DEG, speed_mps=1.5),
    Leg(20.0, None, 0.25, speed_mps=1.5),          # a circle to starboard
    Leg(25.0, 200 * DEG, speed_mps=0.8),
    Leg(25.0, 315 * DEG, speed_mps=2.0),
    Leg(20.0, None, -0.3, speed_mps=1.2),          # a circle to port
    Leg(20.0, 45 * DEG, speed_mps=1.8),
    Leg(20.0, 160 * DEG, speed_mps=0.6),
    Leg(15.0, 250 * DEG, speed_mps=2.2),
)
"""The AIE paper's kind of data: step turns, circles both ways and speed steps (200 s)."""

EFFECT_LEGS = (
    Leg(30.0, 0.0, speed_mps=1.5),
    Leg(21.0, None, 0.3, speed_mps=1.5),           # one full circle to starboard
    Leg(25.0, 90 * DEG, speed_mps=0.8),
    Leg(25.0, 200 * DEG, speed_mps=2.2),
    Leg(25.0, None, -0.25, speed_mps=1.2),         # one full circle to port
    Leg(25.0, 300 * DEG, speed_mps=1.8),
    Leg(20.0, 45 * DEG, speed_mps=1.0),
    Leg(20.0, 135 * DEG, speed_mps=2.5),
    Leg(20.0, 250 * DEG, speed_mps=0.8),
)
"""Headings all round (compass deviation), circles (latency, coupling), speed steps from
0.8 to 2.5 m/s (thrust law, drag, sideslip): 211 s, repeated."""

BLUEBOAT_LEGS = (
    Leg(30.0, 0.0, speed_mps=1.5),
    Leg(20.0, 90 * DEG, speed_mps=2.0),
    Leg(15.0, None, 0.6, speed_mps=0.0),           # spin on the spot to starboard
    Leg(25.0, 240 * DEG, speed_mps=1.0),
    Leg(20.0, None, -0.35, speed_mps=1.8),         # circle to port
    Leg(25.0, 330 * DEG, speed_mps=2.5),
    Leg(15.0, None, -0.5, speed_mps=0.0),          # spin to port
    Leg(20.0, 150 * DEG, speed_mps=1.2),
)

CATAMARAN_LEGS = (
    Leg(30.0, 0.0, speed_mps=1.5),
    Leg(25.0, None, 0.2, speed_mps=1.5),           # a circle to starboard
    Leg(25.0, 90 * DEG, speed_mps=0.8),
    Leg(25.0, 200 * DEG, speed_mps=2.5),
    Leg(25.0, None, -0.12, speed_mps=2.2),         # a wide circle to port at speed
    Leg(25.0, 300 * DEG, speed_mps=1.2),
    Leg(20.0, None, 0.25, speed_mps=1.0),          # a tight circle to starboard
    Leg(20.0, 45 * DEG, speed_mps=2.0),
    Leg(20.0, 160 * DEG, speed_mps=0.8),
)
"""The catamaran's mission: step turns and circles both ways at speeds from 0.8 to
2.5 m/s, so that the drift in turns (speed times yaw rate) is seen at many speeds (215 s,
repeated)."""


def _nominal_boat_autopilot() -> Controller:
    p = NOMINAL_BOAT
    return BoatAutopilot(EFFECT_LEGS, _speed_to_command(p.steady_speed))


def _jaiabot_autopilot() -> Controller:
    p = RudderBoatParams()
    return BoatAutopilot(JAIABOT_LEGS, _speed_to_command(p.steady_speed))


def _blueboat_autopilot() -> Controller:
    p = TwinThrusterParams()
    return BoatAutopilot(
        BLUEBOAT_LEGS,
        _speed_to_command(lambda c: p.steady_speed(2.0 * p.thrust(c * p.n_max))),
        steering="skid", kp=0.8, ki=0.02, kd=0.3, steer_limit=0.6)


def _catamaran_autopilot() -> Controller:
    p = CatamaranParams()
    return BoatAutopilot(CATAMARAN_LEGS, _speed_to_command(p.steady_speed),
                         steering="skid", kp=0.8, ki=0.02, kd=0.3, steer_limit=0.6)


def _gavia_autopilot() -> Controller:
    return AuvAutopilot(rpm=1500.0, depth_m=5.0, schedule=HeadingSchedule((0.0,), 1e9))


REMUS_RPM_STEPS = (1100.0, 1525.0, 1300.0, 1525.0, 1200.0)
"""remus-ins-steps' propeller steps (rpm), 60 s each: 1.13 to 1.57 m/s through the water."""
REMUS_HEADINGS = (0.0, 90 * DEG, 200 * DEG, 300 * DEG)
"""remus-ins-steps' heading steps, 90 s each."""


def _remus_steps_autopilot() -> Controller:
    return AuvAutopilot(rpm=REMUS_RPM_STEPS[0], depth_m=5.0, rpm_steps=REMUS_RPM_STEPS,
                        rpm_period_s=60.0, schedule=HeadingSchedule(REMUS_HEADINGS, 90.0))


def _spheroid_autopilot() -> Controller:
    return AuvAutopilot(rpm=1000.0, depth_m=10.0,
                        schedule=HeadingSchedule((15 * DEG, -15 * DEG), 100.0, tau_s=5.0),
                        kz=0.1, kw=0.5, k_theta=1.0, kq=1.0, kpsi=0.8, kr=2.0,
                        fin_limit=0.26)


def _rov_pid() -> Controller:
    from onboard.sitl.plants.bluerov2 import thruster_commands

    return RovCirclePid(CircleReference(), thruster_commands)


# --------------------------------------------------------------------------- registry


def _effect_scenario(name: str, description: str, effects: tuple[Effect, ...],
                     params: RudderBoatParams = NOMINAL_BOAT) -> Scenario:
    return Scenario(
        name=name,
        description=description,
        reproduces="model closure: an effect the estimator is not told about",
        vehicle=_rudder_boat(params),
        sensors=_effect_sensors(),
        controller=_nominal_boat_autopilot,
        duration_s=600.0,
        injected=effects,
        declared=(),
    )


def _build() -> dict[str, Scenario]:
    s: list[Scenario] = [
        Scenario(
            name="jaiabot-turns",
            description="Jaiabot-class rudder boat: step turns, circles and speed steps "
                        "(GPS 5 Hz, compass, IMU)",
            reproduces="Faros & Tanner 2025, AIE of the Jaiabot's surge and heading inputs",
            vehicle=_rudder_boat(),
            sensors=_boat_sensors(gnss_hz=5.0),
            controller=_jaiabot_autopilot,
            duration_s=300.0,
        ),
        Scenario(
            name="twin-thruster-turns",
            description="BlueBoat-class twin-thruster boat: skid-steered turns, spins on "
                        "the spot, speed steps",
            reproduces="BlueBoat system identification runs (skid steering, PWM logged)",
            vehicle=_twin_thruster(),
            sensors=_boat_sensors(gnss_hz=5.0),
            controller=_blueboat_autopilot,
            duration_s=300.0,
            origin=(63.4390, 10.3990),
        ),
        Scenario(
            name="bluerov2-circle",
            description="BlueROV2 on a 2 m circle at 0.5 m/s, 20 m deep, under a constant "
                        "[40, 40, 10] N world-frame push",
            reproduces="Lo, Hu et al., ESESO + AMPC circle test (algorithms.md §5.3)",
            vehicle=_bluerov2(),
            sensors=SensorSuiteConfig(
                # no position fix at 20 m: IMU, AHRS, depth, DVL and the DVL-aided INS, as
                # the ESESO runs in sitl/closed_loop.py (an acoustic fix fed to ArduSub as
                # GPS would be GnssConfig(max_depth_m=math.inf); the engine rejects GNSS
                # below the surface, so it is not used here)
                imu=ImuConfig(rate_hz=50.0, accel_noise_std=0.05, gyro_noise_std=0.005),
                compass=CompassConfig(rate_hz=10.0, noise_std_rad=0.02),
                depth=DepthConfig(rate_hz=10.0, depth_std_m=0.02),
                dvl=DvlConfig(rate_hz=5.0, velocity_std_mps=0.01, max_altitude_m=50.0),
                ins=InsConfig(rate_hz=10.0, velocity_std_mps=0.02, bias_std_mps=0.01),
            ),
            controller=_rov_pid,
            duration_s=240.0,
            injected=(Effect("external_force", {"north": 40.0, "east": 40.0, "down": 10.0}),),
            declared=("external_force",),
            initial=Initial(north=0.0, east=-2.0, down=20.0, yaw=math.pi),
            origin=(22.3040, 114.1800),
            bottom_depth_m=30.0,
            # 0.5 m/s, not the paper's 1.5 m/s: with Table I damping and T200 thrust the
            # 1.5 m/s circle needs up to 117 N against 99 N available along a body axis
            # (70 N diagonally), so every controller saturates (docs/eseso-mpc.md).
            reference=CircleReference(),
        ),
    ]
    s += [
        Scenario(
            name="gavia-tidal",
            description="Gavia/REMUS-class torpedo AUV: straight run at 5 m depth against a "
                        "~1 m/s tidal stream (DVL bottom track, INS, rpm, fins)",
            reproduces="Kim, Fan & Bose 2018 (HGO) / Randeni et al. 2017, Tamar estuary run",
            vehicle=_auv("torpedo"),
            sensors=SensorSuiteConfig(
                gnss=GnssConfig(rate_hz=1.0, position_std_m=1.5, drift_std_m=2.0),
                imu=ImuConfig(rate_hz=100.0, accel_noise_std=0.02, gyro_noise_std=0.001,
                              gyro_bias_std=5e-5, gyro_bias_walk=2e-6),
                compass=CompassConfig(rate_hz=20.0, noise_std_rad=0.003,
                                      attitude_noise_std_rad=0.001),
                depth=DepthConfig(rate_hz=10.0, depth_std_m=0.02),
                dvl=DvlConfig(rate_hz=5.0, velocity_std_mps=0.005, max_altitude_m=30.0,
                              dropout_rate_hz=0.003),
                ins=InsConfig(rate_hz=10.0, velocity_std_mps=0.01, bias_std_mps=0.003),
                rpm=RpmConfig(rate_hz=10.0, noise_std_rpm=5.0),
            ),
            controller=_gavia_autopilot,
            duration_s=600.0,
            environment=lambda: Environment(current=TurbulentCurrent()),
            injected=(Effect("tidal_current", {"amplitude": 1.1, "period": 44712.0,
                                               "direction": math.pi, "phase": 0.5}),),
            declared=("tidal_current",),
            initial=Initial(down=5.0, yaw=0.0, u=1.5),
            origin=(50.4030, -4.2010),
            bottom_depth_m=15.0,
        ),
        Scenario(
            name="remus-ins-steps",
            description="REMUS 100 (Prestero 2001) fed as an ArduSub-like INS: DVL-aided "
                        "velocity and its own true heading in GLOBAL_POSITION_INT (10 Hz), "
                        "the AHRS attitude in ATTITUDE (25 Hz, a magnetic yaw 4-9 deg off "
                        "with heading and propeller load), IMU 50 Hz, RPM and fins 10 Hz, no "
                        "GNSS or depth; propeller steps 1100-1525 rpm, heading steps every "
                        "90 s, a 0.3 m/s current",
            reproduces="issue 22: an independent torpedo-AUV log (velocity and heading from "
                       "the INS, attitude from the AHRS)",
            vehicle=_auv("torpedo"),
            sensors=SensorSuiteConfig(
                imu=ImuConfig(rate_hz=50.0, accel_noise_std=0.02, gyro_noise_std=0.001),
                # the autopilot's AHRS: a magnetic heading with hard-iron deviation and the
                # propeller motor's field (0.15 rad at full thrust: 3.8-5.2 deg at the steps)
                compass=CompassConfig(rate_hz=25.0, noise_std_rad=0.003,
                                      attitude_noise_std_rad=0.001, hard_iron_rad=0.06,
                                      hard_iron_phase_rad=0.8, motor_rad_per_thrust=0.15),
                ins=InsConfig(rate_hz=10.0, velocity_std_mps=0.01, bias_std_mps=0.003,
                              heading_std_rad=0.001),
                rpm=RpmConfig(rate_hz=10.0, noise_std_rpm=5.0),
            ),
            controller=_remus_steps_autopilot,
            duration_s=360.0,
            injected=(Effect("water_current", {"north": 0.18, "east": -0.24}),),
            initial=Initial(down=5.0, yaw=0.0, u=1.1),
            origin=(41.52, -70.67),
        ),
        Scenario(
            name="spheroid-sawtooth",
            description="2 m spheroid at 0.77 m/s, heading +15/-15 deg switching every 100 s "
                        "in the nonuniform flow V = [0, -0.3 sqrt((500+N)/500), 0]",
            reproduces="Fan et al., nonlinear observer for current in nonuniform flow",
            vehicle=_auv("spheroid"),
            sensors=SensorSuiteConfig(
                imu=ImuConfig(rate_hz=50.0, accel_noise_std=0.02, gyro_noise_std=0.002),
                compass=CompassConfig(rate_hz=10.0, noise_std_rad=0.005,
                                      attitude_noise_std_rad=0.002),
                depth=DepthConfig(rate_hz=10.0, depth_std_m=0.02),
                dvl=DvlConfig(rate_hz=5.0, velocity_std_mps=0.005, max_altitude_m=50.0),
                ins=InsConfig(rate_hz=10.0, velocity_std_mps=0.01, bias_std_mps=0.003),
                rpm=RpmConfig(rate_hz=10.0, noise_std_rpm=3.0),
            ),
            controller=_spheroid_autopilot,
            duration_s=600.0,
            injected=(Effect("nonuniform_current", {"amplitude": 0.3, "length": 500.0}),),
            declared=("nonuniform_current",),
            initial=Initial(down=10.0, yaw=15 * DEG, u=0.77),
            origin=(30.2700, 122.3000),
            bottom_depth_m=40.0,
        ),
        _effect_scenario("clean", "the effect scenarios' boat and mission with no effect", ()),
        _effect_scenario("effect-current", "undeclared uniform water current 0.29 m/s",
                         (Effect("water_current", {"north": 0.25, "east": -0.15}),)),
        _effect_scenario("effect-compass-deviation",
                         "undeclared compass deviation 0.12 sin(psi + 0.7) rad",
                         (Effect("compass_deviation", {"amplitude": 0.12, "phase": 0.7}),)),
        _effect_scenario("effect-heading-bias", "undeclared constant heading error 0.08 rad",
                         (Effect("heading_bias", {"radians": 0.08}),)),
        _effect_scenario("effect-gyro-bias", "undeclared gyro bias 0.01 rad/s in yaw",
                         (Effect("gyro_bias", {"z": 0.01}),)),
        _effect_scenario("effect-gps-latency", "undeclared GNSS latency 0.6 s",
                         (Effect("gps_latency", {"seconds": 0.6}),)),
        _effect_scenario("effect-thrust-nonlinearity",
                         "undeclared propeller law thrust ~ |s|^3 (the hull's own: s|s|)",
                         (Effect("thrust_nonlinearity", {"exponent": 3.0}),)),
        _effect_scenario("effect-quadratic-drag",
                         "undeclared quadratic surge drag 1.5 N s^2/m^2",
                         (Effect("quadratic_drag", {"coefficient": 1.5}),)),
        _effect_scenario("effect-surge-yaw-coupling",
                         "undeclared speed loss in turns, surge accel -3 u r^2",
                         (Effect("surge_yaw_coupling", {"coefficient": 3.0}),)),
        _effect_scenario("effect-sideslip",
                         "undeclared side force 2 u|u| N: a crab angle growing with speed",
                         (Effect("sideslip", {"coefficient": 2.0}),)),
        _effect_scenario("effect-waves", "undeclared regular waves, 2.5 s period, 0.3 m high",
                         (Effect("wave_oscillation", {"period": 2.5, "height": 0.3,
                                                      "direction": 0.5}),)),
        _effect_scenario("effect-two",
                         "two undeclared effects: current 0.22 m/s and compass deviation",
                         (Effect("water_current", {"north": 0.2, "east": 0.1}),
                          Effect("compass_deviation", {"amplitude": 0.1, "phase": -1.0}))),
        # Effects outside the diagnosis catalog (tests/test_diagnose_unknown.py).
        _effect_scenario("effect-rotating-current",
                         "undeclared current of 0.3 m/s whose direction turns 60 deg over "
                         "the run",
                         (Effect("rotating_current", {"speed": 0.3, "direction": 0.3,
                                                      "rate": math.radians(60.0) / 600.0}),)),
        _effect_scenario("effect-soft-iron",
                         "undeclared second-harmonic (soft-iron) compass error "
                         "0.08 sin(2 psi + 0.4) rad",
                         (Effect("soft_iron", {"amplitude": 0.08, "phase": 0.4}),)),
        _effect_scenario("effect-wind",
                         "undeclared steady 5 m/s wind toward 2.0 rad on the hull",
                         (Effect("wind", {"speed": 5.0, "direction": 2.0}),)),
        _effect_scenario("effect-thrust-loss",
                         "undeclared fouled propeller: 35 % of the thrust lost from 240 s",
                         (Effect("thrust_loss", {"start": 240.0, "fraction": 0.35}),)),
        _effect_scenario("effect-gnss-jitter",
                         "undeclared GNSS time-tag jitter, 0.15 s std, no mean latency",
                         (Effect("gnss_jitter", {"std_s": 0.15}),)),
    ]
    s.append(Scenario(
        name="clean-twin-thruster",
        description="twin-thruster-turns for 600 s with the effect scenarios' sensors, "
                    "nothing injected",
        reproduces="model closure: the twin-thruster boat's clean log (false alarms)",
        vehicle=_twin_thruster(),
        sensors=_effect_sensors(),
        controller=_blueboat_autopilot,
        duration_s=600.0,
        origin=(63.4390, 10.3990),
    ))
    s.append(Scenario(
        name="effect-thruster-swap",
        description="twin-thruster-turns for 600 s with SERVO1 driving the starboard "
                    "thruster reversed and SERVO3 the port one (undeclared)",
        reproduces="model closure: thruster channels swapped and reversed",
        vehicle=_twin_thruster_miswired(),
        sensors=_effect_sensors(),
        controller=_blueboat_autopilot,
        duration_s=600.0,
        origin=(63.4390, 10.3990),
    ))
    cat = Scenario(
        name="cat-clean",
        description="Otter-class catamaran (speed-independent sway damping, thrust ~ n|n| "
                    "behind a 0.4 s shaft lag) flying turns for 600 s with the effect "
                    "scenarios' sensors, nothing injected",
        reproduces="model closure: a catamaran's clean log (false latency from its drift "
                   "in turns)",
        vehicle=_catamaran(),
        sensors=_effect_sensors(),
        controller=_catamaran_autopilot,
        duration_s=600.0,
        origin=(63.4390, 10.3990),
    )
    s.append(cat)
    s.append(dataclasses.replace(
        cat, name="cat-gps-latency",
        description="cat-clean with an undeclared GNSS latency of 0.6 s",
        reproduces="model closure: a true latency on a hull that drifts in turns",
        injected=(Effect("gps_latency", {"seconds": 0.6}),)))
    by_name = {sc.name: sc for sc in s}
    faults = [
        _fault(by_name["jaiabot-turns"], "fault-gnss-outage",
               "jaiabot-turns with no GNSS fix from 30 s to 150 s",
               (Effect("gnss_outage", {"start": 30.0, "duration": 120.0}),)),
        _fault(by_name["gavia-tidal"], "fault-gnss-submerged",
               "gavia-tidal starting at the surface and diving to 5 m, its GNSS receiver "
               "reporting (wrong) fixes under water",
               (), sensors=dataclasses.replace(
                   by_name["gavia-tidal"].sensors,
                   gnss=dataclasses.replace(by_name["gavia-tidal"].sensors.gnss,  # type: ignore[arg-type]
                                            max_depth_m=math.inf)),
               initial=Initial(down=0.0, yaw=0.0, u=1.5)),
        _fault(by_name["gavia-tidal"], "fault-dvl-lock-loss",
               "gavia-tidal with the DVL out of bottom lock from 40 s to 70 s",
               (Effect("dvl_lock_loss", {"start": 40.0, "duration": 30.0}),)),
        _fault(by_name["bluerov2-circle"], "fault-dvl-lock-loss-rov",
               "bluerov2-circle with the DVL out of bottom lock from 40 s to 70 s",
               (Effect("dvl_lock_loss", {"start": 40.0, "duration": 30.0}),)),
        _fault(by_name["jaiabot-turns"], "fault-compass-step",
               "jaiabot-turns with the compass reading 30 deg too much from 40 s to 45 s",
               (Effect("compass_step", {"start": 40.0, "duration": 5.0,
                                        "radians": 30 * DEG}),)),
    ]
    by_name.update((sc.name, sc) for sc in faults)
    by_name.update((sc.name, sc) for sc in _noise_family(by_name))
    return by_name


NOISE_SCALES = (0.3, 1.0, 3.0)
"""The true sensor noise of the noise-scale scenarios, relative to the declared."""
NOISE_BOAT_CURRENT = {"north": 0.15, "east": -0.2}
"""The noise-scale boat's water current (m/s, earth; 0.25 m/s), undeclared."""
AUV_DECLARED_COMPASS_RAD = 0.02
"""The compass noise ``config/torpedo-auv.toml`` declares (the default of
``[sensors.compass] heading_std_rad``)."""


def noise_scaled(base: Scenario, name: str, k: float, compass_declared_rad: float
                 ) -> Scenario:
    """``base`` with every sensor's white noise (and the GNSS drift) ``k`` times its own,
    the compass's ``k`` times ``compass_declared_rad``; the receiver reports the accuracy
    of ``k = 1``. ``base``'s noise is what its config declares."""
    sn = base.sensors
    g, c, d = sn.gnss, sn.compass, sn.dvl
    changes: dict[str, Any] = {}
    if g is not None:
        changes["gnss"] = dataclasses.replace(
            g, position_std_m=k * g.position_std_m, drift_std_m=k * g.drift_std_m,
            velocity_std_mps=k * g.velocity_std_mps,
            reported_accuracy_m=math.hypot(g.position_std_m, g.drift_std_m))
    if c is not None:
        changes["compass"] = dataclasses.replace(c, noise_std_rad=k * compass_declared_rad)
    if d is not None:
        changes["dvl"] = dataclasses.replace(d, velocity_std_mps=k * d.velocity_std_mps)
    return dataclasses.replace(
        base, name=name, sensors=dataclasses.replace(sn, **changes),
        description=f"{base.description}; every sensor's noise {k:g} times the declared",
        reproduces="a world whose noise the configuration does not know (issue 32)")


def _noise_family(by_name: dict[str, Scenario]) -> list[Scenario]:
    """The noise-scale scenarios (module docstring): the rudder boat of the effect
    scenarios with the small-boat sensors ``config/rudder-boat.toml`` declares, in a
    0.25 m/s current, and ``gavia-tidal``."""
    boat = dataclasses.replace(
        by_name["effect-current"], sensors=_boat_sensors(),
        description="rudder boat on the effect mission in a 0.25 m/s current",
        injected=(Effect("water_current", NOISE_BOAT_CURRENT),))
    out = []
    for k in NOISE_SCALES:
        out.append(noise_scaled(boat, f"noise-boat-{k:g}x", k, 0.03))
        out.append(noise_scaled(by_name["gavia-tidal"], f"noise-auv-{k:g}x", k,
                                AUV_DECLARED_COMPASS_RAD))
    return out


def _fault(base: Scenario, name: str, description: str, effects: tuple[Effect, ...],
           **changes: Any) -> Scenario:
    """``base`` with the sensor faults ``effects`` injected and declared."""
    return dataclasses.replace(
        base, name=name, description=description,
        reproduces=f"fault injection on {base.name}: the service's handling of a sensor fault",
        injected=base.injected + effects,
        declared=base.declared + tuple(e.name for e in effects), **changes)


SCENARIOS: dict[str, Scenario] = _build()
"""Every scenario by name."""


def names() -> list[str]:
    """The scenario names, in listing order."""
    return list(SCENARIOS)


def get(name: str) -> Scenario:
    """The scenario called ``name``; :class:`~onboard.core.errors.UsageError` if there is none."""
    try:
        return SCENARIOS[name]
    except KeyError:
        raise UsageError(f"unknown scenario {name!r}; try `onboard sitl --list`") from None
